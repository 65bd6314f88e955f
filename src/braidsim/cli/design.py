"""Verb ``design``: optimise the horn-gear speed profile, rank the other levers, find the speed
limits, and write the report."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from braidsim.cli.common import app, guarded, print_json


@app.command()
@guarded
def design(
    spec: Annotated[Path, typer.Argument(help="Design spec TOML (see braidsim.design.spec).")],
    out: Annotated[Path, typer.Option("--out", help="Report directory to write.")],
    workers: Annotated[
        int | None,
        typer.Option(help="Processes (default: the spec's design.workers; results do not change)."),
    ] = None,
    json_: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
) -> None:
    """Design study of a braiding machine: the horn-gear speed profile that minimises the
    objective within the drive's limits (same mean speed), the sensitivity of the other
    levers and the speed limits; writes a report into --out."""
    import dataclasses
    import sys

    from braidsim.design import load_design_spec, run_design, write_report
    from braidsim.design.report import REPORT_KIND
    from braidsim.errors import InputError
    from braidsim.io import check_output_directory

    s = load_design_spec(spec)
    if workers is not None:
        if workers < 1:
            raise InputError(f"--workers: {workers} is out of range; allowed >= 1")
        s = dataclasses.replace(
            s, workers=workers, optimizer=dataclasses.replace(s.optimizer, workers=workers)
        )
    check_output_directory(out, REPORT_KIND)  # fail before the study, not after it

    def say(line: str) -> None:
        if not json_:
            sys.stderr.write(line + "\n")
            sys.stderr.flush()

    res = run_design(s, progress=say)
    data = write_report(res, out)
    if json_:
        keep = (
            "name",
            "objective",
            "baseline",
            "optimised",
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
    from rich.console import Console

    con = Console()
    b, a, r = data["baseline"], data["optimised"], data["reduction"]
    con.print(f"[bold]{data['name']}[/bold] (objective {data['objective']})")
    for k, unit in (("peak_force", "N"), ("impact_energy", "W"), ("impacts", "1/s")):
        con.print(f"  {k}: {b[k]:.5g} -> {a[k]:.5g} {unit} ({-100 * r[k]:+.1f} %)")
    if "sensitivity" in data:
        con.print("  levers by Morris mu*: " + ", ".join(data["sensitivity"]["morris"]["ranking"]))
    con.print(f"report: {data['out']}/report.md")
