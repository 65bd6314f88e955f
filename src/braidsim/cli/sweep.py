"""Verbs ``sweep`` (run a parameter study into a zarr store) and ``sweep-plot`` (plot one)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from braidsim.cli.common import (
    app,
    fail,
    flush_notices,
    guarded,
    notice,
    print_json,
    result_console,
    spec_loaded,
)


@app.command()
@guarded
def sweep(
    spec: Annotated[Path, typer.Argument(help="Sweep spec TOML (docs/sweeps.md).", metavar="SPEC")],
    out: Annotated[Path, typer.Option("--out", help="The zarr store to write (a folder).")],
    processes: Annotated[
        int | None, typer.Option(help="Local worker processes (default or 0: all cores).")
    ] = None,
    workers: Annotated[
        int | None, typer.Option(help="Start a local Dask cluster of N workers and run on it.")
    ] = None,
    scheduler: Annotated[
        str | None, typer.Option(help="Run on the existing Dask cluster at this address.")
    ] = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="Finish an interrupted sweep of the same spec.")
    ] = False,
    netcdf: Annotated[
        Path | None, typer.Option(help="Also export the finished store as a netCDF file.")
    ] = None,
    no_progress: Annotated[
        bool, typer.Option("--no-progress", help="No progress bar on stderr.")
    ] = False,
    json_: Annotated[bool, typer.Option("--json", help="Print a JSON summary.")] = False,
) -> None:
    """Run a parameter study: every run of SPEC into the zarr store --out (resumable)."""
    from braidsim.cli.common import Interrupted, signal_decides
    from braidsim.cli.progress import enabled
    from braidsim.io import check_output_target
    from braidsim.sweep import SweepError, export_netcdf, load_spec, run_sweep

    s = spec_loaded(load_spec, spec)
    check_output_target(out, "--out", directory=True)
    if netcdf is not None:
        check_output_target(netcdf, "--netcdf", directory=False, suffixes=(".nc",))
    if resume:
        from braidsim.sweep.store import nothing_at

        if nothing_at(out):  # (a script that always passes --resume starts this way)
            notice(f"--resume: there is no store at {out} yet; a new sweep is started there")
    flush_notices()

    def resume_hint() -> str:
        # the store is created whole or not at all: without it there is nothing to resume
        # (an empty folder given as --out stays as it was)
        if not (out / "zarr.json").is_file():
            return f"no store was written at {out}"
        from braidsim.errors import StoreError
        from braidsim.sweep.store import done_chunks

        try:
            finished = bool(done_chunks(out).all())
        except StoreError:
            finished = False
        if finished:  # a signal after the last chunk: its results are all there
            rest = " and writes --netcdf" if netcdf is not None else ""
            return f"every run is written in {out}; --resume marks the store complete{rest}"
        return f"the chunks done are kept in {out}; finish with --resume"

    try:
        with signal_decides():
            summary = run_sweep(
                s,
                out,
                resume=resume,
                processes=processes,
                workers=workers,
                scheduler=scheduler,
                # drawn only where someone watches, as every verb's (progress.enabled)
                progress=not no_progress and enabled(quiet=json_),
            )
    except SweepError as exc:
        fail(f"sweep failed: {exc}; {resume_hint()}", 1)
        return
    except Interrupted as exc:
        fail(f"interrupted by {exc.args[0]}; {resume_hint()}", 128 + exc.signum)
        return
    except KeyboardInterrupt:
        fail(f"interrupted by SIGINT; {resume_hint()}", 130)
        return
    except OSError as exc:
        from braidsim.cli.common import _os_error_text

        fail(f"{_os_error_text(exc)}; {resume_hint()}", 1)
        return
    if netcdf is not None:
        summary["netcdf"] = str(export_netcdf(out, netcdf))
    if json_:
        print_json(summary)
        return
    con = result_console()
    con.print(
        f"[bold]{summary['store']}[/bold]: {summary['runs']} runs {summary['dims']}, "
        f"{summary['runs_computed']} computed now in {summary['elapsed_s']:.3g} s "
        f"({summary['executor']}), {summary['failed_runs']} failed"
    )
    if "regimes" in summary:
        con.print("regimes: " + ", ".join(f"{k} {v}" for k, v in summary["regimes"].items()))
    if summary["failed_runs"]:
        con.print(
            f"failed runs: {summary['failed_runs']}, most often: {summary['failure_example']} "
            "(every run's reason is in the store's `failure` variable)",
            markup=False,
        )


@app.command("sweep-plot")
@guarded
def sweep_plot(
    store: Annotated[
        Path, typer.Argument(help="A sweep store written by `braidsim sweep`.", metavar="STORE")
    ],
    metric: Annotated[
        str, typer.Option(help="Metric to plot (e.g. regime, track_max_contact_force).")
    ],
    x: Annotated[str, typer.Option("--x", help="Axis on the horizontal axis.")],
    out: Annotated[Path, typer.Option("--out", help="Image file to write (.png, .pdf, .svg).")],
    y: Annotated[
        str | None, typer.Option("--y", help="Second axis: a heat map (else a line over --x).")
    ] = None,
    sel: Annotated[
        list[str] | None,
        typer.Option(
            "--sel",
            help="AXIS=VALUE fixing another dimension (nearest grid value, within its range; "
            "a bare number is in the axis's SI unit).",
        ),
    ] = None,
    unit: Annotated[
        list[str] | None,
        typer.Option(
            "--unit", help="NAME=UNIT display unit of an axis, the metric or a --sel, e.g. h_a=mm."
        ),
    ] = None,
    log: Annotated[bool, typer.Option("--log", help="Logarithmic colour scale / y axis.")] = False,
    json_: Annotated[bool, typer.Option("--json", help="Print a JSON summary.")] = False,
) -> None:
    """Plot a finished sweep: a heat map over two axes (--x, --y) or a line over one (--x)."""
    from braidsim.errors import InputError
    from braidsim.plotting import save
    from braidsim.sweep import open_sweep, plot_sweep
    from braidsim.sweep.store import being_written, resume_command

    def pairs(items: list[str] | None, option: str) -> dict[str, str]:
        outd = {}
        for item in items or []:
            if "=" not in item:
                raise InputError(f"{option}: expected NAME=VALUE, got {item!r}")
            k, v = item.split("=", 1)
            outd[k.strip()] = v.strip()
        return outd

    from braidsim.cli.common import quantity_option
    from braidsim.io import check_output_target

    check_output_target(out, "--out", directory=False, suffixes=(".png", ".pdf", ".svg"))
    ds = open_sweep(store)
    # the cells of chunks not done hold the fill values, which read as failed runs
    missing = int(ds.attrs["runs_not_done"])
    if missing and being_written(store):  # (--resume would be refused while it runs)
        raise InputError(
            f"STORE: {store} is being written by a braidsim sweep now: {missing} of "
            f"{int(ds.attrs['n_runs'])} runs have not run yet; plot it once that sweep has "
            "finished"
        )
    if missing:
        raise InputError(
            f"STORE: {store} is not finished: {missing} of {int(ds.attrs['n_runs'])} runs have "
            f"not run yet; finish it with {resume_command(store)}, then plot it"
        )
    sels: dict[str, object] = dict(pairs(sel, "--sel"))
    for dim, value in sels.items():
        if dim in ds.dims and ds[dim].dtype.kind == "f":  # a grid axis in its SI unit
            sels[dim] = quantity_option(f"--sel {dim}", value, ds[dim].attrs.get("units", ""))
    fig = plot_sweep(ds, metric, x, y, sel=sels, units=pairs(unit, "--unit"), log=log)
    path = save(fig, out)
    if json_:
        print_json({"figure": str(path), "metric": metric, "x": x, "y": y})
        return
    over = f"{x} and {y}" if y else x
    result_console().print(f"{metric} over {over} written to {path}")
