"""A lean, event-exact Dormand-Prince 5(4) loop for the x-only carrier: the yardstick.

This is what a careful user writes by hand in numba for one carrier on a vibrating track,
x only (paper section 3.3), with nothing the run does not need: no sampled series, no energy
quadratures, no window ranges. :mod:`benchmarks.bench_core` times braidsim against it at equal
peak-force accuracy; ``tests/integration/test_lean_peer.py`` checks that both integrate the same
thing.

Model (SI units; x radial, measured from the track's rest position)::

    m x'' = -s N - f(x') - L,        L = T1 cos(phi) + m r_c omega0^2,
    f(v)  = mu1 |m g - T2| (2/pi) atan(v / v_hat)                     (arctan friction law)
    N     = max(0, K p^n (1 + D p' / v0))                              (Hunt-Crossley family)

with the inner track wall at h(t) = h_a cos(w t + phase) and the outer one at h(t) + eps_g;
s = -1 in contact with the inner wall (p = h - x), +1 with the outer one (p = x - h - eps_g),
0 in free flight; v0 is the approach speed p' latched at contact onset (at least v_min). A
contact that exists at t = 0 with an overlap has no approach speed: v0 = inf (no damping term
until the next onset) unless a finite initial impact speed is given (``vinit > 0``).

Integrator: the Dormand-Prince 5(4) pair with its 4th-order continuous extension (Hairer,
Norsett & Wanner, Solving Ordinary Differential Equations I, 2nd ed., Springer 1993,
Sect. II.5-II.6, code DOPRI5; doi:10.1007/978-3-540-78862-1), FSAL, PI step-size control
(ibid. Sect. IV.2; exponents 0.17 and 0.04 as DOPRI5). After each accepted step the contact
event functions (the gaps to both walls in free flight, the penetration in contact) are
checked at the step end and at 3 interior points of the interpolant (theta = 1/4, 1/2, 3/4); the
first sign change is located by the Illinois method on the interpolant, the step is recomputed
from its start to the event time, the mode is switched and the approach speed latched. Peak
forces: where dN/dt changes sign from + to - across a step in contact, its root is found by the
Illinois method on the interpolant (state from the interpolant, acceleration from the equation
of motion) and N there is the peak candidate; N at every step end is folded in as well.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from braidsim import Scenario

# ---- parameter vector (see :func:`lean_params`) ---------------------------------------
(
    Q_MASS,  # m [kg]
    Q_LOAD,  # L = T1 cos(phi) + m r_c omega0^2 [N]
    Q_K,  # K [N/m^n]
    Q_N,  # n [-]
    Q_D,  # D [-]
    Q_EPS,  # eps_g [m]
    Q_HA,  # h_a [m]
    Q_W,  # w [rad/s]
    Q_PH,  # phase [rad]
    Q_FRIC,  # mu1 |m g - T2| 2/pi [N]
    Q_VHAT,  # v_hat [m/s]
    Q_VMIN,  # v_min [m/s]
    Q_VINIT,  # latched speed of a contact present at t = 0; <= 0: inf
    Q_SIZE,
) = range(14)

# episode rows: onset time, end time, wall (-1 inner, +1 outer), latched speed, peak force,
# time of the peak force, 1 when the contact existed at t = 0
EP_T, EP_TEND, EP_WALL, EP_V0, EP_PEAK, EP_TPEAK, EP_INITIAL = range(7)
NEPCOL = 7
# stats: rhs evaluations, accepted steps, rejected steps, events
S_NFEV, S_ACC, S_REJ, S_EV = range(4)

# Dormand-Prince 5(4) tableau, error weights and dense-output weights (DOPRI5)
C2, C3, C4, C5 = 0.2, 0.3, 0.8, 8.0 / 9.0
A21 = 0.2
A31, A32 = 3.0 / 40.0, 9.0 / 40.0
A41, A42, A43 = 44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0
A51, A52, A53, A54 = 19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0
A61, A62, A63 = 9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0
A64, A65 = 49.0 / 176.0, -5103.0 / 18656.0
B1, B3, B4, B5, B6 = 35.0 / 384.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0
E1, E3, E4 = 71.0 / 57600.0, -71.0 / 16695.0, 71.0 / 1920.0
E5, E6, E7 = -17253.0 / 339200.0, 22.0 / 525.0, -1.0 / 40.0
D1, D3 = -12715105075.0 / 11282082432.0, 87487479700.0 / 32700410799.0
D4, D5 = -10690763975.0 / 1880347072.0, 701980252875.0 / 199316789632.0
D6, D7 = -1453857185.0 / 822651844.0, 69997945.0 / 29380423.0
THETAS = (0.25, 0.5, 0.75, 1.0)  # where the event functions are checked in a step

jit = njit(cache=True, error_model="numpy")


@jit
def wall(t, q):
    """Inner wall position h, speed h' and acceleration h'' at time t."""
    arg = q[Q_W] * t + q[Q_PH]
    c = math.cos(arg)
    s = math.sin(arg)
    return q[Q_HA] * c, -q[Q_HA] * q[Q_W] * s, -q[Q_HA] * q[Q_W] * q[Q_W] * c


@jit
def penetration(t, x, v, mode, q):
    """Penetration p and its rate p' into the wall of ``mode`` (-1 inner, +1 outer)."""
    h, hd, _ = wall(t, q)
    if mode < 0:
        return h - x, hd - v
    return x - h - q[Q_EPS], v - hd


@jit
def normal_force(p, pd, v0, q):
    """N = max(0, K p^n (1 + D p'/v0)) and K p^n."""
    if p <= 0.0:
        return 0.0, 0.0
    fk = q[Q_K] * p * math.sqrt(p) if q[Q_N] == 1.5 else q[Q_K] * p ** q[Q_N]
    nn = fk * (1.0 + q[Q_D] * pd / v0)
    return max(nn, 0.0), fk


@jit
def fold_peak(EP, ie, nn, t):
    """Fold the normal force nn at time t into the peak of episode row ie."""
    if nn > EP[ie, EP_PEAK]:
        EP[ie, EP_PEAK] = nn
        EP[ie, EP_TPEAK] = t


@jit
def accel(t, x, v, mode, v0, q):
    """x'' from the equation of motion in contact mode ``mode``."""
    a = -(q[Q_FRIC] * math.atan(v / q[Q_VHAT]) + q[Q_LOAD])
    if mode != 0:
        p, pd = penetration(t, x, v, mode, q)
        nn, _ = normal_force(p, pd, v0, q)
        a -= mode * nn
    return a / q[Q_MASS]


@jit
def force_slope(t, x, v, a, mode, v0, q):
    """dN/dt = K n p^(n-1) p' (1 + D p'/v0) + K p^n D p''/v0 (p > 0), and N."""
    h, hd, hdd = wall(t, q)
    if mode < 0:
        p, pd, pdd = h - x, hd - v, hdd - a
    else:
        p, pd, pdd = x - h - q[Q_EPS], v - hd, a - hdd
    if p <= 0.0:
        return pd, 0.0
    nn, fk = normal_force(p, pd, v0, q)
    dv = q[Q_D] / v0
    return q[Q_N] * fk / p * pd * (1.0 + dv * pd) + fk * dv * pdd, nn


@jit
def event_g(t, x, side, mode, q):
    """Event function of wall ``side``: the gap in free flight, the penetration in contact
    (an event when it turns negative)."""
    h, _, _ = wall(t, q)
    u = x - h
    if mode == 0:
        return u if side < 0 else q[Q_EPS] - u
    return -u if side < 0 else u - q[Q_EPS]


@jit
def illinois_point(lo, hi, glo, ghi, tol):
    """The next point of the Illinois method on [lo, hi] with g(lo) = glo >= 0 > g(hi) = ghi
    (or, for a peak, slope glo > 0 >= ghi): the secant's zero, moved half the tolerance
    ``tol`` inside where it falls closer to an end (so that the bracket closes from that
    side); the midpoint where glo = 0 or the point is not inside."""
    if glo > 0.0:
        mid = lo + glo * (hi - lo) / (glo - ghi)
        if mid - lo < 0.5 * tol:
            mid = lo + 0.5 * tol
        elif hi - mid < 0.5 * tol:
            mid = hi - 0.5 * tol
    else:  # g(lo) = 0: the secant would stay at lo (a run of exact zeros): halve
        mid = 0.5 * (lo + hi)
    if not (lo < mid < hi):
        mid = 0.5 * (lo + hi)
    return mid


@jit
def dense(th, r0, r1, r2, r3, r4):
    """The continuous extension at fraction th of the step."""
    t1 = 1.0 - th
    return r0 + th * (r1 + t1 * (r2 + th * (r3 + t1 * r4)))


@jit
def dp_step(t, x, v, h, k1x, k1v, mode, v0, q):
    """One Dormand-Prince step: (x1, v1, k7v, error estimates of x and v, dense coefficients
    r2..r4 of x and v). The x-stages are the v-values of the stages (x' = v)."""
    k1 = k1v
    v2 = v + h * A21 * k1
    x2 = x + h * A21 * k1x
    k2 = accel(t + C2 * h, x2, v2, mode, v0, q)
    v3 = v + h * (A31 * k1 + A32 * k2)
    x3 = x + h * (A31 * k1x + A32 * v2)
    k3 = accel(t + C3 * h, x3, v3, mode, v0, q)
    v4 = v + h * (A41 * k1 + A42 * k2 + A43 * k3)
    x4 = x + h * (A41 * k1x + A42 * v2 + A43 * v3)
    k4 = accel(t + C4 * h, x4, v4, mode, v0, q)
    v5 = v + h * (A51 * k1 + A52 * k2 + A53 * k3 + A54 * k4)
    x5 = x + h * (A51 * k1x + A52 * v2 + A53 * v3 + A54 * v4)
    k5 = accel(t + C5 * h, x5, v5, mode, v0, q)
    v6 = v + h * (A61 * k1 + A62 * k2 + A63 * k3 + A64 * k4 + A65 * k5)
    x6 = x + h * (A61 * k1x + A62 * v2 + A63 * v3 + A64 * v4 + A65 * v5)
    k6 = accel(t + h, x6, v6, mode, v0, q)
    v1 = v + h * (B1 * k1 + B3 * k3 + B4 * k4 + B5 * k5 + B6 * k6)
    x1 = x + h * (B1 * k1x + B3 * v3 + B4 * v4 + B5 * v5 + B6 * v6)
    k7 = accel(t + h, x1, v1, mode, v0, q)
    ex = h * (E1 * k1x + E3 * v3 + E4 * v4 + E5 * v5 + E6 * v6 + E7 * v1)
    ev = h * (E1 * k1 + E3 * k3 + E4 * k4 + E5 * k5 + E6 * k6 + E7 * k7)
    dx = x1 - x
    dv = v1 - v
    x2c = h * k1x - dx
    v2c = h * k1 - dv
    x3c = dx - h * v1 - x2c
    v3c = dv - h * k7 - v2c
    x4c = h * (D1 * k1x + D3 * v3 + D4 * v4 + D5 * v5 + D6 * v6 + D7 * v1)
    v4c = h * (D1 * k1 + D3 * k3 + D4 * k4 + D5 * k5 + D6 * k6 + D7 * k7)
    return x1, v1, k7, ex, ev, x2c, x3c, x4c, v2c, v3c, v4c


@jit
def integrate_lean(t_end, x, v, q, rtol, atol_x, atol_v, hmax, EP, stats):
    """Integrate from t = 0 to t_end; returns (status, number of episodes).

    Status 0: done; 1: step size collapsed; 2: episode table full; 3: non-finite state.
    ``EP`` receives the contact episodes (columns EP_*), ``stats`` the counters S_*.
    """
    for i in range(stats.shape[0]):
        stats[i] = 0.0
    t = 0.0
    nep = 0
    # contact at t = 0: an overlap starts in contact with v0 = inf (or the given vinit)
    mode = 0
    v0 = 1.0
    h0, hd0, _ = wall(t, q)
    u = x - h0
    ud = v - hd0
    if u < 0.0 or (u == 0.0 and ud < 0.0):
        mode = -1
    elif u > q[Q_EPS] or (u == q[Q_EPS] and ud > 0.0):
        mode = 1
    if mode != 0:
        p, pd = penetration(t, x, v, mode, q)
        if p > 0.0:  # an overlap: no approach speed, released elastically unless vinit > 0
            v0 = q[Q_VINIT] if q[Q_VINIT] > 0.0 else math.inf
        else:  # on the wall and moving into it: the approach speed, floored
            v0 = max(pd, q[Q_VMIN])
        nn, _ = normal_force(p, pd, v0, q)
        EP[0, EP_T] = 0.0
        EP[0, EP_WALL] = mode
        EP[0, EP_V0] = v0
        EP[0, EP_PEAK] = nn
        EP[0, EP_TPEAK] = 0.0
        EP[0, EP_INITIAL] = 1.0 if p > 0.0 else 0.0
        nep = 1
    a = accel(t, x, v, mode, v0, q)
    stats[S_NFEV] += 1
    slope0 = 0.0
    if mode != 0:
        slope0, _ = force_slope(t, x, v, a, mode, v0, q)
    h = min(1e-6, hmax, t_end)
    lerr_old = math.log(1e-4)
    while t < t_end:
        last = False
        if h >= (t_end - t) * (1.0 - 1e-12):
            h = t_end - t
            last = True
        if h < 1e-15 * max(1.0, t):
            return 1, nep
        x1, v1, a1, ex, ev, x2c, x3c, x4c, v2c, v3c, v4c = dp_step(t, x, v, h, v, a, mode, v0, q)
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
        # PI control, one log and one exp per step
        lerr = math.log(max(err, 1e-4))
        fac = min(5.0, max(0.2, 0.9 * math.exp(-0.17 * lerr + 0.04 * lerr_old)))
        lerr_old = lerr
        # ---- contact events at the step end and 3 interior points of the interpolant
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
                    # Illinois on [th_prev, th] (g(th_prev) >= 0 > g(th))
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
        # ---- peaks: dN/dt from + to - across the step
        if mode != 0:
            slope1, n1 = force_slope(t1, x1, v1, a1, mode, v0, q)
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
        stats[S_ACC] += 1
        t = t1
        x = x1
        v = v1
        a = a1
        if side_ev != 0:
            stats[S_EV] += 1
            if mode == 0:  # onset: latch the approach speed
                p, pd = penetration(t, x, v, side_ev, q)
                mode = side_ev
                v0 = max(pd, q[Q_VMIN])
                if nep >= EP.shape[0]:
                    return 2, nep
                EP[nep, EP_T] = t
                EP[nep, EP_WALL] = mode
                EP[nep, EP_V0] = v0
                EP[nep, EP_PEAK] = 0.0
                EP[nep, EP_TPEAK] = t
                EP[nep, EP_INITIAL] = 0.0
                nep += 1
            else:  # exit
                EP[nep - 1, EP_TEND] = t
                mode = 0
            a = accel(t, x, v, mode, v0, q)
            stats[S_NFEV] += 1
            if mode != 0:
                slope0, _ = force_slope(t, x, v, a, mode, v0, q)
        h = min(h * fac, hmax)
    if mode != 0:
        EP[nep - 1, EP_TEND] = t
    return 0, nep


def lean_params(sc: Scenario, track_stiffness: float, track_damping_factor: float) -> np.ndarray:
    """The parameter vector of :func:`integrate_lean` from a braidsim Scenario (public keys
    only) and the track pair's K and D(c_r) as braidsim reports them in ``Result.stats``."""
    if sc["simulation.dof"] != "x" or sc["friction.law"] != "arctan":
        raise ValueError("the lean loop covers the x-only carrier with the arctan friction law")
    if sc["track.harmonics"] or sc["horn_gear.speed_harmonics"] or sc["horn_gear.speed_profile"]:
        raise ValueError("the lean loop covers one track harmonic and a constant horn-gear speed")
    m = sc["carrier.mass"]
    q = np.zeros(Q_SIZE)
    q[Q_MASS] = m
    w0 = sc["horn_gear.angular_velocity"]
    q[Q_LOAD] = (
        sc["yarn.tension_horizontal"] * math.cos(sc["yarn.angle"])
        + m * sc["carrier.turning_radius"] * w0 * w0
    )
    q[Q_K] = track_stiffness
    n = sc["contact.track.exponent"]
    q[Q_N] = 1.5 if n is None else float(n)
    q[Q_D] = track_damping_factor
    q[Q_EPS] = sc["track.clearance"]
    q[Q_HA] = sc["track.vibration_amplitude"]
    q[Q_W] = sc["track.vibration_frequency"]
    q[Q_PH] = sc["track.vibration_phase"]
    q[Q_FRIC] = (
        sc["friction.carrier_horn_gear"] * abs(m * sc["gravity"] - sc["yarn.tension_vertical"])
    ) * (2.0 / math.pi)
    q[Q_VHAT] = sc["friction.regularization_velocity"]
    q[Q_VMIN] = sc["contact.min_impact_velocity"]
    vinit = sc["contact.initial_impact_velocity"]
    q[Q_VINIT] = -1.0 if vinit is None else float(vinit)
    return q


def run_lean(
    q: np.ndarray,
    t_end: float,
    x0: float,
    v0: float,
    rtol: float,
    atol_x: float,
    atol_v: float,
    hmax: float,
    capacity: int = 4096,
) -> tuple[np.ndarray, np.ndarray]:
    """Run :func:`integrate_lean`; returns (episode rows, stats). Raises on failure."""
    EP = np.full((capacity, NEPCOL), np.nan)
    stats = np.zeros(4)
    status, nep = integrate_lean(t_end, x0, v0, q, rtol, atol_x, atol_v, hmax, EP, stats)
    if status != 0:
        raise RuntimeError(f"lean DP5 loop failed with status {status}")
    return EP[:nep], stats
