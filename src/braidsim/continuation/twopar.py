"""Two-parameter continuation of fold, period-doubling, Neimark-Sacker and grazing points.

A special point found on a branch in the parameter lambda_1 is followed as a second
parameter lambda_2 changes: the curve it draws in the (lambda_1, lambda_2) plane bounds a
region of one kind of motion. The curve is followed by pseudo-arclength continuation, so a
boundary that turns back in lambda_2 (or in lambda_1) is followed round the turn.

Fold, period doubling, Neimark-Sacker: the augmented system
--------------------------------------------------------------
The unknowns are the shooting states and both parameters, V = (Z, lambda_1, lambda_2)
(scaled as in :class:`~braidsim.continuation.orbit.Shooter`), the equations the shooting
residuals and one test function of the monodromy M(V):

    r(V) = 0,   g(V) = 0,   g = det(M - I) (fold), det(M + I) (period doubling),
                            |mu| - 1 of the complex pair nearest the unit circle (NS),

N + 1 equations in N + 2 unknowns: a curve (the "minimally extended" systems of Kuznetsov,
Y. A. (2004), Elements of Applied Bifurcation Theory, 3rd ed., Springer, ch. 10,
doi:10.1007/978-1-4757-3978-7; for maps, det(M -+ I) are the standard fold and flip test
functions). The Jacobian of r is that of the shooting equations (the exact or
finite-difference flow map, with d r / d lambda_1,2); the gradient of g, a second
derivative of the flow, is taken by central differences of g over each unknown (steps of
1e-5 of the scaled unknowns with the exact map, 1e-3 with the finite-difference map, whose
monodromy carries noise of about 1e-5). From a point V_i with unit tangent tau_i (the null
vector of the Jacobian) the next solves

    r(V) = 0,   g(V) = 0,   tau_i . (V - V_i - h tau_i) = 0

by Newton's method (Keller, H. B. (1977), in Applications of Bifurcation Theory, Academic
Press, 359-384). The step h is measured in the plane of the two parameters, each in units
of its range: it grows by 1.5 after a corrector of at most 3 iterations and halves after a
failure. The curve ends where it leaves either parameter's range (the last point placed on
the edge), where the orbit's contact structure changes (the curve meets a grazing: beyond
it the test function belongs to another orbit family), where the step falls below
``min_step``, or after ``max_points``.

Grazing: continuation in the parameter plane
--------------------------------------------
At a grazing the orbit family itself ends (a contact appears or disappears), so the
shooting equations of one structure do not continue across it and Newton iterates beyond
it meet another map. The grazing curve is therefore followed in the plane of the two
parameters, q = (lambda_1 / P_1, lambda_2 / P_2), with the orbit of the approaching
structure solved at each trial point (from the nearest one known): a secant predictor
q_i + h t_i (t_i the unit chord of the last two points; the first step along lambda_2),
and a corrector on the line through the prediction normal to t_i, on which the grazing is
bracketed between an orbit of the approaching structure and a point where that structure
no longer exists, then located by regula falsi on the orbit's distance to grazing
(:attr:`~braidsim.continuation.orbit.Profile.approach`, a free-flight gap minimum or a
contact's least depth), extrapolated linearly to zero from the last two orbits of the
approaching structure, to a bracket of 1e-7 of the plane's unit. The corrector's line
turns with the curve, so a grazing curve that turns back is followed too.

The curves over (h_a, omega) or (eps_g, omega) bound the regions with one kind of motion:
resting on the wall below the lift-off grazing curve, impacting above it, and so on; drawn
over a brute-force regime map of the same range they form the safe operating map
(:func:`braidsim.continuation.plots.plot_operating_map`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from braidsim.continuation.branch import Branch, SpecialPoint, grazing_zero, signature
from braidsim.continuation.orbit import (
    ContinuationError,
    Orbit,
    Shooter,
    choose_phase,
    cuts_from,
    exact_available,
    finish,
    monodromy_of,
    recut,
    resting_speed,
    solve_fixed,
    states_at,
)
from braidsim.errors import InputError, SimulationError

SMOOTH_TYPES = ("fold", "period_doubling", "neimark_sacker")
GRAZING_XTOL = 1e-7
"""Bracket width (units of the parameters' ranges) to which a grazing is located."""
GRAZING_ATOL = 1e-9
"""An orbit whose distance to grazing is below this fraction of the length scale L is at
the grazing."""
CARRY_FROM = 0.05
"""Grazing: orbits are carried from known ones at least this fraction of the largest known
distance to grazing away from it."""
SUBSTEP = 0.005
"""Grazing: the longest step (units of the parameters' ranges) over which an orbit of the
approaching structure is carried at fixed parameters."""
_FAILURES = (ContinuationError, SimulationError, np.linalg.LinAlgError)


class _NoisyTestFunction(ContinuationError):
    """The central-difference corrector stalled with its test function above tolerance."""


@dataclass
class BoundaryCurve:
    """A special point followed in two parameters.

    Attributes
    ----------
    type : str
        ``fold``, ``period_doubling``, ``neimark_sacker`` or ``grazing``.
    key1, key2 : str
        The branch's parameter and the second one.
    period : int
        Period of the orbit [forcing cycles].
    p1, p2 : list of float
        The curve [SI], in arclength order.
    stop : str
        Why it ended.
    orbits : list of Orbit or None
        The orbit at each point (fold, period doubling, Neimark-Sacker; for grazing the
        nearest orbit of the approaching structure, None at the start).
    residuals : list of float
        The test function at each point (0 up to the corrector's tolerance; for grazing the
        distance to grazing of the nearest orbit of the approaching structure [m]).
    name : str
        What the boundary is, in words (for a grazing: which contact opens or appears,
        :func:`grazing_name`; else the type).
    end : str
        ``"grazing"`` where a fold, doubling or Neimark-Sacker curve ends on a grazing of
        its orbit (a codimension-two point: the last point; the contact pattern changes
        there and the test function belongs to another family beyond), else empty.
    """

    type: str
    key1: str
    key2: str
    period: int
    p1: list[float] = field(default_factory=list)
    p2: list[float] = field(default_factory=list)
    stop: str = ""
    detail: str = ""
    residuals: list[float] = field(default_factory=list)
    orbits: list[Orbit | None] = field(default_factory=list, repr=False)
    name: str = ""
    end: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (SI)."""
        return {
            "type": self.type,
            "parameters": [self.key1, self.key2],
            "period": self.period,
            "points": [[a, b] for a, b in zip(self.p1, self.p2, strict=True)],
            "stop": self.stop,
            "detail": self.detail,
            "name": self.name,
            "end": self.end,
        }

    def add(
        self,
        a: float,
        b: float,
        res: float,
        on_point: Callable[[float, float], None] | None,
        orbit: Orbit | None = None,
    ) -> None:
        """Append a point (and report it)."""
        self.p1.append(float(a))
        self.p2.append(float(b))
        self.residuals.append(float(res))
        self.orbits.append(orbit)
        if on_point:
            on_point(float(a), float(b))


def bifurcation_function(kind: str, M: np.ndarray) -> float:
    """The test function of ``kind`` on the monodromy M (module docstring)."""
    n = M.shape[0]
    if kind == "fold":
        return float(np.linalg.det(M - np.eye(n)))
    if kind == "period_doubling":
        return float(np.linalg.det(M + np.eye(n)))
    if kind == "neimark_sacker":
        mu = np.linalg.eigvals(M)
        cx = mu[np.abs(mu.imag) > 1e-9 * np.maximum(1.0, np.abs(mu))]
        if cx.size == 0:
            raise ContinuationError(
                "the complex pair of the Neimark-Sacker point turned real (a strong resonance)"
            )
        return float(np.abs(cx[np.argmin(np.abs(np.abs(cx) - 1.0))]) - 1.0)
    raise InputError(f"type: {kind!r}; allowed {', '.join(SMOOTH_TYPES)} or grazing")


WALL_NAMES = {(0, -1): "inner wall", (0, 1): "outer wall", (1, -1): "slot", (1, 1): "slot"}
"""The walls of the contact pairs (pair, wall): the track's inner and outer walls, the
horn-gear slot's two flanks."""


def grazing_name(sp: SpecialPoint, side: Orbit | None = None) -> str:
    """A grazing in words: ``lift-off`` where a contact open over the whole orbit (the
    carrier resting on a wall) opens, else which walls' contacts appear or disappear."""
    a = sp.orbit if sp.orbit is not None else side
    if a is None:
        return "grazing"
    walls_a = set(zip(a.profile.onset_pairs.tolist(), a.profile.onset_walls.tolist(), strict=True))
    resting = not walls_a and any(m != 0 for c in a.cuts for m in c.modes)
    if resting:
        return "lift-off"
    if sp.other is None:
        return "grazing"
    b = sp.other.profile
    walls_b = set(zip(b.onset_pairs.tolist(), b.onset_walls.tolist(), strict=True))
    new = sorted(walls_b - walls_a)
    lost = sorted(walls_a - walls_b)
    words = [f"grazing of the {WALL_NAMES.get(w, 'wall')}" for w in new]
    words += [f"{WALL_NAMES.get(w, 'wall')} contact lost" for w in lost]
    return ", ".join(words) if words else "grazing"


def _ranges(
    system: Any, branch: Branch, key2: str, p2_0: float, to2: float, range1: Any
) -> tuple[float, float, float, float]:
    if range1 is None:
        v = branch.values
        a, b = float(v.min()), float(v.max())
        # the branch's range and half as much again each side (not below 0 for a range >= 0)
        lo1, hi1 = a - 0.5 * (b - a), b + 0.5 * (b - a)
        if a >= 0.0:
            lo1 = max(lo1, 0.0)
    else:
        lo1, hi1 = (float(x) for x in range1)
    if not (hi1 > lo1):
        raise InputError(f"range1: ({lo1:g}, {hi1:g}) is empty; allowed lo < hi")
    if to2 == p2_0:
        raise InputError(f"{key2}: the target {to2:g} equals the start; allowed another value")
    return lo1, hi1, min(p2_0, to2), max(p2_0, to2)


def trace_boundary(
    system: Any,
    branch: Branch,
    sp: SpecialPoint,
    key2: str,
    to2: float,
    *,
    steps: int = 10,
    window: float = 0.04,
    method: str = "auto",
    tol: float = 1e-8,
    range1: tuple[float, float] | None = None,
    range2: tuple[float, float] | None = None,
    max_points: int | None = None,
    min_step: float = 1e-4,
    on_point: Callable[[float, float], None] | None = None,
) -> BoundaryCurve:
    """Follow the special point ``sp`` of ``branch`` in the plane of its parameter and
    ``key2``, starting towards ``key2 = to2`` [SI] (module docstring).

    Parameters
    ----------
    steps : int
        The largest step is 1 / ``steps`` of the parameters' ranges (measured in the plane).
    window : float
        Grazing: the first search step along the corrector's line, as a fraction of the
        ranges.
    range1 : (lo, hi), optional
        Range of the branch's parameter (default the branch's range and half as much again
        each side); ``range2`` of ``key2`` (default from the start to ``to2``). The curve
        ends where it leaves either.
    max_points : int, optional
        Default 20 ``steps``.
    """
    system.check_key(key2)
    if int(steps) != steps or steps < 1:
        raise InputError(f"steps: {steps!r}; allowed an integer >= 1")
    key1 = branch.key
    anchor = sp.orbit if sp.orbit is not None else branch.points[sp.index]
    p2_0 = float(anchor.values.get(key2, system.value(key2)))
    anchor = replace(anchor, values={**anchor.values, key2: p2_0})
    lo1, hi1, lo2, hi2 = _ranges(system, branch, key2, p2_0, to2, range1)
    if range2 is not None:
        lo2, hi2 = (float(x) for x in range2)
    box = (lo1, hi1, lo2, hi2)
    npts = int(max_points) if max_points is not None else 20 * int(steps)
    direction = 1.0 if to2 > p2_0 else -1.0
    if sp.type == "grazing":
        side = branch.points[sp.index]
        side = replace(side, values={**side.values, key2: p2_0})
        return _trace_grazing(
            system,
            sp,
            side,
            key1,
            key2,
            box,
            direction,
            1.0 / steps,
            min_step / steps,
            window,
            npts,
            method,
            tol,
            on_point,
        )
    if sp.type not in SMOOTH_TYPES:
        raise InputError(f"type: {sp.type!r}; allowed {', '.join(SMOOTH_TYPES)} or grazing")
    return _trace_smooth(
        system,
        sp,
        anchor,
        key1,
        key2,
        box,
        direction,
        1.0 / steps,
        min_step / steps,
        npts,
        method,
        tol,
        on_point,
    )


# ----------------------------------------------------------------------------------------
# fold, period doubling, Neimark-Sacker: the augmented system
# ----------------------------------------------------------------------------------------


class Augmented:
    """The shooting equations of one orbit structure with both parameters free, and the
    test function of one bifurcation (module docstring)."""

    def __init__(
        self,
        system: Any,
        orbit: Orbit,
        kind: str,
        key1: str,
        key2: str,
        scales: tuple[float, float],
        method: str,
    ) -> None:
        self.system = system
        self.kind = kind
        self.key1, self.key2 = key1, key2
        self.scales = scales
        self.method = method
        self.sh = Shooter(
            system,
            dict(orbit.values),
            key1,
            orbit.period,
            orbit.phase,
            orbit.cuts,
            method,
            scales[0],
            key2=key2,
            pscale2=scales[1],
        )
        # central-difference step of the test function's gradient (scaled unknowns)
        self.delta = 1e-5 if method != "fd" else 1e-3

    def pack(self, o: Orbit) -> np.ndarray:
        """Scaled unknowns of an orbit of this structure."""
        return self.sh.pack(o.z, o.values[self.key1], o.values[self.key2])

    def g_at(self, V: np.ndarray) -> float:
        """The test function at V (the monodromy at fixed parameters)."""
        vals = self.sh.values_of(V)
        z, _ = self.sh.unpack(V)
        fixed = Shooter(
            self.system, vals, None, self.sh.period, self.sh.phase, self.sh.cuts, self.method
        )
        _, _, Js = fixed.residual(fixed.pack(z, None))
        return bifurcation_function(self.kind, monodromy_of(Js))

    def equations(self, V: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """(r, g), their Jacobian ((N + 1) x (N + 2)) and the segment Jacobians."""
        R, DR, Js = self.sh.residual(V)
        g = bifurcation_function(self.kind, monodromy_of(Js))
        grad = np.zeros(V.size)
        d = self.delta
        for i in range(V.size):
            e = np.zeros(V.size)
            e[i] = d
            grad[i] = (self.g_at(V + e) - self.g_at(V - e)) / (2 * d)
        return np.concatenate([R, [g]]), np.vstack([DR, grad]), Js

    def tangent(self, DF: np.ndarray, prev: np.ndarray | None, direction: float) -> np.ndarray:
        """Unit null vector of the Jacobian, oriented as ``prev`` (or with lambda_2 in
        ``direction``)."""
        _, _, vt = np.linalg.svd(DF)
        tau = vt[-1] / np.linalg.norm(vt[-1])
        if prev is not None:
            if float(tau @ prev) < 0:
                tau = -tau
        elif tau[-1] * direction < 0:
            tau = -tau
        return tau

    def correct(
        self, Vp: np.ndarray, normal: np.ndarray, tol: float, gtol: float, max_iter: int = 10
    ) -> tuple[np.ndarray, float, int, np.ndarray, list[np.ndarray]]:
        """Newton's method on r = 0, g = 0, normal . (V - Vp) = 0. Returns (V, g,
        iterations, Jacobian of (r, g), segment Jacobians)."""
        V = Vp.copy()
        F, DF, Js = self.equations(V)
        r0 = float(np.max(np.abs(F[:-1])))
        g0 = abs(float(F[-1]))
        f0 = max(r0, g0)
        if r0 < tol and g0 < gtol:
            # a start already on the curve to the noise of its equations (the special point
            # a branch located) is kept: a step from it only wanders in the test function's
            # noise, which can exceed gtol, and the divergence test below, scaled by this
            # start's tiny residual, then refuses a point that was there
            return V, float(F[-1]), 0, DF, Js
        for it in range(1, max_iter + 1):
            A = np.vstack([DF, normal])
            b = -np.concatenate([F, [float(normal @ (V - Vp))]])
            try:
                dV = np.linalg.solve(A, b)
            except np.linalg.LinAlgError:
                dV = np.linalg.lstsq(A, b, rcond=None)[0]
            V = V + dV
            F, DF, Js = self.equations(V)
            r = float(np.max(np.abs(F[:-1])))
            g = abs(float(F[-1]))
            if not math.isfinite(r + g) or max(r, g) > 10 * max(f0, tol):
                raise ContinuationError(f"Newton diverged on the augmented system ({r:.3g})")
            step = float(np.max(np.abs(dV)))
            # converged: the residuals at tolerance and the test function too, or the steps
            # down to the test function's noise (that of the monodromy: about 3e-8 with the
            # exact map at rtol 1e-10, 1e-6 with central differences)
            # (tiny steps with g far above its noise: the corrector is stuck where g is
            # not smooth, at a grazing, and the point is not on the curve)
            if r < tol and (
                (g < gtol and step < 1e3 * tol) or (step < 1e2 * tol and g < 1e3 * gtol)
            ):
                return V, float(F[-1]), it, DF, Js
        raise ContinuationError(
            f"Newton did not converge on the augmented system in {max_iter} iterations"
        )

    def orbit(self, V: np.ndarray, Js: list[np.ndarray]) -> Orbit:
        """The orbit at converged unknowns."""
        return finish(self.sh, V, 0.0, 0, Js)


GRAZING_END = 1e-3
"""A fold, doubling or Neimark-Sacker curve whose corrector stalls where its orbit's
distance to grazing has fallen below this fraction of the largest along the curve ends on
a grazing."""


def _at_grazing(curve: BoundaryCurve, system: Any) -> bool:
    """Whether the curve's last orbit is at a grazing: its distance to grazing (a
    free-flight gap minimum or a contact's least depth) below ``GRAZING_END`` of the
    largest along the curve, or below 1e-9 of the length scale."""
    dist = [o.profile.approach for o in curve.orbits if o is not None]
    dist = [d for d in dist if math.isfinite(d)]
    if len(dist) < 2:
        return False
    last = curve.orbits[-1]
    assert last is not None
    L = float(system.scales(last.values)[0])
    return dist[-1] < max(GRAZING_END * max(dist), GRAZING_ATOL * L)


def _moved(system: Any, o: Orbit) -> Orbit:
    """The same orbit cut at a phase away from onsets and exits, its states at the new cuts
    integrated from the old ones (not solved again: at a fold the orbit's own Newton matrix
    M - I is singular)."""
    prep = system.prepare(o.values)
    w = prep.omega
    th = choose_phase(o.profile, w, o.period, o.segments)
    t0 = o.phase / w
    if th / w < t0:
        th += 2 * math.pi * o.period
    cuts = cuts_from(o.profile, w, th, o.period, o.segments, t0, resting_speed(system, o.values))
    times = th / w + np.arange(o.segments) * o.profile.period / o.segments
    n = 2 * prep.n_coords
    c0 = o.cuts[0]
    z = states_at(system, o.values, t0, o.z[0][:n], c0.modes, c0.v0s(o.z[0][n:]), times, cuts)
    full = 2 * math.pi * o.period
    return replace(o, phase=float(th % full), cuts=cuts, z=tuple(z))


def _land_on_edge(
    aug: Augmented,
    Vn: np.ndarray,
    beyond: Orbit,
    i: int,
    edge: float,
    tol: float,
    gtol: float,
) -> tuple[Orbit, float] | None:
    """The curve's point on a range's edge: Newton's method on the augmented system from the
    point ``Vn`` beyond it (orbit ``beyond``), with unknown ``i`` (a parameter, scaled) held
    at ``edge``. Returns (orbit, test function) or None.

    With the central-difference map the test function's noise (about 1e-5 on the carrier's
    doubling curve) can exceed ``gtol``, so that Newton's method wanders instead of
    converging; as where the curve's own corrector stalls (:func:`_trace_smooth`), the
    exact map then takes over. (Without it the small example's doubling curve lost its point
    on the 6 pi rad/s edge.)"""
    e = np.zeros(Vn.size)
    e[i] = 1.0
    Ve = Vn.copy()
    Ve[i] = edge
    try:
        Ve, g, _, _, Js = aug.correct(Ve, e, tol, gtol)
        return aug.orbit(Ve, Js), g
    except _FAILURES:
        if aug.method != "fd" or not exact_available():
            return None
    try:
        exact = Augmented(aug.system, beyond, aug.kind, aug.key1, aug.key2, aug.scales, "exact")
        Ve = exact.pack(beyond)
        Ve[i] = edge
        Ve, g, _, _, Js = exact.correct(Ve, e, tol, 1e-9)
        return exact.orbit(Ve, Js), g
    except _FAILURES:
        return None


def _trace_smooth(
    system: Any,
    sp: SpecialPoint,
    anchor: Orbit,
    key1: str,
    key2: str,
    box: tuple[float, float, float, float],
    direction: float,
    hmax: float,
    hmin: float,
    npts: int,
    method: str,
    tol: float,
    on_point: Callable[[float, float], None] | None,
) -> BoundaryCurve:
    lo1, hi1, lo2, hi2 = box
    scales = (hi1 - lo1, hi2 - lo2)
    gtol = 1e-9 if method != "fd" else 1e-6
    curve = BoundaryCurve(
        sp.type, key1, key2, sp.period, detail=sp.detail, name=sp.type.replace("_", " ")
    )
    aug = Augmented(system, anchor, sp.type, key1, key2, scales, method)
    V = aug.pack(anchor)
    # the located point onto the augmented system, lambda_2 held
    e2 = np.zeros(V.size)
    e2[-1] = 1.0
    try:
        V, g, _, DF, Js = aug.correct(V, e2, tol, gtol)
    except _FAILURES as exc:
        curve.stop = f"the {sp.type} point did not converge on the augmented system ({exc})"
        return curve
    o = aug.orbit(V, Js)
    sig = signature(o)
    curve.add(o.values[key1], o.values[key2], g, on_point, o)
    tau = aug.tangent(DF, None, direction)
    h = 0.5 * hmax
    exact_ok = True  # (False once the exact map failed to take over from central differences)
    while len(curve.p1) < npts:
        plane = math.hypot(tau[-2], tau[-1])
        step = h / max(plane, 0.1)
        try:
            Vn, g, its, DFn, Js = aug.correct(V + step * tau, tau, tol, gtol)
            if aug.method == "fd" and abs(g) > gtol and exact_ok and exact_available():
                # accepted by the corrector's stall rule (steps at the noise, g up to 1e3
                # gtol): the central-difference monodromy no longer resolves the test
                # function (next to a grazing det(M + I) is not smooth); with the maps held
                # to rtol times the state scales it stalled there, close to the grazing, and
                # the curve ended on points 1e-3 off it. The exact map decides.
                raise _NoisyTestFunction(f"test function {g:.3g} above {gtol:g}")
            on = aug.orbit(Vn, Js)
            if signature(on) != sig:
                a, b = on.values[key1], on.values[key2]
                if h > 4 * hmin:
                    raise ContinuationError("the contact structure changed within the step")
                curve.stop = (
                    f"the orbit's contact structure changed near ({key1}, {key2}) = "
                    f"({a:.6g}, {b:.6g}): the {sp.type} curve meets a grazing"
                )
                curve.end = "grazing"
                break
        except _FAILURES as exc:
            noisy = isinstance(exc, _NoisyTestFunction)
            if not noisy:
                h *= 0.5
            if noisy or h < hmin:
                last = curve.orbits[-1]
                if aug.method == "fd" and last is not None and exact_available():
                    # the central-difference monodromy's error grows with the impacts'
                    # hardness (about 1e-2 on the multipliers at 5 kN on the carrier),
                    # and det(M + I) jumps by as much between neighbouring orbits: the
                    # corrector stalls on noise, not on the curve. Go on with the exact map.
                    try:
                        exact = Augmented(system, last, sp.type, key1, key2, scales, "exact")
                        Ve, g, _, DF, _ = exact.correct(exact.pack(last), tau, tol, 1e-9)
                        # oriented on the parameters' components (the noisy gradient of
                        # g tilted the old tangent's state components)
                        tau_new = exact.tangent(DF, None, direction)
                        if float(tau_new[-2:] @ tau[-2:]) < 0:
                            tau_new = -tau_new
                        aug, V, tau, gtol = exact, Ve, tau_new, 1e-9
                        h = 0.5 * hmax
                        curve.detail += (
                            f"; exact flow map from {key2} = {curve.p2[-1]:.6g} on (the "
                            "central-difference monodromy was too noisy for the corrector)"
                        )
                        continue
                    except _FAILURES:
                        pass
                if noisy:
                    # the exact map could not take over (a record without tangents): the
                    # central-difference point is accepted by the stall rule, as before
                    exact_ok = False
                    continue
                curve.stop = f"step below {hmin:g} at {key2} = {curve.p2[-1]:.6g} ({exc})"
                if _at_grazing(curve, system):
                    a, b = curve.p1[-1], curve.p2[-1]
                    assert last is not None
                    curve.stop = (
                        f"the {sp.type} curve meets a grazing at ({key1}, {key2}) = "
                        f"({a:.6g}, {b:.6g}): the orbit's distance to grazing fell to "
                        f"{last.profile.approach:.3g} m (a codimension-two point; beyond it "
                        "the contact pattern changes)"
                    )
                    curve.end = "grazing"
                break
            continue
        a, b = on.values[key1], on.values[key2]
        out1 = not (lo1 <= a <= hi1)
        out2 = not (lo2 <= b <= hi2)
        if out1 or out2:
            # land on the edge the step crossed, that parameter held there
            i, edge = (-1, hi2 if b > hi2 else lo2) if out2 else (-2, hi1 if a > hi1 else lo1)
            e = np.zeros(V.size)
            e[i] = 1.0
            oe = _land_on_edge(aug, Vn, on, i, edge / scales[i + 2], tol, gtol)
            if oe is not None:
                curve.add(oe[0].values[key1], oe[0].values[key2], oe[1], on_point, oe[0])
            name = key2 if out2 else key1
            curve.stop = f"left the range of {name} at {edge:.6g}"
            break
        curve.add(a, b, g, on_point, on)
        tau = aug.tangent(DFn, tau, direction)
        V = Vn
        if its <= 3:
            h = min(1.5 * h, hmax)
        # keep the cuts away from onsets and exits
        prof = on.profile
        w = system.prepare(on.values).omega
        tcut = on.phase / w
        if any(
            prof.event_distance(tcut + j * prof.period / on.segments) < 0.01 * prof.period
            for j in range(on.segments)
        ):
            try:
                moved = _moved(system, on)
                # (with the map the curve has now: the exact one once it took over)
                aug = Augmented(system, moved, sp.type, key1, key2, scales, aug.method)
                V = aug.pack(moved)
                e2 = np.zeros(V.size)  # (the state's size may change with the cut)
                e2[-1] = 1.0
                V, g, _, DF, Js = aug.correct(V, e2, tol, gtol)
                tau_new = aug.tangent(DF, None, float(np.sign(tau[-1]) or direction))
                # keep the orientation: compare the parameter components (the state
                # components changed meaning with the cut)
                if float(tau_new[-2:] @ tau[-2:]) < 0:
                    tau_new = -tau_new
                tau = tau_new
            except _FAILURES as exc:
                curve.stop = f"could not move the section at {key2} = {b:.6g} ({exc})"
                break
        if len(curve.p1) > 3:
            d = math.hypot(
                (curve.p1[-1] - curve.p1[0]) / scales[0], (curve.p2[-1] - curve.p2[0]) / scales[1]
            )
            if d < 0.5 * h:
                curve.stop = "the curve closed on itself"
                break
    else:
        curve.stop = f"{npts} points reached"
    return curve


# ----------------------------------------------------------------------------------------
# grazing: continuation in the parameter plane
# ----------------------------------------------------------------------------------------


class GrazingLost(ContinuationError):
    """The approaching orbit family ends before it grazes (the grazing curve ends)."""


class _GrazingPlane:
    """Orbits of the approaching structure at points of the scaled parameter plane."""

    def __init__(
        self,
        system: Any,
        start: Orbit,
        key1: str,
        key2: str,
        box: tuple[float, float, float, float],
        method: str,
        tol: float,
        before: tuple[Orbit, ...] = (),
    ) -> None:
        self.system = system
        self.key1, self.key2 = key1, key2
        self.lo1, self.hi1, self.lo2, self.hi2 = box
        self.s1, self.s2 = self.hi1 - self.lo1, self.hi2 - self.lo2
        self.sig = signature(start)
        self.known: list[tuple[np.ndarray, Orbit]] = [(self.q(o), o) for o in (*before, start)]
        self.method, self.tol = method, tol
        # an orbit this close to grazing is at it (a resting contact's least depth can
        # reach the integrator's noise, 1e-18 m, before Newton fails beyond it)
        self.atol = GRAZING_ATOL * float(system.scales(start.values)[0])

    def q(self, o: Orbit) -> np.ndarray:
        return np.array([o.values[self.key1] / self.s1, o.values[self.key2] / self.s2])

    def lam(self, q: np.ndarray) -> tuple[float, float]:
        return float(q[0] * self.s1), float(q[1] * self.s2)

    def orbit(self, q: np.ndarray) -> Orbit | None:
        """The orbit of the approaching structure at q, or None where it does not exist
        (Newton fails, or converges to another structure). It is carried from the nearest
        known orbit in steps of ``SUBSTEP``, doubled after each success up to 4 ``SUBSTEP``
        and quartered after a failure (orbits of both structures can coexist near a
        grazing: a long jump could land on the other one)."""
        # carried from the nearest known orbit not itself next to the grazing (Newton from
        # an orbit at the grazing can fall either way: onto the other structure)
        top = max(kv[1].profile.approach for kv in self.known)
        pool = [kv for kv in self.known if kv[1].profile.approach >= CARRY_FROM * top]
        qc, o = min(pool or self.known, key=lambda kv: float(np.linalg.norm(kv[0] - q)))
        h = SUBSTEP
        for _ in range(math.ceil(float(np.linalg.norm(q - qc)) / SUBSTEP) + 64):
            d = float(np.linalg.norm(q - qc))
            if d == 0.0:
                break
            qk = q if d <= h else qc + (q - qc) * (h / d)
            a, b = self.lam(qk)
            try:
                ok = solve_fixed(
                    self.system,
                    {**o.values, self.key1: a, self.key2: b},
                    o.period,
                    o.phase,
                    o.cuts,
                    o.z,
                    self.method,
                    self.tol,
                )
            except (*_FAILURES, InputError):
                # Newton's iterates can meet the wall far from the orbit: a shorter step
                h *= 0.25
                if h < SUBSTEP / 300:
                    return None
                continue
            # (a gap minimum that reached zero has crossed the wall between the solver's
            # checks: beyond the grazing as well)
            if signature(ok) != self.sig or not (0.0 < ok.profile.approach < math.inf):
                return None
            qc, o = qk.copy(), ok
            self.known.append((qc, o))
            h = min(2.0 * h, 4 * SUBSTEP)
        else:
            return None
        if len(self.known) > 60:
            del self.known[1:21]
        return o

    def locate(
        self, qc: np.ndarray, n: np.ndarray, first: float, reach: float
    ) -> tuple[np.ndarray, float, Orbit] | None:
        """The grazing on the line qc + s n, |s| <= ``reach`` (n pointing from the
        approaching structure's side to the other): (point, distance to grazing of the
        nearest orbit, that orbit), None when no bracket is found."""
        pts: list[tuple[float, float, Orbit]] = []  # (s, approach, orbit) on side A
        s_b: float | None = None  # where the approaching structure does not exist
        o = self.orbit(qc)
        step = first
        if o is not None:
            pts.append((0.0, o.profile.approach, o))
            s_b = self._forward(qc, n, pts, step, reach)
        else:
            s_b, s = 0.0, 0.0
            while abs(s) < reach:
                s -= step
                o = self.orbit(qc + s * n)
                if o is not None:
                    pts.append((s, o.profile.approach, o))
                    break
                s_b = s
                step *= 2.0
        if not pts or s_b is None:
            return None
        for _ in range(4):
            s_b = self._refine(qc, n, pts, s_b)
            # a structure that ended well before its distance to grazing extrapolates to
            # zero: the verdict at s_b came from a jump onto a coexisting orbit of the
            # other structure; carried from the orbit now next to it, look again
            a_top = max(p[1] for p in pts)
            ext = _extrapolated(pts)
            if pts[-1][1] <= 1e-3 * a_top or ext is None or ext <= s_b + 0.01 * (s_b - pts[0][0]):
                break
            o = self.orbit(qc + s_b * n)
            if o is None:
                break
            pts.append((s_b, o.profile.approach, o))
            nb = self._forward(qc, n, pts, max(ext - s_b, GRAZING_XTOL), reach)
            if nb is None:
                return None
            s_b = nb
        s_a, a_a, o_a = pts[-1]
        s_n, a_n, o_n = min(pts, key=lambda p: p[1])
        if a_n <= self.atol:
            return qc + s_n * n, a_n, o_n
        ext = grazing_zero([(p[0], p[1]) for p in pts])
        # (where the corrector gives up just before a stiff contact lifts off, the zero lies
        # a little beyond the last orbit: extrapolated, as on a branch; a zero further than
        # 2 % of the search's reach is not the family's end but an extrapolation past it)
        if ext is None or ext < s_a or ext - s_a > 0.02 * reach:
            # the family ends short of its extrapolated zero: either at a fold, or at a
            # grazing whose distance collapses faster than linearly (a Hertz contact
            # softens as its depth falls to zero), where Newton's method from the orbits
            # on this line falls onto the other structure. A branch through the last
            # orbit tells them apart (its grazing location carries the family in short
            # steps up to the grazing).
            via = self._by_branch(o_a, n, reach)
            if via is not None:
                return via
        if ext is None or ext < s_a or ext - s_a > 0.02 * reach:
            # the family ends with its distance to grazing still finite: not a grazing (a
            # fold of the family, or another structure taking over)
            raise GrazingLost(
                f"the orbit family ends at ({self.key1}, {self.key2}) = "
                f"{self.lam(qc + s_a * n)} with its distance to grazing still {a_a:.3g} m "
                "(a fold of the family or another bifurcation ends the grazing curve)"
            )
        return qc + ext * n, a_a, o_a

    def _by_branch(
        self, o: Orbit, n: np.ndarray, reach: float
    ) -> tuple[np.ndarray, float, Orbit] | None:
        """The grazing met by a one-parameter branch from ``o`` in the parameter along
        which ``n`` mostly points (the other held), within ``reach``; None where the branch
        meets no grazing of ``o``'s structure first (a fold, or nothing)."""
        from braidsim.continuation.branch import Continuer

        i = 0 if abs(n[0]) >= abs(n[1]) else 1
        key, scale = ((self.key1, self.s1), (self.key2, self.s2))[i]
        lo, hi = ((self.lo1, self.hi1), (self.lo2, self.hi2))[i]
        lam0 = float(o.values[key])
        sign = 1.0 if n[i] > 0 else -1.0
        to = min(max(lam0 + sign * reach * scale, lo), hi)
        if to == lam0:
            return None
        cont = Continuer(
            self.system,
            key,
            (lam0, to),
            method=self.method,
            tol=self.tol,
            step=0.02,
            max_step=0.1,
            max_points=30,
            pscale=abs(to - lam0),
            stop_on="grazing",
        )
        try:
            br = cont.run(o, sign)
        except (*_FAILURES, InputError):
            return None
        first = next((sp for sp in br.special if sp.type in ("grazing", "fold")), None)
        if first is None or first.type != "grazing" or first.orbit is None:
            return None
        # a branch that turned back on its way met a fold first (undetected where the
        # grazing lies in the same step): the family ends there, not at this grazing
        v = br.values[: first.index + 1]
        if v.size > 1 and np.any(np.diff(v) * sign <= 0):
            return None
        if (first.value - lam0) * sign <= 0:
            return None
        if signature(first.orbit) != self.sig:
            return None
        q = self.q(o)
        q[i] = first.value / scale
        return q, first.orbit.profile.approach, first.orbit

    def _forward(
        self, qc: np.ndarray, n: np.ndarray, pts: list[Any], step: float, reach: float
    ) -> float | None:
        """From the last orbit of ``pts``, step along n (doubling) until the approaching
        structure ends; its s (None: not within ``reach``)."""
        s = pts[-1][0]
        while abs(s) < reach:
            s += step
            o = self.orbit(qc + s * n)
            if o is None:
                return s
            pts.append((s, o.profile.approach, o))
            step *= 2.0
        return None

    def _refine(self, qc: np.ndarray, n: np.ndarray, pts: list[Any], s_b: float) -> float:
        """Close the bracket (last of ``pts``, s_b) round the grazing; the new s_b."""
        pts.sort(key=lambda p: p[0])
        theta = 1.0
        for _ in range(30):
            s_a = pts[-1][0]
            w = s_b - s_a
            if w < GRAZING_XTOL:
                break
            # regula falsi on the distance to grazing (its zero extrapolated from the two
            # orbits nearest it), a little beyond that zero so that the bracket closes round
            # it; after a miss (the structure ended before it) only part of the way there
            ext = _extrapolated(pts)
            if ext is None or ext <= s_a:
                ext = s_a + 0.5 * w
            if ext > s_b and w < 0.1 * (ext - s_a):
                break  # the family ends short of the zero: it is extrapolated (locate)
            ext = min(ext, s_b)
            nudge = max(0.25 * GRAZING_XTOL, 1e-3 * w) if theta >= 1.0 else 0.0
            trial = s_a + theta * (ext - s_a) + nudge
            trial = min(max(trial, s_a + 1e-3 * w), s_b - 1e-3 * w)
            o = self.orbit(qc + trial * n)
            if o is None:
                s_b = trial
                theta = max(0.5 * theta, 0.05)
            else:
                pts.append((trial, o.profile.approach, o))
                pts.sort(key=lambda p: p[0])
                theta = 1.0
        return s_b


def _extrapolated(pts: list[tuple[float, float, Orbit]]) -> float | None:
    """Where the distance to grazing of the two orbits nearest the grazing extrapolates to
    zero (linear in the parameters near a regular grazing)."""
    if len(pts) < 2:
        return None
    (s1, a1, _), (s2, a2, _) = pts[-2], pts[-1]
    if a1 == a2 or s1 == s2:
        return None
    return float(s2 - a2 * (s2 - s1) / (a2 - a1))


def _trace_grazing(
    system: Any,
    sp: SpecialPoint,
    side: Orbit,
    key1: str,
    key2: str,
    box: tuple[float, float, float, float],
    direction: float,
    hmax: float,
    hmin: float,
    window: float,
    npts: int,
    method: str,
    tol: float,
    on_point: Callable[[float, float], None] | None,
) -> BoundaryCurve:
    lo1, hi1, lo2, hi2 = box
    start = sp.orbit if sp.orbit is not None else side
    start = replace(start, values={**start.values, key2: side.values[key2]})
    if (
        sp.orbit is not None
        and signature(start) != signature(side)
        and signature(start)[0] == signature(side)[0]
    ):
        # the grazing's orbit was cut anew by the branch's bisection (Newton's method
        # failed from the orbit as the branch cut it): the branch's orbit cut the same way,
        # or every orbit carried from it would differ from the plane's in its cuts
        try:
            side = recut(side, system, start.phase, start.segments, method)
        except (*_FAILURES, InputError):
            pass
    # (the branch's orbit before the grazing too: the located one can be at the grazing)
    before = (side,) if side is not start and math.isfinite(side.profile.approach) else ()
    plane = _GrazingPlane(system, start, key1, key2, box, method, tol, before)
    curve = BoundaryCurve(
        sp.type, key1, key2, sp.period, detail=sp.detail, name=grazing_name(sp, side)
    )
    q0 = np.array([sp.value / plane.s1, side.values[key2] / plane.s2])
    # the normal points from the approaching side to the other
    n = np.array([math.copysign(1.0, sp.value - side.values[key1]), 0.0])
    t = np.array([0.0, direction])
    # the branch's grazing located again on the plane's terms (the branch's bisection and
    # the plane's regula falsi end on different sides of a stiff contact's lift-off)
    try:
        f0 = plane.locate(q0, n, min(max(window, 1e-3), 0.25 * hmax), hmax)
    except GrazingLost:
        f0 = None
    if f0 is not None and abs(float(f0[0][1] - q0[1])) < 1e-12 * max(1.0, abs(q0[1])):
        q0 = f0[0]
        a0, b0 = plane.lam(q0)
        curve.add(a0, b0, f0[1], on_point, f0[2])
    else:
        curve.add(sp.value, side.values[key2], 0.0, on_point)
    qs = [q0]
    h = 0.5 * hmax
    first = max(window, 1e-3)
    while len(curve.p1) < npts:
        qp = qs[-1] + h * t
        n_line = np.array([t[1], -t[0]])
        if float(n_line @ n) < 0:
            n_line = -n_line
        known = list(plane.known)
        try:
            found = plane.locate(qp, n_line, min(first, 0.5 * h + 1e-3), 3 * h)
        except GrazingLost as exc:
            if h > 4 * hmin:
                h *= 0.5
                continue
            curve.stop = str(exc)
            break
        if found is None or float(np.linalg.norm(found[0] - qs[-1])) > 3 * h:
            h *= 0.5
            if h < hmin:
                curve.stop = (
                    f"no grazing found next to ({key1}, {key2}) = "
                    f"({curve.p1[-1]:.6g}, {curve.p2[-1]:.6g}) (step below {hmin:g})"
                )
                break
            continue
        qn, dist, _ = found
        chord = qn - qs[-1]
        t_new = chord / float(np.linalg.norm(chord))
        turns_back = len(qs) > 1 and float(t_new @ t) < -0.5
        off = float(np.linalg.norm(qn - qp))
        if len(qs) > 1 and not turns_back and off > 0.2 * h and h > 4 * hmin:
            # found far off the predicted point: the grazing of a coexisting family (near a
            # fold both lie close together), or a bend taken too fast; a shorter step
            # (measured on the (clearance, speed) map: 0.002 of the step on the curve,
            # 0.26-0.63 where it jumped to the other family's grazing). Not on the first
            # step, whose direction is a guess (along the second parameter). Tested before
            # the range: the other family's grazing outside it must not end this curve.
            h *= 0.5
            continue
        a, b = plane.lam(qn)
        out1 = not (lo1 <= a <= hi1)
        out2 = not (lo2 <= b <= hi2)
        if out1 or out2:
            # the grazing on the edge, searched along the edge from where the chord to the
            # point found crosses it, the orbits carried from those known before this step
            # (its own lie beyond the edge next to the grazing, where Newton's method can
            # fall onto the coexisting orbit of the other structure). Searched from the last
            # point's value instead, paper-3.3's lift-off lost its point on the edge: at
            # 5 pi rad/s (the example spec) at rtol 1e-12 and with the implicit step, at
            # 4.5 pi rad/s with the defaults.
            plane.known = known
            k = 1 if out2 else 0  # the coordinate that left its range
            edge = (hi2 if b > hi2 else lo2) if out2 else (hi1 if a > hi1 else lo1)
            e = edge / (plane.s2 if out2 else plane.s1)
            qe = qs[-1] + chord * ((e - qs[-1][k]) / chord[k])
            qe[k] = e
            line = np.zeros(2)
            line[1 - k] = 1.0 if n_line[1 - k] >= 0 else -1.0
            try:
                fe = plane.locate(qe, line, min(first, 0.5 * h + 1e-3), 3 * h)
            except GrazingLost:
                fe = None
            on_edge = False
            if fe is not None:
                ae, be = plane.lam(fe[0])
                if lo1 - 1e-12 <= ae <= hi1 + 1e-12 and lo2 - 1e-12 <= be <= hi2 + 1e-12:
                    curve.add(ae, be, fe[1], on_point, fe[2])
                    on_edge = True
            if not on_edge and h > 4 * hmin:
                # the edge's grazing not found: carried over the whole step from the orbits
                # before it, Newton's method can fall onto a coexisting orbit of the other
                # structure on the way (paper-3.3's lift-off curve from 4 pi up to 10 pi
                # rad/s ended so at 30.12 rad/s, a step of 1.3 rad/s short of the edge). A
                # shorter step, inside the range, and the edge again from there.
                h *= 0.5
                continue
            curve.stop = f"left the range of {key2 if out2 else key1} at {edge:.6g}"
            break
        if turns_back:
            # the curve would turn by more than 120 degrees in one step: the family ended
            # at a fold just past the last point and the new point lies on the way back
            # (the same grazing seen from the other side of the turn)
            curve.stop = (
                f"the orbit family ends at a fold next to ({key1}, {key2}) = "
                f"({curve.p1[-1]:.6g}, {curve.p2[-1]:.6g}) (the grazing curve turns back "
                "onto itself there)"
            )
            break
        curve.add(a, b, dist, on_point, found[2])
        t = t_new
        n = n_line
        qs.append(qn)
        h = min(1.5 * h, hmax)
    else:
        curve.stop = f"{npts} points reached"
    return curve


# ----------------------------------------------------------------------------------------
# boundaries crossed along the second parameter
# ----------------------------------------------------------------------------------------


def crossing_boundaries(
    system: Any,
    key1: str,
    value1: float,
    key2: str,
    from2: float,
    to2: float,
    to1: float,
    *,
    period: int = 1,
    types: tuple[str, ...] = ("grazing",),
    steps: int = 10,
    window: float = 0.04,
    method: str = "auto",
    range1: tuple[float, float] | None = None,
    range2: tuple[float, float] | None = None,
    branch_options: dict[str, Any] | None = None,
    on_point: Callable[[float, float], None] | None = None,
) -> tuple[Branch, list[BoundaryCurve]]:
    """Boundaries of the (``key1``, ``key2``) map met along ``key2``: the orbit seeded at
    (``value1``, ``from2``) [SI] is continued in ``key2`` towards ``to2`` at ``key1 =
    value1``, and the first special point of each of ``types`` on that branch is followed
    in ``key1`` towards ``to1`` with :func:`trace_boundary` (its curves have ``key1`` and
    ``key2`` the other way round: the branch's parameter first).

    A boundary that a branch over ``key1`` never meets is found this way: on the
    (clearance, speed) map the resting orbit's lift-off does not depend on the clearance,
    so a branch over the clearance never lifts off, while one over the speed does.

    ``range1`` and ``range2`` are the ranges of ``key1`` and ``key2`` (default from the
    start to the target of each); the branch stops where it leaves ``range2``.
    ``branch_options`` go to :func:`~braidsim.continuation.branch.continue_orbit`.
    Returns the branch and the curves.
    """
    from braidsim.continuation.branch import continue_orbit
    from braidsim.continuation.orbit import seed_orbit

    r1 = range1 if range1 is not None else (min(value1, to1), max(value1, to1))
    r2 = range2 if range2 is not None else (min(from2, to2), max(from2, to2))
    orbit = seed_orbit(system, {key1: float(value1), key2: float(from2)}, period, method=method)
    opts = {"switch": False, **(branch_options or {})}
    branch = continue_orbit(system, orbit, key2, to2, bounds=r2, method=method, **opts)
    curves = []
    for kind in types:
        for sp in [s for s in branch.special if s.type == kind][:1]:
            curves.append(
                trace_boundary(
                    system,
                    branch,
                    sp,
                    key1,
                    to1,
                    steps=steps,
                    window=window,
                    method=method,
                    range1=r2,
                    range2=r1,
                    on_point=on_point,
                )
            )
    return branch, curves
