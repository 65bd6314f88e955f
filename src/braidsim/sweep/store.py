"""The sweep store: a zarr (format 3) group that xarray opens as the result Dataset.

Layout (``STORE/``)::

    zarr.json                 root attributes: spec text and hash, base parameters (SI), units
    <axis name>/              one coordinate array per grid axis (values in SI, ``units``)
    run/, <sampled key>/      with samples: the run index and each sampled parameter
    t/                        with series: the sample times
    <metric>/, failure/       one array per kept metric on the sweep's dimensions
    <series variable>/        sampled series on the dimensions plus ``t``
    _sweep/done/              one int8 per chunk: 1 once every array of that chunk is written

The arrays are chunked exactly like the work: one work chunk is one zarr chunk of every
array, written by one task, so no two tasks ever write to the same file. A chunk's data is
written first and its ``done`` flag last; zarr writes each file through a temporary name
and a rename, so after a kill (SIGKILL included) every file is either whole or absent and a
chunk without its flag is simply computed and written again on resume. Runs are
deterministic, so the rewritten bytes equal the ones an uninterrupted sweep writes. The
store is created whole under a temporary name and renamed into place, and it holds no
timestamps, so a resumed store equals an uninterrupted one.
"""

from __future__ import annotations

import json
import os
import shutil
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.batch import METRICS, REGIME_FAILED, REGIMES
from braidsim.errors import InputError
from braidsim.params import SCHEMA
from braidsim.result import UNITS as SERIES_UNITS
from braidsim.sweep.spec import RUN_DIM, TIME_DIM, SweepSpec

if TYPE_CHECKING:
    import xarray as xr
    import zarr

STORE_FORMAT = "braidsim-sweep/1"
_METRIC = {m.name: m for m in METRICS}


def _zarr() -> Any:
    import zarr

    return zarr


def _coord_dtype(values: tuple[Any, ...]) -> Any:
    if all(isinstance(v, bool) for v in values):
        return bool
    if all(isinstance(v, str) for v in values):
        return str
    if all(isinstance(v, int) for v in values):
        return np.int64
    return np.float64


def _root_attrs(spec: SweepSpec) -> dict[str, Any]:
    import braidsim

    o = spec.options
    return {
        "title": spec.name,
        "format": STORE_FORMAT,
        "source": f"braidsim {braidsim.__version__} sweep",
        # no creation date: a store is reproducible to the bit (a resumed store equals an
        # uninterrupted one), and the spec and parameters above say how it was made
        "braidsim_version": braidsim.__version__,
        "scenario": spec.base.name,
        "spec": spec.text,
        "spec_sha256": spec.digest(),
        "parameters": json.dumps(spec.base.to_dict(), sort_keys=True),
        "parameter_units": json.dumps({k: s.unit for k, s in SCHEMA.items()}, sort_keys=True),
        "duration": "simulation.duration of each run" if spec.duration is None else spec.duration,
        "metrics_window": "whole run" if o.window is None else list(o.window),
        "rms_x": "Gauss-Legendre quadrature of x^2 on the interpolant of every step",
        "regime_labels": json.dumps(
            {str(REGIME_FAILED): "failed", **{str(i): r for i, r in enumerate(REGIMES)}}
        ),
        "dims": list(spec.dims),
        "chunk_shape": list(spec.chunk_shape),
        "n_runs": spec.n_runs,
        "n_chunks": spec.n_chunks,
        "sign_convention": "parameters and metrics in SI; depths and forces are magnitudes",
    }


def create_store(spec: SweepSpec, path: str | Path) -> Path:
    """Create an empty store for ``spec`` at ``path`` (whole, or not at all).

    Raises
    ------
    InputError
        ``path`` exists already.
    """
    zarr = _zarr()
    final = Path(path)
    if final.exists():
        raise InputError(
            f"--out: {final} exists; pass --resume to finish it, or choose another path"
        )
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = final.parent / f".{final.name}.creating-{uuid.uuid4().hex[:8]}"
    try:
        g = zarr.open_group(str(tmp), mode="w", zarr_format=3, attributes=_root_attrs(spec))
        dims = spec.dims
        for a in spec.axes:
            arr = g.create_array(
                a.name,
                shape=(len(a.values),),
                chunks=(len(a.values),),
                dtype=_coord_dtype(a.values),
                dimension_names=[a.name],
                attributes={
                    "units": a.unit,
                    "key": a.key,
                    "spacing": a.spacing,
                    "description": SCHEMA[a.key].doc,
                },
            )
            arr[:] = np.array(a.values, dtype=_coord_dtype(a.values))
        coords_attr = ""
        if spec.samples is not None:
            s = spec.samples
            r = g.create_array(
                RUN_DIM,
                shape=(s.n,),
                chunks=(s.n,),
                dtype=np.int64,
                dimension_names=[RUN_DIM],
                attributes={"description": f"{s.method} sample number (seed {s.seed})"},
            )
            r[:] = np.arange(s.n)
            for j, key in enumerate(s.keys):
                arr = g.create_array(
                    key,
                    shape=(s.n,),
                    chunks=(s.n,),
                    dtype=np.float64,
                    dimension_names=[RUN_DIM],
                    attributes={
                        "units": SCHEMA[key].unit,
                        "key": key,
                        "low": s.low[j],
                        "high": s.high[j],
                        "spacing": s.spacing[j],
                        "method": s.method,
                        "seed": s.seed,
                        "description": SCHEMA[key].doc,
                    },
                )
                arr[:] = s.values[:, j]
            coords_attr = " ".join(s.keys)
        extra = {"coordinates": coords_attr} if coords_attr else {}
        for name in spec.metrics:
            m = _METRIC[name]
            attrs: dict[str, Any] = {"units": m.unit, "description": m.description, **extra}
            if name == "regime":
                attrs["flag_values"] = [REGIME_FAILED, *range(len(REGIMES))]
                attrs["flag_meanings"] = " ".join(("failed", *REGIMES))
            g.create_array(
                name,
                shape=spec.shape,
                chunks=spec.chunk_shape,
                dtype=m.dtype,
                fill_value=m.fill,
                dimension_names=list(dims),
                attributes=attrs,
            )
        g.create_array(
            "failure",
            shape=spec.shape,
            chunks=spec.chunk_shape,
            dtype=str,
            fill_value="",
            dimension_names=list(dims),
            attributes={"description": "why a run failed (empty: it finished)", **extra},
        )
        o = spec.options
        if o.series:
            nt = o.series_times.size
            t = g.create_array(
                TIME_DIM,
                shape=(nt,),
                chunks=(nt,),
                dtype=np.float64,
                dimension_names=[TIME_DIM],
                attributes={"units": "s", "description": "sample times of the series"},
            )
            t[:] = o.series_times
            for name in o.series:
                g.create_array(
                    name,
                    shape=(*spec.shape, nt),
                    chunks=(*spec.chunk_shape, nt),
                    dtype=np.float64,
                    fill_value=np.nan,
                    dimension_names=[*dims, TIME_DIM],
                    attributes={
                        "units": SERIES_UNITS[name],
                        "description": f"sampled {name}",
                        **extra,
                    },
                )
        sub = g.create_group(
            "_sweep", attributes={"description": "progress of the sweep (chunks done)"}
        )
        sub.create_array(
            "done",
            shape=(spec.n_chunks,),
            chunks=(1,),
            dtype=np.int8,
            fill_value=0,
            dimension_names=["chunk"],
        )
        os.rename(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return final


def store_attrs(path: str | Path) -> Mapping[str, Any]:
    """Root attributes of a sweep store.

    Raises
    ------
    InputError
        ``path`` is not a braidsim sweep store.
    """
    zarr = _zarr()
    p = Path(path)
    if not (p / "zarr.json").is_file():
        raise InputError(f"STORE: {p} is not a sweep store (no zarr.json)")
    attrs = dict(zarr.open_group(str(p), mode="r").attrs)
    if attrs.get("format") != STORE_FORMAT:
        raise InputError(
            f"STORE: {p} is not a braidsim sweep store (format {attrs.get('format')!r})"
        )
    return attrs


def remove_partial_files(path: str | Path) -> int:
    """Delete the temporary files a killed writer left (``*.partial``); return how many."""
    n = 0
    for p in Path(path).rglob("*.partial"):
        p.unlink(missing_ok=True)
        n += 1
    return n


def done_chunks(path: str | Path) -> np.ndarray:
    """Boolean array: which chunks are complete."""
    zarr = _zarr()
    g = zarr.open_group(str(path), mode="r")
    return np.asarray(g["_sweep/done"][:]) == 1


class StoreWriter:
    """Writes finished chunks into a store (one writer: the process that runs the sweep)."""

    def __init__(self, path: str | Path, spec: SweepSpec) -> None:
        self.spec = spec
        self.group: zarr.Group = _zarr().open_group(str(path), mode="r+")
        self.arrays = {
            name: self.group[name] for name in (*spec.metrics, "failure", *spec.options.series)
        }
        self.done = self.group["_sweep/done"]

    def write_chunk(
        self,
        chunk: int,
        values: Mapping[str, np.ndarray],
        failure: np.ndarray,
        series: Mapping[str, np.ndarray],
    ) -> None:
        """Write one chunk's arrays (block-shaped), then mark it done."""
        region = self.spec.chunk_region(chunk)
        for name in self.spec.metrics:
            self.arrays[name][region] = values[name]
        self.arrays["failure"][region] = failure.astype(str)
        for name, arr in series.items():
            self.arrays[name][(*region, slice(None))] = arr
        self.done[chunk] = 1


def open_sweep(path: str | Path) -> xr.Dataset:
    """The sweep store as an xarray Dataset (lazily loaded; chunks not yet done hold the
    fill values: NaN, -1 or "")."""
    import xarray as xr

    store_attrs(path)
    return xr.open_zarr(str(path), consolidated=False, chunks=None)


def export_netcdf(path: str | Path, out: str | Path) -> Path:
    """Write the store as one netCDF-3 file (SciPy engine), whole or not at all.

    netCDF-3 has no 64-bit integers, booleans or variable-length strings: int64 metrics are
    stored as int32 (they count steps, far below 2^31), booleans as int8 and strings as
    character arrays.
    """
    from braidsim.io import atomic_write_with

    ds = open_sweep(path).load()

    def nc_attrs(attrs: Mapping[str, Any]) -> dict[str, Any]:
        # netCDF-3 attributes: numbers, number arrays and (ASCII) text only
        out = {}
        for k, v in attrs.items():
            if isinstance(v, list | tuple) and not all(isinstance(e, int | float) for e in v):
                v = json.dumps(v)
            if isinstance(v, str):
                v = v.encode("ascii", "backslashreplace").decode("ascii")
            out[k] = v
        return out

    ds.attrs = nc_attrs(ds.attrs)
    for name in list(ds.variables):
        ds[name].attrs = nc_attrs(ds[name].attrs)
    for name in list(ds.variables):
        v = ds[name]
        if v.dtype.kind == "T" or v.dtype.kind == "U":
            ds[name] = v.astype(object)
        elif v.dtype == np.int64:
            if v.size and (
                int(v.max()) > np.iinfo(np.int32).max or int(v.min()) < np.iinfo(np.int32).min
            ):
                raise InputError(f"--netcdf: {name} does not fit netCDF-3 int32")
            ds[name] = v.astype(np.int32)
        elif v.dtype == bool:
            ds[name] = v.astype(np.int8)
    return atomic_write_with(out, lambda p: ds.to_netcdf(p, engine="scipy", format="NETCDF3_64BIT"))
