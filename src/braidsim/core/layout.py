"""The named records at the boundary of the compiled core.

Everything that crosses between Python and the compiled solver is named here: the solver
options, the impact (episode) rows, the run statistics, the restart state and the codes
(status, series row kinds, contact sides). numba reads a field of a structured array
(``EP[i].peak_force``) or of a ``NamedTuple`` (``opts.rtol``) at a fixed offset, at the speed
of a raw index, so no code outside this module needs to know a column number.

Physical parameters are records too, but they belong to the model that uses them (see
:mod:`braidsim.core.models`); this module holds what every model shares.
"""

from __future__ import annotations

import struct
from collections import namedtuple
from typing import Any, NamedTuple

import numpy as np

from braidsim.core.interfaces import TAYLOR_ROWS

# ---- status codes of a run ----------------------------------------------------------------
ST_OK = 0  # reached the end time
ST_STEP_COLLAPSE = 1  # the step size fell below round-off
ST_NONFINITE = 2  # the state became NaN or infinite
ST_MAX_STEPS = 3  # the step budget was spent
ST_ROWS_FULL = 4  # the series buffer is full: flush it and resume (not a failure)
ST_EPISODES_FULL = 5  # the impact table is full: flush it and resume (not a failure)
ST_ZENO = 6  # more than 50 contact events at one instant
ST_STIFF = 7  # steps held by stability for STIFF_LIMIT steps
ST_BAD_ARRAYS = 8  # an array of the wrong size was passed (a caller bug, never user input)
ST_GRAZING = 9  # sensitivities asked of a run with a grazing contact (event sequence not smooth)
ST_PAUSED = 10  # the driver's: a call's share of steps done, resume (not a failure)
# The driver has the compiled loop hand control back to Python after this many step attempts
# (it shifts the record's count of attempts so that the loop meets its budget there), so that
# a signal (Ctrl-C, SIGTERM) is acted on during a long run whose buffers never fill (a carrier
# at rest writes no impact rows): every 0.02 s of CPU on paper-3.1, 0.2 s with two
# sensitivities. Resuming changes no bit. (Keep it far above 1: a pause right after a refused
# Taylor step has the resumed loop take that step again.)
PAUSE_STEPS = 50_000
STIFF_LIMIT = 100_000  # accepted steps held by stability (few breaks) before giving up
# A step held by stability counts towards STIFF_LIMIT only below this fraction of the maximum
# step: above it the explicit method is slowed by at most that factor, and is not crawling (a
# carrier at rest on a still wall sits on the stability boundary at about the maximum step,
# and paper-3.1 stopped at t = 132.8 s after 100,000 such steps of ~0.6 ms)
STIFF_STEP_FRACTION = 0.01

# ---- kinds of the rows of the sampled series -----------------------------------------------
# (floats: the kind is a column of the float series array)
KIND_SAMPLE, KIND_ONSET, KIND_EXIT, KIND_PEAK, KIND_TRANSFER, KIND_START, KIND_END = (
    float(k) for k in range(7)
)
KIND_NAMES = ("sample", "onset", "exit", "peak", "transfer", "start", "end")

# ---- contact sides (the mode of a pair) -----------------------------------------------------
FREE = 0
INNER = -1  # the inner (track) or rear (slot) wall: the coordinate's lower bound
OUTER = 1  # the outer (track) or front (slot) wall: its upper bound

# ---- why an episode ended ---------------------------------------------------------------
END_EXIT = 0.0  # the carrier left the wall
END_ONGOING = 1.0  # still in contact at the end of the run
END_TRANSFER = 2.0  # cut by a transfer to the next horn gear

MAX_PAIRS = 2  # contact pairs a model may have (track and slot)


class SolverOptions(NamedTuple):
    """How the solver integrates (not what: that is the model).

    Attributes
    ----------
    rtol : float
        Relative tolerance of the embedded error estimate [-].
    atol_position, atol_velocity : float
        Absolute tolerances on coordinates [m] and speeds [m/s].
    max_step : float
        Largest step [s].
    max_steps : int
        Step budget of the run (accepted and rejected steps).
    t_end : float
        End time [s].
    record_events : bool
        Write the exact onset, exit, peak and transfer states into the series.
    energy : bool
        Integrate the energy quadratures (work of every force) with the motion.
    quadratures : int
        With ``energy``: how many of the model's quadratures to integrate, counted from the
        first; -1 all of them. Every model orders its quadratures so that two shorter
        prefixes mean something: the energy each contact pair dissipates (n_pairs, what the
        impact table reports: the lean path), then the friction work along each coordinate
        as well (n_pairs + n_coords, what the batch metrics read). The works not integrated
        are not in the state (the series gives them as NaN).
    """

    rtol: float
    atol_position: float
    atol_velocity: float
    max_step: float
    max_steps: int
    t_end: float
    record_events: bool = True
    energy: bool = True
    quadratures: int = -1


class ImplicitWork(NamedTuple):
    """The work arrays of the implicit (Radau IIA) step of resting contacts
    (:mod:`braidsim.core.solver.radau`), for a state of n components of which m = 2 n_coords
    are coordinates and speeds; ``None`` in their place compiles the step out.

    Attributes
    ----------
    J : array (n, m)
        df/dy over the coordinates and speeds.
    LUR, LUC : arrays (m, m), (2 m, 2 m)
        LU factors of the real system and of the complex one in real form.
    pivr, pivc : int arrays (m,), (2 m,)
        Their pivots.
    Z, W : arrays (3, n)
        The stages' increments and their transform.
    B : array (4, n)
        Newton increments and scratch.
    V : array (2 m,)
        Scratch of the complex solve.
    scale : array (m,)
        atol + rtol |y| of the Newton and error norms.
    Q : array (3, n)
        The collocation polynomial y + Q_1 theta + Q_2 theta^2 + Q_3 theta^3 of the last
        accepted implicit step, whose extrapolation starts the next step's Newton iterations
        (valid while the restart record's ``implicit_prev_h`` is not 0).
    """

    J: np.ndarray
    LUR: np.ndarray
    LUC: np.ndarray
    pivr: np.ndarray
    pivc: np.ndarray
    Z: np.ndarray
    W: np.ndarray
    B: np.ndarray
    V: np.ndarray
    scale: np.ndarray
    Q: np.ndarray


def implicit_work(n: int, m: int) -> ImplicitWork:
    """Work arrays of the implicit step for n state components, m coordinates and speeds."""
    return ImplicitWork(
        np.empty((n, m)),
        np.empty((m, m)),
        np.empty((2 * m, 2 * m)),
        np.empty(m, dtype=np.int64),
        np.empty(2 * m, dtype=np.int64),
        np.empty((3, n)),
        np.empty((3, n)),
        np.empty((4, n)),
        np.empty(2 * m),
        np.empty(m),
        np.zeros((3, n)),
    )


class TaylorWork(NamedTuple):
    """The work arrays of the Taylor-series step (:mod:`braidsim.core.solver.taylor`) of
    order N for a state of n components; ``None`` in their place compiles the step out.

    Attributes
    ----------
    C : array (n, N + 1)
        The state's Taylor coefficients at the step's start: y_i(t + tau) = sum_k C[i, k]
        tau^k (each component's coefficients contiguous, as the recurrences read them).
    W : array (TAYLOR_ROWS, N + 2)
        The model's work rows (:func:`braidsim.core.interfaces.model_series`).
    RT : array (N + 1, n)
        The step's dense output: RT[k, i] = C[i, k] h^k, a polynomial in theta = tau / h.
    kind : array (1,) of int64
        1 while the step in hand is a Taylor step, 2 an onset step, 0 otherwise: the dense
        output's readers look here (:class:`braidsim.core.solver.dense.StepPolynomial`).
    CS : array (n, M + 1)
        The state's coefficients in s = sqrt(tau) of an onset step of order M.
    RS : array (M + 1, n)
        The onset step's dense output, RS[k, i] = CS[i, k] S^k (a polynomial in sqrt(theta)).
    onset : int or None
        M, or ``None`` where the model has no onset series: the onset step is then compiled
        out (and CS, RS are placeholders) and each contact starts with a Runge-Kutta step.
    """

    C: np.ndarray
    W: np.ndarray
    RT: np.ndarray
    kind: np.ndarray
    CS: np.ndarray
    RS: np.ndarray
    onset: int | None


def taylor_work(n: int, order: int, onset_order: int | None = None) -> TaylorWork:
    """Work arrays of a Taylor step of ``order`` (>= 6) for n state components, and of an
    onset step of ``onset_order`` in s (even, >= 12; ``None``: no onset step)."""
    if order < 6:
        # (the step stands in for the Dormand-Prince pair, of order 5, where it is longer)
        raise ValueError(f"taylor order: {order}; allowed >= 6")
    if onset_order is not None and (onset_order < 12 or onset_order % 2):
        # (the step size reads the last six coefficients; the walls fill the even ones)
        raise ValueError(f"onset order: {onset_order}; allowed an even number >= 12")
    m = 0 if onset_order is None else onset_order
    return TaylorWork(
        np.zeros((n, order + 1)),
        np.zeros((TAYLOR_ROWS, max(order, m) + 2)),
        np.zeros((order + 1, n)),
        np.zeros(1, dtype=np.int64),
        np.zeros((n, m + 1)),
        np.zeros((m + 1, n)),
        onset_order,
    )


class SensitivityWork(NamedTuple):
    """The forward sensitivities a run carries along k directions (``None`` for a run
    without them). Direction d is a tangent of the model record and of the initial state.

    Attributes
    ----------
    tangents : numba.typed.List
        k tangent records of the model's class (d field / d key; integer fields copied).
    S : array (k, 2 n_coords) or (k, 2 n_coords + n_pairs)
        Tangent of the coordinates and speeds, and of the energy each pair dissipates where
        the run integrates it (those start at 0); in (at the start) and out (at the end).
    DV0 : array (k, 2)
        Tangents of the latched approach speeds of the pairs; in and out.
    DTR : array (k, n_transfers)
        Tangents of the transfer times.
    ESENS : array (episode capacity, k, 7)
        Tangents of each impact's onset time, approach speed, peak force, maximum depth,
        exit time, rebound speed and dissipated energy (:data:`IMPACT_SENS_FIELDS`), rows
        matching the impact table.
    RSENS : array (row capacity, k, 8) or None
        Tangents of each series row's :data:`SERIES_SENS_FIELDS`, rows matching the series.
    SMAX : array (k, 2)
        Largest |tangent| of positions and of speeds so far in each direction (the scale of
        the tangents' error control); carried across calls.
    ATOL : array (k, 2)
        Absolute tolerances of the tangents of positions and speeds in each direction: the
        state's, divided by the scale of the direction's parameter.
    n_dof2 : int
        2 n_coords: where the dissipations' tangents start in S.
    controlled : bool
        Whether the tangents' own error estimate bounds the step (True: they are held to
        the state's relative tolerance). False: they follow the steps the state's error
        control chooses, as a Newton iteration's Jacobian can (see
        :class:`braidsim.core.driver.Tangents`).
    """

    tangents: Any
    S: np.ndarray
    DV0: np.ndarray
    DTR: np.ndarray
    ESENS: np.ndarray
    RSENS: Any
    SMAX: np.ndarray
    ATOL: np.ndarray
    n_dof2: int
    controlled: bool


IMPACT_SENS_FIELDS = (
    "t",
    "velocity",
    "peak_force",
    "max_depth",
    "t_end",
    "rebound_velocity",
    "dissipated_energy",
)
SERIES_SENS_FIELDS = (
    "x",
    "vx",
    "y",
    "vy",
    "ax",
    "ay",
    "track_contact_force",
    "slot_contact_force",
)
ES_T, ES_VELOCITY, ES_PEAK, ES_DEPTH, ES_T_END, ES_REBOUND, ES_DISS = range(len(IMPACT_SENS_FIELDS))


# ---- one row of the impact table (a contact episode) ----------------------------------------
EPISODE_DTYPE = np.dtype(
    [
        ("t", "f8"),  # onset time [s]
        ("t_end", "f8"),  # exit time [s] (NaN while ongoing)
        ("pair", "f8"),  # 0 track, 1 slot
        ("wall", "f8"),  # -1 inner/rear, +1 outer/front
        ("velocity", "f8"),  # approach speed at onset (relative, >= 0 when approaching) [m/s]
        ("latched_velocity", "f8"),  # v0 used by the force law (floored, or the start policy)
        ("rebound_velocity", "f8"),  # separation speed at exit, NaN while ongoing [m/s]
        ("max_depth", "f8"),  # [m]
        ("t_max_depth", "f8"),  # [s]
        ("peak_force", "f8"),  # largest normal force [N]
        ("t_peak_force", "f8"),  # [s]
        ("min_damping_force", "f8"),  # [N]
        ("max_damping_force", "f8"),  # [N]
        ("dissipated_energy", "f8"),  # energy the contact law dissipated [J] (NaN: not integrated)
        ("end_reason", "f8"),  # END_EXIT, END_ONGOING or END_TRANSFER
        ("initial", "f8"),  # 1 when the contact existed at the start or right after a transfer
    ]
)
EPISODE_COLUMNS: tuple[str, ...] = tuple(EPISODE_DTYPE.names or ())

# ---- run statistics -------------------------------------------------------------------------
STATS_DTYPE = np.dtype(
    [
        ("steps", "f8"),  # accepted steps
        ("rejected_steps", "f8"),
        ("events", "f8"),  # contact onsets and exits
        ("rhs_evaluations", "f8"),
        ("transfers", "f8"),
        ("min_step", "f8"),  # [s]
        ("max_step", "f8"),  # [s]
        ("implicit_steps", "f8"),  # accepted steps of resting contacts (Radau IIA)
        ("taylor_steps", "f8"),  # accepted Taylor-series steps (the onset steps included)
        ("onset_steps", "f8"),  # accepted onset steps (Taylor series in sqrt(t - t_onset))
    ]
)

# ---- everything the step loop carries from one step to the next -----------------------------
# A run interrupted at any accepted step (a full series buffer, a full impact table, the end of
# one call of a longer run) continues from this record and the state vector with the same
# bits as an uninterrupted run.
RESTART_DTYPE = np.dtype(
    [
        ("started", "f8"),  # NEW_RUN, CONTINUED or STARTED
        ("t", "f8"),  # time [s]
        ("h", "f8"),  # next step size [s] (0: choose the first step)
        ("err_old", "f8"),  # last accepted error norm (PI control)
        ("onset_q", "f8"),  # error exponent of a pending first contact step (0: none)
        ("stiff_run", "f8"),
        ("nonstiff_run", "f8"),
        ("same_time_events", "f8"),
        ("last_event_t", "f8"),
        ("steps", "f8"),  # step attempts counted against max_steps
        ("next_sample", "f8"),  # index of the next sample time
        ("next_transfer", "f8"),  # index of the next transfer time
        ("mode_0", "f8"),  # contact mode of pair 0 and 1 (FREE, INNER, OUTER)
        ("mode_1", "f8"),
        ("v0_0", "f8"),  # latched approach speeds [m/s]
        ("v0_1", "f8"),
        ("open_0", "f8"),  # row of the open episode of each pair in the impact table (-1: none)
        ("open_1", "f8"),
        ("rows", "f8"),  # rows of the series buffer written
        ("episodes", "f8"),  # rows of the impact table written
        ("implicit", "f8"),  # 1: the next step is an implicit step (a contact at rest)
        ("rest_run", "f8"),  # explicit steps in a row held by a contact's fast mode
        ("explicit_rate", "f8"),  # [1/s] the explicit method's evaluations per s at the switch
        ("implicit_count", "f8"),  # implicit steps since the switch
        ("implicit_evals", "f8"),  # evaluations of those after the first REST_RAMP
        ("implicit_time", "f8"),  # [s] the time they covered
        ("rest_blocked", "f8"),  # 1: the implicit step did not pay; explicit until an event
        ("implicit_prev_h", "f8"),  # [s] the last step, when implicit (its polynomial in Q)
        ("taylor_wait", "f8"),  # Runge-Kutta steps to take before a Taylor step is tried again
        ("onset_pair", "f8"),  # the pair whose contact the pending first step starts (-1: none)
        # whether each pair's contact force is held at its law's clamp, as the last clamp
        # event left it (-1: not known, read from the force's sign)
        ("clamped_0", "f8"),
        ("clamped_1", "f8"),
    ]
)


# what the ``started`` field of a restart record says
NEW_RUN = 0.0  # a new run: the start policy decides the contacts, the first step is chosen
STARTED = 1.0  # a run under way (resumed after its buffers were flushed): nothing is redone
CONTINUED = 2.0  # a new run continuing an earlier one's state, contacts and step control


def _restart_template() -> np.ndarray:
    r = np.zeros(1, dtype=RESTART_DTYPE)
    r[0]["open_0"] = -1.0
    r[0]["open_1"] = -1.0
    r[0]["clamped_0"] = -1.0
    r[0]["clamped_1"] = -1.0
    r[0]["v0_0"] = 1.0
    r[0]["v0_1"] = 1.0
    r[0]["err_old"] = 1e-4
    r[0]["last_event_t"] = -1.0
    r[0]["onset_pair"] = -1.0
    return r


# (the record's bytes: numpy copies a structured array field by field, ~17 us for this
# one, and makes an array of bytes in ~1.5 us)
_NEW_RESTART = _restart_template().tobytes()


def _from_bytes(template: bytes, dtype: np.dtype) -> np.ndarray:
    """A new, writable one-element structured array holding ``template``."""
    return np.frombuffer(bytearray(template), dtype=dtype)


def copy_records(a: np.ndarray) -> np.ndarray:
    """A writable copy of a structured array, by its bytes: numpy copies a structured array
    field by field, 11-19 us for one to a few records of these dtypes, against 1.5 us."""
    return np.frombuffer(bytearray(a.tobytes()), dtype=a.dtype).reshape(a.shape)


def new_restart() -> np.ndarray:
    """A restart record for a new run (one-element structured array)."""
    return _from_bytes(_NEW_RESTART, RESTART_DTYPE)


# per record dtype: the named tuple of its fields, and the struct that unpacks a record of
# packed float64 fields (None for another layout)
_RECORD_VIEWS: dict[np.dtype, tuple[Any, struct.Struct | None]] = {}


def record_view(records: np.ndarray) -> Any:
    """The first record of a structured array as a named tuple of Python values, read in
    one go (``record_view(RS).t``): the restart and statistics records are read this way
    after every run. A record of packed float64 fields (all of this module's one-record
    dtypes) is unpacked from its bytes: the view of a restart record in 0.8 us, against
    1.0 us for numpy's ``item()`` alone and 2.6 us for a dict of the fields."""
    dtype = records.dtype
    known = _RECORD_VIEWS.get(dtype)
    if known is None:
        names = dtype.names or ()
        fields: Any = dtype.fields or {}
        packed = dtype.itemsize == 8 * len(names) and all(
            fields[f][0] == np.dtype("<f8") and fields[f][1] == 8 * i for i, f in enumerate(names)
        )
        known = (
            namedtuple("RecordView", names),
            struct.Struct(f"<{len(names)}d") if packed else None,
        )
        _RECORD_VIEWS[dtype] = known
    view: Any = known[0]
    unpack = known[1]
    if unpack is not None and records.flags.c_contiguous:
        # (an ndarray is a buffer; numpy's stubs do not say so. Through a memoryview: 4x slower)
        return view._make(unpack.unpack_from(records))  # type: ignore[arg-type]
    return view._make(records[0].item())


def _stats_template() -> bytes:
    s = np.zeros(1, dtype=STATS_DTYPE)
    s[0]["min_step"] = np.inf
    return s.tobytes()


_NEW_STATS = _stats_template()


def new_stats() -> np.ndarray:
    """Zeroed run statistics (one-element structured array; the smallest step +inf)."""
    return _from_bytes(_NEW_STATS, STATS_DTYPE)


# ---- window ranges: RANGES[window, pair, quantity, 0 min / 1 max] ----------------------------
RANGE_QUANTITIES = ("depth", "stiffness_force", "damping_force", "contact_force")


def _ranges_template(n_windows: int) -> np.ndarray:
    r = np.empty((n_windows, MAX_PAIRS, len(RANGE_QUANTITIES), 2))
    r[..., 0] = np.inf
    r[..., 1] = -np.inf
    return r


_ONE_WINDOW = _ranges_template(1)


def new_ranges(n_windows: int) -> np.ndarray:
    """Window extremes initialised to (+inf, -inf) (one window, the usual case: a copy of a
    template, a fifth of the time of filling a new array)."""
    return _ONE_WINDOW.copy() if n_windows == 1 else _ranges_template(n_windows)
