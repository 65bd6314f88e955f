"""The braiding-machine carrier: radial x against the track, tangential y against the slot.

Equations of motion (x radial, y tangential)::

    m x'' = -s_t N_t - f_x(x') - T1 cos(phi) - m r_c omega(t)^2
    m y'' = -s_s N_s - f_y(y') + T1 sin(phi)                      (xy only)

with the track walls at x = h(t) (inner) and x = h(t) + eps_g (outer), the slot walls at
y = s(t) (rear) and y = s(t) + eps_h (front), s(t) = r_c int omega dt, s_t, s_s the side of
the wall in contact (-1 inner/rear, +1 outer/front, 0 free), N the normal force of each
pair's contact law (:mod:`braidsim.core.physics.contact_laws`), and the friction of the
paper's Eq. (14): f_x = mu1 |m g - T2| phi(x'), f_y = mu2 |N_t| phi(y'), phi the regularised
sign function (:mod:`braidsim.core.physics.friction`). ``docs/model.md`` explains how these
equations read the paper (moving walls, signs, the calibrated stiffness).

Energy quadratures (integrated with the motion when asked): the energy each contact law
dissipates int (N - F_k) p' dt, the friction work int f v dt, the work of the loads, and the
work the moving walls do on the carrier int -s N h' dt. With them the carrier's energy
m v^2/2 + K p^(n+1)/(n+1) balances to the integrator's tolerance.

A transfer to the next horn gear maps the carrier from the wall it leans on to the far wall:
x - h -> eps_g - (x - h), x' -> 2 h' - x' + v_tr (the track pair only). Its work, the jump
of m x'^2 / 2 plus the elastic energy of a contact it ends, is the last quadrature
(``transfer_work``), so the balance closes across transfers too.

The initial tangential speed ``initial.vy`` is relative to the slot: the state holds the
ground-frame y' = initial.vy + r_c omega(0) (:func:`braidsim.model.build_model`).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

from braidsim.core.generic import inline_helper
from braidsim.core.interfaces import (
    SERIES_ROWS,
    apply_transfer,
    apply_transfer_jvp,
    contact_force_onset_series,
    contact_force_rates,
    contact_force_series,
    contact_forces,
    contact_forces_jvp,
    contact_onset_power,
    contact_onset_step,
    contact_potential,
    derivatives,
    derivatives_jvp,
    describe_model,
    dissipation_index,
    free_accel_bound,
    friction_force,
    friction_force_jvp,
    friction_force_series,
    friction_series_reach,
    model_onset_series,
    model_onset_start,
    model_series,
    model_series_reach,
    model_series_start,
    model_size,
    pair_gap_accel,
    pair_gaps,
    pair_gaps_jvp,
    pair_law,
    pair_law_jvp,
    pair_law_rates,
    pair_onset_step,
    pair_series_rows,
    penetration,
    penetration_jvp,
    series_row,
    wall_accel_bound,
    wall_motion,
    wall_motion_jvp,
    wall_series,
)
from braidsim.core.jets import jet_in_sqrt, jet_mul, jet_sq
from braidsim.core.physics.excitation import (
    HornGear,
    horn_gear_accel,
    horn_gear_state,
    horn_gear_state_jvp,
)

CARRIER_COLUMNS = (
    "t",
    "x",
    "vx",
    "y",
    "vy",
    "track_depth",
    "track_stiffness_force",
    "track_damping_force",
    "track_contact_force",
    "slot_depth",
    "slot_stiffness_force",
    "slot_damping_force",
    "slot_contact_force",
    "friction_x",
    "friction_y",
    "track_dissipated",
    "slot_dissipated",
    "friction_work_x",
    "friction_work_y",
    "load_work_x",
    "track_work",
    "load_work_y",
    "slot_work",
    "track_position",
    "slot_position",
    "omega",
    "transfer_work",
    "kind",
)
"""The columns of a carrier's sampled series and event rows, in order: time [s], the
coordinates [m] and speeds [m/s], each pair's depth [m] and stiffness, damping and total
contact forces [N], the friction forces [N], the energy quadratures [J] (NaN where the run
did not integrate them), the walls' positions [m], the horn gear's speed omega [rad/s], and
the row's kind (``core.layout.KIND_NAMES``: sample, onset, exit, peak, transfer, start,
end)."""
# Energy quadratures of the xy carrier in state order (after x, vx, y, vy); the x-only
# carrier integrates the five of them that concern x (transfers included), in this order.
XY_QUADS = (
    "track_dissipated",
    "slot_dissipated",
    "friction_work_x",
    "friction_work_y",
    "load_work_x",
    "track_work",
    "load_work_y",
    "slot_work",
    "transfer_work",
)
X_QUADS = ("track_dissipated", "friction_work_x", "load_work_x", "track_work", "transfer_work")


class CarrierX(NamedTuple):
    """The carrier moving radially only (one coordinate x, the track pair).

    Physical parameters in SI units; ``track_law``, ``slot_law`` and ``friction`` are
    physics records, ``track`` the track's excitation record, ``horn_gear`` the
    :class:`HornGear`.

    ``mass_radius`` and ``normal_x`` are derived from ``mass`` (and r_c, g, T2) when the
    record is built (:func:`braidsim.model.build_model`): a record changed with
    ``_replace(mass=...)`` must have them changed too.
    """

    mass: float  # m [kg]
    load_x: float  # T1 cos(phi) [N]
    mass_radius: float  # m r_c [kg m] (centrifugal load m r_c omega^2), derived from m
    load_y: float  # T1 sin(phi) [N]
    track_clearance: float  # eps_g [m]
    slot_clearance: float  # eps_h [m]
    track_law: Any
    slot_law: Any
    friction: Any
    mu_x: float  # mu1, friction between carrier and horn gear [-]
    normal_x: float  # |m g - T2| [N], derived from m
    mu_y: float  # mu2, friction between guide pad and track [-]
    track: Any  # excitation of the track walls
    horn_gear: HornGear
    transfer_speed: float  # v_tr added to x' at a transfer [m/s]
    min_impact_velocity: float  # floor of the latched approach speed [m/s]
    initial_impact_velocity: float  # v0 of a contact present at the start (<= 0: inf) [m/s]


class CarrierXY(CarrierX):
    """The carrier moving radially and tangentially (x and y, the track and slot pairs)."""


describe_model(CarrierX, CARRIER_COLUMNS, X_QUADS)
describe_model(CarrierXY, CARRIER_COLUMNS, XY_QUADS)


@model_size.register(CarrierX)
def _size_x(model):
    return 1, 1, 5


@model_size.register(CarrierXY)
def _size_xy(model):
    return 2, 2, 9


@inline_helper
def _track_contact(model, t, y, mode, v0):
    """(p', F_k, N) of the track pair at t (zeros when free: the wall's motion is not
    evaluated then, a sine and a cosine saved in every evaluation of a free flight)."""
    if mode == 0:
        return 0.0, 0.0, 0.0
    h, hd, _ = wall_motion(model.track, t)
    u = y[0] - h
    p, pd = penetration(mode, u, model.track_clearance - u, y[1] - hd)
    fk, _, nn = contact_forces(model.track_law, p, pd, v0)
    return pd, fk, nn


@inline_helper
def _wall_speed(model, t):
    """The track wall's speed h'(t) (for the work the wall does on the carrier)."""
    _, hd, _ = wall_motion(model.track, t)
    return hd


@inline_helper
def _slot_contact(model, t, y, mode, v0, om, s):
    """(p', F_k, N) of the slot pair at t (the slot at s moving at r_c omega)."""
    if mode == 0:
        return 0.0, 0.0, 0.0
    u = y[2] - s
    p, pd = penetration(
        mode, u, model.slot_clearance - u, y[3] - model.horn_gear.turning_radius * om
    )
    fk, _, nn = contact_forces(model.slot_law, p, pd, v0)
    return pd, fk, nn


@derivatives.register(CarrierX)
def _derivs_x(model, t, y, modes, v0s, n_state, out):
    om, _ = horn_gear_state(model.horn_gear, t)
    mt = modes[0]
    pdt, fkt, nt = _track_contact(model, t, y, mt, v0s[0])
    fx = friction_force(model.friction, y[1], model.normal_x, model.mu_x)
    load_x = model.load_x + model.mass_radius * om * om
    out[0] = y[1]
    out[1] = (-mt * nt - fx - load_x) / model.mass
    if n_state > 2:
        # with p = s (x - wall), p' = s (x' - h'), the carrier's energy
        # E = m v^2 / 2 + K p^(n+1) / (n+1) changes at -(N - F_k) p' - f x' - load x' - s N h'
        out[2] = (nt - fkt) * pdt
    if n_state > 3:  # the friction work too
        out[3] = fx * y[1]
    if n_state > 4:  # all the quadratures
        out[4] = -load_x * y[1]
        out[5] = -mt * nt * _wall_speed(model, t) if mt != 0 else 0.0
        out[6] = 0.0  # transfers change the energy at an instant (apply_transfer)


@derivatives.register(CarrierXY)
def _derivs_xy(model, t, y, modes, v0s, n_state, out):
    om, s = horn_gear_state(model.horn_gear, t)
    mt = modes[0]
    ms = modes[1]
    pdt, fkt, nt = _track_contact(model, t, y, mt, v0s[0])
    fx = friction_force(model.friction, y[1], model.normal_x, model.mu_x)
    load_x = model.load_x + model.mass_radius * om * om
    pds, fks, ns = _slot_contact(model, t, y, ms, v0s[1], om, s)
    fy = friction_force(model.friction, y[3], abs(nt), model.mu_y)
    out[0] = y[1]
    out[1] = (-mt * nt - fx - load_x) / model.mass
    out[2] = y[3]
    out[3] = (-ms * ns - fy + model.load_y) / model.mass
    if n_state > 4:
        out[4] = (nt - fkt) * pdt
        out[5] = (ns - fks) * pds
    if n_state > 6:  # the friction works too
        out[6] = fx * y[1]
        out[7] = fy * y[3]
    if n_state > 8:  # all the quadratures
        out[8] = -load_x * y[1]
        out[9] = -mt * nt * _wall_speed(model, t) if mt != 0 else 0.0
        out[10] = model.load_y * y[3]
        out[11] = -ms * ns * model.horn_gear.turning_radius * om
        out[12] = 0.0  # transfers change the energy at an instant (apply_transfer)


def _for_each_carrier(generic_fn: Any) -> Any:
    """Decorator of ``make(n_coords)``, which returns an implementation of ``generic_fn``
    for the carrier with ``n_coords`` coordinates: registers ``make(1)`` for
    :class:`CarrierX` and ``make(2)`` for :class:`CarrierXY`.

    Written once for both carriers, each implementation holds its number of coordinates as
    a constant of its code: numba drops the other carrier's branches (``if n_coords == 2``,
    ``if n_coords == 1 or pair == 0``) before it types the function, so the x-only
    carrier's compiled code holds no slot terms, which numba would otherwise type and lower
    in every caller (about a tenth of the x-only carrier's cold compile)."""

    def deco(make: Any) -> Any:
        generic_fn.register(CarrierX)(make(1))
        generic_fn.register(CarrierXY)(make(2))
        return make

    return deco


# The functions of a pair: the x-only carrier has the track pair alone (``pair`` is 0).


@_for_each_carrier(pair_gaps)
def _gaps_for(n_coords):
    def _gaps(model, pair, t, y):
        if n_coords == 1 or pair == 0:
            h, hd, _ = wall_motion(model.track, t)
            u = y[0] - h
            return u, model.track_clearance - u, y[1] - hd
        s, sd, _ = wall_motion(model.horn_gear, t)
        u = y[2] - s
        return u, model.slot_clearance - u, y[3] - sd

    return _gaps


@_for_each_carrier(pair_gap_accel)
def _gap_accel_for(n_coords):
    def _gap_accel(model, pair, t, f):
        if n_coords == 1 or pair == 0:
            _, _, hdd = wall_motion(model.track, t)
            return f[1] - hdd
        return f[3] - model.horn_gear.turning_radius * horn_gear_accel(model.horn_gear, t)

    return _gap_accel


@_for_each_carrier(pair_law)
def _law_for(n_coords):
    def _law(model, pair, p, p_dot, v0):
        if n_coords == 1 or pair == 0:
            return contact_forces(model.track_law, p, p_dot, v0)
        return contact_forces(model.slot_law, p, p_dot, v0)

    return _law


@_for_each_carrier(pair_law_rates)
def _law_rates_for(n_coords):
    def _law_rates(model, pair, p, p_dot, p_ddot, v0, f_k, f_c):
        if n_coords == 1 or pair == 0:
            return contact_force_rates(model.track_law, p, p_dot, p_ddot, v0, f_k, f_c)
        return contact_force_rates(model.slot_law, p, p_dot, p_ddot, v0, f_k, f_c)

    return _law_rates


@_for_each_carrier(pair_onset_step)
def _onset_for(n_coords):
    def _onset(model, pair, v):
        if n_coords == 1 or pair == 0:
            return contact_onset_step(model.track_law, model.mass, v)
        return contact_onset_step(model.slot_law, model.mass, v)

    return _onset


@free_accel_bound.register(CarrierX)
@free_accel_bound.register(CarrierXY)
def _free_bound(model, pair, f0, f1):
    if pair != 0:
        return math.inf
    # |x''| at the ends (plus 10 %), the full swing of the friction force, and the wall's
    # acceleration bound
    return (
        1.1 * max(abs(f0[1]), abs(f1[1]))
        + 2.0 * model.mu_x * model.normal_x / model.mass
        + wall_accel_bound(model.track)
    )


@apply_transfer.register(CarrierX)
@apply_transfer.register(CarrierXY)
def _transfer(model, t, y):
    hh, hd, _ = wall_motion(model.track, t)
    xr = y[0] - hh
    eps = model.track_clearance
    # the carrier's energy m x'^2 / 2 + (elastic energy in either wall) before the jump
    p = max(0.0, -xr, xr - eps)
    before = 0.5 * model.mass * y[1] * y[1] + contact_potential(model.track_law, p)
    if xr < 0.0:
        xr = 0.0
    if xr > eps:
        xr = eps
    y[0] = hh + eps - xr
    y[1] = 2.0 * hd - y[1] + model.transfer_speed
    n_coords, _, n_quads = model_size(model)
    if y.shape[0] == 2 * n_coords + n_quads:
        # the work of the transfer: the jump of that energy (the carrier lands in the gap)
        y[y.shape[0] - 1] += 0.5 * model.mass * y[1] * y[1] - before
    return 1  # the contacts of the first pair (the track) start anew


@dissipation_index.register(CarrierX)
def _diss_x(model, pair):
    return 2


@dissipation_index.register(CarrierXY)
def _diss_xy(model, pair):
    return 4 + pair


@inline_helper
def _signed_forces(law, mode, g_in, g_out, rate, v0):
    if mode == 0:
        return 0.0, 0.0, 0.0, 0.0
    p, pd = penetration(mode, g_in, g_out, rate)
    fk, fc, nn = contact_forces(law, p, pd, v0)
    s = float(mode)
    return s * p, s * fk, s * fc, s * nn


@_for_each_carrier(series_row)
def _row_for(n_coords):
    def _row(model, t, y, modes, v0s, n_state, kind, row):
        row[0] = t
        row[1] = y[0]
        row[2] = y[1]
        h, hd, _ = wall_motion(model.track, t)
        om, s = horn_gear_state(model.horn_gear, t)
        u = y[0] - h
        d, fk, fc, nn = _signed_forces(
            model.track_law, modes[0], u, model.track_clearance - u, y[1] - hd, v0s[0]
        )
        row[5] = d
        row[6] = fk
        row[7] = fc
        row[8] = nn
        row[13] = friction_force(model.friction, y[1], model.normal_x, model.mu_x)
        if n_coords == 2:
            row[3] = y[2]
            row[4] = y[3]
            us = y[2] - s
            ds, fks, fcs, nns = _signed_forces(
                model.slot_law,
                modes[1],
                us,
                model.slot_clearance - us,
                y[3] - model.horn_gear.turning_radius * om,
                v0s[1],
            )
            row[9] = ds
            row[10] = fks
            row[11] = fcs
            row[12] = nns
            row[14] = friction_force(model.friction, y[3], abs(nn), model.mu_y)
            for i in range(8):
                row[15 + i] = y[4 + i] if 4 + i < n_state else math.nan
            row[26] = y[12] if 12 < n_state else math.nan
        else:
            for i in (3, 4, 9, 10, 11, 12, 14):
                row[i] = 0.0
            # state order: track_dissipated, friction_work_x, load_work_x, track_work,
            # transfer_work
            energy = n_state > 4  # all the quadratures
            row[15] = y[2] if n_state > 2 else math.nan
            row[16] = 0.0 if n_state > 2 else math.nan
            row[17] = y[3] if n_state > 3 else math.nan
            row[18] = 0.0 if n_state > 3 else math.nan
            row[19] = y[4] if energy else math.nan
            row[20] = y[5] if energy else math.nan
            row[21] = 0.0 if energy else math.nan
            row[22] = 0.0 if energy else math.nan
            row[26] = y[6] if energy else math.nan
        row[23] = h
        row[24] = s
        row[25] = om
        row[27] = kind

    return _row


# ---- Taylor series -------------------------------------------------------------------------
# The rows of the work array W (interfaces.TAYLOR_ROWS) the carrier's series use: the walls'
# series from model_series_start, and per pair its penetration, rate, force and damping
# force, then the work rows of its physics records (SERIES_ROWS each).
R_H, R_HD, R_SL, R_SD, R_OM, R_LOAD, R_NX = range(7)  # track wall, its speed, slot wall, ...
R_PT, R_PDT, R_NT, R_FCT = range(7, 11)  # track pair: p, p', N, F_c
R_PS, R_PDS, R_NS, R_FCS = range(11, 15)  # slot pair
R_FX, R_FY = 15, 16  # friction forces along x and y
R_LAW_T = 17  # work rows of the track's contact law, then the slot's, then the friction's
R_LAW_S = R_LAW_T + SERIES_ROWS
R_FR_X = R_LAW_S + SERIES_ROWS
R_FR_Y = R_FR_X + SERIES_ROWS


@inline_helper
def _constant_speed(hg):
    """Whether the horn gear turns at the constant omega0 (no harmonics, no profile)."""
    return hg.harmonics.shape[0] == 0 and hg.profile_times.shape[0] < 2


@_for_each_carrier(model_series_start)
def _series_start_for(n_coords):
    def _series_start(model, t, modes, order, W):
        # the walls to order + 1, for their speeds to order; a wall the equations do not read
        # in these modes is left out (the track's when the track pair is free, the slot's in
        # the x-only model at a constant horn-gear speed, whose omega series is omega0 alone)
        hz = math.inf
        if modes[0] != 0:
            hz = wall_series(model.track, t, order + 1, W[R_H])
            for j in range(order + 1):
                W[R_HD, j] = (j + 1) * W[R_H, j + 1]
        hg = model.horn_gear
        W[R_NX, 0] = model.normal_x  # (a constant: the friction reads coefficient 0 only)
        if n_coords == 1 and _constant_speed(hg):
            W[R_OM, 0] = hg.omega0
            W[R_LOAD, 0] = model.mass_radius * hg.omega0 * hg.omega0 + model.load_x
            for j in range(1, order + 1):
                W[R_OM, j] = 0.0
                W[R_LOAD, j] = 0.0
            return hz
        hz_slot = wall_series(hg, t, order + 1, W[R_SL])
        rc = hg.turning_radius
        irc = 1.0 / rc if rc != 0.0 else 0.0
        for j in range(order + 1):
            W[R_SD, j] = (j + 1) * W[R_SL, j + 1]
            # omega = s' / r_c (without a turning radius the centrifugal load m r_c omega^2 is 0)
            W[R_OM, j] = W[R_SD, j] * irc
        for j in range(order + 1):
            # T1 cos(phi) + m r_c omega^2
            W[R_LOAD, j] = model.mass_radius * jet_sq(W[R_OM], j) + (
                model.load_x if j == 0 else 0.0
            )
        return min(hz, hz_slot)

    return _series_start


@inline_helper
def _pair_series(law, k, mode, clearance, C, i, W, r_wall, r_p, v0, r_law):
    """Coefficient k of the pair's (p', F_c, N) along coordinate i against the wall series
    W[r_wall] (zeros when free); writes p up to k + 1 and p' to k in W[r_p], W[r_p + 1]."""
    if mode == 0:
        W[r_p + 1, k] = 0.0
        return 0.0, 0.0
    sg = -1.0 if mode < 0 else 1.0
    if k == 0:
        # p = h - x on the inner wall, x - h - eps on the outer one (interfaces.penetration)
        W[r_p, 0] = sg * (C[i, 0] - W[r_wall, 0]) - (clearance if mode > 0 else 0.0)
    W[r_p, k + 1] = sg * (C[i, k + 1] - W[r_wall, k + 1])
    W[r_p + 1, k] = (k + 1) * W[r_p, k + 1]
    _, fc, nn = contact_force_series(law, k, W[r_p], v0, W[r_law : r_law + SERIES_ROWS])
    return fc, nn


def _coefficient_for(n_coords, pair_coefficient, shift):
    """One coefficient of the series of the carrier with ``n_coords`` coordinates (see
    :func:`_for_each_carrier`): C[:, k + shift] from the coefficients k of the equations of
    motion of the module docstring, each times fac = shift / (k + shift). In time (shift 1,
    ``pair_coefficient`` :func:`_pair_series`) coefficient k + 1 of y is coefficient k of
    dy/dt over k + 1 (:func:`_series`); in s = sqrt(t - t_onset) from an onset (shift 2,
    :func:`_pair_onset`) dy/ds = 2 s dy/dt, so coefficient k + 2 is 2 (dy/dt)_k / (k + 2)
    (:func:`_onset_series`). The coordinates first (the pairs' penetrations read them), then
    the pairs' forces, the friction, the speeds and the quadratures."""
    fshift = float(shift)

    @inline_helper
    def _coefficient(model, k, modes, v0s, n_state, C, W):
        j = k + shift
        fac = fshift / (k + fshift)
        C[0, j] = C[1, k] * fac
        mt = modes[0]
        ms = modes[1] if n_coords == 2 else 0
        fct, nt = pair_coefficient(
            model.track_law, k, mt, model.track_clearance, C, 0, W, R_H, R_PT, v0s[0], R_LAW_T
        )
        W[R_FCT, k] = fct
        W[R_NT, k] = nt
        if n_coords == 2:
            C[2, j] = C[3, k] * fac
            fcs, ns = pair_coefficient(
                model.slot_law, k, ms, model.slot_clearance, C, 2, W, R_SL, R_PS, v0s[1], R_LAW_S
            )
            W[R_FCS, k] = fcs
            W[R_NS, k] = ns
        # from the pairs' force rows at coefficient k (W[R_NT], W[R_FCT], ...): the friction,
        # the speeds' C[1, j] (and C[3, j]) and the quadratures' C[q, j]
        fx = friction_force_series(
            model.friction, k, C[1], W[R_NX, :1], model.mu_x, W[R_FR_X : R_FR_X + SERIES_ROWS]
        )
        W[R_FX, k] = fx
        C[1, j] = (-mt * W[R_NT, k] - fx - W[R_LOAD, k]) * (fac / model.mass)
        if n_coords == 2:
            # the pad's friction under |N_t| = N_t (a Taylor step keeps N_t >= 0)
            fy = friction_force_series(
                model.friction, k, C[3], W[R_NT], model.mu_y, W[R_FR_Y : R_FR_Y + SERIES_ROWS]
            )
            W[R_FY, k] = fy
            load_y = model.load_y if k == 0 else 0.0
            C[3, j] = (-ms * W[R_NS, k] - fy + load_y) * (fac / model.mass)
        # the energy quadratures (as in derivatives: (N - F_k) p' = F_c p', f v, ...); a pair's
        # terms are 0 while it is free (and its rows are not written then)
        q = 2 * n_coords
        if n_state > q:
            C[q, j] = jet_mul(W[R_FCT], W[R_PDT], k) * fac if mt != 0 else 0.0
            if n_coords == 2:
                C[q + 1, j] = jet_mul(W[R_FCS], W[R_PDS], k) * fac if ms != 0 else 0.0
        q += n_coords
        if n_state > q:  # the friction works
            C[q, j] = jet_mul(W[R_FX], C[1], k) * fac
            if n_coords == 2:
                C[q + 1, j] = jet_mul(W[R_FY], C[3], k) * fac
        q += n_coords
        if n_state > q:  # all the quadratures
            # (a constant load in the x-only model at a constant speed: one product)
            if n_coords == 1 and _constant_speed(model.horn_gear):
                C[q, j] = -W[R_LOAD, 0] * C[1, k] * fac
            else:
                C[q, j] = -jet_mul(W[R_LOAD], C[1], k) * fac
            C[q + 1, j] = -mt * jet_mul(W[R_NT], W[R_HD], k) * fac if mt != 0 else 0.0
            if n_coords == 2:
                C[q + 2, j] = (model.load_y * C[3, k]) * fac
                C[q + 3, j] = -ms * jet_mul(W[R_NS], W[R_SD], k) * fac if ms != 0 else 0.0
                C[q + 4, j] = 0.0
            else:
                C[q + 2, j] = 0.0

    return _coefficient


def _series_rows(model, pair):
    # (model_series leaves each pair's p, F_c and N in these rows: _pair_series)
    if pair == 0:
        return R_PT, R_FCT, R_NT
    return R_PS, R_FCS, R_NS


pair_series_rows.register(CarrierX)(_series_rows)
pair_series_rows.register(CarrierXY)(_series_rows)


@_for_each_carrier(model_series_reach)
def _series_reach_for(n_coords):
    def _series_reach(model, C, h):
        # the friction along x (and along y) turns over with its sliding speed, x' (y')
        h = friction_series_reach(model.friction, C[1], h)
        if n_coords == 2:
            h = friction_series_reach(model.friction, C[3], h)
        return h

    return _series_reach


@_for_each_carrier(model_series)
def _series_for(n_coords):
    coefficient = _coefficient_for(n_coords, _pair_series, 1)

    def _series(model, k, modes, v0s, n_state, C, W):
        # the equations of motion of the module docstring, coefficient by coefficient
        coefficient(model, k, modes, v0s, n_state, C, W)

    return _series


# ---- the onset series in s = sqrt(t - t_onset) --------------------------------------------


@_for_each_carrier(model_onset_start)
def _onset_start_for(n_coords):
    def _onset_start(model, t, pair, modes, order, W):
        # one pair touching while the other is free (the force of a pair already in contact
        # would need its rate p' = dp/dt in s, which its law's series does not take); the series
        # of time alone to order / 2 in tau, then spread to s: coefficient j of h(t + tau) is
        # that of s^(2 j) in h(t + s^2), the odd ones are 0
        if n_coords == 2 and modes[1 - pair] != 0:
            return 0.0
        law = model.track_law if n_coords == 1 or pair == 0 else model.slot_law
        if contact_onset_power(law) == 0:
            return 0.0
        half = order // 2
        hz = model_series_start(model, t, modes, half, W)
        for r in (R_H, R_HD, R_SL, R_SD, R_OM, R_LOAD):
            jet_in_sqrt(W[r], half, order)
        return hz

    return _onset_start


@inline_helper
def _pair_onset(law, k, mode, clearance, C, i, W, r_wall, r_p, v0, r_law):
    """Coefficient k in s of the pair's (F_c, N) from its onset along coordinate i, whose
    coefficient k + 2 is known; writes p to k + 2 and p' = dp/dt to k in W[r_p], W[r_p + 1]
    (zeros when the pair is free)."""
    if mode == 0:
        W[r_p + 1, k] = 0.0
        return 0.0, 0.0
    sg = -1.0 if mode < 0 else 1.0
    if k == 0:
        W[r_p, 0] = 0.0  # (the onset: p = 0, and p = s^2 q has no term in s)
        W[r_p, 1] = 0.0
    W[r_p, k + 2] = sg * (C[i, k + 2] - W[r_wall, k + 2])
    W[r_p + 1, k] = 0.5 * (k + 2) * W[r_p, k + 2]
    return contact_force_onset_series(law, k, W[r_p, 2:], v0, W[r_law : r_law + SERIES_ROWS])


@_for_each_carrier(model_onset_series)
def _onset_series_for(n_coords):
    coefficient = _coefficient_for(n_coords, _pair_onset, 2)

    def _onset_series(model, k, pair, modes, v0s, n_state, C, W):
        # the equations of _series along t + s^2, coefficient by coefficient: the penetration
        # p = s^2 q to k + 2, i.e. q to k, with the coordinates; the other pair is free
        # (_onset_start)
        coefficient(model, k, modes, v0s, n_state, C, W)

    return _onset_series


# ---- tangents (forward sensitivities) ------------------------------------------------------


@inline_helper
def _track_contact_jvp(model, dm, t, y, s, mode, v0, dv0):
    """Tangents (dp', dF_k, dN) of the track pair's penetration rate, elastic force and
    normal force (0 when free)."""
    if mode == 0:
        return 0.0, 0.0, 0.0
    h, hd, _ = wall_motion(model.track, t)
    dh, dhd, _ = wall_motion_jvp(model.track, dm.track, t)
    u = y[0] - h
    du = s[0] - dh
    rate = y[1] - hd
    drate = s[1] - dhd
    p, pd = penetration(mode, u, model.track_clearance - u, rate)
    dp, dpd = penetration_jvp(mode, du, dm.track_clearance - du, drate)
    dfk, _, dn = contact_forces_jvp(model.track_law, dm.track_law, p, dp, pd, dpd, v0, dv0)
    return dpd, dfk, dn


@inline_helper
def _slot_contact_jvp(model, dm, t, y, s, mode, v0, dv0, om, dom, sp, dsp):
    """Tangents (dp', dF_k, dN) of the slot pair's penetration rate, elastic force and
    normal force (0 when free)."""
    if mode == 0:
        return 0.0, 0.0, 0.0
    rc = model.horn_gear.turning_radius
    drc = dm.horn_gear.turning_radius
    u = y[2] - sp
    du = s[2] - dsp
    rate = y[3] - rc * om
    drate = s[3] - drc * om - rc * dom
    p, pd = penetration(mode, u, model.slot_clearance - u, rate)
    dp, dpd = penetration_jvp(mode, du, dm.slot_clearance - du, drate)
    dfk, _, dn = contact_forces_jvp(model.slot_law, dm.slot_law, p, dp, pd, dpd, v0, dv0)
    return dpd, dfk, dn


@_for_each_carrier(derivatives_jvp)
def _derivs_jvp_for(n_coords):
    def _derivs_jvp(model, dm, t, y, s, modes, v0s, dv0s, out):
        # tangent of m x'' = -s_t N_t - f_x - T1 cos(phi) - m r_c omega^2 (and of the y equation)
        om, sp = horn_gear_state(model.horn_gear, t)
        dom, dsp = horn_gear_state_jvp(model.horn_gear, dm.horn_gear, t)
        m = model.mass
        mt = modes[0]
        pdt, fkt, nt = _track_contact(model, t, y, mt, v0s[0])
        dpdt, dfkt, dnt = _track_contact_jvp(model, dm, t, y, s, mt, v0s[0], dv0s[0])
        fx = friction_force(model.friction, y[1], model.normal_x, model.mu_x)
        dfx = friction_force_jvp(
            model.friction,
            dm.friction,
            y[1],
            s[1],
            model.normal_x,
            dm.normal_x,
            model.mu_x,
            dm.mu_x,
        )
        load_x = model.load_x + model.mass_radius * om * om
        dload_x = dm.load_x + dm.mass_radius * om * om + 2.0 * model.mass_radius * om * dom
        ax = (-mt * nt - fx - load_x) / m
        out[0] = s[1]
        out[1] = (-mt * dnt - dfx - dload_x) / m - ax * dm.mass / m
        if out.shape[0] > 2 * n_coords:
            # the tangent of the track law's dissipation rate (N - F_k) p' (derivatives)
            out[2 * n_coords] = (dnt - dfkt) * pdt + (nt - fkt) * dpdt
        if n_coords == 2:
            ms = modes[1]
            pds, fks, ns = _slot_contact(model, t, y, ms, v0s[1], om, sp)
            dpds, dfks, dns = _slot_contact_jvp(
                model, dm, t, y, s, ms, v0s[1], dv0s[1], om, dom, sp, dsp
            )
            if out.shape[0] > 5:
                out[5] = (dns - dfks) * pds + (ns - fks) * dpds
            sgn = 1.0 if nt >= 0.0 else -1.0
            fy = friction_force(model.friction, y[3], abs(nt), model.mu_y)
            dfy = friction_force_jvp(
                model.friction, dm.friction, y[3], s[3], abs(nt), sgn * dnt, model.mu_y, dm.mu_y
            )
            ay = (-ms * ns - fy + model.load_y) / m
            out[2] = s[3]
            out[3] = (-ms * dns - dfy + dm.load_y) / m - ay * dm.mass / m

    return _derivs_jvp


@_for_each_carrier(pair_gaps_jvp)
def _gaps_jvp_for(n_coords):
    def _gaps_jvp(model, dmodel, pair, t, y, s):
        if n_coords == 1 or pair == 0:
            dh, dhd, _ = wall_motion_jvp(model.track, dmodel.track, t)
            du = s[0] - dh
            return du, dmodel.track_clearance - du, s[1] - dhd
        dsp, dsd, _ = wall_motion_jvp(model.horn_gear, dmodel.horn_gear, t)
        du = s[2] - dsp
        return du, dmodel.slot_clearance - du, s[3] - dsd

    return _gaps_jvp


@_for_each_carrier(pair_law_jvp)
def _law_jvp_for(n_coords):
    def _law_jvp(model, dmodel, pair, p, dp, p_dot, dp_dot, v0, dv0):
        if n_coords == 1 or pair == 0:
            return contact_forces_jvp(
                model.track_law, dmodel.track_law, p, dp, p_dot, dp_dot, v0, dv0
            )
        return contact_forces_jvp(model.slot_law, dmodel.slot_law, p, dp, p_dot, dp_dot, v0, dv0)

    return _law_jvp


@_for_each_carrier(apply_transfer_jvp)
def _transfer_jvp_for(n_coords):
    def _transfer_jvp(model, dmodel, t, y, s, dt, out):
        # x -> h + eps - clamp(x - h, 0, eps),  x' -> 2 h' - x' + v_tr, at the time t + dt
        hh, hd, hdd = wall_motion(model.track, t)
        dhh, dhd, _ = wall_motion_jvp(model.track, dmodel.track, t)
        dhh += hd * dt
        dhd += hdd * dt
        xr = y[0] - hh
        eps = model.track_clearance
        dxr = s[0] - dhh
        if xr < 0.0:
            dxr = 0.0
        elif xr > eps:
            dxr = dmodel.track_clearance
        out[0] = dhh + dmodel.track_clearance - dxr
        out[1] = 2.0 * dhd - s[1] + dmodel.transfer_speed
        if n_coords == 2:
            out[2] = s[2]
            out[3] = s[3]

    return _transfer_jvp
