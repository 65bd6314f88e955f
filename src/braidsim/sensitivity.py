"""Forward sensitivities: how a run's results change with a parameter or the initial state.

Along each direction (a numeric scenario key, or a component of the initial state) the
compiled solver integrates the variational equations with the motion and carries them
through contact onset and exit, the latched approach speed and the transfers
(:mod:`braidsim.core.solver.tangent`; the method and its derivation are in
``docs/sensitivities.md``). What comes out, in SI units per SI unit of the key:

- the derivatives of the final state (x, vx, y, vy);
- for every impact, of its onset time, approach speed, peak force, maximum depth, exit
  time and rebound speed (:data:`IMPACT_QUANTITIES`);
- for every row of the series, of (x, vx, y, vy, ax, ay) and of both contact forces
  (:data:`SERIES_QUANTITIES`), at the fixed time of the row.

The map from a scenario key to the fields of the model record (a stiffness from Eq. (4),
a damping factor from a restitution, a load from a tension and an angle) is closed-form
algebra; it is differentiated by a fourth-order central difference of the record builder
(relative error about 1e-12), the dynamics by the variational equations.

:func:`flow_map` gives the Jacobians of the map from one time to another (the state and the
latched speeds at t0 to those at t1): the monodromy of a periodic orbit's stroboscopic map.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.core import layout as L
from braidsim.core.driver import RawRun, SensitivityRun, Tangents, as_declared
from braidsim.errors import InputError, SimulationError

if TYPE_CHECKING:
    import pandas as pd

    from braidsim.model import Model
    from braidsim.params import Scenario

IMPACT_QUANTITIES: tuple[str, ...] = L.IMPACT_SENS_FIELDS
"""What the derivatives of each impact are of, in order."""
SERIES_QUANTITIES: tuple[str, ...] = L.SERIES_SENS_FIELDS
"""What the derivatives of each series row are of, in order."""
STATE_NAMES = ("x", "vx", "y", "vy")
GAP_SAMPLES = 400  # samples of a flow map's run for its smallest gaps

# keys that are settings of the solver or of the run, not parameters of the model
_NOT_PARAMETERS = ("simulation.",)


class SensitivityError(SimulationError):
    """Sensitivities asked of a run whose event sequence changes under an infinitesimal
    change of the parameters (a grazing contact): its derivatives do not exist there."""


def _relative_step(value: float) -> float:
    return 1e-4 * abs(value) if value != 0.0 else 1e-8


def _leaves_equal(a: Any, b: Any) -> bool:
    if isinstance(a, tuple) and hasattr(a, "_fields"):
        return all(_leaves_equal(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.shape == b.shape
    return True


#: stencil values within this many rounding units of the primal value are its value
ROUNDING_UNITS = 8.0


def _stencil_derivative(
    values: Sequence[Any], weights: Sequence[float], h: float, primal: Any
) -> np.ndarray:
    """sum_i w_i f(p + o_i h) / h, elementwise, and exactly 0 where every stencil value is
    within :data:`ROUNDING_UNITS` rounding units of f(p).

    A field that does not depend on the key still differs between the stencil's records by
    the rounding of the algebra that builds it (an ulp or two), and divided by h that
    rounding became a derivative: with h = 1e-8 (a key whose value is 0) about 1e-8
    relative, more than a run's tolerance (the initial speed of the xy carrier along
    ``initial.x``, whose true derivative is 0, was 1.4e-9 m/s). A true derivative D that
    moves f by no more than that over the stencil (|D| h <= 8 eps |f|) is below what the
    stencil resolves anyway.
    """
    f0 = np.asarray(primal, dtype=float)
    acc = np.zeros_like(f0)
    spread = np.zeros_like(f0)
    for r, w in zip(values, weights, strict=True):
        v = np.asarray(r, dtype=float)
        acc = acc + w * v
        with np.errstate(invalid="ignore"):
            spread = np.maximum(spread, np.abs(v - f0))
    out = np.array(acc / h, dtype=float)  # (0-d for a scalar field)
    out[spread <= ROUNDING_UNITS * np.finfo(float).eps * np.abs(f0)] = 0.0
    return out


def _tangent(records: Sequence[Any], weights: Sequence[float], h: float, primal: Any) -> Any:
    """The derivative of a record tree from its values at stencil points (weights / h, 0
    where they differ from the primal's by rounding only: :func:`_stencil_derivative`);
    integer and boolean fields are copied from the primal, infinite fields get 0."""
    if isinstance(primal, tuple) and hasattr(primal, "_fields"):
        return type(primal)(
            *[
                _tangent([getattr(r, f) for r in records], weights, h, getattr(primal, f))
                for f in primal._fields
            ]
        )
    if isinstance(primal, np.ndarray):
        if primal.dtype.kind != "f":
            return primal
        out = _stencil_derivative(records, weights, h, primal)
        out[~np.isfinite(primal)] = 0.0
        return np.ascontiguousarray(out)
    if isinstance(primal, (bool, np.bool_, int, np.integer)):
        if any(r != primal for r in records):
            raise ValueError("an integer field changes")
        return primal
    if not math.isfinite(primal):
        return 0.0
    return float(_stencil_derivative(records, weights, h, primal))


def zero_tangent(primal: Any) -> Any:
    """The tangent record of a direction that changes no parameter.

    Integer fields (a law's code, a flag) are kept: they say what the record is, and have
    no derivative. A field declared ``float`` but given as an integer (``mass=1``) is a
    number like any other: its tangent is 0.0, not the integer itself (which made d mass
    = 1 along every direction, and the monodromy of such a record wrong).
    """
    if isinstance(primal, tuple) and hasattr(primal, "_fields"):
        primal = as_declared(primal)
        return type(primal)(*[zero_tangent(getattr(primal, f)) for f in primal._fields])
    if isinstance(primal, np.ndarray):
        return primal if primal.dtype.kind != "f" else np.zeros_like(primal)
    if isinstance(primal, (bool, np.bool_, int, np.integer)):
        return primal
    return 0.0


# central (x +- h, x +- 2h) and one-sided (x, x + h ... x + 4h) fourth-order stencils
_CENTRAL = ((-2, 1 / 12), (-1, -8 / 12), (1, 8 / 12), (2, -1 / 12))
_FORWARD = ((0, -25 / 12), (1, 48 / 12), (2, -36 / 12), (3, 16 / 12), (4, -3 / 12))


@dataclass
class Directions:
    """The tangents of the model's record, initial state and transfer times along each key."""

    keys: tuple[str, ...]
    records: list[Any]
    S0: np.ndarray  # (k, 2 n_coords)
    DTR: np.ndarray  # (k, n_transfers)
    scale: np.ndarray  # (k,)

    def tangents(self, series: bool, DV0: np.ndarray | None = None) -> Tangents:
        k = len(self.keys)
        dv0 = np.zeros((k, 2)) if DV0 is None else DV0
        return Tangents(self.records, self.S0, dv0, self.DTR, self.scale, series)


def _key_value(model: Model, key: str) -> float:
    """The SI value of a numeric key as the model uses it (a stiffness derived from the
    materials, an exponent from the law, when the scenario leaves them out)."""
    from braidsim.params import SCHEMA

    if not isinstance(key, str) or key not in SCHEMA:
        from braidsim.params import _closest

        key = str(key)
        # (an empty or unprintable name quoted: it was ": unknown parameter", naming nothing)
        shown = key if key and key.isprintable() and len(key) <= 80 else repr(key[:80])
        raise InputError(
            f"sensitivity: {shown} is not a scenario key{_closest(key)}; allowed: numeric "
            "model parameters (`braidsim scenarios --keys` lists all)"
        )
    spec = SCHEMA[key]
    if spec.kind != "float" or key.startswith(_NOT_PARAMETERS):
        raise InputError(
            f"sensitivity: {key} is not a differentiable parameter (a {spec.kind} "
            "setting); allowed: numeric model parameters such as contact.track.restitution, "
            "track.clearance, initial.x"
        )
    value = model.scenario[key]
    if value is None:
        for pair in ("track", "slot"):
            if key == f"contact.{pair}.stiffness":
                return float(getattr(model, pair).stiffness)
            if key == f"contact.{pair}.exponent":
                return float(getattr(model, pair).exponent)
        raise InputError(f"sensitivity: {key} is not set in this scenario; set it to a number")
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f"sensitivity: {key} = {value} is not finite; set it to a number")
    return value


def key_unit(model: Model, key: str) -> str:
    """The SI unit of a scenario key as :class:`Sensitivities` differentiate by it: the
    schema's unit ("" for a dimensionless key), and ``N/m^n`` with the pair's exponent n for
    a contact stiffness (whose unit depends on n)."""
    from braidsim.params import SCHEMA

    for pair in ("track", "slot"):
        if key == f"contact.{pair}.stiffness":
            return f"N/m^{float(getattr(model, pair).exponent):g}"
    return SCHEMA[key].unit


def directions(model: Model, keys: Sequence[str]) -> Directions:
    """The tangents along each scenario key (see the module docstring)."""
    from braidsim.model import build_model

    sc = model.scenario
    n2 = 2 * (2 if model.two_dof else 1)

    def over_span(scenario: Any) -> Model:
        # (over the run's own span: its transfers, whose times have tangents too)
        return build_model(
            scenario,
            model.duration,
            t_start=model.t_start,
            keep_zero_harmonics=True,
            continued=model.continued,
        )

    base = over_span(sc)
    out_records: list[Any] = []
    S0 = np.zeros((len(keys), n2))
    DTR = np.zeros((len(keys), base.transfer_times.size))
    scale = np.ones(len(keys))
    seen: set[str] = set()
    for i, key in enumerate(keys):
        if key in seen:
            raise InputError(f"sensitivity: {key} is asked twice")
        seen.add(key)
        p = _key_value(base, key)
        scale[i] = abs(p) if p != 0.0 else 1.0
        h = _relative_step(p)
        built = None
        for stencil in (_CENTRAL, _FORWARD, tuple((-o, -w) for o, w in _FORWARD)):
            try:
                built = [(over_span(sc.with_overrides({key: p + o * h})), w) for o, w in stencil]
            except InputError:
                continue
            break
        if built is None:
            raise InputError(f"sensitivity: {key} = {p:g} sits where the model cannot vary it")
        models = [m for m, _ in built]
        weights = [w for _, w in built]
        if not all(_leaves_equal(base.record, m.record) for m in models) or any(
            m.transfer_times.shape != base.transfer_times.shape for m in models
        ):
            raise InputError(
                f"sensitivity: {key} changes the structure of the model (a harmonic or a "
                "transfer appears or goes), so it has no derivative here"
            )
        try:
            out_records.append(_tangent([m.record for m in models], weights, h, base.record))
        except ValueError:
            raise InputError(
                f"sensitivity: {key} switches a discrete setting of the model; it has no "
                "derivative here"
            ) from None
        S0[i] = _stencil_derivative([m.y0[:n2] for m in models], weights, h, base.y0[:n2])
        if DTR.shape[1]:
            DTR[i] = _stencil_derivative(
                [m.transfer_times for m in models], weights, h, base.transfer_times
            )
    return Directions(tuple(keys), out_records, S0, DTR, scale)


def check_differentiable(record: Any) -> None:
    """Raise an InputError naming the part of a model record that has no tangents: the model
    itself (its four model tangents) or a physics record inside it, found by what it
    implements (a contact law, a friction law or an excitation needs the tangent of that
    function), whatever the field that holds it."""
    from braidsim.core.driver import tangents_missing

    missing = tangents_missing(record)
    if missing is None:
        return
    field, sub, fn = missing
    if sub is None:
        raise InputError(
            f"sensitivity: the model {type(record).__name__} has no tangents (register "
            f"{fn.__name__} for it)"
        )
    raise InputError(
        f"sensitivity: {type(sub).__name__} ({field}) does not provide its derivatives "
        f"(register {fn.__name__} for it)"
    )


@dataclass
class Sensitivities:
    """The derivatives of a run's results along ``keys`` (SI per SI unit of the key).

    Attributes
    ----------
    keys : tuple of str
        The directions, in the order of axis 1 of the arrays below.
    final : np.ndarray (k, 4)
        d(x, vx, y, vy) at the end of the run / d key (y and vy are 0 for the x-only
        carrier).
    impacts : np.ndarray (n_impacts, k, 7)
        d(:data:`IMPACT_QUANTITIES`) / d key for each row of ``Result.impacts`` (NaN where
        undefined: the exit time and rebound speed of a contact still open at the end, the
        rebound speed of one cut by a transfer, the approach speed of a contact carried
        into a continued run, the dissipated energy of a run that does not integrate it;
        the onset of a contact present at the start is the start, its derivative 0).
    series : np.ndarray (n_rows, k, 8) or None
        d(:data:`SERIES_QUANTITIES`) / d key at the time of each row of ``Result.series``.
    latched : np.ndarray (k, 2)
        d(latched approach speed of the track and slot pairs at the end) / d key.
    """

    keys: tuple[str, ...]
    final: np.ndarray
    impacts: np.ndarray
    series: np.ndarray | None
    latched: np.ndarray

    def __repr__(self) -> str:
        rows = "no series" if self.series is None else f"{self.series.shape[0]} series rows"
        return (
            f"<braidsim.Sensitivities along {', '.join(self.keys)}: "
            f"{self.impacts.shape[0]} impacts, {rows}>"
        )

    @classmethod
    def from_run(cls, keys: Sequence[str], sens: SensitivityRun) -> Sensitivities:
        k = len(keys)
        final = np.zeros((k, 4))
        final[:, : sens.S.shape[1]] = sens.S
        return cls(tuple(keys), final, sens.impacts, sens.series, sens.DV0)

    def final_dict(self) -> dict[str, dict[str, float]]:
        """``{key: {"x", "vx", "y", "vy"}}`` as in ``braidsim run --json``."""
        return {
            key: {q: float(self.final[i, j]) for j, q in enumerate(STATE_NAMES)}
            for i, key in enumerate(self.keys)
        }

    def impact_dict(self, row: int) -> dict[str, dict[str, float | None]]:
        """``{key: {"t", "velocity", "peak_force", "max_depth", "t_end",
        "rebound_velocity", "dissipated_energy"}}`` of impact ``row`` (None where
        undefined)."""
        out: dict[str, dict[str, float | None]] = {}
        for i, key in enumerate(self.keys):
            vals = self.impacts[row, i]
            out[key] = {
                q: (float(v) if math.isfinite(v) else None)
                for q, v in zip(IMPACT_QUANTITIES, vals, strict=True)
            }
        return out

    def impacts_frame(self, impacts: pd.DataFrame) -> pd.DataFrame:
        """A long table: one row per (impact, key), the impact's time and pair beside the
        derivatives."""
        import pandas as pd

        rows = []
        for r in range(self.impacts.shape[0]):
            for i, key in enumerate(self.keys):
                rec: dict[str, Any] = {
                    "impact": r,
                    "t": float(impacts["t"].iloc[r]),
                    "pair": impacts["pair"].iloc[r],
                    "key": key,
                }
                vals = self.impacts[r, i]
                rec.update(
                    {f"d_{q}": float(v) for q, v in zip(IMPACT_QUANTITIES, vals, strict=True)}
                )
                rows.append(rec)
        return pd.DataFrame(rows)


def sensitivity_error(t: float, t_start: float | None = None) -> SensitivityError:
    """The error of a run that met a grazing contact; at the run's start ``t_start`` (within
    a picosecond), of one that starts on a wall whose gap a key moves."""
    if t_start is not None and abs(t - t_start) <= 1e-12 * max(1.0, abs(t_start)):
        return SensitivityError(
            f"the carrier starts on a wall at t = {t_start:.9g} s (touching it, no overlap) "
            "and a sensitivity key moves that wall's gap there (or, at rest on the wall, its "
            "rate): one way the contact starts later or not at all, the other it overlaps "
            "from the start, so the sensitivities do not exist (as at a grazing contact); "
            "leave such keys (the initial position or speed, that wall's clearance) out, or "
            "start the carrier off the wall or overlapping it",
            t,
        )
    return SensitivityError(
        f"a contact starts or ends with (almost) zero normal speed at t = {t:.9g} s (a "
        "grazing contact): the sequence of impacts changes under an infinitesimal change, "
        "so the sensitivities do not exist there; change the parameters a little or end the "
        "run before that time",
        t,
    )


# =======================================================================================
# Flow map and monodromy
# =======================================================================================


@dataclass
class FlowMap:
    """The map from the state and contacts at t0 to those at t1, with its Jacobians.

    ``n`` is 2 for the x-only carrier (x, vx), 4 for the xy carrier (x, vx, y, vy), ground
    frame as the solver holds it. Latched speeds are those of the contacts open at t0 (a
    free pair's column is 0) and at t1 (a free pair's row is 0).
    """

    t0: float
    t1: float
    y0: np.ndarray
    modes0: tuple[int, int]
    v0s0: np.ndarray
    y1: np.ndarray
    modes1: tuple[int, int]
    v0s1: np.ndarray
    jac_y: np.ndarray  # (n, n)
    jac_v0: np.ndarray  # (n, 2)
    dv0_dy: np.ndarray  # (2, n)
    dv0_dv0: np.ndarray  # (2, 2)
    keys: tuple[str, ...]
    jac_p: np.ndarray  # (n, len(keys))
    dv0_dp: np.ndarray  # (2, len(keys))
    episodes: np.ndarray  # the run's impact table (EPISODE_DTYPE rows)
    impact_sens: np.ndarray  # (n_impacts, n + 2 + len(keys), 7)
    min_gaps: np.ndarray  # (2, 2)

    @functools.cached_property
    def impacts(self) -> pd.DataFrame:
        """The impacts in [t0, t1] (the columns of ``Result.impacts``), made when first read:
        continuation reads only the Jacobians of its many maps (a table took ~0.8 ms a
        map)."""
        from braidsim.result import impacts_frame  # pandas: only once a table is read

        return impacts_frame(self.episodes)

    def contact_pairs(self) -> list[int]:
        """The pairs in contact at t0 (their latched speeds are part of the map's state)."""
        return [p for p in range(2) if self.modes0[p] != 0]

    def monodromy(self) -> np.ndarray:
        """The Jacobian of the map on z = (y, latched speeds of the pairs in contact at t0):
        the monodromy matrix when t1 - t0 is a period of a periodic orbit whose section
        this is. The contact modes at t0 and t1 must agree."""
        if tuple(self.modes1) != tuple(self.modes0):
            raise SimulationError(
                f"the contacts at t1 ({self.modes1}) differ from those at t0 ({self.modes0}): "
                "not the section of a periodic orbit",
                self.t1,
            )
        cp = self.contact_pairs()
        n = self.y1.size
        M = np.zeros((n + len(cp), n + len(cp)))
        M[:n, :n] = self.jac_y
        for j, p in enumerate(cp):
            M[:n, n + j] = self.jac_v0[:, p]
            M[n + j, :n] = self.dv0_dy[p]
            for jj, pp in enumerate(cp):
                M[n + j, n + jj] = self.dv0_dv0[p, pp]
        return M


def _initial_state(y0: Any, n: int) -> np.ndarray:
    """``y0`` as the n entries of a flow map's start, checked."""
    try:
        ya = np.asarray(y0, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"flow_map: y0 = {y0!r}; allowed {n} finite numbers") from None
    if ya.shape != (n,):
        raise InputError(f"flow_map: y0 has the shape {ya.shape}; allowed {n} finite numbers")
    if not np.all(np.isfinite(ya)):
        raise InputError(f"flow_map: y0 = {ya.tolist()} is not finite; allowed {n} finite numbers")
    return ya


def _checked_keys(keys: Any) -> tuple[str, ...]:
    """The keys of a flow map's parameters: a sequence of names, not one name (whose
    letters a loop would take for keys)."""
    if isinstance(keys, str) or not all(isinstance(k, str) for k in keys):
        raise InputError(
            f"flow_map: keys = {keys!r}; allowed a list of parameter names, "
            "e.g. ['track.clearance']"
        )
    return tuple(keys)


def _contact_state(
    modes: Sequence[int], v0s: Sequence[float]
) -> tuple[tuple[int, int], np.ndarray]:
    """The contact modes and latched speeds a flow map starts from, checked: each mode -1,
    0 or +1, and a speed > 0 for a pair in contact."""
    try:
        modes_t = (int(modes[0]), int(modes[1]))
        if len(modes) != 2:
            raise ValueError
    except (TypeError, ValueError, IndexError):
        raise InputError(
            f"flow_map: modes = {modes!r}; allowed two contact modes (track, slot), each -1, "
            "0 or +1"
        ) from None
    try:
        v0a = np.array(v0s, dtype=float).reshape(2)
    except (TypeError, ValueError):
        raise InputError(
            f"flow_map: v0s = {v0s!r}; allowed two latched speeds in m/s (NaN for a free pair)"
        ) from None
    for p in range(2):
        if modes_t[p] not in (-1, 0, 1):
            raise InputError(f"flow_map: modes[{p}] = {modes_t[p]}; allowed -1, 0, +1")
        if modes_t[p] != 0 and not (v0a[p] > 0):
            raise InputError(f"flow_map: v0s[{p}] must be > 0 m/s for a pair in contact")
    return modes_t, v0a


def flow_map(
    scenario: Scenario | str | Mapping[str, Any],
    t0: float,
    t1: float,
    y0: Sequence[float] | np.ndarray | None = None,
    modes: tuple[int, int] = (0, 0),
    v0s: Sequence[float] = (math.nan, math.nan),
    keys: Sequence[str] = (),
    overrides: Mapping[str, Any] | None = None,
    *,
    check_start: bool = True,
    control_tangents: bool = True,
) -> FlowMap:
    """Integrate from t0 (state ``y0``, contacts ``modes`` with latched speeds ``v0s``) to
    t1 with the Jacobians of the result with respect to the state, the latched speeds and
    the scenario ``keys`` (see :class:`FlowMap`).

    The Jacobians are held to the run's relative tolerance by their own error estimate
    (``control_tangents``, default True). With False they are integrated over the steps
    the state's error control chooses, their error not estimated: enough for a Newton
    iteration's Jacobian, not for the multipliers of a converged orbit (up to 4e-3 off on
    paper-3.3's bouncing orbit, at any tolerance: the tangents' field is not smooth at the
    contact's onset and exit), and cheaper (a period of the resting orbit at 6 pi rad/s,
    h_a = 0.1 mm, at the continuation's tolerances: 42 ms against 100 ms).

    ``y0`` is (x, vx) or (x, vx, y, vy) in the solver's ground frame (default: the
    scenario's initial state). The run from t0 starts with a fresh step-size controller, so
    that the map depends on (t0, y0, contacts) only. A pair declared in contact must start
    on that wall (:data:`CONTACT_START_SLACK`), unless ``check_start`` is False (a Newton
    iterate of a continuation, whose cuts keep their contacts while the state moves: a
    contact then ends at once, and the continuation reports the changed contacts).
    """
    from braidsim.core import run as core_run
    from braidsim.core.driver import state_size
    from braidsim.model import build_model
    from braidsim.params import Scenario as _Sc
    from braidsim.params import load_scenario
    from braidsim.simulate import failure_message, stats_dict

    sc = scenario if isinstance(scenario, _Sc) else load_scenario(scenario)
    if overrides:
        sc = sc.with_overrides(overrides)
    t0 = float(t0)
    t1 = float(t1)
    if not (math.isfinite(t0) and math.isfinite(t1) and t1 > t0 >= 0.0):
        raise InputError(
            f"flow_map: [t0, t1] = [{t0}, {t1}] is not a time interval; allowed 0 <= t0 < t1"
        )
    model = build_model(sc, t1 - t0, t_start=t0, keep_zero_harmonics=True)
    check_differentiable(model.record)
    n = 4 if model.two_dof else 2
    y = model.y0.copy()
    if y0 is not None:
        y[:n] = _initial_state(y0, n)
        y[n:] = 0.0
    modes_t, v0a = _contact_state(modes, v0s)
    # directions: the n state components, the 2 latched speeds, the keys
    keys = _checked_keys(keys)
    fixed = [key for key in keys if key.startswith("initial.")] if y0 is not None else []
    if fixed:
        # (the given y0 replaces the scenario's initial state: its column would be 0)
        raise InputError(
            f"flow_map: {fixed[0]} with y0: the map starts from the given y0, not the "
            "scenario's initial state; its derivatives along y0 are the map's state columns"
        )
    dirs = directions(model, keys) if keys else None
    zero = zero_tangent(model.record)
    k = n + 2 + len(keys)
    records = [zero] * (n + 2) + (dirs.records if dirs else [])
    S0 = np.zeros((k, n))
    S0[:n, :n] = np.eye(n)
    DV0 = np.zeros((k, 2))
    DV0[n, 0] = 1.0 if modes_t[0] != 0 else 0.0
    DV0[n + 1, 1] = 1.0 if modes_t[1] != 0 else 0.0
    ntr = model.transfer_times.size
    DTR = np.zeros((k, ntr))
    scale = np.ones(k)
    scale[n] = v0a[0] if modes_t[0] != 0 else 1.0
    scale[n + 1] = v0a[1] if modes_t[1] != 0 else 1.0
    if dirs is not None:
        # the keys' own tangents of the initial state are not wanted: y0 is given
        DTR[n + 2 :] = dirs.DTR
        scale[n + 2 :] = dirs.scale
        if y0 is None:
            S0[n + 2 :] = dirs.S0
    # no series tangents: the map samples the state 400 times for the gaps, and their
    # tangents were a third of a bouncing orbit's map (2.2 against 1.5 ms); the solver
    # without them is compiled for this alone (as long as the one it shared with
    # simulate(..., sensitivities=...), 22 s from an empty cache)
    # (the dissipations' tangents are not needed either, and would hold the step at a clamp)
    tangents = Tangents(
        records,
        S0,
        DV0,
        DTR,
        scale,
        series=False,
        dissipations=False,
        controlled=bool(control_tangents),
    )
    restart = L.new_restart()
    r = restart[0]
    r["t"] = t0
    r["started"] = L.CONTINUED if any(modes_t) else L.NEW_RUN
    r["mode_0"], r["mode_1"] = modes_t
    r["v0_0"] = v0a[0] if modes_t[0] else 1.0
    r["v0_1"] = v0a[1] if modes_t[1] else 1.0
    if any(modes_t):
        r["h"] = min(1e-6, model.options.max_step)
    opts = model.options._replace(t_end=t1, record_events=True)
    W = np.array([[t0, t1]])
    raw = core_run(
        model.record,
        opts,
        y[: state_size(model.record, True)],
        sample_times=np.linspace(t0, t1, GAP_SAMPLES + 1),
        transfer_times=model.transfer_times,
        windows=W,
        series=True,
        xsq=False,
        restart=restart,
        tangents=tangents,
    )
    if check_start:
        assert raw.series is not None  # (series=True)
        _check_declared_contacts(raw.series[0], model, modes_t)
    if raw.status == L.ST_GRAZING:
        raise sensitivity_error(raw.t, t0)
    if raw.status != L.ST_OK:
        raise SimulationError(failure_message(raw.status, raw.t, model, stats_dict(raw)), raw.t)
    return _flow_map_of_run(t0, t1, y[:n], modes_t, v0a, raw, n, keys, _min_gaps(raw, model))


#: how far off its wall [fraction of the pair's clearance] a state declared in contact may
#: start: a located onset lies up to ~1e-12 m off the wall, a free state ~1e-4 of it and more
CONTACT_START_SLACK = 1e-6


def _check_declared_contacts(first: np.ndarray, model: Model, modes: tuple[int, int]) -> None:
    """Refuse a contact mode declared for a pair whose start is off that wall (``first``:
    the run's first sample, the state at t0 with the walls' positions). The solver took
    such a contact for one that ends at once, with no force: the map was that of a free
    start, with a latched speed it never used (or a grazing exit)."""
    from braidsim.core import CARRIER_COLUMNS

    col = {c: i for i, c in enumerate(CARRIER_COLUMNS)}
    rec = model.record
    pairs = (
        ("x", "track_position", rec.track_clearance, ("inner track wall", "outer track wall")),
        ("y", "slot_position", rec.slot_clearance, ("rear slot wall", "front slot wall")),
    )
    for p, mode in enumerate(modes):
        if mode == 0:
            continue
        coord, wall, eps, names = pairs[p]
        u = first[col[coord]] - first[col[wall]]
        depth = -u if mode < 0 else u - eps
        if depth < -CONTACT_START_SLACK * eps:
            raise InputError(
                f"flow_map: modes[{p}] = {mode:+d} declares a contact with the "
                f"{names[mode > 0]}, but y0 is {-depth * 1e3:.4g} mm off it at t0 = "
                f"{first[0]:.9g} s; allowed a start on that wall (overlap >= 0) or mode 0"
            )


def _min_gaps(raw: Any, model: Model) -> np.ndarray:
    """Smallest gap [m] to the (inner, outer) wall of each pair over the run: minus the
    largest depth where the pair touched that wall, else the smallest gap of the sampled
    series (samples and exact event states), refined by a parabola through the smallest
    sample and its neighbours. NaN for a pair the model does not have."""
    from braidsim.core import CARRIER_COLUMNS

    out = np.full((2, 2), math.nan)
    R = raw.ranges[0]  # (pair, quantity, min/max); quantity 0 is the signed depth
    col = {c: i for i, c in enumerate(CARRIER_COLUMNS)}
    ser = raw.series
    rec = model.record
    for pair in range(2 if model.two_dof else 1):
        if pair == 0:
            u = ser[:, col["x"]] - ser[:, col["track_position"]]
            eps = rec.track_clearance
        else:
            u = ser[:, col["y"]] - ser[:, col["slot_position"]]
            eps = rec.slot_clearance
        t = ser[:, 0]
        for side, gap in ((0, u), (1, eps - u)):
            depth = -R[pair, 0, 0] if side == 0 else R[pair, 0, 1]
            if np.isfinite(depth) and depth > 0.0:
                out[pair, side] = -depth
                continue
            out[pair, side] = _parabolic_min(t, gap)
    return out


def _parabolic_min(t: np.ndarray, g: np.ndarray) -> float:
    """The minimum of samples g(t), refined by the parabola through the smallest sample
    and its two neighbours when it is interior."""
    if g.size == 0:
        return math.nan
    i = int(np.argmin(g))
    if 0 < i < g.size - 1:
        t0, t1, t2 = t[i - 1], t[i], t[i + 1]
        g0, g1, g2 = g[i - 1], g[i], g[i + 1]
        denom = (t0 - t1) * (t0 - t2) * (t1 - t2)
        if denom != 0.0 and t0 < t1 < t2:
            a = (t2 * (g1 - g0) + t1 * (g0 - g2) + t0 * (g2 - g1)) / denom
            b = (t2 * t2 * (g0 - g1) + t1 * t1 * (g2 - g0) + t0 * t0 * (g1 - g2)) / denom
            if a > 0.0:
                tv = -b / (2 * a)
                if t0 <= tv <= t2:
                    c = g1 - a * t1 * t1 - b * t1
                    return float(min(g1, a * tv * tv + b * tv + c))
    return float(g[i])


def forcing_period(scenario: Scenario) -> float:
    """The period of the track vibration 2 pi / omega_h [s] (``track.vibration_frequency``
    is held in rad/s)."""
    w = float(scenario["track.vibration_frequency"])
    if not (math.isfinite(w) and w > 0):
        raise InputError(
            f"track.vibration_frequency: {w!r} rad/s has no period; allowed > 0 for a "
            "stroboscopic map"
        )
    return 2.0 * math.pi / w


def stroboscopic_map(
    scenario: Scenario | str | Mapping[str, Any],
    t0: float,
    y0: Sequence[float] | np.ndarray | None = None,
    modes: tuple[int, int] = (0, 0),
    v0s: Sequence[float] = (math.nan, math.nan),
    periods: int = 1,
    keys: Sequence[str] = (),
    overrides: Mapping[str, Any] | None = None,
) -> FlowMap:
    """:func:`flow_map` over ``periods`` periods of the track vibration from t0: the map
    whose fixed points are the orbits of that period, and whose ``monodromy()`` gives their
    Floquet multipliers."""
    from braidsim.params import Scenario as _Sc
    from braidsim.params import load_scenario

    sc = scenario if isinstance(scenario, _Sc) else load_scenario(scenario)
    if overrides:
        sc = sc.with_overrides(overrides)
    if not (isinstance(periods, (int, np.integer)) and periods >= 1):
        raise InputError(f"periods: {periods!r}; allowed an integer >= 1")
    T = forcing_period(sc)
    return flow_map(sc, t0, t0 + int(periods) * T, y0=y0, modes=modes, v0s=v0s, keys=keys)


def _with_field(record: Any, path: str, value: float) -> Any:
    """``record`` with the (dotted) field ``path`` replaced by ``value``."""
    head, _, rest = path.partition(".")
    if not rest:
        return record._replace(**{head: value})
    return record._replace(**{head: _with_field(getattr(record, head), rest, value)})


def _field(record: Any, path: str) -> float:
    obj = record
    for part in path.split("."):
        obj = getattr(obj, part)
    return float(obj)


def record_flow_map(
    record: Any,
    options: L.SolverOptions,
    t0: float,
    t1: float,
    y0: Sequence[float] | np.ndarray,
    modes: tuple[int, int] = (0, 0),
    v0s: Sequence[float] = (math.nan, math.nan),
    keys: Sequence[str] = (),
    *,
    control_tangents: bool = True,
) -> FlowMap:
    """:func:`flow_map` for a model record of the compiled core itself (for example
    :class:`braidsim.core.ImpactOscillator` with a
    :class:`braidsim.core.KelvinVoigtContact` law) instead of a scenario: the same
    Jacobians, by the same variational equations, with respect to the state (x, vx[, y,
    vy]), the latched speeds and the record's numeric fields ``keys`` (dotted for a nested
    record: ``"force_frequency"``, ``"law.stiffness"``). The tangent record of a field is
    the record's zero tangent with that field 1 (the record enters the equations as it is).
    No transfers; ``min_gaps`` is NaN (the gaps of a scenario's carrier only); the run
    from t0 continues with a first step of min(1e-7 s, max_step). ``control_tangents`` as
    in :func:`flow_map`.
    """
    from braidsim.core import run as core_run
    from braidsim.core.driver import state_size

    t0, t1 = float(t0), float(t1)
    if not (math.isfinite(t0) and math.isfinite(t1) and t1 > t0):
        raise InputError(f"flow_map: [t0, t1] = [{t0}, {t1}] is not a time interval")
    check_differentiable(record)
    keys = _checked_keys(keys)
    n = state_size(record, False)
    ya = _initial_state(y0, n)
    modes_t, v0a = _contact_state(modes, v0s)
    zero = zero_tangent(record)
    records = [zero] * (n + 2)
    scale = np.ones(n + 2 + len(keys))
    scale[n] = v0a[0] if modes_t[0] != 0 else 1.0
    scale[n + 1] = v0a[1] if modes_t[1] != 0 else 1.0
    for i, key in enumerate(keys):
        try:
            value = _field(record, key)
            records.append(_with_field(zero, key, 1.0))
        except (AttributeError, TypeError, ValueError):
            raise InputError(
                f"flow_map: {key!r} is not a numeric field of {type(record).__name__}"
            ) from None
        scale[n + 2 + i] = abs(value) if value != 0.0 and math.isfinite(value) else 1.0
    k = n + 2 + len(keys)
    S0 = np.zeros((k, n))
    S0[:n, :n] = np.eye(n)
    DV0 = np.zeros((k, 2))
    DV0[n, 0] = 1.0 if modes_t[0] != 0 else 0.0
    DV0[n + 1, 1] = 1.0 if modes_t[1] != 0 else 0.0
    tangents = Tangents(
        records,
        S0,
        DV0,
        np.zeros((k, 0)),
        scale,
        series=False,
        dissipations=False,
        controlled=bool(control_tangents),
    )
    restart = L.new_restart()
    r = restart[0]
    r["t"] = t0
    r["started"] = L.CONTINUED
    r["h"] = min(1e-7, options.max_step, t1 - t0)
    r["mode_0"], r["mode_1"] = modes_t
    r["v0_0"] = v0a[0] if modes_t[0] else 1.0
    r["v0_1"] = v0a[1] if modes_t[1] else 1.0
    opts = options._replace(t_end=t1, record_events=True, energy=False)
    raw = core_run(
        record, opts, ya.copy(), series=False, xsq=False, restart=restart, tangents=tangents
    )
    if raw.status == L.ST_GRAZING:
        raise sensitivity_error(raw.t)
    if raw.status != L.ST_OK:
        raise SimulationError(
            f"the integrator stopped with status {raw.status} at t = {raw.t:.9g} s (a flow "
            f"map of {type(record).__name__} from t = {t0:.9g} s)",
            raw.t,
        )
    return _flow_map_of_run(t0, t1, ya, modes_t, v0a, raw, n, keys, np.full((2, 2), math.nan))


def _flow_map_of_run(
    t0: float,
    t1: float,
    y0: np.ndarray,
    modes_t: tuple[int, int],
    v0a: np.ndarray,
    raw: RawRun,
    n: int,
    keys: Sequence[str],
    min_gaps: np.ndarray,
) -> FlowMap:
    """The :class:`FlowMap` of a run that carried the tangents of (state, latched speeds,
    keys) from t0 (state ``y0``, contact modes ``modes_t``, latched speeds ``v0a``) to t1;
    the latched speed of a contact closed at t1 has no derivative."""
    sens = raw.sensitivity
    assert sens is not None
    rs = raw.restart[0]
    modes1 = (int(rs["mode_0"]), int(rs["mode_1"]))
    v0s1 = np.array([rs["v0_0"] if modes1[0] else math.nan, rs["v0_1"] if modes1[1] else math.nan])
    S = sens.S  # (k, n)
    D = sens.DV0.copy()  # (k, 2)
    for p in range(2):
        if modes1[p] == 0:
            D[:, p] = 0.0
    return FlowMap(
        t0=t0,
        t1=t1,
        y0=np.array(y0, dtype=float),
        modes0=modes_t,
        v0s0=np.where(np.array(modes_t) != 0, v0a, math.nan),
        y1=raw.y[:n].copy(),
        modes1=modes1,
        v0s1=v0s1,
        jac_y=S[:n].T.copy(),
        jac_v0=S[n : n + 2].T.copy(),
        dv0_dy=D[:n].T.copy(),
        dv0_dv0=D[n : n + 2].T.copy(),
        keys=tuple(keys),
        jac_p=S[n + 2 :].T.copy(),
        dv0_dp=D[n + 2 :].T.copy(),
        episodes=raw.episodes,
        impact_sens=sens.impacts,
        min_gaps=min_gaps,
    )
