"""The step loop: Dormand-Prince 5(4) with PI step control, contact events located on the
interpolant, the step recomputed exactly to each event, and the contact state machine.

:func:`integrate` runs one model from the restart record ``RS`` to ``opts.t_end``, or until
the series buffer or the impact table needs flushing: it then returns with every counter
and the step controller's memory in ``RS`` and the state in ``y``, and the next call goes
on with the same bits as an uninterrupted run (:mod:`braidsim.core.driver` drives it).
"""

from __future__ import annotations

import math

import numpy as np

from braidsim.core.generic import by_ref, cached_njit, helper
from braidsim.core.interfaces import (
    apply_transfer,
    dissipation_index,
    model_series_reach,
    model_size,
    pair_onset_step,
)
from braidsim.core.layout import (
    END_EXIT,
    END_TRANSFER,
    ES_DISS,
    ES_T,
    KIND_END,
    KIND_EXIT,
    KIND_ONSET,
    KIND_SAMPLE,
    KIND_START,
    KIND_TRANSFER,
    NEW_RUN,
    ST_BAD_ARRAYS,
    ST_EPISODES_FULL,
    ST_GRAZING,
    ST_MAX_STEPS,
    ST_NONFINITE,
    ST_OK,
    ST_ROWS_FULL,
    ST_STEP_COLLAPSE,
    ST_STIFF,
    ST_ZENO,
    STARTED,
    STIFF_LIMIT,
    STIFF_STEP_FRACTION,
)
from braidsim.core.solver.calls import rhs
from braidsim.core.solver.dense import dense_eval, step_output
from braidsim.core.solver.dopri5 import (
    dense_coeffs,
    error_norm,
    onset_error_ratio,
    quadrature_error,
    rk_step,
)
from braidsim.core.solver.events import (
    CLAMP0,
    N_EVENTS,
    N_SUB,
    clamp_pending,
    clamp_state,
    first_event,
    locate_clamp,
    locate_event,
    sample_events,
    sample_events_call,
)
from braidsim.core.solver.pairs import I_DN, I_FC, I_FK, I_P, I_PD, NI, gaps, pair_infos
from braidsim.core.solver.radau import (
    ATTEMPT_OK,
    implicit_attempt,
    implicit_to,
    keep_polynomial,
    radau_safety,
)
from braidsim.core.solver.recorders import (
    close_episode,
    episode_start_values,
    open_episode,
    scan_step,
    update_ranges,
    write_row,
)
from braidsim.core.solver.tangent import (
    arrays_fit,
    clamp_event,
    clamp_step_end,
    dissipation_tangent_error,
    episode_extremes,
    new_episode_row,
    onset_correction,
    series_tangent_row,
    start_contact,
    start_on_wall_fixed,
    step_series_tangents,
    surface_event,
    tangent_dense_coeffs,
    tangent_dense_eval,
    tangent_error,
    tangent_scales,
    tangent_start,
    tangent_step,
    transfer_contacts,
    transfer_cut,
    transfer_jump,
)
from braidsim.core.solver.taylor import (
    RETEST,
    depth_root_reach,
    onset_step,
    taylor_coefficients,
    taylor_dense,
    taylor_shorten,
    taylor_step_size,
)

ONSET_RK_FRACTION = 0.25  # the Runge-Kutta step after an onset step, as its fraction
# the Runge-Kutta step carried over a Taylor step is at least this fraction of it
RK_CARRY = 1e-6
# a step below COLLAPSE max(COLLAPSE_T, |t|) has collapsed: 14 rounding units of t, and of
# 1 ns near t = 0, where a contact that starts from rest takes steps of femtoseconds first
COLLAPSE = 8 * 4e-16
COLLAPSE_T = 1e-9
EPISODE_RESERVE = 4  # impact-table rows one step can open at most
EVENT_ROWS = 16  # series rows one step writes at most besides its samples
# the controller's memory of the last error is at least 1e-4 (DOPRI5's floor); its log, as
# libm gives it at run time after a restart (math.log(1e-4)), so that a step with a smaller
# error (every Taylor step, whose error is 0) takes no log for it
ERR_FLOOR = 1e-4
LOG_ERR_FLOOR = math.log(ERR_FLOOR)
# A contact rests when its fast mode holds the explicit step: h |lambda| (estimated from the
# last two stages) above REST_HLAMBDA for REST_AFTER accepted steps in a row. An impact's
# steps resolve its bounce at h |lambda| ~ 0.1; a resting contact's sit at 1-1.6 whatever
# the tolerance (benchmarks/README.md).
# The implicit step costs about 15 evaluations against the explicit one's 6. Its steps after
# the first REST_RAMP (which grow from the explicit size) are counted; from REST_TRIAL steps
# on, should they have bought less simulated time per evaluation than the explicit method's
# next step would have, the contact goes back to the explicit method until its next event.
REST_HLAMBDA = 1.0
REST_AFTER = 8
REST_RAMP = 3
REST_TRIAL = 6


@helper
def _transfer(model, t, y):
    """:func:`~braidsim.core.interfaces.apply_transfer` as a call (rare: not inlined)."""
    return apply_transfer(model, t, y)


@helper(always_inline=True)  # (called at every step: see core.generic.helper)
def _dense_at(theta, RCs, out, n):
    """:func:`~braidsim.core.solver.dense.dense_eval` as a call (inlined into the loop, whose
    variables numba reference-counts, it cost an atomic increment and decrement of each
    array of the dense output at every step)."""
    dense_eval(theta, RCs, out, n)


@helper
def _onset_step(model, pair, v0):
    """:func:`~braidsim.core.interfaces.pair_onset_step` as a call (once per contact)."""
    return pair_onset_step(model, pair, v0)


# Calls of integrate that keep numba's reference counting (unlike the helpers of
# braidsim.core.generic: _open and _start_contacts reach the tangents' records), compiled to
# be called from compiled code only, without the Python and C-callback wrappers of a function
# callable from Python (numba's type stubs do not list these switches)
# (cached by the sources their code holds: core.generic.cached_njit)
_OPTIONS = {"error_model": "numpy", "no_cfunc_wrapper": True}
_solver_call = cached_njit(no_cpython_wrapper=True, **_OPTIONS)
# integrate itself: called from Python, never through a C callback
_entry_point = cached_njit(nogil=True, **_OPTIONS)


@_solver_call
def _energy(y, idx, n):
    """The dissipated-energy quadrature at ``idx`` (NaN when the run does not integrate it)."""
    return y[idx] if idx < n else math.nan


@_solver_call
def _open(model, EP, nep, t, y, pair, mode, vel, v0, initial, n, open_ep, SENS):
    """Open row ``nep`` of the impact table for a contact of ``pair`` starting at t (approach
    speed ``vel``, latched ``v0``) and fold its first values in; returns the new row count."""
    open_ep[pair] = nep
    e0 = _energy(y, dissipation_index(model, pair), n)
    if SENS is not None:
        new_episode_row(SENS, nep)
    nep = open_episode(EP, nep, t, pair, mode, vel, v0, initial, e0)
    # a contact present at the start may have its largest force there, and a law whose
    # force jumps at onset (a dashpot) has its first extremes there
    episode_start_values(model, EP, nep - 1, t, y, pair, mode, v0)
    return nep


@_solver_call
def _start_contacts(model, t, y, modes, v0s, open_ep, EP, nep, npair, n, SENS, itr, f_free):
    """The contact policy at the start (``itr`` = -1) and right after the transfer ``itr``
    (``f_free``: dy/dt after it, before the contacts start; read for the tangents only), for
    the first ``npair`` pairs.

    A pair whose carrier overlaps a wall starts in contact. Such a contact has no approach
    speed: it is released elastically (v0 = inf, no damping term until the next onset) unless
    the model's ``initial_impact_velocity`` gives a speed. A body exactly on a wall and moving
    into it starts in contact with its approach rate latched (floored at the model's
    ``min_impact_velocity``), as after a transfer.
    """
    for pair in range(npair):
        g_in, g_out, rate = gaps(model, pair, t, y)
        mode = 0
        p = 0.0
        pd = 0.0
        if g_in < 0.0 or (g_in == 0.0 and rate < 0.0):
            mode = -1
            p = -g_in
            pd = -rate
        elif g_out < 0.0 or (g_out == 0.0 and rate > 0.0):
            mode = 1
            p = -g_out
            pd = rate
        if mode == 0:
            modes[pair] = 0
            continue
        if p > 0.0:
            vi = model.initial_impact_velocity
            v0 = vi if vi > 0.0 else math.inf
        else:
            vmin = model.min_impact_velocity
            v0 = pd if pd > vmin else vmin
        modes[pair] = mode
        v0s[pair] = v0
        initial = 1.0 if p > 0.0 else 0.0
        nep = _open(model, EP, nep, t, y, pair, mode, pd, v0, initial, n, open_ep, SENS)
        if SENS is not None:
            start_contact(model, SENS, pair, t, y, mode, nep - 1, p > 0.0, itr, f_free)
    return nep


# nogil: the loop touches no Python object, so runs of a batch overlap on threads
@_entry_point
def integrate(
    record, opts, y, RS, ST, TR, WIN, rows, row_reserve, EP, RANGES, XSQ, STATS, SENS, IMP, TAY
):
    """Integrate the model ``record`` from the restart record to ``opts.t_end``; returns a
    status.

    Parameters
    ----------
    record : model record
        A model of :mod:`braidsim.core.models`. The functions called here read it through a
        :class:`~braidsim.core.generic.RecordRef` (one pointer, not one argument per field).
    opts : SolverOptions
    y : array
        The state (length 2 n_coords, plus with ``opts.energy`` the first
        ``opts.quadratures`` of the n_quads quadratures, all for -1); in and out.
    RS : array of RESTART_DTYPE, shape (1,)
        Where the run stands; in and out (:func:`braidsim.core.layout.new_restart`).
    ST, TR : arrays
        Sample times and transfer times [s], increasing.
    WIN : array (n_windows, 2)
        Windows of the ranges and of the x^2 integrals.
    rows : array (capacity, n_columns) or None
        Series buffer (the model's :func:`~braidsim.core.interfaces.series_columns`);
        ``None`` records no series.
    row_reserve : int
        Rows one step may write (its samples plus EVENT_ROWS): the run returns ST_ROWS_FULL
        before a step when fewer are free.
    EP : array of EPISODE_DTYPE
        The impact table; ST_EPISODES_FULL before a step when fewer than EPISODE_RESERVE rows
        are free.
    RANGES : array (n_windows, 2, 4, 2)
        Window extremes, accumulated (initialised by the caller to +inf / -inf).
    XSQ : array (n_windows,) or None
        int x^2 dt over each window, accumulated.
    STATS : array of STATS_DTYPE, shape (1,)
        Run statistics, accumulated.
    SENS : SensitivityWork or None
        Forward sensitivities to carry (:mod:`braidsim.core.solver.tangent`); ``None``
        compiles them out.
    IMP : ImplicitWork or None
        The work arrays of the implicit step of resting contacts
        (:mod:`braidsim.core.solver.radau`); ``None`` compiles it out (Dormand-Prince
        throughout).
    TAY : TaylorWork or None
        The work arrays of the Taylor-series step (:mod:`braidsim.core.solver.taylor`),
        taken where it is longer than the Runge-Kutta step; ``None`` compiles it out. The
        model must give its series (:func:`~braidsim.core.interfaces.model_series`).
    """
    # every function below reads the model through one pointer: numba would pass the
    # record to each call field by field, ~65 values for the carrier (see RecordRef)
    model = by_ref(record)
    n_coords, n_pairs, n_quads = model_size(model)
    n_dof2 = 2 * n_coords
    n = n_dof2
    if opts.energy:
        # a prefix of the quadratures (the dissipations, then the friction works, come first)
        n += n_quads if opts.quadratures < 0 else min(opts.quadratures, n_quads)
    if (
        y.shape[0] != n
        or WIN.shape[0] != RANGES.shape[0]
        or (XSQ is not None and XSQ.shape[0] != WIN.shape[0])
        or EP.shape[0] < EPISODE_RESERVE
        or (rows is not None and rows.shape[0] < row_reserve)
    ):
        return ST_BAD_ARRAYS
    rec = opts.record_events
    t_end = opts.t_end
    hmax = opts.max_step
    stiff_below = STIFF_STEP_FRACTION * hmax
    st = STATS[0]
    r = RS[0]
    # (the work arrays by np.empty alone, filled where they must start filled: each other
    # constructor is one more function numba compiles)
    y1 = np.empty(n)
    yt = np.empty(n)
    ys = np.empty(n)
    yd = np.empty(n)
    ye = np.empty(n)
    INF0 = np.empty((2, NI))  # pair summaries at the start of the step (the end of the last)
    INF1 = np.empty((2, NI))  # ... at its end
    IX = np.empty(NI)
    for i in range(NI):
        INF0[0, i] = INF0[1, i] = INF1[0, i] = INF1[1, i] = IX[i] = 0.0
    K = np.empty((7, n))
    Ke = np.empty((7, n))
    jac_fresh = False  # the implicit step's Jacobian belongs to the current (t, y)
    newton_iters = 0
    RC = np.empty((5, n))
    GS = np.empty((N_EVENTS, N_SUB + 1))
    if SENS is not None:
        nsens = SENS.S.shape[0]
        # a tangent: the coordinates and speeds (n_dof2), then the dissipations where the
        # run integrates them (tangent.py); the dense output and the stage states need the
        # first part only
        n_tan = SENS.S.shape[1]
        # (NaN where a model's derivatives_jvp would not write the dissipations' tangents:
        # their impacts' derivatives then come out NaN, not from uninitialised memory)
        KS = np.full((nsens, 7, n_tan), np.nan)
        RCS = np.empty((nsens, 5, n_dof2))
        S1 = np.empty((nsens, n_tan))
        SQ = np.empty((nsens, n_dof2))  # tangents at an instant inside a step
        ss = np.full(n_tan, np.nan)
        YS = np.empty((7, n_dof2))  # stage states of a step, for the tangents
        sw = np.full(n_tan, np.nan)
        f_minus = np.empty(n)
        y_minus = np.empty(n)
        prev_depth_t = np.zeros(2)
        prev_peak_t = np.zeros(2)
        ev_modes = np.empty(2, dtype=np.int64)  # (the contact modes before an event)
        yc = np.empty(n)  # the state on the wall at an event, and the fields there
        fm = np.empty(n)
        fp = np.empty(n)
        if not arrays_fit(SENS, SENS.RSENS, rows, n, n_dof2, n_pairs, EP.shape[0]):
            return ST_BAD_ARRAYS
    modes = np.empty(2, dtype=np.int64)  # (all three set from the restart record below)
    v0s = np.empty(2)
    open_ep = np.empty(2, dtype=np.int64)
    modes[0] = int(r.mode_0)
    modes[1] = int(r.mode_1)
    v0s[0] = r.v0_0
    v0s[1] = r.v0_1
    open_ep[0] = int(r.open_0)
    open_ep[1] = int(r.open_1)
    # whether each contact force is held at its clamp (events.clamp_crossing; -1: read from
    # the force's sign once the pair summaries are known, below)
    clamped = np.empty(2, dtype=np.int64)
    clamped[0] = int(r.clamped_0)
    clamped[1] = int(r.clamped_1)
    nrow = int(r.rows)
    nep = int(r.episodes)
    isamp = int(r.next_sample)
    itr = int(r.next_transfer)
    t = r.t
    # a new run's start time: a contact that starts within a picosecond of it, from rest on
    # its wall, started with the run (tangent.contact_event); -inf in a continued call
    t_begin = -math.inf
    start_on_wall = False  # a start on a wall whose gap a direction moves: no derivative
    if r.started != STARTED:
        if r.started == NEW_RUN:
            t_begin = t
            if SENS is not None:
                # (before the start's contacts, which read these scales and leave S alone)
                tangent_scales(SENS.S, n_dof2, SENS.SMAX)
            nep = _start_contacts(
                model, t, y, modes, v0s, open_ep, EP, nep, n_pairs, n, SENS, -1, K[0]
            )
            # a first step of 1 us (the shortest contacts last ~0.1 ms), which the controller
            # grows by up to 5x a step: a few cheap steps, and no start-step heuristic whose
            # trial evaluations would have to be made contact-aware
            r.h = min(1e-6, hmax, t_end - t)
            if SENS is not None and not start_on_wall_fixed(model, SENS, t, y, modes, n_pairs):
                start_on_wall = True
        else:
            # a continuation (CONTINUED): the contacts carried over open new episodes; a
            # step of 0 means "choose one", as for a new run
            if not r.h > 0.0:
                r.h = min(1e-6, hmax, t_end - t)
            for pair in range(n_pairs):
                open_ep[pair] = -1
                if modes[pair] != 0:
                    mode = modes[pair]
                    nep = _open(
                        model, EP, nep, t, y, pair, mode, math.nan, v0s[pair], 1.0, n, open_ep, SENS
                    )
                    if SENS is not None:
                        for d in range(nsens):
                            SENS.ESENS[nep - 1, d, ES_T] = 0.0
                            if n_dof2 + pair < n_tan:  # (D from this run's start)
                                SENS.ESENS[nep - 1, d, ES_DISS] = SENS.S[d, n_dof2 + pair]
        if SENS is not None:
            for pair in range(n_pairs):
                ie = open_ep[pair]
                if ie >= 0:
                    episode_extremes(model, SENS, ie, pair, t, y, SENS.S, modes[pair], v0s[pair], 3)
        nrow0 = nrow
        nrow = write_row(model, rows, nrow, t, y, modes, v0s, n, KIND_START, rec)
        if SENS is not None and nrow > nrow0:
            series_tangent_row(
                model, SENS, SENS.RSENS, nrow0, t, y, SENS.S, modes, v0s, n_pairs, sw
            )
        update_ranges(model, n_pairs, t, y, modes, v0s, WIN, RANGES)
        while isamp < ST.shape[0] and ST[isamp] <= t:
            if ST[isamp] == t:
                nrow0 = nrow
                nrow = write_row(model, rows, nrow, t, y, modes, v0s, n, KIND_SAMPLE, rec)
                if SENS is not None and nrow > nrow0:
                    series_tangent_row(
                        model, SENS, SENS.RSENS, nrow0, t, y, SENS.S, modes, v0s, n_pairs, sw
                    )
            isamp += 1
        # a new run makes no transfer at its start time; a continued one does (the run it
        # continues stopped there before making it), in the loop below
        while itr < TR.shape[0] and (TR[itr] < t or (TR[itr] == t and r.started == NEW_RUN)):
            itr += 1
        r.started = STARTED
    h = r.h
    nsteps = int(r.steps)
    same_time_events = int(r.same_time_events)
    last_event_t = r.last_event_t
    stiff_run = int(r.stiff_run)
    nonstiff_run = int(r.nonstiff_run)
    err_old = r.err_old
    lerr_old = math.log(err_old)  # (the controller works on logarithms: one log, one exp)
    # (the implicit step's own state stays in the restart record and is read there: seven
    # more values live across the loop made every step of a run without it 5-8 % slower)
    # error exponent of the first step of a contact: the force grows as s^n after onset, so
    # that step's error scales as h^(n+1), not h^5 (0: no contact step pending)
    onset_q = r.onset_q
    onset_pair = int(r.onset_pair)  # the pair whose contact that step starts
    tols = (opts.rtol, opts.atol_position, opts.atol_velocity)
    force_rk = False  # a Taylor step was refused after the fact: a Runge-Kutta step next
    h_rk = h
    err_old_rk = err_old
    lerr_old_rk = lerr_old

    # the rows of the stages the loop hands to calls, and the step's dense output, made once:
    # a view or a record of arrays made in the loop costs numba's reference counting (an
    # atomic increment and decrement) at every step
    K0 = K[0]
    K6 = K[6]
    Ke6 = Ke[6]
    RCs = step_output(RC, TAY)
    if TAY is not None:
        TC, TW, TRT, TRS, TKIND = TAY.C, TAY.W, TAY.RT, TAY.RS, TAY.kind
    else:  # (never read: every use is under TAY is not None)
        TC, TW, TRT, TRS, TKIND = RC, RC, RC, RC, modes

    rhs(model, t, y, modes, v0s, n, K0)
    pair_infos(model, n_pairs, t, y, K0, modes, v0s, INF0)
    st.rhs_evaluations += 1
    for pair in range(2):  # (a pair the model lacks: its summary is zeros, never clamped)
        if clamped[pair] < 0:
            clamped[pair] = clamp_state(INF0, pair)
    if SENS is not None:
        tangent_start(model, SENS, t, y, modes, v0s, KS)
    status = ST_GRAZING if start_on_wall else ST_OK
    h_cut = 0.0
    while t < t_end and status == ST_OK:
        # room for what one step writes, else hand the buffers back to be flushed
        if rows is not None and nrow > rows.shape[0] - row_reserve:
            status = ST_ROWS_FULL
            break
        if nep > EP.shape[0] - EPISODE_RESERVE:
            status = ST_EPISODES_FULL
            break
        if nsteps >= opts.max_steps:
            status = ST_MAX_STEPS
            break
        while itr < TR.shape[0] and TR[itr] <= t:
            # a transfer: the state jumps and the contacts of the pairs it moves start anew
            itr += 1
            st.transfers += 1
            if SENS is not None:
                for i in range(n):
                    y_minus[i] = y[i]
                for i in range(n_tan):
                    f_minus[i] = K[0, i]
            reset = _transfer(model, t, y)
            if IMP is not None:
                r.implicit = 0  # the implicit phase ends with the contacts the transfer moves
                r.rest_run = 0
                r.rest_blocked = 0
                jac_fresh = False
            for pair in range(reset):
                ie = open_ep[pair]
                if ie >= 0:
                    close_episode(
                        EP,
                        ie,
                        t,
                        math.nan,
                        _energy(y, dissipation_index(model, pair), n),
                        END_TRANSFER,
                    )
                    if SENS is not None:
                        transfer_cut(SENS, itr - 1, ie, pair, f_minus)
                    open_ep[pair] = -1
                modes[pair] = 0
            nrow_tr = nrow
            nrow = write_row(model, rows, nrow, t, y, modes, v0s, n, KIND_TRANSFER, rec)
            if SENS is not None:
                # the tangents jump with the state (the new contacts need them)
                rhs(model, t, y, modes, v0s, n, K0)
                transfer_jump(model, SENS, itr - 1, t, y_minus, f_minus, K0, n_dof2, ss, sw)
                for i in range(n_tan):
                    f_minus[i] = K0[i]  # the flow after the transfer, before its contacts
            nep = _start_contacts(
                model, t, y, modes, v0s, open_ep, EP, nep, reset, n, SENS, itr - 1, K0
            )
            rhs(model, t, y, modes, v0s, n, K0)
            pair_infos(model, n_pairs, t, y, K0, modes, v0s, INF0)
            st.rhs_evaluations += 1
            for pair in range(reset):
                clamped[pair] = clamp_state(INF0, pair)
            if SENS is not None:
                transfer_contacts(SENS, itr - 1, f_minus, K0, n_dof2)
                for pair in range(reset):
                    ie = open_ep[pair]
                    if ie >= 0:
                        # extremes at the contact's first instant, which moves with the
                        # transfer (its onset time's tangent)
                        episode_extremes(
                            model, SENS, ie, pair, t, y, SENS.S, modes[pair], v0s[pair], 3
                        )
                        onset_correction(SENS, ie, 3, INF0[pair, I_PD], INF0[pair, I_DN])
                tangent_start(model, SENS, t, y, modes, v0s, KS)
                if nrow > nrow_tr:
                    series_tangent_row(
                        model, SENS, SENS.RSENS, nrow_tr, t, y, SENS.S, modes, v0s, n_pairs, sw
                    )
        t_stop = t_end
        if itr < TR.shape[0] and TR[itr] < t_stop:
            t_stop = TR[itr]
        hits_stop = False
        h_cut = 0.0
        if h >= (t_stop - t) * (1.0 - 1e-9):
            # reach the stop exactly (and never leave a sliver too small to step over)
            if t_stop == t_end:
                h_cut = h  # (the step the control wanted: where a continuation starts)
            h = t_stop - t
            hits_stop = True
        # (with Taylor steps h is here the Runge-Kutta step carried over them: the step taken
        # is checked below, once it is known)
        if TAY is None:
            if not hits_stop and h < COLLAPSE * max(COLLAPSE_T, abs(t)):
                status = ST_STEP_COLLAPSE
                break
        # (without IMP the step is written as if there were no implicit step at all: any
        # test around the explicit step, even one the compiler can fold, made every step of
        # paper-3.3 4-8 % slower)
        took_implicit = False
        took_taylor = False
        series_order = 0  # (> 0: a Taylor step of that order, its series in TW)
        if TAY is not None:
            # the step's dense output (RCs, braidsim.core.solver.dense) is the Runge-Kutta
            # interpolant unless a Taylor step is taken below
            TKIND[0] = 0
            # the first step of a contact: the onset step in s = sqrt(t - t_onset) where the
            # model has its series (compiled out where it has none: taylor.onset_step)
            if onset_q > 0.0 and onset_pair >= 0 and not force_rk:
                if INF0[onset_pair, I_PD] > 0.0:
                    ho = onset_step(
                        model,
                        t,
                        y,
                        onset_pair,
                        modes,
                        v0s,
                        n,
                        n_dof2,
                        tols,
                        min(hmax, t_stop - t),
                        t_stop - t,
                        TAY,
                    )
                    if ho > 0.0:
                        took_taylor = True
                        # the Runge-Kutta step carried: a quarter of the distance to the
                        # onset's branch point at the step's end (where a Dormand-Prince step
                        # passes its error test, measured on paper-3.3), not the onset's
                        # guess, which the Taylor steps would then have to beat
                        h_rk = min(h, ONSET_RK_FRACTION * ho)
                        err_old_rk = err_old
                        lerr_old_rk = lerr_old
                        h = ho
                        hits_stop = h >= (t_stop - t) * (1.0 - 1e-9)
                        if hits_stop:
                            h = t_stop - t
                        TKIND[0] = 2
            # the Taylor step where it is at least the Runge-Kutta step (module docstring
            # of taylor.py); not in the first step of a contact (the force's series does not
            # exist at p = 0), nor where a contact force is held at 0 by its clamp
            try_taylor = onset_q == 0.0 and not force_rk and not took_taylor
            if IMP is not None:
                if r.implicit:
                    try_taylor = False
            if r.taylor_wait > 0.0:
                try_taylor = False
                r.taylor_wait -= 1.0
            for pair in range(n_pairs):
                if modes[pair] != 0 and not (
                    INF0[pair, I_P] > 0.0 and INF0[pair, I_FK] + INF0[pair, I_FC] >= 0.0
                ):
                    try_taylor = False
            force_rk = False
            if try_taylor:
                hstop = min(hmax, t_stop - t)
                horizon, used = taylor_coefficients(
                    model, t, y, modes, v0s, n, TC, TW, n_dof2, tols, hstop
                )
                ht = taylor_step_size(
                    TC, used, n_dof2, opts.rtol, opts.atol_position, opts.atol_velocity, hstop
                )
                if ht > horizon:
                    ht = horizon  # (a piecewise motion: to the end of its piece)
                # (and not past where a saturating law's series stops showing its change)
                ht = model_series_reach(model, TC, ht)
                # no Taylor step that would reach a contact's depth returning towards 0
                # (taylor.depth_root_reach): the Runge-Kutta step passes such a turn as any
                # other, where Taylor steps bounded short of it crept towards it until they
                # collapsed
                near_return = depth_root_reach(model, n_pairs, modes, TW, ht) < ht
                if ht >= h and not near_return:
                    took_taylor = True
                    # the Runge-Kutta step and its controller's memory are carried over the
                    # Taylor steps; the step no shorter than RK_CARRY of the Taylor step, where
                    # it never binds but after an onset from rest (its branch point a few
                    # femtoseconds away, the step proposed there would otherwise be carried
                    # through a resting contact of any length)
                    h_rk = max(h, RK_CARRY * ht)
                    err_old_rk = err_old
                    lerr_old_rk = lerr_old
                    h = ht
                    hits_stop = False
                    if h >= (t_stop - t) * (1.0 - 1e-9):
                        h = t_stop - t
                        hits_stop = True
                    taylor_dense(TC, h, n, TRT)
                    TKIND[0] = 1
                    series_order = used
                else:
                    # near a singularity: the Runge-Kutta steps from here on, starting no
                    # longer than the series' own step (the distance to the singularity
                    # bounds both; a step carried from elsewhere may cross it, as an exit,
                    # in one step whose error estimate misses the p^n there)
                    r.taylor_wait = RETEST - 1.0
                    if ht < h:
                        h = ht
                        hits_stop = False
            if took_taylor:
                # the end of a series step (onset or Taylor): the state from its polynomial
                # and f there; no error estimate, no rejection
                _dense_at(1.0, RCs, y1, n)
                rhs(model, t + h, y1, modes, v0s, n, K6)
                st.rhs_evaluations += 1
                nsteps += 1
                err = 0.0
        if TAY is not None:
            if not hits_stop and h < COLLAPSE * max(COLLAPSE_T, abs(t)):
                status = ST_STEP_COLLAPSE
                break
        if not took_taylor:  # (the Taylor step was taken above)
            if IMP is None:
                rk_step(model, t, y, h, K, modes, v0s, n, yt, y1)
                st.rhs_evaluations += 6
                nsteps += 1
                err = error_norm(
                    y, y1, h, K, n_dof2, opts.rtol, opts.atol_position, opts.atol_velocity
                )
            else:
                evals_before = st.rhs_evaluations
                if r.implicit:
                    took_implicit = True
                    nsteps += 1
                    code, err, newton_iters, nfev = implicit_attempt(
                        model,
                        t,
                        y,
                        h,
                        K,
                        modes,
                        v0s,
                        n,
                        n_dof2,
                        opts,
                        jac_fresh,
                        IMP,
                        y1,
                        RC,
                        r.implicit_prev_h,
                    )
                    st.rhs_evaluations += nfev
                    jac_fresh = True
                    if code != ATTEMPT_OK:
                        # the collocation equations did not converge (or a system is singular):
                        # a shorter step
                        if h < 1e-14 * max(1.0, t):
                            status = ST_STEP_COLLAPSE
                            break
                        h *= 0.5
                        st.rejected_steps += 1
                        continue
                else:
                    rk_step(model, t, y, h, K, modes, v0s, n, yt, y1)
                    st.rhs_evaluations += 6
                    nsteps += 1
                    err = error_norm(
                        y, y1, h, K, n_dof2, opts.rtol, opts.atol_position, opts.atol_velocity
                    )
        if onset_q > 0.0:
            # the first step of a contact: its estimate misses the tau^n onset (on paper-3.3
            # this makes the peak forces about five times more accurate at the same cost)
            err *= onset_error_ratio(onset_q)
        if clamped[0] + clamped[1] > 0 and n > n_dof2 and not took_taylor and not took_implicit:
            # a contact held at its clamp: the body flies free (long steps), but the contact
            # still releases its stored energy, dD/dt = -F_k(p) p', into the dissipation
            # quadrature, whose error the motion's estimate does not see: it is bounded too
            for pair in range(n_pairs):
                iq = dissipation_index(model, pair)
                if modes[pair] != 0 and clamped[pair] == 1 and iq < n:
                    err = max(err, quadrature_error(y, y1, h, K, iq, opts.rtol))
        finite = True
        for i in range(n):
            if not math.isfinite(y1[i]):
                finite = False
        if not finite or not math.isfinite(err):
            if TAY is not None:
                if took_taylor:
                    # (a series that overflowed: the Runge-Kutta step decides)
                    h = h_rk
                    force_rk = True
                    st.rejected_steps += 1
                    continue
            if h < 1e-14 * max(1.0, t):
                status = ST_NONFINITE
                break
            h *= 0.1
            st.rejected_steps += 1
            continue
        if err > 1.0:
            if onset_q > 0.0:
                fac = max(0.02, 0.9 * err ** (-1.0 / onset_q))
            else:
                fac = max(0.2, 0.9 * math.exp(-0.2 * math.log(err)))
            if IMP is not None:
                if took_implicit:
                    fac = max(0.2, radau_safety(newton_iters) * err ** (-0.25))
            h *= fac
            st.rejected_steps += 1
            continue
        tangents_cut = False  # (the tangents below made over the part before a kink)
        if SENS is not None:
            # the tangents over the step, held to the same tolerance as the state (unless
            # the caller asked for them over the state's steps only: err_s stays 0)
            tangent_step(model, SENS, t, y, h, K, KS, modes, v0s, n_dof2, YS, ss, S1)
            err_s = 0.0
            if SENS.controlled:
                err_s = tangent_error(SENS, S1, h, KS, n_dof2, opts.rtol, SENS.SMAX)
            if SENS.controlled and clamped[0] + clamped[1] > 0 and n_tan > n_dof2:
                # (the dissipations' tangents where a clamped force leaves them unbounded;
                # written out here and below: one function for both, called every step,
                # made a run with one key 4 % slower)
                err_s = max(
                    err_s,
                    dissipation_tangent_error(
                        SENS,
                        S1,
                        h,
                        KS,
                        n_dof2,
                        y,
                        y1,
                        opts.rtol,
                        opts.atol_position,
                        modes,
                        clamped,
                    ),
                )
            if not err_s <= 1.0 and not took_taylor and not took_implicit:
                # A step over the kink of a clamped force: its stages past the kink read the
                # tangents' field on the far side, and the estimate sees the jump of its
                # derivative, which only a short step makes small (h times the jump of
                # dN / m). It rejected the steps that crossed the kink until they were a
                # few 1e-14 s long (at rtol 1e-12 on a 1e10 N/m Kelvin-Voigt wall: a
                # collapsed step). Where the step ends at that kink (its earliest event),
                # the tangents will be carried over the part before it only: the estimate
                # of that part decides (the step there and its tangents are made again
                # below, the same bits).
                dense_coeffs(y, y1, h, K, RC, n)
                pair_infos(model, n_pairs, t + h, y1, K6, modes, v0s, INF1)
                th_k, j_k = first_event(
                    model,
                    n_pairs,
                    t,
                    h,
                    RCs,
                    modes,
                    v0s,
                    clamped,
                    n_dof2,
                    ys,
                    GS,
                    K0,
                    K6,
                    INF0,
                    INF1,
                )
                if j_k >= CLAMP0:
                    hk = th_k * h
                    if hk <= 0.0:
                        hk = 1e-16 * max(1.0, t)
                    for i in range(n):
                        Ke[0, i] = K[0, i]
                    rk_step(model, t, y, hk, Ke, modes, v0s, n, yc, ye)
                    st.rhs_evaluations += 6
                    tangent_step(model, SENS, t, y, hk, Ke, KS, modes, v0s, n_dof2, YS, ss, S1)
                    clamp_step_end(
                        model,
                        SENS,
                        (j_k - CLAMP0) // 2,
                        (j_k - CLAMP0) % 2 == 1,
                        t,
                        hk,
                        Ke,
                        KS,
                        modes,
                        v0s,
                        n_dof2,
                        YS,
                        ss,
                        S1,
                        yc,
                        sw,
                    )
                    err_s = tangent_error(SENS, S1, hk, KS, n_dof2, opts.rtol, SENS.SMAX)
                    if clamped[0] + clamped[1] > 0 and n_tan > n_dof2:
                        err_s = max(
                            err_s,
                            dissipation_tangent_error(
                                SENS,
                                S1,
                                hk,
                                KS,
                                n_dof2,
                                y,
                                ye,
                                opts.rtol,
                                opts.atol_position,
                                modes,
                                clamped,
                            ),
                        )
                    tangents_cut = True
                    if not err_s <= 1.0:
                        # (the next try ends short of the kink)
                        h = hk
            if not err_s <= 1.0:
                # near onset and exit the tangents' error grows as h^1.5 (Hertz's sqrt(p)
                # stiffness; other exponents are rescaled as Hertz, which costs steps only)
                h *= max(0.02, 0.9 * err_s ** (-1.0 / 1.5)) if math.isfinite(err_s) else 0.1
                st.rejected_steps += 1
                continue
            err = max(err, err_s)
        # stiffness detection (Hairer & Wanner's test in DOPRI5): h |lambda| estimated from the
        # last two stages; a long run of steps on the stability boundary, and far below the
        # maximum step, means the explicit method is crawling
        stnum = 0.0
        stden = 0.0
        for i in range(n_dof2):
            stnum += (K[6, i] - K[5, i]) ** 2
            stden += (y1[i] - yt[i]) ** 2
        if IMP is not None:
            if took_implicit:
                stden = 0.0  # (an implicit step has no such stages: counted as non-stiff)
        if TAY is not None:
            if took_taylor:
                stden = 0.0  # (nor has a Taylor step)
        if stden > 0.0 and h * math.sqrt(stnum / stden) > 3.25 and h < stiff_below:
            stiff_run += 1
            nonstiff_run = 0
            if stiff_run >= STIFF_LIMIT:
                status = ST_STIFF
                break
        else:
            nonstiff_run += 1
            if nonstiff_run >= 6:  # as in DOPRI5: six non-stiff steps clear the suspicion
                stiff_run = 0
        if IMP is not None:
            if not took_implicit and not r.rest_blocked:
                # a contact at rest: hand it to the implicit step from the next step on
                if (
                    stden > 0.0
                    and h * math.sqrt(stnum / stden) > REST_HLAMBDA
                    and (modes[0] != 0 or modes[1] != 0)
                ):
                    r.rest_run += 1
                else:
                    r.rest_run = 0
        # PI step-size control (Gustafsson, Lundh & Soderlind, BIT 28 (1988) 270-287,
        # doi:10.1007/BF01934091; Hairer & Wanner II, Sect. IV.2): DOPRI5's exponents
        # 0.2 - 0.75 beta and beta = 0.04, safety 0.9, growth at most 5 (DOPRI5: 10). Unlike
        # DOPRI5 the step may grow right after a rejection: forbidding it saved 0.8 % of the
        # evaluations on paper-3.3 (benchmarks/README.md), not worth new bits.
        # On logarithms, fac = 0.9 err^-0.17 err_old^0.04 takes one log and one exp instead
        # of two pow calls (the lean loop's form).
        lerr = -math.inf
        if err == 0.0:
            fac = 5.0
        else:
            lerr = math.log(err)
            fac = 0.9 * math.exp(-0.17 * lerr + 0.04 * lerr_old)
            fac = min(5.0, max(0.2, fac))
        if IMP is not None:
            if took_implicit and err > 0.0:
                # the estimate is of order 3 (RADAU5's controller, without its predictive
                # part, which would need the last step to be carried across a restart)
                fac = min(10.0, max(0.2, radau_safety(newton_iters) * err ** (-0.25)))
        err_old = max(err, ERR_FLOOR)
        lerr_old = lerr if err >= ERR_FLOOR else LOG_ERR_FLOOR
        onset_q = 0.0
        onset_pair = -1
        h_next = min(h * fac, hmax)
        if TAY is not None:
            if took_taylor:
                h_next = h_rk
                err_old = err_old_rk
                lerr_old = lerr_old_rk
        if IMP is None:
            if not took_taylor:
                dense_coeffs(y, y1, h, K, RC, n)
        elif not took_implicit and not took_taylor:
            dense_coeffs(y, y1, h, K, RC, n)
        pair_infos(model, n_pairs, t + h, y1, K6, modes, v0s, INF1)
        # ---- events on the interpolant
        theta_ev = 2.0
        j_ev = -1
        # (the event functions read the coordinates and speeds only)
        if SENS is None:
            sampled = sample_events(
                model, n_pairs, t, h, RCs, modes, n_dof2, ys, GS, K0, K6, INF0, INF1
            )
        else:
            sampled = sample_events_call(
                model, n_pairs, t, h, RCs, modes, n_dof2, ys, GS, K0, K6, INF0, INF1
            )
        if sampled:
            for j in range(2 * n_pairs):
                th = locate_event(model, j, t, h, RCs, modes, v0s, n_dof2, ys, GS)
                if th < theta_ev:
                    theta_ev = th
                    j_ev = j
        if clamp_pending(n_pairs, modes, clamped, INF0, INF1):
            # a contact force that reaches or leaves its clamp in the step (events.py)
            th, j = locate_clamp(
                model,
                n_pairs,
                t,
                h,
                RCs,
                modes,
                v0s,
                clamped,
                n_dof2,
                ys,
                GS,
                INF0,
                INF1,
                theta_ev,
                j_ev,
            )
            if th < theta_ev:
                theta_ev = th
                j_ev = j
        if TAY is not None:
            if took_taylor:
                # the Taylor step is taken again by the Runge-Kutta method where its
                # polynomial is not the solution: past an exit (the contact force's series
                # ends at the branch point of p^n at p = 0), or where the law's clamp holds
                # a contact force at 0 by the end of the step (not the series of the
                # unclamped force)
                refused = j_ev >= CLAMP0 or (j_ev >= 0 and modes[j_ev // 2] != 0)
                for pair in range(n_pairs):
                    if modes[pair] != 0 and INF1[pair, I_FK] + INF1[pair, I_FC] < 0.0:
                        refused = True
                if refused:
                    h = h_rk
                    force_rk = True
                    st.rejected_steps += 1
                    continue
        if j_ev >= 0:
            # recompute the step exactly to the event time
            he = theta_ev * h
            if he <= 0.0:
                he = 1e-16 * max(1.0, t)
            for i in range(n):
                Ke[0, i] = K[0, i]
            if took_taylor:
                # the polynomial cut at the event
                if TAY is not None:
                    if TKIND[0] == 2:
                        taylor_shorten(TRS, math.sqrt(theta_ev), n)
                    else:
                        taylor_shorten(TRT, theta_ev, n)
                _dense_at(1.0, RCs, ye, n)
                rhs(model, t + he, ye, modes, v0s, n, Ke6)
                st.rhs_evaluations += 1
            elif IMP is None:
                rk_step(model, t, y, he, Ke, modes, v0s, n, yt, ye)
                st.rhs_evaluations += 6
                dense_coeffs(y, ye, he, Ke, RC, n)
            elif took_implicit:
                st.rhs_evaluations += implicit_to(
                    model, t, y, he, theta_ev, K, Ke, modes, v0s, n, n_dof2, opts, IMP, ye, RC
                )
            else:
                rk_step(model, t, y, he, Ke, modes, v0s, n, yt, ye)
                st.rhs_evaluations += 6
                dense_coeffs(y, ye, he, Ke, RC, n)
            pair_infos(model, n_pairs, t + he, ye, Ke6, modes, v0s, INF1)
            h_taken = he
        else:
            h_taken = h
        # post-process the step taken (to the event, or whole): samples, extremes, ranges
        nrow_step = nrow
        if SENS is not None:
            for pair in range(n_pairs):
                ie = open_ep[pair]
                if ie >= 0:
                    prev_depth_t[pair] = EP[ie].t_max_depth
                    prev_peak_t[pair] = EP[ie].t_peak_force
        nrow, isamp = scan_step(
            model,
            n_pairs,
            n_dof2,
            n,
            t,
            h_taken,
            RCs,
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
            rec,
            TAY,
            series_order,
        )
        st.steps += 1
        if TAY is not None:
            if took_taylor:
                st.taylor_steps += 1
                if TKIND[0] == 2:
                    st.onset_steps += 1
        if IMP is not None:
            jac_fresh = False
            # a whole implicit step's polynomial starts the next one's Newton iterations
            r.implicit_prev_h = 0.0
            if took_implicit and j_ev < 0:
                keep_polynomial(RC, n, IMP.Q)
                r.implicit_prev_h = h
            if took_implicit:
                st.implicit_steps += 1
                r.implicit_count += 1
                if r.implicit_count > REST_RAMP:
                    r.implicit_evals += st.rhs_evaluations - evals_before
                    r.implicit_time += h_taken
                if (
                    r.implicit_count >= REST_TRIAL
                    and r.implicit_evals > r.explicit_rate * r.implicit_time
                ):
                    r.implicit = 0
                    r.rest_blocked = 1
        st.min_step = min(st.min_step, h_taken)
        if SENS is not None:
            # the tangents over the step taken (recomputed when it ended at an event), then
            # at the instants the step recorded
            if j_ev >= 0 or tangents_cut:
                # (a step whose kink the search above found is found here too, from the
                # same values; were it not, the tangents over the whole step)
                tangent_step(
                    model,
                    SENS,
                    t,
                    y,
                    h_taken,
                    Ke if j_ev >= 0 else K,
                    KS,
                    modes,
                    v0s,
                    n_dof2,
                    YS,
                    ss,
                    S1,
                )
                if j_ev >= CLAMP0:
                    # (the stages at the kink on the step's side of it: tangent.py)
                    clamp_step_end(
                        model,
                        SENS,
                        (j_ev - CLAMP0) // 2,
                        (j_ev - CLAMP0) % 2 == 1,
                        t,
                        h_taken,
                        Ke,
                        KS,
                        modes,
                        v0s,
                        n_dof2,
                        YS,
                        ss,
                        S1,
                        yc,
                        sw,
                    )
            tangent_scales(S1, n_dof2, SENS.SMAX)
            tangent_dense_coeffs(SENS, S1, h_taken, KS, RCS, n_dof2)
            for pair in range(n_pairs):
                ie = open_ep[pair]
                if ie < 0:
                    continue
                which = 0
                if EP[ie].t_max_depth != prev_depth_t[pair]:
                    which += 1
                if EP[ie].t_peak_force != prev_peak_t[pair]:
                    which += 2
                if which == 0:
                    continue
                for q in range(2):
                    if not (which & (q + 1)):
                        continue
                    tq = EP[ie].t_max_depth if q == 0 else EP[ie].t_peak_force
                    theta = (tq - t) / h_taken
                    dense_eval(theta, RC, yd, n)
                    for d in range(nsens):
                        tangent_dense_eval(theta, RCS, d, SQ[d], n_dof2)
                    episode_extremes(
                        model, SENS, ie, pair, tq, yd, SQ, modes[pair], v0s[pair], q + 1
                    )
            if nrow > nrow_step:
                step_series_tangents(
                    model,
                    SENS,
                    SENS.RSENS,
                    rows,
                    nrow_step,
                    nrow,
                    t,
                    h_taken,
                    RC,
                    RCS,
                    n,
                    n_dof2,
                    modes,
                    v0s,
                    n_pairs,
                    yd,
                    SQ,
                    sw,
                )
            for d in range(nsens):
                for i in range(n_tan):
                    SENS.S[d, i] = S1[d, i]
                    KS[d, 0, i] = KS[d, 6, i]
        if j_ev >= 0:
            t_ev = t + h_taken
            for i in range(n):
                y[i] = ye[i]
            kink = j_ev >= CLAMP0
            pair = (j_ev - CLAMP0) // 2 if kink else j_ev // 2
            # (the wall and the rate into it: read at an onset or exit, not at a kink)
            side = -1 if j_ev % 2 == 0 else 1
            _, _, rate_in = gaps(model, pair, t_ev, y)
            rate = -rate_in if side < 0 else rate_in  # penetration rate into this wall
            ev_onset = modes[pair] == 0
            ev_ie = open_ep[pair]
            nrow_ev = nrow
            if kink:
                # the contact force reached or left its clamp: the step is cut there, so that
                # the next one starts on the kink's other side; the contact goes on
                clamped[pair] = 1 - clamped[pair]
            elif modes[pair] == 0:
                # onset: latch the approach speed
                vmin = model.min_impact_velocity
                vlat = rate if rate > vmin else vmin
                modes[pair] = side
                v0s[pair] = vlat
                nep = _open(model, EP, nep, t_ev, y, pair, side, rate, vlat, 0.0, n, open_ep, SENS)
                ev_ie = nep - 1
                nrow_ev = nrow
                nrow = write_row(model, rows, nrow, t_ev, y, modes, v0s, n, KIND_ONSET, rec)
                # start the contact with a step of a fraction of its duration estimated from
                # the elastic closed form, and rescale a rejected first step by its own law
                h_on, onset_q = _onset_step(model, pair, vlat)
                onset_pair = pair
                h = min(h, h_on)
                clamped[pair] = 0  # (the force starts at 0 or above: p = 0, p' > 0)
            else:
                # exit
                nrow = write_row(model, rows, nrow, t_ev, y, modes, v0s, n, KIND_EXIT, rec)
                ie = open_ep[pair]
                if ie >= 0:
                    close_episode(
                        EP, ie, t_ev, -rate, _energy(y, dissipation_index(model, pair), n), END_EXIT
                    )
                open_ep[pair] = -1
                modes[pair] = 0
                clamped[pair] = 0
            update_ranges(model, n_pairs, t_ev, y, modes, v0s, WIN, RANGES)
            st.events += 1
            if t_ev - last_event_t <= 1e-12 * max(1.0, t_ev):
                same_time_events += 1
                if same_time_events > 50:
                    status = ST_ZENO
                    t = t_ev
                    break
            else:
                same_time_events = 0
            last_event_t = t_ev
            t = t_ev
            r.taylor_wait = 0.0
            if IMP is not None:
                r.implicit = 0
                r.rest_run = 0
                r.rest_blocked = 0
                jac_fresh = False
            rhs(model, t, y, modes, v0s, n, K0)
            pair_infos(model, n_pairs, t, y, K0, modes, v0s, INF0)
            st.rhs_evaluations += 1
            if SENS is not None:
                # (at a clamp the field is continuous: the tangents do not jump; its
                # derivative does: tangent.clamp_event below)
                # (t_begin is -inf in a call that resumes a run: no onset there is the
                # run's start, though inf <= inf would say so)
                at_start = (
                    ev_onset
                    and t_begin > -math.inf
                    and t - t_begin <= 1e-12 * max(1.0, abs(t_begin))
                )
                # (on the wall itself: tangent.surface_event)
                if not kink and not surface_event(
                    model,
                    SENS,
                    pair,
                    side,
                    ev_onset,
                    at_start,
                    t,
                    y,
                    Ke6,
                    K0,
                    n,
                    n_dof2,
                    ev_ie,
                    KS,
                    h_taken,
                    modes,
                    v0s,
                    ev_modes,
                    yc,
                    fm,
                    fp,
                    sw,
                ):
                    status = ST_GRAZING
                    break
                if ev_onset:
                    episode_extremes(
                        model, SENS, ev_ie, pair, t, y, SENS.S, modes[pair], v0s[pair], 3
                    )
                    onset_correction(SENS, ev_ie, 3, INF0[pair, I_PD], INF0[pair, I_DN])
                if kink:
                    # (to the kink and back, and the next step's first stage on its new
                    # side: tangent.clamp_event)
                    clamp_event(
                        model,
                        SENS,
                        pair,
                        clamped[pair] == 1,
                        t,
                        y,
                        K0,
                        h_taken,
                        modes,
                        v0s,
                        n_dof2,
                        KS,
                        yc,
                        sw,
                    )
                else:
                    tangent_start(model, SENS, t, y, modes, v0s, KS)
                if nrow > nrow_ev:
                    series_tangent_row(
                        model, SENS, SENS.RSENS, nrow_ev, t, y, SENS.S, modes, v0s, n_pairs, sw
                    )
            continue
        # ---- accepted step without event
        st.max_step = max(st.max_step, h)
        t = t_stop if hits_stop else t + h
        for i in range(n):
            y[i] = y1[i]
            K[0, i] = K[6, i]
        INF0, INF1 = INF1, INF0
        h = h_next
        if IMP is not None:
            if r.rest_run >= REST_AFTER:
                r.implicit = 1
                r.implicit_count = 0
                r.implicit_evals = 0.0
                r.implicit_time = 0.0
                # what the explicit method would spend per second from here: its next step
                r.explicit_rate = 6.0 / h
                r.rest_run = 0
    # ---- where the run stands
    r.t = t
    if t >= t_end and h_cut > h:
        # the last step was cut short to land on the end: a run continued from here starts
        # with the step the control wanted, not one grown from that sliver (a transfer
        # 1e-17 s before the end left 5e-17 s, below what the step control can take at t)
        h = h_cut
    r.h = h
    r.err_old = err_old
    r.onset_q = onset_q
    r.onset_pair = onset_pair
    r.stiff_run = stiff_run
    r.nonstiff_run = nonstiff_run
    r.same_time_events = same_time_events
    r.last_event_t = last_event_t
    r.steps = nsteps
    r.next_sample = isamp
    r.next_transfer = itr
    r.mode_0 = modes[0]
    r.mode_1 = modes[1]
    r.v0_0 = v0s[0]
    r.v0_1 = v0s[1]
    r.open_0 = open_ep[0]
    r.open_1 = open_ep[1]
    r.clamped_0 = clamped[0]
    r.clamped_1 = clamped[1]
    if status == ST_OK:
        nrow0 = nrow
        nrow = write_row(model, rows, nrow, t, y, modes, v0s, n, KIND_END, rec)
        if SENS is not None and nrow > nrow0:
            series_tangent_row(
                model, SENS, SENS.RSENS, nrow0, t, y, SENS.S, modes, v0s, n_pairs, sw
            )
    r.rows = nrow
    r.episodes = nep
    return status
