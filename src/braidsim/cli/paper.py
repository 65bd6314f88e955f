"""Verb ``paper``: reproduce every result of sections 3.1-3.5 of the paper."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from braidsim.cli.common import app, guarded, print_json, result_console


@app.command()
@guarded
def paper(
    out: Annotated[
        Path, typer.Option(help="Directory for the report, tables and figures (replaced whole).")
    ] = Path("paper-results"),
    json_: Annotated[
        bool, typer.Option("--json", help="Print the items (paper, ours, deviation, status).")
    ] = False,
) -> None:
    """Reproduce sections 3.1-3.5: Figures 3-22, Table 1 and a report of every number.

    Files: report.md, report.html, items.json, items.csv, table1.csv, table1.md, excerpt.md
    (a few rows of the report, for a README), figures/.

    OUT is built aside and renamed into place at the end: complete or absent.
    """
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from braidsim.io import check_output_directory
    from braidsim.paper.report import OUTPUT_KIND, reproduce, total_steps
    from braidsim.paper.values import load_paper_values

    check_output_directory(out, OUTPUT_KIND)  # refuse before the work, not after
    err = Console(stderr=True)
    columns = (
        TextColumn("[bold]braidsim paper[/bold]"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TimeElapsedColumn(),
        TextColumn("{task.description}"),
    )
    from braidsim.cli.progress import enabled

    # progress only for a person watching: not under --json, not into a pipe or a log
    with Progress(*columns, console=err, transient=False, disable=not enabled(json_)) as progress:
        task = progress.add_task("compiling the integrator", total=total_steps(load_paper_values()))

        def on_step(description: str, n: int) -> None:
            progress.update(task, advance=n, description=description)

        report = reproduce(out, on_step)
        progress.update(task, description="done")
    if json_:
        print_json(report.to_json())
        return
    from rich.table import Table

    con = result_console()
    counts = report.counts()
    tab = Table("status", "items")
    for k, v in counts.items():
        tab.add_row(k, str(v))
    con.print(tab)
    for a in report.acceptance():
        mark = "[green]yes[/green]" if a["ok"] else "[red]no[/red]"
        con.print(f"{mark}  {a['check']} ({a['items']} items)")
    con.print(f"report: {out / 'report.html'} and {out / 'report.md'}")
