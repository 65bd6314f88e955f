"""A continuation study from a TOML spec: branches, special points, boundary curves, files.

Spec (SI numbers or unit strings)::

    scenario = "paper-3.3"              # a built-in name or a TOML path
    [overrides]                         # optional, any scenario keys
    "friction.pad_track" = 0.0
    [continuation]
    parameter = "track.vibration_amplitude"
    from = "0.01 mm"                    # the seed orbit is computed here
    to = "0.5 mm"
    period = 1                          # forcing cycles per orbit (k)
    segments = 1                        # shooting segments (1: single shooting)
    method = "auto"                     # flow map: auto, exact, fd
    max_points = 200
    step = 0.02                         # first arclength step (parameter in units of |to - from|)
    max_step = 0.1
    switch = true                       # follow the period-2k branch at period doublings
    max_doublings = 2
    both_directions = false
    transient_cycles = 300              # periods simulated to the steady state that seeds the orbit
    resting_speed = "0.1 mm/s"          # latched speed of a contact open all along an orbit
                                        # (default contact.min_impact_velocity)
    seed = ["0.05 mm", "0 m/s"]         # optional (x, vx) at forcing phase 0 instead
    restart = "earlier/branch_0.nc"     # optional: start from a saved branch ...
    restart_point = -1                  # ... at this point (default the last)
    [operating_map]                     # optional: boundary curves of the first special
                                        # point of each type on each branch
    parameter = "horn_gear.angular_velocity"
    to = "10 pi rad/s"
    steps = 10                          # largest step along a curve: 1/steps of the ranges
    types = ["grazing", "fold", "period_doubling"]
    regime_points = [12, 10]            # brute-force regime map beneath (0: none)
    window = 0.04                       # grazing: first search step on the normal line
    cross = ["5 pi rad/s", "3 pi rad/s"]  # optional: a branch over this parameter (from, to)
                                        # at continuation.from, its boundaries followed too

``operating_map.cross`` finds boundaries a branch over the first parameter never meets: the
orbit seeded at (``continuation.from``, ``cross[0]``) is continued in the map's parameter to
``cross[1]``, and its special points of ``types`` are followed in the first parameter
(:func:`braidsim.continuation.twopar.crossing_boundaries`; on the (clearance, speed) map the
resting carrier's lift-off, which does not depend on the clearance).

The boundary curves are followed by pseudo-arclength continuation
(:mod:`braidsim.continuation.twopar`): a (clearance, speed) map is a spec with
``parameter = "track.clearance"`` and ``operating_map.parameter =
"horn_gear.angular_velocity"`` (``examples/continuation_clearance.toml``).

Transfers to the next horn gear break the time-periodicity unless they repeat with a whole
number of vibration periods: the spec is refused otherwise (see
:mod:`braidsim.continuation.system`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from braidsim.continuation.branch import SPECIAL_TYPES, Branch, continue_orbit
from braidsim.continuation.orbit import METHODS, seed_orbit
from braidsim.continuation.results import (
    branch_dataset,
    branch_json,
    branch_points_table,
    open_branch,
    orbit_from_dataset,
    write_branch,
)
from braidsim.continuation.system import ScenarioSystem, check_continuable
from braidsim.continuation.twopar import BoundaryCurve, trace_boundary
from braidsim.errors import InputError
from braidsim.io import json_safe
from braidsim.params import SCHEMA, Scenario, convert, load_scenario
from braidsim.specfile import check_keys, expect_table, read_toml_file

CONT_KEYS = (
    "parameter",
    "from",
    "to",
    "period",
    "segments",
    "method",
    "max_points",
    "step",
    "max_step",
    "min_step",
    "switch",
    "max_doublings",
    "both_directions",
    "transient_cycles",
    "seed",
    "restart",
    "restart_point",
    "resting_speed",
)
MAP_KEYS = ("parameter", "to", "steps", "types", "regime_points", "window", "cross")
REPORT_KIND = "continuation"


@dataclass(frozen=True)
class ContinuationSpec:
    """A validated continuation spec (module docstring); values in SI."""

    scenario: Scenario
    parameter: str
    start: float
    to: float
    period: int = 1
    segments: int = 1
    method: str = "auto"
    max_points: int = 200
    step: float = 0.02
    max_step: float = 0.1
    min_step: float = 1e-6
    switch: bool = True
    max_doublings: int = 2
    both_directions: bool = False
    transient_cycles: float = 300.0
    seed: tuple[float, ...] | None = None
    restart: str | None = None
    restart_point: int = -1
    resting_speed: float | None = None
    map_parameter: str | None = None
    map_to: float = 0.0
    map_steps: int = 10
    map_types: tuple[str, ...] = ("grazing", "fold", "period_doubling")
    regime_points: tuple[int, int] = (0, 0)
    map_window: float = 0.04
    map_cross: tuple[float, float] | None = None
    base_dir: Path = field(default_factory=Path)


def _si(key: str, value: Any, where: str) -> float:
    if key not in SCHEMA:
        raise InputError(f"{where}: unknown key {key!r}")
    v = convert(SCHEMA[key], value)
    if v is None:
        raise InputError(f"{where}: a value is needed; allowed {SCHEMA[key].range_text()}")
    return float(v)


def _int(where: str, value: Any, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise InputError(f"{where}: {value!r} is out of range; allowed an integer >= {low}")
    return int(value)


def _float(where: str, value: Any, low: float, high: float = math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where}: {value!r} is not a number; allowed {low:g} < value <= {high:g}")
    v = float(value)
    if not (math.isfinite(v) and low < v <= high):
        raise InputError(f"{where}: {value!r} is out of range; allowed {low:g} < value <= {high:g}")
    return v


def _bool(where: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise InputError(f"{where}: {value!r} is not a boolean; allowed true or false")
    return value


def parse_spec(table: Mapping[str, Any], base_dir: Path = Path()) -> ContinuationSpec:
    """Validate a spec table (module docstring); every error is one :class:`InputError`
    naming the key and the allowed values."""
    check_keys("", table, ("scenario", "overrides", "continuation", "operating_map", "name"))
    if "scenario" not in table:
        raise InputError("scenario: missing; allowed a built-in scenario name or a TOML path")
    name = table["scenario"]
    if not isinstance(name, str):
        raise InputError(f"scenario: {name!r} is not a name; allowed a built-in name or a path")
    path = base_dir / name
    sc = load_scenario(str(path) if path.is_file() else name)
    over = expect_table("overrides", table.get("overrides", {}))
    if over:
        sc = sc.with_overrides(dict(over))
    cont = expect_table("continuation", table.get("continuation", {}))
    check_keys("continuation.", cont, CONT_KEYS)
    for req in ("parameter", "from", "to"):
        if req not in cont and not (req == "from" and "restart" in cont):
            raise InputError(f"continuation.{req}: missing; allowed see `braidsim continue --help`")
    key = cont["parameter"]
    if not isinstance(key, str):
        raise InputError(f"continuation.parameter: {key!r} is not a key name")
    check_continuable(key)
    start = _si(key, cont["from"], "continuation.from") if "from" in cont else math.nan
    to = _si(key, cont["to"], "continuation.to")
    if to == start:
        raise InputError(
            f"continuation.to: equals continuation.from ({to:g}); allowed another value"
        )
    method = cont.get("method", "auto")
    if method not in METHODS:
        raise InputError(
            f"continuation.method: {method!r} is not allowed; allowed {', '.join(METHODS)}"
        )
    seed = None
    if "seed" in cont:
        s = cont["seed"]
        if not isinstance(s, list) or len(s) not in (2, 4):
            raise InputError("continuation.seed: expected [x, vx] or [x, vx, y, vy]")
        units = ("m", "m/s", "m", "m/s")
        from braidsim.units import to_si

        seed = tuple(
            float(to_si("continuation.seed", v, u)) for v, u in zip(s, units, strict=False)
        )
    resting = None
    if "resting_speed" in cont:
        from braidsim.units import to_si

        resting = float(to_si("continuation.resting_speed", cont["resting_speed"], "m/s"))
        if not (math.isfinite(resting) and resting > 0.0):
            raise InputError(
                f"continuation.resting_speed: {cont['resting_speed']!r} is out of range; "
                "allowed a speed > 0 m/s"
            )
    restart = cont.get("restart")
    if restart is not None and (
        not isinstance(restart, str) or Path(restart).suffix not in (".nc", ".zarr")
    ):
        raise InputError(
            f"continuation.restart: {restart!r} is not a saved branch; allowed the path of a "
            "branch_*.nc or branch_*.zarr that braidsim continue wrote"
        )
    restart_point = cont.get("restart_point", -1)
    if isinstance(restart_point, bool) or not isinstance(restart_point, int):
        raise InputError(
            f"continuation.restart_point: {restart_point!r} is not an integer; allowed a "
            "point of the saved branch, from 0 (negative: from the end, -1 the last)"
        )
    steps = {
        name: _float(f"continuation.{name}", cont.get(name, default), 0.0, 1.0)
        for name, default in (("step", 0.02), ("max_step", 0.1), ("min_step", 1e-6))
    }
    if not steps["min_step"] <= steps["step"] <= steps["max_step"]:
        raise InputError(
            f"continuation.step: min_step {steps['min_step']:g} <= step {steps['step']:g} <= "
            f"max_step {steps['max_step']:g} does not hold; allowed steps in that order"
        )
    transient = cont.get("transient_cycles", 300)
    if isinstance(transient, bool) or not isinstance(transient, int | float):
        raise InputError(
            f"continuation.transient_cycles: {transient!r} is not a number; allowed an "
            "integer 0 <= value <= 1e6"
        )
    if not (math.isfinite(transient) and transient == int(transient) and 0 <= transient <= 1e6):
        raise InputError(
            f"continuation.transient_cycles: {transient!r} is out of range; allowed an "
            "integer 0 <= value <= 1e6 (whole periods simulated before the orbit is sought; "
            "0: from the scenario's initial state)"
        )
    mp = expect_table("operating_map", table.get("operating_map", {}))
    check_keys("operating_map.", mp, MAP_KEYS)
    map_key = None
    map_to = 0.0
    types: tuple[str, ...] = ("grazing", "fold", "period_doubling")
    rp = (0, 0)
    cross = None
    if mp:
        map_key = mp.get("parameter")
        if not isinstance(map_key, str):
            raise InputError("operating_map.parameter: missing; allowed a scalar scenario key")
        check_continuable(map_key, "operating_map.parameter")
        if map_key == key:
            raise InputError("operating_map.parameter: must differ from continuation.parameter")
        if "to" not in mp:
            raise InputError("operating_map.to: missing; allowed a value of the second parameter")
        map_to = _si(map_key, mp["to"], "operating_map.to")
        base = sc[map_key]
        if base is not None and map_to == float(base):
            raise InputError(
                f"operating_map.to: equals the scenario's {map_key} ({map_to:g}), where the "
                "map starts; allowed another value"
            )
        if "types" in mp:
            t = mp["types"]
            if not isinstance(t, list) or any(x not in (*SPECIAL_TYPES[:2], "grazing") for x in t):
                raise InputError(
                    "operating_map.types: allowed a list of fold, period_doubling, grazing"
                )
            types = tuple(t)
        if "cross" in mp:
            c = mp["cross"]
            if not isinstance(c, list) or len(c) != 2:
                raise InputError(
                    "operating_map.cross: expected [from, to], two values of "
                    "operating_map.parameter"
                )
            cross = (
                _si(map_key, c[0], "operating_map.cross"),
                _si(map_key, c[1], "operating_map.cross"),
            )
            if cross[0] == cross[1]:
                raise InputError(
                    f"operating_map.cross: from equals to ({cross[0]:g}); allowed two values"
                )
        if "regime_points" in mp:
            r = mp["regime_points"]
            if not isinstance(r, list) or len(r) != 2:
                raise InputError("operating_map.regime_points: expected [n1, n2] (0: no map)")
            rp = (
                _int("operating_map.regime_points", r[0], 0),
                _int("operating_map.regime_points", r[1], 0),
            )
    return ContinuationSpec(
        scenario=sc,
        parameter=key,
        start=start,
        to=to,
        period=_int("continuation.period", cont.get("period", 1), 1),
        segments=_int("continuation.segments", cont.get("segments", 1), 1),
        method=method,
        max_points=_int("continuation.max_points", cont.get("max_points", 200), 2),
        step=steps["step"],
        max_step=steps["max_step"],
        min_step=steps["min_step"],
        switch=_bool("continuation.switch", cont.get("switch", True)),
        max_doublings=_int("continuation.max_doublings", cont.get("max_doublings", 2), 0),
        both_directions=_bool("continuation.both_directions", cont.get("both_directions", False)),
        transient_cycles=float(transient),
        seed=seed,
        restart=str(base_dir / restart) if restart else None,
        restart_point=restart_point,
        resting_speed=resting,
        map_parameter=map_key,
        map_to=map_to,
        map_steps=_int("operating_map.steps", mp.get("steps", 10), 1) if mp else 10,
        map_types=types,
        regime_points=rp,
        map_window=_float("operating_map.window", mp.get("window", 0.04), 0.0, 1.0) if mp else 0.04,
        map_cross=cross,
        base_dir=base_dir,
    )


def load_spec(path: str | Path) -> ContinuationSpec:
    """Read and validate a continuation spec file."""
    p = Path(path)
    return parse_spec(read_toml_file(p, "continuation spec"), p.parent)


@dataclass
class ContinuationResult:
    """What :func:`run_study` computed."""

    spec: ContinuationSpec
    branch: Branch
    curves: list[BoundaryCurve] = field(default_factory=list)
    regimes: tuple[np.ndarray, np.ndarray, list[list[str]]] | None = None
    timings: dict[str, float] = field(default_factory=dict)
    cross_branch: Branch | None = None
    """The branch over the map's parameter (``operating_map.cross``)."""

    @property
    def branches(self) -> list[Branch]:
        """The main branch and those switched to, depth first."""
        return self.branch.all_branches()

    def to_json(self) -> dict[str, Any]:
        """The ``--json`` object (SI)."""
        return {
            "scenario": self.spec.scenario.name,
            "branches": [branch_json(b) for b in self.branches],
            "boundaries": [c.to_dict() for c in self.curves],
            "cross_branch": branch_json(self.cross_branch) if self.cross_branch else None,
            "timings": self.timings,
        }


def run_study(
    spec: ContinuationSpec, progress: Callable[[str], None] | None = None
) -> ContinuationResult:
    """Seed, continue, switch branches and trace boundary curves as the spec says."""
    import time

    say = progress or (lambda s: None)
    system = ScenarioSystem(spec.scenario, resting_speed=spec.resting_speed)
    key = spec.parameter
    t_start = time.process_time()
    if spec.restart:
        ds = open_branch(spec.restart, "continuation.restart")
        if str(ds.attrs.get("parameter")) != key:
            raise InputError(
                f"continuation.restart: the saved branch continues {ds.attrs.get('parameter')!r}, "
                f"not {key!r}; allowed a branch of the same parameter"
            )
        orbit = orbit_from_dataset(system, ds, spec.restart_point, spec.method)
        say(f"restarted from point {spec.restart_point} of {spec.restart}")
    else:
        orbit = seed_orbit(
            system,
            {key: spec.start},
            spec.period,
            segments=spec.segments,
            transient_cycles=spec.transient_cycles,
            method=spec.method,
            state=spec.seed,
        )
        mods = np.round(np.abs(orbit.multipliers), 4).tolist()
        say(f"seed orbit at {key} = {spec.start:g}: |multipliers| {mods}")
    t_seed = time.process_time() - t_start
    count = [0]

    def on_point(o: Any) -> None:
        count[0] += 1
        say(
            f"point {count[0]}: {key} = {o.values[key]:.6g}, {'stable' if o.stable else 'unstable'}"
        )

    # the spec's step control, for the main branch and for the one along the map's parameter
    branch_options: dict[str, Any] = {
        "max_points": spec.max_points,
        "step": spec.step,
        "max_step": spec.max_step,
        "min_step": spec.min_step,
    }
    t0 = time.process_time()
    br = continue_orbit(
        system,
        orbit,
        key,
        spec.to,
        both_directions=spec.both_directions,
        method=spec.method,
        switch=spec.switch,
        max_depth=spec.max_doublings,
        on_point=on_point,
        **branch_options,
    )
    t_cont = time.process_time() - t0
    n_points = sum(len(b.points) for b in br.all_branches())
    res = ContinuationResult(spec, br)
    res.timings = {
        "seed_s": t_seed,
        "continuation_s": t_cont,
        "points": n_points,
        "per_point_s": t_cont / max(n_points, 1),
    }
    if spec.map_parameter:
        t1 = time.process_time()
        lo, hi = sorted((spec.start if math.isfinite(spec.start) else orbit.values[key], spec.to))
        for b in br.all_branches():
            # the first point of each type on each branch: the boundary of the regime the
            # branch starts in (later ones are followed by restarting from there)
            firsts: dict[str, Any] = {}
            for sp in b.special:
                firsts.setdefault(sp.type, sp)
            for sp in b.special:
                if sp.type not in spec.map_types or firsts[sp.type] is not sp:
                    continue
                say(f"boundary: {sp.type} at {key} = {sp.value:.6g} (period {sp.period})")
                c = trace_boundary(
                    system,
                    b,
                    sp,
                    spec.map_parameter,
                    spec.map_to,
                    steps=spec.map_steps,
                    window=spec.map_window,
                    method=spec.method,
                    range1=(lo, hi),
                    on_point=lambda a, c2: say(
                        f"  {spec.map_parameter} = {c2:.6g}: {key} = {a:.6g}"
                    ),
                )
                res.curves.append(c)
        if spec.map_cross is not None:
            from braidsim.continuation.twopar import crossing_boundaries

            f2, t2 = spec.map_cross
            p2_0 = float(spec.scenario[spec.map_parameter])
            r2 = (min(p2_0, spec.map_to, f2, t2), max(p2_0, spec.map_to, f2, t2))
            say(f"branch over {spec.map_parameter} from {f2:.6g} to {t2:.6g}")
            res.cross_branch, cs = crossing_boundaries(
                system,
                key,
                spec.start if math.isfinite(spec.start) else orbit.values[key],
                spec.map_parameter,
                f2,
                t2,
                spec.to,
                period=spec.period,
                types=spec.map_types,
                steps=spec.map_steps,
                window=spec.map_window,
                method=spec.method,
                range1=(lo, hi),
                range2=r2,
                branch_options=branch_options,
                on_point=lambda a, c2: say(f"  {key} = {c2:.6g}: {spec.map_parameter} = {a:.6g}"),
            )
            for c in cs:
                say(f"boundary: {c.name} met along {spec.map_parameter}")
            res.curves += cs
        n2 = sum(len(c.p1) for c in res.curves)
        dt = time.process_time() - t1
        res.timings.update(
            {"boundaries_s": dt, "boundary_points": n2, "per_boundary_point_s": dt / max(n2, 1)}
        )
        n1, n2r = spec.regime_points
        if n1 and n2r:
            res.regimes = regime_map(spec, lo, hi, n1, n2r, say)
    return res


def regime_map(
    spec: ContinuationSpec, lo: float, hi: float, n1: int, n2: int, say: Callable[[str], None]
) -> tuple[np.ndarray, np.ndarray, list[list[str]]]:
    """The brute-force regimes (:mod:`braidsim.analysis.regimes`) on an n1 x n2 grid of the
    two parameters."""
    from braidsim.analysis.runs import run_steady_states

    assert spec.map_parameter is not None
    key2 = spec.map_parameter
    p2_0 = float(spec.scenario[key2])
    v1 = np.linspace(lo, hi, n1)
    ends = (p2_0, spec.map_to, *(spec.map_cross or ()))
    v2 = np.linspace(min(ends), max(ends), n2)
    sets = [{spec.parameter: float(a), key2: float(b)} for a in v1 for b in v2]
    say(f"brute-force regime map: {len(sets)} runs")
    states = run_steady_states(spec.scenario, sets, transient_cycles=200, cycles=20)
    labels = [[states[i * n2 + j].regime.label for j in range(n2)] for i in range(n1)]
    return v1, v2, labels


def write_outputs(res: ContinuationResult, directory: Path, fmt: str = "nc") -> dict[str, Any]:
    """Branch files (netCDF or zarr), CSV tables, figures and ``summary.json`` into
    ``directory`` (which the caller makes whole or absent)."""
    import pandas as pd

    from braidsim.continuation.plots import plot_branches, plot_operating_map
    from braidsim.plotting import save

    files = []
    for i, b in enumerate(res.branches):
        ds = branch_dataset(b, res.spec.scenario.name)
        p = write_branch(ds, directory / f"branch_{i}.{fmt}")
        files.append(p.name)
    if res.cross_branch is not None:
        ds = branch_dataset(res.cross_branch, res.spec.scenario.name)
        files.append(write_branch(ds, directory / f"branch_cross.{fmt}").name)
    tab = pd.concat([branch_points_table(b).assign(branch=i) for i, b in enumerate(res.branches)])
    tab.to_csv(directory / "points.csv", index=False)
    sp_rows = [{"branch": i, **s.to_dict()} for i, b in enumerate(res.branches) for s in b.special]
    pd.DataFrame(sp_rows, columns=["branch", "type", "value", "period", "detail"]).to_csv(
        directory / "special_points.csv", index=False
    )
    files += ["points.csv", "special_points.csv"]
    fig = plot_branches(
        res.branches, title=f"{res.spec.scenario.name}: continuation in {res.spec.parameter}"
    )
    save(fig, directory / "bifurcation.png")
    files.append("bifurcation.png")
    if res.curves or res.regimes is not None:
        rows = [
            {"curve": i, "type": c.type, "name": c.name, "period": c.period, c.key1: a, c.key2: b}
            for i, c in enumerate(res.curves)
            for a, b in zip(c.p1, c.p2, strict=True)
        ]
        pd.DataFrame(rows).to_csv(directory / "boundaries.csv", index=False)
        keys = (res.spec.parameter, res.spec.map_parameter or "")
        fig = plot_operating_map(res.curves, regimes=res.regimes, keys=keys)
        save(fig, directory / "operating_map.png")
        files += ["boundaries.csv", "operating_map.png"]
    from braidsim.provenance import version

    # (the same object as `braidsim continue --json` prints, which starts with the version)
    data = {"braidsim_version": version(), **res.to_json()}
    data["files"] = sorted(files)
    (directory / "summary.json").write_text(
        json.dumps(json_safe(data), allow_nan=False), encoding="utf-8"
    )
    return data
