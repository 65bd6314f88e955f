"""Periodic orbits of the forced carrier by Newton shooting on the stroboscopic map.

Section and map state
---------------------
An orbit of period k forcing cycles is cut at a *section*: the forcing phase theta_0 [rad],
i.e. the times t_0 = theta_0 / Omega + j k T. Multiple shooting cuts it at m equally spaced
phases theta_0 + 2 pi k j / m (j = 0..m-1); single shooting is m = 1. At each cut the state
of the hybrid system is

    z = (x, x'[, y, y'], v0 of each pair in contact at the cut whose contact starts again
         within the period)

The latched approach speed v0 of a contact open at the cut sets the contact's damping for
the rest of that contact, so it is part of the state: the map z -> z' includes how v0 is
latched again at the next onset, and the monodromy matrix (the Jacobian of the return map)
has the same eigenvalues wherever the period is cut. A contact that lasts the whole orbit
(the carrier resting on a wall) never latches again; its v0 is then a fixed parameter of the
orbit, not a state entry (it would add a multiplier 1 that means nothing).

That parameter is a memory of how the contact formed, which a periodic orbit does not
know: continuation gives it one value, :func:`resting_speed`, by default the law's floor
``min_impact_velocity``. At a lift-off the orbits beyond it strike the wall with approach
speeds that fall to zero at the grazing, so they latch the floor: with the floor the
resting orbit is the limit of the bouncing family at its lift-off (the grazing is
continuous), and it does not depend on which run seeded it.

Shooting
--------
With Phi_j the flow map from cut j to cut j + 1 (:func:`evaluate_map`), the orbit solves

    r_j = Phi_j(z_j; lambda) - z_{j+1} = 0,   j = 0..m-1 (z_m = z_0),

by Newton's method with the Jacobians of the flow map; the state is scaled by the system's
length L and speed L Omega. The Floquet multipliers are the eigenvalues of the monodromy
M = J_{m-1} ... J_0 (J_j = d Phi_j / d z_j); the orbit is stable when all lie inside the
unit circle (Parker, T. S. and Chua, L. O. (1989), Practical Numerical Algorithms for Chaotic
Systems, Springer, ch. 5, doi:10.1007/978-1-4612-3486-9).

The cut is chosen away from contact onsets and exits (preferably in free flight): a cut that
an onset crosses changes the contacts at the cut. When that happens during continuation the
section is moved (:func:`reseat`), which leaves the multipliers unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from braidsim.continuation.fdmap import FloatSeq, FlowMap, advance, fd_flow_map
from braidsim.continuation.system import ModelSystem, ScenarioSystem
from braidsim.core import derivatives, gaps_along, pair_gaps
from braidsim.errors import InputError, SimulationError

METHODS = ("auto", "exact", "fd")
DEFAULT_TOL = 1e-8
"""Newton tolerance on the scaled residual (units of the length scale L and of L Omega)."""
PROFILE_SAMPLES = 200
"""Samples per forcing period of an orbit's profile (gaps, depths, strobe points)."""


class ContinuationError(SimulationError):
    """Newton shooting or continuation failed (a numerical failure, exit code 1)."""


class SectionChanged(ContinuationError):
    """The contacts at a cut changed within one Newton iteration (an onset crossed it)."""


class OutOfDomain(ContinuationError):
    """A Newton iterate outside the map's domain: a latched speed at or below 0, or a
    parameter outside its range (:func:`newton` shortens such a step)."""


def exact_available() -> bool:
    """Whether the exact variational flow map (``braidsim.sensitivity``) is installed."""
    try:
        from braidsim.sensitivity import flow_map  # noqa: F401
    except ImportError:
        return False
    return True


def evaluate_map(
    system: Any,
    values: Mapping[str, float],
    t0: float,
    t1: float,
    y0: FloatSeq,
    modes: Sequence[int],
    v0s: FloatSeq,
    keys: Sequence[str] = (),
    method: str = "auto",
    accurate: bool = True,
) -> FlowMap:
    """The flow map with its Jacobians: the one place where continuation asks for it.

    ``method``: ``"exact"`` (the variational equations of :mod:`braidsim.sensitivity`: the
    carrier of a scenario, or a model record of the compiled core through
    :func:`braidsim.sensitivity.record_flow_map`), ``"fd"`` (central finite differences,
    :func:`braidsim.continuation.fdmap.fd_flow_map`) or ``"auto"`` (exact where available).
    ``accurate`` False: the exact map's Jacobians over the state's steps, their error not
    controlled (``control_tangents=False``), enough for a Newton step; central
    differences are the same either way.
    """
    if method not in METHODS:
        raise InputError(f"method: {method!r} is not allowed; allowed {', '.join(METHODS)}")
    use_exact = method == "exact" or (method == "auto" and exact_available())
    if use_exact and isinstance(system, ModelSystem):
        from braidsim.sensitivity import check_differentiable, record_flow_map

        prep = system.prepare(values)
        if method == "auto":
            try:
                check_differentiable(prep.record)
            except InputError:  # a record without tangents: central differences
                return fd_flow_map(system, values, t0, t1, y0, modes, v0s, keys)
        rfm = record_flow_map(
            prep.record,
            prep.options,
            t0,
            t1,
            prep.to_ground(t0, np.asarray(y0, dtype=float)),
            (int(modes[0]), int(modes[1])),
            tuple(float(v) for v in v0s),
            tuple(keys),
            control_tangents=accurate,
        )
        return _in_slot_frame(system, values, rfm, keys)
    if use_exact:
        if not isinstance(system, ScenarioSystem):
            raise InputError("method: 'exact' needs a scenario or a model record; allowed 'fd'")
        from braidsim.sensitivity import flow_map

        fm = flow_map(
            system.scenario_at(values),
            t0,
            t1,
            y0=system.prepare(values).to_ground(t0, np.asarray(y0, dtype=float)),
            modes=(int(modes[0]), int(modes[1])),
            v0s=tuple(float(v) for v in v0s),
            keys=tuple(keys),
            check_start=False,
            control_tangents=accurate,
        )
        # (the same fields, module docstring)
        return _in_slot_frame(system, values, fm, keys)
    return fd_flow_map(system, values, t0, t1, y0, modes, v0s, keys)


SLOT_REL_STEP = 1e-6
"""Relative step of the central differences of the slot's travel s(t) in the parameters
(:func:`_in_slot_frame`): s is linear in each parameter that moves it (omega_0, r_c)."""


def _in_slot_frame(system: Any, values: Mapping[str, float], fm: Any, keys: Sequence[str]) -> Any:
    """An exact map of the xy carrier taken to the slot's frame (``system`` module
    docstring): y0 and y1 as y - s(t), and the parameters' columns at fixed y - s(t0)
    rather than fixed y, d(y1 - s(t1))/dp = dy1/dp + dy1/dy0 ds(t0)/dp - ds(t1)/dp (the
    latched speeds' likewise); ds/dp by central differences. The state's Jacobians do not
    change. Other maps are returned as they are."""
    prep = system.prepare(values)
    if not prep.has_slot:
        return fm
    jac_p = np.array(fm.jac_p, dtype=float)
    dv0_dp = np.array(fm.dv0_dp, dtype=float)
    for j, key in enumerate(keys):
        p = float(values[key]) if key in values else float(system.value(key))
        d = SLOT_REL_STEP * max(abs(p), 1e-12)
        hi = system.prepare({**values, key: p + d})
        lo = system.prepare({**values, key: p - d})
        ds0 = (hi.slot_travel(fm.t0)[0] - lo.slot_travel(fm.t0)[0]) / (2 * d)
        ds1 = (hi.slot_travel(fm.t1)[0] - lo.slot_travel(fm.t1)[0]) / (2 * d)
        jac_p[:, j] += np.asarray(fm.jac_y)[:, 2] * ds0
        jac_p[2, j] -= ds1
        dv0_dp[:, j] += np.asarray(fm.dv0_dy)[:, 2] * ds0
    return replace(
        fm,
        y0=prep.to_slot(fm.t0, fm.y0),
        y1=prep.to_slot(fm.t1, fm.y1),
        jac_p=jac_p,
        dv0_dp=dv0_dp,
    )


def frequency_key(system: Any) -> str:
    """The parameter that sets the forcing frequency (the section times move with it)."""
    if isinstance(system, ModelSystem):
        return system.frequency_field
    return "track.vibration_frequency"


# --------------------------------------------------------------------------------------
# layouts and profiles
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Cut:
    """The hybrid state's discrete part at one cut.

    Attributes
    ----------
    modes : (int, int)
        Contact modes of the two pairs (-1 inner, +1 outer, 0 free).
    v0_state : (bool, bool)
        Whether each pair's latched speed is a state entry (in contact, re-latched within
        the period).
    v0_fixed : (float, float)
        Latched speeds held fixed (in contact all period) [m/s]; NaN otherwise.
    """

    modes: tuple[int, int]
    v0_state: tuple[bool, bool]
    v0_fixed: tuple[float, float]

    @property
    def size_extra(self) -> int:
        """Latched speeds in the state."""
        return int(sum(self.v0_state))

    def v0s(self, z_extra: np.ndarray) -> np.ndarray:
        """The (2,) latched speeds of a run from this cut."""
        out = np.array(self.v0_fixed, dtype=float)
        it = iter(z_extra)
        for i in range(2):
            if self.v0_state[i]:
                out[i] = float(next(it))
        return out


def _hermite_min(t0: float, t1: float, g0: float, g1: float, d0: float, d1: float) -> float:
    """Smallest value of the cubic Hermite interpolant of (g, g') on [t0, t1]."""
    h = t1 - t0
    if h <= 0:
        return min(g0, g1)
    s = np.linspace(0.0, 1.0, 41)
    h00 = 2 * s**3 - 3 * s**2 + 1
    h10 = s**3 - 2 * s**2 + s
    h01 = -2 * s**3 + 3 * s**2
    h11 = s**3 - s**2
    return float(np.min(h00 * g0 + h10 * h * d0 + h01 * g1 + h11 * h * d1))


@dataclass(frozen=True)
class Profile:
    """What an orbit does over one period, from a dense run of two periods.

    Attributes
    ----------
    t0, period : float
        Section time and orbit period k T [s].
    onsets : np.ndarray
        Onset times in [t0, t0 + period) (per pair and wall in ``onset_pairs``).
    onset_pairs, onset_walls : np.ndarray
    exits : np.ndarray
        Exit times in [t0, t0 + period).
    peak_force, max_depth : float
        Largest contact force [N] and depth [m] over the orbit (0 without contact).
    min_gap : float
        Closest approach to a wall the carrier is not touching [m]: the smallest interior
        minimum of a gap in free flight, or the gap to a wall never touched (inf: none).
    approach : float
        Distance to the nearest grazing from this side [m]: the smallest interior minimum of
        a free-flight gap or of a contact's depth (inf: none). Zero at a grazing.
    feature : float
        Size of the smallest contact or flight [m]: the least peak depth of a contact and the
        least height of a free flight between two contacts (inf: none). Zero at a grazing
        seen from the other side.
    strobe_u, strobe_v : np.ndarray
        The k stroboscopic samples (forcing phase 0): position relative to the inner wall
        [m] (x - h(t) for the carrier; x for a model without an inner wall) and speed [m/s].
    u_min, u_max : float
        Range of that position over the orbit [m].
    impacts : int
        Contact onsets per orbit.
    """

    t0: float
    period: float
    onsets: np.ndarray
    onset_pairs: np.ndarray
    onset_walls: np.ndarray
    exits: np.ndarray
    peak_force: float
    max_depth: float
    min_gap: float
    approach: float
    feature: float
    strobe_u: np.ndarray
    strobe_v: np.ndarray
    u_min: float
    u_max: float
    impacts: int
    intervals: tuple[tuple[float, float, int, int, float], ...] = field(repr=False, default=())

    def contact_at(self, t: float) -> tuple[tuple[int, int], tuple[float, float]]:
        """Modes and latched speeds at time t (any time, by periodicity)."""
        modes = [0, 0]
        v0 = [math.nan, math.nan]
        P = self.period
        for a, b, pair, wall, v in self.intervals:
            for shift in (-P, 0.0, P):
                if a + shift < t < b + shift:
                    modes[pair] = wall
                    v0[pair] = v
        return (modes[0], modes[1]), (v0[0], v0[1])

    def event_distance(self, t: float) -> float:
        """Time from t to the nearest onset or exit, periodically [s]."""
        ev = np.concatenate([self.onsets, self.exits])
        if ev.size == 0:
            return math.inf
        d = np.abs((t - ev + 0.5 * self.period) % self.period - 0.5 * self.period)
        return float(d.min())


def _position(prep: Any, t: float, y: np.ndarray) -> float:
    """Position relative to the inner wall (x itself when there is none)."""
    g = float(pair_gaps.py(prep.record, 0, t, y)[0])
    return g if math.isfinite(g) else float(y[0])


def profile(
    system: Any,
    values: Mapping[str, float],
    t0: float,
    k: int,
    y0: FloatSeq,
    modes: Sequence[int],
    v0s: FloatSeq,
    samples: int = PROFILE_SAMPLES,
) -> Profile:
    """Run an orbit (from its section state) over two periods and measure it (:class:`Profile`).

    The first period gives the events; the samples of both find the interior extremes."""
    prep = system.prepare(values)
    T = prep.period
    P = k * T
    y0 = np.asarray(y0, dtype=float)
    n = y0.size
    phase_off = float(getattr(system, "strobe_offset", lambda v: 0.0)(values))
    grid = np.linspace(t0, t0 + 2 * P, 2 * k * samples + 1)
    js = math.ceil((t0 - phase_off) / T - 1e-9) + np.arange(2 * k + 2)
    strobes = phase_off + js * T
    strobes = strobes[(strobes >= t0) & (strobes < t0 + P)]
    st = np.unique(np.concatenate([grid, strobes]))
    seg = advance(prep, t0, t0 + 2 * P, y0, modes, v0s, st)
    ep = seg.episodes
    rows = seg.series if seg.series is not None else np.zeros((0, n + 1))
    t = rows[:, 0]
    Y = rows[:, 1 : 1 + n]
    in1 = (ep["t"] >= t0 - 1e-12) & (ep["t"] < t0 + P - 1e-12) & (ep["initial"] == 0.0)
    onsets = ep["t"][in1]
    ends = ep["t_end"]
    ex = (ends >= t0) & (ends < t0 + P) & np.isfinite(ends) & (ep["end_reason"] == 0.0)
    exits = ends[ex]
    intervals = []
    for e in ep:
        te = float(e["t_end"]) if np.isfinite(e["t_end"]) else t0 + 2 * P
        if e["end_reason"] == 1.0 and e["initial"] == 1.0:  # the whole run: resting
            te = math.inf
        ta = -math.inf if (e["initial"] == 1.0 and te == math.inf) else float(e["t"])
        intervals.append((ta, te, int(e["pair"]), int(e["wall"]), float(e["latched_velocity"])))
    peak = float(ep["peak_force"].max()) if ep.size else 0.0
    maxd = float(ep["max_depth"].max()) if ep.size else 0.0
    pairs = 1 if prep.n_coords == 1 else 2
    # gaps and their rates at every row
    G = np.stack([np.column_stack(gaps_along(prep.record, p, t, Y.T)) for p in range(pairs)], 1)
    # contact state of every row (0 free, else the wall), per pair
    M = np.zeros((t.size, pairs), dtype=int)
    for a, b, pair, wall, _ in intervals:
        if pair < pairs:
            M[(t > a) & (t < b), pair] = wall
    approach = math.inf
    min_gap = math.inf
    feature = math.inf
    touched = {(int(p), int(w)) for p, w in zip(ep["pair"], ep["wall"], strict=True)}
    for p in range(pairs):
        for wi, wall in enumerate((-1, 1)):
            g = G[:, p, wi]
            rate = G[:, p, 2] * (1.0 if wall == -1 else -1.0)
            if (p, wall) not in touched:
                min_gap = min(min_gap, float(g.min()))
            free = M[:, p] == 0
            inc = M[:, p] == wall
            # signed distance to the switching surface: the gap in free flight, the depth
            # (minus the gap) in contact with this wall
            for mask, sign in ((free, 1.0), (inc, -1.0)):
                d = sign * g
                dr = sign * rate
                for i in range(1, t.size - 1):
                    if not (mask[i - 1] and mask[i] and mask[i + 1]):
                        continue
                    if (
                        d[i] <= d[i - 1]
                        and d[i] <= d[i + 1]
                        and (d[i] < d[i - 1] or d[i] < d[i + 1])
                    ):
                        lo = min(
                            _hermite_min(t[i - 1], t[i], d[i - 1], d[i], dr[i - 1], dr[i]),
                            _hermite_min(t[i], t[i + 1], d[i], d[i + 1], dr[i], dr[i + 1]),
                        )
                        lo = max(lo, 0.0)
                        approach = min(approach, lo)
                        if sign > 0:
                            min_gap = min(min_gap, lo)
        # flights between two contacts of this pair: their heights
        free = M[:, p] == 0
        i = 0
        while i < t.size:
            if free[i]:
                j = i
                while j < t.size and free[j]:
                    j += 1
                if i > 0 and j < t.size:  # bounded by contacts on both sides
                    hgt = float(np.max(np.min(G[i:j, p, :2], axis=1)))
                    feature = min(feature, max(hgt, 0.0))
                i = j
            else:
                i += 1
    for e in ep[in1]:
        feature = min(feature, float(e["max_depth"]))
    su = np.array([_position(prep, ts, Y[np.searchsorted(t, ts)]) for ts in strobes])
    sv = np.array([Y[np.searchsorted(t, ts), 1] for ts in strobes])
    pos = G[:, 0, 0] if np.all(np.isfinite(G[:, 0, 0])) else Y[:, 0]
    return Profile(
        t0=float(t0),
        period=P,
        onsets=onsets,
        onset_pairs=ep["pair"][in1].astype(int),
        onset_walls=ep["wall"][in1].astype(int),
        exits=exits,
        peak_force=peak,
        max_depth=maxd,
        min_gap=min_gap,
        approach=approach,
        feature=feature,
        strobe_u=su,
        strobe_v=sv,
        u_min=float(pos.min()) if pos.size else math.nan,
        u_max=float(pos.max()) if pos.size else math.nan,
        impacts=int(onsets.size),
        intervals=tuple(intervals),
    )


# --------------------------------------------------------------------------------------
# orbits
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Orbit:
    """A periodic orbit found by shooting.

    Attributes
    ----------
    values : dict
        Parameter values it was solved at (SI), the continuation parameter among them.
    period : int
        k, forcing cycles per orbit.
    phase : float
        Forcing phase theta_0 of the section [rad] (t_0 = theta_0 / Omega).
    cuts : tuple of Cut
        The discrete state at each of the m cuts.
    z : tuple of np.ndarray
        The state at each cut (SI: m, m/s, and m/s for latched speeds): (x, vx[, y, vy],
        latched speeds), the xy carrier's y in the slot's frame, y - s(t) (the
        :mod:`~braidsim.continuation.system` module docstring).
    monodromy : np.ndarray
        The monodromy matrix on the state at cut 0.
    multipliers : np.ndarray
        Its eigenvalues, by decreasing modulus.
    profile : Profile
        Measures of the orbit.
    residual : float
        Final scaled residual of Newton's method.
    iterations : int
        Newton iterations used.
    reliable : bool
        False where a finite-difference map's runs straddled a change of the contacts
        (:attr:`braidsim.continuation.fdmap.FlowMap.straddled`: an orbit closer to a wall
        than the map's smallest step): its monodromy and multipliers, hence ``stable``, are
        not the orbit's. The exact map's are always reliable.
    """

    values: dict[str, float]
    period: int
    phase: float
    cuts: tuple[Cut, ...]
    z: tuple[np.ndarray, ...]
    monodromy: np.ndarray
    multipliers: np.ndarray
    profile: Profile
    residual: float = 0.0
    iterations: int = 0
    reliable: bool = True

    @property
    def segments(self) -> int:
        """m, the number of shooting segments."""
        return len(self.cuts)

    @property
    def stable(self) -> bool:
        """All multipliers strictly inside the unit circle (up to 1e-6)."""
        return bool(np.all(np.abs(self.multipliers) < 1.0 - 1e-6))

    @property
    def layout(self) -> tuple[Cut, ...]:
        """The cuts without their fixed speeds (for comparing orbit structures)."""
        return self.cuts


def sort_multipliers(mu: np.ndarray) -> np.ndarray:
    """Eigenvalues by decreasing modulus, then real part."""
    mu = np.asarray(mu, dtype=complex)
    return mu[np.lexsort((-mu.real, -np.abs(mu)))]


@dataclass
class Shooter:
    """The shooting equations of one orbit structure (period, cuts) of a system.

    Unknowns U = (z_0 / S_0, ..., z_{m-1} / S_{m-1}, lambda / P) scaled by the state scales
    S_j and the parameter scale P. ``key`` None solves at fixed parameters. With ``key2``
    a second parameter is free as well, U = (..., lambda / P, lambda_2 / P_2) (two-parameter
    continuation of a bifurcation).
    """

    system: Any
    values: dict[str, float]
    key: str | None
    period: int
    phase: float
    cuts: tuple[Cut, ...]
    method: str = "auto"
    pscale: float = 1.0
    evaluations: int = 0
    # whether a map of the last residual's evaluation straddled a change of the contacts
    straddled: bool = False
    # whether the last residual's Jacobian came from exact maps without the error control
    # of their tangents (``residual(U, accurate=False)``): good for a Newton step only
    rough: bool = False
    key2: str | None = None
    pscale2: float = 1.0
    # the state scales of each cut (fixed for the shooter: its base values and cuts)
    _scales: dict[int, np.ndarray] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    @property
    def free(self) -> list[tuple[str, float]]:
        """The free parameters and their scales, in the order of U's last entries."""
        out = [] if self.key is None else [(self.key, self.pscale)]
        if self.key2 is not None:
            out.append((self.key2, self.pscale2))
        return out

    def values_of(self, U: np.ndarray) -> dict[str, float]:
        """Parameter values [SI] at the unknowns U."""
        v = dict(self.values)
        nf = len(self.free)
        for i, (k, sc) in enumerate(self.free):
            v[k] = float(U[U.size - nf + i]) * sc
        return v

    def times(self, values: Mapping[str, float]) -> np.ndarray:
        """The cut times t_0..t_m [s] at ``values``."""
        try:
            w = self.system.prepare(values).omega
        except InputError as exc:
            raise ContinuationError(f"parameter out of range ({exc})") from None
        m = len(self.cuts)
        return (self.phase + 2.0 * math.pi * self.period * np.arange(m + 1) / m) / w

    def scale(self, j: int, values: Mapping[str, float]) -> np.ndarray:
        """State scales of cut j: (L, L Omega[, L, L Omega], L Omega per latched speed), at
        the shooter's base values (fixed, so that the scaling does not move with lambda;
        kept per cut, read-only)."""
        S = self._scales.get(j)
        if S is None:
            Ls, Vs = self.system.scales(self.values)
            n = 2 * self.system.prepare(self.values).n_coords
            base = [Ls if i % 2 == 0 else Vs for i in range(n)]
            S = np.array(base + [Vs] * self.cuts[j].size_extra)
            S.setflags(write=False)
            self._scales[j] = S
        return S

    def sizes(self) -> list[int]:
        """Entries of the state at each cut."""
        n = 2 * self.system.prepare(self.values).n_coords
        return [n + c.size_extra for c in self.cuts]

    def values_at(self, lam: float | None) -> dict[str, float]:
        """Parameter values with the continuation parameter at ``lam`` [SI]."""
        v = dict(self.values)
        if self.key is not None and lam is not None:
            v[self.key] = float(lam)
        return v

    def pack(
        self, z: Sequence[np.ndarray], lam: float | None, lam2: float | None = None
    ) -> np.ndarray:
        """Scaled unknowns from SI states (and the free parameters)."""
        vals = self.values_at(lam)
        parts = [np.asarray(z[j]) / self.scale(j, vals) for j in range(len(self.cuts))]
        if self.key is not None:
            parts.append(np.array([float(lam) / self.pscale]))  # type: ignore[arg-type]
        if self.key2 is not None:
            p2 = float(self.values[self.key2]) if lam2 is None else float(lam2)
            parts.append(np.array([p2 / self.pscale2]))
        return np.concatenate(parts)

    def unpack(self, U: np.ndarray) -> tuple[list[np.ndarray], float | None]:
        """SI states and parameter from scaled unknowns."""
        nf = len(self.free)
        lam = float(U[U.size - nf]) * self.pscale if self.key is not None else None
        vals = self.values_at(lam)
        out = []
        i = 0
        for j, s in enumerate(self.sizes()):
            out.append(U[i : i + s] * self.scale(j, vals))
            i += s
        return out, lam

    def residual(
        self, U: np.ndarray, accurate: bool = True
    ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """Scaled residuals r, their Jacobian (rows r, columns U) and the segment Jacobians
        J_j (SI) of the state maps; ``accurate`` False: the exact maps' Jacobians without
        the error control of their tangents (:func:`evaluate_map`), for a Newton step."""
        z, _ = self.unpack(U)
        vals = self.values_of(U)
        try:
            prep = self.system.prepare(vals)
        except InputError as exc:  # a Newton iterate outside the parameter's range
            raise OutOfDomain(f"parameter out of range in Newton's method ({exc})") from None
        tt = self.times(vals)
        m = len(self.cuts)
        sizes = self.sizes()
        N = sum(sizes)
        offs = np.concatenate([[0], np.cumsum(sizes)])
        R = np.zeros(N)
        DR = np.zeros((N, U.size))
        Js = []
        self.straddled = False
        self.rough = False
        n = 2 * prep.n_coords
        free = self.free
        keys = [k for k, _ in free]
        fkey = frequency_key(self.system)
        for j in range(m):
            cj, cn = self.cuts[j], self.cuts[(j + 1) % m]
            y0 = z[j][:n]
            v0 = cj.v0s(z[j][n:])
            try:
                fm = evaluate_map(
                    self.system,
                    vals,
                    tt[j],
                    tt[j + 1],
                    y0,
                    cj.modes,
                    v0,
                    keys,
                    self.method,
                    accurate,
                )
            except InputError as exc:  # a Newton iterate outside the map's domain (v0 <= 0)
                raise OutOfDomain(f"Newton left the map's domain ({exc})") from None
            self.evaluations += 1
            self.rough = self.rough or not (accurate or isinstance(fm, FlowMap))
            self.straddled = self.straddled or bool(getattr(fm, "straddled", False))
            if tuple(fm.modes1) != tuple(cn.modes):
                raise SectionChanged(
                    f"the contacts at cut {(j + 1) % m} changed from {cn.modes} to "
                    f"{tuple(fm.modes1)} at t = {tt[j + 1]:.9g} s"
                )
            ci = [i for i in range(2) if cj.v0_state[i]]
            co = [i for i in range(2) if cn.v0_state[i]]
            out = np.concatenate([fm.y1, np.asarray(fm.v0s1)[co]])
            J = np.vstack(
                [
                    np.hstack([fm.jac_y, fm.jac_v0[:, ci]]),
                    np.hstack([fm.dv0_dy[co, :], fm.dv0_dv0[np.ix_(co, ci)]]),
                ]
            )
            Js.append(J)
            Sj, Sn = self.scale(j, vals), self.scale((j + 1) % m, vals)
            jn = (j + 1) % m
            R[offs[j] : offs[j + 1]] = (out - z[jn]) / Sn
            DR[offs[j] : offs[j + 1], offs[j] : offs[j + 1]] += J * Sj[None, :] / Sn[:, None]
            DR[offs[j] : offs[j + 1], offs[jn] : offs[jn + 1]] -= np.eye(sizes[jn])
            for ip, (key, psc) in enumerate(free):
                dp = np.concatenate([fm.jac_p[:, ip], np.asarray(fm.dv0_dp)[co, ip]])
                if key == fkey:
                    # the cut times move with the forcing frequency: t_j = (theta_j) / Omega
                    # (the rates of the state in the slot's frame: y' - s'(t) for the xy
                    # carrier's y, system module docstring)
                    f1 = np.zeros(n)
                    f0 = np.zeros(n)
                    m1 = np.array(fm.modes1, dtype=np.int64)
                    derivatives.py(
                        prep.record,
                        tt[j + 1],
                        prep.to_ground(tt[j + 1], fm.y1),
                        m1,
                        np.nan_to_num(np.asarray(fm.v0s1, dtype=float), nan=1.0),
                        n,
                        f1,
                    )
                    m0 = np.array(cj.modes, dtype=np.int64)
                    derivatives.py(
                        prep.record,
                        tt[j],
                        prep.to_ground(tt[j], y0),
                        m0,
                        np.nan_to_num(v0, nan=1.0),
                        n,
                        f0,
                    )
                    if prep.has_slot:
                        f1[2] -= prep.slot_travel(tt[j + 1])[1]
                        f0[2] -= prep.slot_travel(tt[j])[1]
                    w = prep.omega
                    # the end state moves with t_1 along the flow, and every output with
                    # t_0 as -(d out / d y0) f0 (the same trajectory started later); a
                    # latched speed out of this map is constant once set: no t_1 term
                    dp[:n] += f1 * (-tt[j + 1] / w) - fm.jac_y @ f0 * (-tt[j] / w)
                    dp[n:] -= np.asarray(fm.dv0_dy)[co, :] @ f0 * (-tt[j] / w)
                DR[offs[j] : offs[j + 1], N + ip] = dp * psc / Sn
        # a change of the section structure along the way (a contact that stays open)
        return R, DR, Js


def monodromy_of(Js: Sequence[np.ndarray]) -> np.ndarray:
    """M = J_{m-1} ... J_0."""
    M = np.eye(Js[0].shape[1])
    for J in Js:
        M = J @ M
    return M


DOMAIN_HALVINGS = 6
"""Newton's method halves a step whose iterate leaves the map's domain at most this often."""


def newton(
    F: Any,
    U0: np.ndarray,
    tol: float = DEFAULT_TOL,
    max_iter: int = 10,
    final: Any = None,
) -> tuple[np.ndarray, float, int, Any]:
    """Newton's method on F(U) -> (G, DG, extra); returns (U, |G|, iterations, extra).

    ``final(U)``, where given, returns the (G, DG, extra) of F at its full accuracy or
    None: F's iterates may take rougher Jacobians (the exact maps' without the error
    control of their tangents: on a resting orbit less than half the time), the converged
    point's ``extra`` (the segment Jacobians, whose product gives the multipliers) is
    then ``final``'s. The residual |G| is F's.

    A step whose iterate F refuses as outside its domain (:class:`OutOfDomain`: a latched
    speed of a contact pushed through 0) is halved, up to ``DOMAIN_HALVINGS`` times.

    Raises :class:`ContinuationError` when it does not converge in ``max_iter`` iterations or
    the residual grows tenfold."""
    U = np.array(U0, dtype=float)
    G, DG, extra = F(U)
    g0 = float(np.max(np.abs(G)))
    for it in range(1, max_iter + 1):
        try:
            dU = np.linalg.solve(DG, -G)
        except np.linalg.LinAlgError:
            dU = np.linalg.lstsq(DG, -G, rcond=None)[0]
        for halvings in range(DOMAIN_HALVINGS + 1):
            try:
                G, DG, extra = F(U + dU)
                break
            except OutOfDomain:
                # (paper-3.3's xy carrier past its lift-off: the latched speed of the
                # contact open at the cut went below 0 on full steps near 0.1037 mm, and
                # the branch's grazing search read the failures as the grazing, 2 % short)
                if halvings == DOMAIN_HALVINGS:
                    raise
                dU = 0.5 * dU
        U = U + dU
        g = float(np.max(np.abs(G)))
        if not math.isfinite(g) or g > 10 * max(g0, tol):
            raise ContinuationError(f"Newton diverged (residual {g:.3g})")
        if g < tol and float(np.max(np.abs(dU))) < 100 * tol:
            full = final(U) if final is not None else None
            return U, g, it, extra if full is None else full[2]
    raise ContinuationError(
        f"Newton did not converge in {max_iter} iterations (residual {g:.3g} > {tol:g})"
    )


def finish(sh: Shooter, U: np.ndarray, res: float, its: int, Js: Sequence[np.ndarray]) -> Orbit:
    """The :class:`Orbit` of converged unknowns."""
    z, _ = sh.unpack(U)
    vals = sh.values_of(U)
    M = monodromy_of(Js)
    mu = sort_multipliers(np.linalg.eigvals(M))
    tt = sh.times(vals)
    n = 2 * sh.system.prepare(vals).n_coords
    prof = profile(
        sh.system, vals, tt[0], sh.period, z[0][:n], sh.cuts[0].modes, sh.cuts[0].v0s(z[0][n:])
    )
    return Orbit(
        vals, sh.period, sh.phase, sh.cuts, tuple(z), M, mu, prof, res, its, not sh.straddled
    )


def shooter_for(orbit: Orbit, system: Any, key: str | None, method: str, pscale: float) -> Shooter:
    """The shooting equations of ``orbit``'s structure."""
    return Shooter(
        system, dict(orbit.values), key, orbit.period, orbit.phase, orbit.cuts, method, pscale
    )


def solve_fixed(
    system: Any,
    values: Mapping[str, float],
    period: int,
    phase: float,
    cuts: Sequence[Cut],
    z: Sequence[np.ndarray],
    method: str = "auto",
    tol: float = DEFAULT_TOL,
) -> Orbit:
    """Newton shooting at fixed parameters from a guess ``z`` at each cut."""
    sh = Shooter(system, dict(values), None, int(period), float(phase), tuple(cuts), method)

    def F(U: np.ndarray) -> tuple[np.ndarray, np.ndarray, Any]:
        return sh.residual(U, accurate=False)

    def final(U: np.ndarray) -> tuple[np.ndarray, np.ndarray, Any] | None:
        return sh.residual(U) if sh.rough else None

    U, res, its, Js = newton(F, sh.pack(z, None), tol, final=final)
    return finish(sh, U, res, its, Js)


# --------------------------------------------------------------------------------------
# sections: choosing and moving the cuts
# --------------------------------------------------------------------------------------


def choose_phase(prof: Profile, omega: float, period: int, segments: int) -> float:
    """The forcing phase theta_0 of the first cut (from ``prof.t0``'s phase) that puts all m
    cuts farthest from any onset or exit, preferring cuts in free flight."""
    P = prof.period
    best = (-1.0, -math.inf, 0.0)
    for th in np.linspace(0.0, 2 * math.pi * period / segments, 96, endpoint=False):
        ts = prof.t0 + th / omega + np.arange(segments) * P / segments
        dist = min(prof.event_distance(t) for t in ts)
        free = all(prof.contact_at(t)[0] == (0, 0) for t in ts)
        score = (1.0 if free else 0.0, dist, th)
        if score[:2] > best[:2]:
            best = score
    theta = (omega * prof.t0 + best[2]) % (2 * math.pi * period)
    return float(theta)


def resting_speed(system: Any, values: Mapping[str, float]) -> float | None:
    """The latched approach speed v0 [m/s] given to a contact open over the whole orbit
    (the carrier resting on a wall), the convention of continuation (module docstring):
    the system's ``resting_speed`` where set, else the floor ``min_impact_velocity`` of the
    contact law (``contact.min_impact_velocity`` of a scenario). None (a record without
    that floor): the speed the seeding run latched is kept."""
    v = getattr(system, "resting_speed", None)
    if v is not None:
        return float(v)
    if isinstance(system, ScenarioSystem):
        return float(system.scenario_at(values)["contact.min_impact_velocity"])
    floor = getattr(system.prepare(values).record, "min_impact_velocity", None)
    return None if floor is None else float(floor)


def cuts_from(
    prof: Profile,
    omega: float,
    phase: float,
    period: int,
    segments: int,
    values_t0: float,
    resting_v0: float | None = None,
) -> tuple[Cut, ...]:
    """The cuts of an orbit at ``phase`` from its profile; a contact open over the whole
    orbit gets the latched speed ``resting_v0`` (:func:`resting_speed`; None: the one the
    profile's run latched)."""
    out = []
    P = prof.period
    for j in range(segments):
        t = phase / omega + j * P / segments
        modes, v0 = prof.contact_at(t)
        st = []
        fx = []
        for i in range(2):
            relatched = bool(np.any(prof.onset_pairs == i))
            if modes[i] != 0 and relatched:
                st.append(True)
                fx.append(math.nan)
            elif modes[i] != 0:
                st.append(False)
                fx.append(v0[i] if resting_v0 is None else float(resting_v0))
            else:
                st.append(False)
                fx.append(math.nan)
        out.append(Cut(modes, (st[0], st[1]), (fx[0], fx[1])))
    return tuple(out)


def states_at(
    system: Any,
    values: Mapping[str, float],
    t_from: float,
    y: FloatSeq,
    modes: Sequence[int],
    v0s: FloatSeq,
    times: FloatSeq,
    cuts: Sequence[Cut],
) -> list[np.ndarray]:
    """Integrate from (t_from, y, modes, v0s) through ``times`` and return the state z at
    each (as ``cuts`` lay it out)."""
    prep = system.prepare(values)
    n = 2 * prep.n_coords
    out = []
    t, yy, mm, vv = t_from, np.asarray(y, float), tuple(modes), np.asarray(v0s, float)
    for tc, c in zip(times, cuts, strict=True):
        if tc > t:
            seg = advance(prep, t, tc, yy, mm, vv)
            t, yy, mm, vv = tc, seg.y1, seg.modes1, seg.v0s1
        extra = [vv[i] for i in range(2) if c.v0_state[i]]
        out.append(np.concatenate([yy[:n], extra]))
    return out


def _wrap(theta: float, period: int) -> float:
    """theta modulo 2 pi k, with values within 1e-9 of 2 pi k read as 0."""
    full = 2 * math.pi * period
    th = theta % full
    return 0.0 if abs(th - full) < 1e-9 else float(th)


def reseat(orbit: Orbit, system: Any, method: str = "auto") -> Orbit:
    """The same orbit cut at a new phase away from onsets and exits (same multipliers)."""
    prep = system.prepare(orbit.values)
    w = prep.omega
    m = orbit.segments
    th = choose_phase(orbit.profile, w, orbit.period, m)
    n = 2 * prep.n_coords
    c0 = orbit.cuts[0]
    t0 = orbit.phase / w
    if th / w < t0:
        th += 2 * math.pi * orbit.period
    cuts = cuts_from(orbit.profile, w, th, orbit.period, m, t0, resting_speed(system, orbit.values))
    P = orbit.period * prep.period
    times = th / w + np.arange(m) * P / m
    z = states_at(
        system, orbit.values, t0, orbit.z[0][:n], c0.modes, c0.v0s(orbit.z[0][n:]), times, cuts
    )
    th_mod = _wrap(th, orbit.period)
    return solve_fixed(system, orbit.values, orbit.period, th_mod, cuts, z, method)


# --------------------------------------------------------------------------------------
# seeding
# --------------------------------------------------------------------------------------


def simulate_state(
    system: Any, values: Mapping[str, float], cycles: float
) -> tuple[float, np.ndarray, tuple[int, int], np.ndarray]:
    """Simulate the system's own start for ``cycles`` forcing periods: (t, y, modes, v0s),
    y in the slot's frame (``system`` module docstring)."""
    prep = system.prepare(values)
    t_end = cycles * prep.period
    if isinstance(system, ScenarioSystem):
        from braidsim.model import build_model
        from braidsim.simulate import final_state, run_model

        model = build_model(system.scenario_at(values), t_end)
        raw = run_model(model, series=False, record_events=False, energy=False, xsq=False)
        fs = final_state(raw)
        n = 2 * prep.n_coords
        m = (fs.track_mode, fs.slot_mode)
        v = np.array([fs.track_v0 if m[0] else math.nan, fs.slot_v0 if m[1] else math.nan])
        return fs.t, prep.to_slot(fs.t, np.array(fs.y[:n])), m, v
    y0, _ = system.initial_state(values)
    seg = advance(prep, 0.0, t_end, y0, (0, 0), (math.nan, math.nan))
    return t_end, seg.y1, seg.modes1, seg.v0s1


def seed_orbit(
    system: Any,
    values: Mapping[str, float],
    period: int = 1,
    *,
    segments: int = 1,
    transient_cycles: float = 300,
    method: str = "auto",
    tol: float = DEFAULT_TOL,
    state: FloatSeq | None = None,
    start: tuple[float, np.ndarray, tuple[int, int], np.ndarray] | None = None,
) -> Orbit:
    """A period-``period`` orbit from the steady state simulated for ``transient_cycles``
    forcing cycles, or from ``state``: (x, vx[, y, vy]) at forcing phase 0 (t = 0) in free
    flight, from which Newton's method starts as it is.

    Raises
    ------
    InputError
        ``state`` given and Newton does not converge from it (not near an orbit).
    ContinuationError
        The simulated steady state is not near a period-``period`` orbit.
    """
    if int(period) != period or period < 1:
        raise InputError(
            f"continuation.period: {period!r} is out of range; allowed an integer >= 1"
        )
    if int(segments) != segments or segments < 1:
        raise InputError(
            f"continuation.segments: {segments!r} is out of range; allowed an integer >= 1"
        )
    if method not in METHODS:  # (before the transient's simulation, not after it)
        raise InputError(
            f"continuation.method: {method!r} is not allowed; allowed {', '.join(METHODS)}"
        )
    prep = system.prepare(values)
    T = prep.period
    if state is not None:
        y = np.asarray(state, dtype=float)
        if y.shape != (2 * prep.n_coords,):
            raise InputError(
                f"continuation.seed: needs {2 * prep.n_coords} numbers (x, vx[, y, vy]); "
                f"got {y.size}"
            )
        # a user seed is the state at forcing phase 0 (t = 0), in free flight; Newton starts
        # from it as it is, cut at that phase
        t, modes, v0 = 0.0, (0, 0), np.array([math.nan, math.nan])
        prof = profile(system, values, t, period, y, modes, v0)
        cuts = cuts_from(prof, prep.omega, 0.0, period, segments, t, resting_speed(system, values))
        times = t + np.arange(segments) * period * T / segments
        z = states_at(system, values, t, y, modes, v0, times, cuts)
        try:
            return solve_fixed(system, values, period, 0.0, cuts, z, method, tol)
        except (ContinuationError, SectionChanged) as exc:
            where = ", ".join(f"{k} = {v:g}" for k, v in values.items())
            raise InputError(
                f"continuation.seed: the state {tuple(float(v) for v in state)} is not near a "
                f"period-{period} orbit at {where or 'the base values'} ({exc}); allowed a "
                "state close to an orbit, or leave seed out to start from a simulated steady "
                "state"
            ) from None
    elif start is not None:
        # from a given hybrid state (t, y, modes, v0s): simulate the transient from there
        t, y, modes, v0 = start
        n_per = math.ceil(transient_cycles)
        t_end = (math.floor(t / T + 1e-9) + n_per) * T
        seg = advance(prep, t, t_end, np.asarray(y, float), modes, np.asarray(v0, float))
        t, y, modes, v0 = t_end, seg.y1, seg.modes1, seg.v0s1
    else:
        t, y, modes, v0 = simulate_state(system, values, math.ceil(transient_cycles))
        t = math.ceil(transient_cycles) * T
    prof = profile(system, values, t, period, y, modes, v0)
    th = choose_phase(prof, prep.omega, period, segments)
    t_cut = th / prep.omega
    while t_cut < t:
        t_cut += period * T
    cuts = cuts_from(
        prof, prep.omega, t_cut * prep.omega, period, segments, t, resting_speed(system, values)
    )
    times = t_cut + np.arange(segments) * period * T / segments
    z = states_at(system, values, t, y, modes, v0, times, cuts)
    th_mod = _wrap(th, period)
    try:
        orbit = solve_fixed(system, values, period, th_mod, cuts, z, method, tol)
    except ContinuationError as exc:
        where = ", ".join(f"{k} = {v:g}" for k, v in values.items())
        q = _simulated_period(system, values, t, y, modes, v0, period)
        hint = (
            f"the simulated motion repeats every {q} cycles: set period = {q}"
            if q is not None and q != period
            else "lengthen transient_cycles or start from another value"
        )
        raise ContinuationError(
            f"the period-{period} orbit did not converge from the steady state simulated for "
            f"{transient_cycles:g} cycles at {where or 'the base values'} ({exc}); {hint}",
            t,
        ) from None
    # the steady state must be near a period-k orbit, as documented: Newton's method also
    # converges from a run that repeats with another period, or not at all, to an unstable
    # period-k orbit far from anything the machine does (paper-3.3 at h_a = 0.12 mm: a
    # period-1 orbit with |mu| = 4.2, 3.2 scales from the run)
    shown = _simulated_period(system, values, t, y, modes, v0, period)
    if shown is None or period % shown:
        where = ", ".join(f"{k} = {v:g}" for k, v in values.items())
        Ls, Vs = system.scales(values)
        scale = np.tile([Ls, Vs], prep.n_coords)  # (the coordinates and speeds)
        off = max(
            float(np.abs((zi[: scale.size] - oi[: scale.size]) / scale).max())
            for zi, oi in zip(z, orbit.z, strict=True)
        )
        if shown is not None or off > NEAR_DISTANCE:
            what = (
                f"repeats every {shown} cycles: set period = {shown}"
                if shown is not None
                else "does not repeat within 12 cycles (to 1e-4 of the length and speed "
                "scales): lengthen transient_cycles, start from another value, or give a "
                "seed state"
            )
            stab = "a stable" if orbit.stable else "an unstable"
            raise ContinuationError(
                f"the steady state simulated for {transient_cycles:g} cycles at "
                f"{where or 'the base values'} is not near a period-{period} orbit (Newton's "
                f"method found {stab} one {off:.3g} scales away from it): the motion {what}",
                t,
            )
    q = minimal_period(orbit, system)
    if q < period:
        where = ", ".join(f"{k} = {v:g}" for k, v in values.items())
        raise ContinuationError(
            f"the steady state at {where or 'the base values'} is a period-{q} orbit, not a "
            f"period-{period} one; set period = {q} (or seed the period-{period} orbit from a "
            "period doubling of it: continuation.switch)",
            t,
        )
    return orbit


NEAR_DISTANCE = 0.1
"""Largest distance, in the length and speed scales, between the simulated steady state and
the period-k orbit Newton's method found from it, for a run that does not repeat within its
12 test cycles (a slowly attracting orbit, or a motion that hovers near an unstable one) to
count as near that orbit. Measured on paper-3.3: the period-3 orbit the run at h_a = 0.12
mm hovers near lies 0.041 scales from it, the unstable period-1 orbits Newton's method also
finds from the runs at 0.12 and 0.15 mm 3.2 and 0.66 scales."""


def minimal_period(orbit: Orbit, system: Any) -> int:
    """The smallest q dividing the orbit's period k whose stroboscopic samples repeat after
    q cycles (to 1e-6 of the length and speed scales)."""
    k = orbit.period
    su, sv = orbit.profile.strobe_u, orbit.profile.strobe_v
    if su.size < k:
        return k
    Ls, Vs = system.scales(orbit.values)
    for q in range(1, k):
        if k % q:
            continue
        du = np.abs(su - np.roll(su, -q)).max() / Ls
        dv = np.abs(sv - np.roll(sv, -q)).max() / Vs
        if du < 1e-6 and dv < 1e-6:
            return q
    return k


def _simulated_period(
    system: Any,
    values: Mapping[str, float],
    t: float,
    y: FloatSeq,
    modes: Any,
    v0: Any,
    period: int,
) -> int | None:
    from braidsim.analysis.regimes import detect_period

    prep = system.prepare(values)
    T = prep.period
    cycles = 24
    st = t + T * np.arange(cycles + 1)
    seg = advance(prep, t, st[-1], y, modes, v0, st)
    rows = seg.series
    if rows is None:
        return None
    keep = np.isin(rows[:, 0], st)
    Ls, Vs = system.scales(values)
    z = np.column_stack([rows[keep, 1] / Ls, rows[keep, 2] / Vs])
    return detect_period(z, 1e-4, 12)


def with_values(orbit: Orbit, **kw: Any) -> Orbit:
    """A copy with fields replaced."""
    return replace(orbit, **kw)


def recut(
    orbit: Orbit, system: Any, phase: float, segments: int | None = None, method: str = "auto"
) -> Orbit:
    """The same orbit cut at the forcing phase ``phase`` [rad] (into ``segments`` shooting
    segments, default as before) and solved again: its multipliers do not depend on the
    cut, which may lie inside a contact (the latched speed then joins the state)."""
    prep = system.prepare(orbit.values)
    w = prep.omega
    m = orbit.segments if segments is None else int(segments)
    n = 2 * prep.n_coords
    t0 = orbit.phase / w
    th = float(phase)
    while th / w < t0:
        th += 2 * math.pi * orbit.period
    cuts = cuts_from(orbit.profile, w, th, orbit.period, m, t0, resting_speed(system, orbit.values))
    P = orbit.period * prep.period
    times = th / w + np.arange(m) * P / m
    c0 = orbit.cuts[0]
    z = states_at(
        system, orbit.values, t0, orbit.z[0][:n], c0.modes, c0.v0s(orbit.z[0][n:]), times, cuts
    )
    return solve_fixed(system, orbit.values, orbit.period, _wrap(th, orbit.period), cuts, z, method)
