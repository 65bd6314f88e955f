"""Parameter studies at scale: sweep specs, chunked execution, a resumable zarr store, plots.

::

    from braidsim.sweep import load_spec, run_sweep, open_sweep, plot_sweep
    spec = load_spec("examples/sweep_ha_omega.toml")
    summary = run_sweep(spec, "ha_omega.zarr")          # local processes, all cores
    ds = open_sweep("ha_omega.zarr")                    # xarray Dataset, one dim per axis
    fig = plot_sweep(ds, "regime", x="omega", y="h_a")

Command line: ``braidsim sweep SPEC.toml --out STORE`` and ``braidsim sweep-plot STORE``.
The spec format is described in :mod:`braidsim.sweep.spec`, the store in
:mod:`braidsim.sweep.store`, the executors in :mod:`braidsim.sweep.execute` and the
per-run metrics in :mod:`braidsim.batch`.
"""

from braidsim.sweep.execute import (
    DaskExecutor,
    LocalProcesses,
    SweepError,
    compute_chunk,
    run_sweep,
    summarize_store,
)
from braidsim.sweep.plot import plot_sweep
from braidsim.sweep.spec import SweepSpec, load_spec, parse_spec
from braidsim.sweep.store import done_chunks, export_netcdf, open_sweep

__all__ = [
    "DaskExecutor",
    "LocalProcesses",
    "SweepError",
    "SweepSpec",
    "compute_chunk",
    "done_chunks",
    "export_netcdf",
    "load_spec",
    "open_sweep",
    "parse_spec",
    "plot_sweep",
    "run_sweep",
    "summarize_store",
]
