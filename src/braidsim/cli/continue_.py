"""Verb ``continue``: periodic orbits continued in a parameter, their stability, bifurcations
and grazing, and the boundary curves of the safe operating map."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from braidsim.cli.common import app, guarded, print_json, spec_loaded


@app.command("continue")
@guarded
def continue_(
    spec: Annotated[
        Path, typer.Argument(help="Continuation spec TOML (docs/continuation.md).", metavar="SPEC")
    ],
    out: Annotated[Path, typer.Option("--out", help="Output directory to write.")],
    fmt: Annotated[
        str, typer.Option("--format", help="Branch files: nc (netCDF4) or zarr.")
    ] = "nc",
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress display.")] = False,
    json_: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
) -> None:
    """Continue periodic orbits of the carrier in one parameter (Newton shooting,
    pseudo-arclength, Floquet multipliers), locate folds, period doublings, Neimark-Sacker
    points and grazing, switch to period-doubled branches, and trace boundary curves in a
    second parameter; writes branch files, CSV tables, figures and summary.json into --out.
    Restart from a saved branch with continuation.restart in the spec."""
    from braidsim.cli.progress import _console, enabled
    from braidsim.continuation.study import REPORT_KIND, load_spec, run_study, write_outputs
    from braidsim.errors import InputError
    from braidsim.io import atomic_directory, check_output_directory

    if fmt not in ("nc", "zarr"):
        raise InputError(f"--format: {fmt!r} is not allowed; allowed nc or zarr")
    s = spec_loaded(load_spec, spec)
    check_output_directory(out, REPORT_KIND)  # fail before the work, not after it
    show = enabled(quiet) and not json_
    if show:
        con = _console()
        with con.status("continuing ...") as status:

            def say(line: str) -> None:
                status.update(line)

            res = run_study(s, progress=say)
    else:
        res = run_study(s)
    with atomic_directory(out, REPORT_KIND) as tmp:
        data = write_outputs(res, tmp, fmt)
    if json_:
        print_json(data)  # (summary.json's object: every key of the result, and the files)
        return
    for i, b in enumerate(res.branches):
        n_st = int(sum(o.stable and o.reliable for o in b.points))
        n_un = int(sum(not o.reliable for o in b.points))
        unsure = f" ({n_un} of unreliable finite-difference multipliers)" if n_un else ""
        sys.stdout.write(
            f"branch {i} (period {b.period}): {len(b.points)} points, {n_st} stable{unsure}; "
            f"{b.stop}\n"
        )
        for sp in b.special:
            sys.stdout.write(f"  {sp.type} at {b.key} = {sp.value:.6g}\n")
        for note in b.notes:
            sys.stdout.write(f"  note: {note}\n")
    for c in res.curves:
        what = c.name or c.type  # a grazing says which contact opens or appears
        end = f" (ends on a {c.end} of its orbit)" if c.end else ""
        sys.stdout.write(
            f"boundary {what} (period {c.period}): {len(c.p1)} points; {c.stop}{end}\n"
        )
    sys.stdout.write(f"written: {out}\n")
