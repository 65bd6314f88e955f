"""The sweep store: a zarr (format 3) group that xarray opens as the result Dataset.

Layout (``STORE/``)::

    zarr.json                 root attributes: spec text and hash, base parameters (SI), units,
                              ``complete`` (1 once every chunk is written, else 0)
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

Integrity: every chunk file ends with a CRC-32C checksum (zarr's ``crc32c`` codec after the
``zstd`` compressor), so a file changed after it was written (a flipped bit, a truncated
copy) is detected when it is read: :func:`open_sweep` checks every chunk marked done and
every coordinate array, ``--resume`` recomputes the chunks that fail and writes again the
coordinate arrays that fail or differ from the spec's values. One process writes a store at
a time: the writer holds an exclusive lock (``flock``) on ``_sweep/.lock`` for as long as it
runs, the operating system releases it when the process ends (also after SIGKILL), and a
second writer is refused with a message instead of deleting the first one's files in flight.

netCDF: every root and variable attribute is a number, a list of numbers or a string (a
list of names is one string of names separated by spaces, ``complete`` is 0 or 1), so the
Dataset that xarray opens is saved by its own ``to_netcdf`` with any engine, netCDF-3
(SciPy) included. Stores of formats 1 and 2 (``complete`` a boolean, ``dims`` and
``arrays`` lists) are read and resumed as they are; :func:`open_sweep` gives their Dataset
the format-3 attributes.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.batch import METRICS, REGIME_FAILED, REGIMES
from braidsim.errors import InputError, StoreError
from braidsim.io import process_gone
from braidsim.params import SCHEMA
from braidsim.result import UNITS as SERIES_UNITS
from braidsim.sweep.spec import RUN_DIM, TIME_DIM, SweepSpec

if TYPE_CHECKING:
    import xarray as xr
    import zarr

STORE_FORMAT = "braidsim-sweep/3"
#: formats this version reads (format 1 stores have no checksums; formats 1 and 2 store
#: ``complete`` as a boolean and ``dims`` and ``arrays`` as lists, which netCDF-3 cannot hold)
READ_FORMATS = ("braidsim-sweep/1", "braidsim-sweep/2", STORE_FORMAT)
LOCK = "_sweep/.lock"
_METRIC = {m.name: m for m in METRICS}


def _zarr() -> Any:
    import zarr

    return zarr


def _codecs() -> dict[str, Any]:
    """zstd compression, then a CRC-32C checksum of every chunk file. (:class:`StoreWriter`
    writes every chunk as a file, even one of fill values only, so a missing file of a
    finished chunk is damage.)"""
    from zarr.codecs import Crc32cCodec, ZstdCodec

    return {"compressors": [ZstdCodec(level=0), Crc32cCodec()]}


def resume_command(path: str | Path) -> str:
    """The command that finishes or repairs the store at ``path``, for messages. The store
    keeps its spec's text (attribute ``spec``), not the file's path: the command names the
    file as the spec it was made from."""
    return (
        f"`braidsim sweep SPEC --out {path} --resume`, SPEC being the spec file the store was "
        "made from (the store keeps its text in its attribute 'spec')"
    )


def _damaged(path: str | Path, what: str, repairable: bool = True) -> StoreError:
    """The error of a damaged store: ``repairable`` where ``--resume`` computes the damaged
    part again (a chunk), not where the store's structure itself is lost (its root or an
    array's metadata: ``--resume`` reads those first and would fail the same way)."""
    if not repairable:
        return StoreError(
            f"STORE: {path} is damaged ({what}); --resume cannot repair the store's structure: "
            "run the sweep again into a new store"
        )
    return StoreError(
        f"STORE: {path} is damaged ({what}); recompute its damaged chunks with "
        f"{resume_command(path)}, or run the sweep again into a new store"
    )


def remove_stale_temporaries(final: Path) -> int:
    """Remove the hidden folders ``.NAME.creating-PID-*`` that a killed process left beside
    the store ``NAME`` (only those whose process is gone); return how many."""
    n = 0
    pat = re.compile(re.escape(f".{final.name}.creating-") + r"(\d+)-[0-9a-f]+")
    if not final.parent.is_dir():
        return 0
    for p in final.parent.iterdir():
        m = pat.fullmatch(p.name)
        if m and process_gone(int(m.group(1))):
            shutil.rmtree(p, ignore_errors=True)
            n += 1
    return n


def nothing_at(path: str | Path) -> bool:
    """Whether ``path`` is absent or an empty folder: a new store may be made there (an
    empty folder holds nothing to lose; the store's rename replaces it)."""
    p = Path(path)
    if not p.exists():
        return True
    try:
        return p.is_dir() and not any(p.iterdir())
    except OSError:
        return False


def being_written(path: str | Path) -> bool:
    """Whether a braidsim sweep holds the store's writer lock (:class:`StoreLock`) now."""
    import fcntl

    try:
        fd = os.open(Path(path) / LOCK, os.O_RDONLY)
    except OSError:  # no lock file: no writer
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)  # (releases the shared lock taken, if any)
    return False


class StoreLock:
    """An exclusive lock on a store for the life of one writer (``flock`` on ``_sweep/.lock``).

    Raises
    ------
    InputError
        Another process holds the lock (it is writing the store now).
    """

    def __init__(self, path: str | Path) -> None:
        import fcntl

        self.path = Path(path)
        lock = self.path / LOCK
        try:
            self.fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644 & ~0o022)
        except OSError as exc:
            raise StoreError(f"{lock}: cannot open the lock file ({exc.strerror})") from None
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(self.fd)
            raise InputError(
                f"--out: {self.path} is being written by another braidsim sweep now; wait for "
                "it to finish (or stop it), then --resume"
            ) from None

    def release(self) -> None:
        """Release the lock."""
        if self.fd >= 0:
            os.close(self.fd)  # closing the descriptor releases the flock
            self.fd = -1


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
        # names separated by spaces (like CF's "coordinates"): a netCDF-3 attribute cannot be
        # a list of strings, and the names are identifiers
        "dims": " ".join(spec.dims),
        "arrays": " ".join([*spec.metrics, "failure", *o.series]),
        "chunk_shape": list(spec.chunk_shape),
        "n_runs": spec.n_runs,
        "n_chunks": spec.n_chunks,
        # 1 once every chunk is written, else 0 (for readers that do not look at _sweep/done);
        # an int, not a boolean: netCDF has no boolean attributes
        "complete": 0,
        "sign_convention": "parameters and metrics in SI; depths and forces are magnitudes",
    }


def _coordinate_arrays(spec: SweepSpec) -> list[tuple[str, np.ndarray, str, dict[str, Any]]]:
    """The store's coordinate arrays as ``spec`` gives them: (name, values, dimension,
    attributes) for each grid axis, or the run index and each sampled key, and the series'
    sample times. :func:`create_store` writes them, :func:`repair_coordinates` compares the
    stored ones with them."""
    out: list[tuple[str, np.ndarray, str, dict[str, Any]]] = []
    for a in spec.axes:
        attrs: dict[str, Any] = {
            "units": a.unit,
            "key": a.key,
            "spacing": a.spacing,
            "description": SCHEMA[a.key].doc,
        }
        out.append((a.name, np.array(a.values, dtype=_coord_dtype(a.values)), a.name, attrs))
    if spec.samples is not None:
        s = spec.samples
        run_attrs = {"description": f"{s.method} sample number (seed {s.seed})"}
        out.append((RUN_DIM, np.arange(s.n, dtype=np.int64), RUN_DIM, run_attrs))
        for j, key in enumerate(s.keys):
            attrs = {
                "units": SCHEMA[key].unit,
                "key": key,
                "low": s.low[j],
                "high": s.high[j],
                "spacing": s.spacing[j],
                "method": s.method,
                "seed": s.seed,
                "description": SCHEMA[key].doc,
            }
            out.append((key, np.asarray(s.values[:, j], dtype=np.float64), RUN_DIM, attrs))
    if spec.options.series:
        t_attrs = {"units": "s", "description": "sample times of the series"}
        times = np.asarray(spec.options.series_times, dtype=np.float64)
        out.append((TIME_DIM, times, TIME_DIM, t_attrs))
    return out


def create_store(spec: SweepSpec, path: str | Path) -> Path:
    """Create an empty store for ``spec`` at ``path`` (whole, or not at all).

    Raises
    ------
    InputError
        ``path`` exists already and is not an empty folder.
    """
    zarr = _zarr()
    final = Path(path)
    if not nothing_at(final):
        raise InputError(
            f"--out: {final} exists; pass --resume to finish it, or choose another path"
        )
    final.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(final)
    tmp = final.parent / f".{final.name}.creating-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    try:
        g = zarr.open_group(str(tmp), mode="w", zarr_format=3, attributes=_root_attrs(spec))
        dims = spec.dims
        for name, values, dim, coord_attrs in _coordinate_arrays(spec):
            arr = g.create_array(
                name,
                shape=values.shape,
                chunks=values.shape,
                dtype=str if values.dtype.kind == "U" else values.dtype,
                dimension_names=[dim],
                attributes=coord_attrs,
                **_codecs(),
            )
            arr[:] = values
        coords_attr = " ".join(spec.samples.keys) if spec.samples is not None else ""
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
                **_codecs(),
            )
        g.create_array(
            "failure",
            shape=spec.shape,
            chunks=spec.chunk_shape,
            dtype=str,
            fill_value="",
            dimension_names=list(dims),
            attributes={"description": "why a run failed (empty: it finished)", **extra},
            **_codecs(),
        )
        o = spec.options
        if o.series:
            nt = o.series_times.size
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
                    **_codecs(),
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
            **_codecs(),
        )
        (tmp / LOCK).touch()
        try:
            os.rename(tmp, final)
        except OSError:
            if final.exists():  # another sweep created it between our check and now
                raise InputError(
                    f"--out: {final} was just created by another process; choose another "
                    "path, or --resume once that sweep is done"
                ) from None
            raise
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
    try:
        attrs = dict(zarr.open_group(str(p), mode="r").attrs)
    except Exception as exc:  # zarr raises several types for damaged metadata
        raise StoreError(
            f"STORE: {p}/zarr.json cannot be read ({exc.__class__.__name__}); the store is "
            "damaged: run the sweep again into a new store"
        ) from None
    if attrs.get("format") not in READ_FORMATS:
        raise InputError(
            f"STORE: {p} is not a braidsim sweep store (format {attrs.get('format')!r})"
        )
    return attrs


def names_attr(value: Any) -> list[str]:
    """The names of a root attribute ``dims`` or ``arrays``: a string of names separated by
    spaces (format 3), or a list of them (formats 1 and 2)."""
    if value is None:
        return []
    if isinstance(value, str):
        return value.split()
    return [str(v) for v in value]


def set_complete(path: str | Path, complete: bool) -> None:
    """Set the root attribute ``complete``: 0 while chunks are still to be written, 1 once
    all are (zarr rewrites ``zarr.json`` through a temporary file and a rename). A store of
    format 1 or 2 (a boolean there) gets the integer too."""
    g = _zarr().open_group(str(path), mode="r+")
    old = g.attrs.get("complete")
    if isinstance(old, bool) or old != int(complete):
        g.attrs["complete"] = int(complete)


def remove_partial_files(path: str | Path) -> int:
    """Delete the temporary files a killed writer left (``*.partial``); return how many."""
    n = 0
    for p in Path(path).rglob("*.partial"):
        p.unlink(missing_ok=True)
        n += 1
    return n


def check_store(path: str | Path) -> Any:
    """Open a sweep store and check its structure: the progress array and every data array
    the store was created with are present and readable. Returns the zarr group.

    Raises
    ------
    StoreError
        A part of the store is missing or its metadata cannot be read.
    """
    attrs = store_attrs(path)
    zarr = _zarr()
    try:
        g = zarr.open_group(str(path), mode="r")
    except Exception as exc:  # zarr raises several types for damaged metadata
        where = Path(path) / "zarr.json"
        raise _damaged(
            path, f"root: {where} missing or unreadable, {exc.__class__.__name__}", False
        ) from None
    for name in ["_sweep/done", *names_attr(attrs.get("arrays"))]:
        try:
            g[name]
        except Exception as exc:  # a missing array (KeyError) or damaged metadata
            where = Path(path) / name / "zarr.json"
            raise _damaged(
                path,
                f"array {name!r}: {where} missing or unreadable, {exc.__class__.__name__}",
                False,
            ) from None
    return g


def done_chunks(path: str | Path, strict: bool = False) -> np.ndarray:
    """Boolean array: which chunks are complete.

    A flag whose file fails its checksum counts as not done (the chunk is computed again on
    resume); with ``strict`` it is a :class:`StoreError` instead (reading a store).
    """
    g = check_store(path)
    arr = g["_sweep/done"]
    try:
        return np.asarray(arr[:]) == 1
    except ValueError:
        if strict:
            raise _damaged(path, "a chunk's done flag fails its checksum") from None
        out = np.zeros(arr.shape[0], dtype=bool)
        for c in range(arr.shape[0]):
            try:
                out[c] = int(arr[c]) == 1
            except ValueError:
                out[c] = False
        return out


def runs_not_done(path: str | Path) -> int:
    """How many runs of a store lie in chunks not done yet (0 once the sweep is finished)."""
    g = check_store(path)
    done = done_chunks(path, strict=True)
    chunk_shape, shape, grid = _chunk_grid(g)
    n = 0
    for c in np.flatnonzero(~done):
        n += int(
            np.prod([r.stop - r.start for r in _chunk_region(int(c), chunk_shape, shape, grid)])
        )
    return n


def _chunk_grid(g: Any) -> tuple[tuple[int, ...], tuple[int, ...], tuple[int, ...]]:
    """(chunk shape, shape, chunks along each dimension) of the work of store group ``g``,
    read from its data arrays (their first dimensions; a series adds its time)."""
    chunk_shape = tuple(int(c) for c in g.attrs["chunk_shape"])
    names = _data_arrays(g)
    shape = tuple(g[names[0]].shape[: len(chunk_shape)]) if names else ()
    grid = tuple(-(-s // c) for s, c in zip(shape, chunk_shape, strict=True))
    return chunk_shape, shape, grid


def _chunk_region(
    c: int, chunk_shape: tuple[int, ...], shape: tuple[int, ...], grid: tuple[int, ...]
) -> tuple[slice, ...]:
    """Index region (a slice per dimension) of chunk number ``c`` (C order)."""
    idx = np.unravel_index(c, grid)
    return tuple(
        slice(int(i) * k, min((int(i) + 1) * k, n))
        for i, k, n in zip(idx, chunk_shape, shape, strict=True)
    )


def _chunk_key(c: int, grid: tuple[int, ...]) -> str:
    """The chunk's file key ("i/j/...") below an array's ``c`` folder."""
    return "/".join(str(int(i)) for i in np.unravel_index(c, grid))


def _data_arrays(group: Any) -> list[str]:
    """The arrays chunked like the work (metrics, failure, series), as the store lists them."""
    return names_attr(group.attrs.get("arrays"))


def corrupt_chunks(path: str | Path, strict: bool = False) -> dict[int, str]:
    """Chunks marked done whose files are missing or fail their checksum:
    ``{chunk: array name}``.

    Reads every done chunk of every data array (metrics, failure, series). Stores of format
    1 have no checksums and report nothing.
    """
    p = Path(path)
    g = check_store(p)
    if g.attrs.get("format") == "braidsim-sweep/1":
        return {}
    done = done_chunks(p, strict=strict)
    names = _data_arrays(g)
    bad: dict[int, str] = {}
    if not names:
        return bad
    chunk_shape, shape, grid = _chunk_grid(g)
    for c in map(int, np.flatnonzero(done)):
        region = _chunk_region(c, chunk_shape, shape, grid)
        key = _chunk_key(c, grid)
        for name in names:
            f = p / name / "c" / key
            if g[name].ndim > len(chunk_shape):
                f = f / "0"  # the series' time dimension is one chunk
            if _damaged_chunk(g[name], f, region):
                bad[c] = name
                break
    return bad


def _damaged_chunk(arr: Any, f: Path, region: Any) -> bool:
    """Whether the chunk of ``arr`` in file ``f`` (holding ``region``) is missing or fails
    its checksum. (zarr reads a missing chunk file as fill values, without error.)"""
    if not f.is_file():
        return True
    try:
        arr[region]
    except ValueError:
        return True
    return False


def damaged_coordinates(path: str | Path) -> list[str]:
    """The coordinate arrays of a store (grid axes, run index and sampled keys, sample
    times) whose file is missing or fails its checksum. (Stores made before these arrays
    had checksums read as they are.)"""
    g = check_store(path)
    data = {*_data_arrays(g)}
    bad = []
    for name in sorted(str(k) for k in g.array_keys()):
        # (one chunk each)
        if name not in data and g[name].size:
            if _damaged_chunk(g[name], Path(path) / name / "c" / "0", ...):
                bad.append(name)
    return bad


def repair_coordinates(path: str | Path, spec: SweepSpec) -> list[str]:
    """Write again every coordinate array of the store that cannot be read or whose values
    are not the ones ``spec`` gives (to the bit); returns their names. They follow from the
    spec alone, as the store's spec hash (checked before) says."""
    zarr = _zarr()
    g = zarr.open_group(str(path), mode="r+")
    fixed = []
    for name, values, _, _ in _coordinate_arrays(spec):
        arr = g[name]
        try:
            same = np.array_equal(np.asarray(arr[...]), values)
        except ValueError:  # (its checksum)
            same = False
        if not same:
            arr[...] = values
            fixed.append(name)
    return fixed


def mark_undone(path: str | Path, chunks: list[int]) -> None:
    """Clear the done flag of ``chunks`` and remove their (damaged) files: they are computed
    and written again."""
    p = Path(path)
    g = _zarr().open_group(str(p), mode="r+")
    names = _data_arrays(g)
    chunk_shape, _, grid = _chunk_grid(g)
    for c in chunks:
        g["_sweep/done"][c] = 0
        key = _chunk_key(c, grid)
        for name in names:
            f = p / name / "c" / key
            if f.is_dir() and g[name].ndim > len(chunk_shape):
                f = f / "0"
            if f.is_dir() and not f.is_symlink():
                shutil.rmtree(f)
            elif f.exists() or f.is_symlink():
                f.unlink()


class StoreWriter:
    """Writes finished chunks into a store (one writer: the process that runs the sweep)."""

    def __init__(self, path: str | Path, spec: SweepSpec) -> None:
        self.spec = spec
        zr = _zarr()
        # every chunk is written as a file, even one of fill values only (see _codecs)
        with zr.config.set({"array.write_empty_chunks": True}):
            self.group: zarr.Group = zr.open_group(str(path), mode="r+")
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
    """The sweep store as an xarray Dataset, lazily loaded.

    A store whose sweep has not finished can be read while it runs or after an interruption:
    the chunks not done yet hold the fill values (NaN, -1 or ""), and ``attrs["runs_not_done"]``
    counts their runs (0 once the sweep is finished), so that such cells are not taken for
    results. A damaged chunk (missing, or failing its checksum) is refused.

    Its attributes are numbers, lists of numbers and strings (``complete``: 1 or 0, also for
    a store of an earlier format), so xarray's ``to_netcdf`` saves it with any engine."""
    import xarray as xr

    if not isinstance(path, str | os.PathLike):
        raise InputError(f"path: {path!r} is not a path; allowed the path of a sweep store")
    coords = damaged_coordinates(path)
    if coords:
        raise StoreError(
            f"STORE: {path}: the coordinate array {coords[0]!r} is missing or fails its "
            f"checksum; write it again with {resume_command(path)}"
        )
    bad = corrupt_chunks(path, strict=True)
    if bad:
        c, name = next(iter(bad.items()))
        raise StoreError(
            f"STORE: {path}: chunk {c} of {name!r} is missing or fails its checksum "
            f"({len(bad)} chunk(s) damaged after they were written); recompute them with "
            f"{resume_command(path)}"
        )
    ds = xr.open_zarr(str(path), consolidated=False, chunks=None)
    # a store of format 1 or 2: the attributes as format 3 has them, which netCDF can hold
    ds.attrs["complete"] = int(bool(ds.attrs.get("complete", 0)))
    for key in ("dims", "arrays"):
        if key in ds.attrs:
            ds.attrs[key] = " ".join(names_attr(ds.attrs[key]))
    ds.attrs["runs_not_done"] = runs_not_done(path)
    return ds


def export_netcdf(path: str | Path, out: str | Path, *, partial: bool = False) -> Path:
    """Write the store as one netCDF-3 file (SciPy engine), whole or not at all.

    A store whose sweep has not finished is refused (its cells not run yet hold fill values
    that would read as failed runs), unless ``partial=True``: the file then carries the
    count of those runs in its ``runs_not_done`` attribute, as :func:`open_sweep` gives it.

    netCDF-3 has no 64-bit integers, booleans or variable-length strings: int64 metrics are
    stored as int32 (they count steps, far below 2^31), booleans as int8 and strings as
    character arrays.
    """
    from braidsim.io import atomic_write_with

    ds = open_sweep(path)
    missing = int(ds.attrs["runs_not_done"])
    if missing and not partial:
        raise StoreError(
            f"STORE: {path} is not finished: {missing} of {int(ds.attrs['n_runs'])} runs have "
            f"not run yet; finish it with {resume_command(path)}, then export it (or pass "
            "partial=True to export the runs done so far)"
        )
    ds = ds.load()

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
