"""Compiled core: equations of motion and an event-exact Dormand-Prince 5(4) integrator.

Everything here is numba ``njit`` code on plain float64 arrays (no units, no objects); the
layers above (:mod:`braidsim.model`, :mod:`braidsim.simulate`) build the arrays and read the
results. The layout of the parameter vector ``P`` is given by the ``P_*`` constants.

Equations of motion (MODEL_NOTES sections 2-3; x radial, y tangential)::

    m x'' = -s_t N_t - f_x(x') - T1 cos(phi) - m r_c omega(t)^2
    m y'' = -s_s N_s - f_y(y') + T1 sin(phi)

with the track walls at x = h(t) (inner) and x = h(t) + eps_g (outer), the slot walls at
y = s(t) (rear) and y = s(t) + eps_h (front), s(t) = r_c int omega dt, s_t, s_s the side of
the wall in contact (-1 inner/rear, +1 outer/front, 0 free), and the normal force

    N = max(0, K p^n (1 + D pdot / v0))

(see :mod:`braidsim.contact`), p the penetration into the wall, pdot its rate relative to the
moving wall, v0 the approach speed latched at contact onset. Friction (Eq. 14):
f_x = mu1 |m g - T2| phi(x'), f_y = mu2 N_t phi(y'), phi the regularised sign function.

The integrator is the Dormand-Prince 5(4) pair (Hairer, Norsett & Wanner, Solving ODEs I,
Sect. II.5, code DOPRI5) with its 4th-order continuous extension. In every accepted step the
event functions (wall gaps in free flight, penetrations in contact) are sampled at
``N_SUB`` interior points of the interpolant; a sign change is located by the Illinois method
on the interpolant, and an interior minimum that does not change sign at the samples is
searched for by golden section, so that a contact cannot hide inside a step. The step is then
recomputed from its start to the event time exactly (full 5th-order accuracy at the event), the
mode is switched and the integration restarts there.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# Every helper below works on arrays that integrate() allocates and passes down, and none
# allocates: they are compiled without numba's reference-counted memory management (NRT),
# whose atomic increment/decrement on each array argument of each call was more than half of
# the run time (paper-3.4a kernel: 4.5 ms with it, 2.1 ms without).
# (``_nrt`` is numba's switch for it; the type stubs do not list it.)
helper = njit(cache=True, error_model="numpy", _nrt=False)  # type: ignore[call-overload]
inline_helper = njit(  # the smallest, hottest ones are also inlined into their callers
    cache=True, error_model="numpy", inline="always", _nrt=False
)  # type: ignore[call-overload]

# ---- parameter vector layout ---------------------------------------------------------
P_MASS = 0
P_LOAD_X = 1  # T1 cos(phi) [N]
P_MRC = 2  # m r_c [kg m]
P_T_Y = 3  # T1 sin(phi) [N]
P_EPS_G = 4
P_EPS_H = 5
P_K_T = 6
P_N_T = 7
P_D_T = 8
P_K_S = 9
P_N_S = 10
P_D_S = 11
P_FRIC_LAW = 12  # 0 arctan, 1 tanh, 2 stribeck, 3 none
P_MU1 = 13
P_MU2 = 14
P_NX = 15  # |m g - T2| [N]
P_VHAT = 16
P_MUS_RATIO = 17
P_VSTRIBECK = 18
P_VMIN = 19
P_VINIT = 20  # <= 0: energy-equivalent policy
P_ALLOW_TENSION = 21
P_DOF = 22  # 1: x only, 2: x and y
P_RC = 23
P_RTOL = 24
P_ATOL_X = 25
P_ATOL_V = 26
P_HMAX = 27
P_MAXSTEPS = 28
P_T_END = 29
P_TRANSFER_SPEED = 30
P_OMEGA0 = 31
P_RECORD_EVENTS = 32  # 1: write onset/exit/peak rows into the series; 0: samples only
P_T_START = 33  # start time [s]
P_INIT_GIVEN = 34  # 1: start in the contact modes and latched speeds below (a restart)
P_INIT_MODE_T = 35
P_INIT_MODE_S = 36
P_INIT_V0_T = 37
P_INIT_V0_S = 38
P_SIZE = 39

# ---- state vector layout ---------------------------------------------------------------
# x, vx, y, vy, then quadratures for the energy balance: energy dissipated by the track and
# slot contacts, friction work in x and y (dissipated), work of the x load (tension and
# centrifugal), of the moving track walls, of the y tension and of the moving slot walls
NY = 12

# ---- sampled series columns --------------------------------------------------------------
COLUMNS = (
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
    "kind",
)
NCOL = len(COLUMNS)
# Numba compiles a separate copy of a function for each integer constant it is called with
# (a Literal[int] type). Row kinds are therefore floats, and the pair indices and counters
# passed to the bigger helpers are computed (``TRACK``/``SLOT`` below are run-time values
# derived from an argument), which keeps the cold compile time of the kernel down.
KIND_SAMPLE, KIND_ONSET, KIND_EXIT, KIND_PEAK, KIND_TRANSFER, KIND_START, KIND_END = (
    float(k) for k in range(7)
)

# ---- episode (impact) table columns ------------------------------------------------------
EPISODE_COLUMNS = (
    "t",
    "t_end",
    "pair",  # 0 track, 1 slot
    "wall",  # -1 inner/rear, +1 outer/front
    "velocity",  # approach speed at onset (raw, relative, >= 0 when approaching)
    "latched_velocity",  # v0 used in the force law (floored, or the t = 0 policy)
    "rebound_velocity",  # separation speed at exit, NaN while ongoing
    "max_depth",
    "t_max_depth",
    "peak_force",
    "t_peak_force",
    "min_damping_force",
    "max_damping_force",
    "dissipated_energy",
    "end_reason",  # 0 exit, 1 still in contact at the end, 2 cut by a transfer
    "initial",  # 1 when the contact existed at the start (t = 0 or right after a transfer)
)
NEP = len(EPISODE_COLUMNS)

# ---- status codes ---------------------------------------------------------------------------
ST_OK = 0
ST_STEP_COLLAPSE = 1
ST_NONFINITE = 2
ST_MAX_STEPS = 3
ST_CAPACITY_ROWS = 4
ST_CAPACITY_EPISODES = 5
ST_ZENO = 6
ST_STIFF = 7
ST_BAD_ARRAYS = 8  # an array of the wrong size was passed (a caller bug, never user input)
STIFF_LIMIT = 100_000  # accepted steps held by stability (few breaks) before giving up

N_SUB = 8  # interior samples of the interpolant per step for events and extremes
# steps, rejected, events, rhs evaluations, transfers, min h, max h, final t, then the final
# contact modes and latched speeds (track, slot) for a restart
N_STATS = 12

# The smallest, hottest helpers (``inline_helper``) are inlined into their callers (numba IR
# inlining): a call that passes arrays costs some 40 ns even without reference counting; the
# equations of motion are inlined once into the stage loop of _step. Inlining more than
# these was measured slower (larger code) and costs compile time.

# ---- Dormand-Prince 5(4) coefficients (Hairer's DOPRI5) ------------------------------
C2, C3, C4, C5 = 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0
A21 = 1.0 / 5.0
A31, A32 = 3.0 / 40.0, 9.0 / 40.0
A41, A42, A43 = 44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0
A51, A52, A53, A54 = 19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0
A61, A62, A63, A64, A65 = (
    9017.0 / 3168.0,
    -355.0 / 33.0,
    46732.0 / 5247.0,
    49.0 / 176.0,
    -5103.0 / 18656.0,
)
A71, A73, A74, A75, A76 = 35.0 / 384.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0
E1, E3, E4, E5, E6, E7 = (
    71.0 / 57600.0,
    -71.0 / 16695.0,
    71.0 / 1920.0,
    -17253.0 / 339200.0,
    22.0 / 525.0,
    -1.0 / 40.0,
)
D1, D3, D4, D5, D6, D7 = (
    -12715105075.0 / 11282082432.0,
    87487479700.0 / 32700410799.0,
    -10690763975.0 / 1880347072.0,
    701980252875.0 / 199316789632.0,
    -1453857185.0 / 822651844.0,
    69997945.0 / 29380423.0,
)
# the tableau as arrays for the stage loop of _step: RK_A[s] gives stage s (row 6: the
# solution), RK_C[s] its time fraction
RK_A = np.zeros((7, 6))
RK_A[1, :1] = (A21,)
RK_A[2, :2] = (A31, A32)
RK_A[3, :3] = (A41, A42, A43)
RK_A[4, :4] = (A51, A52, A53, A54)
RK_A[5, :5] = (A61, A62, A63, A64, A65)
RK_A[6, :6] = (A71, 0.0, A73, A74, A75, A76)
RK_C = np.array([0.0, C2, C3, C4, C5, 1.0, 1.0])
GOLD = 0.3819660112501051  # 2 - golden ratio
# 4-point Gauss-Legendre rule on [0, 1] (nodes, weights), exact for polynomials of degree 7:
# the quadrature of x^2 over each step, x being the degree-5 interpolant
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


# =======================================================================================
# Excitation: track vibration h(t), horn-gear speed omega(t) and slot position s(t)
# =======================================================================================


# The excitation tables travel in one flat array EX (fewer array arguments make the many
# small calls of the hot path cheaper):
#   EX[0] = n_th, EX[1] = n_wh, EX[2] = n_pt, then n_th rows (amplitude, angular frequency,
#   phase) of h(t), n_wh rows of omega(t), and the profile: n_pt times, n_pt speeds and n_pt
#   cumulative integrals of omega.
EX_HEAD = 3


def pack_excitation(TH, WH, PT, PW, PI):
    """Build the flat excitation array EX from the tables (plain Python, called once)."""
    return np.concatenate(
        (
            np.array([TH.shape[0], WH.shape[0], PT.shape[0]], dtype=np.float64),
            TH.ravel(),
            WH.ravel(),
            PT,
            PW,
            PI,
        )
    ).astype(np.float64)


@inline_helper
def track_h(t, EX):
    """Track wall displacement h(t) = sum a cos(w t + phi) [m] and its rate [m/s]."""
    h = 0.0
    hd = 0.0
    n = int(EX[0])
    for i in range(n):
        a = EX[EX_HEAD + 3 * i]
        w = EX[EX_HEAD + 3 * i + 1]
        arg = w * t + EX[EX_HEAD + 3 * i + 2]
        h += a * math.cos(arg)
        hd -= a * w * math.sin(arg)
    return h, hd


@helper
def track_accel_bound(EX):
    """Largest possible |h''(t)| = sum |a| w^2 [m/s^2] (for the contact screens)."""
    acc = 0.0
    for i in range(int(EX[0])):
        acc += abs(EX[EX_HEAD + 3 * i]) * EX[EX_HEAD + 3 * i + 1] ** 2
    return acc


@inline_helper
def _phase(t, EX, TC):
    """(cos, sin) of the first harmonic's phase w t + phi of the track at t, remembered in
    TC = (t, cos, sin): the end of one step, where the contact summaries need them
    (:func:`track_motion`), is the start of the next, where :func:`_step` does (one libm
    sincos per step instead of two; the same bits as without the memo)."""
    if TC[0] != t:
        arg = EX[EX_HEAD + 1] * t + EX[EX_HEAD + 2]
        TC[0] = t
        TC[1] = math.cos(arg)
        TC[2] = math.sin(arg)
    return TC[1], TC[2]


@helper
def track_motion(t, EX, TC):
    """Track wall position h [m], speed h' [m/s] and acceleration h'' [m/s^2] at time t;
    the first harmonic's cos and sin from the phase memo ``TC`` (:func:`_phase`)."""
    h = 0.0
    hd = 0.0
    hdd = 0.0
    for i in range(int(EX[0])):
        a = EX[EX_HEAD + 3 * i]
        w = EX[EX_HEAD + 3 * i + 1]
        if i == 0:
            c, sn = _phase(t, EX, TC)
        else:
            arg = w * t + EX[EX_HEAD + 3 * i + 2]
            c = math.cos(arg)
            sn = math.sin(arg)
        h += a * c
        hd -= a * w * sn
        hdd -= a * w * w * c
    return h, hd, hdd


@helper
def horn_gear_accel(t, P, EX):
    """Horn-gear angular acceleration omega'(t) [rad/s^2] (by a central difference on the
    profile, analytic for the harmonics)."""
    nth = int(EX[0])
    nwh = int(EX[1])
    npf = int(EX[2])
    if npf >= 2:
        dt = 1e-7
        wp, _ = horn_gear(t + dt, P, EX)
        wm, _ = horn_gear(t - dt, P, EX)
        return (wp - wm) / (2.0 * dt)
    acc = 0.0
    o = EX_HEAD + 3 * nth
    for i in range(nwh):
        w = EX[o + 3 * i + 1]
        acc -= EX[o + 3 * i] * w * math.sin(w * t + EX[o + 3 * i + 2])
    return acc


@helper
def _profile_integral(tau, EX, o, npf, period):
    """int of the periodic piecewise-linear omega from the profile start over tau >= 0."""
    k = math.floor(tau / period)
    tau -= k * period
    j = 0
    while j < npf - 2 and EX[o + j + 1] - EX[o] <= tau:
        j += 1
    dt = tau - (EX[o + j] - EX[o])
    w0 = EX[o + npf + j]
    slope = (EX[o + npf + j + 1] - w0) / (EX[o + j + 1] - EX[o + j])
    om = w0 + slope * dt
    return om, k * EX[o + 3 * npf - 1] + EX[o + 2 * npf + j] + w0 * dt + 0.5 * slope * dt * dt


@helper
def horn_gear(t, P, EX):
    """Horn-gear speed omega(t) [rad/s] and slot travel s(t) = r_c int_0^t omega [m]."""
    rc = P[P_RC]
    nth = int(EX[0])
    nwh = int(EX[1])
    npf = int(EX[2])
    if npf >= 2:
        o = EX_HEAD + 3 * nth + 3 * nwh
        period = EX[o + npf - 1] - EX[o]
        om, integral = _profile_integral(t - EX[o], EX, o, npf, period)
        _, integral0 = _profile_integral(-EX[o], EX, o, npf, period)
        return om, rc * (integral - integral0)
    om = P[P_OMEGA0]
    integral = P[P_OMEGA0] * t
    o = EX_HEAD + 3 * nth
    for i in range(nwh):
        a = EX[o + 3 * i]
        w = EX[o + 3 * i + 1]
        ph = EX[o + 3 * i + 2]
        om += a * math.cos(w * t + ph)
        if w > 0.0:
            integral += a / w * (math.sin(w * t + ph) - math.sin(ph))
        else:
            integral += a * math.cos(ph) * t
    return om, rc * integral


# =======================================================================================
# Contact and friction laws
# =======================================================================================


@inline_helper
def friction(v, normal, mu, P):
    """Regularised friction force [N] opposing the sliding speed v (Eq. 14 and variants)."""
    law = int(P[P_FRIC_LAW])
    vhat = P[P_VHAT]
    if law == 0:
        return mu * normal * (2.0 / math.pi) * math.atan(v / vhat)
    if law == 1:
        return mu * normal * math.tanh(v / vhat)
    if law == 2:
        vs = P[P_VSTRIBECK]
        mu_eff = mu * (1.0 + (P[P_MUS_RATIO] - 1.0) * math.exp(-((v / vs) ** 2)))
        return mu_eff * normal * math.tanh(v / vhat)
    return 0.0


@inline_helper
def contact(mode, gap_rel, rate_rel, k, n, d, v0, allow_tension):
    """Penetration, stiffness force, damping force and normal force of one contact pair.

    ``gap_rel`` is the coordinate relative to the wall pair (x - h for the track), ``rate_rel``
    its rate; ``mode`` = -1 (inner wall at 0) or +1 (outer wall at the clearance, passed in
    ``gap_rel`` already shifted). Returns (p, pdot, F_k, F_c, N) with F_k = K p^n >= 0,
    F_c = K p^n D pdot / v0 and N = F_k + F_c clamped at 0 unless tension is allowed.
    """
    if mode < 0:
        p = -gap_rel
        pd = -rate_rel
    else:
        p = gap_rel
        pd = rate_rel
    if p < 0.0:
        p = 0.0
    # the Hertz exponent 3/2 is by far the most common: p sqrt(p) is cheaper than pow
    fk = k * p * math.sqrt(p) if n == 1.5 else k * p**n
    fc = fk * d * pd / v0
    nn = fk + fc
    if nn < 0.0 and allow_tension == 0.0:
        nn = 0.0
    return p, pd, fk, fc, nn


@inline_helper
def pair_state(t, Y, pair, P, EX):
    """Coordinate and rate of the carrier relative to the inner/rear wall of a pair."""
    if pair == 0:
        h, hd = track_h(t, EX)
        return Y[0] - h, Y[1] - hd, P[P_EPS_G]
    om, s = horn_gear(t, P, EX)
    return Y[2] - s, Y[3] - P[P_RC] * om, P[P_EPS_H]


@inline_helper
def pair_forces(t, Y, pair, mode, v0, P, EX):
    """(p, pdot, F_k, F_c, N) of a pair in contact mode ``mode`` (zeros when free)."""
    if mode == 0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    u, ud, eps = pair_state(t, Y, pair, P, EX)
    if mode > 0:
        u = u - eps
    base = P_K_T if pair == 0 else P_K_S
    return contact(mode, u, ud, P[base], P[base + 1], P[base + 2], v0, P[P_ALLOW_TENSION])


# ---- what the step control and the post-processing need of one pair at one instant ------
# (computed once at each end of each accepted step and handed from one step to the next)
INFO_FIELDS = (
    "u",  # carrier coordinate relative to the inner/rear wall [m]
    "u_dot",  # its rate [m/s]
    "u_ddot",  # its second derivative [m/s^2]
    "p",  # penetration into the wall in contact (>= 0; 0 when free) [m]
    "p_dot",  # penetration rate [m/s]
    "p_ddot",  # [m/s^2]
    "F_k",  # stiffness force K p^n [N]
    "F_c",  # damping force K p^n D p' / v0 [N]
    "N",  # normal force [N]
    "N_dot",  # dN/dt [N/s]
    "F_c_dot",  # dF_c/dt [N/s]
)
I_U, I_UD, I_UDD, I_P, I_PD, I_PDD, I_FK, I_FC, I_N, I_DN, I_DFC = range(len(INFO_FIELDS))
NI = len(INFO_FIELDS)


@helper
def pair_info(t, Y, F, pair, mode, v0, P, EX, out, TC):
    """Fill ``out[:NI]`` (see ``INFO_FIELDS``) for one pair in contact mode ``mode``
    (``TC``: the track's phase memo, see :func:`_phase`).

    ``F`` is the time derivative of ``Y`` at t (an RK stage, or the derivative of the
    interpolant); only the accelerations F[1] and F[3] are read. In contact the slopes are

        dN/dt   = K n p^(n-1) p' (1 + D p' / v0) + K p^n D p'' / v0,
        dF_c/dt = D / v0 (K n p^(n-1) p'^2 + K p^n p''),

    with the factor K n p^(n-1) replaced by 1 at p = 0 (only the signs are used there).
    The force terms are those of :func:`contact` (same operations, same bits).
    """
    if pair == 0:
        h, hd, hdd = track_motion(t, EX, TC)
        u = Y[0] - h
        ud = Y[1] - hd
        udd = F[1] - hdd
        eps = P[P_EPS_G]
    else:
        om, s = horn_gear(t, P, EX)
        u = Y[2] - s
        ud = Y[3] - P[P_RC] * om
        udd = F[3] - P[P_RC] * horn_gear_accel(t, P, EX)
        eps = P[P_EPS_H]
    out[I_U] = u
    out[I_UD] = ud
    out[I_UDD] = udd
    if mode == 0:
        for i in range(I_P, NI):
            out[i] = 0.0
        return
    if mode < 0:
        p, pd, pdd = -u, -ud, -udd
    else:
        p, pd, pdd = u - eps, ud, udd
    base = P_K_T if pair == 0 else P_K_S
    p, pd, fk, fc, nn = contact(1, p, pd, P[base], P[base + 1], P[base + 2], v0, P[P_ALLOW_TENSION])
    n = P[base + 1]
    dfk = n * fk / p * pd if p > 0.0 else pd
    d_v0 = P[base + 2] / v0
    out[I_P] = p
    out[I_PD] = pd
    out[I_PDD] = pdd
    out[I_FK] = fk
    out[I_FC] = fc
    out[I_N] = nn
    out[I_DN] = dfk * (1.0 + d_v0 * pd) + fk * d_v0 * pdd
    out[I_DFC] = d_v0 * (dfk * pd + fk * pdd)


@inline_helper
def rhs_track(t, Y, htr, hdtr, mt, ms, v0t, v0s, P, EX, out):
    """Time derivative of the state ``Y`` in the contact modes (mt, ms), the track wall being
    at ``htr`` [m] moving at ``hdtr`` [m/s] (= :func:`track_h` at t)."""
    m = P[P_MASS]
    om, _ = horn_gear(t, P, EX)
    if mt != 0:
        u = Y[0] - htr
        if mt > 0:
            u = u - P[P_EPS_G]
        _, pdt, fkt, _, nt = contact(
            mt, u, Y[1] - hdtr, P[P_K_T], P[P_N_T], P[P_D_T], v0t, P[P_ALLOW_TENSION]
        )
    else:
        pdt = 0.0
        fkt = 0.0
        nt = 0.0
    fx = friction(Y[1], P[P_NX], P[P_MU1], P)
    load_x = P[P_LOAD_X] + P[P_MRC] * om * om
    out[0] = Y[1]
    out[1] = (-mt * nt - fx - load_x) / m
    # energy rates: with p = s (x - wall), pdot = s (vx - hdot), the carrier's energy
    # E = m v^2 / 2 + K p^(n+1) / (n+1) changes at -(N - F_k) pdot - f vx - load vx - s N hdot
    out[4] = (nt - fkt) * pdt
    out[6] = fx * Y[1]
    out[8] = -load_x * Y[1]
    out[9] = -mt * nt * hdtr
    if P[P_DOF] > 1.5:
        track = mt - mt  # 0 as a run-time integer (see the note on literals)
        _, pds, fks, _, ns = pair_forces(t, Y, track + 1, ms, v0s, P, EX)
        fy = friction(Y[3], abs(nt), P[P_MU2], P)
        out[2] = Y[3]
        out[3] = (-ms * ns - fy + P[P_T_Y]) / m
        out[5] = (ns - fks) * pds
        out[7] = fy * Y[3]
        out[10] = P[P_T_Y] * Y[3]
        out[11] = -ms * ns * P[P_RC] * om
    else:
        out[2] = 0.0
        out[3] = 0.0
        out[5] = 0.0
        out[7] = 0.0
        out[10] = 0.0
        out[11] = 0.0


@helper
def rhs(t, Y, mt, ms, v0t, v0s, P, EX, out):
    """Time derivative of the state ``Y`` in the contact modes (mt, ms) (see the equations of
    motion at the top of this module)."""
    htr, hdtr = track_h(t, EX)
    rhs_track(t, Y, htr, hdtr, mt, ms, v0t, v0s, P, EX, out)


@inline_helper
def _sin_cos_small(d):
    """(sin d, cos d); for |d| < 0.1 by their Taylor series to d^9 and d^10 (truncation
    below 3e-19), cheaper than the library calls."""
    if abs(d) < 0.1:
        d2 = d * d
        sn = d * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0 * (1.0 - d2 / 72.0))))
        cs = 1.0 - d2 / 2.0 * (
            1.0 - d2 / 12.0 * (1.0 - d2 / 30.0 * (1.0 - d2 / 56.0 * (1.0 - d2 / 90.0)))
        )
        return sn, cs
    return math.sin(d), math.cos(d)


@inline_helper
def _track_at(c, h, t, rot, amp, w, cb, sb, EX):
    """Track wall (h, h') at the stage time t + c h: for one harmonic a cos(w t + phi) by
    rotating its phase at t (cos, sin = cb, sb) by w c h (steps inside a contact turn the
    phase by less than 0.1 rad, where the rotation needs no library call); else
    :func:`track_h`."""
    if rot:
        sd, cd = _sin_cos_small(w * (c * h))
        return amp * (cb * cd - sb * sd), -amp * w * (sb * cd + cb * sd)
    return track_h(t + c * h, EX)


# =======================================================================================
# Dense output
# =======================================================================================


@inline_helper
def dense_component(theta, RC, i):
    """Component i of the state at fraction theta of the step (continuous extension)."""
    th1 = 1.0 - theta
    return RC[0, i] + theta * (RC[1, i] + th1 * (RC[2, i] + theta * (RC[3, i] + th1 * RC[4, i])))


@inline_helper
def dense_eval(theta, RC, out):
    """State at fraction theta of the step from the continuous extension coefficients."""
    for i in range(NY):
        out[i] = dense_component(theta, RC, i)


@inline_helper
def dense_deriv(theta, h, RC, out):
    """Time derivative of the continuous extension at theta for the four coordinates and
    speeds (d/dtheta of :func:`dense_eval`, divided by the step h); it equals the RK
    derivative at both ends of the step."""
    th1 = 1.0 - theta
    for i in range(4):
        b = RC[3, i] + th1 * RC[4, i]
        c = RC[2, i] + theta * b
        d = RC[1, i] + th1 * c
        out[i] = (d + theta * (th1 * (b - theta * RC[4, i]) - c)) / h


@helper
def event_value(j, t, Y, mt, ms, P, EX):
    """Event function j (>= 0 allowed, < 0 means the event happened); +1 when inactive.

    j = 0, 1: track inner / outer onset (free) or exit (contact on that wall);
    j = 2, 3: the same for the slot (only with two DOFs).
    """
    pair = 0 if j < 2 else 1
    side = -1 if j % 2 == 0 else 1
    mode = mt if pair == 0 else ms
    if pair == 1 and P[P_DOF] < 1.5:
        return 1.0
    u, _, eps = pair_state(t, Y, pair, P, EX)
    if mode == 0:
        return u if side < 0 else eps - u
    if mode != side:
        return 1.0
    return -u if side < 0 else u - eps


# =======================================================================================
# The integrator
# =======================================================================================


@helper
def _step(t, Y, h, K, mt, ms, v0t, v0s, P, EX, Yt, Y1, TC):
    """One Dormand-Prince step of size h from (t, Y) with K[0] = f(t, Y); fills K[1..6], Y1.

    Stage s (1..5) is evaluated at Y + h sum_j A[s, j] K[j]; the solution Y1 uses the row
    A[6] (the 5th-order weights) and K[6] = f(t + h, Y1) is the first stage of the next step.
    """
    # a single-harmonic track (the paper's) is evaluated at the stages by rotating its phase
    rot = EX[0] == 1.0
    amp = EX[EX_HEAD]
    w = EX[EX_HEAD + 1]
    cb = 1.0
    sb = 0.0
    if rot:
        cb, sb = _phase(t, EX, TC)
    for s in range(1, 7):
        Ystage = Y1 if s == 6 else Yt
        for i in range(NY):
            acc = 0.0
            for j in range(s):
                acc += RK_A[s, j] * K[j, i]
            Ystage[i] = Y[i] + h * acc
        ht, hdt = _track_at(RK_C[s], h, t, rot, amp, w, cb, sb, EX)
        rhs_track(t + RK_C[s] * h, Ystage, ht, hdt, mt, ms, v0t, v0s, P, EX, K[s])


@helper
def _error_norm(Y, Y1, h, K, P):
    """RMS of the embedded error estimate scaled by atol + rtol |y| over the active DOFs."""
    rtol = P[P_RTOL]
    nd = 4 if P[P_DOF] > 1.5 else 2
    acc = 0.0
    for i in range(nd):
        atol = P[P_ATOL_X] if i % 2 == 0 else P[P_ATOL_V]
        err = h * (
            E1 * K[0, i] + E3 * K[2, i] + E4 * K[3, i] + E5 * K[4, i] + E6 * K[5, i] + E7 * K[6, i]
        )
        sc = atol + rtol * max(abs(Y[i]), abs(Y1[i]))
        acc += (err / sc) ** 2
    return math.sqrt(acc / nd)


@helper
def _dense_coeffs(Y, Y1, h, K, RC):
    for i in range(NY):
        ydiff = Y1[i] - Y[i]
        bspl = h * K[0, i] - ydiff
        RC[0, i] = Y[i]
        RC[1, i] = ydiff
        RC[2, i] = bspl
        RC[3, i] = ydiff - h * K[6, i] - bspl
        RC[4, i] = h * (
            D1 * K[0, i] + D3 * K[2, i] + D4 * K[3, i] + D5 * K[4, i] + D6 * K[5, i] + D7 * K[6, i]
        )


@helper
def _event_at(j, t0, h, theta, RC, mt, ms, P, EX, Ys):
    dense_eval(theta, RC, Ys)
    return event_value(j, t0 + theta * h, Ys, mt, ms, P, EX)


@helper
def event_active(j, mt, ms, P):
    """Whether event function j can fire in the modes (mt, ms)."""
    pair = 0 if j < 2 else 1
    if pair == 1 and P[P_DOF] < 1.5:
        return False
    side = -1 if j % 2 == 0 else 1
    mode = mt if pair == 0 else ms
    return mode == 0 or mode == side


@helper
def _golden_dip(j, t0, h, a, b, RC, mt, ms, P, EX, Ys):
    """Golden-section search of event function j on [a, b] for a value below zero.

    Returns the first theta found with a negative value, or 2.0 when the minimum is >= 0.
    """
    c = a + GOLD * (b - a)
    d = b - GOLD * (b - a)
    fc = _event_at(j, t0, h, c, RC, mt, ms, P, EX, Ys)
    fd = _event_at(j, t0, h, d, RC, mt, ms, P, EX, Ys)
    for _ in range(80):
        if fc < 0.0:
            return c
        if fd < 0.0:
            return d
        if b - a < 1e-13:
            break
        if fc < fd:
            b = d
            d = c
            fd = fc
            c = a + GOLD * (b - a)
            fc = _event_at(j, t0, h, c, RC, mt, ms, P, EX, Ys)
        else:
            a = c
            c = d
            fc = fd
            d = b - GOLD * (b - a)
            fd = _event_at(j, t0, h, d, RC, mt, ms, P, EX, Ys)
    return 2.0


@helper
def _track_events_possible(h, F0, F1, mt, P, EX, I0, I1):
    """Screen: can a track event (onset in free flight, exit in contact) happen in the step?

    For a function g with |g''| <= A on a step of length h, g >= min(g(0), g(h)) - A h^2 / 8.
    In free flight g is a gap to a wall and A bounds |x''| + |h''| (the load and friction,
    plus 10 % and the full friction swing, and sum |a| w^2 of the vibration); in contact g is
    the penetration and A is twice the larger |p''| at the ends (the contact force varies
    smoothly over the tens of steps a contact takes). Only when the bound does not clear zero
    are the event functions sampled. ``I0``, ``I1``: :func:`pair_info` of the track at the
    two ends of the step.
    """
    if mt == 0:
        u0 = I0[I_U]
        u1 = I1[I_U]
        eps = P[P_EPS_G]
        acc = (
            1.1 * max(abs(F0[1]), abs(F1[1]))
            + 2.0 * P[P_MU1] * P[P_NX] / P[P_MASS]
            + track_accel_bound(EX)
        )
        margin = acc * h * h / 8.0
        return min(u0, u1) <= margin or min(eps - u0, eps - u1) <= margin
    margin = 2.0 * max(abs(I0[I_PDD]), abs(I1[I_PDD])) * h * h / 8.0
    return min(I0[I_P], I1[I_P]) <= margin


@helper
def _sample_events(t0, h, RC, mt, ms, P, EX, Ys, GS, F0, F1, I0, I1):
    """Event functions at the N_SUB + 1 equally spaced points of the step (GS[j, k]).

    A pair whose events the screen :func:`_track_events_possible` rules out is not sampled
    (its rows are +1). Returns False when nothing needs sampling.
    """
    track_on = _track_events_possible(h, F0, F1, mt, P, EX, I0, I1)
    slot_on = P[P_DOF] > 1.5
    if not (track_on or slot_on):
        return False
    for k in range(N_SUB + 1):
        dense_eval(k / N_SUB, RC, Ys)
        tk = t0 + k / N_SUB * h
        for pair in range(2):
            j0 = 2 * pair
            on = track_on if pair == 0 else slot_on
            a0 = on and event_active(j0, mt, ms, P)
            a1 = on and event_active(j0 + 1, mt, ms, P)
            if not (a0 or a1):
                GS[j0, k] = 1.0
                GS[j0 + 1, k] = 1.0
                continue
            # one evaluation of the relative coordinate serves both walls of the pair
            u, _, eps = pair_state(tk, Ys, pair, P, EX)
            mode = mt if pair == 0 else ms
            if mode == 0:
                GS[j0, k] = u if a0 else 1.0
                GS[j0 + 1, k] = eps - u if a1 else 1.0
            else:
                GS[j0, k] = -u if a0 else 1.0
                GS[j0 + 1, k] = u - eps if a1 else 1.0
    return True


@helper
def _locate_event(j, t0, h, RC, mt, ms, P, EX, Ys, GS):
    """Earliest theta in (0, 1] where event function j turns negative; 2.0 when none.

    Uses the samples GS[j] (see :func:`_sample_events`); a sign change is refined by the
    Illinois method, an interior local minimum of the samples by golden section (a contact
    between two samples).
    """
    if not event_active(j, mt, ms, P):
        return 2.0
    gs = GS[j]
    gs[0] = max(gs[0], 0.0)
    lo = -1.0
    hi = -1.0
    for k in range(1, N_SUB + 1):
        if gs[k] < 0.0:
            lo = (k - 1) / N_SUB
            hi = k / N_SUB
            break
        if (
            k < N_SUB
            and gs[k] < gs[k - 1]
            and gs[k] <= gs[k + 1]
            and gs[k] < max(gs[k - 1] - gs[k], gs[k + 1] - gs[k])
        ):
            # interior local minimum of the samples, close enough to zero that the function
            # could dip below it between the samples: golden section for that dip
            dip = _golden_dip(j, t0, h, (k - 1) / N_SUB, (k + 1) / N_SUB, RC, mt, ms, P, EX, Ys)
            if dip < 2.0:
                lo = (k - 1) / N_SUB
                hi = dip
                break
    if hi < 0.0:
        return 2.0
    # Illinois on [lo, hi] with g(lo) >= 0 > g(hi)
    glo = max(_event_at(j, t0, h, lo, RC, mt, ms, P, EX, Ys), 0.0)
    ghi = _event_at(j, t0, h, hi, RC, mt, ms, P, EX, Ys)
    side = 0
    for _ in range(200):
        if hi - lo <= 1e-15 * max(1.0, abs(t0) / max(h, 1e-300)) or hi - lo < 1e-16:
            break
        denom = glo - ghi
        mid = hi - ghi * (hi - lo) / denom if denom > 0.0 else 0.5 * (lo + hi)
        if not (lo < mid < hi):
            mid = 0.5 * (lo + hi)
        gm = _event_at(j, t0, h, mid, RC, mt, ms, P, EX, Ys)
        if gm < 0.0:
            hi = mid
            ghi = gm
            if side == -1:
                glo *= 0.5
            side = -1
        else:
            lo = mid
            glo = gm
            if side == 1:
                ghi *= 0.5
            side = 1
    return hi


@helper
def _write_row(rows, nrow, t, Y, mt, ms, v0t, v0s, kind, P, EX):
    """Append one row of the sampled series (state plus derived contact quantities)."""
    if kind != KIND_SAMPLE and P[P_RECORD_EVENTS] == 0.0:
        return nrow
    if nrow >= rows.shape[0]:
        return nrow + 1
    r = rows[nrow]
    r[0] = t
    for i in range(4):
        r[1 + i] = Y[i]
    for pair in range(2):
        mode = mt if pair == 0 else ms
        v0 = v0t if pair == 0 else v0s
        p, _, fk, fc, nn = pair_forces(t, Y, pair, mode, v0, P, EX)
        sgn = float(mode)
        r[5 + 4 * pair] = sgn * p
        r[6 + 4 * pair] = sgn * fk
        r[7 + 4 * pair] = sgn * fc
        r[8 + 4 * pair] = sgn * nn
    _, _, _, _, nt = pair_forces(t, Y, mt - mt, mt, v0t, P, EX)
    r[13] = friction(Y[1], P[P_NX], P[P_MU1], P)
    r[14] = friction(Y[3], abs(nt), P[P_MU2], P) if P[P_DOF] > 1.5 else 0.0
    for i in range(8):
        r[15 + i] = Y[4 + i]
    h, _ = track_h(t, EX)
    om, s = horn_gear(t, P, EX)
    r[23] = h
    r[24] = s
    r[25] = om
    r[26] = kind
    return nrow + 1


@inline_helper
def _fold_values(t, pair, vals, WIN, RANGES):
    """Fold one pair's (depth, F_kg, F_cg, contact force) at time t into the [min, max] of
    each window containing t: RANGES[w, pair, q, 0/1]."""
    for w in range(WIN.shape[0]):
        if WIN[w, 0] <= t <= WIN[w, 1]:
            for q in range(4):
                v = vals[q]
                if v < RANGES[w, pair, q, 0]:
                    RANGES[w, pair, q, 0] = v
                if v > RANGES[w, pair, q, 1]:
                    RANGES[w, pair, q, 1] = v


@helper
def _update_ranges(t, Y, mt, ms, v0t, v0s, P, EX, WIN, RANGES):
    """Fold the contact quantities at time t into the [min, max] of each window containing t.

    RANGES[w, pair, q, 0/1] with q = 0 depth, 1 F_kg, 2 F_cg, 3 contact force (paper signs).
    """
    for pair in range(2):
        mode = mt if pair == 0 else ms
        v0 = v0t if pair == 0 else v0s
        p, _, fk, fc, nn = pair_forces(t, Y, pair, mode, v0, P, EX)
        sgn = float(mode)
        _fold_values(t, pair, (sgn * p, sgn * fk, sgn * fc, sgn * nn), WIN, RANGES)


@inline_helper
def _fold_ranges(t, pair, mode, info, WIN, RANGES):
    """:func:`_update_ranges` for one pair from its :func:`pair_info` at time t."""
    sgn = float(mode)
    vals = (sgn * info[I_P], sgn * info[I_FK], sgn * info[I_FC], sgn * info[I_N])
    if mode == 0:
        vals = (0.0, 0.0, 0.0, 0.0)
    _fold_values(t, pair, vals, WIN, RANGES)


@inline_helper
def _extreme_value(kind, info):
    """The quantity tracked for extremes: kind 0 p, 1 F_c, 2 -F_c (its minimum), 3 N."""
    if kind == 0:
        return info[I_P]
    if kind == 1:
        return info[I_FC]
    if kind == 2:
        return -info[I_FC]
    return info[I_N]


@inline_helper
def _extreme_slope(kind, info):
    """Time derivative of :func:`_extreme_value`."""
    if kind == 0:
        return info[I_PD]
    if kind == 1:
        return info[I_DFC]
    if kind == 2:
        return -info[I_DFC]
    return info[I_DN]


@helper
def _refine_extreme(kind, pair, mode, v0, t0, h, g0, g1, RC, P, EX, Ys, Yd, info, TC):
    """The maximum inside the step of quantity ``kind`` (see :func:`_extreme_slope`), whose
    slope goes from g0 > 0 at the start to g1 <= 0 at the end.

    The slope is evaluated on the interpolant (state from :func:`dense_eval`, accelerations
    from :func:`dense_deriv`, which match the RK derivatives at the ends) and its zero found
    by the Illinois method. Returns theta and leaves the pair's :func:`pair_info` there in
    ``info`` and the state in ``Ys``.
    """
    lo = 0.0
    hi = 1.0
    glo = g0
    ghi = g1
    side = 0
    for _ in range(100):
        if hi - lo <= 1e-12:
            break
        denom = glo - ghi
        mid = lo + glo * (hi - lo) / denom if denom > 0.0 else 0.5 * (lo + hi)
        if not (lo < mid < hi):
            mid = 0.5 * (lo + hi)
        dense_eval(mid, RC, Ys)
        dense_deriv(mid, h, RC, Yd)
        pair_info(t0 + mid * h, Ys, Yd, pair, mode, v0, P, EX, info, TC)
        gm = _extreme_slope(kind, info)
        if gm == 0.0:
            return mid
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
    dense_eval(theta, RC, Ys)
    dense_deriv(theta, h, RC, Yd)
    pair_info(t0 + theta * h, Ys, Yd, pair, mode, v0, P, EX, info, TC)
    return theta


@inline_helper
def _episode_update(EP, ie, q, val, t):
    """Fold a value of quantity q (per pair) into the open episode ie."""
    kind = q % 4
    if kind == 0:
        if val > EP[ie, 7]:
            EP[ie, 7] = val
            EP[ie, 8] = t
    elif kind == 1:
        if val > EP[ie, 12]:
            EP[ie, 12] = val
        if val < EP[ie, 11]:
            EP[ie, 11] = val
    elif kind == 2:
        if -val < EP[ie, 11]:
            EP[ie, 11] = -val
        if -val > EP[ie, 12]:
            EP[ie, 12] = -val
    else:
        if val > EP[ie, 9]:
            EP[ie, 9] = val
            EP[ie, 10] = t


@helper
def _scan_step(
    t0,
    h,
    RC,
    mt,
    ms,
    v0t,
    v0s,
    open_ep,
    EP,
    P,
    EX,
    WIN,
    RANGES,
    XSQ,
    rows,
    nrow,
    ST,
    isamp,
    Ys,
    Yd,
    I0,
    I1,
    IX,
    TC,
):
    """Post-process an accepted (sub)step [t0, t0 + h]: samples, extremes, ranges, peaks,
    the windows' integrals of x^2.

    ``I0`` and ``I1`` hold the :func:`pair_info` of both pairs at the two ends of the step;
    ``IX`` is work space, ``TC`` the track's phase memo.
    """
    t1 = t0 + h
    # sampled series
    while isamp < ST.shape[0] and ST[isamp] <= t1:
        if ST[isamp] > t0:
            theta = (ST[isamp] - t0) / h if h > 0 else 1.0
            dense_eval(theta, RC, Ys)
            nrow = _write_row(rows, nrow, ST[isamp], Ys, mt, ms, v0t, v0s, KIND_SAMPLE, P, EX)
        isamp += 1
    # int x^2 dt over the part of the step inside each window (Gauss-Legendre on the
    # interpolant), for the RMS of x
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
        _fold_ranges(t1, 0, mt, I1[0], WIN, RANGES)
        _fold_ranges(t1, 1, ms, I1[1], WIN, RANGES)
        for w in range(WIN.shape[0]):
            for e in range(2):
                tb = WIN[w, e]
                if t0 < tb < t1:
                    dense_eval((tb - t0) / h, RC, Ys)
                    _update_ranges(tb, Ys, mt, ms, v0t, v0s, P, EX, WIN, RANGES)
    if mt == 0 and ms == 0:
        return nrow, isamp
    # Extremes inside the step for each pair in contact. The sign of each quantity's time
    # derivative at the two ends of the step tells whether a maximum (or a minimum of F_c)
    # lies inside; only then is it located, by a root of the slope on the interpolant.
    # Steps resolve a contact in tens of steps, so a quantity does not turn twice in a step.
    for pair in range(2):
        mode = mt if pair == 0 else ms
        if mode == 0:
            continue
        ie = open_ep[pair]
        v0 = v0t if pair == 0 else v0s
        a0 = I0[pair]
        a1 = I1[pair]
        if ie >= 0:
            _episode_update(EP, ie, 4 * pair, a1[I_P], t1)
            _episode_update(EP, ie, 4 * pair + 1, a1[I_FC], t1)
            _episode_update(EP, ie, 4 * pair + 3, a1[I_N], t1)
        for kind in range(4):
            g0 = _extreme_slope(kind, a0)
            g1 = _extreme_slope(kind, a1)
            if not (g0 > 0.0 and g1 <= 0.0):
                continue
            theta = _refine_extreme(kind, pair, mode, v0, t0, h, g0, g1, RC, P, EX, Ys, Yd, IX, TC)
            tq = t0 + theta * h
            val = _extreme_value(kind, IX)
            q = 4 * pair + kind
            if ie >= 0:
                _episode_update(EP, ie, q, val, tq)
            _fold_ranges(tq, pair, mode, IX, WIN, RANGES)
            if kind == 0 or kind == 3:
                nrow = _write_row(rows, nrow, tq, Ys, mt, ms, v0t, v0s, KIND_PEAK, P, EX)
    return nrow, isamp


@helper
def _pair_infos(t, Y, F, mt, ms, v0t, v0s, P, EX, INF, TC):
    """:func:`pair_info` of the track (INF[0]) and, with two DOFs, of the slot (INF[1])."""
    track = mt - mt  # 0 as a run-time integer (see the note on literals)
    pair_info(t, Y, F, track, mt, v0t, P, EX, INF[0], TC)
    if P[P_DOF] > 1.5:
        pair_info(t, Y, F, track + 1, ms, v0s, P, EX, INF[1], TC)


@helper
def _open_episode(EP, nep, t, pair, wall, vel, v0, initial):
    if nep >= EP.shape[0]:
        return nep + 1
    e = EP[nep]
    e[0] = t
    e[1] = math.nan
    e[2] = pair
    e[3] = wall
    e[4] = vel
    e[5] = v0
    e[6] = math.nan
    e[7] = 0.0
    e[8] = t
    e[9] = 0.0
    e[10] = t
    e[11] = 0.0
    e[12] = 0.0
    e[13] = 0.0
    e[14] = 1.0
    e[15] = initial
    return nep + 1


@helper
def _episode_start_values(EP, ie, t, Y, pair, mode, v0, P, EX):
    """Fold the depth and forces at the first instant of an episode into its extremes (a
    contact present at the start may have its largest force right there)."""
    p, _, _, fc, nn = pair_forces(t, Y, pair, mode, v0, P, EX)
    _episode_update(EP, ie, 4 * pair, p, t)
    _episode_update(EP, ie, 4 * pair + 1, fc, t)
    _episode_update(EP, ie, 4 * pair + 3, nn, t)


@helper
def _start_contacts(t, Y, mt_ms, v0s_arr, open_ep, EP, nep, ED, npair, P, EX):
    """Contact policy at t = 0 and right after a transfer.

    A pair whose carrier overlaps a wall starts in contact. Such a contact has no approach
    speed; by default it is released elastically (v0 = inf, so the damping term vanishes until
    the next onset), which reproduces the paper's sections 3.3-3.4 (MODEL_NOTES section 4);
    ``contact.initial_impact_velocity`` gives a finite v0 instead. A carrier exactly on a
    wall and moving into it starts in contact with its approach rate latched (floored at
    ``contact.min_impact_velocity``), as after a transfer (section 3.2).
    """
    for pair in range(npair):
        u, ud, eps = pair_state(t, Y, pair, P, EX)
        mode = 0
        p = 0.0
        pd = 0.0
        if u < 0.0 or (u == 0.0 and ud < 0.0):
            mode = -1
            p = -u
            pd = -ud
        elif u > eps or (u == eps and ud > 0.0):
            mode = 1
            p = u - eps
            pd = ud
        if mode == 0:
            mt_ms[pair] = 0
            continue
        if p > 0.0:
            # an overlap with no approach history: released elastically (v0 = inf, no damping
            # term) unless contact.initial_impact_velocity gives a speed
            v0 = P[P_VINIT] if P[P_VINIT] > 0.0 else math.inf
        else:
            v0 = pd if pd > P[P_VMIN] else P[P_VMIN]
        mt_ms[pair] = mode
        v0s_arr[pair] = v0
        nep_new = _open_episode(EP, nep, t, pair, mode, pd, v0, 1.0 if p > 0.0 else 0.0)
        if nep < EP.shape[0]:
            open_ep[pair] = nep
            EP[nep, 13] = ED[pair]
            _episode_start_values(EP, nep, t, Y, pair, mode, v0, P, EX)
        nep = nep_new
    return nep


# nogil: the kernel touches no Python object, so it releases the GIL and runs of a batch
# overlap on threads (braidsim.batch)
@njit(cache=True, error_model="numpy", nogil=True)
def integrate(Y0, P, EX, TR, WIN, ST, rows, EP, RANGES, XSQ, STATS):
    """Integrate from t = 0 to P[P_T_END]; returns (status, number of rows, number of episodes).

    Outputs are written into the preallocated ``rows`` (series), ``EP`` (episodes),
    ``RANGES`` (window extremes, initialised by the caller to +inf/-inf), ``XSQ`` (the
    integral of x^2 dt over each window [m^2 s], from a Gauss-Legendre rule on the
    interpolant of every step: exact up to the integrator's own error) and ``STATS``.
    A status of ST_CAPACITY_* asks the caller to retry with larger arrays.
    """
    if (
        Y0.shape[0] != NY
        or P.shape[0] < P_SIZE
        or STATS.shape[0] < N_STATS
        or rows.shape[1] != NCOL
        or EP.shape[1] != NEP
        or RANGES.shape[0] != WIN.shape[0]
        or XSQ.shape[0] != WIN.shape[0]
    ):
        return ST_BAD_ARRAYS, 0, 0
    t_end = P[P_T_END]
    hmax = P[P_HMAX]
    max_steps = int(P[P_MAXSTEPS])
    Y = Y0.copy()
    Y1 = np.empty(NY)
    Yt = np.empty(NY)
    Ys = np.empty(NY)
    Yd = np.empty(NY)
    Ye = np.empty(NY)
    INF0 = np.zeros((2, NI))  # pair_info at the start of the step (the end of the last one)
    INF1 = np.zeros((2, NI))  # ... at its end
    IX = np.zeros(NI)
    TC = np.full(3, math.nan)  # phase memo of the track's first harmonic (see _phase)
    K = np.empty((7, NY))
    Ke = np.empty((7, NY))
    RC = np.empty((5, NY))
    GS = np.empty((4, N_SUB + 1))
    modes = np.zeros(2, dtype=np.int64)
    v0 = np.ones(2)
    open_ep = -np.ones(2, dtype=np.int64)
    ED = np.zeros(2)
    nrow = rows.shape[0] - rows.shape[0]  # 0 as a run-time integer
    nep = nrow
    isamp = 0
    itr = 0
    t = P[P_T_START]
    ED[0] = Y[4]
    ED[1] = Y[5]
    status = ST_OK
    for i in range(STATS.shape[0]):
        STATS[i] = 0.0
    for w in range(XSQ.shape[0]):
        XSQ[w] = 0.0
    STATS[5] = math.inf

    if P[P_INIT_GIVEN] > 0.5:
        # a restart: the contact modes and latched speeds carry over from an earlier run
        modes[0] = int(P[P_INIT_MODE_T])
        modes[1] = int(P[P_INIT_MODE_S])
        v0[0] = P[P_INIT_V0_T]
        v0[1] = P[P_INIT_V0_S]
        for pair in range(2):
            if modes[pair] != 0:
                if nep < EP.shape[0]:
                    open_ep[pair] = nep
                nep = _open_episode(EP, nep, t, pair, modes[pair], math.nan, v0[pair], 1.0)
                if open_ep[pair] >= 0:
                    EP[open_ep[pair], 13] = Y[4 + pair]
                    _episode_start_values(
                        EP, open_ep[pair], t, Y, pair, modes[pair], v0[pair], P, EX
                    )
    else:
        nep = _start_contacts(
            t, Y, modes, v0, open_ep, EP, nep, ED, 2 if P[P_DOF] > 1.5 else 1, P, EX
        )
    nrow = _write_row(rows, nrow, t, Y, modes[0], modes[1], v0[0], v0[1], KIND_START, P, EX)
    _update_ranges(t, Y, modes[0], modes[1], v0[0], v0[1], P, EX, WIN, RANGES)
    while isamp < ST.shape[0] and ST[isamp] <= t:
        if ST[isamp] == t:
            nrow = _write_row(
                rows, nrow, t, Y, modes[0], modes[1], v0[0], v0[1], KIND_SAMPLE, P, EX
            )
        isamp += 1
    while itr < TR.shape[0] and TR[itr] <= t:
        itr += 1

    rhs(t, Y, modes[0], modes[1], v0[0], v0[1], P, EX, K[0])
    _pair_infos(t, Y, K[0], modes[0], modes[1], v0[0], v0[1], P, EX, INF0, TC)
    STATS[3] += 1
    h = min(1e-6, hmax, t_end - t)
    nsteps = 0
    same_time_events = 0
    last_event_t = -1.0
    stiff_run = 0
    nonstiff_run = 0
    err_old = 1e-4
    # error exponent of the first step of a contact: the force K p^n grows as s^n after onset,
    # so that step's error scales as h^(n+1), not h^5 (0: no contact step pending)
    onset_q = 0.0
    while t < t_end:
        if nsteps >= max_steps:
            status = ST_MAX_STEPS
            break
        while itr < TR.shape[0] and TR[itr] <= t:
            # transfer to the next horn gear: the wall the carrier leans on becomes the far wall
            itr += 1
            STATS[4] += 1
            for pair in range(1):
                ie = open_ep[pair]
                if ie >= 0:
                    EP[ie, 1] = t
                    EP[ie, 13] = ED[pair] - EP[ie, 13]
                    EP[ie, 14] = 2.0
                    open_ep[pair] = -1
            hh, hd = track_h(t, EX)
            xr = Y[0] - hh
            eps = P[P_EPS_G]
            if xr < 0.0:
                xr = 0.0
            if xr > eps:
                xr = eps
            Y[0] = hh + eps - xr
            Y[1] = 2.0 * hd - Y[1] + P[P_TRANSFER_SPEED]
            modes[0] = 0
            nrow = _write_row(
                rows, nrow, t, Y, modes[0], modes[1], v0[0], v0[1], KIND_TRANSFER, P, EX
            )
            nep = _start_contacts(t, Y, modes, v0, open_ep, EP, nep, ED, nrow - nrow + 1, P, EX)
            rhs(t, Y, modes[0], modes[1], v0[0], v0[1], P, EX, K[0])
            _pair_infos(t, Y, K[0], modes[0], modes[1], v0[0], v0[1], P, EX, INF0, TC)
            STATS[3] += 1
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
        _step(t, Y, h, K, modes[0], modes[1], v0[0], v0[1], P, EX, Yt, Y1, TC)
        STATS[3] += 6
        nsteps += 1
        err = _error_norm(Y, Y1, h, K, P)
        finite = True
        for i in range(NY):
            if not math.isfinite(Y1[i]):
                finite = False
        if not finite or not math.isfinite(err):
            if h < 1e-14 * max(1.0, t):
                status = ST_NONFINITE
                break
            h *= 0.1
            hits_stop = False
            STATS[1] += 1
            continue
        if err > 1.0:
            if onset_q > 0.0:
                fac = max(0.02, 0.9 * err ** (-1.0 / onset_q))
            else:
                fac = max(0.2, 0.9 * err ** (-0.2))
            h *= fac
            STATS[1] += 1
            continue
        # stiffness detection (Hairer & Wanner's test in DOPRI5): h * |lambda| estimated from the
        # last two stages; a long run of steps on the stability boundary means the explicit
        # method is crawling
        nd = 4 if P[P_DOF] > 1.5 else 2
        stnum = 0.0
        stden = 0.0
        for i in range(nd):
            stnum += (K[6, i] - K[5, i]) ** 2
            stden += (Y1[i] - Yt[i]) ** 2
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
        _dense_coeffs(Y, Y1, h, K, RC)
        _pair_infos(t + h, Y1, K[6], modes[0], modes[1], v0[0], v0[1], P, EX, INF1, TC)
        # ---- events on the interpolant
        theta_ev = 2.0
        j_ev = -1
        if _sample_events(
            t, h, RC, modes[0], modes[1], P, EX, Ys, GS, K[0], K[6], INF0[0], INF1[0]
        ):
            for j in range(4):
                th = _locate_event(j, t, h, RC, modes[0], modes[1], P, EX, Ys, GS)
                if th < theta_ev:
                    theta_ev = th
                    j_ev = j
        if j_ev >= 0:
            # recompute the step exactly to the event time
            he = theta_ev * h
            if he <= 0.0:
                he = 1e-16 * max(1.0, t)
            for i in range(NY):
                Ke[0, i] = K[0, i]
            _step(t, Y, he, Ke, modes[0], modes[1], v0[0], v0[1], P, EX, Yt, Ye, TC)
            STATS[3] += 6
            _dense_coeffs(Y, Ye, he, Ke, RC)
            _pair_infos(t + he, Ye, Ke[6], modes[0], modes[1], v0[0], v0[1], P, EX, INF1, TC)
            h_taken = he
        else:
            h_taken = h
        # post-process the step taken (to the event, or whole): samples, extremes, ranges
        nrow, isamp = _scan_step(
            t,
            h_taken,
            RC,
            modes[0],
            modes[1],
            v0[0],
            v0[1],
            open_ep,
            EP,
            P,
            EX,
            WIN,
            RANGES,
            XSQ,
            rows,
            nrow,
            ST,
            isamp,
            Ys,
            Yd,
            INF0,
            INF1,
            IX,
            TC,
        )
        STATS[0] += 1
        STATS[5] = min(STATS[5], h_taken)
        if j_ev >= 0:
            t_ev = t + h_taken
            for i in range(NY):
                Y[i] = Ye[i]
            ED[0] = Y[4]
            ED[1] = Y[5]
            pair = 0 if j_ev < 2 else 1
            side = -1 if j_ev % 2 == 0 else 1
            _, ud, _ = pair_state(t_ev, Y, pair, P, EX)
            rate = -ud if side < 0 else ud  # penetration rate into this wall
            if modes[pair] == 0:
                # onset: latch the approach speed
                vlat = rate if rate > P[P_VMIN] else P[P_VMIN]
                modes[pair] = side
                v0[pair] = vlat
                nep_new = _open_episode(EP, nep, t_ev, pair, side, rate, vlat, 0.0)
                if nep < EP.shape[0]:
                    open_ep[pair] = nep
                    EP[nep, 13] = ED[pair]
                nep = nep_new
                nrow = _write_row(
                    rows, nrow, t_ev, Y, modes[0], modes[1], v0[0], v0[1], KIND_ONSET, P, EX
                )
                # start the contact with a step of about 1/12 of its duration estimated from
                # the elastic closed form (p_m from the approach speed, T ~ 3 p_m / v)
                base = P_K_T if pair == 0 else P_K_S
                n1 = P[base + 1] + 1.0
                p_m = (n1 * P[P_MASS] * vlat * vlat / (2.0 * P[base])) ** (1.0 / n1)
                h = min(h, 0.25 * p_m / vlat)
                onset_q = n1
            else:
                # exit
                nrow = _write_row(
                    rows, nrow, t_ev, Y, modes[0], modes[1], v0[0], v0[1], KIND_EXIT, P, EX
                )
                ie = open_ep[pair]
                if ie >= 0:
                    EP[ie, 1] = t_ev
                    EP[ie, 6] = -rate
                    EP[ie, 13] = ED[pair] - EP[ie, 13]
                    EP[ie, 14] = 0.0
                open_ep[pair] = -1
                modes[pair] = 0
            _update_ranges(t_ev, Y, modes[0], modes[1], v0[0], v0[1], P, EX, WIN, RANGES)
            STATS[2] += 1
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
            rhs(t, Y, modes[0], modes[1], v0[0], v0[1], P, EX, K[0])
            _pair_infos(t, Y, K[0], modes[0], modes[1], v0[0], v0[1], P, EX, INF0, TC)
            STATS[3] += 1
            continue
        # ---- accepted step without event
        STATS[6] = max(STATS[6], h)
        t = t_stop if hits_stop else t + h
        for i in range(NY):
            Y[i] = Y1[i]
            K[0, i] = K[6, i]
        INF0, INF1 = INF1, INF0
        ED[0] = Y[4]
        ED[1] = Y[5]
        h = h_next
    STATS[7] = t
    STATS[8] = modes[0]
    STATS[9] = modes[1]
    STATS[10] = v0[0]
    STATS[11] = v0[1]
    if status == ST_OK:
        nrow = _write_row(rows, nrow, t, Y, modes[0], modes[1], v0[0], v0[1], KIND_END, P, EX)
        for pair in range(2):
            ie = open_ep[pair]
            if ie >= 0:
                EP[ie, 1] = t
                EP[ie, 13] = Y[4 + pair] - EP[ie, 13]
                EP[ie, 14] = 1.0
        if nrow > rows.shape[0]:
            status = ST_CAPACITY_ROWS
        elif nep > EP.shape[0]:
            status = ST_CAPACITY_EPISODES
    for i in range(NY):
        Y0[i] = Y[i]
    return status, nrow, nep
