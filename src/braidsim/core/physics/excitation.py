"""Prescribed wall motions: the track's vibration and the horn gear's slot.

Track (the walls of the radial pair move together)::

    h(t) = sum_i a_i cos(w_i t + phi_i)            [m]

Horn gear (the walls of the tangential pair move with the slot)::

    omega(t) = omega_0 + sum_i b_i cos(v_i t + psi_i)      [rad/s], or a periodic
               piecewise-linear profile through (t_k, omega_k)
    s(t)     = r_c int_0^t omega dt                        [m]

The inner wall of the track pair is at x = h(t), the rear wall of the slot pair at y = s(t).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from braidsim.core.generic import helper, inline_helper
from braidsim.core.interfaces import wall_accel_bound, wall_motion, wall_motion_jvp, wall_series
from braidsim.core.jets import jet_cos_linear

# a knot of a horn-gear speed profile within this many units of rounding of t is at t
KNOT_ROUNDING = 64.0 * 2.220446049250313e-16


class TrackHarmonics(NamedTuple):
    """h(t) = sum a cos(w t + phi): rows (a [m], w [rad/s], phi [rad]) of ``table``."""

    table: np.ndarray  # (n, 3)


@helper
def _harmonic_sum(tab, t):
    """(h, h', h'') of sum a cos(w t + phi) over the rows (a, w, phi) of ``tab``."""
    h = 0.0
    hd = 0.0
    hdd = 0.0
    for i in range(tab.shape[0]):
        a = tab[i, 0]
        w = tab[i, 1]
        arg = w * t + tab[i, 2]
        c = math.cos(arg)
        h += a * c
        hd -= a * w * math.sin(arg)
        hdd -= a * w * w * c
    return h, hd, hdd


@wall_motion.register(TrackHarmonics)
def _track_motion(ex, t):
    tab = ex.table
    if tab.shape[0] == 1:
        # one harmonic (the usual track) in straight-line code: where the solver asks for
        # the wall's position and its acceleration at one instant in two calls, the compiler
        # then shares their cosine
        a = tab[0, 0]
        w = tab[0, 1]
        arg = w * t + tab[0, 2]
        c = math.cos(arg)
        return a * c, -a * w * math.sin(arg), -a * w * w * c
    # several (or none): a call, so that the ten places the solver inlines this hold no loop
    return _harmonic_sum(tab, t)


@wall_motion_jvp.register(TrackHarmonics)
def _track_motion_jvp(ex, dex, t):
    # d/d(a, w, phi) of a cos(w t + phi) and its time derivatives
    dh = 0.0
    dhd = 0.0
    dhdd = 0.0
    tab = ex.table
    dtab = dex.table
    for i in range(tab.shape[0]):
        a = tab[i, 0]
        w = tab[i, 1]
        da = dtab[i, 0]
        dw = dtab[i, 1]
        arg = w * t + tab[i, 2]
        darg = dw * t + dtab[i, 2]
        c = math.cos(arg)
        sn = math.sin(arg)
        dh += da * c - a * sn * darg
        dhd -= da * w * sn + a * dw * sn + a * w * c * darg
        dhdd -= da * w * w * c + 2.0 * a * w * dw * c - a * w * w * sn * darg
    return dh, dhd, dhdd


@wall_series.register(TrackHarmonics)
def _track_series(ex, t, order, H):
    # h(t + tau) = sum a cos(w (t + tau) + phi): analytic, the series holds for all tau
    tab = ex.table
    for i in range(tab.shape[0]):
        jet_cos_linear(tab[i, 0], tab[i, 1], tab[i, 2], t, order, H, i > 0)
    if tab.shape[0] == 0:
        for k in range(order + 1):
            H[k] = 0.0
    return math.inf


@wall_accel_bound.register(TrackHarmonics)
def _track_bound(ex):
    acc = 0.0
    tab = ex.table
    for i in range(tab.shape[0]):
        acc += abs(tab[i, 0]) * tab[i, 1] ** 2
    return acc


class HornGear(NamedTuple):
    """The horn gear's speed omega(t) and the slot travel s(t) = r_c int omega dt.

    A profile (``profile_times`` of at least two points) replaces ``omega0`` and the
    harmonics; it repeats with the period profile_times[-1] - profile_times[0].
    """

    turning_radius: float  # r_c [m]
    omega0: float  # [rad/s]
    # (n, 3): amplitude [rad/s], angular frequency [rad/s] (>= 0; 0: a constant term
    # a cos(phase), as the scenario keys allow), phase [rad]
    harmonics: np.ndarray
    profile_times: np.ndarray  # [s]
    profile_speeds: np.ndarray  # [rad/s]
    profile_integral: np.ndarray  # int of omega from profile_times[0] to each time [rad]


@inline_helper
def _profile_segment(tau, pt, period):
    """(k, j, dt) of the periodic profile with times ``pt``: the whole periods k in tau (time
    from the profile start), the piece [pt[j], pt[j + 1]] that holds the rest, and the time
    dt into that piece."""
    npf = pt.shape[0]
    k = math.floor(tau / period)
    tau -= k * period
    j = 0
    while j < npf - 2 and pt[j + 1] - pt[0] <= tau:
        j += 1
    return k, j, tau - (pt[j] - pt[0])


@helper
def _profile_integral(tau, hg, period):
    """(omega, int of the periodic piecewise-linear omega from the profile start over tau)."""
    pt = hg.profile_times
    pw = hg.profile_speeds
    pi_ = hg.profile_integral
    npf = pt.shape[0]
    k, j, dt = _profile_segment(tau, pt, period)
    w0 = pw[j]
    slope = (pw[j + 1] - w0) / (pt[j + 1] - pt[j])
    om = w0 + slope * dt
    return om, k * pi_[npf - 1] + pi_[j] + w0 * dt + 0.5 * slope * dt * dt


@helper
def _profile_piece(tau, hg, period):
    """Index j of the piece [pt[j], pt[j+1]] of the periodic profile that holds tau (time
    from the profile start, reduced to one period here)."""
    return _profile_segment(tau, hg.profile_times, period)[1]


@inline_helper
def horn_gear_state(hg, t):
    """(omega(t) [rad/s], s(t) = r_c int_0^t omega [m])."""
    rc = hg.turning_radius
    pt = hg.profile_times
    if pt.shape[0] >= 2:
        period = pt[pt.shape[0] - 1] - pt[0]
        om, integral = _profile_integral(t - pt[0], hg, period)
        _, integral0 = _profile_integral(-pt[0], hg, period)
        return om, rc * (integral - integral0)
    om = hg.omega0
    integral = hg.omega0 * t
    tab = hg.harmonics
    for i in range(tab.shape[0]):
        a = tab[i, 0]
        w = tab[i, 1]
        ph = tab[i, 2]
        om += a * math.cos(w * t + ph)
        if w > 0.0:
            integral += a / w * (math.sin(w * t + ph) - math.sin(ph))
        else:
            integral += a * math.cos(ph) * t
    return om, rc * integral


@helper
def horn_gear_accel(hg, t):
    """omega'(t) [rad/s^2]: analytic for the harmonics; on a profile the slope of its piece
    (at a knot, the piece that starts there, as :func:`horn_gear_state` takes it)."""
    pt = hg.profile_times
    if pt.shape[0] >= 2:
        j = _profile_piece(t - pt[0], hg, pt[pt.shape[0] - 1] - pt[0])
        pw = hg.profile_speeds
        return (pw[j + 1] - pw[j]) / (pt[j + 1] - pt[j])
    acc = 0.0
    tab = hg.harmonics
    for i in range(tab.shape[0]):
        w = tab[i, 1]
        acc -= tab[i, 0] * w * math.sin(w * t + tab[i, 2])
    return acc


@helper
def _profile_integral_jvp(tau, hg, dhg, period):
    """Tangent of :func:`_profile_integral` along the profile speeds' tangent (the profile
    times are fixed)."""
    pt = hg.profile_times
    dpw = dhg.profile_speeds
    dpi = dhg.profile_integral
    npf = pt.shape[0]
    k, j, dt = _profile_segment(tau, pt, period)
    dslope = (dpw[j + 1] - dpw[j]) / (pt[j + 1] - pt[j])
    return dpw[j] + dslope * dt, k * dpi[npf - 1] + dpi[j] + dpw[j] * dt + 0.5 * dslope * dt * dt


@helper
def horn_gear_state_jvp(hg, dhg, t):
    """The tangent (d omega, d s) of :func:`horn_gear_state` at fixed t."""
    rc = hg.turning_radius
    pt = hg.profile_times
    _, s = horn_gear_state(hg, t)
    integral = s / rc
    if pt.shape[0] >= 2:
        period = pt[pt.shape[0] - 1] - pt[0]
        dom, dint = _profile_integral_jvp(t - pt[0], hg, dhg, period)
        _, dint0 = _profile_integral_jvp(-pt[0], hg, dhg, period)
        return dom, dhg.turning_radius * integral + rc * (dint - dint0)
    dom = dhg.omega0
    dint = dhg.omega0 * t
    tab = hg.harmonics
    dtab = dhg.harmonics
    for i in range(tab.shape[0]):
        a = tab[i, 0]
        w = tab[i, 1]
        ph = tab[i, 2]
        da = dtab[i, 0]
        dw = dtab[i, 1]
        dph = dtab[i, 2]
        arg = w * t + ph
        darg = dw * t + dph
        dom += da * math.cos(arg) - a * math.sin(arg) * darg
        if w > 0.0:
            dint += (da / w - a * dw / (w * w)) * (math.sin(arg) - math.sin(ph)) + a / w * (
                math.cos(arg) * darg - math.cos(ph) * dph
            )
        else:
            dint += (da * math.cos(ph) - a * math.sin(ph) * dph) * t
    return dom, dhg.turning_radius * integral + rc * dint


@helper
def horn_gear_accel_jvp(hg, dhg, t):
    """The tangent of :func:`horn_gear_accel` at fixed t."""
    pt = hg.profile_times
    if pt.shape[0] >= 2:
        j = _profile_piece(t - pt[0], hg, pt[pt.shape[0] - 1] - pt[0])
        dpw = dhg.profile_speeds
        return (dpw[j + 1] - dpw[j]) / (pt[j + 1] - pt[j])
    dacc = 0.0
    tab = hg.harmonics
    dtab = dhg.harmonics
    for i in range(tab.shape[0]):
        a = tab[i, 0]
        w = tab[i, 1]
        arg = w * t + tab[i, 2]
        darg = dtab[i, 1] * t + dtab[i, 2]
        sn = math.sin(arg)
        dacc -= dtab[i, 0] * w * sn + a * dtab[i, 1] * sn + a * w * math.cos(arg) * darg
    return dacc


@wall_motion_jvp.register(HornGear)
def _slot_motion_jvp(ex, dex, t):
    om, _ = horn_gear_state(ex, t)
    dom, ds = horn_gear_state_jvp(ex, dex, t)
    rc = ex.turning_radius
    drc = dex.turning_radius
    return (
        ds,
        drc * om + rc * dom,
        drc * horn_gear_accel(ex, t) + rc * horn_gear_accel_jvp(ex, dex, t),
    )


@wall_motion.register(HornGear)
def _slot_motion(ex, t):
    om, s = horn_gear_state(ex, t)
    rc = ex.turning_radius
    return s, rc * om, rc * horn_gear_accel(ex, t)


@wall_series.register(HornGear)
def _slot_series(ex, t, order, H):
    # s(t + tau) = s(t) + r_c int_0^tau omega: s_{k+1} = r_c om_k / (k + 1), with om_k of
    # omega0 + sum a cos(w (t + tau) + psi) (a term with w = 0 is the constant a cos(psi));
    # on a profile omega is linear on the piece holding t (at a knot, the piece that starts
    # there): s is quadratic up to the piece's end, the horizon
    om0, s0 = horn_gear_state(ex, t)
    rc = ex.turning_radius
    H[0] = s0
    for k in range(1, order + 1):
        H[k] = 0.0
    pt = ex.profile_times
    if pt.shape[0] >= 2:
        period = pt[pt.shape[0] - 1] - pt[0]
        tp = t - pt[0]  # time in the profile, reduced to one period as _profile_piece does
        tp -= math.floor(tp / period) * period
        j = _profile_piece(t - pt[0], ex, period)
        horizon = pt[j + 1] - pt[0] - tp
        if horizon <= KNOT_ROUNDING * max(abs(t), period):
            # t is a knot that the reduction to one period put a few ulps before it (0.03 s
            # of a 0.02-s profile reduces to 0.009999999999999998): the series is that of
            # the next piece, else the steps to the knot would be below the rounding of t
            j = j + 1 if j + 1 < pt.shape[0] - 1 else 0
            horizon = pt[j + 1] - pt[j]
        if order >= 1:
            H[1] = rc * om0
        if order >= 2:
            pw = ex.profile_speeds
            H[2] = rc * ((pw[j + 1] - pw[j]) / (pt[j + 1] - pt[j])) / 2.0
        return max(horizon, 0.0)
    if order >= 1:
        H[1] = ex.omega0
        om = H[1:]
        tab = ex.harmonics
        for i in range(tab.shape[0]):
            jet_cos_linear(tab[i, 0], tab[i, 1], tab[i, 2], t, order - 1, om, True)
        for k in range(1, order + 1):
            H[k] = rc * H[k] / k
    return math.inf


@wall_accel_bound.register(HornGear)
def _slot_bound(ex):
    return math.inf
