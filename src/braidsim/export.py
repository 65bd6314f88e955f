"""Writing a run's series to disk: compressed netCDF4 by default, CSV on request.

The series of a 5-s run sampled every 10 us holds ~5e5 rows of 27 columns: ~110 MB as
uncompressed netCDF3 and as much again as CSV. netCDF4 (HDF5) with zlib compression and the
byte-shuffle filter stores the same numbers bit for bit in a fraction of that (the columns
are smooth, so neighbouring values share their high bytes). The file is written through
``h5netcdf`` (a netCDF4 writer on ``h5py``, no C netCDF library needed) and opens with
``xarray.open_dataset(path)``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from braidsim.io import atomic_write_with

if TYPE_CHECKING:
    from braidsim.result import Result

#: zlib level of the series file: 4 gives nearly all of level 9's saving at a third of its time
COMPLEVEL = 4


@contextlib.contextmanager
def local_writes() -> Iterator[None]:
    """Write netCDF files with this process's own locks. xarray takes a dask.distributed lock
    whenever a distributed client is registered as the default, even for data in memory; a
    client left over from a failed connection (``sweep --scheduler``) then makes every write
    of the process fail. The synchronous scheduler keeps writes local."""
    try:
        import dask
    except ImportError:  # pragma: no cover - dask comes with xarray's extras here
        yield
        return
    with dask.config.set(scheduler="synchronous"):
        yield


def write_netcdf4(ds: Any, path: str | Path, encoding: Mapping[Any, Any] | None = None) -> Path:
    """Write the xarray Dataset ``ds`` to ``path`` as netCDF4 (h5netcdf); the file is whole
    or absent.

    The file is made in memory and then written as bytes: HDF5 writing to a file meets a
    failed write (a full disk, a file-size limit) inside its own driver, where h5py prints
    "Exception ignored" tracebacks by the hundred and the process can end in a segmentation
    fault; a write of bytes fails as an ``OSError`` naming the path."""
    import io

    buf = io.BytesIO()
    with local_writes():
        ds.to_netcdf(buf, engine="h5netcdf", encoding=encoding)
    data = buf.getbuffer()
    try:
        return atomic_write_with(path, lambda tmp: tmp.write_bytes(data))
    finally:
        data.release()


def write_series_netcdf(result: Result, path: str | Path) -> Path:
    """Write :meth:`Result.to_xarray` as compressed netCDF4 (zlib + shuffle); the file is
    whole or absent."""
    ds = result.to_xarray()
    encoding = {
        name: {"zlib": True, "complevel": COMPLEVEL, "shuffle": True} for name in ds.data_vars
    }
    return write_netcdf4(ds, path, encoding)
