"""The L-stable Radau IIA method of order 5 for resting contacts, with its collocation
polynomial as dense output.

A carrier that rests on a wall for many steps (the force following the wall's motion
quasi-statically) makes the equations stiff: the contact's fast mode holds an explicit step
near h |lambda| ~ 1 whatever the tolerance (on paper-3.3's resting orbit it is overdamped,
eigenvalues -190 and -78,700 1/s, because the damping term K p^n D p'/v0 is large where the
latched approach speed v0 sits at its floor). An L-stable implicit method follows the slow
motion with steps set by accuracy. The step loop (:mod:`braidsim.core.solver.loop`) hands a
resting contact to this method and takes it back at the next event.

Method: the 3-stage Radau IIA collocation method (order 5, stage order 3, L-stable), solved
by simplified Newton iterations in the eigenbasis of its coefficient matrix (one real and one
complex linear system per iteration, the complex one solved in real form), with the embedded
error estimate filtered through the real system, as in Hairer's RADAU5: Hairer & Wanner,
Solving Ordinary Differential Equations II, 2nd ed. (1996), Sect. IV.8,
doi:10.1007/978-3-642-05221-7. The transformation matrices T, T^-1, the collocation
weights P, the Newton tolerance and iteration limit and the safety factor are those of
SciPy's ``Radau`` (Virtanen et al., Nat. Methods 17 (2020) 261-272,
doi:10.1038/s41592-019-0686-2), whose eigenvectors are normalised differently from
RADAU5's (a reader comparing with ``radau5.f`` finds other numbers for the same method).
With the stages' increments
Z_i = y(t + c_i h) - y::

    Z = h (A (x) I) F(Z),   y1 = y + Z_3,
    dense output y(t + theta h) = y + sum_{j=1..3} Q_j theta^j  (the collocation polynomial)

The Jacobian J = df/dy over the coordinates and speeds is taken by forward differences at
the start of every step (n_dof2 evaluations), so that a run interrupted and resumed at any
step takes the same steps bit for bit (it is kept across a rejected attempt only). The
quadratures (energy works) depend on no other component's derivative: the linear systems are
solved for the coordinates and speeds, and each quadrature follows by substitution. The
model's equations are called through :func:`~braidsim.core.solver.calls.rhs`, so that this
rarely used step does not compile another copy of them.
"""

from __future__ import annotations

import math

from braidsim.core.generic import helper
from braidsim.core.solver.calls import rhs

S6 = math.sqrt(6.0)
# nodes (c_3 = 1) and the error estimate's weights
NODE1 = (4.0 - S6) / 10.0
NODE2 = (4.0 + S6) / 10.0
RE1 = (-13.0 - 7.0 * S6) / 3.0
RE2 = (-13.0 + 7.0 * S6) / 3.0
RE3 = -1.0 / 3.0
# the eigenvalues of A^-1: one real, one complex pair
MU_REAL = 3.0 + 3.0 ** (2.0 / 3.0) - 3.0 ** (1.0 / 3.0)
MU_RE = 3.0 + 0.5 * (3.0 ** (1.0 / 3.0) - 3.0 ** (2.0 / 3.0))  # MU_COMPLEX = MU_RE + i MU_IM
MU_IM = -0.5 * (3.0 ** (5.0 / 6.0) + 3.0 ** (7.0 / 6.0))
# A = T diag(MU_REAL, MU_COMPLEX, conj)^-1 T^-1 in real form (W = TI Z, Z = T W)
T11, T12, T13 = 0.09443876248897524, -0.14125529502095421, 0.03002919410514742
T21, T22, T23 = 0.25021312296533332, 0.20412935229379994, -0.38294211275726192
T31, T32 = 1.0, 1.0
TI11, TI12, TI13 = 4.17871859155190428, 0.32768282076106237, 0.52337644549944951
TI21, TI22, TI23 = -4.17871859155190428, -0.32768282076106237, 0.47662355450055044
TI31, TI32, TI33 = 0.50287263494578682, -2.57192694985560522, 0.59603920482822492
# collocation polynomial: Q_j = sum_i Z_i P[i, j]
P11, P12, P13 = 13.0 / 3.0 + 7.0 * S6 / 3.0, -23.0 / 3.0 - 22.0 * S6 / 3.0, 10.0 / 3.0 + 5.0 * S6
P21, P22, P23 = 13.0 / 3.0 - 7.0 * S6 / 3.0, -23.0 / 3.0 + 22.0 * S6 / 3.0, 10.0 / 3.0 - 5.0 * S6
P31, P32, P33 = 1.0 / 3.0, -8.0 / 3.0, 10.0 / 3.0


NEWTON_MAXITER = 6
SQRT_EPS = 1.4901161193847656e-08
# what :func:`implicit_attempt` reports besides the error norm
ATTEMPT_OK = 0
ATTEMPT_NO_CONVERGENCE = -1  # the collocation equations did not converge: retry shorter
ATTEMPT_SINGULAR = -2  # a linear system is singular
NEWTON_SINGULAR = -2  # :func:`_collocate`'s iterations where a linear system is singular


@helper
def _jacobian(model, t, y, f0, modes, v0s, n, m, atol_x, atol_v, rtol, J, yp, fp):
    """Forward differences J[:, k] = df/dy_k for the coordinates and speeds (k < m = n_dof2,
    all n rows), f0 = f(t, y); increments sqrt(eps) max(|y_k|, atol_k / rtol)."""
    for i in range(n):
        yp[i] = y[i]
    for k in range(m):
        floor = (atol_x if k % 2 == 0 else atol_v) / rtol
        yk = y[k]
        yp[k] = yk + SQRT_EPS * max(abs(yk), floor)
        d = yp[k] - yk  # the increment as represented
        rhs(model, t, yp, modes, v0s, n, fp)
        for i in range(n):
            J[i, k] = (fp[i] - f0[i]) / d
        yp[k] = yk


@helper
def _lu(A, piv, m):
    """In-place LU factors with partial pivoting of the m x m matrix A (m <= 8 here, where a
    library call costs more than the elimination). False when singular."""
    for k in range(m):
        p = k
        for i in range(k + 1, m):
            if abs(A[i, k]) > abs(A[p, k]):
                p = i
        piv[k] = p
        if A[p, k] == 0.0:
            return False
        if p != k:
            for c in range(m):
                tmp = A[k, c]
                A[k, c] = A[p, c]
                A[p, c] = tmp
        inv = 1.0 / A[k, k]
        for i in range(k + 1, m):
            f = A[i, k] * inv
            A[i, k] = f
            for c in range(k + 1, m):
                A[i, c] -= f * A[k, c]
    return True


@helper
def _lu_solve(A, piv, m, b):
    """b <- A^-1 b from the factors of :func:`_lu` (whose row swaps moved the multipliers
    too: all the swaps first, then the two substitutions)."""
    for k in range(m):
        p = piv[k]
        if p != k:
            tmp = b[k]
            b[k] = b[p]
            b[p] = tmp
    for k in range(m):
        for i in range(k + 1, m):
            b[i] -= A[i, k] * b[k]
    for k in range(m - 1, -1, -1):
        acc = b[k]
        for c in range(k + 1, m):
            acc -= A[k, c] * b[c]
        b[k] = acc / A[k, k]


@helper
def _factor(J, h, m, LUR, pivr, LUC, pivc):
    """LU factors of MU_REAL / h - J and, in real form, of (MU_RE + i MU_IM) / h - J over the
    coordinates and speeds: [[a - J, -b], [b, a - J]] with a + i b = MU_COMPLEX / h."""
    mr = MU_REAL / h
    a = MU_RE / h
    b = MU_IM / h
    for i in range(m):
        for k in range(m):
            LUR[i, k] = -J[i, k]
            LUC[i, k] = -J[i, k]
            LUC[m + i, m + k] = -J[i, k]
            LUC[i, m + k] = 0.0
            LUC[m + i, k] = 0.0
        LUR[i, i] += mr
        LUC[i, i] += a
        LUC[m + i, m + i] += a
        LUC[i, m + i] = -b
        LUC[m + i, i] = b
    return _lu(LUR, pivr, m) and _lu(LUC, pivc, 2 * m)


@helper
def _solve_real(J, LUR, pivr, h, n, m, b):
    """b <- (MU_REAL / h - J)^-1 b; each quadrature (row MU_REAL / h e_i - J[i, :m]) by
    substitution."""
    _lu_solve(LUR, pivr, m, b)
    mr = MU_REAL / h
    for i in range(m, n):
        acc = b[i]
        for k in range(m):
            acc += J[i, k] * b[k]
        b[i] = acc / mr


@helper
def _solve_complex(J, LUC, pivc, h, n, m, br, bi, v):
    """br + i bi <- (MU_COMPLEX / h - J)^-1 (br + i bi), through the real form; ``v`` is
    scratch of length 2m."""
    for k in range(m):
        v[k] = br[k]
        v[m + k] = bi[k]
    _lu_solve(LUC, pivc, 2 * m, v)
    for k in range(m):
        br[k] = v[k]
        bi[k] = v[m + k]
    a = MU_RE / h
    b = MU_IM / h
    den = a * a + b * b
    for i in range(m, n):
        xr = br[i]
        xi = bi[i]
        for k in range(m):
            xr += J[i, k] * br[k]
            xi += J[i, k] * bi[k]
        # (xr + i xi) / (a + i b)
        br[i] = (xr * a + xi * b) / den
        bi[i] = (xi * a - xr * b) / den


@helper
def _newton(
    model, t, y, h, K, modes, v0s, n, m, J, LUR, pivr, LUC, pivc, Z, W, B, V, scale, tol, Q, hq
):
    """Solve the collocation equations of the step of size h from (t, y) (K[0] = f(t, y);
    the factors for this h) by simplified Newton iterations; the stage derivatives go to
    K[1..3]. Returns (iterations, evaluations); iterations < 0 when they did not converge.
    On success Z holds the stages' increments.

    The iterations start, as RADAU5's, from the collocation polynomial of the previous step
    (of size ``hq``, coefficients Q; this step starts at its end) extrapolated to this step's
    nodes: with s = c_i h / hq, Z_i = s (Q_1 + (2 + s) Q_2 + (3 + 3 s + s^2) Q_3), that is
    P(1 + s) - P(1) written without the difference. Without one (``hq`` = 0: the first
    implicit step after the explicit method, an event or a new run), from Z_i = c_i h f(t, y).
    The predictive test below gives up on iterations that cannot converge within
    NEWTON_MAXITER; from the crude start its first increment is ~1e4 tolerances, and a
    carrier resting on the outer wall of paper-3.3 had most of its steps rejected so, though
    the iterations converged (rates 0.05-0.23)."""
    mr = MU_REAL / h
    a = MU_RE / h
    b = MU_IM / h
    for i in range(n):
        if hq > 0.0:
            for s in range(3):
                cs = NODE1 if s == 0 else (NODE2 if s == 1 else 1.0)
                x = cs * h / hq
                Z[s, i] = x * (Q[0, i] + (2.0 + x) * Q[1, i] + (3.0 + x * (3.0 + x)) * Q[2, i])
        else:
            Z[0, i] = NODE1 * h * K[0, i]
            Z[1, i] = NODE2 * h * K[0, i]
            Z[2, i] = h * K[0, i]
        W[0, i] = TI11 * Z[0, i] + TI12 * Z[1, i] + TI13 * Z[2, i]
        W[1, i] = TI21 * Z[0, i] + TI22 * Z[1, i] + TI23 * Z[2, i]
        W[2, i] = TI31 * Z[0, i] + TI32 * Z[1, i] + TI33 * Z[2, i]
    norm_old = -1.0
    nfev = 0
    for k in range(NEWTON_MAXITER):
        for s in range(3):
            cs = NODE1 if s == 0 else (NODE2 if s == 1 else 1.0)
            for i in range(n):
                B[3, i] = y[i] + Z[s, i]
            rhs(model, t + cs * h, B[3], modes, v0s, n, K[s + 1])
        nfev += 3
        for i in range(n):
            f1, f2, f3 = K[1, i], K[2, i], K[3, i]
            B[0, i] = TI11 * f1 + TI12 * f2 + TI13 * f3 - mr * W[0, i]
            # (TI21 f + i TI31 f) - (a + i b) (W1 + i W2)
            fr = TI21 * f1 + TI22 * f2 + TI23 * f3
            fi = TI31 * f1 + TI32 * f2 + TI33 * f3
            B[1, i] = fr - (a * W[1, i] - b * W[2, i])
            B[2, i] = fi - (a * W[2, i] + b * W[1, i])
            if not (math.isfinite(B[0, i]) and math.isfinite(B[1, i]) and math.isfinite(B[2, i])):
                return -1, nfev
        _solve_real(J, LUR, pivr, h, n, m, B[0])
        _solve_complex(J, LUC, pivc, h, n, m, B[1], B[2], V)
        acc = 0.0
        for i in range(m):
            acc += (B[0, i] / scale[i]) ** 2 + (B[1, i] / scale[i]) ** 2
            acc += (B[2, i] / scale[i]) ** 2
        dw_norm = math.sqrt(acc / (3 * m))
        rate = -1.0
        if norm_old > 0.0:
            rate = dw_norm / norm_old
            if rate >= 1.0 or rate ** (NEWTON_MAXITER - k) / (1.0 - rate) * dw_norm > tol:
                return -1, nfev
        for i in range(n):
            W[0, i] += B[0, i]
            W[1, i] += B[1, i]
            W[2, i] += B[2, i]
            Z[0, i] = T11 * W[0, i] + T12 * W[1, i] + T13 * W[2, i]
            Z[1, i] = T21 * W[0, i] + T22 * W[1, i] + T23 * W[2, i]
            Z[2, i] = T31 * W[0, i] + T32 * W[1, i]
        if dw_norm == 0.0 or (rate > 0.0 and rate / (1.0 - rate) * dw_norm < tol):
            return k + 1, nfev
        norm_old = dw_norm
    return -1, nfev


@helper
def _error(model, t, y, h, K, y1, modes, v0s, n, m, J, LUR, pivr, Z, B, scale):
    """The embedded error estimate's scaled RMS over the coordinates and speeds, filtered
    through (MU_REAL / h - J)^-1 as in RADAU5; above 1 it is filtered once more through f
    (Hairer & Wanner II, Sect. IV.8), one evaluation. Returns (norm, evaluations)."""
    for i in range(n):
        B[0, i] = K[0, i] + (RE1 * Z[0, i] + RE2 * Z[1, i] + RE3 * Z[2, i]) / h
    _solve_real(J, LUR, pivr, h, n, m, B[0])
    err = _norm(B[0], scale, m)
    if err <= 1.0:
        return err, 0
    for i in range(n):
        B[3, i] = y[i] + B[0, i]
    rhs(model, t, B[3], modes, v0s, n, B[0])
    for i in range(n):
        B[0, i] += (RE1 * Z[0, i] + RE2 * Z[1, i] + RE3 * Z[2, i]) / h
    _solve_real(J, LUR, pivr, h, n, m, B[0])
    return _norm(B[0], scale, m), 1


@helper
def _scale(y, z, m, opts, scale):
    """scale = atol + rtol max(|y|, |z|) over the coordinates and speeds (z = y: the start's
    alone), the weights of the Newton and error norms."""
    for i in range(m):
        atol = opts.atol_position if i % 2 == 0 else opts.atol_velocity
        scale[i] = atol + opts.rtol * max(abs(y[i]), abs(z[i]))


@helper
def _newton_tol(rtol):
    """The tolerance of the Newton iterations in the scaled norm, as SciPy's ``Radau``
    (RADAU5 applies the same rule to a transformed rtol)."""
    return max(10.0 * 2.220446049250313e-16 / rtol, min(0.03, math.sqrt(rtol)))


@helper
def _norm(v, scale, m):
    acc = 0.0
    for i in range(m):
        acc += (v[i] / scale[i]) ** 2
    return math.sqrt(acc / m)


@helper
def _finish(y, Z, n, y1, RC):
    """y1 = y + Z_3 and the dense coefficients RC of the collocation polynomial in the basis
    of :func:`~braidsim.core.solver.dopri5.interpolant_component`: with the polynomial
    y + Q1 theta + Q2 theta^2 + Q3 theta^3, r0 = y, r1 = Q1 + Q2 + Q3, r2 = -Q2 - Q3,
    r3 = -Q3, r4 = 0."""
    for i in range(n):
        q1 = P11 * Z[0, i] + P21 * Z[1, i] + P31 * Z[2, i]
        q2 = P12 * Z[0, i] + P22 * Z[1, i] + P32 * Z[2, i]
        q3 = P13 * Z[0, i] + P23 * Z[1, i] + P33 * Z[2, i]
        y1[i] = y[i] + Z[2, i]
        RC[0, i] = y[i]
        RC[1, i] = q1 + q2 + q3
        RC[2, i] = -q2 - q3
        RC[3, i] = -q3
        RC[4, i] = 0.0


@helper
def _collocate(model, t, y, h, K, modes, v0s, n, m, opts, IMP, hq):
    """The factors for step size h, then the collocation equations of the step from (t, y)
    solved by :func:`_newton` (norm weights in ``IMP.scale``; started from the polynomial
    ``IMP.Q`` of a previous step of size ``hq``, if not 0). Returns (iterations,
    evaluations): iterations NEWTON_SINGULAR where a system is singular, otherwise as
    :func:`_newton`'s."""
    J, LUR, pivr, LUC, pivc = IMP.J, IMP.LUR, IMP.pivr, IMP.LUC, IMP.pivc
    if not _factor(J, h, m, LUR, pivr, LUC, pivc):
        return NEWTON_SINGULAR, 0
    return _newton(
        model,
        t,
        y,
        h,
        K,
        modes,
        v0s,
        n,
        m,
        J,
        LUR,
        pivr,
        LUC,
        pivc,
        IMP.Z,
        IMP.W,
        IMP.B,
        IMP.V,
        IMP.scale,
        _newton_tol(opts.rtol),
        IMP.Q,
        hq,
    )


@helper
def implicit_attempt(model, t, y, h, K, modes, v0s, n, m, opts, jac_fresh, IMP, y1, RC, hq):
    """One attempt of a Radau IIA step of size h from (t, y), K[0] = f(t, y).

    Takes the Jacobian at (t, y) unless ``jac_fresh`` (an attempt from the same point was
    rejected), factors, solves the collocation equations (from the previous implicit step's
    polynomial ``IMP.Q`` when ``hq``, its size, is not 0); on success fills y1, the dense
    coefficients RC and K[6] = f(t + h, y1) (the next step's first derivative, as the
    explicit method's FSAL stage). Returns (ATTEMPT_*, error norm, Newton iterations,
    evaluations).
    """
    J, LUR, pivr = IMP.J, IMP.LUR, IMP.pivr
    Z, B, scale = IMP.Z, IMP.B, IMP.scale
    nfev = 0
    if not jac_fresh:
        _jacobian(
            model,
            t,
            y,
            K[0],
            modes,
            v0s,
            n,
            m,
            opts.atol_position,
            opts.atol_velocity,
            opts.rtol,
            J,
            B[3],
            B[0],
        )
        nfev += m
    _scale(y, y, m, opts, scale)
    iters, ne = _collocate(model, t, y, h, K, modes, v0s, n, m, opts, IMP, hq)
    if iters == NEWTON_SINGULAR:
        return ATTEMPT_SINGULAR, math.inf, 0, nfev
    nfev += ne
    if iters < 0:
        return ATTEMPT_NO_CONVERGENCE, math.inf, iters, nfev
    _finish(y, Z, n, y1, RC)
    _scale(y, y1, m, opts, scale)
    err, ne = _error(model, t, y, h, K, y1, modes, v0s, n, m, J, LUR, pivr, Z, B, scale)
    rhs(model, t + h, y1, modes, v0s, n, K[6])
    return ATTEMPT_OK, err, iters, nfev + ne + 1


@helper
def implicit_to(model, t, y, he, theta, K, Ke, modes, v0s, n, m, opts, IMP, ye, RC):
    """The step recomputed from (t, y) to an event at he = theta h (J from the step's start);
    fills ye, RC and Ke[6] = f(t + he, ye) (Ke[0] = K[0]). Should the equations over the
    shorter step not converge, the state at the event is the collocation polynomial's (order
    3 there instead of 5), restricted to [0, theta]. Returns the evaluations."""
    iters, nfev = _collocate(model, t, y, he, Ke, modes, v0s, n, m, opts, IMP, 0.0)
    if iters >= 0:
        _finish(y, IMP.Z, n, ye, RC)
    else:
        radau_restrict(RC, theta, n, ye)
    rhs(model, t + he, ye, modes, v0s, n, Ke[6])
    return nfev + 1


@helper
def keep_polynomial(RC, n, Q):
    """Q = the coefficients of the collocation polynomial of the step whose dense
    coefficients RC :func:`_finish` wrote (q3 = -r3, q2 = r3 - r2, q1 = r1 + r2): the next
    implicit step's Newton start."""
    for i in range(n):
        Q[0, i] = RC[1, i] + RC[2, i]
        Q[1, i] = RC[3, i] - RC[2, i]
        Q[2, i] = -RC[3, i]


@helper
def radau_restrict(RC, theta, n, y1):
    """Restrict the collocation polynomial of RC to [0, theta], rescaled to [0, 1], and
    y1 = its value at theta."""
    for i in range(n):
        q1 = (RC[1, i] + RC[2, i]) * theta
        q2 = (RC[3, i] - RC[2, i]) * theta * theta
        q3 = -RC[3, i] * theta * theta * theta
        y1[i] = RC[0, i] + q1 + q2 + q3
        RC[1, i] = q1 + q2 + q3
        RC[2, i] = -q2 - q3
        RC[3, i] = -q3
        RC[4, i] = 0.0


@helper
def radau_safety(iterations):
    """RADAU5's safety factor of the step-size controller: 0.9, less after slow Newton
    iterations."""
    return 0.9 * (2 * NEWTON_MAXITER + 1) / (2 * NEWTON_MAXITER + max(iterations, 1))
