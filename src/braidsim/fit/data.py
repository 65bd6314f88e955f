"""Measured records for :mod:`braidsim.fit`: read, check, convert to SI.

A record is a strictly increasing time axis ``t`` [s] (measured from the scenario's t = 0,
where its ``initial.*`` state holds) and one or more measured quantities of the carrier:

========================  ==========  ==================================================
name                      SI unit     what the model compares it with
========================  ==========  ==================================================
``x``                     m           the carrier's displacement x(t) (a laser sensor)
``acceleration``          m/s^2       its acceleration dvx/dt (an accelerometer)
``contact_force``         N           the track contact force, signed as the series
                                      (negative on the inner wall)
========================  ==========  ==================================================

Sources: a CSV file with a header row (a name may carry its unit in brackets, ``x [mm]``,
as ``braidsim run --out`` writes ``series.csv``; SI without one; other columns are ignored;
``track_contact_force`` is read as ``contact_force``), a netCDF file or an
:class:`xarray.Dataset` (a coordinate or variable ``t``; units from each variable's
``units`` attribute, SI without one), or in Python a :class:`pandas.DataFrame` or a dict of
arrays with the same column names.

An *impact list* is the other kind of record: one row per track impact, its onset time
``t`` [s] (strictly increasing) and one or more of

========================  ==========  ==================================================
name                      SI unit     what the model compares it with
========================  ==========  ==================================================
``peak_force``            N           the impact's largest contact-force magnitude
``velocity``              m/s         its approach speed at onset (>= 0)
``rebound_velocity``      m/s         its separation speed at the end of the contact
``dissipated_energy``     J           the energy its contact law dissipated (a force -
                                      penetration loop's area)
========================  ==========  ==================================================

The kind is told by the columns: impact columns make an impact list, sample columns a
sampled record; a table with both is refused.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from braidsim.errors import InputError

QUANTITY_UNITS: dict[str, str] = {"x": "m", "acceleration": "m/s**2", "contact_force": "N"}
"""The quantities a measured record may hold, and their SI units (pint expressions)."""
#: quantities of an impact list and their SI units
IMPACT_UNITS: dict[str, str] = {
    "peak_force": "N",
    "velocity": "m/s",
    "rebound_velocity": "m/s",
    "dissipated_energy": "J",
}
#: other names accepted for a quantity (the column names of ``braidsim run --out``)
ALIASES: dict[str, str] = {"track_contact_force": "contact_force", "ax": "acceleration"}
#: largest record read [samples]
MAX_SAMPLES = 50_000_000
#: largest magnitude of a measured value [SI]. Far beyond any sensor's range (an
#: accelerometer's 1e6 m/s^2, a force washer's 1e7 N), and small enough that the fit's
#: differences, squares and sums of squares of such values stay finite in float64 (1e200
#: per square, over MAX_SAMPLES samples); a glitch of 1e308 overflowed the noise estimate's
#: second differences and then the time-scale check (an internal error).
MAX_MAGNITUDE = 1e100

_HEADER = re.compile(r"^\s*([^\[\]]*?)\s*(?:\[\s*([^\]]*?)\s*\])?\s*$")


@dataclass(frozen=True)
class Record:
    """A measured record in SI.

    Attributes
    ----------
    t : ndarray
        Sample times [s], strictly increasing, >= 0.
    columns : dict
        ``{quantity: values}`` in SI (see :data:`QUANTITY_UNITS`), each as long as ``t``.
    source : str
        Where it came from (a path or "xarray"), for messages and the report.
    """

    t: np.ndarray
    columns: Mapping[str, np.ndarray]
    source: str = "record"
    units_read: Mapping[str, str] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        """Time of the last sample [s]."""
        return float(self.t[-1])

    @property
    def sample_interval(self) -> float:
        """Median spacing of the samples [s]."""
        return float(np.median(np.diff(self.t)))


@dataclass(frozen=True)
class ImpactList:
    """A measured list of track impacts in SI (see the module docstring).

    Attributes
    ----------
    t : ndarray
        Impact onset times [s], strictly increasing, >= 0.
    columns : dict
        ``{quantity: values}`` in SI (see :data:`IMPACT_UNITS`), each as long as ``t``.
    source : str
    """

    t: np.ndarray
    columns: Mapping[str, np.ndarray]
    source: str = "impact list"
    units_read: Mapping[str, str] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        """Onset time of the last impact [s]."""
        return float(self.t[-1])


def _factor(where: str, unit: str, quantity: str) -> float:
    """The factor that converts values in ``unit`` to the SI unit of ``quantity``."""
    from braidsim.units import to_si

    target = "s" if quantity == "t" else {**QUANTITY_UNITS, **IMPACT_UNITS}[quantity]
    if not unit:
        return 1.0
    try:
        return to_si(where, f"1 {unit}", target)
    except InputError:
        # (pint's g is the gram: an accelerometer's g is its g0, standard gravity)
        hint = " (g is the gram: write [g0] for standard gravity)" if unit.strip() == "g" else ""
        raise InputError(
            f"{where}: unit [{unit}] does not match the quantity {quantity!r}{hint}; "
            f"allowed a unit of {target}"
        ) from None


def _to_si(values: Any, where: str, unit: str, quantity: str) -> np.ndarray:
    """``values`` (a flat float array) in ``unit`` converted to the SI unit of ``quantity``;
    a value the conversion takes past the float range becomes inf, without numpy's
    overflow warning (the checks that follow refuse it in one line)."""
    v = np.asarray(values, dtype=float).ravel()
    with np.errstate(over="ignore"):
        return v * _factor(where, unit, quantity)


def _check_magnitude(source: str, name: str, v: np.ndarray, t: np.ndarray, q: str) -> None:
    """Refuse a value of column ``name`` (SI, quantity ``q``) beyond :data:`MAX_MAGNITUDE`."""
    bad = np.flatnonzero(~(np.abs(v) <= MAX_MAGNITUDE))
    if bad.size:
        i = int(bad[0])
        unit = {**QUANTITY_UNITS, **IMPACT_UNITS}[q]
        raise InputError(
            f"{source}: column {name} has {v[i]:.3g} {unit} at row {i} (t = {t[i]:.9g} s); "
            f"allowed magnitudes up to {MAX_MAGNITUDE:g} {unit} (a glitch or a wrong unit? "
            "check the record)"
        )


def make_record(
    t: Any,
    columns: Mapping[str, Any],
    units: Mapping[str, str] | None = None,
    source: str = "record",
) -> Record:
    """A checked :class:`Record` from arrays (values in ``units``, SI where not given).

    Raises
    ------
    InputError
        No time, no known quantity, NaN or infinite values, time not strictly increasing or
        negative, fewer than 3 samples, a unit that does not match its quantity.
    """
    units = dict(units or {})
    tt = _to_si(t, f"{source}: column t", units.get("t", ""), "t")
    if tt.size < 3:
        raise InputError(f"{source}: {tt.size} samples; allowed a record of at least 3 samples")
    if tt.size > MAX_SAMPLES:
        raise InputError(f"{source}: {tt.size} samples; allowed at most {MAX_SAMPLES}")
    bad = np.flatnonzero(~np.isfinite(tt))
    if bad.size:
        raise InputError(f"{source}: column t has a missing or non-finite value at row {bad[0]}")
    if tt[0] < 0:
        raise InputError(
            f"{source}: column t starts at {tt[0]:g} s; allowed times >= 0 (measured from the "
            "scenario's start)"
        )
    steps = np.diff(tt)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise InputError(
            f"{source}: column t is not strictly increasing at row {i} "
            f"(t = {tt[i - 1]:.9g} s then {tt[i]:.9g} s); allowed increasing sample times"
        )
    out: dict[str, np.ndarray] = {}
    for name, values in columns.items():
        q = ALIASES.get(name, name)
        if q not in QUANTITY_UNITS:
            raise InputError(
                f"{source}: unknown quantity {name!r}; allowed {', '.join(QUANTITY_UNITS)}"
            )
        v = np.asarray(values, dtype=float).ravel()
        if v.shape != tt.shape:
            raise InputError(f"{source}: column {name} has {v.size} values for {tt.size} times")
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise InputError(
                f"{source}: column {name} has a missing or non-finite value (NaN) at row "
                f"{bad[0]} (t = {tt[bad[0]]:.9g} s); allowed finite numbers (drop or fill "
                "the gap first)"
            )
        out[q] = _to_si(v, f"{source}: column {name}", units.get(name, ""), q)
        _check_magnitude(source, name, out[q], tt, q)
    if not out:
        raise InputError(
            f"{source}: no measured column; allowed one or more of {', '.join(QUANTITY_UNITS)}"
        )
    return Record(tt, out, source, {k: units.get(k, "") for k in ("t", *columns)})


def make_impact_list(
    t: Any,
    columns: Mapping[str, Any],
    units: Mapping[str, str] | None = None,
    source: str = "impact list",
) -> ImpactList:
    """A checked :class:`ImpactList` from arrays (values in ``units``, SI where not given).

    Raises
    ------
    InputError
        No impact, no known quantity, NaN, negative or non-increasing times, negative
        peak forces or speeds, a unit that does not match its quantity.
    """
    units = dict(units or {})
    tt = _to_si(t, f"{source}: column t", units.get("t", ""), "t")
    if tt.size == 0:
        raise InputError(f"{source}: no impact; allowed an impact list of at least one row")
    bad = np.flatnonzero(~np.isfinite(tt))
    if bad.size:
        raise InputError(f"{source}: column t has a missing or non-finite value at row {bad[0]}")
    if tt[0] < 0:
        raise InputError(
            f"{source}: column t starts at {tt[0]:g} s; allowed times >= 0 (measured from the "
            "scenario's start)"
        )
    bad = np.flatnonzero(np.diff(tt) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise InputError(
            f"{source}: impact times are not strictly increasing at row {i} "
            f"(t = {tt[i - 1]:.9g} s then {tt[i]:.9g} s); allowed one row per impact in "
            "the order they happen"
        )
    out: dict[str, np.ndarray] = {}
    for name, values in columns.items():
        if name not in IMPACT_UNITS:
            raise InputError(
                f"{source}: unknown impact quantity {name!r}; allowed {', '.join(IMPACT_UNITS)}"
            )
        v = np.asarray(values, dtype=float).ravel()
        if v.shape != tt.shape:
            raise InputError(f"{source}: column {name} has {v.size} values for {tt.size} times")
        bad = np.flatnonzero(~np.isfinite(v) | (v < 0))
        if bad.size:
            raise InputError(
                f"{source}: column {name} has a missing, non-finite or negative value at row "
                f"{bad[0]} (t = {tt[bad[0]]:.9g} s); allowed finite magnitudes >= 0"
            )
        out[name] = _to_si(v, f"{source}: column {name}", units.get(name, ""), name)
        _check_magnitude(source, name, out[name], tt, name)
        if name == "peak_force" and not np.all(v > 0):
            # (a contact has a positive peak force: a list of zeros gave no noise scale, its
            # fit ended where the model lacked impacts, "simulation failed")
            i = int(np.flatnonzero(~(v > 0))[0])
            raise InputError(
                f"{source}: column peak_force is 0 at row {i} (t = {tt[i]:.9g} s); allowed "
                "peak forces > 0 (an impact's; leave out a row without one)"
            )
    if not out:
        raise InputError(
            f"{source}: no impact quantity; allowed one or more of {', '.join(IMPACT_UNITS)}"
        )
    return ImpactList(tt, out, source, {k: units.get(k, "") for k in ("t", *columns)})


def _split_header(name: str) -> tuple[str, str]:
    m = _HEADER.match(name)
    if m is None:
        return name.strip(), ""
    return m.group(1), (m.group(2) or "")


def from_table(table: Mapping[Any, Any], source: str) -> Record | ImpactList:
    """A record or an impact list from named columns (``{header: values}``; a header may
    carry its unit in brackets, ``peak_force [kN]``); the kind is told by the columns."""
    t_col = None
    cols: dict[str, Any] = {}
    units: dict[str, str] = {}
    for raw in table:
        name, unit = _split_header(str(raw))
        if name == "t":
            t_col = raw
            units["t"] = unit
        elif name in QUANTITY_UNITS or name in ALIASES or name in IMPACT_UNITS:
            q = ALIASES.get(name, name)
            if q in cols:
                raise InputError(f"{source}: two columns give {q}; allowed one")
            cols[q] = raw
            units[q] = unit
    if t_col is None:
        raise InputError(
            f"{source}: no column t (the sample or impact times); allowed a header with t [s]"
        )
    if not cols:
        # (a t column alone was taken for a record of samples: "2 samples; allowed a record
        # of at least 3 samples")
        raise InputError(
            f"{source}: no measured column beside t; allowed one or more of "
            f"{', '.join(QUANTITY_UNITS)} (a record) or {', '.join(IMPACT_UNITS)} (an impact "
            "list)"
        )
    impact = [q for q in cols if q in IMPACT_UNITS]
    if impact and len(impact) != len(cols):
        raise InputError(
            f"{source}: columns {', '.join(cols)} mix sampled quantities and impact "
            "quantities; allowed one kind per record"
        )
    data: dict[str, np.ndarray] = {}
    for q, raw in {"t": t_col, **cols}.items():
        v = np.asarray(table[raw])
        if v.dtype.kind not in "biuf":
            import pandas as pd

            v = pd.to_numeric(pd.Series(v.ravel()), errors="coerce").to_numpy(dtype=float)
        v = v.astype(float)
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise InputError(
                f"{source}: column {q} has a missing, non-finite or non-numeric value (NaN) at "
                f"data row {bad[0] + 1}; allowed finite numbers"
            )
        data[q] = v
    t = data.pop("t")
    if "kind" in table and not impact and t.size:
        # braidsim's own series (`braidsim run --csv`'s series.csv) repeats a sample time in
        # its start and end rows and at a transfer's state map (before and after): kept as
        # Result.to_xarray and series.nc keep them, the last row of each equal time. A
        # measured record has no kind column; its times must increase strictly.
        last = np.ones(t.size, dtype=bool)
        last[:-1] = t[1:] != t[:-1]
        t = t[last]
        data = {q: v[last] for q, v in data.items()}
    if impact:
        return make_impact_list(t, data, units, source)
    return make_record(t, data, units, source)


def read_csv(path: str | Path) -> Record | ImpactList:
    """A record or an impact list from a CSV file with a header row (see the module
    docstring)."""
    import pandas as pd

    p = Path(path)
    if not p.is_file():
        raise InputError(f"data (--data): {str(p)!r} is not a file; allowed a CSV or netCDF record")
    import warnings

    try:
        with warnings.catch_warnings():
            # a row longer than the header: pandas took the first column for an index (every
            # column shifted, read as a NaN at row 1) or, told not to, dropped the extra
            # fields with a warning; either is an error of the file
            warnings.simplefilter("error", pd.errors.ParserWarning)
            df = pd.read_csv(p, comment="#", skipinitialspace=True, index_col=False)
    except pd.errors.ParserWarning:
        raise InputError(
            f"{p}: a data row has more fields than the header's {len(_header_names(p))}; "
            "allowed rows of the header's length"
        ) from None
    except (ValueError, UnicodeDecodeError, pd.errors.ParserError) as exc:
        line = " ".join(str(exc).split())[:120]
        raise InputError(f"{p}: cannot read as CSV ({line})") from None
    header = [str(c) for c in df.columns]
    first = _header_names(p)
    seen = set()
    for name in first:
        if name in seen:
            # (pandas renamed the second one "name.1", which no quantity matched: ignored)
            raise InputError(f"{p}: column {name!r} appears twice; allowed each column once")
        seen.add(name)
    return from_table({c: df[c].to_numpy() for c in header}, str(p))


def _header_names(path: Path) -> list[str]:
    """The names of a CSV file's header row as written (the first line that is not empty or
    a # comment), each stripped."""
    with path.open(encoding="utf-8", errors="replace") as f:
        for line in f:
            text = line.split("#", 1)[0].strip()
            if text:
                return [" ".join(name.split()) for name in text.split(",")]
    return []


def from_xarray(ds: Any, source: str = "xarray") -> Record:
    """A record from an :class:`xarray.Dataset` (a coordinate or variable ``t``; units from
    each variable's ``units`` attribute)."""
    if "t" not in ds.variables:
        raise InputError(f"{source}: no coordinate or variable t (the sample times)")
    cols: dict[str, Any] = {}
    units = {"t": str(ds["t"].attrs.get("units", ""))}
    for name in ds.data_vars:
        q = ALIASES.get(str(name), str(name))
        if q in QUANTITY_UNITS and q not in cols:
            cols[q] = ds[name].values
            units[q] = str(ds[name].attrs.get("units", ""))
    return make_record(ds["t"].values, cols, units, source)


def read_record(data: Any) -> Record | ImpactList:
    """A record from a path (``.csv``, ``.nc``/``.nc4``/``.netcdf``), an xarray Dataset, a
    pandas DataFrame or dict of arrays (named columns), a :class:`Record` or an
    :class:`ImpactList`.

    Raises
    ------
    InputError
        The file is missing or unreadable, or the record fails the checks of
        :func:`make_record`.
    """
    if isinstance(data, Record | ImpactList):
        return data
    if hasattr(data, "data_vars"):
        return from_xarray(data)
    if isinstance(data, Mapping):
        return from_table(data, "dict")
    if hasattr(data, "columns") and hasattr(data, "to_numpy"):
        return from_table({c: data[c].to_numpy() for c in data.columns}, "DataFrame")
    if not isinstance(data, str | Path):
        raise InputError(
            "data (--data): expected a CSV or netCDF path or an xarray Dataset, got "
            f"{type(data).__name__}"
        )
    p = Path(data)
    if p.suffix.lower() in (".nc", ".nc4", ".netcdf", ".h5"):
        if not p.is_file():
            raise InputError(
                f"data (--data): {str(p)!r} is not a file; allowed a CSV or netCDF record"
            )
        import xarray as xr

        try:
            with xr.open_dataset(p) as ds:
                return from_xarray(ds.load(), str(p))
        except (OSError, ValueError) as exc:
            line = " ".join(str(exc).split())[:120]
            raise InputError(f"{p}: cannot read as netCDF ({line})") from None
    return read_csv(p)


def pulse_levels(y: np.ndarray, noise: float, fraction: float = 0.05) -> tuple[float, float, float]:
    """``(base, threshold, top)`` of an acceleration or contact-force record [its units]:
    the median ``base`` (free flight, or rest on a wall), the largest distance ``top`` of a
    sample from it, and the pulse threshold ``max(6 noise, fraction * top)`` of
    :func:`detect_pulses`."""
    base = float(np.median(y))
    top = float(np.max(np.abs(y - base))) if y.size else 0.0
    return base, max(6.0 * noise, fraction * top), top


def detect_pulses(
    t: np.ndarray, y: np.ndarray, noise: float, fraction: float = 0.05
) -> tuple[np.ndarray, float]:
    """Onset times [s] of the impact pulses of an acceleration or contact-force record.

    A pulse is a run of samples whose distance from the record's median (free flight, or
    rest on a wall) exceeds ``threshold = max(6 noise, fraction * largest distance)``; runs
    closer than two samples merge. The onset is the time of the run's first sample less half
    a sample interval (the true onset lies between the last quiet sample and the first loud
    one). Returns ``(onsets, threshold)``.
    """
    base, thr, top = pulse_levels(y, noise, fraction)
    loud = np.abs(y - base) > thr
    if not loud.any() or not math.isfinite(thr) or top <= 0:
        return np.zeros(0), thr
    idx = np.flatnonzero(loud)
    starts = [idx[0]]
    for a, b in itertools.pairwise(idx):
        if b - a > 2:
            starts.append(b)
    dt = np.median(np.diff(t))
    return np.maximum(t[np.asarray(starts)] - 0.5 * dt, 0.0), thr


def noise_estimate(y: np.ndarray) -> float:
    """A robust estimate of white measurement noise [units of y]: the scaled median absolute
    deviation of the second differences, sigma = 1.4826 MAD(d2 y) / sqrt(6) (the second
    difference of white noise has variance 6 sigma^2; the median ignores impact pulses and
    the smooth motion adds ~ a dt^2 per sample, negligible at sensor rates)."""
    d2 = np.diff(y, 2)
    if d2.size == 0:
        return 0.0
    mad = float(np.median(np.abs(d2 - np.median(d2))))
    return 1.4826 * mad / math.sqrt(6.0)
