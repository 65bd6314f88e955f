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
"""

from __future__ import annotations

import math

from braidsim.core.generic import helper, inline_helper
from braidsim.core.interfaces import model_series, model_series_start

# In a run of Runge-Kutta steps the series is built again to test the rule only every
# RETEST-th step (testing at every step cost 5-8 % of a run in the benchmark's loop)
RETEST = 4
# the lowest order at which the series may stop (:func:`taylor_coefficients`)
MIN_ORDER = 3
STOP_SAFETY = 1e-3


# (in IEEE order: with the sums reassociated, which LLVM then vectorises, the carrier's series
# of order 12 took 1.1-2.1 times as long, on sums of at most 13 terms)
@helper
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
    h = hstop
    for i in range(n_dof2):
        tol = (atol_x if i % 2 == 0 else atol_v) + rtol * abs(C[i, 0])
        for k in range(order - 1, order + 1):
            c = abs(C[i, k])
            if c > 0.0:
                hk = math.exp(math.log(tol / c) / k)
                if hk < h:
                    h = hk
    return h


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
