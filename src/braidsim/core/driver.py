"""Drive the compiled solver: buffers, flushing, and one pass however long the run.

:func:`run` calls :func:`braidsim.core.solver.loop.integrate` with a series buffer of
bounded size and an impact table of bounded size. When either fills, the solver returns at a
step boundary with everything it carries in the restart record. The driver then hands the
rows to the series sink (kept in memory, or passed to a callback that streams them to a
store or decimates them) and moves the closed impacts out. Then it calls the solver again.
The run is integrated once; its bits do not depend on the buffer sizes.
"""

from __future__ import annotations

import contextvars
import functools
import math
import typing
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from braidsim.core import interfaces as I
from braidsim.core import layout as L
from braidsim.core.interfaces import dissipation_index, model_size, series_columns
from braidsim.core.solver.loop import EPISODE_RESERVE, EVENT_ROWS, integrate
from braidsim.core.solver.taylor import ONSET_ORDER

SeriesSink = Callable[[np.ndarray], None]
"""Receives each chunk of series rows (a (rows, columns) array, a copy it may keep)."""

DEFAULT_ROW_CHUNK = 32768  # rows of the series buffer (about 7 MB for the carrier)
DEFAULT_EPISODE_CHUNK = 256
SAMPLED_EVENT_ROWS = 1024  # buffer rows for the events of a run with sample times


class SeriesOverflow(Exception):
    """The series kept in memory outgrew ``max_rows`` (:func:`run`); the run stopped at
    ``t`` after keeping ``rows`` rows, ``event_rows`` of them event rows (not samples: the
    start, onsets, exits, force peaks, transfers)."""

    def __init__(self, t: float, rows: int, event_rows: int) -> None:
        super().__init__(f"series of {rows} rows at t = {t:.9g} s")
        self.t = t
        self.rows = rows
        self.event_rows = event_rows


@dataclass
class Tangents:
    """What a run needs to carry k forward sensitivities (see
    :class:`braidsim.core.layout.SensitivityWork`).

    Attributes
    ----------
    records : sequence of model records
        k tangent records of the model's class.
    S0 : array (k, 2 n_coords)
        Tangents of the initial coordinates and speeds.
    DV0 : array (k, 2)
        Tangents of the latched speeds of contacts carried into the run (a continuation).
    DTR : array (k, n_transfers)
        Tangents of the transfer times.
    scale : array (k,)
        A typical size of each direction's parameter (SI; 1 for a direction of the initial
        state): the tangents' absolute tolerances are the state's divided by it.
    series : bool
        Also give the tangents of every series row.
    dissipations : bool
        Also carry the tangents of the energy each contact pair dissipates, where the run's
        state holds those energies (they give the sensitivities of the impacts' dissipated
        energies). A flow map, which needs the coordinates' and speeds' alone, leaves them
        out: their own error estimate bounds the step while a contact force is clamped,
        which on a resting orbit near its lift-off made each map several times dearer.
    controlled : bool
        Whether the tangents' own error estimate bounds the step, as the state's does
        (True, the default: their accuracy follows the tolerance). False: the tangents are
        integrated over the steps the state's error control chooses and their error is
        not estimated; a Newton iteration, which needs a Jacobian good enough to converge,
        not one at the tolerance, takes that (a period of paper-3.3's resting orbit at
        6 pi rad/s: 100 ms with them controlled, 42 ms without, 1.5 ms the plain run).
    """

    records: Any
    S0: np.ndarray
    DV0: np.ndarray
    DTR: np.ndarray
    scale: np.ndarray
    series: bool = True
    dissipations: bool = True
    controlled: bool = True


@dataclass
class SensitivityRun:
    """The forward sensitivities a run produced, along its k directions.

    Attributes
    ----------
    S : array (k, 2 n_coords)
        Tangents of the final coordinates and speeds.
    DV0 : array (k, 2)
        Tangents of the final latched speeds.
    impacts : array (n_impacts, k, 7)
        :data:`~braidsim.core.layout.IMPACT_SENS_FIELDS` of each row of the impact table.
    series : array (rows, k, 8) or None
        :data:`~braidsim.core.layout.SERIES_SENS_FIELDS` of each row of the series.
    """

    S: np.ndarray
    DV0: np.ndarray
    impacts: np.ndarray
    series: np.ndarray | None


@dataclass
class RawRun:
    """What one run of the solver produced, in the solver's own records.

    Attributes
    ----------
    status : int
        A status code of :mod:`braidsim.core.layout` (``ST_OK`` or a failure).
    series : np.ndarray or None
        (rows, columns) in the model's :func:`~braidsim.core.interfaces.series_columns`
        order, sorted by time (samples and event rows interleaved); None when not kept.
    episodes : np.ndarray
        The impact table (EPISODE_DTYPE); contacts still open at the end are closed at the
        final time with ``end_reason = END_ONGOING``.
    ranges : np.ndarray
        (windows, 2, 4, 2) window extremes.
    xsq : np.ndarray or None
        int x^2 dt over each window [m^2 s].
    stats : np.ndarray
        STATS_DTYPE record.
    y : np.ndarray
        Final state vector.
    restart : np.ndarray
        RESTART_DTYPE record where the run stands (to continue it).
    rows_written : int
        Series rows produced in all (kept or streamed).
    sensitivity : SensitivityRun or None
        The forward sensitivities, when the run carried them.
    integrator : str
        The step that ran: ``"taylor"`` (Taylor-series steps where they step farther,
        Dormand-Prince for the rest) or ``"dormand-prince"``; a run with tangents takes
        Dormand-Prince steps whatever was asked.
    resting_contacts : str
        ``"implicit"`` (Radau IIA steps for contacts at rest) or ``"explicit"``; a run with
        tangents is explicit whatever was asked.
    """

    status: int
    series: np.ndarray | None
    episodes: np.ndarray
    ranges: np.ndarray
    xsq: np.ndarray | None
    stats: np.ndarray
    y: np.ndarray
    restart: np.ndarray
    rows_written: int
    sensitivity: SensitivityRun | None = None
    integrator: str = "dormand-prince"
    resting_contacts: str = "explicit"

    @property
    def t(self) -> float:
        """Where the run stopped [s]."""
        return float(self.restart[0]["t"])


@functools.cache
def _float_fields(cls: type) -> frozenset[str]:
    """The fields of a record class declared ``float``."""
    try:
        hints = typing.get_type_hints(cls)
    except (NameError, TypeError):  # annotations that do not resolve: nothing to coerce
        return frozenset()
    return frozenset(name for name, hint in hints.items() if hint is float)


_PLANS: dict[type, tuple[bool, ...] | None] = {}


def _declared_plan(cls: type) -> tuple[bool, ...] | None:
    """For a record class (a ``NamedTuple``): whether each field is declared ``float``;
    ``None`` for any other class (kept per class)."""
    if cls in _PLANS:
        return _PLANS[cls]
    fields = getattr(cls, "_fields", None)
    plan = None
    if fields is not None and issubclass(cls, tuple):
        floats = _float_fields(cls)
        plan = tuple(name in floats for name in fields)
    _PLANS[cls] = plan
    return plan


# values that are never records nor ints: passed over without a look at their class's plan
_LEAVES = frozenset((float, np.ndarray, bool, str, type(None)))


def as_declared(record: Any) -> Any:
    """``record`` with every integer given for a field declared ``float`` made a float, in
    the records inside it too.

    numba compiles the solver for the types of the record's fields, so
    ``PowerLawContact(K, 1.5, 0)`` (an int damping) would compile the whole solver once
    more, 20-30 s, for the same arithmetic as ``PowerLawContact(K, 1.5, 0.0)``. (Every run
    passes its records through here: the plan of each class is kept, and floats and arrays
    are passed over, so that the carrier's records take a few microseconds.)
    """
    plan = _declared_plan(type(record))
    if plan is None:
        return record
    changes: dict[str, Any] | None = None
    for i, value in enumerate(record):
        kind = type(value)
        if kind in _LEAVES:
            continue
        if plan[i] and (kind is int or isinstance(value, np.integer)):
            new: Any = float(value)
        elif _declared_plan(kind) is not None:
            new = as_declared(value)
            if new is value:
                continue
        else:
            continue
        if changes is None:
            changes = {}
        changes[record._fields[i]] = new
    return record._replace(**changes) if changes else record


# solver options passed through declared_options lately, by value and the types of their
# fields (the types too: an int and a float of equal value are equal keys, but compile apart)
_DECLARED_OPTIONS: dict[tuple[Any, ...], Any] = {}


def declared_options(opts: Any) -> Any:
    """:func:`as_declared` of a solver options record, kept by value: a record of a few
    scalars, made anew for each run (its end time), whose walk cost more than its look-up."""
    key = (opts, tuple(map(type, opts)))
    out = _DECLARED_OPTIONS.get(key)
    if out is None:
        out = as_declared(opts)
        _keep_newest(_DECLARED_OPTIONS, key, out)
    return out


def _keep_newest(memo: dict[Any, Any], key: Any, value: Any) -> None:
    """Store ``value`` in ``memo``, dropping its oldest entry past :data:`_DECLARED_KEPT`."""
    if len(memo) >= _DECLARED_KEPT:
        # (a run on another thread of a batch may have dropped the same entry)
        memo.pop(next(iter(memo)), None)
    memo[key] = value


# the models passed through declared_model lately, by identity; each is held, so that its id
# is not reused while it is kept
_DECLARED: dict[int, tuple[Any, Any]] = {}
_DECLARED_KEPT = 16


def declared_model(model: Any) -> Any:
    """:func:`as_declared` of a model record, kept for the last few records by identity: a
    model built once and run many times (a scenario's records are derived once,
    :func:`braidsim.model.build_model`) is walked once. Records are immutable; the arrays in
    them are not walked."""
    return _by_identity(_DECLARED, model, as_declared)


def _by_identity(memo: dict[int, tuple[Any, Any]], record: Any, derive: Any) -> Any:
    """``derive(record)``, kept in ``memo`` for the last few records by identity (each
    record is held there, so that its id is not reused while it is kept)."""
    seen = memo.get(id(record))
    if seen is not None and seen[0] is record:
        return seen[1]
    value = derive(record)
    _keep_newest(memo, id(record), (record, value))
    return value


# numba's fingerprints of the records passed to the solver lately, by identity
_TYPE_KEYS: dict[int, tuple[Any, Any]] = {}


def _type_key(record: Any) -> Any:
    """numba's fingerprint of an immutable record (:func:`_fingerprint`), kept for the last
    few records by identity: the model's record, walked by numba's dispatcher at every call
    of the solver, cost ~8 us of a ~50-us call."""
    return _by_identity(_TYPE_KEYS, record, _fingerprint)


# integrate's compiled entry points, by the fingerprints of the arguments that select them
#: Called with the simulated time [s] each time a run hands control back to Python between
#: steps (every :data:`braidsim.core.layout.PAUSE_STEPS` step attempts, and at each flush of
#: its buffers): a progress bar of the command line (``braidsim.cli.progress``) sets it for
#: the run it draws. A context variable, so that a thread's runs report to its own bar.
PAUSE_HOOK: contextvars.ContextVar[Callable[[float], None] | None] = contextvars.ContextVar(
    "braidsim_pause_hook", default=None
)

_ENTRIES: dict[tuple[Any, ...], Any] = {}


def _integrate_for(key: tuple[Any, ...] | None) -> Any:
    """The compiled entry point of ``integrate`` for arguments of fingerprints ``key`` (see
    :func:`_keep_entry`), else ``integrate`` itself: numba's dispatcher, which types every
    argument at every call."""
    return integrate if key is None else _ENTRIES.get(key, integrate)


def _keep_entry(key: tuple[Any, ...] | None, args: tuple[Any, ...]) -> None:
    """After a call of ``integrate`` through numba's dispatcher with ``args``, of
    fingerprints ``key``: keep the compiled entry point of their types, which arguments of
    the same fingerprints select (numba's dispatcher keys argument types by them). Where
    numba does not say (another numba, a signature not compiled as such), none is kept and
    the dispatcher goes on choosing."""
    if key is None or key in _ENTRIES:
        return
    try:
        from numba import typeof

        entry = integrate.overloads[tuple(typeof(a) for a in args)].entry_point
    except Exception:
        return
    _keep_newest(_ENTRIES, key, entry)


_PER_CLASS: dict[tuple[Any, ...], Any] = {}


def _per_class(fn: Any, model: Any, *args: int) -> Any:
    """``fn.plain(model, *args)`` of a generic function whose value is a constant of the
    record class, kept per class and arguments. Run by the interpreter, not compiled (see
    ``GenericFunction.plain``): the compiled call had to be loaded from numba's cache first,
    and cost ~5 us a call after that (numba types the whole record)."""
    key = (fn, type(model), args)
    if key not in _PER_CLASS:
        _PER_CLASS[key] = fn.plain(model, *args)
    return _PER_CLASS[key]


_SIZES: dict[type, tuple[int, int, int]] = {}


def model_sizes(model: Any) -> tuple[int, int, int]:
    """(n_coords, n_pairs, n_quads) of ``model``
    (:func:`~braidsim.core.interfaces.model_size`, kept per record class: a run reads them
    five times)."""
    sizes = _SIZES.get(type(model))
    if sizes is None:
        n_coords, n_pairs, n_quads = _per_class(model_size, model)
        sizes = _SIZES[type(model)] = (int(n_coords), int(n_pairs), int(n_quads))
    return sizes


def dissipation_slot(model: Any, pair: int) -> int:
    """Index of pair ``pair``'s dissipated energy in the state vector
    (:func:`~braidsim.core.interfaces.dissipation_index`, kept per record class and pair)."""
    return int(_per_class(dissipation_index, model, pair))


def state_size(model: Any, energy: bool, quadratures: int = -1) -> int:
    """Length of the state vector of ``model``: 2 n_coords, plus with ``energy`` the first
    ``quadratures`` of its n_quads energy quadratures (-1: all; see
    :class:`~braidsim.core.layout.SolverOptions`)."""
    n_coords, _, n_quads = model_sizes(model)
    if not energy:
        return 2 * n_coords
    return 2 * n_coords + (n_quads if quadratures < 0 else min(quadratures, n_quads))


_PREFIXES: dict[type, tuple[int, int]] = {}


def _quadrature_prefixes(model: Any) -> tuple[int, int]:
    """(dissipation, friction) :func:`quadrature_prefix` of the model, kept per class."""
    out = _PREFIXES.get(type(model))
    if out is None:
        out = (quadrature_prefix(model, "dissipation"), quadrature_prefix(model, "friction"))
        _PREFIXES[type(model)] = out
    return out


def quadrature_prefix(model: Any, which: str) -> int:
    """The number of leading quadratures that hold ``which``: ``"dissipation"`` (the energy
    each contact pair dissipates) or ``"friction"`` (those and the friction work along each
    coordinate)."""
    n_coords, n_pairs, _ = model_sizes(model)
    if which == "dissipation":
        return int(n_pairs)
    if which == "friction":
        return int(n_pairs + n_coords)
    raise ValueError(f"quadratures: {which!r}; allowed 'dissipation' or 'friction'")


#: what the solver calls for every model: the model functions of core.interfaces, and beside
#: the function that gives a physics record its role (a contact law, an excitation) the
#: others of that role
_MODEL_FUNCTIONS = (
    I.model_size,
    I.derivatives,
    I.pair_gaps,
    I.pair_gap_accel,
    I.pair_law,
    I.pair_law_rates,
    I.pair_onset_step,
    I.free_accel_bound,
    I.apply_transfer,
    I.dissipation_index,
    I.series_row,
)
_ROLE_FUNCTIONS = (
    (I.contact_forces, I.contact_potential),
    (I.contact_forces, I.contact_force_rates),
    (I.contact_forces, I.contact_onset_step),
    (I.wall_motion, I.wall_accel_bound),
)
_TANGENT_FUNCTIONS = (I.derivatives_jvp, I.pair_gaps_jvp, I.pair_law_jvp, I.apply_transfer_jvp)
_TANGENT_ROLES = (
    (I.contact_forces, I.contact_forces_jvp),
    (I.friction_force, I.friction_force_jvp),
    (I.wall_motion, I.wall_motion_jvp),
)
# the classes (a model's and its fields') found to give every function asked for, by what
# was asked: a registration is never withdrawn, so the answer stays; a refusal is not kept
# (the function may be registered later)
_COMPLETE: set[tuple[str, tuple[type, ...]]] = set()


def _first_missing(what: str, model: Any, functions: Any, roles: Any) -> Any:
    """:func:`~braidsim.core.interfaces.first_missing`, with a yes kept per class."""
    key = (what, (type(model), *map(type, model)))
    if key in _COMPLETE:
        return None
    missing = I.first_missing(model, functions, roles)
    if missing is None:
        _COMPLETE.add(key)
    return missing


def model_incomplete(model: Any) -> str:
    """Why the solver cannot run ``model`` ("" when it can): a function of the model, or of
    a contact law or excitation in its fields, that is not registered (:func:`run` says so
    before it compiles, where numba would fail after seconds of compiling with a typing
    error of several thousand characters), or the model's series columns not described
    (:func:`~braidsim.core.interfaces.describe_model`)."""
    missing = _first_missing("run", model, _MODEL_FUNCTIONS, _ROLE_FUNCTIONS)
    if missing is not None:
        field, sub, fn = missing
        if sub is None:
            return f"the model {type(model).__name__} does not register {fn.__name__}"
        return f"{type(sub).__name__} ({field}) does not register {fn.__name__}"
    if not I.described(model):
        return (
            f"the model {type(model).__name__} has no series columns (call describe_model "
            "for its class)"
        )
    return ""


def tangents_missing(model: Any) -> tuple[str, Any, Any] | None:
    """What ``model`` lacks to carry tangents (:func:`~braidsim.core.interfaces.first_missing`
    of its four model tangents and of the tangent of each physics record's function), or
    None."""
    return _first_missing("tangents", model, _TANGENT_FUNCTIONS, _TANGENT_ROLES)


def taylor_capable(model: Any) -> str:
    """Why ``model`` cannot take Taylor steps ("" when it can): the model must register
    :func:`~braidsim.core.interfaces.model_series`, its start, its reach and
    :func:`~braidsim.core.interfaces.pair_series_rows`, and each physics record in
    its fields (found by the role it plays: a contact law, a friction law, an excitation)
    the series of its function (a friction law also its reach)."""
    missing = _first_missing(
        "taylor",
        model,
        (I.model_series, I.model_series_start, I.model_series_reach, I.pair_series_rows),
        (
            (I.contact_forces, I.contact_force_series),
            (I.friction_force, I.friction_force_series),
            (I.friction_force, I.friction_series_reach),
            (I.wall_motion, I.wall_series),
        ),
    )
    if missing is None:
        return ""
    field, sub, fn = missing
    if sub is None:
        return f"the model {type(model).__name__} gives no Taylor series ({fn.__name__})"
    return f"{type(sub).__name__} ({field}) gives no Taylor series ({fn.__name__})"


def onset_capable(model: Any) -> bool:
    """Whether ``model`` can start its contacts with an onset step in s = sqrt(t - t_onset)
    (:mod:`braidsim.core.solver.taylor`): it registers
    :func:`~braidsim.core.interfaces.model_onset_series` and its start, and each contact law
    in its fields the law's onset series. Where it cannot, a Taylor run starts each contact
    with a Runge-Kutta step. (A yes is kept per class, as in :func:`taylor_capable`.)"""
    missing = _first_missing(
        "onset",
        model,
        (I.model_onset_series, I.model_onset_start),
        (
            (I.contact_forces, I.contact_force_onset_series),
            (I.contact_forces, I.contact_onset_power),
        ),
    )
    return missing is None


def max_samples_per_step(sample_times: np.ndarray, max_step: float) -> int:
    """Most sample times in any half-open interval (t, t + max_step]: what one step can
    write."""
    st = np.asarray(sample_times, dtype=float)
    if st.size == 0:
        return 0
    ends = np.searchsorted(st, st + max_step, side="right")
    return int(np.max(ends - np.arange(st.size))) + 1


def run(
    model: Any,
    opts: L.SolverOptions,
    y0: np.ndarray,
    *,
    sample_times: np.ndarray | None = None,
    transfer_times: np.ndarray | None = None,
    windows: np.ndarray | None = None,
    series: bool | SeriesSink = True,
    xsq: bool = True,
    restart: np.ndarray | None = None,
    row_chunk: int = DEFAULT_ROW_CHUNK,
    episode_chunk: int = DEFAULT_EPISODE_CHUNK,
    tangents: Tangents | None = None,
    implicit: bool = False,
    taylor: int = 0,
    taylor_onset: bool = True,
    max_rows: int | None = None,
) -> RawRun:
    """Integrate ``model`` with solver options ``opts`` from ``y0`` (or from ``restart``).

    Parameters
    ----------
    series : bool or callable
        True: keep the series rows in memory; False: record no series (the lean path: the
        impact table, window ranges and statistics only); a callable: receive the rows in
        chunks of at most ``row_chunk`` (plus one step's worth), each sorted by time and
        together in time order, and keep none.
    xsq : bool
        Integrate x^2 over the windows (for the RMS of x).
    restart : RESTART_DTYPE record, optional
        Where to start: a new run by default (:func:`braidsim.core.layout.new_restart` at
        t = 0 or its ``t``), or a continuation (``started = CONTINUED``).
    tangents : Tangents, optional
        Carry forward sensitivities along these directions (a series sink cannot take them:
        with ``tangents.series`` the series must be kept, ``series=True``).
    implicit : bool
        Integrate a contact at rest (its fast mode holding the explicit step) with the
        L-stable Radau IIA step (:mod:`braidsim.core.solver.radau`) until its next event.
        False (the default) keeps Dormand-Prince throughout and compiles no implicit step;
        runs with tangents always use Dormand-Prince. (A switch of the call, not a field of
        :class:`~braidsim.core.layout.SolverOptions`: one more field there made every step
        of every run 5 % slower.)
    taylor : int
        The order (>= 6) of Taylor-series steps, taken where they are longer than the
        Dormand-Prince step (:mod:`braidsim.core.solver.taylor`); 0 (the default) compiles
        none. The model and every physics record in it must give their series
        (:func:`taylor_capable`); runs with tangents use Dormand-Prince only.
    taylor_onset : bool
        With ``taylor``, start each contact with an onset step in s = sqrt(t - t_onset)
        where the model gives its series there (:func:`onset_capable`; True, the default),
        else with a Dormand-Prince step.
    max_rows : int, optional
        The most rows to keep or hand to ``series`` (give it for a sink that keeps them in
        memory): past it the run stops with :class:`SeriesOverflow` (the sample grid is
        sized beforehand, but the event rows are not: a contact resting for hours has a
        peak of its force at every wobble of the solution).
    """
    why = model_incomplete(model)
    if why:
        raise ValueError(f"model: {why}")
    if tangents is not None:
        missing = tangents_missing(model)
        if missing is not None:
            field, sub, fn = missing
            part = (
                f"the model {type(model).__name__}"
                if sub is None
                else f"{type(sub).__name__} ({field})"
            )
            raise ValueError(f"tangents: {part} does not register {fn.__name__}")
    model = declared_model(model)
    opts = declared_options(opts)
    _, n_pairs, n_quads = model_sizes(model)
    if n_pairs > L.MAX_PAIRS:
        # the solver keeps per-pair state in arrays of MAX_PAIRS, unchecked in compiled code
        raise ValueError(
            f"{type(model).__name__} has {n_pairs} contact pairs; the solver allows at most "
            f"{L.MAX_PAIRS}"
        )
    if opts.quadratures not in (-1, n_quads):
        prefixes = _quadrature_prefixes(model)
        if opts.quadratures not in prefixes:
            # the models write their quadratures in these blocks only
            raise ValueError(
                f"quadratures: {opts.quadratures}; allowed -1, {prefixes[0]} or {prefixes[1]}"
            )
    n = state_size(model, opts.energy, opts.quadratures)
    y = np.array(y0, dtype=float)
    if y.shape != (n,):
        raise ValueError(
            f"the state vector of {type(model).__name__} has {n} entries, got {y.shape}"
        )
    ST = np.zeros(0) if sample_times is None else np.ascontiguousarray(sample_times, dtype=float)
    TR = (
        np.zeros(0) if transfer_times is None else np.ascontiguousarray(transfer_times, dtype=float)
    )
    WIN = np.zeros((0, 2)) if windows is None else np.ascontiguousarray(windows, dtype=float)
    if restart is None:
        RS = L.new_restart()
    elif isinstance(restart, np.ndarray) and restart.dtype is L.RESTART_DTYPE:
        RS = L.copy_records(restart.reshape(1))  # (the caller's record is not changed)
    else:
        RS = np.array(restart, dtype=L.RESTART_DTYPE).reshape(1)
    RANGES = L.new_ranges(WIN.shape[0])
    XSQ = np.zeros(WIN.shape[0]) if xsq else None
    STATS = L.new_stats()
    keep = series is True
    sink: SeriesSink | None = series if callable(series) else None
    ncol = len(series_columns(model))
    reserve = max_samples_per_step(ST, opts.max_step) + EVENT_ROWS
    capacity = max(row_chunk, 1)
    if ST.shape[0]:
        # room for the samples and the event rows a run has besides them (more are flushed
        # in chunks), not the whole chunk: a short run with sensitivities zeroed its series
        # tangents over all of it (11 MB for the 430 rows of a flow map)
        capacity = min(capacity, ST.shape[0] + SAMPLED_EVENT_ROWS)
    rows = np.empty((capacity + reserve, ncol)) if (keep or sink) else None
    EP = np.empty(max(episode_chunk, 2 * EPISODE_RESERVE), dtype=L.EPISODE_DTYPE)
    chunks: list[np.ndarray] = []
    closed: list[np.ndarray] = []
    SENS = None
    if tangents is not None:
        SENS = _sensitivity_work(tangents, EP, rows, TR, keep, sink, opts, model, n)
    # the implicit step of resting contacts, where asked and no tangents are carried
    IMP = None
    if implicit and SENS is None:
        IMP = L.implicit_work(n, 2 * model_sizes(model)[0])
    TAY = None
    if taylor and SENS is None:
        why = taylor_capable(model)
        if why:
            raise ValueError(f"taylor: {why}")
        onset = ONSET_ORDER if taylor_onset and onset_capable(model) else None
        TAY = L.taylor_work(n, int(taylor), onset)
    sens_chunks: list[np.ndarray] = []
    sens_closed: list[np.ndarray] = []
    written = 0
    event_rows = 0  # of those, the rows that are not samples (start, onsets, peaks, ...)
    i_kind = list(series_columns(model)).index("kind") if rows is not None else -1
    budget = int(opts.max_steps)
    pause = L.PAUSE_STEPS if budget <= 2**52 else budget  # (see below)
    steps = RS["steps"]  # (a view of the record's field: its reads and writes cost 0.1 us)
    args = (model, opts, y, RS, ST, TR, WIN, rows, reserve, EP, RANGES, XSQ, STATS, SENS, IMP, TAY)
    # the arguments' types, by numba's fingerprints (None where one has none: a typed list);
    # the record's and the options' kept by identity. (A fingerprint does not tell an int64
    # from a uint64 int, which numba types by value: reserve, the only int, is small.)
    fingerprints = (_type_key(model), _type_key(opts), _fingerprint(args[2:]))
    key = None if None in fingerprints else fingerprints
    call = _integrate_for(key)
    while True:
        # a call takes at most PAUSE_STEPS step attempts and returns to Python, so that a
        # pending signal (Ctrl-C, SIGTERM) is acted on: the record's count of attempts is
        # shifted so that the loop meets its budget there, stops between steps as at a
        # flush, and is resumed (the compiled code is unchanged: a check of its own in the
        # loop cost 2-3 % on paper-3.3, new options for each call 4-5 us a call)
        # (the record's count is a float: exact to 2^53; a larger budget runs unpaused)
        shift = max(0, budget - pause - int(steps[0]))
        steps[0] += shift
        status = call(*args)
        if call is integrate:
            _keep_entry(key, args)
            call = _integrate_for(key)
        if shift:
            steps[0] -= shift
            if status == L.ST_MAX_STEPS:
                status = L.ST_PAUSED
        r = L.record_view(RS)  # (read once; the writes below go to RS itself)
        final = status not in (L.ST_ROWS_FULL, L.ST_EPISODES_FULL, L.ST_PAUSED)
        nrow = int(r.rows)
        if rows is not None:
            if nrow > rows.shape[0]:
                raise RuntimeError(f"solver wrote {nrow} rows into a buffer of {rows.shape[0]}")
            if nrow and (final or status == L.ST_ROWS_FULL):
                # a flush happens between steps, and a step's rows (its samples, then its
                # peaks and event) lie inside the step: sorted chunks make a sorted stream
                order = np.argsort(rows[:nrow, 0], kind="stable")
                chunk = rows[:nrow][order]
                written += nrow
                event_rows += int(np.count_nonzero(chunk[:, i_kind] != L.KIND_SAMPLE))
                if max_rows is not None and written > max_rows:
                    raise SeriesOverflow(float(chunk[-1, 0]), written, event_rows)
                if SENS is not None and SENS.RSENS is not None:
                    sens_chunks.append(SENS.RSENS[:nrow][order])
                if keep:
                    chunks.append(chunk)
                elif sink is not None:
                    sink(chunk)
                RS[0]["rows"] = 0
        if not final:
            hook = PAUSE_HOOK.get()
            if hook is not None:
                hook(float(r.t))
        if final:
            closed.append(L.copy_records(EP[: int(r.episodes)]))
            if SENS is not None:
                sens_closed.append(SENS.ESENS[: int(r.episodes)].copy())
            break
        if status == L.ST_EPISODES_FULL:
            _flush_episodes(EP, RS, closed, None if SENS is None else (SENS.ESENS, sens_closed))
    episodes = np.concatenate(closed) if len(closed) > 1 else closed[0]
    # in order of onset (a contact open across a flush was written after later ones), and
    # of pair where two begin at once (at the start: the order an uninterrupted run opens them)
    by_onset: Any = slice(None)  # (the rows as they are)
    t_on = episodes["t"]
    if t_on.size > 1 and not np.all(t_on[1:] > t_on[:-1]):  # (strictly increasing: in order)
        order = np.lexsort((episodes["pair"], t_on))
        if np.any(order != np.arange(order.size)):
            by_onset = order
            episodes = episodes[order]
    sens_impacts = np.concatenate(sens_closed)[by_onset] if SENS is not None else None
    _close_open(episodes, r, y, model, n, sens_impacts, None if SENS is None else SENS.S)
    series_rows = None
    if keep:
        series_rows = np.concatenate(chunks) if chunks else np.zeros((0, ncol))
    sens = None
    if SENS is not None and sens_impacts is not None:
        k = SENS.S.shape[0]
        sens = SensitivityRun(
            SENS.S[:, : SENS.n_dof2].copy(),  # (the dissipations' tangents left out)
            SENS.DV0.copy(),
            sens_impacts,
            (np.concatenate(sens_chunks) if sens_chunks else np.zeros((0, k, 8)))
            if SENS.RSENS is not None
            else None,
        )
    return RawRun(
        status,
        series_rows,
        episodes,
        RANGES,
        XSQ,
        STATS,
        y,
        RS,
        written,
        sens,
        integrator="dormand-prince" if TAY is None else "taylor",
        resting_contacts="explicit" if IMP is None else "implicit",
    )


try:
    from numba._dispatcher import compute_fingerprint as _compute_fingerprint  # (not public)
except ImportError:  # another numba: no fingerprints, numba's dispatcher types every call
    _compute_fingerprint = None  # type: ignore[assignment]


def _fingerprint(value: Any) -> Any:
    """numba's fingerprint of a value, what its dispatcher keys argument types by (a
    record's class and field names, the dtypes and layouts of its arrays); a typed list's
    own numba type, which it carries; None where numba gives none (or has no fingerprint)."""
    if hasattr(value, "_numba_type_"):
        return ("typed", value._numba_type_)
    if _compute_fingerprint is None:
        return None
    try:
        return _compute_fingerprint(value)
    except Exception:  # a value numba cannot fingerprint
        return None


# numba types of tangent records, by fingerprint
_RECORD_TYPES: dict[Any, Any] = {}


def _typed_records(records: Any) -> Any:
    """The tangent records as a numba typed list (the solver reads direction d's record
    from it). The list's item type is taken from :data:`_RECORD_TYPES` where the first
    record's fingerprint is known: numba's ``typeof`` of the carrier's record walks its
    fields in Python, 0.28 ms, which a typed list started empty pays at its first append
    in every run."""
    from numba import typed, typeof

    first = records[0] if len(records) else None
    if first is None:
        return typed.List()
    key = _fingerprint(first)
    item = _RECORD_TYPES.get(key) if key is not None else None
    if item is None:
        item = typeof(first)
        if key is not None:
            _RECORD_TYPES[key] = item
    out = typed.List.empty_list(item)
    for rec in records:
        out.append(rec)
    return out


# numba types of the sensitivity work records, by the fingerprints of their fields
_SENS_TYPES: dict[tuple[Any, ...], Any] = {}


def _typeof_sensitivity_work(val: Any, c: Any) -> Any:
    """numba's type of a :class:`~braidsim.core.layout.SensitivityWork`, kept by the
    fingerprints of its fields. Its typed list has no fingerprint, so numba's dispatcher
    types the whole record in Python at every call of the solver (its arrays each made a
    new numba type and hashed, about 0.5 ms a run)."""
    from numba.core import types
    from numba.core.typing.typeof import typeof

    key: tuple[Any, ...] | None = tuple(_fingerprint(f) for f in val)
    if key is not None and any(k is None for k in key):
        key = None  # a field numba cannot fingerprint: typed as numba would, not kept
    ty = _SENS_TYPES.get(key) if key is not None else None
    if ty is None:
        # (as numba's own typeof of a tuple makes it)
        ty = types.BaseTuple.from_types([typeof(f, c.purpose) for f in val], type(val))
        if key is not None:
            _SENS_TYPES[key] = ty
    return ty


def _register_sensitivity_typeof() -> None:
    """Install :func:`_typeof_sensitivity_work` as numba's ``typeof`` of the record."""
    from numba.extending import typeof_impl

    typeof_impl.register(L.SensitivityWork)(_typeof_sensitivity_work)


_register_sensitivity_typeof()


def _sensitivity_work(
    tangents: Tangents,
    EP: np.ndarray,
    rows: np.ndarray | None,
    TR: np.ndarray,
    keep: bool,
    sink: SeriesSink | None,
    opts: L.SolverOptions,
    model: Any,
    n: int,
) -> L.SensitivityWork:
    """The arrays the solver fills with the tangents, sized like the impact table and the
    series buffer. The tangents of the coordinates and speeds come from ``tangents.S0``;
    where the state of n entries holds the energy each pair dissipates, their tangents
    follow, from 0 (they give the impacts' dissipated energies)."""
    S0 = np.array(tangents.S0, dtype=float, ndmin=2)
    k = S0.shape[0]
    if k == 0:
        raise ValueError("tangents: at least one direction is needed")
    n_coords, n_pairs, _ = model_sizes(model)
    n_dof2 = 2 * n_coords
    if S0.shape[1] != n_dof2:
        raise ValueError(f"tangents.S0: shape {S0.shape}, expected {(k, n_dof2)}")
    slots = [dissipation_slot(model, pair) for pair in range(n_pairs)]
    n_tan = n_dof2
    if (
        tangents.dissipations
        and slots == list(range(n_dof2, n_dof2 + n_pairs))
        and n >= n_dof2 + n_pairs
    ):
        n_tan = n_dof2 + n_pairs
    S = np.zeros((k, n_tan))
    S[:, :n_dof2] = S0
    DV0 = np.array(tangents.DV0, dtype=float).reshape(k, 2)
    DTR = np.zeros((k, TR.shape[0])) if TR.shape[0] == 0 else np.array(tangents.DTR, dtype=float)
    if DTR.shape != (k, TR.shape[0]):
        raise ValueError(f"tangents.DTR: shape {DTR.shape}, expected {(k, TR.shape[0])}")
    if len(tangents.records) != k:
        raise ValueError(f"tangents: {len(tangents.records)} records for {k} directions")
    if tangents.series and sink is not None:
        raise ValueError("series sensitivities need the series kept in memory (series=True)")
    records = _typed_records(tangents.records)
    RSENS = None
    if tangents.series and rows is not None and keep:
        RSENS = np.zeros((rows.shape[0], k, 8))
    ESENS = np.full((EP.shape[0], k, len(L.IMPACT_SENS_FIELDS)), np.nan)
    scale = np.abs(np.array(tangents.scale, dtype=float).reshape(k))
    scale[~(np.isfinite(scale) & (scale > 0))] = 1.0
    ATOL = np.array([opts.atol_position, opts.atol_velocity])[None, :] / scale[:, None]
    SMAX = np.zeros((k, 2))
    controlled = bool(tangents.controlled)
    return L.SensitivityWork(records, S, DV0, DTR, ESENS, RSENS, SMAX, ATOL, n_dof2, controlled)


def _flush_episodes(
    EP: np.ndarray,
    RS: np.ndarray,
    closed: list[np.ndarray],
    sens: tuple[np.ndarray, list[np.ndarray]] | None = None,
) -> None:
    """Move the closed impact rows out of the solver's table; the open ones (at most one a
    pair) go on at the front of the table, their rows in the restart record updated (and
    the rows of their tangents with them)."""
    r = RS[0]
    nep = int(r["episodes"])
    open_rows = [int(r["open_0"]), int(r["open_1"])]
    held = [i for i in open_rows if i >= 0]
    mask = np.ones(nep, dtype=bool)
    mask[held] = False
    closed.append(EP[:nep][mask].copy())
    kept = EP[held].copy()
    EP[: len(held)] = kept
    if sens is not None:
        ES, sens_closed = sens
        sens_closed.append(ES[:nep][mask].copy())
        ES[: len(held)] = ES[held].copy()
    for pair in range(2):
        r[f"open_{pair}"] = held.index(open_rows[pair]) if open_rows[pair] >= 0 else -1
    r["episodes"] = len(held)


def _last_open(episodes: np.ndarray, pair: int) -> int:
    """Index of the last row of ``pair`` with no end time (NaN), -1 if none."""
    pairs = episodes["pair"]
    ends = episodes["t_end"]
    for i in range(episodes.shape[0] - 1, -1, -1):
        if pairs[i] == pair and math.isnan(ends[i]):
            return i
    return -1


def _close_open(
    episodes: np.ndarray,
    r: Any,
    y: np.ndarray,
    model: Any,
    n: int,
    sens_impacts: np.ndarray | None = None,
    S: np.ndarray | None = None,
) -> None:
    """Close, in the output table, the contacts still open at the end of the run (``r``:
    the restart record at the end, :func:`~braidsim.core.layout.record_view`), and the
    tangents of their dissipated energies (``sens_impacts``, from the final tangents ``S``
    with the dissipations' after the coordinates and speeds)."""
    modes = (int(r.mode_0), int(r.mode_1))
    if modes == (0, 0):
        return
    t = r.t
    for pair in range(2):
        if modes[pair] == 0:
            continue
        # the open episode of this pair is the last row of the table for the pair that has
        # no end time yet (searched from the end: it is one of the last rows)
        i = _last_open(episodes, pair)
        if i < 0:
            continue
        k = dissipation_slot(model, pair)
        energy = float(y[k]) if k < n else float("nan")
        episodes["t_end"][i] = t
        episodes["dissipated_energy"][i] = energy - episodes["dissipated_energy"][i]
        episodes["end_reason"][i] = L.END_ONGOING
        if sens_impacts is not None and S is not None and k < S.shape[1]:
            # (6) at the run's end, a fixed instant
            sens_impacts[i, :, L.ES_DISS] = S[:, k] - sens_impacts[i, :, L.ES_DISS]
