"""The lean loop of ``lean_dp5.py`` with Taylor-series steps where the solution is smooth: what
a Taylor method buys on the x-only carrier (an experiment for the design of the core).

Same model, parameter vector, episode rows and event semantics as :mod:`lean_dp5`, whose
compiled functions it reuses (the rule for a contact present at t = 0, the latched speed floor
v_min, force peaks where dN/dt changes from + to - across a step, N at every step end folded
in). Between events the solution is analytic in t except at a few complex singularities, so
high-order Taylor steps are long; Dormand-Prince 5(4) steps are taken only where one of those
singularities is close.

Taylor step (order N, default 12). From (t, x, v) the coefficients x_k, v_k of x(t + tau) and
x'(t + tau) follow from the equation of motion by automatic-differentiation recurrences
(x_{k+1} = v_k / (k + 1), v_{k+1} = a_k / (k + 1), a_k the k-th coefficient of the acceleration;
Jorba & Zou, A software package for the numerical integration of ODEs by means of high-order
Taylor methods, Experimental Mathematics 14 (2005) 99-117, doi:10.1080/10586458.2005.10128904):

    friction  U = v / v_hat, W = 1 + U^2 (a Cauchy product), Z = atan U from Z' W = U':
              k Z_k W_0 = k U_k - sum_{j=1}^{k-1} j Z_j W_{k-j}
    wall      h_k = h_a w^k / k! cos(w t + phase + k pi / 2)   (analytically)
    contact   p_k from x_k and h_k; P = p^n from P' p = n p' P:
              k p_0 P_k = sum_{j=0}^{k-1} (n (k - j) - j) p_{k-j} P_j
              N_k = K (P_k + (D / v0) (P p')_k),   p'_m = (m + 1) p_{m+1}

The step size is Jorba & Zou's first rule: h = min (tol_c / |c_k|)^(1/k) over c = x, x' and
k = N - 1, N, with tol_c = atol_c + rtol |c_0|, capped at hmax; there is no error estimate and
no rejection. In free flight the order is adaptive: the recurrence stops at the first order
>= 3 at which the last two terms of x and x' at tau = hmax (or to t_end) are within
tolerance. Contact events
are found on the polynomials (in flight the gap to either wall, the wall as its series; in
contact the penetration) at 4 equally spaced points of the step and located by the Illinois
method on the polynomial; in flight there is no check where sum_k |x_k| h^k keeps the carrier
off both walls whatever their phase. A force peak is located on the polynomial of N.

Onset step in s = sqrt(tau). At a contact onset p = 0 and p' > 0, so p^n (n = 1.5) has a branch
point at tau = 0: it has no Taylor series there, and just after the onset the radius of
convergence is the time since the onset. In s the branch point is gone: p(t_on + s^2) =
s^2 q(s) with q analytic and q(0) = p'(t_on) > 0, so p^1.5 = s^3 q(s)^1.5 and
N = K s^3 q^1.5 (1 + (D / v0) p'), p' = dp/dtau = sum_m (m + 2) q_m s^m / 2, are analytic in s.
The first step of a contact expands x(t_on + s^2), x'(t_on + s^2) in s (order 24: dx/ds =
2 s x', dx'/ds = 2 s x'') with the same recurrences (q^1.5 by the power rule with q_0 > 0),
its size from the last six coefficients (the series interleaves sub-series, the even powers
of the free motion and s^(3 + m) of the force, so two consecutive coefficients can both be
small by accident).

DP5 steps (lean_dp5's step, PI control, events and peaks on its interpolant) are taken in
contact where the distance d to the nearest singularity of the continuation is below the DP
step h_dp, which is carried through the Taylor steps and reset at each onset to the first
accepted DP step of the previous contact:

    d = min((t - t_on) / 4, t_exit / 4, sqrt(v^2 + v_hat^2) / |x''|)

with t_on the onset (the branch point of p^n there; after an s-step seldom the nearest),
t_exit the predicted time to the exit (p + p' tau + p'' tau^2 / 2 = 0; the branch point of p^n
at p = 0, where the exit event is) and the last term the distance to the poles of
atan(v / v_hat) at v = +-i v_hat to first order. Near these the Taylor step shrinks
towards zero while the DP step does not. In free flight every step is a Taylor step.

Exit steps in sigma = sqrt(p) (``exit_steps=True``; :func:`tcoef_sigma`). At an exit p^1.5
has a branch point again, which the Taylor steps in t approach geometrically and the DP5 steps
finish. With sigma as the independent variable (p = sigma^2, dt/dsigma = 2 sigma / p') the
force is K sigma^3 (1 + (D / v0) p'), and the motion is analytic in sigma wherever p' != 0,
the exit (sigma = 0) included: once past the deepest point and below SIGMA_P of its depth, one
series in sigma reaches the exit, or two or three do. The exit is then where sigma = 0, with
no root to find. Its limit is the deepest point (p' = 0, where dt/dsigma is infinite).

Measured with ``bench_core.py --part taylor``: about 2x faster than the lean DP5 loop at
peak-force accuracy 2.5e-6 and 2.5x at 1.2e-7; the exit steps take 1.07-1.09 and 1.19-1.23
times less time at those accuracies, 1.03-1.32 on four neighbouring runs (benchmarks/README.md,
"Where the Taylor loop's steps go, and exit steps in sqrt(p)").
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from lean_dp5 import (
    EP_INITIAL,
    EP_PEAK,
    EP_T,
    EP_TEND,
    EP_TPEAK,
    EP_V0,
    EP_WALL,
    NEPCOL,
    Q_D,
    Q_EPS,
    Q_FRIC,
    Q_HA,
    Q_K,
    Q_LOAD,
    Q_MASS,
    Q_N,
    Q_PH,
    Q_VHAT,
    Q_VINIT,
    Q_VMIN,
    Q_W,
    S_ACC,
    S_EV,
    S_NFEV,
    S_REJ,
    THETAS,
    accel,
    dense,
    dp_step,
    event_g,
    fold_peak,
    force_slope,
    illinois_point,
    normal_force,
    penetration,
    wall,
)

# stats: lean_dp5's S_* (S_NFEV: DP5 evaluations only; S_ACC: all accepted steps) and
S_TAYLOR, S_TAYLOR_CONTACT, S_DP_CONTACT, S_TAYLOR_FLIGHT = range(4, 8)
# the exit steps in sigma = sqrt(p) (``exit_steps``): taken, and tried
S_SIGMA, S_SIGMA_TRIED = 8, 9
NSTAT = 10
NSAMP = 4  # event checks per Taylor step, at i / NSAMP of it
# DP in contact where (time since the onset) / DP_ONSET, (time to the exit) / DP_EXIT or the
# distance to the friction poles is below the DP step (measured best on paper-3.3)
DP_ONSET = 4.0
DP_EXIT = 4.0
# the generic switch (``switch="step"``): inside a run of DP steps, the series is built again
# to check the rule only every RETEST-th step (every step cost 5-8 % more, measured)
RETEST = 4
# an exit step in sigma that does not reach the exit is taken where it covers at least this
# fraction of sigma = sqrt(p); exit steps are tried below this fraction of the contact's
# deepest p (above it the deepest point limits them: tried at every step past it, three in
# four failed on paper-3.3)
SIGMA_MIN = 0.25
SIGMA_P = 0.2

jit = njit(cache=True, error_model="numpy")
# the coefficient recurrences only: sums reassociated, reciprocals allowed (8 % off a whole
# run against reassoc and contract alone; peak forces unchanged to 1e-9)
jit_fast = njit(cache=True, error_model="numpy", fastmath={"reassoc", "contract", "nsz", "arcp"})


@jit
def wallcoef(t, q, N, HW, INV):
    """Taylor coefficients HW[0..N] of the inner wall h(t + tau) = h_a cos(w (t + tau) + phase)."""
    w = q[Q_W]
    th = w * t + q[Q_PH]
    c = math.cos(th)
    s = math.sin(th)
    fk = q[Q_HA]
    for k in range(N + 1):
        r = k & 3
        cy = c if r == 0 else (-s if r == 1 else (-c if r == 2 else s))
        HW[k] = fk * cy
        fk *= w * INV[k + 1]


@jit_fast
def friction_coef(k, V, A, F, ivh, load, INV):
    """Coefficient k of -(F atan(U) + load), U = V / v_hat, from V[0..k]: W = 1 + U^2 by a
    Cauchy product and Z = atan U from Z' W = U', k Z_k W_0 = k U_k - sum_{j=1}^{k-1} j Z_j
    W_{k-j}. Work rows A[0] = U, A[1] = W, A[2] = j Z_j."""
    A[0, k] = V[k] * ivh
    if k == 0:
        u0 = A[0, 0]
        A[1, 0] = 1.0 + u0 * u0
        A[2, 0] = 0.0
        return -(F * math.atan(u0) + load)
    sw = 0.0
    for j in range((k + 1) // 2):
        sw += A[0, j] * A[0, k - j]
    sw *= 2.0
    if k % 2 == 0:
        sw += A[0, k // 2] * A[0, k // 2]
    A[1, k] = sw
    sz = 0.0
    for j in range(1, k):
        sz += A[2, j] * A[1, k - j]
    zj = (k * A[0, k] - sz) / A[1, 0]
    A[2, k] = zj
    return -F * zj * INV[k]


@jit_fast
def tcoef(t, x, v, mode, dv0, q, N, X, V, HW, PP, PW, NF, A, INV, hstop, tx, tv):
    """Taylor coefficients X[0..N], V[0..N] of x, x' at t in contact mode ``mode``; returns the
    order used.

    In contact also HW[0..N] the inner wall, PP[0..N] the penetration, PW[0..N-1] p^n and
    NF[0..N-1] the normal force (dv0 = D / v0). A holds the work rows U = v / v_hat,
    W = 1 + U^2, j Z_j (Z = atan U), j PW_j; INV[k] = 1 / k. With hstop > 0 (free flight) the
    recurrence stops at the first order >= 3 at which the last two terms of x and x' at
    tau = hstop are within tx, tv.
    """
    im = 1.0 / q[Q_MASS]
    F = q[Q_FRIC]
    ivh = 1.0 / q[Q_VHAT]
    if mode != 0:
        wallcoef(t, q, N, HW, INV)
    X[0] = x
    V[0] = v
    K = q[Q_K]
    n = q[Q_N]
    n1 = n + 1.0
    eps = q[Q_EPS]
    sg = -1.0 if mode < 0 else 1.0
    ip0 = 1.0
    hk = 1.0  # hstop^k
    prev_ok = False
    for k in range(N):
        X[k + 1] = V[k] * INV[k + 1]
        # friction: W = 1 + U^2 by a Cauchy product, Z from Z' W = U'
        acc = friction_coef(k, V, A, F, ivh, q[Q_LOAD], INV)
        if mode != 0:
            # contact: p^n from P' p = n p' P (p_0 > 0 away from the onset), then N
            if k == 0:
                PP[0] = sg * (X[0] - HW[0]) - (eps if mode > 0 else 0.0)
                PP[1] = sg * (X[1] - HW[1])
                A[3, 0] = 0.0
                A[3, 1] = PP[1]
                p0 = PP[0]
                ip0 = 1.0 / p0
                PW[0] = p0 * math.sqrt(p0) if n == 1.5 else p0**n
                A[4, 0] = 0.0
            else:
                PP[k + 1] = sg * (X[k + 1] - HW[k + 1])
                A[3, k + 1] = (k + 1) * PP[k + 1]
                s1 = 0.0
                s2 = 0.0
                for j in range(k):
                    s1 += PP[k - j] * PW[j]
                    s2 += PP[k - j] * A[4, j]
                pk = (n * k * s1 - n1 * s2) * INV[k] * ip0
                PW[k] = pk
                A[4, k] = k * pk
            sn = 0.0
            for j in range(k + 1):
                sn += PW[j] * A[3, k - j + 1]
            NF[k] = K * (PW[k] + dv0 * sn)
            acc -= mode * NF[k]
        V[k + 1] = acc * im * INV[k + 1]
        if hstop > 0.0:
            # two consecutive small terms, as the step-size rule uses
            hk *= hstop
            ok = abs(X[k + 1]) * hk <= tx and abs(V[k + 1]) * hk <= tv
            if ok and prev_ok and k + 1 >= 3:
                return k + 1
            prev_ok = ok
    return N


@jit_fast
def tcoef_s(t, x, v, mode, dv0, q, N, X, V, HW, PS, R, NS, A, INV):
    """Series in s = sqrt(tau) from a contact onset at t (p = 0 there, p' > 0, n = 1.5):
    X[0..N], V[0..N] of x(t + s^2), x'(t + s^2), PS[0..N] the penetration p = s^2 q(s)
    (q_m = PS[m + 2]), R = q^1.5 and NS[0..N-1] the normal force K s^3 R (1 + dv0 p'),
    p' = dp/dtau = sum_m (m + 2) q_m s^m / 2.

    dx/ds = 2 s x' and dx'/ds = 2 s x'': (k + 1) X[k+1] = 2 V[k-1], (k + 1) V[k+1] = 2 a[k-1].
    """
    im = 1.0 / q[Q_MASS]
    F = q[Q_FRIC]
    ivh = 1.0 / q[Q_VHAT]
    M = N // 2 + 1
    wallcoef(t, q, M, HW, INV)  # h(t + s^2) = sum_j HW[j] s^(2 j)
    K = q[Q_K]
    n = q[Q_N]
    n1 = n + 1.0
    sg = -1.0 if mode < 0 else 1.0
    X[0] = x
    V[0] = v
    X[1] = 0.0
    V[1] = 0.0
    PS[0] = 0.0
    PS[1] = 0.0
    iq0 = 1.0
    acc_prev = 0.0
    for k in range(N):
        if k >= 1:
            X[k + 1] = 2.0 * V[k - 1] * INV[k + 1]
            V[k + 1] = 2.0 * acc_prev * im * INV[k + 1]
            hk = HW[(k + 1) // 2] if (k + 1) % 2 == 0 else 0.0
            PS[k + 1] = sg * (X[k + 1] - hk)
        # friction: Z = atan(U), U = V / v_hat
        acc = friction_coef(k, V, A, F, ivh, q[Q_LOAD], INV)
        # contact: the force starts at s^3; R = q^n by the power rule, q_0 = p'(onset) > 0
        nk = 0.0
        if k >= 3:
            m = k - 3
            if m == 0:
                q0 = PS[2]
                iq0 = 1.0 / q0
                R[0] = q0 * math.sqrt(q0) if n == 1.5 else q0**n
                A[4, 0] = 0.0
            else:
                s1 = 0.0
                s2 = 0.0
                for j in range(m):
                    s1 += PS[m - j + 2] * R[j]
                    s2 += PS[m - j + 2] * A[4, j]
                rm = (n * m * s1 - n1 * s2) * INV[m] * iq0
                R[m] = rm
                A[4, m] = m * rm
            sn = 0.0
            for j in range(m + 1):
                sn += R[j] * (0.5 * (m - j + 2)) * PS[m - j + 2]
            nk = K * (R[m] + dv0 * sn)
        NS[k] = nk
        acc -= mode * nk
        acc_prev = acc


@jit_fast
def tcoef_sigma(t, x, v, mode, dv0, q, N, T, V, CS, SN, PD, QI, G, AC, NF, A, INV):
    """Series in delta = sigma - sigma0 of a contact's exit phase, sigma = sqrt(p) the
    independent variable (n = 1.5), from (t, x, v) with p > 0: T[0..N] the time since t and
    V[0..N] the speed; NF[0..N-1] the normal force. Returns sigma0 = sqrt(p(t)).

    With p = sigma^2, dt/dsigma = 2 sigma / p' (p' = s (x' - h'(t)), s the wall's sign) and
    dx'/dsigma = x'' dt/dsigma; x follows from p = sigma^2 and the wall. Where p' != 0 these
    are analytic in sigma, also at the exit (sigma = 0), where p^1.5 = sigma^3 has no branch
    point: one series can reach the exit, which in t is a branch point every Taylor step in
    t must approach geometrically. The wall's phase u = w (t + T) + phase by
    k C_k = -sum_{j=1}^k j u_j S_{k-j}, k S_k = sum_{j=1}^k j u_j C_{k-j} (C = cos u,
    S = sin u); 1/p' by the reciprocal's recurrence; the friction as in :func:`tcoef`.
    """
    im = 1.0 / q[Q_MASS]
    F = q[Q_FRIC]
    ivh = 1.0 / q[Q_VHAT]
    K = q[Q_K]
    w = q[Q_W]
    ha = q[Q_HA]
    sg = -1.0 if mode < 0 else 1.0
    em = q[Q_EPS] if mode > 0 else 0.0
    u0 = w * t + q[Q_PH]
    CS[0] = math.cos(u0)
    SN[0] = math.sin(u0)
    p0 = sg * (x - ha * CS[0]) - em
    s0 = math.sqrt(p0)
    P3 = (s0 * s0 * s0, 3.0 * s0 * s0, 3.0 * s0, 1.0)
    T[0] = 0.0
    V[0] = v
    for k in range(N):
        if k >= 1:
            sc = 0.0
            ss = 0.0
            for j in range(1, k + 1):
                ju = j * w * T[j]
                sc += ju * SN[k - j]
                ss += ju * CS[k - j]
            CS[k] = -sc * INV[k]
            SN[k] = ss * INV[k]
        PD[k] = sg * (V[k] + ha * w * SN[k])  # p' = s (x' - h'), h' = -h_a w sin u
        if k == 0:
            QI[0] = 1.0 / PD[0]
            G[0] = 2.0 * s0 * QI[0]
        else:
            sq = 0.0
            for j in range(1, k + 1):
                sq += PD[j] * QI[k - j]
            QI[k] = -sq * QI[0]
            G[k] = 2.0 * (s0 * QI[k] + QI[k - 1])  # dt/dsigma = 2 (sigma0 + delta) / p'
        acc = friction_coef(k, V, A, F, ivh, q[Q_LOAD], INV)  # (as tcoef)
        # N = K sigma^3 (1 + dv0 p'), sigma^3 = (sigma0 + delta)^3 = sum_j P3[j] delta^j
        sp = P3[0] * PD[k]
        for j in range(1, min(k, 3) + 1):
            sp += P3[j] * PD[k - j]
        nk = K * ((P3[k] if k <= 3 else 0.0) + dv0 * sp)
        NF[k] = nk
        AC[k] = (acc - mode * nk) * im
        sag = 0.0
        for j in range(k + 1):
            sag += AC[j] * G[k - j]
        V[k + 1] = sag * INV[k + 1]
        T[k + 1] = G[k] * INV[k + 1]
    return s0


@jit
def cstate(t, x, v, mode, v0, q):
    """x'' (as accel), dN/dt and N (as force_slope), and p, p', p'' with one wall evaluation
    (all zero but x'' in free flight)."""
    fr = -(q[Q_FRIC] * math.atan(v / q[Q_VHAT]) + q[Q_LOAD])
    if mode == 0:
        return fr / q[Q_MASS], 0.0, 0.0, 0.0, 0.0, 0.0
    h, hd, hdd = wall(t, q)
    if mode < 0:
        p, pd = h - x, hd - v
    else:
        p, pd = x - h - q[Q_EPS], v - hd
    nn, fk = normal_force(p, pd, v0, q)
    a = (fr - mode * nn) / q[Q_MASS]
    pdd = (hdd - a) if mode < 0 else (a - hdd)
    if p <= 0.0:
        return a, pd, 0.0, p, pd, pdd
    dv = q[Q_D] / v0
    return a, q[Q_N] * fk / p * pd * (1.0 + dv * pd) + fk * dv * pdd, nn, p, pd, pdd


@jit
def horner(C, deg, tau):
    """The polynomial C[0..deg] at tau."""
    s = C[deg]
    for k in range(deg - 1, -1, -1):
        s = s * tau + C[k]
    return s


@jit
def last_terms_step(X, V, k_first, nu, tx, tv, hmax):
    """Jorba & Zou's first rule: min(hmax, (tol / |c_k|)^(1/k)) over c = X, V (tolerances tx,
    tv) and k = k_first..nu (the last two terms: k_first = nu - 1)."""
    h = hmax
    for k in range(k_first, nu + 1):
        cx = abs(X[k])
        if cx > 0.0:
            h = min(h, (tx / cx) ** (1.0 / k))
        cx = abs(V[k])
        if cx > 0.0:
            h = min(h, (tv / cx) ** (1.0 / k))
    return h


@jit
def gval(G, N, tau, side, mode, eps):
    """Event function from the polynomial G[0..N] at tau: in free flight G = x - h (inner wall,
    side -1: G; outer wall, side +1: eps - G), in contact G = p; an event when it turns < 0."""
    d = horner(G, N, tau)
    if mode == 0 and side > 0:
        return eps - d
    return d


@jit
def integrate_taylor(
    t_end, x, v, q, rtol, atol_x, atol_v, hmax, EP, stats, order, order_s, generic, sigma
):
    """Integrate from t = 0 to t_end with Taylor steps of order ``order`` (s-steps of order
    ``order_s`` at onsets) and DP5 steps near singularities; returns (status, episodes).
    ``generic``: choose DP5 by the generic rule (:func:`run_taylor`) instead of the
    distance to the model's singularities.

    Status, ``EP`` and the first four ``stats`` as :func:`lean_dp5.integrate_lean`; stats[4..7]
    the Taylor steps, those in contact, the DP steps in contact, the Taylor steps in flight.
    """
    NM = max(order, order_s)
    for i in range(stats.shape[0]):
        stats[i] = 0.0
    X = np.zeros(NM + 2)
    V = np.zeros(NM + 2)
    A = np.zeros((5, NM + 2))
    HW = np.zeros(NM + 2)
    PP = np.zeros(NM + 2)
    PW = np.zeros(NM + 2)
    NF = np.zeros(NM + 2)
    G = np.zeros(NM + 2)
    SL = np.zeros(NM + 2)
    # the exit step's series (tcoef_sigma)
    ST = np.zeros(NM + 2)
    SV = np.zeros(NM + 2)
    SCS = np.zeros(NM + 2)
    SSN = np.zeros(NM + 2)
    SPD = np.zeros(NM + 2)
    SQI = np.zeros(NM + 2)
    SG = np.zeros(NM + 2)
    SAC = np.zeros(NM + 2)
    SNF = np.zeros(NM + 2)
    INV = np.zeros(NM + 3)
    for k in range(1, NM + 3):
        INV[k] = 1.0 / k
    eps = q[Q_EPS]
    vhat = q[Q_VHAT]
    hamp = abs(q[Q_HA])
    s_steps = q[Q_N] == 1.5  # the onset series is written for p^1.5 = s^3 q^1.5
    t = 0.0
    nep = 0
    # contact at t = 0: an overlap starts in contact with v0 = inf (or the given vinit)
    mode = 0
    v0 = 1.0
    t_on = -math.inf
    h0, hd0, _ = wall(t, q)
    u = x - h0
    ud = v - hd0
    if u < 0.0 or (u == 0.0 and ud < 0.0):
        mode = -1
    elif u > q[Q_EPS] or (u == q[Q_EPS] and ud > 0.0):
        mode = 1
    if mode != 0:
        p, pd = penetration(t, x, v, mode, q)
        if p > 0.0:
            v0 = q[Q_VINIT] if q[Q_VINIT] > 0.0 else math.inf
        else:
            v0 = max(pd, q[Q_VMIN])
            t_on = 0.0
        nn, _ = normal_force(p, pd, v0, q)
        EP[0, EP_T] = 0.0
        EP[0, EP_WALL] = mode
        EP[0, EP_V0] = v0
        EP[0, EP_PEAK] = nn
        EP[0, EP_TPEAK] = 0.0
        EP[0, EP_INITIAL] = 1.0 if p > 0.0 else 0.0
        nep = 1
    a, slope0, _, pc, pdc, pddc = cstate(t, x, v, mode, v0, q)
    stats[S_NFEV] += 1
    h = min(1e-6, hmax, t_end)  # the DP step
    h_on = h  # the DP step at the next onset: the first accepted one of the last contact
    first_after_onset = False
    lerr_old = math.log(1e-4)
    pc1 = pdc1 = pddc1 = 0.0
    dp_run = 0  # DP steps in a row in this contact (generic rule)
    pmax = 0.0  # the deepest p of this contact so far
    nu = order
    while t < t_end:
        # ---- the exit step in sigma = sqrt(p) (tcoef_sigma): tried in contact after the
        # deepest point (p' < 0) below SIGMA_P of its depth; taken where its series reaches
        # the exit or covers SIGMA_MIN of sigma, with no peak of N and no clamped force inside
        if mode == 0:
            pmax = 0.0
        elif pc > pmax:
            pmax = pc
        if sigma and s_steps and mode != 0 and t > t_on and pdc < 0.0 and 0.0 < pc < SIGMA_P * pmax:
            stats[S_SIGMA_TRIED] += 1
            s0 = tcoef_sigma(
                t,
                x,
                v,
                mode,
                q[Q_D] / v0,
                q,
                order,
                ST,
                SV,
                SCS,
                SSN,
                SPD,
                SQI,
                SG,
                SAC,
                SNF,
                A,
                INV,
            )
            tx = atol_x + rtol * abs(x)
            tv = atol_v + rtol * abs(v)
            tt = tx / abs(pdc)  # the time error that makes a depth error of tx
            rho = last_terms_step(ST, SV, order - 1, order, tt, tv, math.inf)
            reach = rho >= s0
            if reach or rho >= SIGMA_MIN * s0:
                dl = -s0 if reach else -rho
                tau1 = horner(ST, order, dl)
                if 0.0 < tau1 <= hmax and t + tau1 < t_end:
                    t1 = t + tau1
                    v1 = horner(SV, order, dl)
                    hs, _, _ = wall(t1, q)
                    sg = -1.0 if mode < 0 else 1.0
                    em = eps if mode > 0 else 0.0
                    sig1 = s0 + dl
                    x1 = hs + sg * (em if reach else sig1 * sig1 + em)
                    n_end = horner(SNF, order - 1, dl)
                    a1, slope1, n1, pc1, pdc1, pddc1 = cstate(t1, x1, v1, mode, v0, q)
                    # (a peak of N, or a clamped force, inside: the steps in t take it)
                    if (reach or n_end >= 0.0) and not (slope0 > 0.0 and slope1 <= 0.0):
                        stats[S_SIGMA] += 1
                        stats[S_TAYLOR] += 1
                        stats[S_TAYLOR_CONTACT] += 1
                        stats[S_ACC] += 1
                        ie = nep - 1
                        fold_peak(EP, ie, n1, t1)
                        t = t1
                        x = x1
                        v = v1
                        a = a1
                        pc, pdc, pddc = pc1, pdc1, pddc1
                        slope0 = slope1
                        dp_run = 0
                        if reach:  # the exit, exactly at p = 0
                            stats[S_EV] += 1
                            EP[ie, EP_TEND] = t
                            mode = 0
                            a, slope0, _, pc, pdc, pddc = cstate(t, x, v, mode, v0, q)
                            stats[S_NFEV] += 1
                        continue
        # ---- DP where a singularity is closer than the DP step (module docstring)
        use_dp = False
        have_coef = False  # the Taylor coefficients of this step are computed already
        if generic:
            if mode != 0 and not (s_steps and t == t_on and pdc > 0.0):
                if dp_run > 0 and dp_run % RETEST != 0:
                    use_dp = True
                else:
                    # DP where the Taylor step is shorter than the DP step: that is where a
                    # singularity, whatever its kind, is close (Jorba & Zou's rule below)
                    tx = atol_x + rtol * abs(x)
                    tv = atol_v + rtol * abs(v)
                    nu = tcoef(
                        t,
                        x,
                        v,
                        mode,
                        q[Q_D] / v0,
                        q,
                        order,
                        X,
                        V,
                        HW,
                        PP,
                        PW,
                        NF,
                        A,
                        INV,
                        -1.0,
                        tx,
                        tv,
                    )
                    have_coef = True
                    ht0 = last_terms_step(X, V, nu - 1, nu, tx, tv, hmax)
                    use_dp = ht0 < h
            dp_run = dp_run + 1 if use_dp else 0
        elif mode != 0:
            d = math.sqrt(v * v + vhat * vhat) / max(abs(a), 1e-300)
            if (t - t_on) / DP_ONSET < d:
                d = (t - t_on) / DP_ONSET
            p, pd, pdd = pc, pdc, pddc
            # the time to the exit: the positive root of p + pd s + pdd s^2 / 2 = 0
            te = math.inf
            if pdd < 0.0:
                te = (pd + math.sqrt(pd * pd - 2.0 * pdd * p)) / (-pdd)
            elif pd < 0.0:
                disc = pd * pd - 2.0 * pdd * p
                if disc >= 0.0:
                    te = (-pd - math.sqrt(disc)) / pdd if pdd > 0.0 else p / (-pd)
            if te / DP_EXIT < d:
                d = te / DP_EXIT
            use_dp = d < h
        if s_steps and mode != 0 and t == t_on and pdc > 0.0:
            # ================= a Taylor step in s = sqrt(t - t_onset) from the onset ========
            dv0 = q[Q_D] / v0
            tcoef_s(t, x, v, mode, dv0, q, order_s, X, V, HW, PP, PW, NF, A, INV)
            tx = atol_x + rtol * abs(x)
            tv = atol_v + rtol * abs(v)
            sh = math.sqrt(min(hmax, t_end - t))
            # the series interleaves sub-series (even powers, s^(3 + m)): the last two
            # coefficients can both be small by accident; the last six bound the step
            sh = last_terms_step(X, V, order_s - 5, order_s, tx, tv, sh)
            # an exit within the step: p(s) < 0 at a sample, located by Illinois
            side_ev = 0
            s_ev = sh
            s_prev = 0.0
            for i in range(1, NSAMP + 1):
                si = sh * i / NSAMP
                if horner(PP, order_s, si) < 0.0:
                    lo = s_prev
                    hi = si
                    glo = max(horner(PP, order_s, lo), 0.0)
                    ghi = horner(PP, order_s, hi)
                    sd = 0
                    for _ in range(100):
                        if hi - lo <= 1e-14 * sh:
                            break
                        mid = illinois_point(lo, hi, glo, ghi, 1e-14 * sh)
                        gm = horner(PP, order_s, mid)
                        if gm < 0.0:
                            hi = mid
                            ghi = gm
                            if sd == -1:
                                glo *= 0.5
                            sd = -1
                        else:
                            lo = mid
                            glo = gm
                            if sd == 1:
                                ghi *= 0.5
                            sd = 1
                    side_ev = mode
                    s_ev = hi
                    break
                s_prev = si
            x1 = horner(X, order_s, s_ev)
            v1 = horner(V, order_s, s_ev)
            t1 = t + s_ev * s_ev
            if t1 > t_end:
                t1 = t_end
            a1, slope1, n1, pc1, pdc1, pddc1 = cstate(t1, x1, v1, mode, v0, q)
            stats[S_TAYLOR] += 1
            stats[S_TAYLOR_CONTACT] += 1
            ie = nep - 1
            fold_peak(EP, ie, n1, t1)
            if slope0 > 0.0 and slope1 <= 0.0:
                # dN/ds = sum k NS_k s^(k-1) has the sign of dN/dt for s > 0 (slope0 = 0 at
                # the onset itself: +1 stands in for it)
                for k in range(order_s - 1):
                    SL[k] = (k + 1) * NF[k + 1]
                lo = 0.0
                hi = s_ev
                glo = 1.0
                ghi = horner(SL, order_s - 2, hi)
                if ghi > 0.0:
                    ghi = -1e-300
                sd = 0
                for _ in range(100):
                    if hi - lo <= 1e-12 * s_ev:
                        break
                    sm = illinois_point(lo, hi, glo, ghi, 1e-12 * s_ev)
                    gm = horner(SL, order_s - 2, sm)
                    nm = horner(NF, order_s - 1, sm)
                    fold_peak(EP, ie, nm, t + sm * sm)
                    if gm == 0.0:
                        break
                    if gm > 0.0:
                        lo = sm
                        glo = gm
                        if sd == 1:
                            ghi *= 0.5
                        sd = 1
                    else:
                        hi = sm
                        ghi = gm
                        if sd == -1:
                            glo *= 0.5
                        sd = -1
            slope0 = slope1
            h_next = h
        elif use_dp:
            # ================= a DP5 step (lean_dp5's loop body) =================
            last = False
            if h >= (t_end - t) * (1.0 - 1e-12):
                h = t_end - t
                last = True
            if h < 1e-15 * max(1.0, t):
                return 1, nep
            x1, v1, a1, ex, ev, x2c, x3c, x4c, v2c, v3c, v4c = dp_step(
                t, x, v, h, v, a, mode, v0, q
            )
            stats[S_NFEV] += 6
            sx = ex / (atol_x + rtol * max(abs(x), abs(x1)))
            sv = ev / (atol_v + rtol * max(abs(v), abs(v1)))
            err = math.sqrt(0.5 * (sx * sx + sv * sv))
            if not err <= 1.0:  # also NaN
                if not math.isfinite(err):
                    if h < 1e-14:
                        return 3, nep
                    h *= 0.1
                else:
                    h *= max(0.2, 0.9 * math.exp(-0.2 * math.log(err)))
                stats[S_REJ] += 1
                continue
            if first_after_onset:
                h_on = h
                first_after_onset = False
            lerr = math.log(max(err, 1e-4))
            fac = min(5.0, max(0.2, 0.9 * math.exp(-0.17 * lerr + 0.04 * lerr_old)))
            lerr_old = lerr
            # contact events at the step end and 3 interior points of the interpolant
            th_ev = 2.0
            side_ev = 0
            th_prev = 0.0
            for th in THETAS:
                xt = x1 if th == 1.0 else dense(th, x, x1 - x, x2c, x3c, x4c)
                tt = t + th * h
                for side in (-1, 1):
                    if mode != 0 and side != mode:
                        continue
                    if event_g(tt, xt, side, mode, q) < 0.0:
                        lo = th_prev
                        hi = th
                        xlo = x if lo == 0.0 else dense(lo, x, x1 - x, x2c, x3c, x4c)
                        glo = max(event_g(t + lo * h, xlo, side, mode, q), 0.0)
                        ghi = event_g(tt, xt, side, mode, q)
                        sd = 0
                        for _ in range(100):
                            if hi - lo <= 1e-14:
                                break
                            mid = illinois_point(lo, hi, glo, ghi, 1e-14)
                            gm = event_g(
                                t + mid * h, dense(mid, x, x1 - x, x2c, x3c, x4c), side, mode, q
                            )
                            if gm < 0.0:
                                hi = mid
                                ghi = gm
                                if sd == -1:
                                    glo *= 0.5
                                sd = -1
                            else:
                                lo = mid
                                glo = gm
                                if sd == 1:
                                    ghi *= 0.5
                                sd = 1
                        if hi < th_ev:
                            th_ev = hi
                            side_ev = side
                if side_ev != 0:
                    break
                th_prev = th
            h_taken = h
            if side_ev != 0:
                # recompute the step from its start to the event
                h_taken = th_ev * h
                x1, v1, a1, ex, ev, x2c, x3c, x4c, v2c, v3c, v4c = dp_step(
                    t, x, v, h_taken, v, a, mode, v0, q
                )
                stats[S_NFEV] += 6
            t1 = t + h_taken if (side_ev != 0 or not last) else t_end
            # DP steps are taken in contact only: peaks where dN/dt goes from + to -
            stats[S_DP_CONTACT] += 1
            _, slope1, n1, pc1, pdc1, pddc1 = cstate(t1, x1, v1, mode, v0, q)
            ie = nep - 1
            fold_peak(EP, ie, n1, t1)
            if slope0 > 0.0 and slope1 <= 0.0:
                lo = 0.0
                hi = 1.0
                glo = slope0
                ghi = slope1
                sd = 0
                th = 1.0
                for _ in range(100):
                    if hi - lo <= 1e-12:
                        break
                    th = illinois_point(lo, hi, glo, ghi, 1e-12)
                    tt = t + th * h_taken
                    xt = dense(th, x, x1 - x, x2c, x3c, x4c)
                    vt = dense(th, v, v1 - v, v2c, v3c, v4c)
                    gm, nm = force_slope(tt, xt, vt, accel(tt, xt, vt, mode, v0, q), mode, v0, q)
                    fold_peak(EP, ie, nm, tt)
                    if gm == 0.0:
                        break
                    if gm > 0.0:
                        lo = th
                        glo = gm
                        if sd == 1:
                            ghi *= 0.5
                        sd = 1
                    else:
                        hi = th
                        ghi = gm
                        if sd == -1:
                            glo *= 0.5
                        sd = -1
            slope0 = slope1
            h_next = min(h * fac, hmax)
        else:
            # ================= a Taylor step =================
            dv0 = q[Q_D] / v0
            tx = atol_x + rtol * abs(x)
            tv = atol_v + rtol * abs(v)
            if have_coef:
                pass  # built by the generic rule above, from the same state
            elif mode != 0:
                nu = tcoef(t, x, v, mode, dv0, q, order, X, V, HW, PP, PW, NF, A, INV, -1.0, tx, tv)
            else:
                # adaptive order: enough terms for a step of hmax (or to t_end)
                hstop = min(hmax, t_end - t)
                nu = tcoef(
                    t, x, v, mode, dv0, q, order, X, V, HW, PP, PW, NF, A, INV, hstop, tx, tv
                )
            # Jorba & Zou's first rule on the last two terms of x and x'
            ht = last_terms_step(X, V, nu - 1, nu, tx, tv, hmax)
            last = False
            if ht >= (t_end - t) * (1.0 - 1e-12):
                ht = t_end - t
                last = True
            # the event polynomial; in flight none where |x(tau) - x| <= sum |X_k| h^k keeps
            # the carrier off both walls whatever their phase (|h| <= |h_a|)
            NG = nu
            nsmp = NSAMP
            if mode == 0:
                bnd = 0.0
                hk = 1.0
                for k in range(1, nu + 1):
                    hk *= ht
                    bnd += abs(X[k]) * hk
                if x - bnd > hamp and x + bnd < eps - hamp:
                    nsmp = 0
                else:
                    # the gap to the inner wall, the wall to the full order
                    wallcoef(t, q, order, HW, INV)
                    NG = order
                    for k in range(nu + 1):
                        G[k] = X[k] - HW[k]
                    for k in range(nu + 1, order + 1):
                        G[k] = -HW[k]
            else:
                for k in range(nu + 1):
                    G[k] = PP[k]
            th_ev = 2.0
            side_ev = 0
            th_prev = 0.0
            for i in range(1, nsmp + 1):
                th = i / NSAMP
                dth = horner(G, NG, th * ht)
                for side in (-1, 1):
                    if mode != 0 and side != mode:
                        continue
                    gh = (eps - dth) if (mode == 0 and side > 0) else dth
                    if gh < 0.0:
                        lo = th_prev
                        hi = th
                        glo = max(gval(G, NG, lo * ht, side, mode, eps), 0.0)
                        ghi = gh
                        sd = 0
                        for _ in range(100):
                            if hi - lo <= 1e-14:
                                break
                            mid = illinois_point(lo, hi, glo, ghi, 1e-14)
                            gm = gval(G, NG, mid * ht, side, mode, eps)
                            if gm < 0.0:
                                hi = mid
                                ghi = gm
                                if sd == -1:
                                    glo *= 0.5
                                sd = -1
                            else:
                                lo = mid
                                glo = gm
                                if sd == 1:
                                    ghi *= 0.5
                                sd = 1
                        if hi < th_ev:
                            th_ev = hi
                            side_ev = side
                if side_ev != 0:
                    break
                th_prev = i / NSAMP
            h_taken = ht
            if side_ev != 0:
                h_taken = th_ev * ht
            x1 = horner(X, nu, h_taken)
            v1 = horner(V, nu, h_taken)
            t1 = t + h_taken if (side_ev != 0 or not last) else t_end
            a1, slope1, n1, pc1, pdc1, pddc1 = cstate(t1, x1, v1, mode, v0, q)
            stats[S_TAYLOR] += 1
            if mode != 0:
                stats[S_TAYLOR_CONTACT] += 1
                ie = nep - 1
                fold_peak(EP, ie, n1, t1)
                if slope0 > 0.0 and slope1 <= 0.0:
                    # a peak: Illinois on the polynomial dN/dtau, SL[0..nu-2]
                    for k in range(nu - 1):
                        SL[k] = (k + 1) * NF[k + 1]
                    lo = 0.0
                    hi = h_taken
                    glo = slope0
                    ghi = slope1
                    sd = 0
                    for _ in range(100):
                        if hi - lo <= 1e-12 * h_taken:
                            break
                        tau = illinois_point(lo, hi, glo, ghi, 1e-12 * h_taken)
                        gm = horner(SL, nu - 2, tau)
                        nm = horner(NF, nu - 1, tau)
                        fold_peak(EP, ie, nm, t + tau)
                        if gm == 0.0:
                            break
                        if gm > 0.0:
                            lo = tau
                            glo = gm
                            if sd == 1:
                                ghi *= 0.5
                            sd = 1
                        else:
                            hi = tau
                            ghi = gm
                            if sd == -1:
                                glo *= 0.5
                            sd = -1
                slope0 = slope1
            else:
                stats[S_TAYLOR_FLIGHT] += 1
            h_next = h  # the DP step stays as it was
        if not (math.isfinite(x1) and math.isfinite(v1)):
            return 3, nep
        stats[S_ACC] += 1
        t = t1
        x = x1
        v = v1
        a = a1
        if mode != 0:
            pc, pdc, pddc = pc1, pdc1, pddc1
        h = h_next
        if side_ev != 0:
            stats[S_EV] += 1
            if mode == 0:  # onset: latch the approach speed
                p, pd = penetration(t, x, v, side_ev, q)
                mode = side_ev
                v0 = max(pd, q[Q_VMIN])
                t_on = t
                if nep >= EP.shape[0]:
                    return 2, nep
                EP[nep, EP_T] = t
                EP[nep, EP_WALL] = mode
                EP[nep, EP_V0] = v0
                EP[nep, EP_PEAK] = 0.0
                EP[nep, EP_TPEAK] = t
                EP[nep, EP_INITIAL] = 0.0
                nep += 1
                h = h_on
                first_after_onset = True
                dp_run = 0
            else:  # exit
                EP[nep - 1, EP_TEND] = t
                mode = 0
            a, slope0, _, pc, pdc, pddc = cstate(t, x, v, mode, v0, q)
            stats[S_NFEV] += 1
    if mode != 0:
        EP[nep - 1, EP_TEND] = t
    return 0, nep


def run_taylor(
    q: np.ndarray,
    t_end: float,
    x0: float,
    v0: float,
    rtol: float,
    atol_x: float,
    atol_v: float,
    hmax: float,
    capacity: int = 4096,
    order: int = 12,
    onset_order: int = 24,
    switch: str = "distance",
    exit_steps: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Run :func:`integrate_taylor` with Taylor steps of ``order`` and onset steps in
    s = sqrt(t - t_onset) of ``onset_order``; returns (episode rows, stats). Raises on
    failure.

    ``switch`` chooses where a DP5 step replaces a Taylor step in contact: ``"distance"``
    where the model's nearest singularity (onset, predicted exit, the friction's poles; module
    docstring) is closer than the DP step; ``"step"``, which knows nothing of the model,
    where the Taylor step that Jorba & Zou's rule gives is shorter than the DP step (checked
    again every ``RETEST``-th step of a run of DP steps). Measured on paper-3.3: within 10 %
    of each other (``benchmarks/README.md``). ``exit_steps``: reach each contact's exit by
    steps in sigma = sqrt(p) (module docstring; the Hertz exponent 1.5 only)."""
    if order < 3 or onset_order < 6:
        raise ValueError("order must be >= 3 and onset_order >= 6")
    if switch not in ("distance", "step"):
        raise ValueError(f"switch: {switch!r}; allowed 'distance' or 'step'")
    EP = np.full((capacity, NEPCOL), np.nan)
    stats = np.zeros(NSTAT)
    status, nep = integrate_taylor(
        t_end,
        x0,
        v0,
        q,
        rtol,
        atol_x,
        atol_v,
        hmax,
        EP,
        stats,
        order,
        onset_order,
        switch == "step",
        exit_steps,
    )
    if status != 0:
        raise RuntimeError(f"hybrid Taylor loop failed with status {status}")
    return EP[:nep], stats
