"""Verb ``fit``: scenario parameters from a measured record, with their uncertainty."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any

import typer

from braidsim.cli.common import app, guarded, print_json, spec_loaded


@app.command()
@guarded
def fit(
    spec: Annotated[Path, typer.Argument(help="Fit spec TOML (docs/fit.md).", metavar="SPEC")],
    data: Annotated[
        list[Path] | None,
        typer.Option(
            "--data",
            metavar="<path>",
            help="Measured record: CSV (t and x, acceleration, contact_force; units in "
            "brackets) or netCDF; or an impact list (CSV: t and peak_force, velocity, "
            "rebound_velocity). Repeat to fit several records together (they replace the "
            "spec's data list, overrides included). Default: the spec's data key.",
        ),
    ] = None,
    out: Annotated[Path | None, typer.Option("--out", help="Report directory to write.")] = None,
    json_: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
) -> None:
    """Fit the spec's free scenario parameters to one or more measured records or impact
    lists (least squares with a global start): estimates, standard errors, 95 % intervals,
    correlations, identifiability warnings, profiles, contact-law selection, and the fitted
    scenario as TOML in --out."""
    from braidsim.cli.progress import enabled
    from braidsim.errors import InputError
    from braidsim.fit import fit_record, load_fit_spec, read_record
    from braidsim.fit.report import REPORT_KIND, summary, write_report
    from braidsim.io import check_output_directory

    s = spec_loaded(load_fit_spec, spec)
    items = [(p, {}) for p in data] if data else list(s.datasets)
    if not items:
        raise InputError("--data: missing; allowed a CSV or netCDF record (or data = in the spec)")
    records = [(read_record(p), ov) for p, ov in items]
    if out is not None:
        check_output_directory(out, REPORT_KIND)  # fail before the fit, not after it

    if enabled(json_):
        from rich.console import Console

        from braidsim.cli.progress import COMPILE_NOTE, kernel_needs_compile

        first = f"{COMPILE_NOTE}; then fitting" if kernel_needs_compile() else "fitting"
        with Console(stderr=True).status(first) as status:
            res = fit_record(s, records, progress=lambda line: status.update(line))
    else:
        res = fit_record(s, records)
    result = write_report(res, s, out) if out is not None else summary(res)
    if json_:
        print_json(result)
        return
    import sys

    from braidsim.fit.data import IMPACT_UNITS, QUANTITY_UNITS

    lines = [
        f"fit of {', '.join(res.quantities)} ({res.n_data} data, law {res.law}): "
        f"{'converged' if res.converged else 'NOT converged'}, cost {res.cost:.6g}, "
        f"residual std {res.stats.residual_std:.3g} (in units of the noise)"
    ]
    given = s.noise or {}
    units = {**QUANTITY_UNITS, **IMPACT_UNITS, "t": "s"}

    lines.append(
        "  noise: "
        + ", ".join(
            f"{q} {sigma:.4g} {units.get(q, '')}".rstrip() + f" ({noise_origin(q, given)})"
            for q, sigma in res.noise.items()
        )
    )
    for i, p in enumerate(res.free):
        lo, hi = res.stats.ci95[i]
        unit = f" {p.unit}" if p.unit else ""
        lines.append(
            f"  {p.key} = {res.stats.values[i]:.6g}{unit} (se {res.stats.stderr[i]:.3g}; "
            f"95 % [{lo:.6g}, {hi:.6g}])"
        )
    for lr in res.laws:
        lines.append(
            f"  law {lr.law}: AIC {lr.aic:.2f}, BIC {lr.bic:.2f}, restitution "
            f"{lr.restitution:.4g} (effective {lr.effective_restitution:.4g})"
        )
    lines += [f"  warning: {w}" for w in res.warnings]
    lines += [f"  note: {w}" for w in res.notes]
    if out is not None:
        lines.append(f"report: {out}")
    sys.stdout.write("\n".join(lines) + "\n")


def noise_origin(quantity: str, given: Mapping[str, Any]) -> str:
    """Where a fitted quantity's noise level came from, as the report line says it: given in
    the spec, an impact list's default (0.1 ms for the onset times, 5 % of the median for
    its other columns: docs/fit.md), or estimated from a sampled record."""
    from braidsim.fit.data import IMPACT_UNITS

    if given.get(quantity):
        return "given"
    if quantity == "t":
        return "default, 0.1 ms"
    if quantity in IMPACT_UNITS:
        return "default, 5 % of the median"
    return "estimated from the record"
