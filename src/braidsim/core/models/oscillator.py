"""A forced one-degree-of-freedom impact oscillator, the textbook model of vibro-impact.

    m x'' + c x' + k x = F cos(Omega t + phi) - s N

between fixed walls at x = -gap_inner and x = +gap_outer (an infinite gap: no wall there),
N the normal force of a contact law (:mod:`braidsim.core.physics`) of penetration p beyond
the wall in contact, s = -1 on the inner and +1 on the outer wall. It runs through the same
solver as the carrier, so the solver's tests can check it against closed forms: free
oscillation, the exact restitution of a law, energy conservation of an elastic law.

Energy quadratures: the energy dissipated by the contact law, by the dashpot (int c x'^2 dt),
and the work of the forcing (int F cos(...) x' dt); the energy
m x'^2/2 + k x^2/2 + (elastic contact energy) balances with them.
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
    derivatives,
    derivatives_jvp,
    describe_model,
    dissipation_index,
    free_accel_bound,
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
)
from braidsim.core.jets import jet_cos_linear, jet_in_sqrt, jet_mul, jet_sq

OSCILLATOR_COLUMNS = (
    "t",
    "x",
    "vx",
    "depth",
    "stiffness_force",
    "damping_force",
    "contact_force",
    "contact_dissipated",
    "viscous_dissipated",
    "forcing_work",
    "kind",
)


class ImpactOscillator(NamedTuple):
    """m x'' + c x' + k x = F cos(Omega t + phi) - s N between walls (module docstring)."""

    mass: float  # m [kg]
    stiffness: float  # k [N/m]
    damping: float  # c [N s/m]
    force_amplitude: float  # F [N]
    force_frequency: float  # Omega [rad/s]
    force_phase: float  # phi [rad]
    gap_inner: float  # the inner wall at x = -gap_inner [m] (inf: none)
    gap_outer: float  # the outer wall at x = +gap_outer [m] (inf: none)
    law: Any  # the contact law of both walls
    min_impact_velocity: float = 1e-4  # floor of the latched approach speed [m/s]
    initial_impact_velocity: float = -1.0  # v0 of a contact present at the start (<= 0: inf)


describe_model(
    ImpactOscillator,
    OSCILLATOR_COLUMNS,
    ("contact_dissipated", "viscous_dissipated", "forcing_work"),
)


@model_size.register(ImpactOscillator)
def _size(model):
    return 1, 1, 3


@pair_gaps.register(ImpactOscillator)
def _gaps(model, pair, t, y):
    return y[0] + model.gap_inner, model.gap_outer - y[0], y[1]


@inline_helper
def _contact(model, mode, y, v0):
    if mode == 0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    # the gaps of pair_gaps above, turned into the penetration of the wall in contact
    p, pd = penetration(mode, y[0] + model.gap_inner, model.gap_outer - y[0], y[1])
    fk, fc, nn = contact_forces(model.law, p, pd, v0)
    return p, pd, fk, fc, nn


@derivatives.register(ImpactOscillator)
def _derivs(model, t, y, modes, v0s, n_state, out):
    mode = modes[0]
    _, pd, fk, _, nn = _contact(model, mode, y, v0s[0])
    force = model.force_amplitude * math.cos(model.force_frequency * t + model.force_phase)
    out[0] = y[1]
    out[1] = (force - model.damping * y[1] - model.stiffness * y[0] - mode * nn) / model.mass
    if n_state > 2:
        out[2] = (nn - fk) * pd
    if n_state > 3:  # the work of the damper (the "friction" of this model) too
        out[3] = model.damping * y[1] * y[1]
    if n_state > 4:
        out[4] = force * y[1]


@pair_gap_accel.register(ImpactOscillator)
def _gap_accel(model, pair, t, f):
    return f[1]


@pair_law.register(ImpactOscillator)
def _law(model, pair, p, p_dot, v0):
    return contact_forces(model.law, p, p_dot, v0)


@pair_law_rates.register(ImpactOscillator)
def _law_rates(model, pair, p, p_dot, p_ddot, v0, f_k, f_c):
    return contact_force_rates(model.law, p, p_dot, p_ddot, v0, f_k, f_c)


@pair_onset_step.register(ImpactOscillator)
def _onset(model, pair, v):
    return contact_onset_step(model.law, model.mass, v)


@free_accel_bound.register(ImpactOscillator)
def _free_bound(model, pair, f0, f1):
    return math.inf  # no screen: the events are sampled in every step


@apply_transfer.register(ImpactOscillator)
def _transfer(model, t, y):
    return 0  # the oscillator has no transfers


@dissipation_index.register(ImpactOscillator)
def _diss(model, pair):
    return 2


@series_row.register(ImpactOscillator)
def _row(model, t, y, modes, v0s, n_state, kind, row):
    mode = modes[0]
    p, _, fk, fc, nn = _contact(model, mode, y, v0s[0])
    s = float(mode)
    row[0] = t
    row[1] = y[0]
    row[2] = y[1]
    row[3] = s * p
    row[4] = s * fk
    row[5] = s * fc
    row[6] = s * nn
    for i in range(3):
        row[7 + i] = y[2 + i] if 2 + i < n_state else math.nan
    row[10] = kind


# ---- Taylor series -------------------------------------------------------------------------
# rows of the work array: the forcing, the penetration, its rate, the damping and normal
# forces, then the contact law's work rows
R_FORCE, R_P, R_PD, R_FC, R_N, R_LAW = range(6)


@pair_series_rows.register(ImpactOscillator)
def _series_rows(model, pair):
    return R_P, R_FC, R_N


@model_series_reach.register(ImpactOscillator)
def _series_reach(model, C, h):
    return h  # (no friction; the contact's branch points: taylor.depth_root_reach)


@model_series_start.register(ImpactOscillator)
def _series_start(model, t, modes, order, W):
    jet_cos_linear(
        model.force_amplitude, model.force_frequency, model.force_phase, t, order, W[R_FORCE], False
    )
    return math.inf


@model_series.register(ImpactOscillator)
def _series(model, k, modes, v0s, n_state, C, W):
    k1 = k + 1.0
    C[0, k + 1] = C[1, k] / k1
    mode = modes[0]
    nn = 0.0
    W[R_PD, k] = 0.0
    W[R_FC, k] = 0.0
    W[R_N, k] = 0.0
    if mode != 0:
        # p = -(x + gap_inner) on the inner wall, x - gap_outer on the outer one
        if k == 0:
            W[R_P, 0] = -(C[0, 0] + model.gap_inner) if mode < 0 else C[0, 0] - model.gap_outer
        W[R_P, k + 1] = -C[0, k + 1] if mode < 0 else C[0, k + 1]
        W[R_PD, k] = k1 * W[R_P, k + 1]
        _, fc, nn = contact_force_series(
            model.law, k, W[R_P], v0s[0], W[R_LAW : R_LAW + SERIES_ROWS]
        )
        W[R_FC, k] = fc
        W[R_N, k] = nn
    C[1, k + 1] = (
        W[R_FORCE, k] - model.damping * C[1, k] - model.stiffness * C[0, k] - mode * nn
    ) / (model.mass * k1)
    if n_state > 2:  # (N - F_k) p' = F_c p'
        C[2, k + 1] = jet_mul(W[R_FC], W[R_PD], k) / k1
    if n_state > 3:
        C[3, k + 1] = model.damping * jet_sq(C[1], k) / k1
    if n_state > 4:
        C[4, k + 1] = jet_mul(W[R_FORCE], C[1], k) / k1


@model_onset_start.register(ImpactOscillator)
def _onset_start(model, t, pair, modes, order, W):
    # the forcing in s: F cos(Omega (t + s^2) + phi), coefficient j in tau at s^(2 j)
    if contact_onset_power(model.law) == 0:
        return 0.0
    half = order // 2
    model_series_start(model, t, modes, half, W)
    jet_in_sqrt(W[R_FORCE], half, order)
    return math.inf


@model_onset_series.register(ImpactOscillator)
def _onset_series(model, k, pair, modes, v0s, n_state, C, W):
    # the equation along t + s^2 (dy/ds = 2 s dy/dt): x first, then the penetration
    # p = s^2 q to k + 2 (q to k), the contact force and x''
    c2 = 2.0 / (k + 2.0)
    mode = modes[0]
    C[0, k + 2] = C[1, k] * c2
    if k == 0:
        W[R_P, 0] = 0.0
        W[R_P, 1] = 0.0
    W[R_P, k + 2] = -C[0, k + 2] if mode < 0 else C[0, k + 2]
    fc, nn = contact_force_onset_series(
        model.law, k, W[R_P, 2:], v0s[0], W[R_LAW : R_LAW + SERIES_ROWS]
    )
    W[R_FC, k] = fc
    W[R_PD, k] = 0.5 * (k + 2) * W[R_P, k + 2]  # p' = dp/dt
    C[1, k + 2] = (
        W[R_FORCE, k] - model.damping * C[1, k] - model.stiffness * C[0, k] - mode * nn
    ) * (c2 / model.mass)
    if n_state > 2:
        C[2, k + 2] = jet_mul(W[R_FC], W[R_PD], k) * c2
    if n_state > 3:
        C[3, k + 2] = model.damping * jet_sq(C[1], k) * c2
    if n_state > 4:
        C[4, k + 2] = jet_mul(W[R_FORCE], C[1], k) * c2


# ---- tangents (forward sensitivities) ------------------------------------------------------


@derivatives_jvp.register(ImpactOscillator)
def _derivs_jvp(model, dm, t, y, s, modes, v0s, dv0s, out):
    mode = modes[0]
    _, pd, fk, _, nn = _contact(model, mode, y, v0s[0])
    dnn = 0.0
    ddiss = 0.0  # the tangent of the law's dissipation rate (N - F_k) p'
    if mode != 0:
        p, pd = penetration(mode, y[0] + model.gap_inner, model.gap_outer - y[0], y[1])
        dp, dpd = penetration_jvp(mode, s[0] + dm.gap_inner, dm.gap_outer - s[0], s[1])
        dfk, _, dnn = contact_forces_jvp(model.law, dm.law, p, dp, pd, dpd, v0s[0], dv0s[0])
        ddiss = (dnn - dfk) * pd + (nn - fk) * dpd
    arg = model.force_frequency * t + model.force_phase
    force = model.force_amplitude * math.cos(arg)
    dforce = dm.force_amplitude * math.cos(arg) - model.force_amplitude * math.sin(arg) * (
        dm.force_frequency * t + dm.force_phase
    )
    m = model.mass
    ax = (force - model.damping * y[1] - model.stiffness * y[0] - mode * nn) / m
    out[0] = s[1]
    out[1] = (
        dforce
        - dm.damping * y[1]
        - model.damping * s[1]
        - dm.stiffness * y[0]
        - model.stiffness * s[0]
        - mode * dnn
    ) / m - ax * dm.mass / m
    if out.shape[0] > 2:
        out[2] = ddiss


@pair_gaps_jvp.register(ImpactOscillator)
def _gaps_jvp(model, dmodel, pair, t, y, s):
    return s[0] + dmodel.gap_inner, dmodel.gap_outer - s[0], s[1]


@pair_law_jvp.register(ImpactOscillator)
def _law_jvp(model, dmodel, pair, p, dp, p_dot, dp_dot, v0, dv0):
    return contact_forces_jvp(model.law, dmodel.law, p, dp, p_dot, dp_dot, v0, dv0)


@apply_transfer_jvp.register(ImpactOscillator)
def _transfer_jvp(model, dmodel, t, y, s, dt, out):
    out[0] = s[0]  # the oscillator has no transfers
    out[1] = s[1]
