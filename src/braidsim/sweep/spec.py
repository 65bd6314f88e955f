"""The sweep specification: a TOML file read and validated whole before any run starts.

Format (every quantity a number in SI or a string with units)::

    name = "h_a against omega"              # optional
    scenario = "paper-3.3"                  # built-in name or TOML path (relative to this file)
    duration = "1 s"                        # optional; default simulation.duration

    [overrides]                             # optional fixed changes to the scenario
    "friction.law" = "tanh"                 # dotted keys, or nested tables [overrides.track]

    [[axes]]                                # one grid dimension per [[axes]] table
    key = "horn_gear.angular_velocity"      # a scenario key (braidsim scenarios --keys)
    name = "omega"                          # dimension name; default: the key
    values = ["120 rpm", "240 rpm"]         # explicit values ...

    [[axes]]
    key = "track.vibration_amplitude"
    start = "0.02 mm"                       # ... or a range:
    stop = "0.3 mm"
    num = 29
    spacing = "linear"                      # or "log"

    [samples]                               # optional: a "run" dimension of sampled points
    method = "latin_hypercube"              # or "random"
    n = 100
    seed = 1
    [samples.ranges]
    "track.clearance" = { low = "1 mm", high = "4 mm" }                  # uniform
    "contact.track.restitution" = { low = 0.3, high = 0.9, spacing = "log" }

    [metrics]
    keep = ["regime", "track_max_contact_force"]    # default: all of braidsim.batch.METRICS
    window = ["0.5 s", "1 s"]               # metrics window; default: second half of the run

    [series]                                # optional sampled time series of every run
    variables = ["x", "track_contact_force"]  # columns of braidsim.core.CARRIER_COLUMNS
    start = "0.9 s"                         # a uniform grid (or times = [...])
    stop = "1 s"
    num = 101

    [execution]
    chunk_size = 32                         # runs per chunk; default: automatic
    retries = 2                             # attempts after a chunk's task fails

The dimensions of the result are the axes in their order, then ``run`` when there are
samples (every grid point runs every sample point). Latin-hypercube samples put one point in
each of ``n`` equal strata of every range, strata paired by independent random permutations
(McKay, Beckman & Conover 1979); both methods draw from ``numpy.random.default_rng(seed)``
and ``log`` spacing samples uniformly in log(value).

Everything is checked before any work: unknown keys (naming the closest known key), empty
ranges, wrong units, out-of-range values, a window longer than a run, unknown metrics and
series variables. Each error is an :class:`~braidsim.errors.InputError` of one line.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from braidsim import limits
from braidsim.batch import METRIC_NAMES, SERIES_VARIABLES, RunOptions, check_options
from braidsim.errors import InputError
from braidsim.params import SCHEMA, Scenario, builtin_names, convert, flatten, load_scenario
from braidsim.specfile import check_choice, check_keys, closest_hint, expect_table
from braidsim.units import to_si

TOP_KEYS = (
    "name",
    "description",
    "scenario",
    "duration",
    "overrides",
    "axes",
    "samples",
    "metrics",
    "series",
    "execution",
)
AXIS_KEYS = ("key", "name", "values", "start", "stop", "num", "spacing")
SAMPLES_KEYS = ("method", "n", "seed", "ranges")
RANGE_KEYS = ("low", "high", "spacing")
METRICS_KEYS = ("keep", "window")
SERIES_KEYS = ("variables", "times", "start", "stop", "num")
EXECUTION_KEYS = ("chunk_size", "retries")
SAMPLE_METHODS = ("random", "latin_hypercube")
SPACINGS = ("linear", "log")
AXIS_KINDS = ("float", "int", "choice", "bool")
RUN_DIM = "run"
TIME_DIM = "t"
#: an axis name: letters, digits and underscores in dot-separated words, starting with a
#: letter (it names a folder of the store, so no "/", "..", hidden or reserved names)
AXIS_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,63}(\.[A-Za-z][A-Za-z0-9_]{0,63}){0,7}")
#: names used by the store itself
RESERVED_NAMES = ("failure", "zarr.json", "run", "t")
MIN_AUTO_CHUNK = 64
MAX_AUTO_CHUNK = 256


def _int(where: str, value: Any, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise InputError(f"{where}: {value!r} is not allowed; allowed an integer >= {low}")
    return int(value)


def _time(where: str, value: Any) -> float:
    t = to_si(where, value, "s")
    if not math.isfinite(t) or t < 0.0:
        raise InputError(f"{where}: {t:g} s is out of range; allowed a finite time >= 0 s")
    return t


def _param_key(where: str, key: Any) -> str:
    if not isinstance(key, str) or key not in SCHEMA:
        close = difflib.get_close_matches(str(key), list(SCHEMA), n=1, cutoff=0.4)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise InputError(
            f"{where}: unknown parameter {key!r}{hint}; `braidsim scenarios --keys` lists all"
        )
    return key


@dataclass(frozen=True)
class Axis:
    """One grid dimension.

    Attributes
    ----------
    name : str
        Dimension name.
    key : str
        Scenario key it sets.
    values : tuple
        Values in SI (floats), or strings / booleans / integers for such keys.
    unit : str
        SI unit of the key ("" when none).
    spacing : str
        ``values``, ``linear`` or ``log``.
    """

    name: str
    key: str
    values: tuple[Any, ...]
    unit: str
    spacing: str


@dataclass(frozen=True)
class Samples:
    """Sampled points: a ``run`` dimension.

    Attributes
    ----------
    method : str
        ``random`` or ``latin_hypercube``.
    n : int
        Number of points.
    seed : int
        Seed of ``numpy.random.default_rng``.
    keys : tuple of str
        Sampled scenario keys.
    low, high : tuple of float
        Ranges in SI.
    spacing : tuple of str
        ``linear`` or ``log`` per key.
    values : np.ndarray
        (n, len(keys)) sampled values in SI.
    """

    method: str
    n: int
    seed: int
    keys: tuple[str, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    spacing: tuple[str, ...]
    values: np.ndarray


def draw_samples(method: str, n: int, d: int, seed: int) -> np.ndarray:
    """(n, d) points in [0, 1): plain uniform (``random``) or Latin hypercube.

    Latin hypercube (:class:`scipy.stats.qmc.LatinHypercube`): for each dimension,
    u = (pi(i) + v_i) / n with pi a random permutation of 0..n-1 and v_i uniform in [0, 1),
    so every stratum [k/n, (k+1)/n) holds exactly one point in every dimension.
    """
    rng = np.random.default_rng(seed)
    if method == "random":
        return rng.random((n, d))
    from scipy.stats import qmc

    return qmc.LatinHypercube(d=d, rng=rng).random(n)


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep.

    Attributes
    ----------
    path : Path or None
        The spec file.
    text : str
        Its text (kept in the store).
    name : str
        Title.
    scenario_ref : str
        The ``scenario`` entry as written.
    base : Scenario
        Base scenario with the overrides applied.
    duration : float or None
        Simulated time of every run [s] (None: each run's ``simulation.duration``).
    axes : tuple of Axis
        Grid dimensions.
    samples : Samples or None
        Sampled points (``run`` dimension).
    metrics : tuple of str
        Metrics kept in the store.
    options : RunOptions
        Window, RMS grid, series.
    chunk_shape : tuple of int
        Runs per chunk along each dimension.
    retries : int
        Extra attempts of a failed chunk task.
    """

    path: Path | None
    text: str
    name: str
    scenario_ref: str
    base: Scenario
    duration: float | None
    axes: tuple[Axis, ...]
    samples: Samples | None
    metrics: tuple[str, ...]
    options: RunOptions
    chunk_shape: tuple[int, ...]
    retries: int

    def __repr__(self) -> str:
        shape = " x ".join(f"{d} {n}" for d, n in zip(self.dims, self.shape, strict=True))
        dur = "each run's duration" if self.duration is None else f"{self.duration:g} s"
        return (
            f"<braidsim.SweepSpec {self.name!r}: {self.base.name!r}, {shape} "
            f"({self.n_runs} runs), {dur}, {len(self.metrics)} metrics>"
        )

    # -------------------------------------------------------------- geometry
    @property
    def dims(self) -> tuple[str, ...]:
        """Dimension names: the axes, then ``run`` when sampled."""
        return tuple(a.name for a in self.axes) + ((RUN_DIM,) if self.samples else ())

    @property
    def shape(self) -> tuple[int, ...]:
        """Size of each dimension."""
        return tuple(len(a.values) for a in self.axes) + ((self.samples.n,) if self.samples else ())

    @property
    def n_runs(self) -> int:
        """Number of runs."""
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def chunk_grid(self) -> tuple[int, ...]:
        """Number of chunks along each dimension."""
        return tuple(-(-s // c) for s, c in zip(self.shape, self.chunk_shape, strict=True))

    @property
    def n_chunks(self) -> int:
        """Number of chunks."""
        return int(np.prod(self.chunk_grid, dtype=np.int64))

    def chunk_region(self, chunk: int) -> tuple[slice, ...]:
        """Index region (one slice per dimension) of chunk number ``chunk`` (C order)."""
        idx = np.unravel_index(chunk, self.chunk_grid)
        return tuple(
            slice(int(i) * c, min((int(i) + 1) * c, s))
            for i, c, s in zip(idx, self.chunk_shape, self.shape, strict=True)
        )

    def chunk_runs(self, chunk: int) -> tuple[tuple[str, ...], list[tuple[Any, ...]]]:
        """The varied keys and, per run of the chunk in C order, their values (SI)."""
        region = self.chunk_region(chunk)
        keys = tuple(a.key for a in self.axes) + (self.samples.keys if self.samples else ())
        grids = np.meshgrid(*[np.arange(r.start, r.stop) for r in region], indexing="ij")
        flat = [g.ravel() for g in grids]
        runs = []
        for j in range(flat[0].size if flat else 0):
            vals: list[Any] = [a.values[int(flat[k][j])] for k, a in enumerate(self.axes)]
            if self.samples is not None:
                vals.extend(float(v) for v in self.samples.values[int(flat[-1][j])])
            runs.append(tuple(vals))
        return keys, runs

    def run_durations(self) -> list[float]:
        """The distinct simulated times of the runs [s]."""
        if self.duration is not None:
            return [self.duration]
        for a in self.axes:
            if a.key == "simulation.duration":
                return [float(v) for v in a.values]
        return [float(self.base["simulation.duration"])]

    # -------------------------------------------------------------- identity
    def canonical(self) -> dict[str, Any]:
        """Everything that determines the store's contents, JSON-ready (for the hash)."""
        samples = None
        if self.samples is not None:
            s = self.samples
            samples = {
                "method": s.method,
                "n": s.n,
                "seed": s.seed,
                "keys": list(s.keys),
                "low": list(s.low),
                "high": list(s.high),
                "spacing": list(s.spacing),
                "values_sha256": hashlib.sha256(
                    np.ascontiguousarray(s.values).tobytes()
                ).hexdigest(),
            }
        o = self.options
        return {
            "format": 1,
            "parameters": self.base.to_dict(),
            "duration": self.duration,
            "axes": [
                {"name": a.name, "key": a.key, "values": list(a.values), "spacing": a.spacing}
                for a in self.axes
            ],
            "samples": samples,
            "metrics": list(self.metrics),
            "window": None if o.window is None else list(o.window),
            "series": list(o.series),
            "series_times": [float(t) for t in o.series_times],
            "chunk_shape": list(self.chunk_shape),
        }

    def digest(self) -> str:
        """SHA-256 of :meth:`canonical` (a store made from another spec is refused on resume)."""
        text = json.dumps(self.canonical(), sort_keys=True, allow_nan=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()


def check_range(
    values: tuple[float, float, int],
    names: tuple[str, str, str],
    said: tuple[str, str],
    unit: str,
    where: str = "",
    reversed_hint: str = "",
) -> None:
    """The rule of a range of ``num`` values from ``start`` to ``stop`` (``values``, SI):
    stop above start, or equal to it for a single value. A reversed range, several equal
    values, or one value with a stop it would not use is refused, naming the entry as the
    caller calls it (``names`` of start, stop and num after ``where``: a sweep axis's
    ``axes[0].stop``, bifurcation's ``--to``) with the values as typed (``said``) and in
    SI."""
    start, stop, num = values
    n_a, n_b, n_n = names
    s_a, s_b = said
    u = f" {unit}" if unit else ""
    if num > 1 and start == stop:
        raise InputError(
            f"{where}{n_b}: {s_b} equals {n_a} ({s_a}; {start:g}{u}), an empty range of {num} "
            f"equal values; allowed {n_b} > {n_a} (or {n_n} 1)"
        )
    if stop < start:  # (with num = 1 as well: stop would be ignored)
        raise InputError(
            f"{where}{n_b}: {s_b} ({stop:g}{u}) is below {n_a} ({s_a}; {start:g}{u}), a "
            f"reversed range; allowed {n_b} > {n_a}{reversed_hint}"
        )
    if num == 1 and stop != start:  # (the range's stop would be silently unused)
        raise InputError(
            f"{where}{n_n}: 1 value runs {n_a} only ({n_b} {s_b} would not be used); allowed "
            f"{n_n} >= 2, or {n_b} equal to {n_a} for a single value"
        )


def _axis(i: int, table: Any, base: Scenario) -> Axis:
    where = f"axes[{i}]."
    t = expect_table(f"axes[{i}]", table)
    check_keys(where, t, AXIS_KEYS)
    if "key" not in t:
        raise InputError(
            f"{where}key: missing; allowed any scenario key (braidsim scenarios --keys)"
        )
    key = _param_key(f"{where}key", t["key"])
    spec = SCHEMA[key]
    if spec.kind not in AXIS_KINDS:
        raise InputError(
            f"{where}key: {key} ({spec.kind}) cannot be an axis; "
            "allowed keys that hold one number, "
            "choice or boolean"
        )
    name = t.get("name", key)
    if (
        not isinstance(name, str)
        or not AXIS_NAME.fullmatch(name)
        or name in RESERVED_NAMES
        or name in METRIC_NAMES
        or (name in SCHEMA and name != key)
    ):
        raise InputError(
            f"{where}name: {str(name)[:40]!r} is not allowed; allowed a name of letters, digits "
            "and underscores (dots between words) starting with a letter, other than "
            f"{', '.join(RESERVED_NAMES)}, the metric names and other keys"
        )
    has_range = any(k in t for k in ("start", "stop", "num", "spacing"))
    if "values" in t and has_range:
        raise InputError(f"{where}values: give either values or start/stop/num, not both")
    if "values" in t:
        raw = t["values"]
        if not isinstance(raw, list) or not raw:
            raise InputError(f"{where}values: empty; allowed a non-empty list of values of {key}")
        limits.check("values", len(raw), f"{where}values")
        try:
            vals: list[Any] = [convert(spec, v) for v in raw]
        except InputError as exc:
            raise InputError(f"{where}values: {exc}") from None
        spacing = "values"
    else:
        for k in ("start", "stop", "num"):
            if k not in t:
                raise InputError(
                    f"{where}{k}: missing; a range needs start, stop and num (or give values)"
                )
        if spec.kind not in ("float", "int"):
            raise InputError(f"{where}start: {key} takes {spec.range_text()}; give explicit values")
        num = t["num"]
        if isinstance(num, float) and num.is_integer():
            num = int(num)  # (TOML's 3.0)
        if isinstance(num, bool) or not isinstance(num, int):
            raise InputError(f"{where}num: {num!r} is not a whole number; allowed an integer >= 1")
        if num < 1:
            raise InputError(f"{where}num: {num!r} gives an empty range; allowed an integer >= 1")
        limits.check("values", num, f"{where}num")
        start = spec.check_number(to_si(f"{where}start ({key})", t["start"], spec.unit))
        stop = spec.check_number(to_si(f"{where}stop ({key})", t["stop"], spec.unit))
        spacing = t.get("spacing", "linear")
        check_choice(f"{where}spacing", spacing, SPACINGS)
        # (the values as written, "60 rpm", and in SI: a unit other than SI's read as
        # bare numbers of another size)
        said = {k: (t[k] if isinstance(t[k], str) else f"{t[k]:g}") for k in ("start", "stop")}
        check_range(
            (start, stop, num),
            ("start", "stop", "num"),
            (said["start"], said["stop"]),
            spec.unit,
            where,
            " (list values = [...] for another order)",
        )
        if spacing == "log":
            if start <= 0.0 or stop <= 0.0:
                raise InputError(
                    f"{where}start: a log range needs start > 0 and stop > 0 (in {spec.unit})"
                )
            arr = np.geomspace(start, stop, num)
        else:
            arr = np.linspace(start, stop, num)
        if spec.kind == "int":
            arr = np.round(arr)
        # start and stop passed the range check, and the range is an interval: every value
        # between them passes too, so only the two ends go through the scenario checks below
        vals = [int(v) for v in arr] if spec.kind == "int" else [float(v) for v in arr]
    if len(set(vals)) != len(vals):
        raise InputError(
            f"{where}values: repeated values in {str(vals)[:80]}; allowed distinct values"
        )
    for v in vals if spacing == "values" else (vals[0], vals[-1]):
        try:
            base.with_overrides({key: v})
        except InputError as exc:
            raise InputError(f"{where}values: {exc}") from None
    return Axis(name, key, tuple(vals), spec.unit, spacing)


def _flatten_ranges(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in table.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping) and not any(r in v for r in RANGE_KEYS):
            out.update(_flatten_ranges(v, key + "."))
        else:
            out[key] = v
    return out


def _samples(table: Any, base: Scenario) -> Samples:
    t = expect_table("samples", table)
    check_keys("samples.", t, SAMPLES_KEYS)
    method = t.get("method", "latin_hypercube")
    check_choice("samples.method", method, SAMPLE_METHODS)
    if "n" not in t:
        raise InputError("samples.n: missing; allowed an integer >= 1")
    n = _int("samples.n", t["n"], 1)
    limits.check("values", n, "samples.n")
    seed = _int("samples.seed", t.get("seed", 0), 0)
    ranges = _flatten_ranges(expect_table("samples.ranges", t.get("ranges", {})))
    if not ranges:
        raise InputError(
            "samples.ranges: empty; allowed a table {KEY = {low = ..., high = ...}, ...}"
        )
    keys, lows, highs, spacings = [], [], [], []
    for key, rng in ranges.items():
        where = f"samples.ranges.{key}"
        _param_key(where, key)
        spec = SCHEMA[key]
        if spec.kind != "float":
            raise InputError(
                f"{where}: {key} takes {spec.range_text()}; only keys with a number can be sampled"
            )
        r = expect_table(where, rng)
        check_keys(f"{where}.", r, RANGE_KEYS)
        for k in ("low", "high"):
            if k not in r:
                raise InputError(f"{where}.{k}: missing; a sampled range needs low and high")
        lo = spec.check_number(to_si(f"{where}.low", r["low"], spec.unit))
        hi = spec.check_number(to_si(f"{where}.high", r["high"], spec.unit))
        if not hi > lo:
            raise InputError(
                f"{where}.high: {hi:g} is not above low ({lo:g}), an empty range; "
                "allowed high > low"
            )
        sp = r.get("spacing", "linear")
        if sp not in SPACINGS:
            raise InputError(
                f"{where}.spacing: {sp!r} is not allowed; allowed {', '.join(SPACINGS)}"
            )
        if sp == "log" and lo <= 0.0:
            raise InputError(
                f"{where}.low: a log range needs low > 0 (in {spec.unit or 'no unit'})"
            )
        for v in (lo, hi):
            try:
                base.with_overrides({key: v})
            except InputError as exc:
                raise InputError(f"{where}: {exc}") from None
        keys.append(key)
        lows.append(lo)
        highs.append(hi)
        spacings.append(sp)
    u = draw_samples(method, n, len(keys), seed)
    vals = np.empty_like(u)
    for j in range(len(keys)):
        if spacings[j] == "log":
            vals[:, j] = np.exp(np.log(lows[j]) + u[:, j] * (np.log(highs[j]) - np.log(lows[j])))
        else:
            vals[:, j] = lows[j] + u[:, j] * (highs[j] - lows[j])
        vals[:, j] = np.clip(vals[:, j], lows[j], highs[j])
    return Samples(method, n, seed, tuple(keys), tuple(lows), tuple(highs), tuple(spacings), vals)


def auto_chunk_size(n_runs: int) -> int:
    """Runs per chunk when the spec gives none: 1/64 of the runs, between 64 and 256.

    At least 64 runs, so that writing a chunk (some 30 ms: about 1 ms per zarr array, ~27
    arrays, by the sweep process while the workers compute) costs under a tenth of computing
    it (one-second paper-3.3 runs take ~6 ms each); at most 256, so that a million runs still
    make thousands of tasks to spread over a cluster. It depends on the number of runs only
    (not on the executor), so a store can be resumed with other workers.
    """
    return int(min(MAX_AUTO_CHUNK, max(MIN_AUTO_CHUNK, -(-n_runs // 64))))


def chunk_shape_for(shape: Sequence[int], size: int) -> tuple[int, ...]:
    """A block of at most ``size`` runs: the last dimensions whole, as far as they fit.

    Blocks are contiguous in the C order of the runs, so a chunk of the store is written by
    exactly one task and every task writes whole chunks of every variable.
    """
    out = [1] * len(shape)
    room = max(1, size)
    for k in range(len(shape) - 1, -1, -1):
        c = min(shape[k], room)
        out[k] = c
        room //= c
        if c < shape[k] or room <= 1:
            break
    return tuple(out)


def _series(table: Any, durations: Sequence[float]) -> tuple[tuple[str, ...], np.ndarray]:
    t = expect_table("series", table)
    check_keys("series.", t, SERIES_KEYS)
    names = t.get("variables", [])
    if not isinstance(names, list) or not names:
        raise InputError(
            f"series.variables: empty; allowed a list of {', '.join(SERIES_VARIABLES)}"
        )
    for v in names:
        if v not in SERIES_VARIABLES:
            raise InputError(
                f"series.variables: unknown variable {v!r}"
                f"{closest_hint(str(v), SERIES_VARIABLES)}; "
                f"allowed {', '.join(SERIES_VARIABLES)}"
            )
    if "times" in t:
        if any(k in t for k in ("start", "stop", "num")):
            raise InputError("series.times: give either times or start/stop/num, not both")
        raw = t["times"]
        if not isinstance(raw, list) or not raw:
            raise InputError("series.times: empty; allowed a non-empty list of times")
        limits.check("series_points", len(raw), "series.times")
        times = np.array([_time("series.times", v) for v in raw])
    else:
        for k in ("start", "stop", "num"):
            if k not in t:
                raise InputError(
                    f"series.{k}: missing; the series needs times = [...] or start, stop and num"
                )
        num = _int("series.num", t["num"], 1)
        limits.check("series_points", num, "series.num")
        a, b = _time("series.start", t["start"]), _time("series.stop", t["stop"])
        if num > 1 and not b > a:
            raise InputError(f"series.stop: {b:g} s is not after start ({a:g} s), an empty range")
        times = np.linspace(a, b, num)
    tmin = min(durations)
    if times.max() > tmin * (1 + 1e-12):
        raise InputError(
            f"series: sample time {times.max():g} s is after the end of the shortest run "
            f"({tmin:g} s)"
        )
    if np.any(np.diff(times) <= 0.0):
        raise InputError("series.times: must increase strictly")
    return tuple(names), times


def parse_spec(data: Mapping[str, Any], text: str = "", path: Path | None = None) -> SweepSpec:
    """Validate a spec table (already read from TOML); see the module docstring.

    Raises
    ------
    InputError
        The first problem found, naming the entry and what is allowed.
    """
    check_keys("", data, TOP_KEYS)
    if "scenario" not in data:
        raise InputError("scenario: missing; allowed a built-in scenario name or a TOML path")
    ref = data["scenario"]
    if not isinstance(ref, str):
        raise InputError(f"scenario: {ref!r} is not a name or a path")
    scen: str | Path = ref
    if ref not in builtin_names() and path is not None and (path.parent / ref).is_file():
        scen = path.parent / ref  # a scenario file next to the spec
    overrides = flatten(expect_table("overrides", data.get("overrides", {})))
    base = load_scenario(scen, overrides=overrides or None)
    duration = None
    if "duration" in data:
        duration = to_si("duration", data["duration"], "s")
        if not (math.isfinite(duration) and duration > 0.0):
            raise InputError(f"duration: {duration:g} s is out of range; allowed > 0 s")
    raw_axes = data.get("axes", [])
    if not isinstance(raw_axes, list):
        raise InputError("axes: expected [[axes]] tables")
    axes = tuple(_axis(i, a, base) for i, a in enumerate(raw_axes))
    samples = _samples(data["samples"], base) if "samples" in data else None
    if not axes and samples is None:
        raise InputError(
            "axes: the spec has no [[axes]] and no [samples]; allowed at least one of them"
        )
    names = [a.name for a in axes]
    keys = [a.key for a in axes] + list(samples.keys if samples else ())
    for seq, what in ((names, "name"), (keys, "key")):
        dup = {x for x in seq if seq.count(x) > 1}
        if dup:
            raise InputError(
                f"axes: {what} {sorted(dup)[0]!r} appears twice; allowed each {what} once"
            )
    both = sorted(set(keys) & set(overrides))
    if both:
        # the axis's values replace the override in every run: the override was ignored
        raise InputError(
            f"overrides.{both[0]}: also an axis or a sampled key of the sweep, whose values "
            "replace it in every run; allowed in one of the two"
        )
    if duration is not None and "simulation.duration" in keys:
        raise InputError(
            "duration: set both at the top and as an axis/sample of simulation.duration; keep one"
        )
    if samples is not None and "simulation.duration" in samples.keys:
        raise InputError(
            "samples.ranges.simulation.duration: the duration cannot be sampled; make it an axis"
        )

    met = expect_table("metrics", data.get("metrics", {}))
    check_keys("metrics.", met, METRICS_KEYS)
    keep = met.get("keep", list(METRIC_NAMES))
    if not isinstance(keep, list) or not keep:
        raise InputError(
            "metrics.keep: empty; allowed a list of metric names (braidsim.batch.METRICS)"
        )
    for m in keep:
        if m not in METRIC_NAMES:
            raise InputError(
                f"metrics.keep: unknown metric {m!r}{closest_hint(str(m), METRIC_NAMES)}; "
                f"allowed {', '.join(METRIC_NAMES)}"
            )
    if len(set(keep)) != len(keep):
        raise InputError("metrics.keep: a metric appears twice")
    metrics = tuple(m for m in METRIC_NAMES if m in keep)  # canonical order
    window = None
    if "window" in met:
        w = met["window"]
        if not isinstance(w, list) or len(w) != 2:
            raise InputError(f"metrics.window: {w!r} is not [T0, T1]; allowed two times")
        window = (_time("metrics.window", w[0]), _time("metrics.window", w[1]))

    partial = SweepSpec(
        path, text, "", ref, base, duration, axes, samples, metrics, RunOptions(), (1,), 0
    )
    durations = partial.run_durations()
    if window is None:
        # the start of a run is a transient (the first impacts): by default the metrics
        # describe the second half of the shortest run, [D/2, D]
        d_min = float(np.min(durations))
        window = (0.5 * d_min, d_min)
    series_names: tuple[str, ...] = ()
    series_times = None
    if "series" in data:
        series_names, series_times = _series(data["series"], durations)
    for a in axes:
        if a.name in series_names:
            raise InputError(
                f"axes: name {a.name!r} is also a series variable kept; allowed another name"
            )
    try:
        opts = check_options(durations, window, series_names, series_times)
    except InputError as exc:
        msg = str(exc)
        raise InputError(f"metrics.{msg}" if msg.startswith("window") else msg) from None

    ex = expect_table("execution", data.get("execution", {}))
    check_keys("execution.", ex, EXECUTION_KEYS)
    shape = partial.shape
    n_runs = math.prod(shape)  # exact (Python integers): no overflow for absurd grids
    limits.check("runs", n_runs, f"sweep {'x'.join(map(str, shape))}")
    n_t = 0 if series_times is None else int(series_times.size)
    per_run = 8 * (len(metrics) + len(series_names) * n_t) + 64  # float64s and a failure text
    limits.check("bytes", n_runs * per_run, "sweep store (estimated size)")
    size = (
        _int("execution.chunk_size", ex["chunk_size"], 1)
        if "chunk_size" in ex
        else auto_chunk_size(n_runs)
    )
    retries = _int("execution.retries", ex.get("retries", 2), 0)
    limits.check("memory", min(size, n_runs) * per_run * 2, "execution.chunk_size (memory)")
    name = data.get("name", path.stem if path else "sweep")
    return SweepSpec(
        path,
        text,
        str(name),
        ref,
        base,
        duration,
        axes,
        samples,
        metrics,
        opts,
        chunk_shape_for(shape, size),
        retries,
    )


def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a sweep spec TOML file.

    Raises
    ------
    InputError
        Missing or malformed file, or any problem listed in the module docstring.
    """
    from braidsim.specfile import parse_toml, read_text

    p = Path(path)
    if not p.is_file():
        raise InputError(f"SPEC: {str(p)!r} is not a file; allowed a sweep spec TOML file")
    text = read_text(p)
    data = parse_toml(text, str(p))
    if not data:
        raise InputError(f"{p}: the sweep spec is empty; allowed a spec with scenario and axes")
    return parse_spec(data, text, p)
