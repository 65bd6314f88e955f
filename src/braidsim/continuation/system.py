"""What continuation integrates: a time-periodic model and the parameter it varies.

A periodic orbit of a forced system is a fixed point of its stroboscopic map; the map is
only defined when the equations repeat with the forcing period T = 2 pi / Omega. Two kinds
of system are accepted:

* :class:`ScenarioSystem`, the braiding-machine carrier of a scenario. Its forcing is the
  track vibration h(t) = h_a cos(omega_h t + phase), T = 2 pi / omega_h. Everything else that
  depends on time must repeat with T: extra track harmonics and horn-gear speed harmonics at
  integer multiples of omega_h, no tabulated speed profile, and transfers to the next horn
  gear either absent (``transfer.period = 0``, no ``transfer.times``) or periodic with a
  whole number m of vibration periods (``transfer.period = m T``); the orbit's period k then
  has to be a multiple of m (a transfer every m cycles repeats only over such orbits).
* :class:`ModelSystem`, any record of the compiled core with a harmonic forcing (for
  example :class:`braidsim.core.ImpactOscillator` with a
  :class:`braidsim.core.KelvinVoigtContact` law), its parameters named by field
  (``"force_amplitude"``, ``"law.stiffness"``).

Both give the same things to the orbit solver: the model record and solver options at a
parameter value, the forcing period, the transfer times in a span, and the length scales
that make the state dimensionless.

The carrier's tangential coordinate. The xy carrier's y is integrated in the ground frame,
where it does not repeat: the horn-gear slot carries it along by s(t) = r_c int_0^t omega,
r_c omega_mean T further each period. Its equations depend on y only through y - s(t)
(the slot's walls move with s; the track's friction sees y'), so its orbits repeat in the
slot's frame. Continuation's states therefore hold y - s(t) where the integrator holds y:
:meth:`Prepared.to_ground` and :meth:`Prepared.to_slot` convert at the integrator's
boundary (``fdmap.advance`` and ``orbit.evaluate_map``), and every state an orbit holds, a
cut, a branch or a report shows is the position in the slot (x, x' and y' are the
integrator's own, y' the ground frame's speed; a run's sampled series stay in the ground
frame).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from braidsim.core import state_size
from braidsim.core.layout import SolverOptions
from braidsim.errors import InputError
from braidsim.params import SCHEMA, Scenario

NOT_CONTINUABLE_PREFIXES = ("initial.", "simulation.", "transfer.times", "transfer.first")
"""Scenario keys that are not parameters of the periodic map: the initial state (an orbit
does not depend on it), the solver's settings and the transfer schedule."""

NOT_CONTINUABLE_KEYS = ("contact.initial_impact_velocity", "transfer.period")
CONTINUABLE_EXAMPLES = (
    "track.vibration_amplitude",
    "track.vibration_frequency",
    "horn_gear.angular_velocity",
    "track.clearance",
    "contact.track.restitution",
    "carrier.mass",
    "yarn.tension_horizontal",
    "contact.track.stiffness",
)

DEFAULT_RTOL = 1e-10
"""Relative tolerance of the integrator in continuation runs (tighter than a plain run's
1e-8: Newton's residual and the finite-difference monodromy can be no better than it). A
scenario's absolute tolerances follow it: at most rtol times the state scales (see
:meth:`ScenarioSystem.scenario_at`; a :class:`ModelSystem` has its own)."""


@dataclass(frozen=True)
class Prepared:
    """A system at one parameter value, ready to integrate.

    Attributes
    ----------
    record : NamedTuple
        The compiled core's model record.
    options : SolverOptions
        Solver options (``t_end`` is set per run).
    omega : float
        Forcing angular frequency [rad/s]; the forcing period is 2 pi / omega.
    n_coords : int
        Coordinates (1: x; 2: x and y); the map's state has 2 n_coords entries.
    transfer_period : float
        Period of the transfers [s] (0: none), and ``transfer_first`` [s] the first one.
    implicit : bool
        Integrate resting contacts with the implicit step (``simulation.resting_contacts``;
        the finite-difference flow maps only: the exact ones carry tangents).
    """

    record: Any
    options: SolverOptions
    omega: float
    n_coords: int
    transfer_period: float = 0.0
    transfer_first: float = 0.0
    implicit: bool = False

    @property
    def period(self) -> float:
        """Forcing period T = 2 pi / omega [s]."""
        return 2.0 * math.pi / self.omega

    @property
    def has_slot(self) -> bool:
        """Whether the model's y is carried by a horn-gear slot (the xy carrier; module
        docstring)."""
        return self.n_coords >= 2 and getattr(self.record, "horn_gear", None) is not None

    def slot_travel(self, t: float) -> tuple[float, float]:
        """(s(t) [m], s'(t) [m/s]): how far the horn-gear slot has carried the carrier's y
        since t = 0, s = r_c int_0^t omega, and its speed r_c omega(t); (0, 0) for a model
        without a slot (:attr:`has_slot`)."""
        if not self.has_slot:
            return 0.0, 0.0
        from braidsim.core.physics.excitation import horn_gear_state

        hg = self.record.horn_gear
        om, s = horn_gear_state(hg, float(t))
        return float(s), float(hg.turning_radius) * float(om)

    def to_ground(self, t: float, z: np.ndarray) -> np.ndarray:
        """The state (x, vx[, y, vy, ...]) at t with y in the ground frame, from y - s(t)
        (a copy; the same values where there is no slot)."""
        return self._slot_shifted(t, z, 1.0)

    def to_slot(self, t: float, y: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`to_ground`: y - s(t) from the ground frame's y (a copy)."""
        return self._slot_shifted(t, y, -1.0)

    def _slot_shifted(self, t: float, z: np.ndarray, sign: float) -> np.ndarray:
        z = np.array(z, dtype=float)
        if self.has_slot:
            z[2] += sign * self.slot_travel(t)[0]
        return z

    def transfers(self, t0: float, t1: float) -> np.ndarray:
        """Transfer times in the open span (t0, t1) [s]."""
        if self.transfer_period <= 0.0:
            return np.zeros(0)
        k0 = math.ceil((t0 - self.transfer_first) / self.transfer_period - 1e-9)
        out = []
        k = max(k0, 0)
        while True:
            t = self.transfer_first + k * self.transfer_period
            if t >= t1:
                break
            if t > t0:
                out.append(t)
            k += 1
        return np.array(out, dtype=float)


def check_continuable(key: str, where: str = "continuation.parameter") -> None:
    """:class:`InputError` unless ``key`` is a scalar scenario key continuation can vary
    (``where``: the spec entry that names it, for the message)."""
    allowed = "a scalar parameter such as " + ", ".join(CONTINUABLE_EXAMPLES)
    if key not in SCHEMA:
        import difflib

        close = difflib.get_close_matches(key, list(SCHEMA), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise InputError(f"{where}: unknown key {key!r}{hint}; allowed {allowed}")
    if SCHEMA[key].kind != "float":
        raise InputError(
            f"{where}: {key!r} is not a number and cannot be continued; allowed {allowed}"
        )
    if key in NOT_CONTINUABLE_KEYS or key.startswith(NOT_CONTINUABLE_PREFIXES):
        raise InputError(
            f"{where}: {key!r} is not a parameter of the periodic orbit "
            f"(initial state, solver setting or transfer schedule); allowed {allowed}"
        )


# how many parameter points a system remembers (the model at each, and its scales): a
# finite-difference Jacobian in both parameters of a two-parameter curve visits a few
# dozen points per corrector iteration, and a branch returns to its last points
CACHE_POINTS = 256


def _values_key(values: Mapping[str, float]) -> tuple[tuple[str, float], ...]:
    return tuple(sorted((k, float(v)) for k, v in values.items()))


def _remember(cache: dict[Any, Any], key: Any, value: Any) -> None:
    """Store ``value``, dropping the oldest entry past :data:`CACHE_POINTS`."""
    if len(cache) >= CACHE_POINTS:
        del cache[next(iter(cache))]
    cache[key] = value


@dataclass(frozen=True)
class ScenarioSystem:
    """The carrier of a scenario as a time-periodic system (module docstring).

    Attributes
    ----------
    scenario : Scenario
        The base scenario (SI).
    rtol : float
        Integrator tolerance of continuation runs (``simulation.rtol`` is replaced by it
        unless the scenario sets a tighter one; the absolute tolerances by rtol times the
        state scales, likewise).
    resting_speed : float, optional
        Latched approach speed [m/s] of a contact open over the whole orbit (default
        ``contact.min_impact_velocity``; see
        :func:`braidsim.continuation.orbit.resting_speed`).
    """

    scenario: Scenario
    rtol: float = DEFAULT_RTOL
    resting_speed: float | None = None
    _cache: dict[Any, Prepared] = field(default_factory=dict, repr=False, compare=False)
    _scales: dict[Any, tuple[float, float]] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        if not isinstance(self.scenario, Scenario):
            raise InputError(
                f"scenario: {self.scenario!r} is not a Scenario; allowed a loaded scenario "
                "(braidsim.load_scenario(name or path))"
            )

    @property
    def name(self) -> str:
        """The scenario's name."""
        return self.scenario.name

    def check_key(self, key: str) -> None:
        """:class:`InputError` unless ``key`` can be continued."""
        check_continuable(key)

    def value(self, key: str) -> float:
        """The base value of ``key`` [SI]."""
        v = self.scenario[key]
        if v is None:
            raise InputError(f"{key}: has no value in the scenario; set it in [overrides]")
        return float(v)

    def scenario_at(self, values: Mapping[str, float]) -> Scenario:
        """The scenario with ``values`` applied (SI), integrated at the continuation's
        tolerances: ``simulation.rtol`` at most ``rtol``, ``simulation.atol_position`` and
        ``simulation.atol_velocity`` at most ``rtol`` times the state scales L and L
        omega_h (:meth:`scales`).

        (The plain run's absolute tolerances, 1e-13 m and 1e-9 m/s, are 1e-9 and 2.7e-8
        of those scales at h_a = 0.1 mm: above Newton's tolerance on the scaled residual,
        1e-8. Left as they were, they and not rtol bounded the maps' error: a period's map
        of paper-3.3 started inside its contact ended 4.8e-7 m/s, 1e-5 of the speed, off
        its converged value at any rtol, and the resting orbit's lift-off at h_a = 0.1 mm
        came out 1.9e-8 off with central differences; with these the exact map and
        central differences both give 12.70652944 rad/s, within 3e-11.)"""
        over = {k: float(v) for k, v in values.items()}
        sc = self.scenario.with_overrides(over) if over else self.scenario
        rt = min(float(sc["simulation.rtol"]), self.rtol)
        tols: dict[str, float] = {"simulation.rtol": rt}
        for key, scale in zip(("atol_position", "atol_velocity"), _state_scales(sc), strict=True):
            atol = float(sc[f"simulation.{key}"])
            if 0.0 < rt * scale < atol:  # (a scale of 0: no forcing, refused by prepare)
                tols[f"simulation.{key}"] = rt * scale
        return sc.with_overrides(tols)

    def prepare(self, values: Mapping[str, float]) -> Prepared:
        """The model record and options at ``values``; checks the time-periodicity."""
        ck = _values_key(values)
        if ck in self._cache:
            return self._cache[ck]
        from braidsim.model import build_model

        sc = self.scenario_at(values)
        w = float(sc["track.vibration_frequency"])
        if not w > 0.0:
            raise InputError(
                "track.vibration_frequency: 0 rad/s leaves no forcing period; allowed > 0 "
                "(continuation follows orbits periodic with the track vibration)"
            )
        for key in ("track.harmonics", "horn_gear.speed_harmonics"):
            for a, f, _ in sc[key]:
                ratio = f / w
                if a != 0.0 and f != 0.0 and abs(ratio - round(ratio)) > 1e-9:
                    raise InputError(
                        f"{key}: frequency {f:g} rad/s is not a whole multiple of "
                        f"track.vibration_frequency ({w:g} rad/s); allowed multiples only "
                        "(the equations must repeat with the vibration period)"
                    )
        if sc["horn_gear.speed_profile"] is not None:
            raise InputError(
                "horn_gear.speed_profile: a tabulated speed profile is not periodic with the "
                "track vibration; allowed none (use horn_gear.speed_harmonics)"
            )
        if sc["transfer.times"]:
            raise InputError(
                "transfer.times: single transfers break the time-periodicity; allowed none "
                "(use transfer.period, a whole number of vibration periods)"
            )
        tp = float(sc["transfer.period"])
        T = 2.0 * math.pi / w
        if tp > 0.0 and abs(tp / T - round(tp / T)) > 1e-9:
            raise InputError(
                f"transfer.period: {tp:g} s is not a whole number of vibration periods "
                f"({T:g} s); allowed 0 or a multiple of 2 pi / track.vibration_frequency"
            )
        model = build_model(sc, 1.0)
        n_coords = 2 if sc["simulation.dof"] == "xy" else 1
        prep = Prepared(
            model.record,
            model.options,
            w,
            n_coords,
            tp,
            float(sc["transfer.first"]),
            model.implicit_rest,
        )
        _remember(self._cache, ck, prep)
        return prep

    def scales(self, values: Mapping[str, float]) -> tuple[float, float]:
        """(length [m], speed [m/s]) that make the state dimensionless: L = the larger of
        h_a and eps_g / 1000, and L omega_h."""
        ck = _values_key(values)
        if ck in self._scales:
            return self._scales[ck]
        out = _state_scales(self.scenario_at(values))
        _remember(self._scales, ck, out)
        return out

    def initial_state(self, values: Mapping[str, float]) -> tuple[np.ndarray, float]:
        """The scenario's own initial state (x, vx[, y, vy]) and start time 0."""
        from braidsim.model import build_model

        model = build_model(self.scenario_at(values), 1.0)
        n = state_size(model.record, False)
        return np.array(model.y0[:n], dtype=float), 0.0


def _state_scales(sc: Scenario) -> tuple[float, float]:
    """(L, L omega_h) of :meth:`ScenarioSystem.scales` for a scenario."""
    L = max(float(sc["track.vibration_amplitude"]), 1e-3 * float(sc["track.clearance"]))
    return L, L * float(sc["track.vibration_frequency"])


def _get_field(record: Any, path: str) -> float:
    obj = record
    for part in path.split("."):
        obj = getattr(obj, part)
    return float(obj)


def _set_field(record: Any, path: str, value: float) -> Any:
    head, _, rest = path.partition(".")
    if not rest:
        return record._replace(**{head: value})
    return record._replace(**{head: _set_field(getattr(record, head), rest, value)})


@dataclass(frozen=True)
class ModelSystem:
    """A record of the compiled core with a harmonic forcing, as a time-periodic system.

    Parameters are the record's numeric fields, dotted for a nested record
    (``"force_amplitude"``, ``"law.stiffness"``).

    Attributes
    ----------
    record : NamedTuple
        E.g. :class:`braidsim.core.ImpactOscillator`.
    frequency_field : str
        The field holding the forcing angular frequency [rad/s].
    length_scale : float
        Typical size of the coordinate [m] (makes the state dimensionless).
    rtol, atol_position, atol_velocity, max_step : float
        Solver options (max_step: default 1/64 of the forcing period).
    initial : tuple of float
        Initial state (x, vx) of a seeding run.
    """

    record: Any
    frequency_field: str = "force_frequency"
    length_scale: float = 1.0
    rtol: float = DEFAULT_RTOL
    atol_position: float = 1e-14
    atol_velocity: float = 1e-12
    max_step: float | None = None
    initial: tuple[float, ...] = (0.0, 0.0)
    name: str = "model"

    def check_key(self, key: str) -> None:
        """:class:`InputError` unless ``key`` names a numeric field of the record."""
        try:
            _get_field(self.record, key)
        except (AttributeError, TypeError, ValueError):
            fields = [f for f in self.record._fields if isinstance(getattr(self.record, f), float)]
            raise InputError(
                f"continuation.parameter: {key!r} is not a numeric field of "
                f"{type(self.record).__name__}; allowed {', '.join(fields)}"
            ) from None

    def value(self, key: str) -> float:
        """The base value of the field ``key``."""
        self.check_key(key)
        return _get_field(self.record, key)

    def prepare(self, values: Mapping[str, float]) -> Prepared:
        """The record with ``values`` applied and the solver options."""
        rec = self.record
        for k, v in values.items():
            rec = _set_field(rec, k, float(v))
        w = _get_field(rec, self.frequency_field)
        if not w > 0.0:
            raise InputError(f"{self.frequency_field}: {w:g} rad/s; allowed > 0")
        T = 2.0 * math.pi / w
        opts = SolverOptions(
            rtol=self.rtol,
            atol_position=self.atol_position,
            atol_velocity=self.atol_velocity,
            max_step=T / 64.0 if self.max_step is None else self.max_step,
            max_steps=10_000_000,
            t_end=1.0,
        )
        n_coords = state_size(rec, False) // 2
        return Prepared(rec, opts, w, n_coords)

    def scales(self, values: Mapping[str, float]) -> tuple[float, float]:
        """(length, length x omega)."""
        w = self.prepare(values).omega
        return self.length_scale, self.length_scale * w

    def initial_state(self, values: Mapping[str, float]) -> tuple[np.ndarray, float]:
        """``initial`` and start time 0."""
        return np.array(self.initial, dtype=float), 0.0


System = ScenarioSystem | ModelSystem
