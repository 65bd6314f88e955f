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
from numba import njit

from braidsim.core.interfaces import (
    apply_transfer,
    derivatives,
    dissipation_index,
    model_size,
    pair_gaps,
    pair_onset_step,
)
from braidsim.core.layout import (
    END_EXIT,
    END_TRANSFER,
    KIND_END,
    KIND_EXIT,
    KIND_ONSET,
    KIND_SAMPLE,
    KIND_START,
    KIND_TRANSFER,
    NEW_RUN,
    ST_BAD_ARRAYS,
    ST_EPISODES_FULL,
    ST_MAX_STEPS,
    ST_NONFINITE,
    ST_OK,
    ST_ROWS_FULL,
    ST_STEP_COLLAPSE,
    ST_STIFF,
    ST_ZENO,
    STARTED,
    STIFF_LIMIT,
)
from braidsim.core.solver.dopri5 import dense_coeffs, error_norm, rk_step
from braidsim.core.solver.events import N_SUB, locate_event, sample_events
from braidsim.core.solver.pairs import NI, pair_infos
from braidsim.core.solver.recorders import (
    close_episode,
    episode_start_values,
    open_episode,
    scan_step,
    update_ranges,
    write_row,
)

EPISODE_RESERVE = 4  # impact-table rows one step can open at most
EVENT_ROWS = 16  # series rows one step writes at most besides its samples


@njit(cache=True, error_model="numpy")
def _energy(y, idx, n):
    """The dissipated-energy quadrature at ``idx`` (NaN when the run does not integrate it)."""
    return y[idx] if idx < n else math.nan


@njit(cache=True, error_model="numpy")
def _open(model, EP, nep, t, y, pair, mode, vel, v0, initial, n, open_ep):
    """Open row ``nep`` of the impact table for a contact of ``pair`` starting at t (approach
    speed ``vel``, latched ``v0``) and fold its first values in; returns the new row count."""
    open_ep[pair] = nep
    e0 = _energy(y, dissipation_index(model, pair), n)
    nep = open_episode(EP, nep, t, pair, mode, vel, v0, initial, e0)
    # a contact present at the start may have its largest force there, and a law whose
    # force jumps at onset (a dashpot) has its first extremes there
    episode_start_values(model, EP, nep - 1, t, y, pair, mode, v0)
    return nep


@njit(cache=True, error_model="numpy")
def _start_contacts(model, t, y, modes, v0s, open_ep, EP, nep, npair, n):
    """The contact policy at the start and right after a transfer, for the first ``npair``
    pairs.

    A pair whose carrier overlaps a wall starts in contact. Such a contact has no approach
    speed: it is released elastically (v0 = inf, no damping term until the next onset) unless
    the model's ``initial_impact_velocity`` gives a speed. A body exactly on a wall and moving
    into it starts in contact with its approach rate latched (floored at the model's
    ``min_impact_velocity``), as after a transfer.
    """
    for pair in range(npair):
        g_in, g_out, rate = pair_gaps(model, pair, t, y)
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
        nep = _open(model, EP, nep, t, y, pair, mode, pd, v0, initial, n, open_ep)
    return nep


# nogil: the loop touches no Python object, so runs of a batch overlap on threads
@njit(cache=True, error_model="numpy", nogil=True)
def integrate(model, opts, y, RS, ST, TR, WIN, rows, row_reserve, EP, RANGES, XSQ, STATS):
    """Integrate ``model`` from the restart record to ``opts.t_end``; returns a status.

    Parameters
    ----------
    model : record
        A model of :mod:`braidsim.core.models`.
    opts : SolverOptions
    y : array
        The state (length 2 n_coords, plus n_quads with ``opts.energy``); in and out.
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
    """
    n_coords, n_pairs, n_quads = model_size(model)
    n_dof2 = 2 * n_coords
    n = n_dof2 + n_quads if opts.energy else n_dof2
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
    st = STATS[0]
    r = RS[0]
    y1 = np.empty(n)
    yt = np.empty(n)
    ys = np.empty(n)
    yd = np.empty(n)
    ye = np.empty(n)
    INF0 = np.zeros((2, NI))  # pair summaries at the start of the step (the end of the last)
    INF1 = np.zeros((2, NI))  # ... at its end
    IX = np.zeros(NI)
    K = np.empty((7, n))
    Ke = np.empty((7, n))
    RC = np.empty((5, n))
    GS = np.empty((4, N_SUB + 1))
    modes = np.zeros(2, dtype=np.int64)
    v0s = np.ones(2)
    open_ep = -np.ones(2, dtype=np.int64)
    modes[0] = int(r.mode_0)
    modes[1] = int(r.mode_1)
    v0s[0] = r.v0_0
    v0s[1] = r.v0_1
    open_ep[0] = int(r.open_0)
    open_ep[1] = int(r.open_1)
    nrow = int(r.rows)
    nep = int(r.episodes)
    isamp = int(r.next_sample)
    itr = int(r.next_transfer)
    t = r.t
    if r.started != STARTED:
        if r.started == NEW_RUN:
            nep = _start_contacts(model, t, y, modes, v0s, open_ep, EP, nep, n_pairs, n)
            r.h = min(1e-6, hmax, t_end - t)
        else:
            # a continuation (CONTINUED): the contacts carried over open new episodes
            for pair in range(n_pairs):
                open_ep[pair] = -1
                if modes[pair] != 0:
                    mode = modes[pair]
                    nep = _open(
                        model, EP, nep, t, y, pair, mode, math.nan, v0s[pair], 1.0, n, open_ep
                    )
        nrow = write_row(model, rows, nrow, t, y, modes, v0s, n, KIND_START, rec)
        update_ranges(model, n_pairs, t, y, modes, v0s, WIN, RANGES)
        while isamp < ST.shape[0] and ST[isamp] <= t:
            if ST[isamp] == t:
                nrow = write_row(model, rows, nrow, t, y, modes, v0s, n, KIND_SAMPLE, rec)
            isamp += 1
        while itr < TR.shape[0] and TR[itr] <= t:
            itr += 1
        r.started = STARTED
    h = r.h
    nsteps = int(r.steps)
    same_time_events = int(r.same_time_events)
    last_event_t = r.last_event_t
    stiff_run = int(r.stiff_run)
    nonstiff_run = int(r.nonstiff_run)
    err_old = r.err_old
    # error exponent of the first step of a contact: the force grows as s^n after onset, so
    # that step's error scales as h^(n+1), not h^5 (0: no contact step pending)
    onset_q = r.onset_q

    derivatives(model, t, y, modes, v0s, n, K[0])
    pair_infos(model, n_pairs, t, y, K[0], modes, v0s, INF0)
    st.rhs_evaluations += 1
    status = ST_OK
    while t < t_end:
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
            reset = apply_transfer(model, t, y)
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
                    open_ep[pair] = -1
                modes[pair] = 0
            nrow = write_row(model, rows, nrow, t, y, modes, v0s, n, KIND_TRANSFER, rec)
            nep = _start_contacts(model, t, y, modes, v0s, open_ep, EP, nep, reset, n)
            derivatives(model, t, y, modes, v0s, n, K[0])
            pair_infos(model, n_pairs, t, y, K[0], modes, v0s, INF0)
            st.rhs_evaluations += 1
        t_stop = t_end
        if itr < TR.shape[0] and TR[itr] < t_stop:
            t_stop = TR[itr]
        hits_stop = False
        if h >= (t_stop - t) * (1.0 - 1e-9):
            # reach the stop exactly (and never leave a sliver too small to step over)
            h = t_stop - t
            hits_stop = True
        if not hits_stop and h < 4e-16 * max(1.0, abs(t)) * 8:
            status = ST_STEP_COLLAPSE
            break
        rk_step(model, t, y, h, K, modes, v0s, n, yt, y1)
        st.rhs_evaluations += 6
        nsteps += 1
        err = error_norm(y, y1, h, K, n_dof2, opts.rtol, opts.atol_position, opts.atol_velocity)
        finite = True
        for i in range(n):
            if not math.isfinite(y1[i]):
                finite = False
        if not finite or not math.isfinite(err):
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
                fac = max(0.2, 0.9 * err ** (-0.2))
            h *= fac
            st.rejected_steps += 1
            continue
        # stiffness detection (Hairer & Wanner's test in DOPRI5): h |lambda| estimated from the
        # last two stages; a long run of steps on the stability boundary means the explicit
        # method is crawling
        stnum = 0.0
        stden = 0.0
        for i in range(n_dof2):
            stnum += (K[6, i] - K[5, i]) ** 2
            stden += (y1[i] - yt[i]) ** 2
        if stden > 0.0 and h * math.sqrt(stnum / stden) > 3.25:
            stiff_run += 1
            nonstiff_run = 0
            if stiff_run >= STIFF_LIMIT:
                status = ST_STIFF
                break
        else:
            nonstiff_run += 1
            if nonstiff_run >= 6:  # as in DOPRI5: six non-stiff steps clear the suspicion
                stiff_run = 0
        # PI step-size control (Hairer, Norsett & Wanner I, Sect. II.4; DOPRI5 with beta = 0.04)
        if err == 0.0:
            fac = 5.0
        else:
            fac = 0.9 * err ** (-0.17) * err_old**0.04
            fac = min(5.0, max(0.2, fac))
        err_old = max(err, 1e-4)
        onset_q = 0.0
        h_next = min(h * fac, hmax)
        dense_coeffs(y, y1, h, K, RC, n)
        pair_infos(model, n_pairs, t + h, y1, K[6], modes, v0s, INF1)
        # ---- events on the interpolant
        theta_ev = 2.0
        j_ev = -1
        if sample_events(model, n_pairs, t, h, RC, modes, n, ys, GS, K[0], K[6], INF0, INF1):
            for j in range(2 * n_pairs):
                th = locate_event(model, j, t, h, RC, modes, n, ys, GS)
                if th < theta_ev:
                    theta_ev = th
                    j_ev = j
        if j_ev >= 0:
            # recompute the step exactly to the event time
            he = theta_ev * h
            if he <= 0.0:
                he = 1e-16 * max(1.0, t)
            for i in range(n):
                Ke[0, i] = K[0, i]
            rk_step(model, t, y, he, Ke, modes, v0s, n, yt, ye)
            st.rhs_evaluations += 6
            dense_coeffs(y, ye, he, Ke, RC, n)
            pair_infos(model, n_pairs, t + he, ye, Ke[6], modes, v0s, INF1)
            h_taken = he
        else:
            h_taken = h
        # post-process the step taken (to the event, or whole): samples, extremes, ranges
        nrow, isamp = scan_step(
            model,
            n_pairs,
            n_dof2,
            n,
            t,
            h_taken,
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
            rec,
        )
        st.steps += 1
        st.min_step = min(st.min_step, h_taken)
        if j_ev >= 0:
            t_ev = t + h_taken
            for i in range(n):
                y[i] = ye[i]
            pair = j_ev // 2
            side = -1 if j_ev % 2 == 0 else 1
            _, _, rate_in = pair_gaps(model, pair, t_ev, y)
            rate = -rate_in if side < 0 else rate_in  # penetration rate into this wall
            if modes[pair] == 0:
                # onset: latch the approach speed
                vmin = model.min_impact_velocity
                vlat = rate if rate > vmin else vmin
                modes[pair] = side
                v0s[pair] = vlat
                nep = _open(model, EP, nep, t_ev, y, pair, side, rate, vlat, 0.0, n, open_ep)
                nrow = write_row(model, rows, nrow, t_ev, y, modes, v0s, n, KIND_ONSET, rec)
                # start the contact with a step of a fraction of its duration estimated from
                # the elastic closed form, and rescale a rejected first step by its own law
                h_on, onset_q = pair_onset_step(model, pair, vlat)
                h = min(h, h_on)
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
            derivatives(model, t, y, modes, v0s, n, K[0])
            pair_infos(model, n_pairs, t, y, K[0], modes, v0s, INF0)
            st.rhs_evaluations += 1
            continue
        # ---- accepted step without event
        st.max_step = max(st.max_step, h)
        t = t_stop if hits_stop else t + h
        for i in range(n):
            y[i] = y1[i]
            K[0, i] = K[6, i]
        INF0, INF1 = INF1, INF0
        h = h_next
    # ---- where the run stands
    r.t = t
    r.h = h
    r.err_old = err_old
    r.onset_q = onset_q
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
    if status == ST_OK:
        nrow = write_row(model, rows, nrow, t, y, modes, v0s, n, KIND_END, rec)
    r.rows = nrow
    r.episodes = nep
    return status
