"""The Taylor-series step: where the solution is smooth, one polynomial of high order per
step instead of six stages of a Runge-Kutta pair.

From (t, y) the coefficients of y_i(t + tau) = sum_{k=0}^{N} C[i, k] tau^k follow from the
equations by the recurrences of automatic differentiation, each model giving its own
(:func:`~braidsim.core.interfaces.model_series`, on :mod:`braidsim.core.jets`). The step size
is Jorba & Zou's first rule (A software package for the numerical integration of ODEs by
means of high-order Taylor methods, Experimental Mathematics 14 (2005) 99-117,
doi:10.1080/10586458.2005.10128904): the last two terms of each coordinate and speed must
be within its tolerance,

    h = min over i, k in {N - 1, N} of (tol_i / |C[i, k]|)^(1/k),
    tol_i = atol_i + rtol |y_i|,

so that the truncated tail is of the size of the tolerance; a step is never rejected for
its error. The polynomial scaled to the step, RT[k, i] = C[i, k] h^k, is the step's dense
output (:mod:`braidsim.core.solver.dense` reads both kinds), on which the loop finds
events, extremes and samples as on the Runge-Kutta interpolant.

Which step the loop takes (:func:`braidsim.core.solver.loop.integrate`) needs nothing of
the model: the Taylor step where its size is at least the Runge-Kutta step the controller
proposes. Near a singularity of the solution's continuation into complex time (the branch
point of a Hertz force p^1.5 at a contact's onset and exit, the poles of a regularised
friction law at v = +-i v_hat) the radius of convergence, and with it the Taylor step,
shrinks to zero while the Runge-Kutta step does not (benchmarks/README.md, "A route to
1.5", measured this rule within 10-15 % of one that knows where the model's
singularities are).

The onset step. At a contact's onset the penetration is 0 and grows, so a power law's p^n
has a branch point there: no series in tau, and just after the onset a radius of
convergence equal to the time since it. In s = sqrt(tau) the branch point is gone:
p(t + s^2) = s^2 q(s), q(0) = p'(t) > 0, so p^n = s^(2n) q^n is a series in s wherever 2n is
an integer (:func:`~braidsim.core.interfaces.contact_force_onset_series`), and the state
follows dy/ds = 2 s dy/dt. The first step of a contact is one series of order ONSET_ORDER
in s (:func:`~braidsim.core.interfaces.model_onset_series`), its length S from the last
six coefficients of each coordinate and speed (the series interleaves sub-series, the even
powers of the free motion and the force's s^(2n + j), so that two consecutive coefficients
can both be small by accident):

    S = min over i, k in N - 5..N of (tol_i / |C[i, k]|)^(1/k),   h = S^2.

Its dense output RS[k, i] = C[i, k] S^k is a polynomial in sqrt(theta), theta = tau / h
(:mod:`braidsim.core.solver.dense`). Measured in benchmarks/README.md ("The onset step in
the core").
"""

from __future__ import annotations

import math
from typing import Any

from numba import types

from braidsim.core.generic import helper, inline_helper, overload_inlined
from braidsim.core.interfaces import (
    model_onset_series,
    model_onset_start,
    model_series,
    model_series_reach,
    model_series_start,
    pair_series_rows,
)

# In a run of Runge-Kutta steps the series is built again to test the rule only every
# RETEST-th step (testing at every step cost 5-8 % of a run in the benchmark's loop)
RETEST = 4
# the lowest order at which the series may stop (:func:`taylor_coefficients`)
MIN_ORDER = 3
STOP_SAFETY = 1e-3
# no Taylor step longer than this multiple of the distance to a contact's depth returning
# towards 0 is taken (depth_root_reach): the roots' modulus itself, the radius within which
# the force's series converges
DEPTH_REACH = 1.0
# the order of the onset step in s (the prototype's: benchmarks/lean_taylor.py)
ONSET_ORDER = 24


# (in IEEE order: with the sums reassociated, which LLVM then vectorises, the carrier's series
# of order 12 took 1.1-2.1 times as long, on sums of at most 13 terms)
@helper(always_inline=True)  # (called at every step: see core.generic.helper)
def taylor_coefficients(model, t, y, modes, v0s, n, C, W, n_dof2, tol_scale, hstop):
    """Fill C[:n, 0..N] (N = C.shape[1] - 1) with the Taylor coefficients of the state at
    (t, y) in the contact modes, and return (the time over which the model's series hold,
    the order used).

    The order adapts: the recurrence stops at the first order m >= MIN_ORDER at which the
    last two terms of every coordinate and speed at tau = ``hstop`` are within their
    tolerances (:func:`taylor_step_size`; ``tol_scale`` = (rtol, atol_x, atol_v)), and
    C[:, m + 1..N] are zero: a step of ``hstop`` then needs no more terms (a smooth free
    flight, benchmarks/README.md).
    """
    order = C.shape[1] - 1
    rtol, atol_x, atol_v = tol_scale
    for i in range(n):
        C[i, 0] = y[i]
    horizon = model_series_start(model, t, modes, order, W)
    used = order
    hk = hstop
    for k in range(order):
        model_series(model, k, modes, v0s, n, C, W)
        hk1 = hk * hstop  # hstop^(k + 1)
        if k + 1 >= MIN_ORDER:
            small = True
            for i in range(n_dof2):
                tol = STOP_SAFETY * ((atol_x if i % 2 == 0 else atol_v) + rtol * abs(C[i, 0]))
                if abs(C[i, k + 1]) * hk1 > tol or abs(C[i, k]) * hk > tol:
                    small = False
                    break
            if small:
                used = k + 1
                break
        hk = hk1
    for k in range(used + 1, order + 1):
        for i in range(n):
            C[i, k] = 0.0
    return horizon, used


@helper
def taylor_step_size(C, used, n_dof2, rtol, atol_x, atol_v, hstop):
    """Jorba & Zou's step (module docstring) over the coordinates and speeds (the energy
    quadratures follow the motion and are not controlled, as in the Runge-Kutta step's
    error norm), at most ``hstop``; ``hstop`` itself when the series stopped early at order
    ``used`` (its last terms are within tolerance there)."""
    order = C.shape[1] - 1
    if used < order:
        return hstop
    return _last_terms_step(C, n_dof2, rtol, atol_x, atol_v, order - 1, hstop)


@inline_helper
def _last_terms_step(C, n_dof2, rtol, atol_x, atol_v, k_first, hmax):
    """min(hmax, min over i < n_dof2, k_first <= k <= N of (tol_i / |C[i, k]|)^(1/k)),
    tol_i = atol_i + rtol |C[i, 0]|: the step at which each of those terms is its
    tolerance."""
    order = C.shape[1] - 1
    # the smallest step is found on the logarithms and taken by one exp: exp is monotone, so
    # it is the step the smallest of the exps would give (the same bits), for one exp
    # instead of one per term (4 a Taylor step, 12 an onset step)
    lmin = math.inf
    for i in range(n_dof2):
        tol = (atol_x if i % 2 == 0 else atol_v) + rtol * abs(C[i, 0])
        for k in range(k_first, order + 1):
            c = abs(C[i, k])
            if c > 0.0:
                lk = math.log(tol / c) / k
                if lk < lmin:
                    lmin = lk
    return min(hmax, math.exp(lmin))


@helper
def taylor_dense(C, h, n, RT):
    """The step's dense output RT[k, i] = C[i, k] h^k (a polynomial in theta = tau / h)."""
    hk = 1.0
    for k in range(C.shape[1]):
        for i in range(n):
            RT[k, i] = C[i, k] * hk
        hk *= h


@helper
def taylor_shorten(RT, theta, n):
    """Cut the dense output RT of a step to its first fraction ``theta`` (a step ended at an
    event): RT[k] theta^k."""
    tk = 1.0
    for k in range(1, RT.shape[0]):
        tk *= theta
        for i in range(n):
            RT[k, i] *= tk


@inline_helper
def taylor_component(theta, RT, i):
    """Component i of the state at fraction theta of a Taylor step: sum_k RT[k, i] theta^k
    (Horner)."""
    deg = RT.shape[0] - 1
    acc = RT[deg, i]
    for k in range(deg - 1, -1, -1):
        acc = acc * theta + RT[k, i]
    return acc


@inline_helper
def taylor_deriv(theta, h, RT, out, n):
    """Time derivative of a Taylor step's polynomial at theta for the first ``n`` components:
    sum_k k RT[k, i] theta^(k-1) / h."""
    deg = RT.shape[0] - 1
    for i in range(n):
        acc = deg * RT[deg, i]
        for k in range(deg - 1, 0, -1):
            acc = acc * theta + k * RT[k, i]
        out[i] = acc / h


@inline_helper
def depth_root_reach(model, n_pairs, modes, W, h):
    """``h``, or less where a step of it would reach a contact's depth returning towards 0
    (DEPTH_REACH times the distance to it), from its coefficients in the work array
    (:func:`~braidsim.core.interfaces.pair_series_rows`), p(tau) ~ p0 + p1 tau + p2 tau^2:

    * complex roots (p1^2 < 4 p0 p2): the depth turns short of 0, and the force's branch
      point p^n = 0 is the pair tau_m +- i sqrt(p_min / p2) near the real axis, at distance
      sqrt(p0 / p2) (the roots' product);
    * two real roots ahead, closer together than the nearer is from here (p1 < 0 < p2): the
      depth dips to 0 and back, a grazing return, at the nearer.

    The last terms of the series need not show either (docs/core.md, "A depth that returns
    towards 0"); the loop takes a Runge-Kutta step where this is shorter than ``h``. A
    single crossing ahead (an exit) or a root behind (the onset) is left to the series' own
    rule and the event location, which handle it."""
    for pair in range(n_pairs):
        if modes[pair] == 0:
            continue
        rp = pair_series_rows(model, pair)[0]
        p0 = W[rp, 0]
        p1 = W[rp, 1]
        p2 = W[rp, 2]
        if not (p0 > 0.0 and p2 > 0.0):
            continue
        disc = p1 * p1 - 4.0 * p0 * p2
        if disc < 0.0:
            h = min(h, DEPTH_REACH * math.sqrt(p0 / p2))
        elif p1 < 0.0:
            # both roots ahead: tau1 = 2 p0 / (-p1 + sqrt(disc)) and tau2 = p0 / (p2 tau1)
            tau1 = 2.0 * p0 / (math.sqrt(disc) - p1)
            tau2 = p0 / (p2 * tau1)
            if tau2 - tau1 < tau1:
                h = min(h, DEPTH_REACH * tau1)
    return h


# ---- the onset step --------------------------------------------------------------------------


@helper
def onset_coefficients(model, t, y, pair, modes, v0s, n, C, W):
    """Fill C[:n, 0..M] (M = C.shape[1] - 1) with the state's coefficients in s from the onset
    of pair ``pair`` at (t, y); return the time over which the model's series hold, 0.0 when
    the model has none in these modes."""
    order = C.shape[1] - 1
    horizon = model_onset_start(model, t, pair, modes, order, W)
    if not horizon > 0.0:
        return 0.0
    for i in range(n):
        C[i, 0] = y[i]
        C[i, 1] = 0.0
    for k in range(order - 1):
        model_onset_series(model, k, pair, modes, v0s, n, C, W)
    return horizon


@helper
def onset_step_size(C, n_dof2, rtol, atol_x, atol_v, smax):
    """The onset step's length in s (module docstring), at most ``smax``."""
    return _last_terms_step(C, n_dof2, rtol, atol_x, atol_v, C.shape[1] - 6, smax)


@helper
def _onset_taylor(model, t, y, pair, modes, v0s, n, n_dof2, tols, hstop, t_left, CS, W, RS):
    horizon = onset_coefficients(model, t, y, pair, modes, v0s, n, CS, W)
    if not horizon > 0.0:
        return 0.0
    rtol, atol_x, atol_v = tols
    s = onset_step_size(CS, n_dof2, rtol, atol_x, atol_v, math.sqrt(min(hstop, horizon)))
    s = model_series_reach(model, CS, s)  # (its polynomials are in s)
    h = s * s
    if h >= t_left * (1.0 - 1e-9):
        h = t_left  # (the loop reaches its stop exactly)
        s = math.sqrt(h)
    if not (h > 0.0 and math.isfinite(h)):
        return 0.0
    taylor_dense(CS, s, n, RS)
    return h


def onset_step(model, t, y, pair, modes, v0s, n, n_dof2, tols, hstop, t_left, TAY):
    """The onset step from (t, y), where pair ``pair`` has just touched: writes the step's
    dense output into ``TAY.RS`` and returns its length h [s], at most ``hstop`` (``t_left``
    exactly when it reaches the loop's stop); 0.0 when the model has no onset series in
    these modes, or its work arrays were not made (``TAY.onset`` None: compiled out)."""
    # (compiled code calls _no_onset or _with_onset, chosen by the type of TAY.onset)
    if TAY.onset is None:
        return 0.0
    return _with_onset(model, t, y, pair, modes, v0s, n, n_dof2, tols, hstop, t_left, TAY)


def _no_onset(model, t, y, pair, modes, v0s, n, n_dof2, tols, hstop, t_left, TAY):
    return 0.0


def _with_onset(model, t, y, pair, modes, v0s, n, n_dof2, tols, hstop, t_left, TAY):
    return _onset_taylor(
        model, t, y, pair, modes, v0s, n, n_dof2, tols, hstop, t_left, TAY.CS, TAY.W, TAY.RS
    )


def _onset_typer(
    model: Any,
    t: Any,
    y: Any,
    pair: Any,
    modes: Any,
    v0s: Any,
    n: Any,
    n_dof2: Any,
    tols: Any,
    hstop: Any,
    t_left: Any,
    TAY: Any,
) -> Any:
    onset = TAY.types[TAY.fields.index("onset")]
    return _no_onset if isinstance(onset, types.NoneType) else _with_onset


overload_inlined(onset_step, _onset_typer)


@inline_helper
def onset_component(theta, RS, i):
    """Component i of the state at fraction theta (of the time) of an onset step: its
    polynomial in s at sqrt(theta)."""
    return taylor_component(math.sqrt(theta), RS, i)


@inline_helper
def onset_deriv(theta, h, RS, out, n):
    """Time derivative of an onset step's polynomial at theta for the first ``n`` components:
    with sigma = sqrt(theta), d/dt = (d/dsigma) / (2 sigma h) = sum_{k>=2} k RS[k, i]
    sigma^(k-2) / (2 h) (RS[1] = 0: dy/ds = 2 s dy/dt), finite at the onset itself."""
    deg = RS.shape[0] - 1
    sg = math.sqrt(theta)
    for i in range(n):
        acc = deg * RS[deg, i]
        for k in range(deg - 1, 1, -1):
            acc = acc * sg + k * RS[k, i]
        out[i] = acc / (2.0 * h)
