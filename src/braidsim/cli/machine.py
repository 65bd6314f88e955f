"""Verb ``machine``: simulate a whole braiding machine and write its report."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from braidsim.cli.common import (
    app,
    guarded,
    print_json,
    quantity_option,
    result_console,
    spec_loaded,
)


@app.command()
@guarded
def machine(
    spec: Annotated[
        Path, typer.Argument(help="Machine spec TOML (docs/machine.md).", metavar="SPEC")
    ],
    out: Annotated[Path, typer.Option("--out", help="Report directory to write.")],
    duration: Annotated[
        str | None,
        typer.Option(help="Simulated time [s] (default: the spec's duration or revolutions)."),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(
            help="Local processes: 1 runs here, 0 all cores (default: a pool of all cores when "
            "the first carrier's cost says the rest would take over 5 s here)."
        ),
    ] = None,
    frames: Annotated[
        int | None, typer.Option(help="Animation frames (default: the spec's; 0: no animation).")
    ] = None,
    json_: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
) -> None:
    """Simulate every carrier of a braiding machine through its transfers; write tables,
    figures and an animation of the carriers coloured by contact force into --out."""
    from braidsim import limits
    from braidsim.errors import InputError
    from braidsim.io import check_output_directory
    from braidsim.machine import load_machine_spec, run_machine, write_report
    from braidsim.machine.report import REPORT_KIND

    if frames is not None and frames < 0:
        raise InputError(f"--frames: {frames} is out of range; allowed >= 0")
    if frames is not None:
        limits.check("frames", frames, "--frames")
    if workers is not None and workers < 0:
        raise InputError(f"--workers: {workers} is out of range; allowed >= 0 (0: all cores)")
    s = spec_loaded(load_machine_spec, spec)
    check_output_directory(out, REPORT_KIND)  # fail before the run, not after it
    dur = None if duration is None else quantity_option("--duration", duration, "s")
    from braidsim.cli.progress import progress_status

    with progress_status(f"simulating every carrier of {s.name}", quiet=json_):
        run = run_machine(s, duration=dur, workers=workers, frames=frames)
    gif = frames != 0 and s.animation.enabled and run.frame_times.size > 0
    what = "tables, figures and the animation (machine.gif)" if gif else "the report"
    with progress_status(f"writing {what} into {out}", quiet=json_):
        data = write_report(run, out, animation=frames != 0)
    if json_:
        print_json(data)
        return
    t = data["totals"]
    con = result_console()
    con.print(
        f"[bold]{data['name']}[/bold]: {t['carriers']} carriers, {t['transfers']} transfers in "
        f"{run.duration:.4g} s simulated ({run.elapsed:.3g} s on {run.workers} process(es))"
    )
    con.print(
        f"track: impacts/s {t['impacts_per_second']:.4g}, "
        f"impact energy/s {t['impact_energy_per_second']:.4g} W, "
        f"largest peak force {t['max_peak_force']:.4g} N (carrier {t['worst_carrier']['carrier']})"
    )
    if "slot" in t:
        sl = t["slot"]
        con.print(
            f"slot: impacts/s {sl['impacts_per_second']:.4g}, "
            f"impact energy/s {sl['impact_energy_per_second']:.4g} W, "
            f"largest peak force {sl['max_peak_force']:.4g} N"
        )
    con.print(f"report: {data['out']}/report.md")
