"""The lean loop of ``lean_dp5.py`` with the Dormand-Prince 8(5,3) pair instead: what a
higher-order pair buys on the x-only carrier (an experiment for the design of the core).

Same equations (the compiled functions of :mod:`lean_dp5`), same event and peak logic, same
maximum step. The method is DOP853 (Hairer, Norsett & Wanner, Solving Ordinary Differential
Equations I, 2nd ed., Sect. II.10; doi:10.1007/978-3-540-78862-1) with the coefficients SciPy
ships (``scipy.integrate._ivp.dop853_coefficients``): 12 stages, the last one also the first
of the next step (FSAL), the error estimate that blends the 5th- and 3rd-order embedded
solutions, step control with exponent 1/8 and safety 0.9 (no PI term, DOP853's default). The
7th-order dense output costs 3 more evaluations, so it is computed only in the steps that need
it: contact events are detected on the cubic Hermite interpolant (free: the end values and
derivatives) at the step end and 3 interior points and, where one is seen, located by the
Illinois method on the 7th-order dense output; the step is then recomputed to the event. A
force peak (dN/dt from + to - across a step in contact) is located on the dense output as well.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.integrate._ivp import dop853_coefficients as _dop

import lean_dp5 as L

A = np.ascontiguousarray(_dop.A, dtype=np.float64)
C = np.ascontiguousarray(_dop.C, dtype=np.float64)
B = np.ascontiguousarray(_dop.B, dtype=np.float64)
E3 = np.ascontiguousarray(_dop.E3, dtype=np.float64)
E5 = np.ascontiguousarray(_dop.E5, dtype=np.float64)
D = np.ascontiguousarray(_dop.D, dtype=np.float64)
NS = 12  # stages of a step; K[NS] = f(t + h, y1) is the first stage of the next
NSX = 16  # with the 3 stages of the dense output
THETAS = (0.25, 0.5, 0.75, 1.0)
NEWTON = True  # refine each event by one Newton step on the recomputed step (see below)
ONSET_STEP = True  # first step of a contact ~1/12 of its elastic duration, as braidsim's

jit = njit(cache=True, error_model="numpy")


@jit
def stages(t, x, v, h, K, s0, s1, mode, v0, q):
    """Stages s0 .. s1-1 of the tableau; K[s] = (x', x'') of stage s."""
    for s in range(s0, s1):
        dx = 0.0
        dv = 0.0
        for j in range(s):
            dx += A[s, j] * K[j, 0]
            dv += A[s, j] * K[j, 1]
        xs = x + h * dx
        vs = v + h * dv
        K[s, 0] = vs
        K[s, 1] = L.accel(t + C[s] * h, xs, vs, mode, v0, q)


@jit
def step(t, x, v, h, K, mode, v0, q):
    """One DOP853 step with K[0] = f(t, y): returns (x1, v1); fills K[1..NS]."""
    stages(t, x, v, h, K, 1, NS, mode, v0, q)
    dx = 0.0
    dv = 0.0
    for j in range(NS):
        dx += B[j] * K[j, 0]
        dv += B[j] * K[j, 1]
    x1 = x + h * dx
    v1 = v + h * dv
    K[NS, 0] = v1
    K[NS, 1] = L.accel(t + h, x1, v1, mode, v0, q)
    return x1, v1


@jit
def error_norm(x, v, x1, v1, h, K, rtol, atol_x, atol_v):
    """DOP853's error: |h| err5^2 / sqrt((err5^2 + 0.01 err3^2) n), scaled components."""
    e5 = 0.0
    e3 = 0.0
    for i in range(2):
        sc = (
            atol_x + rtol * max(abs(x), abs(x1)) if i == 0 else atol_v + rtol * max(abs(v), abs(v1))
        )
        a5 = 0.0
        a3 = 0.0
        for j in range(NS + 1):
            a5 += E5[j] * K[j, i]
            a3 += E3[j] * K[j, i]
        e5 += (a5 / sc) ** 2
        e3 += (a3 / sc) ** 2
    if e5 == 0.0 and e3 == 0.0:
        return 0.0
    return abs(h) * e5 / math.sqrt((e5 + 0.01 * e3) * 2.0)


@jit
def dense_coeffs(t, x, v, x1, v1, h, K, F, mode, v0, q):
    """The 7th-order continuous extension (3 more stages): F[0..6, component]."""
    stages(t, x, v, h, K, NS + 1, NSX, mode, v0, q)
    for i in range(2):
        y0 = x if i == 0 else v
        y1 = x1 if i == 0 else v1
        dy = y1 - y0
        F[0, i] = dy
        F[1, i] = h * K[0, i] - dy
        F[2, i] = 2.0 * dy - h * (K[NS, i] + K[0, i])
        for r in range(4):
            acc = 0.0
            for j in range(NSX):
                acc += D[r, j] * K[j, i]
            F[3 + r, i] = h * acc


@jit
def dense(th, y0, F, i):
    """Component i of the continuous extension at fraction th."""
    y = 0.0
    for k in range(7):
        y += F[6 - k, i]
        y *= th if k % 2 == 0 else 1.0 - th
    return y0 + y


@jit
def hermite(th, x, x1, v, v1, h):
    """Cubic Hermite interpolant of x from the end values and slopes (detection only)."""
    t1 = 1.0 - th
    return t1 * x + th * x1 + th * t1 * ((t1 - th) * (x1 - x) + h * (t1 * v - th * v1))


@jit
def integrate_dop853(t_end, x, v, q, rtol, atol_x, atol_v, hmax, EP, stats):
    """As :func:`lean_dp5.integrate_lean` with DOP853; returns (status, episodes)."""
    for i in range(stats.shape[0]):
        stats[i] = 0.0
    K = np.zeros((NSX, 2))
    F = np.zeros((7, 2))
    t = 0.0
    nep = 0
    mode = 0
    v0 = 1.0
    h0, hd0, _ = L.wall(t, q)
    u = x - h0
    ud = v - hd0
    if u < 0.0 or (u == 0.0 and ud < 0.0):
        mode = -1
    elif u > q[L.Q_EPS] or (u == q[L.Q_EPS] and ud > 0.0):
        mode = 1
    if mode != 0:
        p, pd = L.penetration(t, x, v, mode, q)
        v0 = (q[L.Q_VINIT] if q[L.Q_VINIT] > 0.0 else math.inf) if p > 0.0 else max(pd, q[L.Q_VMIN])
        nn, _ = L.normal_force(p, pd, v0, q)
        EP[0, L.EP_T] = 0.0
        EP[0, L.EP_WALL] = mode
        EP[0, L.EP_V0] = v0
        EP[0, L.EP_PEAK] = nn
        EP[0, L.EP_TPEAK] = 0.0
        EP[0, L.EP_INITIAL] = 1.0 if p > 0.0 else 0.0
        nep = 1
    K[0, 0] = v
    K[0, 1] = L.accel(t, x, v, mode, v0, q)
    stats[L.S_NFEV] += 1
    slope0 = 0.0
    if mode != 0:
        slope0, _ = L.force_slope(t, x, v, K[0, 1], mode, v0, q)
    h = min(1e-6, hmax, t_end)
    err_old = 1e-4
    rejected = False
    while t < t_end:
        last = False
        if h >= (t_end - t) * (1.0 - 1e-12):
            h = t_end - t
            last = True
        if h < 1e-15 * max(1.0, t):
            return 1, nep
        x1, v1 = step(t, x, v, h, K, mode, v0, q)
        stats[L.S_NFEV] += NS
        err = error_norm(x, v, x1, v1, h, K, rtol, atol_x, atol_v)
        if not err <= 1.0:
            if not math.isfinite(err):
                if h < 1e-14:
                    return 3, nep
                h *= 0.1
            else:
                h *= max(0.333, 0.9 * err ** (-0.125))
            stats[L.S_REJ] += 1
            rejected = True
            continue
        # PI control as DOP853 with beta = 0.04; no growth right after a rejection
        fac = 6.0 if err == 0.0 else 0.9 * err ** (-0.125 + 0.2 * 0.04) * err_old**0.04
        fac = min(1.0 if rejected else 6.0, max(0.333, fac))
        err_old = max(err, 1e-4)
        rejected = False
        have_dense = False
        # ---- events: detected on the Hermite cubic, located on the dense output
        th_ev = 2.0
        side_ev = 0
        seen = False
        for th in THETAS:
            xt = x1 if th == 1.0 else hermite(th, x, x1, v, v1, h)
            for side in (-1, 1):
                if (mode == 0 or side == mode) and L.event_g(t + th * h, xt, side, mode, q) < 0.0:
                    seen = True
        if seen:
            dense_coeffs(t, x, v, x1, v1, h, K, F, mode, v0, q)
            stats[L.S_NFEV] += NSX - NS - 1
            have_dense = True
            th_prev = 0.0
            for th in THETAS:
                xt = x1 if th == 1.0 else dense(th, x, F, 0)
                tt = t + th * h
                for side in (-1, 1):
                    if mode != 0 and side != mode:
                        continue
                    if L.event_g(tt, xt, side, mode, q) < 0.0:
                        lo = th_prev
                        hi = th
                        xlo = x if lo == 0.0 else dense(lo, x, F, 0)
                        glo = max(L.event_g(t + lo * h, xlo, side, mode, q), 0.0)
                        ghi = L.event_g(tt, xt, side, mode, q)
                        sd = 0
                        for _ in range(100):
                            if hi - lo <= 1e-14:
                                break
                            mid = L.illinois_point(lo, hi, glo, ghi, 1e-14)
                            gm = L.event_g(t + mid * h, dense(mid, x, F, 0), side, mode, q)
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
            h_taken = th_ev * h
            x1, v1 = step(t, x, v, h_taken, K, mode, v0, q)
            stats[L.S_NFEV] += NS
            have_dense = False
            if NEWTON:
                # the root was found on the dense output of a step that may cross the kink of
                # the contact force: one Newton step on the exact end value of the event
                # function, and the step recomputed again
                g = L.event_g(t + h_taken, x1, side_ev, mode, q)
                _, hd1, _ = L.wall(t + h_taken, q)
                gd = v1 - hd1
                if (mode == 0 and side_ev > 0) or (mode != 0 and side_ev < 0):
                    gd = -gd
                if g != 0.0 and gd < 0.0:
                    h_taken -= g / gd
                    x1, v1 = step(t, x, v, h_taken, K, mode, v0, q)
                    stats[L.S_NFEV] += NS
        t1 = t + h_taken if (side_ev != 0 or not last) else t_end
        a1 = K[NS, 1]
        # ---- peaks
        if mode != 0:
            slope1, n1 = L.force_slope(t1, x1, v1, a1, mode, v0, q)
            ie = nep - 1
            L.fold_peak(EP, ie, n1, t1)
            if slope0 > 0.0 and slope1 <= 0.0:
                if not have_dense:
                    dense_coeffs(t, x, v, x1, v1, h_taken, K, F, mode, v0, q)
                    stats[L.S_NFEV] += NSX - NS - 1
                lo = 0.0
                hi = 1.0
                glo = slope0
                ghi = slope1
                sd = 0
                for _ in range(100):
                    if hi - lo <= 1e-12:
                        break
                    th = L.illinois_point(lo, hi, glo, ghi, 1e-12)
                    tt = t + th * h_taken
                    xt = dense(th, x, F, 0)
                    vt = dense(th, v, F, 1)
                    gm, nm = L.force_slope(
                        tt, xt, vt, L.accel(tt, xt, vt, mode, v0, q), mode, v0, q
                    )
                    L.fold_peak(EP, ie, nm, tt)
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
        stats[L.S_ACC] += 1
        t = t1
        x = x1
        v = v1
        K[0, 0] = K[NS, 0]
        K[0, 1] = K[NS, 1]
        if side_ev != 0:
            stats[L.S_EV] += 1
            if mode == 0:
                p, pd = L.penetration(t, x, v, side_ev, q)
                mode = side_ev
                v0 = max(pd, q[L.Q_VMIN])
                if nep >= EP.shape[0]:
                    return 2, nep
                EP[nep, L.EP_T] = t
                EP[nep, L.EP_WALL] = mode
                EP[nep, L.EP_V0] = v0
                EP[nep, L.EP_PEAK] = 0.0
                EP[nep, L.EP_TPEAK] = t
                EP[nep, L.EP_INITIAL] = 0.0
                nep += 1
                if ONSET_STEP:
                    n1 = q[L.Q_N] + 1.0
                    p_m = (n1 * q[L.Q_MASS] * v0 * v0 / (2.0 * q[L.Q_K])) ** (1.0 / n1)
                    fac = min(fac, 0.25 * p_m / v0 / h)
            else:
                EP[nep - 1, L.EP_TEND] = t
                mode = 0
            K[0, 1] = L.accel(t, x, v, mode, v0, q)
            stats[L.S_NFEV] += 1
            if mode != 0:
                slope0, _ = L.force_slope(t, x, v, K[0, 1], mode, v0, q)
        h = min(h * fac, hmax)
    if mode != 0:
        EP[nep - 1, L.EP_TEND] = t
    return 0, nep


def run(
    q: np.ndarray,
    t_end: float,
    x0: float,
    v0: float,
    rtol: float,
    atol_x: float,
    atol_v: float,
    hmax: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Episode rows (as :mod:`lean_dp5`) and stats; raises on failure."""
    EP = np.full((4096, L.NEPCOL), np.nan)
    stats = np.zeros(4)
    status, nep = integrate_dop853(t_end, x0, v0, q, rtol, atol_x, atol_v, hmax, EP, stats)
    if status != 0:
        raise RuntimeError(f"lean DOP853 loop failed with status {status}")
    return EP[:nep], stats
