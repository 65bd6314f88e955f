"""Verb ``design``: optimise the horn-gear speed profile, rank the other levers, find the speed
limits, and write the report."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from braidsim.cli.common import app, guarded, print_json, result_console, spec_loaded


@app.command()
@guarded
def design(
    spec: Annotated[
        Path, typer.Argument(help="Design spec TOML (docs/design.md).", metavar="SPEC")
    ],
    out: Annotated[Path, typer.Option("--out", help="Report directory to write.")],
    workers: Annotated[
        int | None,
        typer.Option(
            help="Local processes: 1 runs here, 0 all cores (default: the spec's "
            "design.workers; results do not change)."
        ),
    ] = None,
    json_: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
) -> None:
    """Design study of a braiding machine on the two-DOF carrier model (track and slot
    contacts): the horn-gear speed profile that minimises the objective over tolerance samples
    within the drive's limits (same mean speed), its improvement distribution, the other
    levers compared on the same samples; writes a report into --out."""
    import dataclasses
    import sys

    from braidsim.batch import local_processes
    from braidsim.cli.progress import enabled as progress_enabled
    from braidsim.design import load_design_spec, run_design, write_report
    from braidsim.design.report import REPORT_KIND, percent_se
    from braidsim.errors import InputError
    from braidsim.io import check_output_directory

    s = spec_loaded(load_design_spec, spec)
    if workers is not None:
        if workers < 0:
            raise InputError(f"--workers: {workers} is out of range; allowed >= 0 (0: all cores)")
        # as for bifurcation, basins and machine (at most the optimiser's 256)
        workers = min(local_processes(workers), 256)
        s = dataclasses.replace(
            s, workers=workers, optimizer=dataclasses.replace(s.optimizer, workers=workers)
        )
    check_output_directory(out, REPORT_KIND)  # fail before the study, not after it

    # progress only where someone watches, as for every command (docs/cli.md): a terminal
    # on stderr and no --json
    show = progress_enabled(quiet=json_)

    def say(line: str) -> None:
        if show:
            sys.stderr.write(line + "\n")
            sys.stderr.flush()

    res = run_design(s, progress=say)
    data = write_report(res, out)
    if json_:
        keep = (
            "braidsim_version",
            "name",
            "objective",
            "pair",
            "baseline",
            "optimised",
            "robust",
            "levers",
            "drive_model",
            "reduction",
            "production",
            "profile",
            "optimisation",
            "proxy",
            "sensitivity",
            "speed_limits",
            "out",
            "files",
        )
        print_json({k: data[k] for k in keep if k in data})
        return
    con = result_console()
    b, a = data["baseline"], data["optimised"]
    from rich.markup import escape

    con.print(
        f"[bold]{escape(data['name'])}[/bold] (objective {data['objective']}, pairs {data['pair']})"
    )
    for pair in ("track", "slot"):
        for k, unit in (
            ("peak_force", "N"),
            ("impact_energy_rate", "W"),
            ("impact_rate", "1/s"),
        ):
            x, y = b[pair][k], a[pair][k]
            ch = f" ({100 * (y / x - 1):+.1f} %)" if x else ""
            con.print(f"  {pair} {k}: {x:.5g} -> {y:.5g} {unit}{ch}", markup=False)
    for k, unit in (("peak_torque", "N m"), ("rms_torque", "N m"), ("peak_power", "W")):
        con.print(f"  drive {k}: {b['drive'][k]:.4g} -> {a['drive'][k]:.4g} {unit}", markup=False)
    rb = data["robust"]
    if rb.get("median_improvement") is not None:
        con.print(
            f"  improvement over {rb['samples']} tolerance samples: median "
            f"{percent_se(rb, 'median_improvement')}, 5th percentile "
            f"{percent_se(rb, 'p5_improvement')} (+- bootstrap standard error)",
            markup=False,
        )
    opt = data["optimisation"]
    if opt["still_improving"]:
        con.print(
            f"  the optimiser stopped at its iteration cap still improving "
            f"({-100 * opt['recent_gain']:+.2g} % over its last {opt['recent_generations']} "
            "generations): raise design.optimizer.maxiter for a better profile",
            markup=False,
        )
    if data.get("levers"):
        con.print(
            "  levers by improvement per effort: " + ", ".join(lv["name"] for lv in data["levers"]),
            markup=False,
        )
    if "sensitivity" in data:
        con.print("  levers by Morris mu*: " + ", ".join(data["sensitivity"]["morris"]["ranking"]))
    con.print(f"report: {data['out']}/report.md")
