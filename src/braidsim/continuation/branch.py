"""Pseudo-arclength continuation of periodic orbits, with bifurcations and grazing.

Continuation
------------
The orbits of one structure (period, cuts) satisfy r(U) = 0, U = (scaled states, lambda / P),
one equation fewer than unknowns: a curve. From a point U_i with unit tangent tau_i (the null
vector of Dr(U_i), oriented as the last one) the next is found by the predictor
U_p = U_i + h tau_i and Newton's method on

    r(U) = 0,    tau_i . (U - U_p) = 0

(Keller, H. B. (1977), Numerical solution of bifurcation and nonlinear eigenvalue problems,
in Applications of Bifurcation Theory, Academic Press, 359-384). The step h grows by 1.5
after a corrector of at most 2 iterations and halves after a failure, between ``min_step``
and ``max_step`` (in units of the scaled arclength: lambda in units of P = |to - from|, the
state in units of L and L Omega).

Special points between two consecutive points
---------------------------------------------
* fold: the parameter component of the tangent changes sign (a multiplier crosses +1);
* period doubling: det(M + I) changes sign (a real multiplier crosses -1);
* Neimark-Sacker: a complex pair crosses the unit circle (|mu| - 1 of the pair nearest the
  circle changes sign, complex on both sides);
* grazing: the orbit's contact structure changes (contact onsets per orbit, their walls, or
  the contacts at a cut): a free-flight gap minimum or a contact's depth reached zero.

Each is located on the secant between the two points (points corrected back onto the
branch on hyperplanes orthogonal to the secant): by the Illinois variant of regula falsi on
its test function, by bisection on the contact structure for grazing. Smooth test functions
and the nonsmooth grazing are kept apart: a multiplier that jumps across the unit circle at
a grazing is reported as the grazing, not as a bifurcation.

Branch switching at period doubling: the period-2k orbit is sought near the doubling
point at lambda* +/- delta from z* +/- eps w on alternate periods (w the eigenvector of
multiplier -1), and continued away from lambda*.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from braidsim.continuation.orbit import (
    DEFAULT_TOL,
    ContinuationError,
    Cut,
    Orbit,
    Shooter,
    cuts_from,
    finish,
    reseat,
    resting_speed,
    solve_fixed,
    states_at,
)
from braidsim.errors import InputError, SimulationError

SPECIAL_TYPES = ("fold", "period_doubling", "neimark_sacker", "grazing")
GRAZING_REACH = 0.05
"""A grazing's zero extrapolated from the last orbits of the approaching family is accepted
up to this fraction of the branch step beyond the last orbit found (the family's corrector
gives up just before a stiff contact lifts off)."""
BRACKET_TOL = 1e-6
"""Newton tolerance of a grazing's bisection where, at the continuation's tolerance, its
bracket closed well short of the family's extrapolated zero: the orbits of the bracket only
tell on which side of the grazing a parameter value lies and how far from it. Next to a
stiff contact's lift-off the flow map's own noise reaches 1e-9 to 1e-7 of the scaled
residual (the damped contact's force sits at zero for part of the cycle), and Newton's
method at 1e-8 fails there erratically: on paper-3.3 at 4.5 pi rad/s the bracket closed
0.37 % short of where plain runs put the lift-off (at 1e-7 still 0.33 % short)."""
LOCATE_RTOL = 1e-9
"""Bracket width, relative to the continuation's parameter scale |to - from|, to which
fold, period-doubling and Neimark-Sacker points are located."""
ZERO_FRACTION = 1e-4
"""A located sign change of a test function is a zero (a bifurcation) only where |f| at the
located point is at most this fraction of the change of f across the two branch points (and,
along a chord, where the bracket closed): a zero located to a bracket of 1e-9 leaves about
1e-9 of it, a pole (a multiplier jumping through infinity) as much as at the ends. On
paper-3.3's resting branch at 4 pi rad/s (finite-difference map, max_step 0.03) a fold was
reported at h_a = 0.12875 mm with multipliers -1.24 and -0.003, where a step had landed on
another family of the same contacts; it is a note now."""


RETRIES_WITHOUT_A_ZERO = 3
"""Times a step whose test function changed sign without a zero is tried again, halved each
time, before its note is kept: a step that landed on another family then lands on its own
(paper-3.3's resting branch at 4 pi rad/s with max_step 0.03 passed over a period doubling
at 0.12850 mm), while a multiplier jumping through infinity where a contact's depth minimum
touches zero stays a note after three halvings."""


def lam_of(o: Orbit, key: str) -> float:
    """The orbit's value of the continuation parameter [SI]."""
    return float(o.values[key])


@dataclass
class SpecialPoint:
    """A bifurcation or grazing located on a branch.

    Attributes
    ----------
    type : str
        One of :data:`SPECIAL_TYPES`.
    value : float
        The parameter there [SI].
    period : int
        The orbit's period [forcing cycles].
    index : int
        The branch point after which it lies.
    orbit : Orbit or None
        The orbit there (for grazing: the last orbit of the earlier structure).
    detail : str
        What changed (multiplier, walls).
    other : Orbit or None
        For grazing: the first orbit of the other structure.
    tolerance : float
        Width of the parameter bracket the point was located in [SI] (NaN: not located
        by a bracketing solve).
    """

    type: str
    value: float
    period: int
    index: int
    orbit: Orbit | None = None
    detail: str = ""
    other: Orbit | None = field(default=None, repr=False)
    tolerance: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (SI)."""
        return {
            "type": self.type,
            "value": self.value,
            "period": self.period,
            "detail": self.detail,
            "tolerance": self.tolerance,
        }


@dataclass
class Branch:
    """A continued branch of periodic orbits.

    Attributes
    ----------
    key : str
        The continuation parameter.
    period : int
        k [forcing cycles].
    points : list of Orbit
        The orbits, in arclength order.
    special : list of SpecialPoint
    stop : str
        Why the continuation ended.
    children : list of Branch
        Branches switched to at period doublings.
    notes : list of str
        What the detection saw and did not report: a test function that changed sign
        without a zero between two points (:meth:`Continuer._locate`).
    """

    key: str
    period: int
    points: list[Orbit] = field(default_factory=list)
    special: list[SpecialPoint] = field(default_factory=list)
    stop: str = ""
    children: list[Branch] = field(default_factory=list)
    tangents: list[np.ndarray] = field(default_factory=list, repr=False)
    steps: list[float] = field(default_factory=list, repr=False)
    notes: list[str] = field(default_factory=list)

    @property
    def values(self) -> np.ndarray:
        """The parameter at each point [SI]."""
        return np.array([o.values[self.key] for o in self.points])

    @property
    def stable(self) -> np.ndarray:
        """Stability of each point."""
        return np.array([o.stable for o in self.points])

    def all_branches(self) -> list[Branch]:
        """This branch and its children, depth first."""
        out = [self]
        for c in self.children:
            out.extend(c.all_branches())
        return out


def _test_pd(o: Orbit) -> float:
    M = o.monodromy
    return float(np.linalg.det(M + np.eye(M.shape[0])))


def _below_minus_one(o: Orbit) -> int:
    """Real multipliers below -1 (a period doubling changes their number by one; a
    sign change of det(M + I) without it is a complex pair turning real, or noise)."""
    mu = o.multipliers
    real = np.abs(mu.imag) <= 1e-9 * np.maximum(1.0, np.abs(mu))
    return int(np.count_nonzero(real & (mu.real < -1.0)))


def _test_ns(o: Orbit) -> float | None:
    mu = o.multipliers
    cx = mu[np.abs(mu.imag) > 1e-9 * np.maximum(1.0, np.abs(mu))]
    if cx.size == 0:
        return None
    return float(np.abs(cx[np.argmin(np.abs(np.abs(cx) - 1.0))]) - 1.0)


def signature(o: Orbit) -> tuple[Any, ...]:
    """The contact structure of an orbit: onsets per orbit on each wall and the contacts at
    the cuts (a change between two points is a grazing)."""
    p = o.profile
    walls = tuple(sorted(zip(p.onset_pairs.tolist(), p.onset_walls.tolist(), strict=True)))
    return (walls, tuple(c.modes for c in o.cuts), tuple(c.v0_state for c in o.cuts))


def grazing_zero(points: list[tuple[float, float]]) -> float | None:
    """Where the distance to grazing a(s) of a family's orbits extrapolates to zero, from
    (s, a) pairs: the line through the orbit nearest the grazing (smallest a) and the
    nearest one with at least twice its distance, so that the secant spans the
    extrapolation (two orbits a bracket's width apart differ by little more than the
    noise of a). None without two usable points."""
    pts = sorted((p for p in points if math.isfinite(p[1]) and p[1] > 0.0), key=lambda p: p[1])
    if len(pts) < 2:
        return None
    s2, a2 = pts[0]
    far = [p for p in pts[1:] if p[1] >= 2.0 * a2 and p[0] != s2]
    s1, a1 = min(far, key=lambda p: p[1]) if far else pts[-1]
    if a1 == a2 or s1 == s2:
        return None
    return float(s2 - a2 * (s2 - s1) / (a2 - a1))


def _heading(tau: np.ndarray, direction: float) -> float:
    """The direction the parameter moves along ``tau`` (``direction`` where it stands)."""
    return float(np.sign(tau[-1])) if abs(tau[-1]) > 1e-12 else direction


def _null_vector(DR: np.ndarray) -> np.ndarray:
    _, _, vt = np.linalg.svd(DR)
    v = vt[-1]
    return v / np.linalg.norm(v)


class Continuer:
    """Runs the continuation of one branch (see :func:`continue_orbit`)."""

    def __init__(
        self,
        system: Any,
        key: str,
        bounds: tuple[float, float],
        *,
        method: str = "auto",
        tol: float = DEFAULT_TOL,
        step: float = 0.02,
        min_step: float = 1e-6,
        max_step: float = 0.1,
        max_points: int = 200,
        pscale: float | None = None,
        on_point: Callable[[Orbit], None] | None = None,
        stop_on: str | None = None,
    ) -> None:
        lo, hi = sorted(bounds)
        self.stop_on = stop_on
        self.system = system
        self.key = key
        self.lo, self.hi = lo, hi
        self.method = method
        self.tol = tol
        self.h0, self.hmin, self.hmax = step, min_step, max_step
        self.max_points = max_points
        self.pscale = pscale if pscale else (hi - lo if hi > lo else max(abs(hi), 1.0))
        self.on_point = on_point
        self.not_a_zero = False  # set by the last detection that noted a sign change without a zero

    # -- pieces ----------------------------------------------------------------------
    def shooter(self, o: Orbit) -> Shooter:
        return Shooter(
            self.system,
            dict(o.values),
            self.key,
            o.period,
            o.phase,
            o.cuts,
            self.method,
            self.pscale,
        )

    def tangent(
        self, sh: Shooter, U: np.ndarray, prev: np.ndarray | None, direction: float
    ) -> np.ndarray:
        _, DR, _ = sh.residual(U)
        tau = _null_vector(DR)
        if prev is not None and prev.size == tau.size:
            if float(tau @ prev) < 0:
                tau = -tau
        elif tau[-1] * direction < 0:
            tau = -tau
        return tau

    def setup(
        self, o: Orbit, prev: np.ndarray | None, direction: float
    ) -> tuple[Shooter, np.ndarray, np.ndarray]:
        """The shooter of ``o``'s structure, its unknowns and unit tangent (oriented as
        ``prev``, or else with the parameter moving in ``direction``)."""
        sh = self.shooter(o)
        U = sh.pack(o.z, o.values[self.key])
        return sh, U, self.tangent(sh, U, prev, direction)

    def correct(self, sh: Shooter, Up: np.ndarray, normal: np.ndarray) -> Orbit:
        """Newton on r(U) = 0, normal . (U - Up) = 0."""
        from braidsim.continuation.orbit import newton

        def F(U: np.ndarray, accurate: bool = False) -> tuple[np.ndarray, np.ndarray, Any]:
            R, DR, Js = sh.residual(U, accurate)
            G = np.concatenate([R, [float(normal @ (U - Up))]])
            return G, np.vstack([DR, normal]), Js

        def final(U: np.ndarray) -> tuple[np.ndarray, np.ndarray, Any] | None:
            return F(U, True) if sh.rough else None

        U, res, its, Js = newton(F, Up, self.tol, max_iter=8, final=final)
        o = finish(sh, U, res, its, Js)
        return o

    def at_value(self, sh: Shooter, U0: np.ndarray, lam: float) -> Orbit:
        """Correct onto the branch at the parameter value ``lam``."""
        e = np.zeros(U0.size)
        e[-1] = 1.0
        Up = U0.copy()
        Up[-1] = lam / self.pscale
        return self.correct(sh, Up, e)

    def land(
        self, sh: Shooter, U: np.ndarray, tau: np.ndarray, past: Orbit, edge: float
    ) -> Orbit | None:
        """The orbit at the end value ``edge``, from the last point ``U`` (tangent ``tau``)
        whose step ``past`` went beyond it; None where it cannot be found.

        It is sought from the prediction along the tangent first, not from ``past``: a
        step that ends beyond a lift-off lands on the coexisting orbit there (the carrier
        bouncing instead of resting), and the end point found from it was that orbit, with
        a grazing reported between it and the branch (paper-3.3 from 0.05 to 0.0968 mm,
        the lift-off at 0.0983 mm)."""
        attempts = []
        if abs(tau[-1]) > 1e-12:
            attempts.append(U + ((edge / self.pscale - U[-1]) / tau[-1]) * tau)
        attempts.append(sh.pack(past.z, lam_of(past, self.key)))
        for start in attempts:
            try:
                return self.at_value(sh, start, edge)
            except (ContinuationError, SimulationError, np.linalg.LinAlgError):
                continue
        return None

    # -- the run ------------------------------------------------------------------------
    def run(self, start: Orbit, direction: float, branch: Branch | None = None) -> Branch:
        br = branch if branch is not None else Branch(self.key, start.period)
        if branch is None:
            br.points.append(start)
            if self.on_point:
                self.on_point(start)
        o = br.points[-1]
        sh, U, tau = self.setup(o, br.tangents[-1] if br.tangents else None, direction)
        if not br.tangents:
            br.tangents.append(tau)
        h = br.steps[-1] if br.steps else self.h0
        reseated = False
        retries = 0
        while len(br.points) < self.max_points:
            try:
                nxt = self.correct(sh, U + h * tau, tau)
                # a corrector that lands further from the prediction than the step is long
                # has left the branch for a coexisting orbit (next to a grazing the families
                # lie close together): a shorter step instead (on the smooth parts of the
                # paper's branches the correction is below 0.25 of the step, at a jump 200)
                moved = float(np.linalg.norm(sh.pack(nxt.z, lam_of(nxt, self.key)) - U - h * tau))
                if moved > h:
                    raise ContinuationError(
                        f"the corrector moved {moved / h:.3g} steps off the prediction"
                    )
            except (ContinuationError, SimulationError, np.linalg.LinAlgError) as exc:
                h *= 0.5
                if h < self.hmin:
                    if not reseated:
                        try:
                            o = reseat(o, self.system, self.method)
                        except (ContinuationError, SimulationError):
                            lam_o = o.values[self.key]
                            br.stop = (
                                f"step below {self.hmin:g} at {self.key} = {lam_o:.6g} ({exc})"
                            )
                            break
                        sh, U, tau = self.setup(o, None, _heading(tau, direction))
                        h = self.h0
                        reseated = True
                        continue
                    br.stop = (
                        f"step below {self.hmin:g} at {self.key} = {o.values[self.key]:.6g} ({exc})"
                    )
                    jumped = self.past_grazing(
                        br, direction if not br.tangents else float(np.sign(tau[-1]) or direction)
                    )
                    if jumped is None or self.stop_on == "grazing":
                        if jumped is not None:
                            br.stop = "found a grazing point"
                        break
                    o = jumped
                    sh, U, tau = self.setup(o, None, _heading(tau, direction))
                    h = self.h0
                    reseated = False
                    continue
                continue
            reseated = False
            lam = nxt.values[self.key]
            done = False
            if lam > self.hi or lam < self.lo:
                edge = self.hi if lam > self.hi else self.lo
                landed = self.land(sh, U, tau, nxt, edge)
                if landed is None:
                    br.stop = f"could not land on the end value {edge:g}"
                    break
                nxt = landed
                done = True
            try:
                sh_new, U_new, tau_new = self.setup(nxt, tau, direction)
            except (ContinuationError, SimulationError) as exc:
                br.stop = f"tangent failed at {self.key} = {lam:.6g} ({exc})"
                break
            n_special, n_notes = len(br.special), len(br.notes)
            self.not_a_zero = False
            # both ends in the units of ``sh`` (the scales follow the shooter's base values)
            self.detect(br, o, nxt, sh, U, sh.pack(nxt.z, lam_of(nxt, self.key)), tau, tau_new)
            if self.not_a_zero and retries < RETRIES_WITHOUT_A_ZERO and 0.5 * h >= self.hmin:
                # a test function changed sign without a zero: most often the step landed on
                # another family of the same contacts and passed over what lies between
                # (paper-3.3's resting branch at 4 pi rad/s, max_step 0.03: from 0.1273 to
                # 0.1308 mm, over a period doubling at 0.12850 mm); the same step halved
                del br.special[n_special:], br.notes[n_notes:]
                h *= 0.5
                retries += 1
                continue
            retries = 0
            if self.stop_on and any(sp.type == self.stop_on for sp in br.special[n_special:]):
                br.points.append(nxt)
                br.stop = f"found a {self.stop_on} point"
                break
            # a grazing may have changed the cuts' structure: re-solve with the new one
            try:
                nxt2 = self.restructure(nxt)
            except ContinuationError as exc:
                br.stop = str(exc)
                break
            if nxt2 is not nxt:
                nxt = nxt2
                sh_new, U_new, tau_new = self.setup(nxt, None, _heading(tau, direction))
            br.points.append(nxt)
            br.tangents.append(tau_new)
            if self.on_point:
                self.on_point(nxt)
            o, sh, U, tau = nxt, sh_new, U_new, tau_new
            if nxt.iterations <= 2:
                h = min(h * 1.5, self.hmax)
            elif nxt.iterations >= 5:
                h *= 0.7
            br.steps.append(h)
            if len(br.points) > 3 and self._closed(br, sh_new, U_new, h):
                br.stop = f"the branch closed on itself at {self.key} = {lam:.6g}"
                break
            if done:
                br.stop = f"reached {self.key} = {nxt.values[self.key]:.6g}"
                break
            # keep the cuts away from onsets and exits
            prof = o.profile
            T = prof.period / o.period
            w = 2 * math.pi / T
            tcut = o.phase / w
            if any(
                prof.event_distance(tcut + j * prof.period / o.segments) < 0.01 * prof.period
                for j in range(o.segments)
            ):
                try:
                    o = reseat(o, self.system, self.method)
                    br.points[-1] = o
                    sh, U, tau = self.setup(o, None, _heading(tau, direction))
                    br.tangents[-1] = tau
                except (ContinuationError, SimulationError):
                    pass
        else:
            br.stop = f"max_points = {self.max_points} reached"
        return br

    def past_grazing(self, br: Branch, direction: float) -> Orbit | None:
        """Where a family ends at a grazing the corrector cannot step over (a contact that
        lifts off: beyond it the orbit has a new short flight and a new impact): when the
        last points' distance to grazing extrapolates to zero within one step, record the
        grazing there and seed the orbit just beyond it from a run started on the last
        orbit. None when that does not apply or fails."""
        from braidsim.continuation.orbit import seed_orbit

        if len(br.points) < 2:
            return None
        o1, o2 = br.points[-2], br.points[-1]
        a1, a2 = o1.profile.approach, o2.profile.approach
        l1, l2 = o1.values[self.key], o2.values[self.key]
        if not (math.isfinite(a1) and math.isfinite(a2)) or a1 <= a2 or l1 == l2:
            return None
        lg = l2 - a2 * (l2 - l1) / (a2 - a1)
        if abs(lg - l2) > 2 * abs(l2 - l1):
            return None
        sp = SpecialPoint(
            "grazing",
            float(lg),
            o2.period,
            len(br.points) - 1,
            o2,
            "the family ends where its distance to grazing extrapolates to zero",
        )
        br.special.append(sp)
        beyond = lg + 0.5 * (l2 - l1) + 1e-3 * self.pscale * float(np.sign(l2 - l1))
        if not (self.lo <= beyond <= self.hi):
            return None
        n = 2 * self.system.prepare(o2.values).n_coords
        t0 = o2.phase / self.system.prepare(o2.values).omega
        c0 = o2.cuts[0]
        try:
            nxt = seed_orbit(
                self.system,
                {**o2.values, self.key: beyond},
                o2.period,
                segments=o2.segments,
                transient_cycles=100,
                method=self.method,
                tol=self.tol,
                start=(t0, o2.z[0][:n], c0.modes, c0.v0s(o2.z[0][n:])),
            )
        except (ContinuationError, SimulationError, InputError):
            return None
        if signature(nxt) == signature(o2):
            # a run from there settles on an orbit of the same structure (for a resting
            # contact: one with another latched speed, which sets its damping)
            return None
        sp.detail += f"; onsets per orbit {list(signature(o2)[0])} -> {list(signature(nxt)[0])}"
        sp.other = nxt
        br.points.append(nxt)
        if self.on_point:
            self.on_point(nxt)
        br.stop = ""
        return nxt

    def _closed(self, br: Branch, sh: Shooter, U: np.ndarray, h: float) -> bool:
        """Whether the newest point is back at the first one (a closed branch, an isola)."""
        first = br.points[0]
        if first.cuts != br.points[-1].cuts or first.phase != br.points[-1].phase:
            return False
        U0 = sh.pack(first.z, first.values[self.key])
        return bool(U0.size == U.size and np.linalg.norm(U - U0) < 0.5 * h)

    def restructure(self, o: Orbit) -> Orbit:
        """The orbit re-solved with cuts that match its contacts, when they changed (at the
        same phase, else at a phase away from onsets and exits). Raises
        :class:`ContinuationError` where neither converges: the orbit with the old cuts is a
        fixed point of another map (a contact open at a cut held at the resting speed while
        it re-latches within the period), not an orbit of the system."""
        prep = self.system.prepare(o.values)
        cuts = cuts_from(
            o.profile,
            prep.omega,
            o.phase,
            o.period,
            o.segments,
            0.0,
            resting_speed(self.system, o.values),
        )
        if cuts == o.cuts or (
            [c.modes for c in cuts] == [c.modes for c in o.cuts]
            and [c.v0_state for c in cuts] == [c.v0_state for c in o.cuts]
        ):
            return o
        n = 2 * prep.n_coords
        c0 = o.cuts[0]
        t0 = o.phase / prep.omega
        # the states one period on: a contact open at a cut that now re-latches carries
        # the speed of its onset there, where the old cut held the resting speed (from
        # that, Newton's method failed on paper-3.3's xy carrier just past its lift-off,
        # and the branch went on with the old cuts: orbits of another map)
        times = t0 + o.profile.period * (1.0 + np.arange(o.segments) / o.segments)
        try:
            z = states_at(
                self.system, o.values, t0, o.z[0][:n], c0.modes, c0.v0s(o.z[0][n:]), times, cuts
            )
            return solve_fixed(
                self.system, o.values, o.period, o.phase, cuts, z, self.method, self.tol
            )
        except (ContinuationError, SimulationError) as exc:
            try:
                return reseat(o, self.system, self.method)
            except (ContinuationError, SimulationError):
                raise ContinuationError(
                    f"the contacts at the cuts changed at {self.key} = "
                    f"{o.values[self.key]:.6g} and the orbit did not converge with the new "
                    f"ones ({exc})"
                ) from None

    # -- detection and location ------------------------------------------------------
    def _secant_point(self, sh: Shooter, Ua: np.ndarray, Ub: np.ndarray, t: float) -> Orbit:
        d = Ub - Ua
        return self.correct(sh, Ua + t * d, d / np.linalg.norm(d))

    def _illinois(
        self,
        fa: float,
        fb: float,
        trial: Callable[[float], tuple[Orbit, float | None]],
        xtol: float,
    ) -> tuple[Orbit | None, float, float, float]:
        """The Illinois variant of regula falsi on [0, 1] (Dowell, M. and Jarratt, P.
        (1971), BIT 11, 168-174, doi:10.1007/BF01934364): ``trial(t)`` gives the orbit at
        t and its test function. Returns (the trial orbit with the smallest |f|, the zero
        of the final bracket's secant, the bracket's width, that smallest |f|); stops when
        the width is below ``xtol`` or f vanishes."""
        a, b = 0.0, 1.0
        best: Orbit | None = None
        fbest = math.inf
        side = 0
        for _ in range(60):
            t = (a * fb - b * fa) / (fb - fa) if fb != fa else 0.5 * (a + b)
            # keep the trial inside the bracket (and away from its ends, so that it shrinks)
            t = min(max(t, a + 0.01 * (b - a)), b - 0.01 * (b - a))
            try:
                o, ft = trial(t)
            except (ContinuationError, SimulationError, np.linalg.LinAlgError):
                break
            if ft is None:
                break
            if abs(ft) < fbest:
                best, fbest = o, abs(ft)
            if ft == 0.0:
                return best, t, 0.0, 0.0
            if (ft > 0) == (fa > 0):
                a, fa = t, ft
                if side == -1:
                    fb *= 0.5
                side = -1
            else:
                b, fb = t, ft
                if side == 1:
                    fa *= 0.5
                side = 1
            if b - a < xtol:
                break
        t_star = (a * fb - b * fa) / (fb - fa) if fb != fa else 0.5 * (a + b)
        return best, float(t_star), float(b - a), float(fbest)

    def _locate(
        self,
        sh: Shooter,
        Ua: np.ndarray,
        Ub: np.ndarray,
        fa: float,
        fb: float,
        f: Callable[[Orbit], float | None],
        monotone: bool = True,
    ) -> tuple[Orbit | None, float, float, bool]:
        """Locate the zero of ``f`` between two branch points by bracketing along the
        branch. Where the branch is a graph over the parameter (no fold between them) the
        unknown is the parameter itself and each trial orbit is found by Newton's method
        at that fixed value (:meth:`at_value`) from the nearer end; otherwise (``monotone``
        False: a fold between them) the unknown is the position on the chord and the trial
        is corrected onto the branch on the hyperplane normal to the chord. Returns
        (orbit, value [SI], bracket width [SI], whether it is a zero): a sign change of
        ``f`` is a zero only where the located point's |f| is at most :data:`ZERO_FRACTION`
        of the change of ``f`` across the bracket. Where ``f`` changes sign through a pole
        instead (a multiplier that jumps through infinity as a contact's depth minimum
        touches zero inside a contact, which the contact structure does not show; or a
        finite-difference map whose runs straddle such a touch), the search closes on the
        pole with |f| as large as at the ends, or fails."""
        la, lb = float(Ua[-1]) * self.pscale, float(Ub[-1]) * self.pscale
        xtol_abs = LOCATE_RTOL * self.pscale
        if monotone and la != lb:

            def trial(t: float) -> tuple[Orbit, float | None]:
                lam = la + t * (lb - la)
                U0 = Ua if t < 0.5 else Ub
                o = self.at_value(sh, U0, lam)
                return o, f(o)

            o, t_star, w, fo = self._illinois(fa, fb, trial, xtol_abs / abs(lb - la))
            if o is not None and w * abs(lb - la) <= 100 * xtol_abs:
                zero = fo <= ZERO_FRACTION * abs(fb - fa)
                return o, la + t_star * (lb - la), w * abs(lb - la), zero

        def on_chord(t: float) -> tuple[Orbit, float | None]:
            o = self._secant_point(sh, Ua, Ub, t)
            return o, f(o)

        o, t_star, w, fo = self._illinois(fa, fb, on_chord, 1e-9)
        if o is None:
            return None, 0.5 * (la + lb), abs(lb - la), False
        zero = w <= 1e-6 and fo <= ZERO_FRACTION * abs(fb - fa)
        return o, lam_of(o, self.key), w * abs(lb - la), zero

    def _locate_grazing(self, oa: Orbit, ob: Orbit) -> tuple[Orbit | None, Orbit | None]:
        """Bisect in the parameter between two orbits of different contact structure. Each
        trial is solved at fixed parameter from the last orbit of ``oa``'s structure, so the
        bracket closes on where *that* family grazes (a family of the other structure may
        overlap it: hysteresis at a grazing)."""
        sig_a = signature(oa)
        lo, hi = oa.values[self.key], ob.values[self.key]
        hist = [oa]
        la, lb, best_a, best_b = self._bisect(sig_a, lo, hi, oa, ob, hist, None)

        def distance(o: Orbit) -> float:
            return min(o.profile.approach, o.profile.feature)

        def zero() -> float | None:
            # the distance to grazing is linear in the parameter near a regular grazing: the
            # secant of the last two orbits' distances finds its zero when the corrector
            # gave up before the bracket closed (a stiff contact near lift-off). The
            # distance is the nearer of the two kinds: a gap or depth minimum that touches
            # zero (approach: a contact about to appear, a resting contact about to lift
            # off) and the least contact depth or flight height (feature: a contact about
            # to vanish, approached from the impacting side, whose approach stays at the
            # far wall: that placed a forced oscillator's grazing 5.8e-4 to 1.3e-2 beyond
            # the closed form's, now within 2e-4)
            return grazing_zero([(o.values[self.key], distance(o)) for o in hist])

        lg = zero()
        reach = GRAZING_REACH * abs(hi - lo)

        def short(lg: float | None) -> bool:
            # the bracket closed well short of the family's zero, which lies before the
            # other structure's orbit
            return (
                lg is not None
                and (lg - la) * (lb - la) > 0
                and abs(lg - la) > max(reach, abs(lb - la))
                and (hi - lg) * (hi - lo) > 0
            )

        if short(lg):
            # Newton's method at the continuation's tolerance failed on the map's own noise
            # (see BRACKET_TOL); the family carried on at that one
            la, lb, best_a, best_b = self._bisect(sig_a, la, hi, best_a, best_b, hist, BRACKET_TOL)
            lg = zero()
        near = lg is not None and (lg - la) * (lb - la) > 0 and abs(lg - la) <= reach
        if short(lg) or (not near and distance(best_a) > 0.1 * max(distance(o) for o in hist)):
            # or Newton's method failed from the orbit as it is cut: cut anew, away from
            # onsets and exits (paper-3.3's xy carrier past its lift-off, cut inside the
            # contact whose latched speed is a state: Newton's method diverged from an
            # orbit 1e-11 m of h_a away at 0.1037 mm, its distance to grazing still
            # 2.2e-7 m; cut in the flight, the family carries on to 0.10587 mm)
            try:
                cut_anew = reseat(best_a, self.system, self.method)
            except (ContinuationError, SimulationError):
                cut_anew = None
            # (the same onsets; the cuts' part of the signature is the new cuts')
            if cut_anew is not None and signature(cut_anew)[0] == sig_a[0]:
                hist.append(cut_anew)
                la, lb, best_a, best_b = self._bisect(
                    signature(cut_anew), la, hi, cut_anew, best_b, hist, None
                )
                lg = zero()
        self.grazing_value = float(la)
        if lg is not None and min(la, lb) <= lg <= max(la, lb):
            self.grazing_value = float(lg)
        elif lg is not None and (lg - la) * (lb - la) > 0 and abs(lg - la) <= reach:
            # the family ends just short of its zero (Newton's iterates fall onto the other
            # structure next to a stiff contact's lift-off): extrapolated, as past_grazing does
            self.grazing_value = float(lg)
        return best_a, best_b

    def _bisect(
        self,
        sig_a: tuple[Any, ...],
        la: float,
        lb: float,
        best_a: Orbit,
        best_b: Orbit | None,
        hist: list[Orbit],
        tol: float | None,
    ) -> tuple[float, float, Orbit, Orbit | None]:
        """Bisection of :meth:`_locate_grazing` from the bracket (la, lb); the orbits of
        ``sig_a`` found are appended to ``hist``. Returns the bracket and its end orbits."""
        for _ in range(40):
            lam = 0.5 * (la + lb)
            o = self._carry(best_a, lam, sig_a, hist[-2] if len(hist) > 1 else None, tol)
            if o is not None and signature(o) == sig_a:
                la, best_a = lam, o
                hist.append(o)
            else:
                lb = lam
                if o is not None:
                    best_b = o
            if abs(lb - la) < 1e-7 * self.pscale:
                break
        return la, lb, best_a, best_b

    def _carry(
        self,
        o: Orbit,
        lam: float,
        sig: tuple[Any, ...],
        prev: Orbit | None = None,
        tol: float | None = None,
    ) -> Orbit | None:
        """The orbit of ``o``'s family at ``lam`` by Newton's method from ``o`` (its state
        extrapolated along the secant from ``prev``, an orbit of the family, where given);
        where that lands on another structure or fails, again in 4, then 16 shorter steps
        (the structures coexist next to a grazing, and a long jump can land on the other
        one). ``tol``: Newton's tolerance where looser than the continuation's. None where
        Newton fails."""
        out: Orbit | None = None
        l0 = o.values[self.key]
        slope: list[np.ndarray] | None = None
        if prev is not None and prev.cuts == o.cuts and prev.values[self.key] != l0:
            dl = l0 - prev.values[self.key]
            slope = [(a - b) / dl for a, b in zip(o.z, prev.z, strict=True)]
        for n in (1, 4, 16):
            cur: Orbit | None = o
            for j in range(1, n + 1):
                assert cur is not None
                lj = l0 + (lam - l0) * j / n
                lc = cur.values[self.key]
                z0 = (
                    [z + d * (lj - lc) for z, d in zip(cur.z, slope, strict=True)]
                    if slope is not None
                    else cur.z
                )
                try:
                    cur = solve_fixed(
                        self.system,
                        {**cur.values, self.key: lj},
                        cur.period,
                        cur.phase,
                        cur.cuts,
                        z0,
                        self.method,
                        self.tol if tol is None else max(tol, self.tol),
                    )
                except (ContinuationError, SimulationError, np.linalg.LinAlgError):
                    cur = None
                    break
                if signature(cur) != sig:
                    break
            if cur is not None:
                out = cur
                if signature(cur) == sig:
                    return cur
        return out

    def detect(
        self,
        br: Branch,
        oa: Orbit,
        ob: Orbit,
        sh: Shooter,
        Ua: np.ndarray,
        Ub: np.ndarray,
        ta: np.ndarray,
        tb: np.ndarray,
    ) -> None:
        idx = len(br.points) - 1
        k = oa.period
        if signature(oa) != signature(ob):
            ga, gb = self._locate_grazing(oa, ob)
            lam = self.grazing_value
            pa, pb = signature(oa)[0], signature(ob)[0]
            detail = f"onsets per orbit (pair, wall) {list(pa)} -> {list(pb)}"
            if signature(oa)[1:] != signature(ob)[1:]:
                detail += "; contacts at the section change"
            br.special.append(SpecialPoint("grazing", float(lam), k, idx, ga, detail, gb))
            # (the multipliers jump at the grazing: no smooth test across it; next to a
            # grazing of a stiff contact they are not reliable on the near side either)
            return
        self.detect_smooth(br, oa, ob, sh, Ua, Ub, ta, tb, idx)

    def detect_smooth(
        self,
        br: Branch,
        oa: Orbit,
        ob: Orbit,
        sh: Shooter,
        Ua: np.ndarray,
        Ub: np.ndarray,
        ta: np.ndarray,
        tb: np.ndarray,
        idx: int,
    ) -> None:
        """Folds, period doublings and Neimark-Sacker points between two orbits of one
        structure."""
        k = oa.period
        if not (oa.reliable and ob.reliable):
            # (a finite-difference map straddled a change of the contacts at one end: its
            # multipliers and tangent are not the orbit's, and their sign changes say nothing)
            if (
                ta[-1] * tb[-1] < 0
                or _test_pd(oa) * _test_pd(ob) < 0
                or (_test_ns(oa) or 0.0) * (_test_ns(ob) or 0.0) < 0
            ):
                la, lb = lam_of(oa, self.key), lam_of(ob, self.key)
                br.notes.append(
                    f"between {self.key} = {la:.10g} and {lb:.10g} the finite-difference "
                    "multipliers of an orbit closer to a wall than the map's step are not "
                    "reliable: no fold, period doubling or Neimark-Sacker test there "
                    "(method = exact tells)"
                )
            return
        # the parameter is monotone between the points unless a fold lies between them
        monotone = bool(ta[-1] * tb[-1] > 0)
        if ta[-1] * tb[-1] < 0:

            def f_fold(o: Orbit) -> float:
                return float(self.setup(o, ta, 1.0)[2][-1])

            # the parameter is stationary at a fold: regula falsi along the chord on the
            # tangent's parameter component (the bracket width bounds the value's error,
            # which is of second order in it)
            of, lam, w, zero = self._locate(
                sh, Ua, Ub, float(ta[-1]), float(tb[-1]), f_fold, monotone=False
            )
            if zero:
                br.special.append(
                    SpecialPoint("fold", lam, k, idx, of, "a multiplier crosses +1", tolerance=w)
                )
            else:
                self._not_a_zero(br, "the branch turns back (a fold)", oa, ob)
        pa, pb = _test_pd(oa), _test_pd(ob)
        if pa * pb < 0 and _below_minus_one(oa) != _below_minus_one(ob):
            op, lam, w, zero = self._locate(sh, Ua, Ub, pa, pb, _test_pd, monotone)
            if zero:
                br.special.append(
                    SpecialPoint(
                        "period_doubling", lam, k, idx, op, "a multiplier crosses -1", tolerance=w
                    )
                )
            else:
                self._not_a_zero(br, "a real multiplier passes -1 (a period doubling)", oa, ob)
        na, nb = _test_ns(oa), _test_ns(ob)
        if na is not None and nb is not None and na * nb < 0:
            on, lam, w, zero = self._locate(sh, Ua, Ub, na, nb, _test_ns, monotone)
            if zero:
                br.special.append(
                    SpecialPoint(
                        "neimark_sacker",
                        lam,
                        k,
                        idx,
                        on,
                        "a complex pair crosses the unit circle",
                        tolerance=w,
                    )
                )
            else:
                self._not_a_zero(br, "a complex pair crosses the unit circle", oa, ob)

    def _not_a_zero(self, br: Branch, what: str, oa: Orbit, ob: Orbit) -> None:
        """A note on ``br`` where a test function changed sign without a zero between two
        points (:meth:`_locate`): no special point is reported there."""
        self.not_a_zero = True
        la, lb = lam_of(oa, self.key), lam_of(ob, self.key)
        ma = ", ".join(f"{m:.4g}" for m in oa.multipliers)
        mb = ", ".join(f"{m:.4g}" for m in ob.multipliers)
        br.notes.append(
            f"between {self.key} = {la:.10g} and {lb:.10g} the test of '{what}' changes sign "
            f"without a zero (multipliers {ma} -> {mb}): not reported as a bifurcation. A "
            "multiplier jumps where a contact's depth minimum touches zero inside the orbit, "
            "where the finite-difference map's runs straddle such a touch, or where the step "
            "from one point to the next landed on another family of the same contacts; "
            "method = exact and a smaller max_step tell which, and may find a bifurcation there"
        )


def continue_orbit(
    system: Any,
    orbit: Orbit,
    key: str,
    to: float,
    *,
    both_directions: bool = False,
    bounds: tuple[float, float] | None = None,
    method: str = "auto",
    tol: float = DEFAULT_TOL,
    step: float = 0.02,
    min_step: float = 1e-6,
    max_step: float = 0.1,
    max_points: int = 200,
    switch: bool = True,
    max_depth: int = 2,
    on_point: Callable[[Orbit], None] | None = None,
) -> Branch:
    """Continue ``orbit`` in the parameter ``key`` towards ``to`` [SI].

    Parameters
    ----------
    system : ScenarioSystem or ModelSystem
    orbit : Orbit
        The start (e.g. :func:`~braidsim.continuation.orbit.seed_orbit`), solved at
        ``orbit.values[key]``.
    key : str
        The continuation parameter (a scenario key or a record field).
    to : float
        Where to stop [SI]; the branch also stops when it leaves ``bounds`` (default the
        interval between the start and ``to``), after ``max_points``, or when the step falls
        below ``min_step``.
    both_directions : bool
        Also continue backwards from the start (the points are joined in arclength order).
    step, min_step, max_step : float
        Arclength steps (scaled: parameter in units of |to - start|).
    switch : bool
        Switch to the period-2k branch at each period doubling (up to ``max_depth`` doublings).

    Returns
    -------
    Branch
    """
    system.check_key(key)
    lam0 = float(orbit.values.get(key, system.value(key)))
    if key not in orbit.values:
        orbit = dataclasses.replace(orbit, values={**orbit.values, key: lam0})
    if not math.isfinite(to) or to == lam0:
        raise InputError(
            f"continuation.to: {to!r} must differ from the start {lam0:g}; allowed another value"
        )
    bnd = bounds if bounds is not None else (min(lam0, to), max(lam0, to))
    cont = Continuer(
        system,
        key,
        bnd,
        method=method,
        tol=tol,
        step=step,
        min_step=min_step,
        max_step=max_step,
        max_points=max_points,
        pscale=abs(to - lam0),
        on_point=on_point,
    )
    direction = 1.0 if to > lam0 else -1.0
    br = cont.run(orbit, direction)
    if both_directions:
        back = cont.run(orbit, -direction)
        br = _join(back, br)
    if switch and max_depth > 0:
        for sp in list(br.special):
            if sp.type != "period_doubling" or sp.orbit is None:
                continue
            child = switch_period_doubling(
                system, sp, key, cont, max_depth=max_depth - 1, switch=switch
            )
            if child is not None:
                br.children.append(child)
    return br


def _join(back: Branch, fwd: Branch) -> Branch:
    pts = list(reversed(back.points[1:])) + fwd.points
    n_back = len(back.points) - 1
    # (each point as it was located, its tolerance kept, at its index on the joined branch)
    sps = [dataclasses.replace(sp, index=n_back - sp.index) for sp in back.special]
    sps += [dataclasses.replace(sp, index=sp.index + n_back) for sp in fwd.special]
    tans = [-t for t in reversed(back.tangents[1:])] + fwd.tangents
    return Branch(
        fwd.key,
        fwd.period,
        pts,
        sps,
        f"{back.stop}; {fwd.stop}",
        back.children + fwd.children,
        tans,
        notes=back.notes + fwd.notes,
    )


def doubled_guess(orbit: Orbit, offset: np.ndarray) -> tuple[tuple[Cut, ...], list[np.ndarray]]:
    """Cuts and states of a period-2k guess: z* + offset at the first cut of the first
    period, z* - offset at the first cut of the second (the other cuts as on the orbit)."""
    m = orbit.segments
    zs = [orbit.z[j % m].copy() for j in range(2 * m)]
    zs[0] = zs[0] + offset
    zs[m] = zs[m] - offset
    return orbit.cuts + orbit.cuts, zs


def switch_period_doubling(
    system: Any,
    sp: SpecialPoint,
    key: str,
    cont: Continuer,
    *,
    max_depth: int = 1,
    switch: bool = True,
) -> Branch | None:
    """The period-2k branch born at a period doubling, continued away from it (None when no
    distinct period-2k orbit is found next to it)."""
    o = sp.orbit
    if o is None:
        return None
    lam = sp.value
    Ls, Vs = system.scales(o.values)
    n = o.z[0].size
    n_y = 2 * system.prepare(o.values).n_coords
    scale = np.array([Ls if (i % 2 == 0 and i < n_y) else Vs for i in range(n)])
    from braidsim.continuation.orbit import seed_orbit

    mu, V = np.linalg.eig(o.monodromy)
    w = np.real(V[:, int(np.argmin(np.abs(mu + 1.0)))])
    w = w / np.max(np.abs(w / scale))
    prep = system.prepare(o.values)
    t0 = o.phase / prep.omega
    n_y = 2 * prep.n_coords
    c0 = o.cuts[0]
    attempts: list[tuple[float, float | None]] = []
    for dl in (0.01, -0.01, 0.03, -0.03):
        # a run started next to the orbit on the side where it is unstable settles on a
        # stable period-2k orbit (a supercritical doubling) ...
        attempts.append((dl, None))
        # ... Newton from z* +/- eps w on alternate periods finds others
        for eps in (0.05, 0.3, 1.0):
            attempts.append((dl, eps))
    for dl, e in attempts:
        vals = dict(o.values)
        vals[key] = lam + dl * cont.pscale
        if not (cont.lo <= vals[key] <= cont.hi):
            continue
        try:
            if e is None:
                y0 = o.z[0][:n_y] + 0.05 * w[:n_y]
                o2 = seed_orbit(
                    system,
                    vals,
                    2 * o.period,
                    segments=2 * o.segments,
                    transient_cycles=200,
                    method=cont.method,
                    tol=cont.tol,
                    start=(t0, y0, c0.modes, c0.v0s(o.z[0][n_y:])),
                )
            else:
                cuts, zs = doubled_guess(o, e * w)
                o2 = solve_fixed(
                    system, vals, 2 * o.period, o.phase, cuts, zs, cont.method, cont.tol
                )
        except (ContinuationError, SimulationError, InputError, np.linalg.LinAlgError):
            continue
        if o2.segments % 2 == 0:
            half = o2.segments // 2
            n2 = min(o2.z[0].size, o2.z[half].size, scale.size)
            d = float(np.max(np.abs((o2.z[0][:n2] - o2.z[half][:n2]) / scale[:n2])))
        else:
            d = 1.0
        if d < 1e-4:
            continue
        sub = copy.copy(cont)  # the same settings, a run of its own
        sub.stop_on = None
        br = sub.run(o2, 1.0 if dl > 0 else -1.0)
        if switch and max_depth > 0:
            for sp2 in list(br.special):
                if sp2.type == "period_doubling" and sp2.orbit is not None:
                    ch = switch_period_doubling(system, sp2, key, sub, max_depth=max_depth - 1)
                    if ch is not None:
                        br.children.append(ch)
        return br
    return None


def orbit_at(
    system: Any, branch: Branch, value: float, method: str = "auto", tol: float = DEFAULT_TOL
) -> Orbit:
    """The branch's orbit at the parameter ``value`` [SI], solved from the nearest point
    (the first in arclength order among those nearest). Raises :class:`ContinuationError`
    when the value is outside the branch or Newton fails there."""
    v = branch.values
    if not (v.min() <= value <= v.max()):
        raise ContinuationError(
            f"{branch.key} = {value:g} is outside the branch ({v.min():g} to {v.max():g})"
        )
    i = int(np.argmin(np.abs(v - value)))
    o = branch.points[i]
    return solve_fixed(
        system, {**o.values, branch.key: float(value)}, o.period, o.phase, o.cuts, o.z, method, tol
    )
