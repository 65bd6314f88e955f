"""What the solver needs of one contact pair at one instant, from the model's functions.

``pair_info`` fills a summary (the fields ``INFO_FIELDS``, indexed by the ``I_*`` names)
computed once at each end of each accepted step and handed from one step to the next: the
gaps, the penetration and its derivatives, the forces and their slopes.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from braidsim.core.generic import cached_njit, helper
from braidsim.core.interfaces import (
    pair_gap_accel,
    pair_gaps,
    pair_law,
    pair_law_rates,
    penetration,
)

INFO_FIELDS = (
    "g_in",  # gap to the inner wall [m]
    "g_out",  # gap to the outer wall [m]
    "rate",  # d g_in / dt [m/s]
    "accel",  # d^2 g_in / dt^2 [m/s^2]
    "p",  # penetration into the wall in contact (>= 0; 0 when free) [m]
    "p_dot",  # [m/s]
    "p_ddot",  # [m/s^2]
    "F_k",  # stiffness-related force [N]
    "F_c",  # damping-related force [N]
    "N",  # normal force [N]
    "N_dot",  # dN/dt [N/s]
    "F_c_dot",  # dF_c/dt [N/s]
)
I_GIN, I_GOUT, I_RATE, I_ACC, I_P, I_PD, I_PDD, I_FK, I_FC, I_N, I_DN, I_DFC = range(
    len(INFO_FIELDS)
)
NI = len(INFO_FIELDS)


@helper
def gaps(model, pair, t, y):
    """:func:`~braidsim.core.interfaces.pair_gaps` as a call, for the places that need it
    once per event (compiled once, not inlined at each)."""
    return pair_gaps(model, pair, t, y)


@helper
def pair_forces(model, pair, t, y, mode, v0):
    """(p, p', F_k, F_c, N) of a pair in contact mode ``mode`` (zeros when free)."""
    if mode == 0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    g_in, g_out, rate = gaps(model, pair, t, y)
    p, pd = penetration(mode, g_in, g_out, rate)
    fk, fc, nn = pair_law(model, pair, p, pd, v0)
    return p, pd, fk, fc, nn


@helper
def pair_info(model, pair, t, y, f, mode, v0, out):
    """Fill ``out[:NI]`` for one pair in contact mode ``mode``; ``f`` is dy/dt at t (an RK
    stage or the derivative of the interpolant)."""
    g_in, g_out, rate = pair_gaps(model, pair, t, y)
    acc = pair_gap_accel(model, pair, t, f)
    out[I_GIN] = g_in
    out[I_GOUT] = g_out
    out[I_RATE] = rate
    out[I_ACC] = acc
    if mode == 0:
        for i in range(I_P, NI):
            out[i] = 0.0
        return
    p, pd = penetration(mode, g_in, g_out, rate)
    pdd = -acc if mode < 0 else acc
    fk, fc, nn = pair_law(model, pair, p, pd, v0)
    dn, dfc = pair_law_rates(model, pair, p, pd, pdd, v0, fk, fc)
    out[I_P] = p
    out[I_PD] = pd
    out[I_PDD] = pdd
    out[I_FK] = fk
    out[I_FC] = fc
    out[I_N] = nn
    out[I_DN] = dn
    out[I_DFC] = dfc


@helper
def pair_infos(model, n_pairs, t, y, f, modes, v0s, INF):
    """:func:`pair_info` of every pair into INF[pair]."""
    for pair in range(n_pairs):
        pair_info(model, pair, t, y, f, modes[pair], v0s[pair], INF[pair])


@cached_njit(error_model="numpy")
def _forces_along(model, pair, ts, Y, mode, v0, out):
    y = np.empty(Y.shape[0])
    for k in range(ts.shape[0]):
        for i in range(Y.shape[0]):
            y[i] = Y[i, k]
        p, pd, fk, fc, nn = pair_forces(model, pair, ts[k], y, mode, v0)
        out[0, k] = p
        out[1, k] = pd
        out[2, k] = fk
        out[3, k] = fc
        out[4, k] = nn


@cached_njit(error_model="numpy")
def _gaps_along(model, pair, ts, Y, out):
    y = np.empty(Y.shape[0])
    for k in range(ts.shape[0]):
        for i in range(Y.shape[0]):
            y[i] = Y[i, k]
        g_in, g_out, rate = pair_gaps(model, pair, ts[k], y)
        out[0, k] = g_in
        out[1, k] = g_out
        out[2, k] = rate


def gaps_along(
    model: Any, pair: int, t: np.ndarray, Y: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(g_in, g_out, d g_in/dt) of ``pair``: the gaps to its inner and outer wall and the
    rate of the first, at the times ``t`` with the states ``Y`` (one column a time, as
    :func:`contact_quantities`), by the model's :func:`~braidsim.core.interfaces.pair_gaps`.

    One compiled call for all times: a call of ``pair_gaps.py`` from Python costs ~5 us per
    time (numba types the whole record to pick the machine code)."""
    ts = np.ascontiguousarray(np.atleast_1d(t), dtype=float)
    Ya = np.ascontiguousarray(np.asarray(Y, dtype=float).reshape(-1, ts.size))
    out = np.empty((3, ts.size))
    _gaps_along(model, int(pair), ts, Ya, out)
    return out[0], out[1], out[2]


def contact_quantities(
    model: Any, pair: int, t: np.ndarray, Y: np.ndarray, mode: int, v0: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(p, p', F_k, F_c, N) of ``pair`` in contact mode ``mode`` at the times ``t`` with the
    states ``Y`` (one column a time), from the model's compiled functions (for the SciPy
    reference backend and the analyses)."""
    ts = np.ascontiguousarray(np.atleast_1d(t), dtype=float)
    Ya = np.ascontiguousarray(np.asarray(Y, dtype=float).reshape(-1, ts.size))
    out = np.empty((5, ts.size))
    _forces_along(model, pair, ts, Ya, int(mode), float(v0), out)
    return out[0], out[1], out[2], out[3], out[4]
