"""What a run writes, each recorder used only when the caller asks for it.

- the sampled series (``rows``: samples at given times plus, optionally, the exact onset,
  exit, peak and transfer states), one row per instant in the model's
  :func:`~braidsim.core.interfaces.series_columns`;
- window ranges (``RANGES[w, pair, quantity, min/max]``): exact extremes of the depth and
  forces over time windows (refined on the interpolant);
- the integral of x^2 dt over each window (``XSQ``), by a 4-point Gauss-Legendre rule on the
  interpolant of every step, for the RMS of the first coordinate;
- the impact table (``EP``, rows of :data:`braidsim.core.layout.EPISODE_DTYPE`).

A recorder the caller does not want is passed as ``None`` and its code is compiled out.
"""

from __future__ import annotations

import math

import numpy as np

from braidsim.core.generic import helper, inline_helper
from braidsim.core.interfaces import pair_series_rows, series_row
from braidsim.core.layout import END_ONGOING, KIND_PEAK, KIND_SAMPLE
from braidsim.core.solver.dense import dense_component, dense_deriv, dense_eval
from braidsim.core.solver.events import secant_point
from braidsim.core.solver.pairs import (
    I_DFC,
    I_DN,
    I_FC,
    I_FK,
    I_N,
    I_P,
    I_PD,
    pair_forces,
    pair_info,
)

# 4-point Gauss-Legendre rule on [0, 1], exact for polynomials of degree 7: the quadrature
# of x^2 over each step. Dormand-Prince's interpolant is a quartic, so x^2 has degree 8 and
# the rule misses only the square of its top term, O(h^10); Radau IIA's collocation cubic
# is integrated exactly.
GL_NODES = np.array(
    [
        0.5 - 0.4305681557970263,
        0.5 - 0.1699905217924281,
        0.5 + 0.1699905217924281,
        0.5 + 0.4305681557970263,
    ]
)
GL_WEIGHTS = np.array(
    [0.1739274225687269, 0.3260725774312731, 0.3260725774312731, 0.1739274225687269]
)


@helper
def write_row(model, rows, nrow, t, y, modes, v0s, n, kind, record_events):
    """Append one row of the series; returns the new row count."""
    if rows is None:
        return nrow
    if kind != KIND_SAMPLE and not record_events:
        return nrow
    if nrow >= rows.shape[0]:
        return nrow + 1  # never past the buffer; the driver reports the overflow as a bug
    series_row(model, t, y, modes, v0s, n, kind, rows[nrow])
    return nrow + 1


@inline_helper
def fold_values(t, pair, d, fk, fc, nn, WIN, RANGES):
    """Fold one pair's (depth, F_k, F_c, N) at time t into the [min, max] of each window
    containing t."""
    for w in range(WIN.shape[0]):
        if WIN[w, 0] <= t <= WIN[w, 1]:
            for q in range(4):
                v = d if q == 0 else (fk if q == 1 else (fc if q == 2 else nn))
                if v < RANGES[w, pair, q, 0]:
                    RANGES[w, pair, q, 0] = v
                if v > RANGES[w, pair, q, 1]:
                    RANGES[w, pair, q, 1] = v


@helper
def update_ranges(model, n_pairs, t, y, modes, v0s, WIN, RANGES):
    """Fold the contact quantities of every pair at time t into the window ranges (paper
    signs: negative on the inner wall)."""
    for pair in range(n_pairs):
        p, _, fk, fc, nn = pair_forces(model, pair, t, y, modes[pair], v0s[pair])
        s = float(modes[pair])
        fold_values(t, pair, s * p, s * fk, s * fc, s * nn, WIN, RANGES)


@inline_helper
def fold_info(t, pair, mode, info, WIN, RANGES):
    """:func:`update_ranges` for one pair from its summary at time t."""
    # (one fold for both cases: each inlined copy of the fold is typed and lowered again)
    if mode == 0:
        d = fk = fc = nn = 0.0
    else:
        s = float(mode)
        d = s * info[I_P]
        fk = s * info[I_FK]
        fc = s * info[I_FC]
        nn = s * info[I_N]
    fold_values(t, pair, d, fk, fc, nn, WIN, RANGES)


# the quantities whose extremes are tracked inside a contact: 0 the depth p, 1 F_c (max),
# 2 -F_c (its min), 3 the normal force N
@inline_helper
def extreme_value(kind, info):
    if kind == 0:
        return info[I_P]
    if kind == 1:
        return info[I_FC]
    if kind == 2:
        return -info[I_FC]
    return info[I_N]


@inline_helper
def extreme_slope(kind, info):
    """Time derivative of :func:`extreme_value`."""
    if kind == 0:
        return info[I_PD]
    if kind == 1:
        return info[I_DFC]
    if kind == 2:
        return -info[I_DFC]
    return info[I_DN]


@helper
def refine_extreme(model, kind, pair, mode, v0, t0, h, g0, g1, RC, n_dof2, n, ys, yd, info):
    """The maximum inside the step of quantity ``kind``, whose slope goes from g0 > 0 at the
    start to g1 <= 0 at the end: the root of the slope on the interpolant (state from
    :func:`dense_eval`, derivatives from :func:`dense_deriv`) by the Illinois method.
    Returns theta and leaves the pair's summary there in ``info`` and the state in ``ys``.
    """
    lo = 0.0
    hi = 1.0
    glo = g0
    ghi = g1
    side = 0
    for _ in range(100):
        if hi - lo <= 1e-12:
            break
        mid = secant_point(lo, hi, glo, ghi, 1e-12)
        # (the pair's summary reads the coordinates and speeds only: the quadratures are
        # evaluated once, at the root)
        dense_eval(mid, RC, ys, n_dof2)
        dense_deriv(mid, h, RC, yd, n_dof2)
        pair_info(model, pair, t0 + mid * h, ys, yd, mode, v0, info)
        gm = extreme_slope(kind, info)
        if gm == 0.0:
            lo = hi = mid  # (the root itself: the summary there is made again below)
            break
        if gm > 0.0:
            lo = mid
            glo = gm
            if side == 1:
                ghi *= 0.5
            side = 1
        else:
            hi = mid
            ghi = gm
            if side == -1:
                glo *= 0.5
            side = -1
    theta = 0.5 * (lo + hi)
    summary_at(model, pair, mode, v0, t0, h, theta, RC, n_dof2, n, ys, yd, info)
    return theta


@helper
def summary_at(model, pair, mode, v0, t0, h, theta, RC, n_dof2, n, ys, yd, info):
    """The state at fraction theta of the step into ``ys`` (the quadratures too), and the
    pair's summary there into ``info``."""
    dense_eval(theta, RC, ys, n)
    dense_deriv(theta, h, RC, yd, n_dof2)
    pair_info(model, pair, t0 + theta * h, ys, yd, mode, v0, info)


@helper
def series_extreme(A, m, sign, h):
    """The turn inside a Taylor step of a quantity whose series in time the model keeps,
    q(t0 + tau) = sum_{k<=m} A[k] tau^k (:func:`~braidsim.core.interfaces.pair_series_rows`):
    the root theta in (0, 1) of its slope sign * q'(theta h), which goes from > 0 at the
    start to <= 0 at the end, by Newton's method on the polynomial, safeguarded by
    bisection, to 1e-15 of the step. -1.0 where the polynomial's slope does not go so (the
    caller then refines on the state's interpolant).

    On a polynomial of order 12 this takes a few multiplications a point where the
    interpolant's slope takes a pair summary (the wall's motion, the contact law); the
    series is the one the step took, accurate to the step's tolerance, so the turn's
    time is as accurate as the step's state, and its value, where the slope is zero, to the
    square of that."""
    if m < 2:
        return -1.0
    s0 = sign * A[1]
    s1, _ = _series_slope(A, m, sign, h, 1.0)
    if not (s0 > 0.0 and s1 <= 0.0):
        return -1.0
    lo = 0.0
    hi = 1.0
    theta = s0 / (s0 - s1)
    for _ in range(60):
        sl, dsl = _series_slope(A, m, sign, h, theta)
        if sl == 0.0:
            return theta
        if sl > 0.0:
            lo = theta
        else:
            hi = theta
        nxt = theta - sl / dsl if dsl != 0.0 else -1.0
        if not (lo < nxt < hi):
            nxt = 0.5 * (lo + hi)
        if abs(nxt - theta) <= 1e-15:
            return nxt
        theta = nxt
    return theta


@inline_helper
def _series_slope(A, m, sign, h, theta):
    """(sign q'(x), d/dtheta of it) at x = theta h, q(x) = sum_{k<=m} A[k] x^k (Horner)."""
    x = theta * h
    p = m * A[m]
    dp = 0.0
    for k in range(m - 1, 0, -1):
        dp = dp * x + p
        p = p * x + k * A[k]
    return sign * p, sign * dp * h


@inline_helper
def episode_update(EP, ie, kind, val, t):
    """Fold a value of quantity ``kind`` (see :func:`extreme_value`) into open episode ie."""
    e = EP[ie]
    if kind == 0:
        if val > e.max_depth:
            e.max_depth = val
            e.t_max_depth = t
    elif kind == 1:
        if val > e.max_damping_force:
            e.max_damping_force = val
        if val < e.min_damping_force:
            e.min_damping_force = val
    elif kind == 2:
        if -val < e.min_damping_force:
            e.min_damping_force = -val
        if -val > e.max_damping_force:
            e.max_damping_force = -val
    else:
        if val > e.peak_force:
            e.peak_force = val
            e.t_peak_force = t


@inline_helper
def episode_fold(EP, ie, p, fc, nn, t):
    """:func:`episode_update` of the depth (kind 0), the damping force (1) and the normal
    force (3) at one instant, in that order (one inlined copy instead of three of the
    choice of kind)."""
    e = EP[ie]
    if p > e.max_depth:
        e.max_depth = p
        e.t_max_depth = t
    if fc > e.max_damping_force:
        e.max_damping_force = fc
    if fc < e.min_damping_force:
        e.min_damping_force = fc
    if nn > e.peak_force:
        e.peak_force = nn
        e.t_peak_force = t


@helper
def open_episode(EP, nep, t, pair, wall, vel, v0, initial, energy):
    """Start row ``nep`` of the impact table; ``energy``: the pair's dissipated-energy
    quadrature now (NaN when not integrated)."""
    e = EP[nep]
    e.t = t
    e.t_end = math.nan
    e.pair = pair
    e.wall = wall
    e.velocity = vel
    e.latched_velocity = v0
    e.rebound_velocity = math.nan
    e.max_depth = 0.0
    e.t_max_depth = t
    e.peak_force = 0.0
    e.t_peak_force = t
    e.min_damping_force = 0.0
    e.max_damping_force = 0.0
    e.dissipated_energy = energy
    e.end_reason = END_ONGOING
    e.initial = initial
    return nep + 1


@helper
def close_episode(EP, ie, t, rebound, energy, reason):
    """End episode ie at t; its dissipated energy is the quadrature's increase since onset."""
    e = EP[ie]
    e.t_end = t
    e.rebound_velocity = rebound
    e.dissipated_energy = energy - e.dissipated_energy
    e.end_reason = reason


@helper
def episode_start_values(model, EP, ie, t, y, pair, mode, v0):
    """Fold the depth and forces at the first instant of an episode into its extremes (a
    contact present at the start may have its largest force right there)."""
    p, _, _, fc, nn = pair_forces(model, pair, t, y, mode, v0)
    episode_fold(EP, ie, p, fc, nn, t)


@helper(always_inline=True)  # (called at every step: see core.generic.helper)
def scan_step(
    model,
    n_pairs,
    n_dof2,
    n,
    t0,
    h,
    RC,
    modes,
    v0s,
    open_ep,
    EP,
    WIN,
    RANGES,
    XSQ,
    rows,
    nrow,
    ST,
    isamp,
    ys,
    yd,
    INF0,
    INF1,
    IX,
    record_events,
    TAY,
    series_order,
):
    """Post-process an accepted (sub)step [t0, t0 + h]: samples, the windows' integrals of
    x^2, ranges, and the extremes inside contacts. ``INF0``, ``INF1``: the pair summaries at
    the two ends of the step; ``IX`` work space. ``series_order`` > 0: the step is a Taylor
    step of that order whose series the model left in ``TAY.W``, on which the extremes are
    found (:func:`series_extreme`; ``TAY`` None, a run without Taylor steps, compiles that
    out). Returns (rows written, next sample)."""
    t1 = t0 + h
    # sampled series
    if rows is not None:
        while isamp < ST.shape[0] and ST[isamp] <= t1:
            if ST[isamp] > t0:
                theta = (ST[isamp] - t0) / h if h > 0 else 1.0
                dense_eval(theta, RC, ys, n)
                nrow = write_row(
                    model, rows, nrow, ST[isamp], ys, modes, v0s, n, KIND_SAMPLE, record_events
                )
            isamp += 1
    # int x^2 dt over the part of the step inside each window (Gauss-Legendre on the
    # interpolant), for the RMS of x
    if XSQ is not None:
        for w in range(WIN.shape[0]):
            a = max(t0, WIN[w, 0])
            b = min(t1, WIN[w, 1])
            if b > a and h > 0.0:
                ta = (a - t0) / h
                dth = (b - a) / h
                acc = 0.0
                for k in range(4):
                    xk = dense_component(ta + GL_NODES[k] * dth, RC, 0)
                    acc += GL_WEIGHTS[k] * xk * xk
                XSQ[w] += (b - a) * acc
    # ranges at the end point and at window boundaries inside the step
    if WIN.shape[0] > 0:
        for pair in range(n_pairs):
            fold_info(t1, pair, modes[pair], INF1[pair], WIN, RANGES)
        for w in range(WIN.shape[0]):
            for e in range(2):
                tb = WIN[w, e]
                if t0 < tb < t1:
                    dense_eval((tb - t0) / h, RC, ys, n)
                    update_ranges(model, n_pairs, tb, ys, modes, v0s, WIN, RANGES)
    # Extremes inside the step for each pair in contact. The sign of each quantity's time
    # derivative at the two ends of the step tells whether a maximum (or a minimum of F_c)
    # lies inside; only then is it located, by a root of the slope on the interpolant.
    # Steps resolve a contact in tens of steps, so a quantity does not turn twice in a step.
    for pair in range(n_pairs):
        mode = modes[pair]
        if mode == 0:
            continue
        ie = open_ep[pair]
        v0 = v0s[pair]
        a0 = INF0[pair]
        a1 = INF1[pair]
        if ie >= 0:
            episode_fold(EP, ie, a1[I_P], a1[I_FC], a1[I_N], t1)
        for kind in range(4):
            g0 = extreme_slope(kind, a0)
            g1 = extreme_slope(kind, a1)
            if not (g0 > 0.0 and g1 <= 0.0):
                continue
            theta = -1.0
            if TAY is not None and series_order > 0:
                row = pair_series_rows(model, pair)[0 if kind == 0 else (2 if kind == 3 else 1)]
                if row >= 0:
                    # p to the series' order, the forces to one less
                    m = series_order if kind == 0 else series_order - 1
                    sign = -1.0 if kind == 2 else 1.0
                    theta = series_extreme(TAY.W[row], m, sign, h)
            if theta >= 0.0:
                summary_at(model, pair, mode, v0, t0, h, theta, RC, n_dof2, n, ys, yd, IX)
            else:
                theta = refine_extreme(
                    model, kind, pair, mode, v0, t0, h, g0, g1, RC, n_dof2, n, ys, yd, IX
                )
            tq = t0 + theta * h
            val = extreme_value(kind, IX)
            if ie >= 0:
                episode_update(EP, ie, kind, val, tq)
            fold_info(tq, pair, mode, IX, WIN, RANGES)
            if kind == 0 or kind == 3:
                nrow = write_row(model, rows, nrow, tq, ys, modes, v0s, n, KIND_PEAK, record_events)
    return nrow, isamp
