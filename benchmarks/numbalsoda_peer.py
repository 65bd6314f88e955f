"""The x-only carrier of ``lean_dp5.py`` integrated by numbalsoda's DOP853 with its events.

numbalsoda (https://github.com/Nicholaswogan/numbalsoda) wraps Hairer's DOP853 (Fortran) for
numba: its ``solve_ivp`` takes the right-hand side and an event function as numba ``cfunc``
pointers, checks the event functions for a sign change at the end of every accepted step,
locates the first one by Brent's method on the 7th-order dense output (to 1e-8 s, a fixed
tolerance) and stops there (terminal events only). The equations are those of ``lean_dp5``
(same compiled functions). The driver below, compiled with numba, runs one contact mode per
call:

* events: the gaps to both walls in free flight; in contact the penetration (exit) and dN/dt
  (the force peak; disarmed after the first maximum of an episode, since the function is
  near zero right after it, and both directions of a sign change stop the integration);
* onset and exit: the event time from Brent is refined by one Newton step on the event
  function with a 2nd-order Taylor update of the state, and the carrier put exactly on the
  wall (a shift of ~1e-20 m), so that the next mode starts with its event function at zero;
  the approach speed is latched there (floored at v_min);
* peak force: N at the dN/dt event, and at every restart and at the end.

One absolute tolerance serves x and x' (the library takes a scalar).
"""

from __future__ import annotations

import math

import numpy as np
from numba import carray, cfunc, njit
from numbalsoda import lsoda_sig, solve_ivp

import lean_dp5 as L

D_MODE = L.Q_SIZE
D_V0 = L.Q_SIZE + 1
D_ARMED = L.Q_SIZE + 2
NDATA = L.Q_SIZE + 3


@cfunc(lsoda_sig)
def rhs(t, u, du, p):  # type: ignore[no-untyped-def]
    d = carray(p, (NDATA,))
    du[0] = u[1]
    du[1] = L.accel(t, u[0], u[1], int(d[D_MODE]), d[D_V0], d)


@cfunc(lsoda_sig)
def events(t, u, ev, p):  # type: ignore[no-untyped-def]
    d = carray(p, (NDATA,))
    mode = int(d[D_MODE])
    if mode == 0:
        ev[0] = L.event_g(t, u[0], -1, 0, d)
        ev[1] = L.event_g(t, u[0], 1, 0, d)
        ev[2] = 1.0
        return
    ev[0] = L.event_g(t, u[0], mode, mode, d)
    ev[1] = 1.0
    ev[2] = 1.0
    if d[D_ARMED] > 0.0:
        a = L.accel(t, u[0], u[1], mode, d[D_V0], d)
        s, _ = L.force_slope(t, u[0], u[1], a, mode, d[D_V0], d)
        ev[2] = s


RHS_PTR = rhs.address
EV_PTR = events.address


@njit
def _polish(t, x, v, side, mode, d):  # type: ignore[no-untyped-def]
    """One Newton step on the event function of wall ``side`` with a Taylor update of the
    state, then x on the wall exactly."""
    h, hd, _ = L.wall(t, d)
    g = L.event_g(t, x, side, mode, d)
    gd = v - hd
    if (mode == 0 and side > 0) or (mode != 0 and side < 0):
        gd = -gd
    a = L.accel(t, x, v, mode, d[D_V0], d)
    if gd != 0.0:
        dt = -g / gd
        x = x + v * dt + 0.5 * a * dt * dt
        v = v + a * dt
        t = t + dt
    h, _, _ = L.wall(t, d)
    x = h if side < 0 else h + d[L.Q_EPS]
    return t, x, v


@njit
def run_dop853(data, t_end, x0, vx0, rtol, atol, hmax, EP, stats):  # type: ignore[no-untyped-def]
    """Integrate from 0 to t_end; returns the number of episodes (EP rows as lean_dp5)."""
    t = 0.0
    y = np.array([x0, vx0])
    nep = 0
    stats[0] = 0.0
    stats[1] = 0.0
    d = data
    h0, _, _ = L.wall(0.0, d)
    mode = 0
    if x0 < h0:
        mode = -1
    elif x0 > h0 + d[L.Q_EPS]:
        mode = 1
    d[D_MODE] = mode
    d[D_ARMED] = 1.0
    if mode != 0:
        d[D_V0] = d[L.Q_VINIT] if d[L.Q_VINIT] > 0.0 else math.inf
        p, pd = L.penetration(0.0, x0, vx0, mode, d)
        nn, _ = L.normal_force(p, pd, d[D_V0], d)
        EP[0, L.EP_T] = 0.0
        EP[0, L.EP_WALL] = mode
        EP[0, L.EP_PEAK] = nn
        nep = 1
    teval = np.empty(2)
    tspan = np.empty(2)
    while t < t_end:
        tspan[0] = t
        tspan[1] = t_end
        teval[0] = t
        teval[1] = t_end
        res = solve_ivp(
            RHS_PTR,
            tspan,
            y,
            teval,
            "DOP853",
            np.int32(3),
            EV_PTR,
            d.ctypes.data,
            0.0,
            hmax,
            rtol,
            atol,
        )
        stats[0] += res.nfev
        stats[1] += 1
        if not res.success:
            return -1
        if not res.event_found:
            t = t_end
            y[0] = res.y[-1, 0]
            y[1] = res.y[-1, 1]
            break
        t = res.t_event
        x = res.y_event[0]
        v = res.y_event[1]
        j = res.ind_event
        if mode != 0 and j == 2:  # the force peak
            p, pd = L.penetration(t, x, v, mode, d)
            nn, _ = L.normal_force(p, pd, d[D_V0], d)
            if nn > EP[nep - 1, L.EP_PEAK]:
                EP[nep - 1, L.EP_PEAK] = nn
            d[D_ARMED] = 0.0
        elif mode != 0:  # exit
            t, x, v = _polish(t, x, v, mode, mode, d)
            EP[nep - 1, L.EP_TEND] = t
            mode = 0
            d[D_MODE] = 0.0
        else:  # onset
            side = -1 if j == 0 else 1
            t, x, v = _polish(t, x, v, side, 0, d)
            mode = side
            _, pd = L.penetration(t, x, v, mode, d)
            d[D_MODE] = mode
            d[D_V0] = max(pd, d[L.Q_VMIN])
            d[D_ARMED] = 1.0
            if nep >= EP.shape[0]:
                return -2
            EP[nep, L.EP_T] = t
            EP[nep, L.EP_WALL] = mode
            EP[nep, L.EP_PEAK] = 0.0
            nep += 1
        y[0] = x
        y[1] = v
    if mode != 0:
        p, pd = L.penetration(t, y[0], y[1], mode, d)
        nn, _ = L.normal_force(p, pd, d[D_V0], d)
        if nn > EP[nep - 1, L.EP_PEAK]:
            EP[nep - 1, L.EP_PEAK] = nn
        EP[nep - 1, L.EP_TEND] = t
    return nep


def run(
    q: np.ndarray, t_end: float, x0: float, v0: float, rtol: float, atol: float, hmax: float
) -> tuple[np.ndarray, np.ndarray]:
    """Episode rows and (rhs evaluations, solve_ivp calls); raises on failure."""
    data = np.zeros(NDATA)
    data[: L.Q_SIZE] = q
    EP = np.full((4096, L.NEPCOL), np.nan)
    stats = np.zeros(2)
    nep = run_dop853(data, t_end, x0, v0, rtol, atol, hmax, EP, stats)
    if nep < 0:
        raise RuntimeError(f"numbalsoda DOP853 failed ({nep})")
    return EP[:nep], stats
