"""A flow map and its Jacobians by central finite differences.

This is the finite-difference counterpart of :func:`braidsim.sensitivity.flow_map`: the same
fields (:class:`FlowMap`), each derivative a central difference of two runs of the compiled
core started from a perturbed state,

    d y1 / d q  ~  (y1(q + d) - y1(q - d)) / (2 d),

with d a fixed fraction (``rel``, default 1e-5) of the quantity's scale: the length and speed
scales of the system for the state, |v0| for a latched approach speed, max(|p|, scale) for a
parameter. The truncation error is O(d^2); the integrator's own error (relative tolerance
rtol, 1e-10 in continuation runs) adds about rtol / rel. Each Jacobian column costs two runs
over [t0, t1].

It serves as the reference ("finite-difference monodromy") that the exact variational map is
checked against, and as the map where the exact one is not available (models other than the
carrier of a scenario).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from braidsim.core import gaps_along
from braidsim.core import layout as L
from braidsim.core import run as core_run
from braidsim.errors import SimulationError

FloatSeq = Sequence[float] | np.ndarray
"""A vector given as a sequence or an array."""

DEFAULT_REL_STEP = 1e-5
STRUCTURE_RETRIES = 1
"""Times the finite-difference step is cut by 10 where the perturbed runs do not make the
base run's contacts (:func:`contact_structure`), before the first step's difference is
taken as it is (once was enough for the clearance example's cross branch; the shipped paper
study then takes 9.3 s of CPU against 8.5 s without the check)."""
IMPACT_QUANTITIES = L.IMPACT_SENS_FIELDS  # (the columns of the exact maps' impact tangents)


@dataclass(frozen=True)
class Segment:
    """One run of the compiled core from (t0, y0, modes, v0s) to t1.

    Attributes
    ----------
    y1 : np.ndarray
        State at t1.
    modes1 : tuple of int
        Contact modes at t1 (-1 inner, +1 outer, 0 free).
    v0s1 : np.ndarray
        (2,) latched approach speeds at t1 [m/s] (NaN for a free pair).
    episodes : np.ndarray
        Contact episodes (``EPISODE_DTYPE``) in [t0, t1].
    series : np.ndarray or None
        Series rows (the model's columns) when samples were asked for.
    """

    y1: np.ndarray
    modes1: tuple[int, int]
    v0s1: np.ndarray
    episodes: np.ndarray
    series: np.ndarray | None


def _failure(status: int, t: float, t0: float, budget: int) -> str:
    """What stopped a run of the periodic map, when, and what to change."""
    where = f"at t = {t:.9g} s (a run of the periodic map from t = {t0:.9g} s)"
    if status == L.ST_MAX_STEPS:
        return (
            f"the map's step budget of {budget} steps was spent {where}; allowed a shorter "
            "map: a smaller continuation.period (forcing periods per orbit)"
        )
    why = {
        L.ST_STEP_COLLAPSE: "the step size collapsed to the rounding of t",
        L.ST_NONFINITE: "the state became NaN or infinite",
        L.ST_ZENO: "more than 50 contact events came at one instant (a grazing contact)",
        L.ST_STIFF: "the equations became stiff",
    }.get(status, f"the integrator stopped (status {status})")
    return f"{why} {where}; allowed a parameter range away from this value"


def advance(
    prep: Any,
    t0: float,
    t1: float,
    y0: FloatSeq,
    modes: Sequence[int] = (0, 0),
    v0s: FloatSeq = (math.nan, math.nan),
    sample_times: np.ndarray | None = None,
) -> Segment:
    """Integrate a prepared system (:class:`~braidsim.continuation.system.Prepared`) from t0
    to t1, its contacts and latched speeds given. Raises :class:`SimulationError`.

    ``y0`` and the result's ``y1`` hold the xy carrier's y in the slot's frame, y - s(t)
    (:meth:`~braidsim.continuation.system.Prepared.to_ground`); the sampled series stay
    in the ground frame."""
    opts = prep.options._replace(
        t_end=float(t1), record_events=sample_times is not None, energy=False
    )
    rs = L.new_restart()
    r = rs[0]
    r["started"] = L.CONTINUED
    r["t"] = float(t0)
    # a continued run takes its first step as given (0 would stall it)
    r["h"] = min(1e-7, opts.max_step, float(t1) - float(t0))
    r["mode_0"], r["mode_1"] = int(modes[0]), int(modes[1])
    for i in range(2):
        v = float(v0s[i])
        r[f"v0_{i}"] = v if (int(modes[i]) != 0 and math.isfinite(v)) else 1.0
    raw = core_run(
        prep.record,
        opts,
        prep.to_ground(float(t0), np.asarray(y0, dtype=float)),
        sample_times=sample_times,
        transfer_times=prep.transfers(t0, t1),
        series=sample_times is not None,
        xsq=False,
        restart=rs,
        implicit=prep.implicit,
    )
    if raw.status != L.ST_OK:
        raise SimulationError(_failure(raw.status, raw.t, t0, opts.max_steps), raw.t)
    rr = raw.restart[0]
    m1 = (int(rr["mode_0"]), int(rr["mode_1"]))
    v1 = np.array(
        [float(rr["v0_0"]) if m1[0] else math.nan, float(rr["v0_1"]) if m1[1] else math.nan]
    )
    return Segment(prep.to_slot(float(t1), raw.y), m1, v1, raw.episodes, raw.series)


@dataclass(frozen=True)
class FlowMap:
    """The map from (t0, y0, contacts, latched speeds) to t1 and its Jacobians.

    The fields are those of :class:`braidsim.sensitivity.FlowMap` (same names, shapes and
    meaning), so that either can serve continuation; the xy carrier's y0, y1 and their
    parameter columns in the slot's frame, as :func:`advance` takes and gives them.
    """

    y1: np.ndarray
    modes1: tuple[int, int]
    v0s1: np.ndarray
    jac_y: np.ndarray
    jac_v0: np.ndarray
    dv0_dy: np.ndarray
    dv0_dv0: np.ndarray
    jac_p: np.ndarray
    dv0_dp: np.ndarray
    episodes: np.ndarray
    min_gaps: np.ndarray
    modes0: tuple[int, int] = (0, 0)
    # whether a column's runs at +-d made other contacts than the base run's at every step
    # tried (fd_flow_map): its differences, hence its multipliers, are not derivatives
    straddled: bool = False
    # per direction: the impact tables of its runs at +d and -d and d (None: no direction)
    episode_pairs: tuple[tuple[np.ndarray, np.ndarray, float] | None, ...] = field(
        default=(), repr=False, compare=False
    )

    @functools.cached_property
    def impact_sens(self) -> np.ndarray:
        """(n_impacts, directions, 5): central differences of each impact's
        (:data:`~braidsim.sensitivity.IMPACT_QUANTITIES`) along each direction (NaN where
        the two runs' impact tables differ in length), made when first read: continuation
        reads only the Jacobians of its maps."""
        q_base = _episode_quantities(self.episodes)
        cols = []
        for pair in self.episode_pairs:
            dq = None
            if pair is not None:
                qp, qm = _episode_quantities(pair[0]), _episode_quantities(pair[1])
                if qp.shape == qm.shape == q_base.shape:
                    dq = (qp - qm) / (2 * pair[2])
            cols.append(np.full(q_base.shape, math.nan) if dq is None else dq)
        return np.stack(cols, axis=1) if cols else np.zeros((q_base.shape[0], 0, 5))

    @property
    def impacts(self) -> Any:
        """The impacts in [t0, t1] (a pandas DataFrame, the columns of ``Result.impacts``)."""
        from braidsim.result import impacts_frame

        return impacts_frame(self.episodes)

    def monodromy(self) -> np.ndarray:
        """The Jacobian of the map on z = (y, latched speeds of the pairs in contact at t0);
        requires ``modes1 == modes0`` (a periodic orbit's section)."""
        if tuple(self.modes1) != tuple(self.modes0):
            raise ValueError(
                f"monodromy: the contacts at t1 {self.modes1} differ from those at t0 "
                f"{self.modes0}; the map is not a return map there"
            )
        c = [i for i in range(2) if self.modes0[i] != 0]
        top = np.hstack([self.jac_y, self.jac_v0[:, c]])
        bottom = np.hstack([self.dv0_dy[c, :], self.dv0_dv0[np.ix_(c, c)]])
        return np.vstack([top, bottom])


def min_gaps(prep: Any, series: np.ndarray | None, n_state: int) -> np.ndarray:
    """(2, 2) smallest gap to the (inner, outer) wall of each pair over the sampled rows
    (columns 1..n_state of the series hold the state); NaN for a pair the model lacks."""
    out = np.full((2, 2), math.nan)
    if series is None or series.shape[0] == 0:
        return out
    pairs = 1 if prep.n_coords == 1 else 2
    for p in range(pairs):
        g_in, g_out, _ = gaps_along(prep.record, p, series[:, 0], series[:, 1 : 1 + n_state].T)
        out[p] = g_in.min(), g_out.min()
    return out


def contact_structure(episodes: np.ndarray) -> tuple[tuple[int, int], ...]:
    """The contacts of a run in order: (pair, wall) of each episode."""
    return tuple((int(p), int(w)) for p, w in zip(episodes["pair"], episodes["wall"], strict=True))


def _episode_quantities(ep: np.ndarray) -> np.ndarray:
    if not ep.size:
        return np.zeros((0, len(IMPACT_QUANTITIES)))
    return np.column_stack([ep[q] for q in IMPACT_QUANTITIES])


def fd_flow_map(
    system: Any,
    values: Mapping[str, float],
    t0: float,
    t1: float,
    y0: FloatSeq,
    modes: Sequence[int] = (0, 0),
    v0s: FloatSeq = (math.nan, math.nan),
    keys: Sequence[str] = (),
    *,
    rel: float = DEFAULT_REL_STEP,
    samples: int = 0,
) -> FlowMap:
    """The flow map of ``system`` (a :class:`~braidsim.continuation.system.ScenarioSystem`
    or :class:`~braidsim.continuation.system.ModelSystem`) at parameter ``values``, from
    (t0, y0, ``modes``, ``v0s``) to t1, with central finite-difference Jacobians (module
    docstring). ``keys``: parameters for ``jac_p``; ``samples``: rows of the base run for
    ``min_gaps`` (0: none, the gaps NaN).
    """
    prep = system.prepare(values)
    y0 = np.asarray(y0, dtype=float)
    n = y0.size
    modes = (int(modes[0]), int(modes[1]))
    v0 = np.array([float(v0s[0]), float(v0s[1])])
    st = np.linspace(t0, t1, samples) if samples else None
    base = advance(prep, t0, t1, y0, modes, v0, st)
    Ls, Vs = system.scales(values)
    scale_y = np.array([Ls if i % 2 == 0 else Vs for i in range(n)])
    if n == 4:  # (x, vx, y, vy)
        scale_y = np.array([Ls, Vs, Ls, Vs])

    structure = contact_structure(base.episodes)

    # whether a cut step may still restore the base run's contacts in this map
    retry = True

    def runs(
        at: Any, d: float
    ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray, float]]:
        # Where the two runs at +-d do not make the base run's contacts (a contact that
        # appears, vanishes or splits in two at a depth minimum touching zero inside it),
        # their difference is no derivative: on the clearance example's cross branch it
        # made a multiplier jump from 1.17 to -1,367 and a false period doubling. The step
        # is cut by 10 once (STRUCTURE_RETRIES). Where that does not help (an orbit at a grazing,
        # whose free-flight family a boundary follows, touches the wall under any
        # perturbation; a resting contact at its lift-off) the first step's difference
        # stands, as before, and the map's other columns are not tried smaller (cutting in
        # every column made 20 % more runs at the lift-off of paper-3.3's resting orbit).
        nonlocal retry
        d0 = d
        sp0, sm0 = sp, sm = at(d), at(-d)
        same = contact_structure(sp.episodes) == contact_structure(sm.episodes) == structure
        tries = STRUCTURE_RETRIES if retry else 0
        while not same and tries > 0:
            d *= 0.1
            tries -= 1
            sp, sm = at(d), at(-d)
            same = contact_structure(sp.episodes) == contact_structure(sm.episodes) == structure
        if not same:
            retry = False
            sp, sm, d = sp0, sm0, d0
        dy = (sp.y1 - sm.y1) / (2 * d)
        dv = np.where(np.isfinite(sp.v0s1 - sm.v0s1), (sp.v0s1 - sm.v0s1) / (2 * d), 0.0)
        return dy, dv, (sp.episodes, sm.episodes, d)

    cols_y, cols_v = [], []
    cols_q: list[tuple[np.ndarray, np.ndarray, float] | None] = []
    for i in range(n):

        def shifted_y(s: float, i: int = i) -> Segment:
            e = np.zeros(n)
            e[i] = s
            return advance(prep, t0, t1, y0 + e, modes, v0)

        dy, dv, dq = runs(shifted_y, rel * scale_y[i])
        cols_y.append(dy)
        cols_v.append(dv)
        cols_q.append(dq)
    jac_v0 = np.zeros((n, 2))
    dv0_dv0 = np.zeros((2, 2))
    for j in range(2):
        if modes[j] == 0 or not math.isfinite(v0[j]):
            cols_q.append(None)
            continue

        def shifted_v0(s: float, j: int = j) -> Segment:
            e = np.zeros(2)
            e[j] = s
            return advance(prep, t0, t1, y0, modes, v0 + e)

        dy, dv, dq = runs(shifted_v0, rel * abs(v0[j]))
        jac_v0[:, j] = dy
        dv0_dv0[:, j] = dv
        cols_q.append(dq)
    jac_p = np.zeros((n, len(keys)))
    dv0_dp = np.zeros((2, len(keys)))
    for j, key in enumerate(keys):
        p = float(values[key]) if key in values else float(system.value(key))

        def at(s: float, key: str = key, p: float = p) -> Segment:
            vals = dict(values)
            vals[key] = p + s
            return advance(system.prepare(vals), t0, t1, y0, modes, v0)

        dy, dv, dq = runs(at, rel * max(abs(p), 1e-12))
        jac_p[:, j] = dy
        dv0_dp[:, j] = dv
        cols_q.append(dq)
    return FlowMap(
        y1=base.y1,
        modes1=base.modes1,
        v0s1=base.v0s1,
        jac_y=np.column_stack(cols_y),
        jac_v0=jac_v0,
        dv0_dy=np.column_stack(cols_v),
        dv0_dv0=dv0_dv0,
        jac_p=jac_p,
        dv0_dp=dv0_dp,
        episodes=base.episodes,
        min_gaps=min_gaps(prep, base.series, n),
        modes0=modes,
        episode_pairs=tuple(cols_q),
        straddled=not retry,
    )
