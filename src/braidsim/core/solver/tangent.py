"""Forward sensitivities carried with the step loop: the variational equations through the
same Dormand-Prince stages, and the jumps at contact onset, exit and transfers.

Along a direction d (a tangent of the parameters and of the initial state) the tangent
s = dy/d(key) of the coordinates and speeds obeys, between events,

    s' = (df/dy) s + df/d(key)                                            (1)

computed by the model's :func:`~braidsim.core.interfaces.derivatives_jvp`. Each accepted
step integrates (1) with the stages of the step the state took (same step sizes, same
tableau), so the tangent is the derivative of the numerical solution along that step
sequence; rejected steps cost nothing. At an event of function g (a gap to a wall at
onset, a penetration at exit) at time t_e the event time moves by

    dt_e = -(dg/dy s + dg/d(key)) / (dg/dt)                              (2)

and the tangent jumps by the difference of the vector fields on the two sides,

    s+ = s- + (f- - f+) dt_e                                             (3)

(zero for the power-law laws, whose force vanishes at zero depth; the dashpot of a
Kelvin-Voigt law makes f jump). The approach speed v0 latched at onset is a state of the
contact: v0 = -dg/dt(t_e) (the penetration rate), so

    dv0 = d(penetration rate)/dy s + d(...)/d(key) + (penetration acceleration) dt_e   (4)

unless the floor ``min_impact_velocity`` holds it. A transfer at time tau, y+ = T(tau, y-):

    s+ = T_t dtau + T_y (s- + f- dtau) + T_key - f+ dtau                 (5)

A law that cannot pull clamps its force, N = max(0, F_k + F_c). The field is continuous
where F_k + F_c crosses 0 (the kink): nothing jumps there, but the field's derivative does,
and (1) on each side of the kink has its own: the law's linearisation (dN = dF_k + dF_c)
on the side where the force presses, dN = 0 where it is clamped. The solver ends a step at
the kink, so that each step's stages see one side only; those at the kink itself are read
on the side of their step (:func:`clamp_step_end`, :func:`clamp_event`).

Where the run integrates the energy each contact pair dissipates, D' = (N - F_k) p' (the
work of the law's non-conservative part), the tangents carry D's too, after the coordinates
and speeds: (1) for them is the tangent of that integrand, (N - F_k)' along the direction
times p' plus (N - F_k) times the tangent of p', which the model's ``derivatives_jvp``
writes beside the others where its output has room (from the forces' tangents it computes
anyway: a generic function here, which computed the forces again, made a run with one key
on paper-3.3 8-24 % slower in the three forms tried, and a monodromy up to 50 % slower).
They are integrated with the same stages and jump at events and transfers by (3) and (5)
like the others (the transfer map leaves D as it is). An impact's dissipated energy is D
at its exit less D at its onset, each read at the moving instant: its tangent is

    dE = (s_D + D' dt_e)(exit) - (s_D + D' dt_e)(onset)                   (6)

(D' is 0 at both ends for the power laws, whose force and depth vanish together; a
Kelvin-Voigt dashpot dissipates from the onset's first instant). The tangents of D follow
the steps the state and its tangents take, except where a contact force is held at its
clamp: there their own error estimate bounds the step too (:func:`dissipation_tangent_error`).

Peak force and maximum depth are stationary in time where they occur, so their tangents
are the partial ones at that instant (plus their slope times dt_e when the maximum sits at
the onset instant itself). See ``docs/sensitivities.md`` for the derivation. (2), (3) and
(5) are the trajectory sensitivities of hybrid systems of Hiskens & Pai, IEEE Trans.
Circuits Syst. I 47 (2000) 204-220, doi:10.1109/81.828574; (3) is the saltation matrix of
Leine & Nijmeijer, Dynamics and Bifurcations of Non-Smooth Mechanical Systems, Springer
(2004), doi:10.1007/978-3-540-44398-8.
"""

from __future__ import annotations

import math

from braidsim.core.generic import cached_njit, inline_helper
from braidsim.core.interfaces import (
    apply_transfer_jvp,
    derivatives_jvp,
    model_size,
    pair_gap_accel,
    pair_gaps_jvp,
    pair_law_jvp,
    pair_law_rates,
    penetration,
    penetration_jvp,
)
from braidsim.core.layout import (
    ES_DEPTH,
    ES_DISS,
    ES_PEAK,
    ES_REBOUND,
    ES_T,
    ES_T_END,
    ES_VELOCITY,
)
from braidsim.core.solver.calls import rhs
from braidsim.core.solver.dense import dense_eval
from braidsim.core.solver.dopri5 import (
    D1,
    D3,
    D4,
    D5,
    D6,
    D7,
    E1,
    E3,
    E4,
    E5,
    E6,
    E7,
    RK_A,
    RK_C,
)
from braidsim.core.solver.pairs import gaps, pair_forces

# with numba's reference counting (the tangent records come out of a typed list), unlike
# core.generic.helper, whose functions run without it
tangent_helper = cached_njit(error_model="numpy")


@tangent_helper
def tangent_rhs(model, SENS, d, t, y, s, modes, v0s, out):
    """Write (1) for direction d into ``out[:2 n_coords]``, and into the rest of ``out``
    (where it has room) the tangents of the dissipation rates (the model's
    :func:`~braidsim.core.interfaces.derivatives_jvp`)."""
    derivatives_jvp(model, SENS.tangents[d], t, y, s, modes, v0s, SENS.DV0[d], out)


@tangent_helper
def tangent_start(model, SENS, t, y, modes, v0s, KS):
    """KS[d, 0] = (1) at (t, y, S[d]) for every direction."""
    for d in range(SENS.S.shape[0]):
        tangent_rhs(model, SENS, d, t, y, SENS.S[d], modes, v0s, KS[d, 0])


@tangent_helper
def tangent_step(model, SENS, t, y, h, K, KS, modes, v0s, n_dof2, YS, ss, S1):
    """Integrate (1) over the step [t, t + h] the state took (stages K): fills KS[:, 1..6]
    and the tangents at the end of the step S1 (KS[:, 0] holds (1) at the start), the
    dissipations' included where the run carries them. ``YS`` (7, n_dof2) work space for
    the stage states."""
    n_tan = SENS.S.shape[1]
    for st in range(1, 7):
        for i in range(n_dof2):
            acc = 0.0
            for j in range(st):
                acc += RK_A[st, j] * K[j, i]
            YS[st, i] = y[i] + h * acc
    for d in range(SENS.S.shape[0]):
        dm = SENS.tangents[d]  # once per direction and step (a typed-list access)
        dv0 = SENS.DV0[d]
        for st in range(1, 7):
            sd = S1[d] if st == 6 else ss
            # (the field reads the coordinates and speeds only: the dissipations' stage
            # tangents are needed for S1 alone)
            for i in range(n_tan if st == 6 else n_dof2):
                acc = 0.0
                for j in range(st):
                    acc += RK_A[st, j] * KS[d, j, i]
                sd[i] = SENS.S[d, i] + h * acc
            derivatives_jvp(model, dm, t + RK_C[st] * h, YS[st], sd, modes, v0s, dv0, KS[d, st])


@inline_helper
def tangent_embedded_error(h, KS, d, i):
    """The embedded error estimate of component i of direction d's tangent over the step,
    h sum_s E_s KS[d, s, i] (as :func:`~braidsim.core.solver.dopri5.embedded_error` of the
    state's; indexed in place: a view KS[d] per direction made a run with one key 10 %
    slower)."""
    return h * (
        E1 * KS[d, 0, i]
        + E3 * KS[d, 2, i]
        + E4 * KS[d, 3, i]
        + E5 * KS[d, 4, i]
        + E6 * KS[d, 5, i]
        + E7 * KS[d, 6, i]
    )


@tangent_helper
def tangent_error(SENS, S1, h, KS, n_dof2, rtol, SMAX):
    """RMS of the embedded error estimate of the tangents over the step, each component
    scaled by rtol (max(|s|, |s1|) + the largest |s| of its kind (positions or speeds) seen
    so far in its direction, ``SMAX[d, i % 2]``) + ``SENS.ATOL[d, i % 2]``: the tangents are
    held to the relative tolerance of the state. The Hertz law's stiffness sqrt(p) is not
    smooth at onset and exit, so the tangents, not the state, decide the step size there."""
    acc = 0.0
    cnt = 0
    for d in range(SENS.S.shape[0]):
        for i in range(n_dof2):
            err = tangent_embedded_error(h, KS, d, i)
            cnt += 1
            if err == 0.0:
                continue
            sc = (
                rtol * (max(abs(SENS.S[d, i]), abs(S1[d, i])) + SMAX[d, i % 2])
                + SENS.ATOL[d, i % 2]
            )
            if sc == 0.0:
                return math.inf
            acc += (err / sc) ** 2
    return math.sqrt(acc / max(cnt, 1))


@tangent_helper
def dissipation_tangent_error(SENS, S1, h, KS, n_dof2, y, y1, rtol, atol_position, modes, clamped):
    """The largest embedded error estimate of the dissipations' tangents over the step,
    among the pairs in contact whose force is held at its clamp (0 where none is), each
    over rtol (max(|s|, |s1|) + max(|D|, |D1|) / scale): the state's bound on its own
    dissipation D (dopri5.quadrature_error) per unit of the direction's parameter, whose
    scale is atol_position / ``SENS.ATOL[d, 0]`` (as the other tangents' absolute parts).

    While a contact force is clamped the body flies free: the tangents of the coordinates
    and speeds are smooth and take long steps, and the state's dissipation is bounded by
    its own quadrature. Its tangent's integrand, -(dF_k p' + F_k dp'), is not smooth:
    dF_k = n K p^(n-1) dp of a power law goes as sqrt(p) towards the exit. Left to the
    others' steps, an impact's dissipated energy had its tangent along the mass 7.3e-5 off
    its central differences on a Gonthier wall at e = 0.1 (paper-3.3, rtol 1e-12, atol
    1e-17 m), and 2.9e-5 off at rtol 1e-13: it hardly converged with the tolerance. (The
    absolute part keeps the steps to that sqrt(p) finite where the tangent itself is near
    0: a continued run's starts at 0 there.)"""
    worst = 0.0
    for i in range(n_dof2, SENS.S.shape[1]):
        pair = i - n_dof2
        if modes[pair] == 0 or clamped[pair] != 1:
            continue
        dsize = max(abs(y[i]), abs(y1[i]))
        for d in range(SENS.S.shape[0]):
            err = tangent_embedded_error(h, KS, d, i)
            if err == 0.0 or not math.isfinite(err):
                # (not finite: a model that does not write these tangents, NaN from the
                # start; they are reported NaN, and must not hold the step)
                continue
            per_unit = dsize * SENS.ATOL[d, 0] / atol_position
            sc = rtol * (max(abs(SENS.S[d, i]), abs(S1[d, i])) + per_unit)
            if sc > 0.0:  # (0: nothing dissipated, no tangent; the estimate is rounding)
                worst = max(worst, abs(err) / sc)
    return worst


@tangent_helper
def tangent_scales(S1, n_dof2, SMAX):
    """Fold the tangents at the end of an accepted step into their running maxima."""
    for d in range(S1.shape[0]):
        for i in range(n_dof2):
            a = abs(S1[d, i])
            if a > SMAX[d, i % 2]:
                SMAX[d, i % 2] = a


@tangent_helper
def tangent_dense_coeffs(SENS, S1, h, KS, RCS, n_dof2):
    """Continuous extension of the tangents over the step (as the state's)."""
    for d in range(SENS.S.shape[0]):
        for i in range(n_dof2):
            s0 = SENS.S[d, i]
            sdiff = S1[d, i] - s0
            bspl = h * KS[d, 0, i] - sdiff
            RCS[d, 0, i] = s0
            RCS[d, 1, i] = sdiff
            RCS[d, 2, i] = bspl
            RCS[d, 3, i] = sdiff - h * KS[d, 6, i] - bspl
            RCS[d, 4, i] = h * (
                D1 * KS[d, 0, i]
                + D3 * KS[d, 2, i]
                + D4 * KS[d, 3, i]
                + D5 * KS[d, 4, i]
                + D6 * KS[d, 5, i]
                + D7 * KS[d, 6, i]
            )


@tangent_helper
def tangent_dense_eval(theta, RCS, d, out, n_dof2):
    """Tangent of direction d at fraction theta of the step."""
    th1 = 1.0 - theta
    for i in range(n_dof2):
        out[i] = RCS[d, 0, i] + theta * (
            RCS[d, 1, i] + th1 * (RCS[d, 2, i] + theta * (RCS[d, 3, i] + th1 * RCS[d, 4, i]))
        )


@tangent_helper
def pair_tangent(model, dm, pair, t, y, s, mode, v0, dv0):
    """(dp, dp', dN) of a pair in contact mode ``mode`` at fixed t (zeros when free)."""
    if mode == 0:
        return 0.0, 0.0, 0.0
    g_in, g_out, rate = gaps(model, pair, t, y)
    dg_in, dg_out, drate = pair_gaps_jvp(model, dm, pair, t, y, s)
    p, pd = penetration(mode, g_in, g_out, rate)
    dp, dpd = penetration_jvp(mode, dg_in, dg_out, drate)
    _, _, dn = pair_law_jvp(model, dm, pair, p, dp, pd, dpd, v0, dv0)
    return dp, dpd, dn


@tangent_helper
def episode_extremes(model, SENS, ie, pair, t, y, s_all, mode, v0, which):
    """Tangents of the maximum depth (which & 1) and peak force (which & 2) of episode ie
    at the instant t where they were found (state y, tangents s_all[d])."""
    for d in range(SENS.S.shape[0]):
        dp, _, dn = pair_tangent(
            model, SENS.tangents[d], pair, t, y, s_all[d], mode, v0, SENS.DV0[d, pair]
        )
        if which & 1:
            SENS.ESENS[ie, d, ES_DEPTH] = dp
        if which & 2:
            SENS.ESENS[ie, d, ES_PEAK] = dn


@tangent_helper
def onset_correction(SENS, ie, which, slope_depth, slope_force):
    """Add slope x dt_onset to extremes found at the onset instant itself (a law whose
    force jumps at onset can have its peak there: a corner, not a stationary point)."""
    for d in range(SENS.S.shape[0]):
        dt_on = SENS.ESENS[ie, d, ES_T]
        if which & 1:
            SENS.ESENS[ie, d, ES_DEPTH] += slope_depth * dt_on
        if which & 2:
            SENS.ESENS[ie, d, ES_PEAK] += slope_force * dt_on


@tangent_helper
def contact_event(model, SENS, pair, side, onset, at_start, t, y, f_minus, f_plus, n_dof2, ie, KS):
    """Tangents at a contact event of ``pair`` with wall ``side`` at t: (2), (3) and, at
    onset, (4). ``f_minus``, ``f_plus``: dy/dt before and after the mode change; ``ie``:
    the episode opened (onset) or closed (exit), -1 for none. Returns False when the
    event is grazing (its normal speed too small for the event time to be differentiable).

    ``at_start``: an onset within a picosecond of the run's start. A body that starts on a
    wall at rest relative to it and is pressed into it (the xy carrier on the rear slot
    wall, carried by the horn gear) touches from the first instant, and its onset found a
    few 1e-20 s later has no normal speed: grazing by the test above. But where no direction
    moves that wall's gap or its rate at the start (each tangent below the direction's
    absolute tolerance plus 1e-9 of the largest tangent of its kind, the rounding of the
    start's tangents), the contact starts at the run's start whatever the parameters: the
    onset time's derivative is 0 and the tangents do not jump; the approach speed is held at
    its floor. A direction that moves the gap or its rate there (the initial y, say) does
    make the contact appear or not: grazing.
    """
    _, _, rate_in = gaps(model, pair, t, y)
    gdot = rate_in if side < 0 else -rate_in  # d(gap to this wall)/dt
    pinned = False
    if abs(gdot) < 1e-3 * model.min_impact_velocity:
        if not (onset and at_start):
            return False
        for d in range(SENS.S.shape[0]):
            dg_in, dg_out, drate_in = pair_gaps_jvp(model, SENS.tangents[d], pair, t, y, SENS.S[d])
            dg = dg_in if side < 0 else dg_out
            # (the start's tangents are difference quotients of the model's records, good
            # to ~1e-13 of their size: a rate of 1e-13 m/s per unit at an atol of 1e-12
            # m/s was taken for a direction that moves the wall)
            if abs(dg) > SENS.ATOL[d, 0] + 1e-9 * SENS.SMAX[d, 0]:
                return False
            if abs(drate_in) > SENS.ATOL[d, 1] + 1e-9 * SENS.SMAX[d, 1]:
                return False
        pinned = True
    acc_in = pair_gap_accel(model, pair, t, f_minus)
    pen_acc = -acc_in if side < 0 else acc_in
    pen_rate = -gdot
    vmin = model.min_impact_velocity
    for d in range(SENS.S.shape[0]):
        dm = SENS.tangents[d]
        s = SENS.S[d]
        dg_in, dg_out, drate_in = pair_gaps_jvp(model, dm, pair, t, y, s)
        dg = dg_in if side < 0 else dg_out
        dpen_rate = -drate_in if side < 0 else drate_in
        dt_e = 0.0 if pinned else -dg / gdot
        for i in range(s.shape[0]):
            s[i] += (f_minus[i] - f_plus[i]) * dt_e
        if ie >= 0 and s.shape[0] > n_dof2:
            # (6): D at the moving instant (s + f dt_e is the same on either side of the jump)
            k = n_dof2 + pair
            d_at = s[k] + f_plus[k] * dt_e
            SENS.ESENS[ie, d, ES_DISS] = d_at if onset else d_at - SENS.ESENS[ie, d, ES_DISS]
        if onset:
            dvel = dpen_rate + pen_acc * dt_e
            SENS.DV0[d, pair] = dvel if pen_rate > vmin else dm.min_impact_velocity
            if ie >= 0:
                SENS.ESENS[ie, d, ES_T] = dt_e
                SENS.ESENS[ie, d, ES_VELOCITY] = dvel
        elif ie >= 0:
            SENS.ESENS[ie, d, ES_T_END] = dt_e
            # the rebound speed -p' at the exit, read at the moving exit instant
            SENS.ESENS[ie, d, ES_REBOUND] = -(dpen_rate + pen_acc * dt_e)
    return True


@tangent_helper
def tangent_shift(model, SENS, t, y, dt, modes, v0s, n_dof2, work):
    """Carry every direction's tangent over a time ``dt`` (of either sign) by one Euler step
    of (1) in the contact modes ``modes`` at (t, y); ``work``: work space as long as a
    tangent."""
    for d in range(SENS.S.shape[0]):
        tangent_rhs(model, SENS, d, t, y, SENS.S[d], modes, v0s, work)
        s = SENS.S[d]
        for i in range(s.shape[0]):
            s[i] += dt * work[i]


@tangent_helper
def surface_event(
    model,
    SENS,
    pair,
    side,
    onset,
    at_start,
    t,
    y,
    f_minus,
    f_plus,
    n,
    n_dof2,
    ie,
    KS,
    h_step,
    modes,
    v0s,
    old_modes,
    yc,
    fm,
    fp,
    work,
):
    """:func:`contact_event` at the instant the event's function is 0, not at t.

    The state at a located event (the step recomputed to the root of the wall's function
    on the step's interpolant) lies off the wall by the location error g: a few 1e-12 m
    after a long free step. The state's own field is continuous there: a law's force at a
    depth p < 0 is that at p = 0 (the depth is clamped). Not so the tangents' field, whose
    linearisation is the law's at p = 0 on both sides of it (k_c dp for Kelvin-Voigt). The
    tangents leave t with the new mode's field, so that over the time dt_s = -g / (dg/dt)
    between t and the wall they are carried by the wrong one: an error k_c dp dt_s, which
    after the contact, where the tangents' speeds fall back from k_c-sized values to O(1)
    ones, was ~1e-2 of the monodromy of an impact oscillator on a wall of 1e10 N/m.

    Here the tangents are carried to the wall (t + dt_s) by the old mode's field, jump there
    by (2)-(4) with both fields evaluated on the wall (state y + f_minus dt_s), and are
    carried back to t by the new mode's, from where the next step integrates them. A shift
    not small against the step to the event (``h_step``), or at a grazing or pinned
    event, is not made. ``old_modes``, ``yc``, ``fm``, ``fp``, ``work``: work space."""
    g_in, g_out, rate_in = gaps(model, pair, t, y)
    g = g_in if side < 0 else g_out
    gdot = rate_in if side < 0 else -rate_in
    dts = 0.0
    if abs(gdot) >= 1e-3 * model.min_impact_velocity:
        dts = -g / gdot
        if not abs(dts) <= 0.5 * h_step:
            dts = 0.0
    if dts == 0.0:
        return contact_event(
            model, SENS, pair, side, onset, at_start, t, y, f_minus, f_plus, n_dof2, ie, KS
        )
    old_modes[0] = modes[0]
    old_modes[1] = modes[1]
    old_modes[pair] = 0 if onset else side
    for i in range(n):
        yc[i] = y[i] + f_minus[i] * dts
    rhs(model, t + dts, yc, old_modes, v0s, n, fm)
    rhs(model, t + dts, yc, modes, v0s, n, fp)
    tangent_shift(model, SENS, t, y, dts, old_modes, v0s, n_dof2, work)
    if not contact_event(
        model, SENS, pair, side, onset, at_start, t + dts, yc, fm, fp, n_dof2, ie, KS
    ):
        return False
    tangent_shift(model, SENS, t + dts, yc, -dts, modes, v0s, n_dof2, work)
    return True


# the first move of the unclamped force asked of a nudge onto one side of the clamp
# (clamp_side), relative to |F_k| + |F_c| (a 1e10 N/m wall at 2 um: 4e-5 N, ~40 times the
# force of one ulp of the position), and the factor by which the nudge grows while the
# state is still on the wrong side
CLAMP_NUDGE = 1e-9
CLAMP_NUDGE_GROWTH = 10.0


@tangent_helper
def clamp_force_rate(model, pair, t, y, f, mode, v0):
    """(F_k + F_c, d(F_k + F_c)/dt, |F_k| + |F_c|) of ``pair`` in contact mode ``mode`` at
    (t, y), ``f`` being dy/dt there: the unclamped force, its rate (the laws' rates are
    those of the unclamped force) and the size of its two terms."""
    g_in, g_out, rate = gaps(model, pair, t, y)
    p, pd = penetration(mode, g_in, g_out, rate)
    acc = pair_gap_accel(model, pair, t, f)
    pdd = -acc if mode < 0 else acc
    _, _, fk, fc, _ = pair_forces(model, pair, t, y, mode, v0)
    dn, _ = pair_law_rates(model, pair, p, pd, pdd, v0, fk, fc)
    return fk + fc, dn, abs(fk) + abs(fc)


@tangent_helper
def clamp_side(model, pair, mode, v0, want_clamped, t, y, f, m, yn):
    """tau: a time offset that puts y + f tau (written into ``yn[:m]``) on the wanted side
    of the clamp of ``pair`` (clamped: F_k + F_c < 0, the test the laws' linearisations
    make), 0 where y is on it already, NaN where no nudge found one.

    The state at a located kink, and the stages of a step that ends there, lie on either
    side of it by the location's error (F_k + F_c = 1.6e-7 N, of either sign, on a 1e10
    N/m wall: below the force of one ulp of the position). The tangents' field there is
    wanted on the side of the step it belongs to: it is read at the nearby state, moved
    along the flow past the kink, tau = -(F_k + F_c) / (dF/dt) and beyond by
    CLAMP_NUDGE (|F_k| + |F_c|) / |dF/dt|, grown until the sign is the wanted one (the
    field is smooth on each side: a move of a few 1e-15 s changes it by that time over the
    contact's time scale, ~1e-10 on the 1e10 N/m wall)."""
    fsum, fdot, size = clamp_force_rate(model, pair, t, y, f, mode, v0)
    for i in range(m):
        yn[i] = y[i]
    if (fsum < 0.0) == want_clamped:
        return 0.0
    if not (abs(fdot) > 0.0 and math.isfinite(fdot)):
        return math.nan
    # towards F < 0 where a clamped side is wanted, F > 0 otherwise
    sgn = 1.0 if (fdot < 0.0) == want_clamped else -1.0
    tau = sgn * (abs(fsum) + CLAMP_NUDGE * size) / abs(fdot)
    for _ in range(8):
        for i in range(m):
            yn[i] = y[i] + f[i] * tau
        _, _, fk, fc, _ = pair_forces(model, pair, t + tau, yn, mode, v0)
        if (fk + fc < 0.0) == want_clamped:
            return tau
        tau *= CLAMP_NUDGE_GROWTH
    for i in range(m):
        yn[i] = y[i]
    return math.nan


@tangent_helper
def clamp_step_end(
    model, SENS, pair, pre_clamped, t, h, K, KS, modes, v0s, n_dof2, YS, ss, S1, yn, work
):
    """The tangents over a step [t, t + h] that ends at the kink of the force of ``pair``
    (:func:`tangent_step` has filled KS, YS and S1), with the stages at the step's end read
    on the step's side of the kink (``pre_clamped``: whether the force is clamped there).

    Stages 5 and 6 of the Dormand-Prince step sit at t + h: at the kink itself, up to the
    location's error, whose sign decides which linearisation they got. Stage 5 is in the
    solution, weight b6 = 11/84: read on the wrong side, it added h b6 (dN / m) to the
    tangents' speeds, dN the tangent of the unclamped force there, of order dF/dt times the
    kink time's tangent. With the kink located on its far side, this left the monodromy of
    an impact oscillator on a clamped Kelvin-Voigt wall of 1e10 N/m 3e-4 off its central
    differences. Here a stage read on the wrong side (:func:`clamp_side`) is read again
    at a state nudged onto the right one, and S1 takes the difference,

        S1 += h b6 (J- s5 - KS5),

    then stage 6 (the step's end, FSAL: the dense output's slope) is read there at S1.
    ``yn``: n_dof2 of work space, ``work``: as long as a tangent."""
    n_tan = SENS.S.shape[1]
    mode = modes[pair]
    v0 = v0s[pair]
    moved = False
    for st in range(5, 7):
        tau = clamp_side(model, pair, mode, v0, pre_clamped, t + h, YS[st], K[st], n_dof2, yn)
        if not math.isfinite(tau):
            continue
        if tau == 0.0 and not (st == 6 and moved):
            continue
        for d in range(SENS.S.shape[0]):
            if st == 6:
                tangent_rhs(model, SENS, d, t + h + tau, yn, S1[d], modes, v0s, KS[d, 6])
                continue
            for i in range(n_dof2):
                acc = 0.0
                for j in range(st):
                    acc += RK_A[st, j] * KS[d, j, i]
                ss[i] = SENS.S[d, i] + h * acc
            tangent_rhs(model, SENS, d, t + h + tau, yn, ss, modes, v0s, work)
            for i in range(n_tan):
                S1[d, i] += h * RK_A[6, st] * (work[i] - KS[d, st, i])
                KS[d, st, i] = work[i]
        moved = True


@tangent_helper
def clamp_event(model, SENS, pair, post_clamped, t, y, f, h_step, modes, v0s, n_dof2, KS, yn, work):
    """The tangents at a located kink of the force of ``pair`` at (t, y), ``f`` = dy/dt
    there: carried to the kink on the old side's field and back on the new one's (as
    :func:`surface_event` for an onset or exit; no jump: the field is continuous), and the
    first stage of the next step (KS[:, 0], (1) at t) read on the new side
    (``post_clamped``), which the state at t may miss (:func:`clamp_step_end`): read on
    the old one, it weighs b1 = 35/384 in the next step (and E1 in its error estimate).

    The kink lies dt_k = -(F_k + F_c) / (dF/dt) from t (a shift not small against the
    step to the kink, ``h_step``, is not made), so, with J- s = KS[:, 6] (the old side's
    field at the step's end, S = S1),

        s += dt_k (J- s) - dt_k (J+ s).

    ``yn``: n_dof2 of work space, ``work``: as long as a tangent."""
    mode = modes[pair]
    v0 = v0s[pair]
    fsum, fdot, _ = clamp_force_rate(model, pair, t, y, f, mode, v0)
    dtk = 0.0
    if abs(fdot) > 0.0 and math.isfinite(fdot):
        dtk = -fsum / fdot
        if not abs(dtk) <= 0.5 * h_step:
            dtk = 0.0
    tau = clamp_side(model, pair, mode, v0, post_clamped, t, y, f, n_dof2, yn)
    if not math.isfinite(tau):
        tau = 0.0
    for d in range(SENS.S.shape[0]):
        s = SENS.S[d]
        if dtk != 0.0:
            for i in range(s.shape[0]):
                s[i] += dtk * KS[d, 6, i]
            tangent_rhs(model, SENS, d, t + tau, yn, s, modes, v0s, work)
            for i in range(s.shape[0]):
                s[i] -= dtk * work[i]
        tangent_rhs(model, SENS, d, t + tau, yn, s, modes, v0s, KS[d, 0])


@tangent_helper
def start_on_wall_fixed(model, SENS, t, y, modes, npair):
    """False where a contact opened at a new run's start with the body exactly on its wall
    (no overlap, moving into it) has its gap moved by some direction (its tangent above the
    direction's absolute tolerance plus 1e-9 of the largest tangent of its kind, as in
    :func:`contact_event`). Such a contact has no derivative along that direction: a wider
    gap starts the contact later, at t + gap / speed (an onset time whose derivative is
    1 / speed), a narrower one overlaps at the start, a contact released elastically (v0 =
    inf, ``initial_impact_velocity`` aside) instead of one latched at the approach speed.
    A direction that moves only the approach rate keeps the start on the wall."""
    for pair in range(npair):
        mode = modes[pair]
        if mode == 0:
            continue
        g_in, g_out, _ = gaps(model, pair, t, y)
        if (g_in if mode < 0 else g_out) != 0.0:
            continue  # an overlap: it stays one under a small change
        for d in range(SENS.S.shape[0]):
            dg_in, dg_out, _ = pair_gaps_jvp(model, SENS.tangents[d], pair, t, y, SENS.S[d])
            dg = dg_in if mode < 0 else dg_out
            if abs(dg) > SENS.ATOL[d, 0] + 1e-9 * SENS.SMAX[d, 0]:
                return False
    return True


@tangent_helper
def start_contact(model, SENS, pair, t, y, mode, ie, initial, itr, f_free):
    """Tangents of the latched speed (and of the episode's first values) of a contact the
    start policy opens at t: at the start of a run (``itr`` = -1), or right after the
    transfer ``itr``, whose time moves by dtau = ``SENS.DTR[d, itr]`` along direction d.

    Such a contact starts at the transfer: its onset time's derivative is dtau, and its
    approach speed, read on the flow ``f_free`` that follows the transfer before the
    contact starts, changes by its fixed-time tangent plus its rate times dtau, as at an
    onset (:func:`contact_event`).
    """
    g_in, g_out, rate = gaps(model, pair, t, y)
    _, pd = penetration(mode, g_in, g_out, rate)
    with_tau = itr >= 0 and itr < SENS.DTR.shape[1]
    pen_acc = 0.0
    if with_tau:
        acc_in = pair_gap_accel(model, pair, t, f_free)
        pen_acc = -acc_in if mode < 0 else acc_in
    for d in range(SENS.S.shape[0]):
        dm = SENS.tangents[d]
        dtau = SENS.DTR[d, itr] if with_tau else 0.0
        dg_in, dg_out, drate = pair_gaps_jvp(model, dm, pair, t, y, SENS.S[d])
        _, dpd = penetration_jvp(mode, dg_in, dg_out, drate)
        dvel = dpd + pen_acc * dtau if dtau != 0.0 else dpd
        if initial:
            vi = model.initial_impact_velocity
            SENS.DV0[d, pair] = dm.initial_impact_velocity if vi > 0.0 else 0.0
        else:
            SENS.DV0[d, pair] = dvel if pd > model.min_impact_velocity else dm.min_impact_velocity
        if ie >= 0:
            SENS.ESENS[ie, d, ES_T] = dtau
            SENS.ESENS[ie, d, ES_VELOCITY] = dvel
            k = SENS.n_dof2 + pair
            if k < SENS.S.shape[1]:
                # (6) at an onset that moves with the transfer (on its free flow, before the
                # contact's jump: transfer_contacts)
                SENS.ESENS[ie, d, ES_DISS] = SENS.S[d, k] + f_free[k] * dtau


@tangent_helper
def transfer_cut(SENS, itr, ie, pair, f_minus):
    """The end time of episode ``ie`` of ``pair``, cut by the transfer ``itr``, moves with
    it, and so does its dissipated energy (6), on the flow ``f_minus`` before the transfer
    (the tangents not yet jumped)."""
    k = SENS.n_dof2 + pair
    for d in range(SENS.S.shape[0]):
        dtau = SENS.DTR[d, itr] if itr < SENS.DTR.shape[1] else 0.0
        if itr < SENS.DTR.shape[1]:
            SENS.ESENS[ie, d, ES_T_END] = dtau
        if k < SENS.S.shape[1]:
            d_at = SENS.S[d, k] + f_minus[k] * dtau
            SENS.ESENS[ie, d, ES_DISS] = d_at - SENS.ESENS[ie, d, ES_DISS]


@tangent_helper
def transfer_contacts(SENS, itr, f_free, f_after, n_dof2):
    """At the transfer ``itr`` the contacts it starts change the flow from ``f_free`` to
    ``f_after`` at an instant that moves by dtau: the tangents jump by (f_free - f_after)
    dtau, as at an onset (2) (nothing where the new contacts start without a force)."""
    if itr >= SENS.DTR.shape[1]:
        return
    for d in range(SENS.S.shape[0]):
        dtau = SENS.DTR[d, itr]
        s = SENS.S[d]
        for i in range(s.shape[0]):
            s[i] += (f_free[i] - f_after[i]) * dtau


@tangent_helper
def new_episode_row(SENS, ie):
    """Clear the tangents of a new impact-table row (NaN: not defined yet)."""
    for d in range(SENS.S.shape[0]):
        for q in range(SENS.ESENS.shape[2]):
            SENS.ESENS[ie, d, q] = math.nan


@tangent_helper
def transfer_jump(model, SENS, itr, t, y_minus, f_minus, f_plus, n_dof2, v, out):
    """(5) for every direction at the transfer ``itr`` at time t (state before it
    ``y_minus``); ``v``, ``out``: work space."""
    for d in range(SENS.S.shape[0]):
        dtau = SENS.DTR[d, itr] if itr < SENS.DTR.shape[1] else 0.0
        s = SENS.S[d]
        for i in range(n_dof2):
            v[i] = s[i] + f_minus[i] * dtau
        apply_transfer_jvp(model, SENS.tangents[d], t, y_minus, v, dtau, out)
        for i in range(n_dof2):
            s[i] = out[i] - f_plus[i] * dtau
        # (the dissipations are left as they are by the transfer map)
        for i in range(n_dof2, s.shape[0]):
            s[i] += (f_minus[i] - f_plus[i]) * dtau


@tangent_helper
def series_tangent_row(model, SENS, R, r, t, y, s_all, modes, v0s, n_pairs, work):
    """Tangents of the series row r (:data:`~braidsim.core.layout.SERIES_SENS_FIELDS`) at
    time t, state y, tangents s_all[d], into ``R`` (``SENS.RSENS``; None: nothing)."""
    if R is None:
        return
    n_coords, _, _ = model_size(model)
    for d in range(SENS.S.shape[0]):
        s = s_all[d]
        tangent_rhs(model, SENS, d, t, y, s, modes, v0s, work)
        R[r, d, 0] = s[0]
        R[r, d, 1] = s[1]
        R[r, d, 4] = work[1]
        if n_coords == 2:
            R[r, d, 2] = s[2]
            R[r, d, 3] = s[3]
            R[r, d, 5] = work[3]
        else:
            R[r, d, 2] = 0.0
            R[r, d, 3] = 0.0
            R[r, d, 5] = 0.0
        for pair in range(2):
            dn = 0.0
            if pair < n_pairs and modes[pair] != 0:
                _, _, dn = pair_tangent(
                    model,
                    SENS.tangents[d],
                    pair,
                    t,
                    y,
                    s,
                    modes[pair],
                    v0s[pair],
                    SENS.DV0[d, pair],
                )
                dn *= float(modes[pair])
            R[r, d, 6 + pair] = dn


@tangent_helper
def step_series_tangents(
    model, SENS, R, rows, r0, r1, t0, h, RC, RCS, n, n_dof2, modes, v0s, n_pairs, yq, SQ, work
):
    """Tangents of the series rows r0..r1-1 that a step [t0, t0 + h] wrote (samples and
    peaks inside it), from the continuous extensions of the state and the tangents."""
    if R is None:
        return
    for r in range(r0, r1):
        tr = rows[r, 0]
        theta = (tr - t0) / h
        dense_eval(theta, RC, yq, n)
        for d in range(SENS.S.shape[0]):
            tangent_dense_eval(theta, RCS, d, SQ[d], n_dof2)
        series_tangent_row(model, SENS, R, r, tr, yq, SQ, modes, v0s, n_pairs, work)


@tangent_helper
def arrays_fit(SENS, R, rows, n, n_dof2, n_pairs, n_episodes):
    """Whether the tangent arrays match the run's state (the coordinates and speeds, and
    the dissipations where the state has them), impact table and series buffer."""
    k = SENS.S.shape[0]
    n_tan = SENS.S.shape[1]
    if SENS.n_dof2 != n_dof2 or not (n_tan == n_dof2 or (n_tan == n_dof2 + n_pairs and n >= n_tan)):
        return False
    if SENS.DV0.shape[0] != k or SENS.ESENS.shape[0] != n_episodes:
        return False
    if R is None:
        return True
    return rows is not None and R.shape[0] == rows.shape[0]
