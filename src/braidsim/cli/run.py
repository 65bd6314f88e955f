"""Verbs ``run``, ``impact``, ``models`` and ``scenarios``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import typer

from braidsim.cli.common import (
    app,
    guarded,
    parse_sets,
    print_json,
    quantity_option,
    result_console,
)
from braidsim.errors import InputError


@app.command()
@guarded
def run(
    scenario: Annotated[
        str, typer.Argument(help="Built-in scenario name or TOML file.", metavar="SCENARIO")
    ],
    set_: Annotated[
        list[str] | None, typer.Option("--set", help="KEY=VALUE override (repeatable).")
    ] = None,
    duration: Annotated[
        str | None, typer.Option(help="Simulated time [s], e.g. '0.5 s' or '500 ms'.")
    ] = None,
    window: Annotated[
        tuple[str, str] | None, typer.Option(help="T0 T1: ranges over this window [s].")
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            help="Write plots, series.nc (compressed netCDF4), impacts.csv and summary.json "
            "into this new directory (or an earlier run output, replaced)."
        ),
    ] = None,
    csv: Annotated[
        bool, typer.Option("--csv", help="With --out, also write the series as series.csv.")
    ] = False,
    sensitivity: Annotated[
        list[str] | None,
        typer.Option(
            "--sensitivity",
            help="KEY: also give the exact derivatives of every impact and of the final state "
            "with respect to this numeric scenario key (repeatable), SI per SI unit.",
        ),
    ] = None,
    json_: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Simulate one carrier and report depth and force ranges and the impacts."""
    import braidsim
    from braidsim.cli.progress import progress_simulated, progress_status

    if out is not None:
        from braidsim.io import check_output_directory

        check_output_directory(out, "run")  # refuse before the run, not after
    elif csv:
        raise InputError("--csv: writes series.csv into the --out folder; give --out DIR")
    sc = braidsim.load_scenario(scenario, overrides=parse_sets(set_))
    dur = None if duration is None else quantity_option("--duration", duration, "s")
    win = (
        None
        if window is None
        else (
            quantity_option("--window", window[0], "s"),
            quantity_option("--window", window[1], "s"),
        )
    )
    T = float(sc["simulation.duration"] if dur is None else dur)
    if win is not None and math.isfinite(T) and T > 0:
        # checked here to name the option as typed (simulate names its ``windows[0]``); a
        # bad --duration is left for simulate to refuse
        from braidsim.simulate import time_window

        win = time_window("--window", win, 0.0, T)
    windows = [win] if win else None
    with progress_simulated(f"simulating {sc.name}, {T:g} s", 0.0, T, quiet=json_):
        res = braidsim.simulate(
            sc,
            duration=dur,
            windows=windows,
            sensitivities=[k.strip() for k in sensitivity or ()] or None,
            series=out is not None,  # only the files of --out read the series
        )
    summary = res.summary(window=win)
    if out is not None:
        with progress_status(f"writing {out}", quiet=json_):
            _write_run(res, summary, out, csv)
    if json_:
        print_json(summary)
        return
    _print_summary(summary, out)


def _write_run(res: Any, summary: dict[str, Any], out: Path, csv: bool) -> None:
    """The files of ``run --out``, written as one directory (whole or absent)."""
    import json

    from braidsim.export import write_series_netcdf
    from braidsim.io import atomic_directory, json_safe
    from braidsim.plotting import run_figures
    from braidsim.result import impacts_csv

    with atomic_directory(out, kind="run") as tmp:
        if csv:
            res.to_csv(tmp)
        else:
            (tmp / "impacts.csv").write_text(impacts_csv(res.impacts), encoding="utf-8")
        run_figures(res, tmp)
        write_series_netcdf(res, tmp / "series.nc")
        (tmp / "summary.json").write_text(
            json.dumps(json_safe(summary), indent=1), encoding="utf-8"
        )


def _print_summary(summary: dict, out: Path | None) -> None:
    """The tables of ``run``: the ranges of the track pair (x), and of the slot pair (y) too
    when the scenario has both degrees of freedom (``simulation.dof = "xy"``)."""
    from rich.markup import escape
    from rich.table import Table

    con = result_console()
    sim = summary.get("simulation", {})
    con.print(
        f"[bold]{escape(summary['scenario'])}[/bold]  "
        f"window {summary['window'][0]:g}-{summary['window'][1]:g} s"
        + (f"  (run of {sim['duration']:g} s)" if "duration" in sim else "")
    )
    xy = summary["parameters"].get("simulation.dof") == "xy"
    scale = {
        "depth": (1e3, "mm"),
        "stiffness_force": (1, "N"),
        "damping_force": (1, "N"),
        "contact_force": (1, "N"),
    }
    pairs = [("x", "track (x)")] + ([("y", "slot (y)")] if xy else [])
    tab = Table("quantity", *(f"{h} {m}" for _, h in pairs for m in ("min", "max")))
    for k, (f, u) in scale.items():
        cells = []
        for key, _ in pairs:
            lo, hi = summary[key][k]
            cells += [f"{lo * f:.6g}", f"{hi * f:.6g}"]
        tab.add_row(escape(f"{k} [{u}]"), *cells)
    con.print(tab)
    imp = summary["impacts"]
    fin = summary["final"]
    final = f"final x = {fin['x'] * 1e3:.6g} mm"
    if xy:
        final += f", y = {fin['y'] * 1e3:.6g} mm"
    # (a contact present at the start or after a transfer is listed, not counted: an impact
    # is an onset, as in the metrics of a sweep or a batch)
    initial = [r for r in imp if r.get("initial")]
    counted = f"{len(imp) - len(initial)} impacts"
    if initial:
        later = sum(1 for r in initial if r["t"] > 0.0)
        when = ("at the start", "at the start or after a transfer", "after a transfer")[
            (later > 0) + (later == len(initial))
        ]
        counted += f" (+{len(initial)} contact{'s' if len(initial) > 1 else ''} {when})"
    con.print(f"{counted}; {final}")
    if "sensitivity" in fin:
        ts = Table("d/d KEY (SI)", "x", "vx", "y", "vy", title="sensitivity of the final state")
        for key, d in fin["sensitivity"].items():
            ts.add_row(escape(key), *(f"{d[q]:.6g}" for q in ("x", "vx", "y", "vy")))
        con.print(ts)
    if imp:
        t2 = Table(
            *(
                escape(h)
                for h in (
                    "t [s]",
                    "pair",
                    "wall",
                    "v [m/s]",
                    "rebound [m/s]",
                    "peak F [N]",
                    "depth [mm]",
                )
            )
        )
        for r in imp[:12]:
            reb = r["rebound_velocity"]
            # (a contact present at the start has no approach: its row's velocity is the
            # depth rate at t = 0, which the table of approach speeds does not show)
            vel = None if r["initial"] else r["velocity"]
            t2.add_row(
                f"{r['t']:.6f}",
                r["pair"],
                r["wall"],
                "-" if vel is None else f"{vel:.4g}",
                "-" if reb is None else f"{reb:.4g}",
                f"{r['peak_force']:.5g}",
                f"{r['max_depth'] * 1e3:.4g}",
            )
        con.print(t2)
        if len(imp) > 12:
            con.print(f"... {len(imp) - 12} more (--json for all)")
    if out is not None:
        con.print(f"written to {out}")


#: the scenario keys through which `impact` checks its options
_IMPACT_OPTIONS = {
    "contact.track.model": "--model",
    "contact.track.restitution": "--restitution",
    "contact.track.exponent": "--exponent",
    "contact.track.stiffness": "--stiffness",
    "carrier.mass": "--mass",
    "initial.vx": "--velocity",
    "velocity": "--velocity",
}


@app.command()
@guarded
def impact(
    model: Annotated[str, typer.Option(help="Contact law (braidsim models).")] = "hunt_crossley",
    restitution: Annotated[
        str, typer.Option(help="Coefficient of restitution in (0, 1].")
    ] = "0.5555555555555556",
    velocity: Annotated[
        str, typer.Option(help="Approach speed [m/s], e.g. '0.5 m/s'.")
    ] = "0.5 m/s",
    mass: Annotated[str, typer.Option(help="Mass [kg], e.g. '1.2 kg'.")] = "1.2 kg",
    stiffness: Annotated[
        str | None, typer.Option(help="K [N/m^n], e.g. '1e9 N/m^1.5'; Eq. (4) by default.")
    ] = None,
    exponent: Annotated[float | None, typer.Option(help="Force exponent n.")] = None,
    json_: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """One impact of a free mass on a fixed wall."""
    from braidsim.impact import single_impact

    def num(text: str) -> float | str:
        try:
            return float(text)
        except ValueError:
            return text

    k_si = None
    if stiffness is not None:
        from braidsim.contact import get_law

        n = exponent if exponent is not None else get_law(model).default_exponent
        k_si = quantity_option("--stiffness", stiffness, f"N/m**{n!r}")
    try:
        res = single_impact(
            model,
            num(restitution),
            quantity_option("--velocity", num(velocity), "m/s"),
            quantity_option("--mass", num(mass), "kg"),
            k_si,
            exponent,
        )
    except InputError as exc:
        # single_impact checks its values as the scenario keys it sets: name the options
        msg = str(exc)
        for key, option in _IMPACT_OPTIONS.items():
            if msg.startswith(f"{key}:"):
                raise InputError(option + msg[len(key) :]) from None
        raise
    if json_:
        print_json(res)
        return
    from rich.table import Table

    tab = Table("quantity", "value")
    for k, v in res.items():
        if isinstance(v, dict):
            for k2, v2 in v.items():
                tab.add_row(f"closed form {k2}", f"{v2:.8g}")
        else:
            tab.add_row(k, f"{v:.8g}" if isinstance(v, float) else str(v))
    result_console().print(tab)


@app.command()
@guarded
def models(
    json_: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """List the contact force laws with their damping factor D(c_r)."""
    from braidsim.contact import _LAWS

    rows: list[dict[str, Any]] = []
    for law in _LAWS.values():
        d = law.damping_factor(5.0 / 9.0)
        from braidsim.contact import effective_restitution

        rows.append(
            {
                "name": law.name,
                "equation": law.equation,
                "reference": law.reference,
                "formula": law.formula,
                "default_exponent": law.default_exponent,
                "dissipative": law.dissipative,
                "damping_factor_at_5_9": d,
                "effective_restitution_at_5_9": effective_restitution(d),
            }
        )
    if json_:
        print_json({"models": rows})
        return
    from rich.table import Column, Table

    tab = Table(
        _whole("name", [r["name"] for r in rows]),
        *(Column(h, overflow="fold") for h in ("paper", "n", "D(5/9)", "e(5/9)", "reference")),
    )
    for r in rows:
        tab.add_row(
            r["name"],
            r["equation"],
            f"{r['default_exponent']:g}",
            f"{r['damping_factor_at_5_9']:.4f}",
            f"{r['effective_restitution_at_5_9']:.4f}",
            r["reference"],
        )
    result_console().print(tab)


@app.command()
@guarded
def scenarios(
    keys: Annotated[bool, typer.Option("--keys", help="List every parameter key instead.")] = False,
    json_: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """List the built-in scenarios (or, with --keys, every parameter key)."""
    import braidsim
    from braidsim.params import SCHEMA, json_value

    if keys:
        rows = [
            {
                "key": s.key,
                "unit": s.unit,
                "default": json_value(s.default),
                "allowed": s.range_text(),
                "doc": s.doc,
            }
            for s in SCHEMA.values()
        ]
        if json_:
            print_json({"keys": rows})
            return
        from rich.markup import escape
        from rich.table import Column, Table

        tab = Table(
            _whole("key", [r["key"] for r in rows]),
            *(Column(h, overflow="fold") for h in ("unit", "default", "allowed", "meaning")),
        )
        for r in rows:
            tab.add_row(
                *(escape(str(c)) for c in (r["key"], r["unit"], r["default"], r["allowed"])),
                escape(r["doc"]),
            )
        result_console().print(tab)
        return
    rows = []
    for name in braidsim.builtin_names():
        sc = braidsim.load_scenario(name)
        rows.append({"name": name, "description": sc.description, "source": sc.source})
    if json_:
        print_json({"scenarios": rows})
        return
    from rich.table import Column, Table

    tab = Table(
        _whole("name", [r["name"] for r in rows]),
        *(Column(h, overflow="fold") for h in ("description", "source")),
    )
    for r in rows:
        tab.add_row(r["name"], r["description"], r["source"])
    result_console().print(tab)


def _whole(title: str, names: list[str]) -> Any:
    """A table column that shows each name whole on one line, whatever the terminal's width
    (a name the user types back: a law for --model, a scenario, a key for --set); the other
    columns fold instead of cutting it short."""
    from rich.table import Column

    return Column(title, no_wrap=True, min_width=max(map(len, names), default=len(title)))
