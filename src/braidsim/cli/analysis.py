"""Verbs ``restitution``, ``bifurcation``, ``basins``, ``lyapunov`` and ``analyze``.

Thin wrappers over :mod:`braidsim.analysis`; each takes ``--json`` (one JSON object on
stdout) and ``--out DIR`` (figures and ``*.json`` written as a whole directory, or not at all).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
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

JsonOpt = Annotated[bool, typer.Option("--json", help="Print one JSON object.")]
OutOpt = Annotated[
    Path | None, typer.Option("--out", help="Write figures and JSON into this directory.")
]
SetOpt = Annotated[list[str] | None, typer.Option("--set", help="KEY=VALUE override (repeatable).")]
WorkersOpt = Annotated[
    int, typer.Option(help="Local worker processes (1: this process; 0: all cores).")
]
TransientOpt = Annotated[
    float, typer.Option("--transient-cycles", help="Discarded start [excitation cycles].")
]
CyclesOpt = Annotated[
    int, typer.Option("--cycles", help="Steady-state window [excitation cycles].")
]


def _write_outputs(
    out: Path, kind: str, payload: dict[str, Any], figures: dict[str, Callable[[], Any]]
) -> None:
    """Write ``<kind>.json`` and the figures into ``out`` as one atomic directory."""
    from braidsim.io import atomic_directory, json_safe
    from braidsim.plotting import save

    with atomic_directory(out, kind=f"analysis-{kind}") as tmp:
        (tmp / f"{kind}.json").write_text(
            json.dumps(json_safe(payload), indent=1), encoding="utf-8"
        )
        for name, make in figures.items():
            save(make(), tmp / name)


def _check_out(out: Path | None, kind: str) -> None:
    """Refuse an unusable --out before the work starts (not after it)."""
    if out is not None:
        from braidsim.io import check_output_directory

        check_output_directory(out, kind=f"analysis-{kind}")


def _console() -> Any:
    return result_console()


def _with_provenance(
    payload: dict[str, Any], scenario: Any, settings: dict[str, Any]
) -> dict[str, Any]:
    """``payload`` led by the provenance record: version, date, resolved scenario and the
    settings actually used (:func:`braidsim.provenance.provenance`)."""
    from braidsim.provenance import provenance

    prov = provenance(scenario, settings)
    out = {**prov, **payload}
    if "scenario" in payload:  # the analysis' own name wins (e.g. a run folder's)
        out["scenario"] = payload["scenario"]
    return out


def _steady_settings(sc: Any, transient_cycles: float, cycles: int) -> dict[str, Any]:
    """The steady-state window rule of the stroboscopic verbs, in numbers and words."""
    from braidsim.analysis.regimes import reference_period

    T = reference_period(sc)
    t0 = transient_cycles * T
    return {
        "transient_cycles": transient_cycles,
        "cycles": cycles,
        "period": T,
        "window": [t0, t0 + cycles * T],
        "window_rule": (
            f"the first {transient_cycles:g} periods T = {T:.6g} s are discarded; the steady "
            f"state is judged over the next {cycles} ({t0:.6g}-{t0 + cycles * T:.6g} s for "
            "the base scenario; each run uses its own T)"
        ),
    }


def _title(name: str, sets: dict[str, Any]) -> str:
    """Scenario name with the --set overrides, for figure titles."""
    if not sets:
        return name
    return name + " (" + ", ".join(f"{k} = {v}" for k, v in sets.items()) + ")"


# ----------------------------------------------------------------------------------------
# restitution
# ----------------------------------------------------------------------------------------


@app.command()
@guarded
def restitution(
    law: Annotated[
        list[str] | None, typer.Option("--law", help="Contact law (repeatable; default all).")
    ] = None,
    c_min: Annotated[float, typer.Option(help="Smallest nominal c_r.")] = 0.1,
    c_max: Annotated[float, typer.Option(help="Largest nominal c_r.")] = 1.0,
    points: Annotated[int, typer.Option(help="Number of c_r values.")] = 10,
    velocity: Annotated[
        str, typer.Option(help="Approach speed [m/s], e.g. '0.5 m/s'.")
    ] = "0.5 m/s",
    mass: Annotated[str, typer.Option(help="Mass [kg], e.g. '1.2 kg'.")] = "1.2 kg",
    out: OutOpt = None,
    json_: JsonOpt = False,
) -> None:
    """Effective restitution of each contact law against its nominal c_r (simulated impacts
    beside the exact relation of the family)."""
    import numpy as np

    from braidsim.analysis.restitution import restitution_table

    _check_out(out, "restitution")
    for name, v in (("--c-min", c_min), ("--c-max", c_max)):
        if not (0.0 < v <= 1.0):
            raise InputError(f"{name}: {v!r} is out of range; allowed 0 < c_r <= 1")
    if c_min > c_max:
        raise InputError(f"--c-min: {c_min!r} is above --c-max {c_max!r}; allowed c_min <= c_max")
    if points < 1:
        raise InputError(f"--points: {points!r} is out of range; allowed >= 1")
    from braidsim import limits
    from braidsim.contact import law_names
    from braidsim.specfile import closest_hint

    for name in law or ():
        if name not in law_names():
            raise InputError(
                f"--law: {name!r} is not a contact law{closest_hint(name, law_names())}; "
                f"allowed {', '.join(law_names())}"
            )
    limits.check("runs", points * len(law or law_names()), "--points x --law (simulated impacts)")
    v = quantity_option("--velocity", velocity, "m/s")
    m = quantity_option("--mass", mass, "kg")
    if not v > 0:
        raise InputError(f"--velocity: {v!r} m/s is out of range; allowed > 0 m/s")
    if not m > 0:
        raise InputError(f"--mass: {m!r} kg is out of range; allowed > 0 kg")
    from braidsim.cli.progress import progress_status

    with progress_status("simulating the impacts of every law", quiet=json_):
        table = restitution_table(law, np.linspace(c_min, c_max, points), v, m)
    settings = {
        "laws": list(table.laws),
        "c_min": c_min,
        "c_max": c_max,
        "points": points,
        "velocity": v,
        "mass": m,
    }
    payload = _with_provenance(table.to_dict(), None, settings)
    if out is not None:
        from braidsim.analysis.plots import plot_restitution

        _write_outputs(
            out, "restitution", payload, {"restitution.png": lambda: plot_restitution(table)}
        )
    if json_:
        print_json(payload)
        return
    from rich.table import Table

    tab = Table("law", *(f"{c:.3g}" for c in table.nominal), title="effective restitution e")
    for i, name in enumerate(table.laws):
        tab.add_row(name, *(f"{e:.4f}" for e in table.simulated[i]))
    con = _console()
    con.print(tab)
    con.print(f"largest |simulated - exact| = {table.max_deviation:.2g}")
    if out is not None:
        con.print(f"written to {out}")


# ----------------------------------------------------------------------------------------
# bifurcation
# ----------------------------------------------------------------------------------------


def _check_grid(runs: int, workers: int, option: str) -> None:
    """Refuse a negative --workers and a grid over the run limit, before any work."""
    from braidsim import limits

    if workers < 0:
        raise InputError(f"--workers: {workers} is out of range; allowed >= 0 (0: all cores)")
    if runs < 1:
        raise InputError(f"{option}: {runs} is out of range; allowed >= 1")
    limits.check("runs", runs, option)


def _axis_value(option: str, key: str, text: str) -> float:
    """A value of a scalar scenario key given on the command line (unit policy applies), in
    SI, checked against the key's range; an error names ``option`` and the key, as a sweep
    spec's ``start (key)`` does."""
    from braidsim.analysis.bifurcation import to_si
    from braidsim.params import SCHEMA, parse_set_value

    v = quantity_option(option, parse_set_value(key, text), SCHEMA[key].unit)
    try:
        return to_si(key, v)
    except InputError as exc:
        head, _, rest = str(exc).partition(": ")
        raise InputError(f"{option} ({head}): {rest}") from None


def _scalar_key(option: str, key: str) -> None:
    """:func:`~braidsim.analysis.bifurcation.check_scalar_key`, its error naming ``option``
    as typed (the API's says ``parameter``)."""
    from braidsim.analysis.bifurcation import check_scalar_key

    try:
        check_scalar_key(key)
    except InputError as exc:
        raise InputError(f"{option}: {str(exc).partition(': ')[2]}") from None


def _typed(ctx: typer.Context | None, name: str) -> bool:
    """Whether the option of parameter ``name`` was given on the command line (not its
    default)."""
    if ctx is None:
        return True
    source = ctx.get_parameter_source(name)
    return source is None or source.name != "DEFAULT"


def _axis_range(
    key: str,
    start: tuple[str, str],
    stop: tuple[str, str],
    count: tuple[str, int],
    stop_typed: bool = True,
) -> Any:
    """The ``count`` evenly spaced values of ``key`` from ``start`` to ``stop`` [SI], each
    given as (option, value as typed), under the rule of a sweep axis's start/stop/num
    (braidsim.sweep.spec): stop above start, or equal to it for a single value; a reversed
    range, a range of several equal values, or a single value with a stop it would not use
    is refused, naming the option. A single value with a stop left at its default
    (``stop_typed`` false: a basins axis) is the start alone, as asked."""
    import numpy as np

    from braidsim.params import SCHEMA
    from braidsim.sweep.spec import check_range

    (o_a, text_a), (o_b, text_b), (o_n, n) = start, stop, count
    a = _axis_value(o_a, key, text_a)
    if n == 1 and not stop_typed:
        return np.array([a])
    b = _axis_value(o_b, key, text_b)
    check_range((a, b, n), (o_a, o_b, o_n), (text_a, text_b), SCHEMA[key].unit)
    return np.linspace(a, b, n)


@app.command()
@guarded
def bifurcation(
    scenario: Annotated[
        str, typer.Argument(help="Built-in scenario name or TOML file.", metavar="SCENARIO")
    ],
    param: Annotated[
        str, typer.Option("--param", help="Scalar parameter, e.g. track.vibration_amplitude.")
    ],
    start: Annotated[str, typer.Option("--from", help="First value, e.g. '0.05 mm'.")],
    stop: Annotated[str, typer.Option("--to", help="Last value, e.g. '0.3 mm'.")],
    points: Annotated[int, typer.Option(help="Number of values.")] = 41,
    set_: SetOpt = None,
    transient_cycles: TransientOpt = 100.0,
    cycles: CyclesOpt = 50,
    workers: WorkersOpt = 1,
    out: OutOpt = None,
    json_: JsonOpt = False,
) -> None:
    """Stroboscopic bifurcation diagram of the settled motion against one parameter."""
    import braidsim
    from braidsim.analysis.bifurcation import bifurcation as run_bifurcation
    from braidsim.analysis.bifurcation import class_text
    from braidsim.cli.progress import progress_bar, sigterm_as_interrupt

    _check_out(out, "bifurcation")
    _check_grid(points, workers, "--points")
    _scalar_key("--param", param)
    sc = braidsim.load_scenario(scenario, overrides=parse_sets(set_))
    values = _axis_range(param, ("--from", start), ("--to", stop), ("--points", points))
    with (
        sigterm_as_interrupt(),
        progress_bar(f"bifurcation of {sc.name}", len(values), quiet=json_) as advance,
    ):
        diag = run_bifurcation(
            sc,
            param,
            values,
            transient_cycles=transient_cycles,
            cycles=cycles,
            workers=workers,
            on_done=advance,
        )
    settings = {
        "param": param,
        "from": start,
        "to": stop,
        "points": points,
        "workers": workers,
        **_steady_settings(sc, transient_cycles, cycles),
    }
    payload = _with_provenance(diag.to_dict(samples=True), sc, settings)
    if out is not None:
        from braidsim.analysis.plots import plot_bifurcation

        _write_outputs(
            out, "bifurcation", payload, {"bifurcation.png": lambda: plot_bifurcation(diag)}
        )
    if json_:
        print_json(payload)
        return
    from rich.table import Table

    tab = Table(param, "regime", "period", "impacts/cycle", title=f"{sc.name}: steady states")
    for v, s in zip(diag.values, diag.states, strict=True):
        r = s.regime
        tab.add_row(f"{v:.6g}", r.label, str(r.period or "-"), f"{r.impacts_per_cycle:.3g}")
    con = _console()
    con.print(tab)
    con.print(f"steady-state window: {settings['window_rule']}")
    for tr in diag.transitions():
        con.print(
            f"change between {tr['lower']:.6g} and {tr['upper']:.6g}: "
            f"{class_text(tr['from'])} -> {class_text(tr['to'])}"
        )
    if out is not None:
        con.print(f"written to {out}")


# ----------------------------------------------------------------------------------------
# basins
# ----------------------------------------------------------------------------------------


@app.command()
@guarded
def basins(
    ctx: typer.Context,
    scenario: Annotated[
        str, typer.Argument(help="Built-in scenario name or TOML file.", metavar="SCENARIO")
    ],
    x: Annotated[str, typer.Option("--x", help="First grid parameter.")] = "initial.x",
    x_from: Annotated[str, typer.Option("--x-from", help="First value of x.")] = "0 mm",
    x_to: Annotated[str, typer.Option("--x-to", help="Last value of x.")] = "3 mm",
    nx: Annotated[int, typer.Option("--nx", help="Values of x.")] = 16,
    y: Annotated[str, typer.Option("--y", help="Second grid parameter.")] = "initial.vx",
    y_from: Annotated[str, typer.Option("--y-from", help="First value of y.")] = "-0.6 m/s",
    y_to: Annotated[str, typer.Option("--y-to", help="Last value of y.")] = "0.6 m/s",
    ny: Annotated[int, typer.Option("--ny", help="Values of y.")] = 16,
    set_: SetOpt = None,
    transient_cycles: TransientOpt = 100.0,
    cycles: CyclesOpt = 50,
    workers: WorkersOpt = 1,
    out: OutOpt = None,
    json_: JsonOpt = False,
) -> None:
    """Basins of attraction: the steady state reached from each start of a 2-D grid."""
    import braidsim
    from braidsim.analysis.basins import basins as run_basins

    if x == y:
        raise InputError(f"--x, --y: both are {x!r}; allowed two different parameters")
    _check_out(out, "basins")
    for option, count in (("--nx", nx), ("--ny", ny)):
        if count < 1:
            raise InputError(f"{option}: {count} is out of range; allowed >= 1")
    _check_grid(nx * ny, workers, "--nx x --ny")
    _scalar_key("--x", x)
    _scalar_key("--y", y)
    sc = braidsim.load_scenario(scenario, overrides=parse_sets(set_))
    xs = _axis_range(x, ("--x-from", x_from), ("--x-to", x_to), ("--nx", nx), _typed(ctx, "x_to"))
    ys = _axis_range(y, ("--y-from", y_from), ("--y-to", y_to), ("--ny", ny), _typed(ctx, "y_to"))
    from braidsim.cli.progress import progress_bar, sigterm_as_interrupt

    with (
        sigterm_as_interrupt(),
        progress_bar(f"basins of {sc.name}", len(xs) * len(ys), quiet=json_) as advance,
    ):
        bmap = run_basins(
            sc,
            x,
            xs,
            y,
            ys,
            transient_cycles=transient_cycles,
            cycles=cycles,
            workers=workers,
            on_done=advance,
        )
    settings = {
        "x": x,
        "x_from": x_from,
        "x_to": x_to,
        "nx": nx,
        "y": y,
        "y_from": y_from,
        "y_to": y_to,
        "ny": ny,
        "workers": workers,
        **_steady_settings(sc, transient_cycles, cycles),
    }
    payload = _with_provenance(bmap.to_dict(), sc, settings)
    if out is not None:
        from braidsim.analysis.plots import plot_basins

        _write_outputs(out, "basins", payload, {"basins.png": lambda: plot_basins(bmap)})
    if json_:
        print_json(payload)
        return
    from rich.table import Table

    tab = Table("id", "regime", "period", "walls", "starts", title=f"{sc.name}: attractors")
    for a in bmap.attractors:
        tab.add_row(str(a.id), a.label, str(a.period or "-"), a.walls, str(a.count))
    con = _console()
    con.print(tab)
    con.print(f"steady-state window: {settings['window_rule']}")
    failed = int((bmap.ids < 0).sum())
    if failed:
        con.print(f"{failed} runs failed numerically")
    if out is not None:
        con.print(f"written to {out}")


# ----------------------------------------------------------------------------------------
# lyapunov
# ----------------------------------------------------------------------------------------


@app.command()
@guarded
def lyapunov(
    scenario: Annotated[
        str, typer.Argument(help="Built-in scenario name or TOML file.", metavar="SCENARIO")
    ],
    set_: SetOpt = None,
    transient_cycles: TransientOpt = 100.0,
    cycles: Annotated[float, typer.Option(help="Measuring time [excitation cycles].")] = 100.0,
    interval: Annotated[
        str | None, typer.Option(help="Renormalisation interval [s] (default T_h/16).")
    ] = None,
    d0: Annotated[
        str, typer.Option(help="Separation of the two trajectories [m], e.g. '1 nm'.")
    ] = "1 nm",
    curve: Annotated[
        bool,
        typer.Option(
            "--curve",
            help="Print the running estimate (times, running) in the JSON too; "
            "lyapunov.json of --out always has it.",
        ),
    ] = False,
    out: OutOpt = None,
    json_: JsonOpt = False,
) -> None:
    """Largest Lyapunov exponent of the settled motion (two nearby trajectories)."""
    import braidsim
    from braidsim.analysis.lyapunov import carrier_lyapunov
    from braidsim.cli.progress import progress_status

    _check_out(out, "lyapunov")
    sets = parse_sets(set_)
    sc = braidsim.load_scenario(scenario, overrides=sets)
    d0_m = quantity_option("--d0", d0, "m")
    if not (0 < d0_m <= 1e-3):
        raise InputError(
            f"--d0: {d0_m:g} m is out of range; allowed 0 < d0 <= 1 mm (a small separation, "
            "e.g. '1 nm')"
        )
    tau = None if interval is None else quantity_option("--interval", interval, "s")
    with progress_status(f"two trajectories of {sc.name}", quiet=json_):
        res = carrier_lyapunov(
            sc, transient_cycles=transient_cycles, cycles=cycles, interval=tau, d0=d0_m
        )
    settings = {
        "transient_cycles": transient_cycles,
        "cycles": cycles,
        "interval": res.estimate.interval,
        "d0": d0_m,
        "transient": res.transient,
        "window_rule": (
            f"the first {transient_cycles:g} periods ({res.transient:.6g} s) are discarded; "
            f"the exponent is measured over the next {cycles:g}"
        ),
    }
    payload = _with_provenance(res.to_dict(curve=True), sc, settings)
    if out is not None:
        from braidsim.analysis.plots import plot_lyapunov

        title = f"{_title(sc.name, sets)}: convergence"
        _write_outputs(
            out,
            "lyapunov",
            payload,
            {"lyapunov.png": lambda: plot_lyapunov(res.estimate, title)},
        )
    if json_:
        if not curve:
            payload = {k: v for k, v in payload.items() if k not in ("times", "running")}
        print_json(payload)
        return
    con = _console()
    est = res.estimate
    se = est.standard_error()
    # the standard error by batch means is the statistical error; the range of the running
    # estimate only says how far it has settled
    if math.isfinite(se):
        pm, note = f" +- {se:.2g}", "+- its standard error by batch means of 10 blocks"
    else:
        pm, note = "", "no standard error: fewer than 10 intervals"
    con.print(
        f"[bold]{sc.name}[/bold]: largest Lyapunov exponent {est.exponent:.5g}{pm} 1/s "
        f"({note}; {est.times.size} intervals of {est.interval:.3g} s after "
        f"{res.transient:g} s; range of the running estimate over the last half "
        f"{est.spread():.3g} 1/s)"
    )
    if out is not None:
        con.print(f"written to {out}")


# ----------------------------------------------------------------------------------------
# analyze
# ----------------------------------------------------------------------------------------


def _run_source(run: str) -> tuple[Any, float | None]:
    """(scenario, duration) of RUN: a folder written by ``braidsim run --out`` (its
    summary.json) or a scenario name / TOML file."""
    import braidsim

    p = Path(run)
    if p.is_dir():
        summary = p / "summary.json"
        if not summary.is_file():
            raise InputError(
                f"RUN: folder {run!r} has no summary.json; allowed a folder written by "
                "`braidsim run --out` or a scenario"
            )
        try:
            data = json.loads(summary.read_text(encoding="utf-8"))
            # Scenario.to_dict writes an infinite value (a flat body's radius) as "inf"
            params = {
                k: (math.inf if v == "inf" else v)
                for k, v in data["parameters"].items()
                if v is not None
            }
            t_end = float(data["final"]["t"])
            name = str(data.get("scenario", "run"))
        except (ValueError, KeyError, TypeError, AttributeError, UnicodeDecodeError) as exc:
            raise InputError(
                f"RUN: {str(summary)!r} is damaged or incomplete ({exc.__class__.__name__}); "
                "allowed a folder written whole by `braidsim run --out` (run it again)"
            ) from None
        sc = braidsim.load_scenario(params).with_overrides(None, name=name)
        return sc, t_end
    if not p.exists() and len(p.parts) > 1:
        # a path that is not there (load_scenario would name scenarios and TOML files only;
        # a bare name goes on to it, for its "did you mean" among the built-in scenarios)
        raise InputError(
            f"RUN: {run!r} does not exist; allowed a folder written by `braidsim run --out`, "
            "a TOML file or a built-in scenario (`braidsim scenarios` lists them)"
        )
    return braidsim.load_scenario(run), None


@app.command()
@guarded
def analyze(
    run: Annotated[
        str,
        typer.Argument(
            help="Scenario name or TOML file, or a folder written by `braidsim run --out` "
            "(the run is repeated from its parameters; runs are deterministic).",
            metavar="RUN",
        ),
    ],
    set_: SetOpt = None,
    duration: Annotated[
        str | None,
        typer.Option(
            help="Simulated time [s] (default: the scenario's, at least 150 excitation "
            "periods; for a run folder, that run's own length)."
        ),
    ] = None,
    transient: Annotated[
        str | None,
        typer.Option(
            help="Start of the steady-state window [s] (default: after 100 excitation periods, "
            "at least half the run, leaving 50 periods)."
        ),
    ] = None,
    out: OutOpt = None,
    json_: JsonOpt = False,
) -> None:
    """Impact statistics, energy balance, regime, contact-loss bound and spectra of a run."""
    from braidsim.analysis.report import analyze as run_analyze
    from braidsim.cli.progress import progress_status

    _check_out(out, "analyze")
    sc, dur = _run_source(run)
    sets = parse_sets(set_)
    if sets:
        sc = sc.with_overrides(sets)
    if duration is not None:
        dur = quantity_option("--duration", duration, "s")
    t0 = None if transient is None else quantity_option("--transient", transient, "s")
    with progress_status(f"simulating and analysing {sc.name}", quiet=json_):
        a = run_analyze(sc, duration=dur, transient=t0)
    settings = {
        "duration": float(a.result.model.duration),
        "transient": a.window[0] if t0 is None else t0,
        "window": list(a.window),
        "window_rule": a.window_rule,
    }
    prov_sc = a.result.model.scenario.with_overrides(
        {"simulation.duration": float(a.result.model.duration)}
    )
    payload = _with_provenance(a.to_dict(), prov_sc, settings)
    if out is not None:
        from braidsim.analysis import plots

        figs: dict[str, Callable[[], Any]] = {
            "impacts.png": lambda: plots.plot_impact_statistics(a.impacts),
            "energy.png": lambda: plots.plot_energy_balance(a.energy),
            "spectra.png": lambda: plots.plot_spectra(a.spectra),
        }
        steady = a.steady
        if steady is not None:
            figs["poincare.png"] = lambda: plots.plot_poincare(steady)
        _write_outputs(out, "analyze", payload, figs)
    if json_:
        print_json(payload)
        return
    _print_analysis(payload, out)


def _print_analysis(d: dict[str, Any], out: Path | None) -> None:
    con = _console()
    con.print(
        f"[bold]{d['scenario']}[/bold]: {d['duration']:g} s, window {d['window'][0]:.4g}-"
        f"{d['window'][1]:.4g} s"
    )
    con.print(f"steady-state window: {d['window_rule']}", markup=False)
    # the impacts in the steady-state window first: the whole run adds the transient's
    for label, imp in (("in the window", d["impacts_in_window"]), ("whole run", d["impacts"])):
        v = imp["approach_speed"]
        counts = ", ".join(f"{k} {n}" for k, n in imp["counts"].items()) or "-"
        con.print(
            f"impacts, {label}: {imp['count']} ({counts})"
            + (
                f", approach speed {v['min']:.3g}-{v['max']:.3g} m/s"
                if v["max"] is not None
                else ""
            )
            + f", track contact {100 * imp['contact_fraction']['track']:.3g} % of the time"
        )
    e = d["energy_balance"]
    t = e["totals"]
    con.print(
        f"energy, whole run: contact losses {t['contact_dissipated']:.4g} J, "
        f"friction {t['friction_dissipated']:.4g} J, "
        f"wall work {t['track_work'] + t['slot_work']:.4g} J, load work {t['load_work']:.4g} J; "
        f"balance closes to {e['closure']:.2g}"
    )
    r = d["regime"]
    if r is not None:
        reg = r["regime"]
        per = f", period {reg['period']} cycles" if reg["period"] else ""
        con.print(f"steady state: {reg['label']}{per} ({reg['rule']})")
    else:
        con.print(f"steady state: {d['regime_reason']}", markup=False)
    b = d["contact_loss_bound"]
    con.print(
        f"contact-loss bound: a_p = {b['pressing_acceleration']:.4g} m/s^2, h_a omega_h^2 = "
        f"{b['wall_acceleration']:.4g} m/s^2 -> "
        + ("stays on the wall" if b["stays_on_wall"] else "leaves the wall")
    )
    for sp in d["spectra"]:
        pk = ", ".join(f"{p['frequency']:.4g} Hz" for p in sp["peaks"][:4]) or "none"
        con.print(f"spectrum of {sp['quantity']}: dominant {pk}")
    if out is not None:
        con.print(f"written to {out}")
