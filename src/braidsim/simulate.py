"""``simulate``: run one scenario through the compiled integrator and wrap the output."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numba.core import config as numba_config

from braidsim import limits
from braidsim.core import CARRIER_COLUMNS, RawRun, SeriesOverflow, state_size
from braidsim.core import layout as L
from braidsim.core import run as core_run
from braidsim.core.driver import SeriesSink, Tangents, quadrature_prefix
from braidsim.errors import InputError, SimulationError
from braidsim.model import Model, build_model
from braidsim.params import SCHEMA, Scenario, load_scenario
from braidsim.result import Result, State
from braidsim.units import is_number, to_si


def _shown(value: object) -> str:
    """``value`` as a message shows it: its repr, cut to 60 characters."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def time_value(key: str, value: object, *, allow_zero: bool = False) -> float:
    """A time [s] from a number in s or a string with a unit (``"10 ms"``), read as
    :func:`simulate` reads ``duration`` (:func:`braidsim.units.to_si`).

    Raises
    ------
    InputError
        Naming ``key``: not a time, or not finite and > 0 (>= 0 with ``allow_zero``).
    """
    # (a float is a time in s already: the parser is for strings and other numbers)
    t = value if type(value) is float else to_si(key, value, "s")
    if not (math.isfinite(t) and (t >= 0.0 if allow_zero else t > 0.0)):
        raise InputError(
            f"{key}: {t:g} s is out of range; allowed {'>=' if allow_zero else '>'} 0 s"
        )
    return t


def time_window(
    key: str, window: object, t_start: float, t_end: float, what: str = "the run"
) -> tuple[float, float]:
    """One window ``(t0, t1)`` [s], each a number in s or a string with a unit, with
    ``t_start <= t0 < t1 <= t_end`` (the span of ``what``, to rounding).

    Raises
    ------
    InputError
        Naming ``key``: not a pair, not times, reversed or empty, or outside the span.
    """
    allowed = f"allowed {t_start:g} <= t0 < t1 <= {t_end:g} s, the span of {what}"
    if isinstance(window, str | bytes | Mapping) or not isinstance(window, Sequence | np.ndarray):
        raise InputError(
            f"{key}: {_shown(window)} is not a (t0, t1) pair; allowed two times in s, e.g. "
            "(0.001, 0.005) or ('1 ms', '5 ms')"
        )
    if len(window) != 2:
        raise InputError(
            f"{key}: {_shown(window)} has {len(window)} entries, not a (t0, t1) pair; allowed "
            "two times in s, e.g. (0.001, 0.005) or ('1 ms', '5 ms')"
        )
    t0, t1 = to_si(key, window[0], "s"), to_si(key, window[1], "s")
    if not (math.isfinite(t0) and math.isfinite(t1)) or t1 <= t0:
        raise InputError(f"{key}: [{t0:g}, {t1:g}] s is not a time interval; {allowed}")
    tol = 1e-12 * max(1.0, abs(t_start), abs(t_end))
    if t0 < t_start - tol:
        raise InputError(f"{key}: t0 = {t0:g} s is before the start of {what}; {allowed}")
    if t1 > t_end + tol:
        raise InputError(f"{key}: t1 = {t1:g} s is after the end of {what}; {allowed}")
    return t0, t1


def time_array(key: str, values: object) -> np.ndarray:
    """A flat array of times [s] from a sequence of numbers in s or strings with units.

    Raises
    ------
    InputError
        Naming ``key``: not a flat sequence of times.
    """
    flat = "allowed a flat list of times in s, e.g. [0.001, 0.002] or ['1 ms', '2 ms']"
    if isinstance(values, str | bytes | Mapping) or not isinstance(values, Sequence | np.ndarray):
        raise InputError(f"{key}: {_shown(values)} is not a list of times; {flat}")
    if isinstance(values, np.ndarray):
        if values.ndim != 1:
            raise InputError(f"{key}: an array of shape {values.shape}; {flat}")
    elif any(isinstance(v, Sequence | np.ndarray) and not isinstance(v, str) for v in values):
        raise InputError(f"{key}: {_shown(values)} is a nested list; {flat}")
    try:
        return np.asarray(values, dtype=float)
    except (TypeError, ValueError):  # strings with units
        return np.array([to_si(key, v, "s") for v in values], dtype=float)


def increasing_times(
    key: str, values: object, t0: float, t1: float, span: str, slack: float = 0.0
) -> np.ndarray:
    """:func:`time_array`, each time finite, the times strictly increasing and within
    [t0, t1 (1 + slack)] s (``span`` says what that interval is).

    Raises
    ------
    InputError
        Naming ``key`` and the first entry that is not a finite time, out of order, or
        outside [t0, t1].
    """
    st = time_array(key, values)
    allowed = f"allowed increasing times {t0:g} <= t <= {t1:g} s, {span}"
    bad = np.flatnonzero(~np.isfinite(st))
    if bad.size:
        raise InputError(f"{key}: entry {bad[0]} is not a finite time ({st[bad[0]]!r}); {allowed}")
    down = np.flatnonzero(np.diff(st) <= 0.0)
    if down.size:
        i = int(down[0]) + 1
        raise InputError(
            f"{key}: not strictly increasing at entry {i} ({st[i - 1]:.9g} s then "
            f"{st[i]:.9g} s); {allowed}"
        )
    if st.size and (st[0] < t0 or st[-1] > t1 * (1 + slack)):
        out = st[0] if st[0] < t0 else st[-1]
        raise InputError(f"{key}: {out:g} s is outside [{t0:g}, {t1:g}] s; {allowed}")
    return st


def _sample_interval(
    sc: Scenario, sample_interval: float | None, length: float
) -> tuple[float, float]:
    """(the sample interval [s], the samples it makes over ``length`` s, not rounded)."""
    dt = sc["simulation.sample_interval"] if sample_interval is None else float(sample_interval)
    if dt < 0 or not math.isfinite(dt):
        raise InputError(f"sample_interval: {dt!r} s is out of range; allowed >= 0 s")
    span = length / dt if dt > 0 else 0.0
    if not math.isfinite(span):  # a subnormal interval: no count to widen or refuse
        raise InputError(
            f"sample_interval: {dt!r} s is out of range for a run of {length:g} s; "
            f"allowed >= {length * 1e-300:.3g} s"
        )
    return dt, span


def _sensitivity_keys(sensitivities: object) -> tuple[str, ...]:
    """The keys of ``simulate(..., sensitivities=...)``: None or a list of strings."""
    allowed = "allowed a list of numeric scenario keys, e.g. ['track.clearance']"
    if sensitivities is None:
        return ()
    if isinstance(sensitivities, str | bytes | Mapping) or not isinstance(sensitivities, Iterable):
        raise InputError(f"sensitivities: {_shown(sensitivities)} is not a list of keys; {allowed}")
    keys = list(sensitivities)
    for i, key in enumerate(keys):
        if not isinstance(key, str):
            raise InputError(f"sensitivities: entry {i} ({_shown(key)}) is not a key; {allowed}")
    return tuple(str(key) for key in keys)  # (numpy's strings as str)


def run_windows(t_start: float, t_end: float, windows: object) -> np.ndarray:
    """Window 0, the whole run [t_start, t_end], and the ``windows`` given (see
    :func:`simulate`), as an (n, 2) array [s]."""
    W = [(t_start, t_end)]
    if windows is None:
        return np.array(W, dtype=float)
    pairs = "allowed a list of (t0, t1) pairs, e.g. [(0.001, 0.005)] or [('1 ms', '5 ms')]"
    if isinstance(windows, str | bytes | Mapping) or not isinstance(windows, Sequence | np.ndarray):
        raise InputError(f"windows: {_shown(windows)} is not a list of (t0, t1) pairs; {pairs}")
    if any(is_number(w) or isinstance(w, str) for w in windows):
        raise InputError(
            f"windows: {_shown(windows)} is a flat list of times, not a list of (t0, t1) "
            f"pairs; {pairs}"
        )
    for i, w in enumerate(windows):
        W.append(time_window(f"windows[{i}]", w, t_start, t_end))
    return np.array(W, dtype=float)


def _extreme_parameters(model: Model, bound: float = 1e15, tiny: float = 1e-15) -> str:
    """The parameters of a magnitude no machine has, as ``key = value unit``, for a run
    whose state overflowed or whose step collapsed: a real-valued SI value beyond ``bound``
    (a speed of 1e100 m/s), a number in a table (harmonics) beyond it, a physical value
    closer to 0 than ``tiny`` (a mass of 1e-300 kg, which makes every rate overflow; the
    solver's own settings, simulation.*, are left out: tolerances are legitimately small),
    or a contact stiffness whose force at a depth of 1 mm passes ``bound`` (1e300
    N/m^1.5; K is in N/m^n, so a stiff contact of exponent 3 legitimately has K ~ 1e20).
    Counts (simulation.max_steps) are not physical magnitudes and are left out."""
    sc = model.scenario
    out = []
    for key, value in sc.values.items():
        unit = SCHEMA[key].unit
        if isinstance(value, tuple | list):
            flat = np.asarray(value, dtype=object).ravel()
            nums = [float(v) for v in flat if isinstance(v, float | int)]
            big = [v for v in nums if math.isfinite(v) and abs(v) > bound]
            if big:
                out.append(f"{key} holds {big[0]:.3g}")
            continue
        if not isinstance(value, float) or not math.isfinite(value):
            continue
        if key.endswith(".stiffness"):
            n = (model.track if key.startswith("contact.track.") else model.slot).exponent
            if abs(value) * 1e-3**n > bound:
                out.append(f"{key} = {value:.3g} N/m^{n:g}")
        elif abs(value) > bound or (0.0 < abs(value) < tiny and not key.startswith("simulation.")):
            out.append(f"{key} = {value:.3g} {unit}".rstrip())
    return ", ".join(out)


def _rate(compute: Callable[[], float]) -> float:
    """``compute()`` as a rate [1/s]: infinite where it overflows, divides by 0 or is NaN."""
    try:
        r = float(compute())
    except (OverflowError, ZeroDivisionError):
        return math.inf
    return math.inf if math.isnan(r) else abs(r)


def failure_message(status: int, t: float, model: Model, stats: Mapping[str, Any]) -> str:
    """What failed, when, and what to change, for a solver status code."""
    sc = model.scenario
    rec = model.record
    m = sc["carrier.mass"]
    # The two rates that can make the explicit integrator crawl: the friction regularisation,
    # d f_x / d vx = (2/pi) mu1 N / (m x_hat), and the contact damping at rest under the
    # constant load F with the floor speed, d F_c / d pdot / m = F D / (v_min m).
    # (values of extreme magnitude overflow them, or divide by a mass that is 0 in floating
    # point: the rate is then infinite, and the message is still the run's failure)
    fric_rate = 0.0
    if sc["friction.law"] != "none":
        fric_rate = _rate(
            lambda: (
                2 / math.pi * rec.mu_x * rec.normal_x / (m * sc["friction.regularization_velocity"])
            )
        )
    damp_rate = _rate(
        lambda: (
            model.constant_load
            * model.track.damping_factor
            / (sc["contact.min_impact_velocity"] * m)
        )
    )
    if max(fric_rate, damp_rate) * model.options.max_step < 10.0:
        # neither holds the explicit step below a tenth of the maximum step: not stiffness
        other = ', or simulation.integrator = "dormand-prince"' if model.taylor_order > 0 else ""
        hint = (
            "neither the friction regularisation nor the contact damping is stiff here "
            f"(rates ~ {fric_rate:.3g} and {damp_rate:.3g} 1/s); try another simulation.rtol"
            f"{other}, and report the case if that does not help"
        )
    elif fric_rate >= damp_rate:
        hint = (
            "increase friction.regularization_velocity (the friction regularisation makes the "
            f"equations stiff: rate ~ {fric_rate:.3g} 1/s)"
        )
    else:
        hint = (
            "raise contact.min_impact_velocity (tiny latched impact speeds make the damping "
            f"stiff: rate ~ {damp_rate:.3g} 1/s)"
        )
    extreme = _extreme_parameters(model)
    if extreme:
        # a value far outside any machine's (a typo in an exponent): named first
        hint = f"check the values of extreme magnitude ({extreme}); else {hint}"
    if status == L.ST_STEP_COLLAPSE:
        return f"step size collapsed to the rounding of t at t = {t:.9g} s; {hint}"
    if status == L.ST_NONFINITE:
        if extreme:
            return (
                f"the state became NaN or infinite at t = {t:.9g} s: a force or the state "
                f"overflowed; check the values of extreme magnitude ({extreme})"
            )
        return f"the state became NaN or infinite at t = {t:.9g} s; check the parameters; {hint}"
    if status == L.ST_MAX_STEPS:
        budget = model.options.max_steps
        head = (
            f"step budget simulation.max_steps = {budget} exhausted at t = {t:.9g} s "
            f"(smallest step {stats['min_step']:.3g} s)"
        )
        hmax = model.options.max_step
        needed = model.duration / hmax
        if needed <= budget:
            return f"{head}; {hint}, or raise simulation.max_steps"
        # even at its largest step the run needs more steps than the budget: no stiffness
        # is to blame, and the hint above would send the user the wrong way
        cover = f"{needed:.3g} steps of {hmax:.3g} s to cover {model.duration:g} s"
        if sc["simulation.max_step"] is not None:
            return (
                f"{head}; simulation.max_step limits the step: {cover}; raise "
                "simulation.max_step (or leave it unset), or raise simulation.max_steps"
            )
        if "simulation.max_steps" in sc.explicit:
            return (
                f"{head}; even at the largest step allowed the run needs {cover}; raise "
                "simulation.max_steps"
            )
        return (
            f"{head}; the default simulation.max_step, 1/8 of the shortest excitation period, "
            f"limits the step: {cover}; lower the fastest excitation frequency, set a larger "
            "simulation.max_step (resolving that excitation coarsely), or raise "
            "simulation.max_steps"
        )
    if status == L.ST_STIFF:
        below = L.STIFF_STEP_FRACTION * model.options.max_step
        return (
            f"the equations became stiff at t = {t:.9g} s (the step held by stability below "
            f"{below:.3g} s, 1/{1 / L.STIFF_STEP_FRACTION:.0f} of the maximum step, for "
            f"{L.STIFF_LIMIT} steps; smallest step {stats['min_step']:.3g} s); {hint}"
        )
    if status == L.ST_ZENO:
        return (
            f"more than 50 contact events at the same instant t = {t:.9g} s (grazing contact); "
            "raise contact.min_impact_velocity or change the initial state"
        )
    return f"integrator status {status} at t = {t:.9g} s"


def stats_dict(raw: RawRun) -> dict[str, Any]:
    """The solver's statistics by name (``steps``, ``rejected_steps``, ``events``,
    ``rhs_evaluations``, ``implicit_steps``, ``taylor_steps`` (of them ``onset_steps``),
    ``transfers``, ``min_step``, ``max_step``; a Taylor step counts one evaluation, at its
    end), and the steps that ran: ``integrator`` (``"taylor"`` or ``"dormand-prince"``) and
    ``resting_contacts`` (``"implicit"`` or ``"explicit"``). A run with sensitivities takes
    Dormand-Prince steps, explicit at rest, whatever the scenario asks."""
    rec = L.record_view(raw.stats)
    return {
        "integrator": raw.integrator,
        "resting_contacts": raw.resting_contacts,
        "steps": int(rec.steps),
        "rejected_steps": int(rec.rejected_steps),
        "events": int(rec.events),
        "rhs_evaluations": int(rec.rhs_evaluations),
        "implicit_steps": int(rec.implicit_steps),
        "taylor_steps": int(rec.taylor_steps),
        "onset_steps": int(rec.onset_steps),
        "transfers": int(rec.transfers),
        "min_step": rec.min_step if math.isfinite(rec.min_step) else None,
        "max_step": rec.max_step,
    }


def final_state(raw: RawRun) -> State:
    """Where a run ended, with its contacts and step control: a run started from it
    (``simulate(..., start=state)``) continues it."""
    r = L.record_view(raw.restart)
    return State(
        t=r.t,
        y=tuple(raw.y.tolist()),
        track_mode=int(r.mode_0),
        slot_mode=int(r.mode_1),
        track_v0=r.v0_0,
        slot_v0=r.v0_1,
        step=r.h,
        err_old=r.err_old,
        onset_q=r.onset_q,
        onset_pair=int(r.onset_pair),
        track_clamped=int(r.clamped_0),
        slot_clamped=int(r.clamped_1),
    )


def run_model(
    model: Model,
    *,
    sample_times: np.ndarray | None = None,
    windows: np.ndarray | None = None,
    series: bool | SeriesSink = True,
    record_events: bool = True,
    energy: bool | Literal["dissipation", "friction"] = True,
    start: State | None = None,
    tangents: Tangents | None = None,
    in_memory: bool = True,
    xsq: bool = True,
) -> RawRun:
    """Run one model through the compiled core: the one way from a :class:`Model` to its
    results, for :func:`simulate`, the batches, the machine and the analyses.

    ``start`` continues from a :class:`State` (its time, state vector, contacts, latched
    speeds and step control) instead of t = 0 and the scenario's initial conditions; the run
    then ends at ``start.t + model.duration``. ``series``: keep the rows (True), none
    (False: the lean path), or stream them to a callable. Raises :class:`SimulationError` on
    a numerical failure. ``tangents``: carry forward sensitivities
    (:func:`braidsim.sensitivity.directions`). ``energy``: integrate all the energy
    quadratures (True), none (False), only the energy each contact dissipates
    (``"dissipation"``: what the impact table reports; the lean path), or that and the
    friction work (``"friction"``: what the batch metrics read).

    The returned ``y`` is always the model's full state: the quadratures a run did not
    integrate are NaN there, and a run started from such a state integrates them from its
    own start.

    ``in_memory``: the rows kept, or handed to a callable that keeps them, count against
    ``BRAIDSIM_MAX_MEMORY`` as they come (the sample grid is sized beforehand, the event rows
    are not); False for a callable that streams them away. ``xsq``: integrate x^2 over the
    windows (``RawRun.xsq``, for the RMS of x); False compiles that recorder out.
    """
    if getattr(numba_config, "DISABLE_JIT", False):
        # the solver passes its records by reference (a compiled intrinsic) and resolves its
        # generic functions at compile time: it has no pure-Python form
        raise InputError(
            "NUMBA_DISABLE_JIT: 1 is not supported (braidsim's solver runs compiled only); "
            "allowed: unset or 0"
        )
    # the step never exceeds max_step: a run takes at least duration / max_step steps
    # (1e9 steps are 20 minutes to hours of CPU)
    limits.check(
        "steps",
        model.duration / float(model.options.max_step),
        lambda: (
            f"duration: {model.duration:g} s at simulation.max_step = "
            f"{float(model.options.max_step):.3g} s, at least"
        ),
    )
    nq = quadrature_prefix(model.record, energy) if isinstance(energy, str) else -1
    opts = model.options._replace(record_events=record_events, energy=bool(energy), quadratures=nq)
    n = state_size(model.record, bool(energy), nq)
    n_full = state_size(model.record, True)
    y0 = model.y0[:n]
    restart = None
    if start is not None:
        y0 = np.asarray(start.y, dtype=float)
        if y0.shape != (n_full,):
            raise InputError(
                f"start: a state of {y0.size} entries, where this scenario's model "
                f"({type(model.record).__name__}) has {n_full}: the state of a run of another "
                "model; allowed the final state of a run of the same model (for the carrier, "
                "the same simulation.dof)"
            )
        n_coord2 = state_size(model.record, False)
        # a quadrature the previous run did not integrate starts from this run's start
        y0 = np.where(np.isnan(y0) & (np.arange(n_full) >= n_coord2), 0.0, y0)[:n]
        restart = L.new_restart()
        r = restart[0]
        r["started"] = L.CONTINUED
        r["t"] = start.t
        r["h"] = start.step
        r["err_old"] = start.err_old
        r["onset_q"] = start.onset_q
        r["onset_pair"] = start.onset_pair if start.onset_q > 0.0 else -1
        r["mode_0"], r["mode_1"] = start.track_mode, start.slot_mode
        r["v0_0"], r["v0_1"] = start.track_v0, start.slot_v0
        r["clamped_0"], r["clamped_1"] = start.track_clamped, start.slot_clamped
        opts = opts._replace(t_end=start.t + model.duration)
    try:
        raw = core_run(
            model.record,
            opts,
            y0,
            sample_times=sample_times,
            transfer_times=model.transfer_times,
            windows=windows,
            series=series,
            restart=restart,
            tangents=tangents,
            xsq=xsq,
            implicit=model.implicit_rest,
            taylor=model.taylor_order,
            max_rows=int(limits.limit("memory") // (8 * len(CARRIER_COLUMNS)))
            if in_memory
            else None,
        )
    except SeriesOverflow as exc:
        raise SimulationError(
            f"the series kept in memory outgrew the memory limit ({limits.limit('memory'):.3g} "
            f"bytes, {limits.env_name('memory')}) at t = {exc.t:.9g} s with {exc.rows} rows, "
            f"{exc.event_rows} of them event rows: onsets, exits, force peaks (a contact at "
            "rest for long has a peak of its force at every wobble of the solution); keep fewer "
            "rows: "
            "simulate(..., record_events=False) or series=False or a SeriesSink that streams "
            "them (on the command line: run without --out), a shorter duration, or raise "
            f"{limits.env_name('memory')}",
            exc.t,
        ) from None
    if raw.status == L.ST_GRAZING:
        from braidsim.sensitivity import sensitivity_error

        # (a continued run's start is no new start: it opens no contacts there)
        raise sensitivity_error(raw.t, None if start is not None else model.t_start)
    if raw.status != L.ST_OK:
        raise SimulationError(failure_message(raw.status, raw.t, model, stats_dict(raw)), raw.t)
    if n < n_full:
        y_full = np.empty(n_full)  # (np.full costs 1.5 us)
        y_full[:n] = raw.y
        y_full[n:] = np.nan
        raw.y = y_full
    return raw


SERIES_MEMORY = 64 * 2**20
"""Default memory budget of a series kept in memory [bytes] (``max_series_bytes``)."""


def simulate(
    scenario: Scenario | str | Path | Mapping[str, Any],
    duration: float | str | None = None,
    *,
    overrides: Mapping[str, Any] | None = None,
    windows: Sequence[tuple[float | str, float | str]] | None = None,
    sample_interval: float | str | None = None,
    sample_times: Sequence[float | str] | np.ndarray | None = None,
    record_events: bool = True,
    start: State | None = None,
    series: bool | SeriesSink = True,
    max_series_bytes: int | None = SERIES_MEMORY,
    sensitivities: Sequence[str] | None = None,
    rms: bool | None = None,
) -> Result:
    """Simulate one carrier.

    Parameters
    ----------
    scenario : Scenario, str, Path or mapping
        A loaded scenario, a built-in name, a TOML path, or ``{dotted key: value}``.
    duration : float or str, optional
        Simulated time [s] (or a string with a unit, ``"0.1 s"``); default
        ``simulation.duration``.
    overrides : mapping, optional
        Extra ``{key: value}`` applied on top of the scenario.
    windows : sequence of (t0, t1), optional
        Extra time windows [s] (numbers in s or strings with a unit, ``[("1 ms", "5 ms")]``)
        over which the exact ranges of depth and forces are kept (window 0 is always the
        whole run); each inside the run.
    sample_interval : float or str, optional
        Spacing of the sampled series [s] (or a string with a unit); default
        ``simulation.sample_interval``;
        0 keeps only the event rows.
    sample_times : array, optional
        Explicit sample times [s], a flat list (numbers in s or strings with a unit),
        strictly increasing and within the run (replaces ``sample_interval``; an empty list
        keeps only the event rows).
    record_events : bool
        Add the exact onset/exit/peak/transfer states to the series.
    start : State, optional
        Continue from this state (e.g. ``previous.final_state``) for ``duration`` more
        seconds; windows and sample times are then absolute times within the new span.
    series : bool or callable
        True (default): keep the sampled series in ``Result.series``. False: record none
        (the lean path: impacts, ranges, summary and final state only). A callable: receive
        the series in chunks of rows (arrays in the columns of
        :data:`braidsim.core.CARRIER_COLUMNS`, in time order), keeping none in memory: for
        runs of any length, streamed to a store or reduced on the fly.
    max_series_bytes : int or None
        Memory budget (> 0) of the samples kept in memory (default 64 MiB, about 300,000
        rows). A ``sample_interval`` that would exceed it is widened to a multiple of itself
        that fits (``Result.stats["sample_interval"]`` says which), keeping every k-th
        sample of the grid asked for; the first sample is kept whatever the budget (a row
        is 224 bytes). Explicit ``sample_times`` are never thinned. None: no budget.
    sensitivities : sequence of str, optional
        Numeric scenario keys (``"contact.track.restitution"``, ``"track.clearance"``,
        ``"initial.x"``, ...): carry the exact forward sensitivities of the run along each
        (``Result.sensitivity``, a :class:`braidsim.sensitivity.Sensitivities`; the summary
        and ``braidsim run --json`` carry them per impact and in ``final``). Not with a
        series callable. With ``start``, they are the continued run's own, its start state
        held fixed (they do not carry the earlier run's; ``initial.*`` keys are refused).
    rms : bool, optional
        Integrate x^2 over each window for ``Result.rms_x`` (a 4-point Gauss-Legendre rule on
        the interpolant of every step). Default: with a series; the lean path
        (``series=False``) leaves it out, and ``Result.rms_x`` is None, unless ``rms=True``.

    Returns
    -------
    Result
    """
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if overrides:
        sc = sc.with_overrides(overrides)
    if duration is not None:
        duration = time_value("duration", duration)  # a number in s or a string with a unit
    if sample_interval is not None:
        sample_interval = time_value("sample_interval", sample_interval, allow_zero=True)
    if max_series_bytes is not None and not (
        is_number(max_series_bytes)
        and math.isfinite(max_series_bytes)
        and max_series_bytes == math.floor(max_series_bytes)
        and max_series_bytes > 0
    ):
        raise InputError(
            f"max_series_bytes: {_shown(max_series_bytes)} is out of range; allowed an integer "
            "> 0 (bytes), or None for no budget"
        )
    if start is not None and not isinstance(start, State):
        raise InputError(
            f"start: expected the State of an earlier run (Result.final_state), got "
            f"{type(start).__name__}"
        )
    t_start = 0.0 if start is None else float(start.t)
    keys = _sensitivity_keys(sensitivities)
    if keys and callable(series):
        raise InputError("sensitivities: need series=True or False, not a series callable")
    if isinstance(series, bool | np.bool_):
        series = bool(series)  # (compared by identity below)
    elif not callable(series):
        raise InputError(
            f"series: {_shown(series)} is not allowed; allowed True, False or a callable that "
            "receives the rows"
        )
    if not isinstance(record_events, bool | np.bool_):
        raise InputError(
            f"record_events: {_shown(record_events)} is not allowed; allowed True or False"
        )
    record_events = bool(record_events)  # (a numpy bool as the options' plain bool)
    if not (rms is None or isinstance(rms, bool | np.bool_)):
        raise InputError(f"rms: {_shown(rms)} is not allowed; allowed True, False or None")
    model = build_model(
        sc,
        duration,
        t_start=t_start,
        keep_zero_harmonics=bool(keys),
        continued=start is not None,
    )
    tangents = None
    if keys:
        from braidsim.sensitivity import check_differentiable, directions

        check_differentiable(model.record)
        dirs = directions(model, keys)
        if start is not None:
            # a continued run starts from the given state, held fixed: its tangent is zero
            fixed = [k for k in keys if k.startswith("initial.")]
            if fixed:
                raise InputError(
                    f"sensitivities: {fixed[0]} with start: a continued run starts from the "
                    "given state, not the scenario's initial one; ask for it in the first run"
                )
            dirs.S0[:] = 0.0
        tangents = dirs.tangents(series=series is True)
    T = t_start + model.duration
    dt_used: float | None = None
    if series is False:
        st = np.zeros(0)
        if sample_times is None:  # unused, but refused as it would be with a series
            _sample_interval(sc, sample_interval, T - t_start)
    elif sample_times is not None:
        st = increasing_times("sample_times", sample_times, t_start, T, "the span of the run")
    else:
        dt, span = _sample_interval(sc, sample_interval, T - t_start)
        dt0, k = dt, 1
        n = math.floor(span + 1e-9) + 1 if dt > 0 else 0
        row_bytes = 8 * len(CARRIER_COLUMNS)
        if series is True and max_series_bytes is not None and n * row_bytes > max_series_bytes:
            # keep every k-th sample: the widest interval that fits the budget
            k = math.ceil(n * row_bytes / max_series_bytes)
            dt *= k
            n = math.floor((T - t_start) / dt + 1e-9) + 1
        # a streamed series or one without a budget is not widened, but its sample times
        # are one array: refuse it before it is made
        limits.check("memory", 8.0 * n, f"sample_interval = {dt:g} s over {T - t_start:g} s")
        # on the grid of the interval asked (every k-th point where widened), the last
        # sample no later than the end: t_start + i dt may round past it (0.3 s / 1e-5 s)
        st = t_start + np.arange(0, n * k, k, dtype=float) * dt0 if n else np.zeros(0)
        if n and st[-1] > T:
            st[-1] = T
        dt_used = dt
    W = run_windows(t_start, T, windows)
    # a series kept in memory is collected column by column from the solver's chunks, so
    # that it is held once (not as chunks and again as their concatenation)
    kept_here = series is True and tangents is None  # (else the driver keeps or streams them)
    columns: list[list[np.ndarray]] = [[] for _ in CARRIER_COLUMNS] if kept_here else []

    def keep(chunk: np.ndarray) -> None:
        for i, col in enumerate(columns):
            col.append(chunk[:, i].copy())

    raw = run_model(
        model,
        sample_times=st,
        windows=W,
        # the series' tangents come back with the rows kept by the driver
        series=keep if kept_here else series,
        in_memory=series is True,  # a SeriesSink of the caller streams the rows away
        record_events=record_events and series is not False,
        # the lean path integrates only the energy the impact table reports
        energy="dissipation" if series is False else True,
        start=start,
        tangents=tangents,
        # the RMS of x where it is asked for: with a series unless said otherwise
        xsq=series is not False if rms is None else bool(rms),
    )
    series_cols: dict[str, np.ndarray] = {}
    if raw.series is not None:
        for i, name in enumerate(CARRIER_COLUMNS):
            series_cols[name] = raw.series[:, i].copy()
    elif any(columns):
        for i, name in enumerate(CARRIER_COLUMNS):
            series_cols[name] = np.concatenate(columns[i]) if columns[i] else np.zeros(0)
            columns[i] = []
    else:  # no rows (the lean path): one empty array serves every column
        series_cols = dict.fromkeys(CARRIER_COLUMNS, np.zeros(0))
    if not model.two_dof and series_cols["x"].size:
        # the x-only carrier does not move tangentially: y and y' stay at their start values
        series_cols["y"][:] = sc["initial.y"]
        series_cols["vy"][:] = sc["initial.vy"]
    st_dict: dict[str, Any] = stats_dict(raw)
    st_dict.update(
        track_stiffness=model.track.stiffness,
        track_damping_factor=model.track.damping_factor,
        track_effective_restitution=model.track.effective_restitution,
        sample_interval=dt_used,
        series_rows=raw.rows_written,
    )
    fs = final_state(raw)
    y = fs.y  # (Python floats)
    final = {
        "t": fs.t,
        "x": y[0],
        "vx": y[1],
        "y": y[2] if model.two_dof else float(sc["initial.y"]),
        "vy": y[3] if model.two_dof else float(sc["initial.vy"]),
    }
    rms_x = None if raw.xsq is None else np.sqrt(raw.xsq / (W[:, 1] - W[:, 0]))
    sens = None
    if raw.sensitivity is not None:
        from braidsim.sensitivity import Sensitivities

        sens = Sensitivities.from_run(keys, raw.sensitivity)
    return Result(
        model,
        series_cols,
        raw.episodes,
        W,
        raw.ranges,
        st_dict,
        final,
        fs,
        rms_x=rms_x,
        sensitivity=sens,
    )
