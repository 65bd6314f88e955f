"""Many parameter sets through the compiled integrator in one call, reduced to per-run metrics.

:func:`simulate_batch` takes a base scenario and a list of parameter sets (``{dotted key:
value}`` overrides), validates every set before any run starts, integrates each run with the
compiled core (:func:`braidsim.simulate.run_model` with no event rows) and reduces it to the
scalar metrics of :data:`METRICS`. Runs are independent and deterministic: a run's metrics
are the same bits whatever batch, chunk, process or order it runs in, and equal those computed
from :func:`braidsim.simulate` with the same parameters (``tests/unit/test_batch.py``).
``workers > 1`` runs them in parallel: on threads of this process by default (the compiled
kernel releases the GIL, so the integrations overlap; measured 1.9x on 2 cores against 1.7x
for two processes, which pay for their start and for shipping the work), or on local processes
(``executor="processes"``: on many cores, where the Python share of a run, ~0.35 of ~6 ms
for one second of paper-3.3, would make the threads wait for each other).
:mod:`braidsim.sweep` builds parameter grids and samples on top of this and stores the
results.

Metrics window
--------------
Every metric except the final state is taken over one window [t0, t1], so that a start-up
transient is left out: by default the second half of the shortest run, [D/2, D], as in a
sweep (``window=(0.0, D)`` takes the whole run):

* impacts: contact onsets with t0 <= t_onset <= t1, per pair and wall. A contact that exists
  at t = 0 (or right after a transfer) with an overlap has no approach and is not an impact.
* maximum approach speed [m/s]: the largest relative normal speed at those onsets
  (0 when there is none);
* maximum contact force [N] and maximum depth [m]: the largest magnitude of the normal
  contact force and of the penetration over the window, from the kernel's exact window
  ranges (extremes refined on the interpolant), on either wall;
* contact fraction: the time in contact inside the window over t1 - t0, from the episode
  start and end times;
* dissipated energy [J]: the change over the window of the kernel's dissipation integrals
  int (N - K p^n) pdot dt (contact damping, per pair) and int f v dt (friction);
* RMS of x [m]: sqrt( (1/(t1 - t0)) int_t0^t1 x(t)^2 dt ), x measured from the track's rest
  position, the integral taken in the kernel by a 4-point Gauss-Legendre rule on the
  interpolant of every step (it agrees with the trapezoidal rule on 1-us samples to ~1e-11;
  the rule on a 0.5 ms grid, used before, was off by 2e-4 on paper-3.3).

Regime rule
-----------
The regime label describes the track pair over the window (:data:`REGIMES`):

* ``two_sided_impacts`` (3): onsets on both the inner and the outer wall;
* ``one_sided_impacts`` (2): onsets on one wall only (chatter on the inner wall, or the
  bounces after a transfer);
* ``resting_contact`` (1): no onset, but in contact during the window (the carrier stays on
  the wall, docs/model.md §7);
* ``no_contact`` (0): no onset and no contact;
* ``failed`` (-1): the run failed numerically (its reason is kept in ``failure``).

The contact-loss bound (docs/model.md §7) predicts ``resting_contact`` on a vibrating track while
a_p = (T1 cos phi + m r_c omega^2)/m >= h_a omega_h^2 and impacts above that line.
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.core import CARRIER_COLUMNS, RawRun
from braidsim.errors import InputError, SimulationError
from braidsim.model import Model, build_model
from braidsim.params import SCHEMA, Scenario, flatten, load_scenario
from braidsim.regimes import CONTACT_PATTERNS, FAILED, window_contacts
from braidsim.result import UNITS as SERIES_UNITS

if TYPE_CHECKING:
    from concurrent.futures import ProcessPoolExecutor

    import pandas as pd
    import xarray as xr

REGIMES = CONTACT_PATTERNS
"""Regime labels (the contact patterns of :mod:`braidsim.regimes`), index = code; -1 is
``failed``."""
REGIME_FAILED = FAILED


@dataclass(frozen=True)
class Metric:
    """One per-run metric.

    Attributes
    ----------
    name : str
        Variable name.
    unit : str
        SI unit ("" for dimensionless or counts).
    dtype : str
        NumPy dtype of the stored values.
    description : str
        What it is.
    """

    name: str
    unit: str
    dtype: str
    description: str

    @property
    def fill(self) -> float | int:
        """Value of a failed run: NaN for floats, -1 for integers."""
        return -1 if self.dtype.startswith("int") else math.nan


METRICS: tuple[Metric, ...] = (
    Metric(
        "regime",
        "",
        "int8",
        "-1 failed, 0 no_contact, 1 resting_contact, 2 one_sided_impacts, 3 two_sided_impacts "
        "(track pair, over the window; see braidsim.batch)",
    ),
    Metric(
        "track_inner_impacts", "", "int32", "contact onsets on the inner track wall in the window"
    ),
    Metric(
        "track_outer_impacts", "", "int32", "contact onsets on the outer track wall in the window"
    ),
    Metric("slot_rear_impacts", "", "int32", "contact onsets on the rear slot wall in the window"),
    Metric(
        "slot_front_impacts", "", "int32", "contact onsets on the front slot wall in the window"
    ),
    Metric(
        "track_max_approach_speed",
        "m/s",
        "float64",
        "largest relative normal speed at a track contact onset in the window (0: none)",
    ),
    Metric(
        "slot_max_approach_speed",
        "m/s",
        "float64",
        "largest relative normal speed at a slot contact onset in the window (0: none)",
    ),
    Metric(
        "track_max_contact_force",
        "N",
        "float64",
        "largest |normal force| of the track contact in the window",
    ),
    Metric(
        "slot_max_contact_force",
        "N",
        "float64",
        "largest |normal force| of the slot contact in the window",
    ),
    Metric(
        "track_max_depth", "m", "float64", "largest penetration into a track wall in the window"
    ),
    Metric("slot_max_depth", "m", "float64", "largest penetration into a slot wall in the window"),
    Metric(
        "track_contact_fraction",
        "",
        "float64",
        "fraction of the window in contact with a track wall",
    ),
    Metric(
        "slot_contact_fraction", "", "float64", "fraction of the window in contact with a slot wall"
    ),
    Metric(
        "track_dissipated_energy",
        "J",
        "float64",
        "energy dissipated by the track contact damping in the window, int (N - K p^n) pdot dt",
    ),
    Metric(
        "slot_dissipated_energy",
        "J",
        "float64",
        "energy dissipated by the slot contact damping in the window",
    ),
    Metric("friction_work", "J", "float64", "work of the friction forces f_x, f_y in the window"),
    Metric("rms_x", "m", "float64", "root mean square of x over the window (exact quadrature)"),
    Metric("final_x", "m", "float64", "x at the end of the run"),
    Metric("final_vx", "m/s", "float64", "dx/dt at the end of the run"),
    Metric("final_y", "m", "float64", "y at the end of the run"),
    Metric("final_vy", "m/s", "float64", "dy/dt at the end of the run"),
    Metric("steps", "", "int64", "accepted integration steps (cost)"),
    Metric("rhs_evaluations", "", "int64", "evaluations of the equations of motion (cost)"),
)
METRIC_NAMES: tuple[str, ...] = tuple(m.name for m in METRICS)
METRIC_INDEX: Mapping[str, int] = MappingProxyType({m.name: i for i, m in enumerate(METRICS)})
SERIES_VARIABLES: tuple[str, ...] = tuple(c for c in CARRIER_COLUMNS if c not in ("t", "kind"))
"""Columns of the carrier's series that can be sampled per run (units in ``result.UNITS``)."""

_COL = {name: i for i, name in enumerate(CARRIER_COLUMNS)}


# ----------------------------------------------------------------------------------------
# one run
# ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RunOptions:
    """How each run of a batch is reduced.

    Attributes
    ----------
    window : (float, float) or None
        Metrics window [s]; None: the whole run.
    series : tuple of str
        Kernel columns to sample (:data:`SERIES_VARIABLES`).
    series_times : np.ndarray
        Sample times of those columns [s].
    """

    window: tuple[float, float] | None = None
    series: tuple[str, ...] = ()
    series_times: np.ndarray = field(default_factory=lambda: np.zeros(0))


def _window_of(model: Model, opts: RunOptions) -> tuple[float, float]:
    if opts.window is None:
        return 0.0, model.duration
    return float(opts.window[0]), float(opts.window[1])


def run_metrics(model: Model, opts: RunOptions) -> tuple[np.ndarray, np.ndarray | None, str]:
    """Integrate one model and reduce it.

    Parameters
    ----------
    model : Model
        From :func:`braidsim.model.build_model`.
    opts : RunOptions
        Window and sampled series.

    Returns
    -------
    values : np.ndarray
        One float per entry of :data:`METRICS` (NaN everywhere but ``regime`` = -1 when the
        run failed).
    series : np.ndarray or None
        (len(opts.series), len(opts.series_times)) samples, NaN when the run failed; None
        when no series is asked for.
    failure : str
        "" for a run that finished, else the reason (what failed, when, what to change).
    """
    t0, t1 = _window_of(model, opts)
    # the energy integrals are read at the window's ends; the RMS of x comes from the kernel
    edges = np.array([t0, t1])
    st = np.union1d(edges, opts.series_times) if opts.series_times.size else edges
    W = np.array([[t0, t1]])  # (the metrics' window alone: its ranges and x^2 integral)
    values = np.full(len(METRICS), math.nan)
    series = np.full((len(opts.series), opts.series_times.size), math.nan) if opts.series else None
    try:
        raw = run_samples(model, st, W)
    except SimulationError as exc:
        values[METRIC_INDEX["regime"]] = REGIME_FAILED
        return values, series, str(exc)
    rows, EP, R, xsq, y = raw.series, raw.episodes, raw.ranges, raw.xsq, raw.y
    assert rows is not None and xsq is not None
    if rows.shape[0] != st.size or not np.array_equal(rows[:, 0], st):
        # without event rows the solver writes exactly the samples asked for, in order
        raise AssertionError("solver returned a series that does not match the sample times")
    _episode_metrics(EP, t0, t1, values)
    i0 = int(np.searchsorted(st, t0))
    i1 = int(np.searchsorted(st, t1))
    values[METRIC_INDEX["track_dissipated_energy"]] = (
        rows[i1, _COL["track_dissipated"]] - rows[i0, _COL["track_dissipated"]]
    )
    values[METRIC_INDEX["slot_dissipated_energy"]] = (
        rows[i1, _COL["slot_dissipated"]] - rows[i0, _COL["slot_dissipated"]]
    )
    fw = rows[:, _COL["friction_work_x"]] + rows[:, _COL["friction_work_y"]]
    values[METRIC_INDEX["friction_work"]] = fw[i1] - fw[i0]
    values[METRIC_INDEX["rms_x"]] = math.sqrt(xsq[0] / (t1 - t0))
    for ip, pair in enumerate(("track", "slot")):
        depth = R[0, ip, 0]
        force = R[0, ip, 3]
        values[METRIC_INDEX[f"{pair}_max_depth"]] = max(0.0, -depth[0], depth[1])
        values[METRIC_INDEX[f"{pair}_max_contact_force"]] = max(0.0, -force[0], force[1])
    values[METRIC_INDEX["final_x"]] = y[0]
    values[METRIC_INDEX["final_vx"]] = y[1]
    values[METRIC_INDEX["final_y"]] = y[2] if model.two_dof else model.scenario["initial.y"]
    values[METRIC_INDEX["final_vy"]] = y[3] if model.two_dof else model.scenario["initial.vy"]
    values[METRIC_INDEX["steps"]] = raw.stats[0]["steps"]
    values[METRIC_INDEX["rhs_evaluations"]] = raw.stats[0]["rhs_evaluations"]
    if series is not None:
        isr = np.searchsorted(st, opts.series_times)
        for k, name in enumerate(opts.series):
            series[k] = rows[isr, _COL[name]]
    return values, series, ""


def run_samples(model: Model, sample_times: np.ndarray, windows: np.ndarray) -> RawRun:
    """:func:`braidsim.simulate.run_model` with samples only (no event rows): the fast path."""
    from braidsim.simulate import run_model

    # the window metrics read the dissipations and friction works, not the other works
    return run_model(
        model,
        sample_times=sample_times,
        windows=windows,
        record_events=False,
        energy="friction",
    )


def _episode_metrics(EP: np.ndarray, t0: float, t1: float, values: np.ndarray) -> None:
    """Impacts, approach speeds, contact fractions and the regime from the episode table
    (:func:`braidsim.regimes.window_contacts`, as the steady-state regime reads them)."""
    wc = window_contacts(EP, t0, t1)
    for ip, (pname, walls) in enumerate(
        (("track", ("inner", "outer")), ("slot", ("rear", "front")))
    ):
        for k, wname in enumerate(walls):
            values[METRIC_INDEX[f"{pname}_{wname}_impacts"]] = int(wc.onsets[ip, k])
        values[METRIC_INDEX[f"{pname}_max_approach_speed"]] = wc.max_approach_speed[ip]
        values[METRIC_INDEX[f"{pname}_contact_fraction"]] = wc.contact_fraction[ip]
    values[METRIC_INDEX["regime"]] = wc.track_pattern


# ----------------------------------------------------------------------------------------
# many runs
# ----------------------------------------------------------------------------------------


def scenario_payload(sc: Scenario) -> tuple[Any, ...]:
    """A picklable form of a validated Scenario (for worker processes)."""
    return (sc.name, dict(sc.values), sc.description, sc.source, tuple(sorted(sc.explicit)))


def scenario_from_payload(payload: tuple[Any, ...]) -> Scenario:
    """Inverse of :func:`scenario_payload` (the values were validated when it was made)."""
    name, values, description, source, explicit = payload
    return Scenario(name, MappingProxyType(dict(values)), description, source, frozenset(explicit))


def check_options(
    durations: Sequence[float],
    window: tuple[float | str, float | str] | None,
    series: Sequence[str],
    series_times: Sequence[float | str] | np.ndarray | None,
) -> RunOptions:
    """Validate the reduction options against the run durations; an InputError names the option."""
    from braidsim.simulate import increasing_times, time_window

    tmin = min(durations) if durations else math.inf
    win = None
    if window is not None:
        t0, t1 = time_window("window", window, 0.0, tmin, "the shortest run")
        win = (t0, min(t1, tmin))
    if isinstance(series, str):
        # (tuple("x") would be the letters)
        raise InputError(
            f"series: {series!r} is one string; allowed a list of variable names ([{series!r}])"
        )
    names = tuple(series)
    for name in names:
        if name not in SERIES_VARIABLES:
            import difflib

            close = difflib.get_close_matches(name, SERIES_VARIABLES, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise InputError(
                f"series: unknown variable {name!r}{hint}; allowed {', '.join(SERIES_VARIABLES)}"
            )
    times = (
        np.zeros(0)
        if series_times is None
        # (the shortest run's end, computed from its duration, to within rounding)
        else increasing_times("series_times", series_times, 0.0, tmin, "the shortest run", 1e-12)
    )
    if names and times.size == 0:
        raise InputError(
            "series_times: no sample times given for the series; allowed a non-empty list in s"
        )
    return RunOptions(win, names, times if names else np.zeros(0))


def check_parameter_sets(parameter_sets: object) -> list[dict[str, Any]]:
    """The parameter sets as a list of dicts (copies); an InputError unless ``parameter_sets``
    is a list of ``{dotted key: value}`` mappings (one dict alone is refused: wrap it in a
    list)."""
    if isinstance(parameter_sets, Mapping):
        raise InputError(
            "parameter_sets: got one dict; allowed a list of {key: value} dicts, one per run "
            "(wrap it: [{...}])"
        )
    if isinstance(parameter_sets, str | bytes) or not isinstance(parameter_sets, Iterable):
        raise InputError(
            f"parameter_sets: got {type(parameter_sets).__name__}; allowed a list of "
            "{key: value} dicts, one per run"
        )
    sets = []
    for i, ov in enumerate(parameter_sets):
        if not isinstance(ov, Mapping):
            raise InputError(
                f"parameter_sets: entry {i} is a {type(ov).__name__}, not a {{key: value}} "
                "dict; allowed a list of {key: value} dicts, one per run"
            )
        sets.append(dict(ov))
    return sets


def check_workers(workers: object, *, none: bool = False) -> None:
    """An InputError unless ``workers`` is an integer (or None, with ``none``)."""
    if none and workers is None:
        return
    if isinstance(workers, bool) or not isinstance(workers, numbers.Integral):
        also = ", or None to decide from the cost of a run" if none else ""
        raise InputError(
            f"workers: {workers!r} is not allowed; allowed an integer (1: run here, 0 or less: "
            f"all cores){also}"
        )


def build_models(
    base: Scenario, parameter_sets: Sequence[Mapping[str, Any]], duration: float | None
) -> list[Model]:
    """Validate every parameter set on top of ``base`` and build its model.

    Raises
    ------
    InputError
        The first bad set, with its index, the key and the allowed range.
    """
    models = []
    for i, ov in enumerate(parameter_sets):
        try:
            sc = base.with_overrides(ov) if ov else base
            models.append(build_model(sc, duration))
        except InputError as exc:
            raise InputError(f"parameter set {i}: {exc}") from None
    return models


def run_models(
    models: Sequence[Model], opts: RunOptions, threads: int = 1
) -> tuple[np.ndarray, np.ndarray | None, list[str]]:
    """Run models in this process: (values (n, metrics), series, failures).

    ``threads > 1`` runs them on a pool of that many threads, each taking the next run when
    it is free (runs differ in cost several times over, so one run at a time balances best;
    a task costs ~12 us on the development machine against milliseconds of integration).
    """
    n = len(models)
    values = np.empty((n, len(METRICS)))
    series = np.empty((n, len(opts.series), opts.series_times.size)) if opts.series else None
    failures = []
    outs: Iterable[tuple[np.ndarray, np.ndarray | None, str]]
    if threads > 1:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=threads) as pool:
            outs = list(pool.map(lambda model: run_metrics(model, opts), models))
    else:
        outs = (run_metrics(model, opts) for model in models)
    for i, (v, s, f) in enumerate(outs):
        values[i] = v
        if series is not None and s is not None:
            series[i] = s
        failures.append(f)
    return values, series, failures


def _run_payload(
    base: tuple[Any, ...],
    parameter_sets: Sequence[Mapping[str, Any]],
    duration: float | None,
    opts: RunOptions,
) -> tuple[np.ndarray, np.ndarray | None, list[str]]:
    """Worker-process entry: rebuild the scenario, build and run the models."""
    models = build_models(scenario_from_payload(base), parameter_sets, duration)
    return run_models(models, opts)


def typed_metrics(values: np.ndarray) -> dict[str, np.ndarray]:
    """Split an (n, len(METRICS)) float array into named arrays of each metric's dtype
    (NaN becomes -1 in the integer metrics)."""
    out = {}
    for j, m in enumerate(METRICS):
        col = values[:, j]
        if m.dtype.startswith("int"):
            col = np.where(np.isfinite(col), col, -1.0)
        out[m.name] = col.astype(m.dtype)
    return out


@dataclass(frozen=True)
class BatchResult:
    """What :func:`simulate_batch` returns.

    Attributes
    ----------
    parameter_sets : list of dict
        The overrides of each run, as given.
    metrics : dict of str to np.ndarray
        One array per entry of :data:`METRICS`, length n (units in :data:`METRICS`).
    failure : np.ndarray
        Per run: "" when it finished, else the reason it failed.
    series : dict of str to np.ndarray
        (n, len(series_times)) samples of each requested kernel column.
    series_times : np.ndarray
        Sample times [s] of ``series``.
    windows : np.ndarray
        (n, 2) metrics window of each run [s].
    parameters : dict of str to np.ndarray
        Every key that a parameter set gives, resolved for each run in SI (the scenario's
        value where a set leaves the key out): floats, or the text of a choice such as a
        contact law. Units in :meth:`units`.
    """

    parameter_sets: list[dict[str, Any]]
    metrics: dict[str, np.ndarray]
    failure: np.ndarray
    series: dict[str, np.ndarray]
    series_times: np.ndarray
    windows: np.ndarray
    parameters: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.parameter_sets)

    def __repr__(self) -> str:
        labels = self.regime_labels()
        counts = ", ".join(f"{labels.count(r)} {r}" for r in dict.fromkeys(labels))
        keys = ", ".join(self.parameters) or "none"
        return (
            f"<braidsim.BatchResult: {len(self)} runs ({int(self.failed.sum())} failed); "
            f"parameters {keys}; regimes {counts or '-'}>"
        )

    @property
    def failed(self) -> np.ndarray:
        """Boolean mask of the runs that failed numerically."""
        return self.metrics["regime"] == REGIME_FAILED

    def regime_labels(self) -> list[str]:
        """Regime of each run as text ("failed" for a failed run)."""
        return ["failed" if r < 0 else REGIMES[r] for r in self.metrics["regime"]]

    def units(self) -> dict[str, str]:
        """SI unit of every parameter and metric column ("" for none)."""
        out = {key: SCHEMA[key].unit for key in self.parameters}
        out.update({m.name: m.unit for m in METRICS})
        return out

    def to_dataframe(self) -> pd.DataFrame:
        """One row per run: the parameters in SI (:attr:`parameters`), the metrics and
        ``failure``; ``attrs["units"]`` gives the unit of each column."""
        import pandas as pd

        index = pd.RangeIndex(len(self), name="run")
        params = pd.DataFrame(dict(self.parameters), index=index)
        mets = pd.DataFrame(self.metrics, index=index)
        mets["failure"] = self.failure.astype(str)
        df = pd.concat([params, mets], axis=1)
        df.attrs["units"] = self.units()
        return df

    def to_xarray(self) -> xr.Dataset:
        """The metrics (and series) on a ``run`` dimension, units and descriptions in attrs;
        the parameters in SI as coordinates along ``run`` (``ds.swap_dims(run=KEY)`` or
        ``ds.where(ds[KEY] > v)`` select by them)."""
        import xarray as xr

        ds = xr.Dataset(
            coords={
                key: ("run", values, {"units": SCHEMA[key].unit})
                for key, values in self.parameters.items()
            }
        )
        for m in METRICS:
            ds[m.name] = (
                "run",
                self.metrics[m.name],
                {"units": m.unit, "description": m.description},
            )
        ds["failure"] = (
            "run",
            self.failure.astype(str),
            {"description": "reason of a numerical failure"},
        )
        if self.series:
            ds = ds.assign_coords(t=("t", self.series_times, {"units": "s"}))
            for name, arr in self.series.items():
                ds[name] = (("run", "t"), arr, {"units": SERIES_UNITS[name]})
        return ds


EXECUTORS = ("threads", "processes")  # what the parallel workers of simulate_batch are


def simulate_batch(
    scenario: Scenario | str | Path | Mapping[str, Any],
    parameter_sets: Sequence[Mapping[str, Any]],
    duration: float | str | None = None,
    *,
    window: tuple[float | str, float | str] | None = None,
    series: Sequence[str] = (),
    series_times: Sequence[float | str] | np.ndarray | None = None,
    workers: int = 1,
    executor: str = "threads",
) -> BatchResult:
    """Simulate many parameter sets with the compiled integrator and reduce each to metrics.

    Parameters
    ----------
    scenario : Scenario, str, Path or mapping
        The base scenario (built-in name, TOML path, mapping or a loaded Scenario).
    parameter_sets : sequence of mappings
        One ``{dotted key: value}`` per run, applied on top of ``scenario`` (numbers in SI or
        unit strings). Every set is validated before any run starts.
    duration : float or str, optional
        Simulated time of every run [s] (or a string with a unit, ``"10 ms"``); default each
        run's ``simulation.duration``.
    window : (float, float), optional
        Metrics window [s] (numbers in s or strings with a unit; module docstring), inside
        the shortest run; default its second half [D/2, D], as in a sweep.
    series : sequence of str
        Kernel columns to sample at ``series_times`` (:data:`SERIES_VARIABLES`).
    series_times : sequence of float, optional
        Increasing sample times [s] of ``series``, a flat list (numbers in s or strings with a
        unit).
    workers : int
        Parallel workers; 1 runs everything one after the other in this thread, 0 or less
        uses all cores.
    executor : {"threads", "processes"}
        What the workers are: threads of this process (default) or local processes. The
        results are the same bits either way.

    Returns
    -------
    BatchResult

    Raises
    ------
    InputError
        A bad parameter set (with its index) or option, before any run starts.
    """
    from braidsim.simulate import time_value

    base = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if duration is not None:
        duration = time_value("duration", duration)  # a number in s or a string with a unit
    check_workers(workers)
    if not isinstance(executor, str) or executor not in EXECUTORS:
        raise InputError(f"executor: {executor!r} is not known; allowed {' or '.join(EXECUTORS)}")
    sets = check_parameter_sets(parameter_sets)
    models = build_models(base, sets, duration)
    if window is None and models:
        # as a sweep: the start of a run is a transient (the release of an initial overlap,
        # the first impacts), so the metrics describe the second half of the shortest run
        d_min = min(m.duration for m in models)
        window = (0.5 * d_min, d_min)
    opts = check_options([m.duration for m in models], window, series, series_times)
    nw = max(1, min(local_processes(workers), len(models)))
    if executor == "processes" and nw > 1:
        values, ser, failures = _run_in_processes(base, sets, duration, opts, nw)
    else:
        values, ser, failures = run_models(models, opts, threads=nw)
    wins = np.array([_window_of(m, opts) for m in models]).reshape(-1, 2)
    series_out = {} if ser is None else {name: ser[:, k] for k, name in enumerate(opts.series)}
    return BatchResult(
        sets,
        typed_metrics(values),
        np.array(failures, dtype=object),
        series_out,
        opts.series_times,
        wins,
        resolved_parameters(models, sets),
    )


def resolved_parameters(
    models: Sequence[Model], sets: Sequence[Mapping[str, Any]]
) -> dict[str, np.ndarray]:
    """Every key the parameter sets give (a nested table's as dotted keys, as the overrides
    read them), as each run's model resolved it (SI)."""
    keys = list(dict.fromkeys(k for s in sets for k in flatten(s)))
    out: dict[str, np.ndarray] = {}
    for key in keys:
        vals = [m.scenario[key] for m in models]
        if all(isinstance(v, int | float) and not isinstance(v, bool) for v in vals):
            out[key] = np.array(vals, dtype=float)
        else:
            out[key] = np.array([str(v) for v in vals], dtype=object)
    return out


def start_resource_tracker() -> None:
    """Start multiprocessing's resource tracker (the process that frees the pools'
    semaphores and shared memory) with SIGHUP ignored, before any pool needs it.

    It ignores SIGINT and SIGTERM of itself, but a hangup sent to the process group (a
    closed terminal, ``timeout -s HUP``) killed it: it was started again, and printed a
    traceback for every resource the pool then gave back (50 lines on one SIGHUP). An
    ignored signal stays ignored across the tracker's exec. Nothing happens when it runs
    already or outside the main thread (where signals cannot be set).
    """
    import signal
    import threading
    from multiprocessing import resource_tracker

    hup = getattr(signal, "SIGHUP", None)
    if hup is None or threading.current_thread() is not threading.main_thread():
        return
    old = signal.signal(hup, signal.SIG_IGN)
    try:
        resource_tracker.ensure_running()
    finally:
        signal.signal(hup, old)


def die_with_parent() -> None:
    """Worker-pool initializer: end this worker when the process that made the pool ends.

    Without it, a worker outlives a command that dies without ending it: one killed with
    SIGKILL (which no handler sees), or one interrupted while its pool was still forking,
    whose newest worker the pool did not know yet when the command killed the workers. The
    worker then waits forever for tasks (it holds the write end of its own task queue), and
    holds the command's stdout and stderr open. Two ways, for the two start methods:

    - ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` (Linux): the kernel kills the worker when the
      process that forked it ends. That is the command for a ``fork`` worker, but the fork
      server for a ``forkserver`` worker, and the fork server outlives the command as long as
      its workers live (they hold its liveness pipe).
    - a daemon thread waits on the parent's sentinel (a connection to the process that
      started the worker, which reads as closed once that process ends) and ends the worker
      with ``os._exit``: every start method, every platform; it runs when the worker's
      compiled code lets go of the interpreter lock.

    A worker whose parent ended before this ran ends at once.
    """
    import ctypes
    import multiprocessing
    import signal
    import threading

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # pragma: no cover - not Linux
        pass
    parent = multiprocessing.parent_process()
    if parent is None:
        return
    if not parent.is_alive():
        os._exit(1)
    threading.Thread(
        target=_exit_when_closed, args=(parent.sentinel,), name="parent-watch", daemon=True
    ).start()


def _exit_when_closed(sentinel: int) -> None:
    """Block until ``sentinel`` reads as closed, then end this process at once."""
    from multiprocessing.connection import wait

    wait([sentinel])
    os._exit(1)


def local_processes(workers: int) -> int:
    """The number of local worker processes ``workers`` asks for: itself, or every core for
    0 or less (the meaning of ``--workers 0`` in every command with local workers)."""
    return (os.cpu_count() or 1) if workers <= 0 else int(workers)


def process_pool(workers: int, context: Any = None) -> ProcessPoolExecutor:
    """A ``ProcessPoolExecutor`` of ``workers`` processes whose workers end with this
    process (:func:`die_with_parent`); ``context``: its multiprocessing context (default
    :func:`process_context`). Every worker pool of braidsim is made here."""
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(
        max_workers=workers,
        mp_context=process_context() if context is None else context,
        initializer=die_with_parent,
    )


def process_context() -> Any:
    """The multiprocessing context of the worker processes.

    ``fork`` where the platform has it and this process runs a single thread: the workers
    start at once (no re-import of numba and the compiled kernel) and the caller's
    ``__main__`` is not run again, so scripts without a ``__main__`` guard and interactive
    sessions work. Otherwise ``forkserver`` (or ``spawn``), which are safe with threads.
    """
    import multiprocessing
    import threading

    start_resource_tracker()
    methods = multiprocessing.get_all_start_methods()
    if "fork" in methods and threading.active_count() == 1:
        return multiprocessing.get_context("fork")
    return multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")


def _run_in_processes(
    base: Scenario,
    sets: list[dict[str, Any]],
    duration: float | None,
    opts: RunOptions,
    workers: int,
) -> tuple[np.ndarray, np.ndarray | None, list[str]]:
    """Cut the runs into interleaved slices, one task per slice, over ``workers`` processes.

    Interleaving (run i goes to slice i mod k) balances slices whose cost varies along the
    parameter sets. The results are put back in the original order.
    """
    n = len(sets)
    k = min(n, 4 * workers)
    payload = scenario_payload(base)
    values = np.empty((n, len(METRICS)))
    series = np.empty((n, len(opts.series), opts.series_times.size)) if opts.series else None
    failures = [""] * n
    with process_pool(workers) as pool:
        futs = [pool.submit(_run_payload, payload, sets[j::k], duration, opts) for j in range(k)]
        for j, fut in enumerate(futs):
            v, s, f = fut.result()
            idx = np.arange(j, n, k)
            values[idx] = v
            if series is not None and s is not None:
                series[idx] = s
            for a, b in zip(idx, f, strict=True):
                failures[a] = b
    return values, series, failures
