"""The Dormand-Prince 5(4) pair with its 4th-order continuous extension.

The pair: Dormand & Prince, A family of embedded Runge-Kutta formulae, J. Comput. Appl.
Math. 6 (1980) 19-26, doi:10.1016/0771-050X(80)90013-3. Its tableau, error weights and the
dense output's coefficients as in Hairer's code DOPRI5: Hairer, Norsett & Wanner, Solving
Ordinary Differential Equations I, 2nd ed. (1993), Sect. II.5 and II.6,
doi:10.1007/978-3-540-78862-1. The stage
loops run over the ``n`` components the run integrates (coordinates and speeds, plus the
energy quadratures only when asked).
"""

from __future__ import annotations

import math

import numpy as np

from braidsim.core.generic import helper, inline_helper
from braidsim.core.interfaces import derivatives

C2, C3, C4, C5 = 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0
A21 = 1.0 / 5.0
A31, A32 = 3.0 / 40.0, 9.0 / 40.0
A41, A42, A43 = 44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0
A51, A52, A53, A54 = 19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0
A61, A62, A63, A64, A65 = (
    9017.0 / 3168.0,
    -355.0 / 33.0,
    46732.0 / 5247.0,
    49.0 / 176.0,
    -5103.0 / 18656.0,
)
A71, A73, A74, A75, A76 = 35.0 / 384.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0
E1, E3, E4, E5, E6, E7 = (
    71.0 / 57600.0,
    -71.0 / 16695.0,
    71.0 / 1920.0,
    -17253.0 / 339200.0,
    22.0 / 525.0,
    -1.0 / 40.0,
)
D1, D3, D4, D5, D6, D7 = (
    -12715105075.0 / 11282082432.0,
    87487479700.0 / 32700410799.0,
    -10690763975.0 / 1880347072.0,
    701980252875.0 / 199316789632.0,
    -1453857185.0 / 822651844.0,
    69997945.0 / 29380423.0,
)
# the tableau as arrays for the tangents' stage loop: RK_A[s] gives stage s (row 6: the solution),
# RK_C[s] its time fraction
RK_A = np.zeros((7, 6))
RK_A[1, :1] = (A21,)
RK_A[2, :2] = (A31, A32)
RK_A[3, :3] = (A41, A42, A43)
RK_A[4, :4] = (A51, A52, A53, A54)
RK_A[5, :5] = (A61, A62, A63, A64, A65)
RK_A[6, :6] = (A71, 0.0, A73, A74, A75, A76)
RK_C = np.array([0.0, C2, C3, C4, C5, 1.0, 1.0])


@helper(always_inline=True)  # (called at every step: see core.generic.helper)
def rk_step(model, t, y, h, K, modes, v0s, n, yt, y1):
    """One step of size h from (t, y) with K[0] = f(t, y); fills K[1..6] and y1.

    Stage s (1..5) is evaluated at y + h sum_j A[s, j] K[j]; the solution y1 uses row A[6]
    (the 5th-order weights) and K[6] = f(t + h, y1) is the first stage of the next step.
    Each stage's combination is written out, so that its coefficients are constants of the
    code; the right-hand side is called from one place, so that it is compiled into the
    step once, not six times (11 s less to compile from an empty cache).
    """
    for s in range(1, 7):
        ys = y1 if s == 6 else yt
        for i in range(n):
            if s == 1:
                acc = A21 * K[0, i]
            elif s == 2:
                acc = A31 * K[0, i] + A32 * K[1, i]
            elif s == 3:
                acc = A41 * K[0, i] + A42 * K[1, i] + A43 * K[2, i]
            elif s == 4:
                acc = A51 * K[0, i] + A52 * K[1, i] + A53 * K[2, i] + A54 * K[3, i]
            elif s == 5:
                acc = A61 * K[0, i] + A62 * K[1, i] + A63 * K[2, i] + A64 * K[3, i] + A65 * K[4, i]
            else:
                acc = A71 * K[0, i] + A73 * K[2, i] + A74 * K[3, i] + A75 * K[4, i] + A76 * K[5, i]
            ys[i] = y[i] + h * acc
        derivatives(model, t + RK_C[s] * h, ys, modes, v0s, n, K[s])


@helper
def onset_error_ratio(q):
    """How far the embedded error estimate falls short on the first step of a contact.

    A contact whose force grows as tau^n after onset (tau = t - t_on; n the exponent of a
    power law, q = n + 1 the exponent of that step's error, as
    :func:`~braidsim.core.interfaces.contact_onset_step` gives it) adds to the motion the
    component x'' = c tau^n, which is not a polynomial when n is not an integer. On a step
    [0, h] from the onset both the true local error of that component and its embedded
    estimate scale as c h^(n+1) (speed) and c h^(n+2) (position), with different constants:
    their ratio does not depend on h or c. It is computed here by applying the tableau to
    x'' = tau^n from rest over a unit step, against the closed form x = tau^(n+2) / ((n+1)
    (n+2)), x' = tau^(n+1) / (n+1). For the Hertz exponent n = 3/2 the estimate is 11.3
    times too small in the speed (3.6 in the position); the solver multiplies that step's
    estimate by the larger ratio (at least 1). An integer n (a linear spring, a dashpot
    whose force jumps at onset) has no such component: 1.
    """
    n = q - 1.0
    if n == math.floor(n):
        return 1.0
    # the speed's stage derivatives tau^n at the stage times (the last two at tau = 1), and
    # the speed at each stage, which is the position's stage derivative
    k2, k3, k4, k5 = C2**n, C3**n, C4**n, C5**n
    k6 = k7 = 1.0
    v3 = A32 * k2
    v4 = A42 * k2 + A43 * k3
    v5 = A52 * k2 + A53 * k3 + A54 * k4
    v6 = A62 * k2 + A63 * k3 + A64 * k4 + A65 * k5
    v7 = A73 * k3 + A74 * k4 + A75 * k5 + A76 * k6  # the 5th-order speed (A72 = 0)
    x1 = A73 * v3 + A74 * v4 + A75 * v5 + A76 * v6
    ev = E3 * k3 + E4 * k4 + E5 * k5 + E6 * k6 + E7 * k7
    ex = E3 * v3 + E4 * v4 + E5 * v5 + E6 * v6 + E7 * v7
    true_x = x1 - 1.0 / ((n + 1.0) * (n + 2.0))
    true_v = v7 - 1.0 / (n + 1.0)
    ratio = 1.0
    if ev != 0.0:
        ratio = max(ratio, abs(true_v / ev))
    if ex != 0.0:
        ratio = max(ratio, abs(true_x / ex))
    return ratio


@inline_helper
def embedded_error(h, K, i):
    """The embedded error estimate of component i over the step: h sum_s E_s k_s."""
    return h * (
        E1 * K[0, i] + E3 * K[2, i] + E4 * K[3, i] + E5 * K[4, i] + E6 * K[5, i] + E7 * K[6, i]
    )


@helper
def error_norm(y, y1, h, K, n_dof2, rtol, atol_x, atol_v):
    """RMS of the embedded error estimate, each component scaled by
    atol + rtol max(|y0_i|, |y1_i|) (ibid. Sect. II.4, "Automatic step size control"), over
    the coordinates and speeds (the energy quadratures follow the motion and are not
    controlled)."""
    acc = 0.0
    for i in range(n_dof2):
        atol = atol_x if i % 2 == 0 else atol_v
        err = embedded_error(h, K, i)
        sc = atol + rtol * max(abs(y[i]), abs(y1[i]))
        acc += (err / sc) ** 2
    return math.sqrt(acc / n_dof2)


@helper
def quadrature_error(y, y1, h, K, i, rtol):
    """The embedded error estimate of component i over rtol max(|y0_i|, |y1_i|), for an
    energy quadrature whose error the step must bound where the motion's does not (no
    absolute part: the quadratures that need it are positive; 0 where the estimate is 0)."""
    err = embedded_error(h, K, i)
    if err == 0.0:
        return 0.0
    return abs(err) / (rtol * max(abs(y[i]), abs(y1[i])) + 1e-300)


@helper
def dense_coeffs(y, y1, h, K, RC, n):
    """Coefficients of the continuous extension of the step (Hairer's CONTD5)."""
    for i in range(n):
        ydiff = y1[i] - y[i]
        bspl = h * K[0, i] - ydiff
        RC[0, i] = y[i]
        RC[1, i] = ydiff
        RC[2, i] = bspl
        RC[3, i] = ydiff - h * K[6, i] - bspl
        RC[4, i] = h * (
            D1 * K[0, i] + D3 * K[2, i] + D4 * K[3, i] + D5 * K[4, i] + D6 * K[5, i] + D7 * K[6, i]
        )


@inline_helper
def interpolant_component(theta, RC, i):
    """Component i of the state at fraction theta of the step, on the continuous extension
    (the nested form of DOPRI5's CONTD5)."""
    th1 = 1.0 - theta
    return RC[0, i] + theta * (RC[1, i] + th1 * (RC[2, i] + theta * (RC[3, i] + th1 * RC[4, i])))


@inline_helper
def interpolant_deriv(theta, h, RC, out, n):
    """Time derivative of the continuous extension at theta for the first ``n`` components
    (d/dtheta of :func:`interpolant_component`, divided by h); it equals the RK derivative
    at both ends of the step."""
    th1 = 1.0 - theta
    for i in range(n):
        b = RC[3, i] + th1 * RC[4, i]
        c = RC[2, i] + theta * b
        d = RC[1, i] + th1 * c
        out[i] = (d + theta * (th1 * (b - theta * RC[4, i]) - c)) / h
