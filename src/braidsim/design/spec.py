"""The design specification: a TOML file read and validated whole before any run.

A design spec names a machine (a machine spec file, or the machine spec's own tables inline)
and says what to study. Every quantity is a number in SI or a string with units::

    name = "16-carrier braider: slow down for the transfers"   # optional
    description = "..."                                          # optional
    machine_spec = "machine16.toml"    # a machine spec (relative to this file); or put the
                                       # machine spec's keys here (scenario, overrides,
                                       # [machine], duration/revolutions, [braid])

    [design]
    objective = "score"                # score | peak_force | impact_energy | impacts | noise
    pair = "both"                      # both | track | slot
    workers = 1                        # processes, 0: all cores (the results do not depend on it)

    [design.profile]                   # the speed-profile family (braidsim.design.profiles)
    family = "dip"                     # dip | fourier | dip+fourier
    harmonics = 2                      # K, for fourier and dip+fourier
    ramp_nodes = 32                    # table segments per ramp
    amplitude = 0.5                    # |a_k|, |b_k| <= amplitude / k

    [design.limits]                    # motion limits of the horn-gear drive
    min_speed = 0.25                   # fraction of the mean speed
    max_speed = 2.0                    # fraction of the mean speed
    max_acceleration = "1000 rad/s^2"
    max_jerk = "2e5 rad/s^3"

    [design.drive]                     # braidsim.design.drive (defaults stated there)
    gear_inertia = "0.0096 kg m^2"     # per horn gear; default: steel disc estimate
    motor_inertia = "2e-4 kg m^2"
    gear_ratio = 10
    max_torque = "150 N m"             # on the horn-gear speed
    max_rms_torque = "48 N m"
    max_power = "3 kW"
    tensioner_mass = "50 g"
    drag_torque = "1.94 N m"           # default: measured, (dissipated + friction power)
                                       # / mean speed of the constant-speed proxy run (this
                                       # value for examples/design16.toml)

    [design.robust]                    # braidsim.design.robust
    samples = 8                        # parameter sets of the objective (0: nominal only)
    check_samples = 32                 # held-out sets of the improvement distribution
    statistic = "mean"                 # mean | quantile
    quantile = 0.9
    seed = 1
    check_cycles = 32
    check_seed = 2                     # of the held-out sets (default seed + 1): another
                                       # draw checks the same optimum on other sets
    [design.robust.tolerances]         # key = [low, high] factors on the nominal value
    "track.clearance" = [0.8, 1.3]     # (absolute values for track.vibration_phase); not a
                                       # key the machine sets (machine.speed, the pitch
                                       # radius, initial.* at rest), and every drawn set
                                       # must be a machine the machine spec accepts

    [design.levers]                    # compare the paper's levers on the held-out sets
    enabled = true
    [design.levers.effort]             # assumed effort, 1 (a setting) to 5 (a redesign);
                                       # allowed > 0 and <= 100
    profile = 2

    [design.optimizer]                 # scipy.optimize.differential_evolution
    maxiter = 20
    popsize = 8
    seed = 1
    cycles = 16                        # proxy length in transfer cycles

    [design.proxy_check]               # compare proxy and full run on random profiles
    profiles = 4                       # 0: skip
    seed = 1

    [design.sensitivity]
    enabled = true
    levers = ["track.clearance", "contact.track.restitution", "track.vibration_amplitude",
              "track.vibration_frequency", "carrier.mass", "yarn.tension_horizontal"]
    span = 0.5                         # default range nominal * (1 -+ span)
    levels = 3                         # one-at-a-time values per lever (plus the nominal)
    trajectories = 4                   # Morris trajectories
    morris_levels = 4                  # Morris grid levels p
    seed = 1
    optimised = true                   # one-at-a-time also with the optimised profile
    [design.sensitivity.ranges]
    "track.clearance" = ["2 mm", "4 mm"]

    [design.speed_limit]
    enabled = true
    metric = "peak_force"              # default: the objective
    threshold = "3.7 kN"               # default: the metric at the nominal setting and speed
    speeds = [0.25, 2.0]               # scanned range, fractions of the mean speed
    points = 8
    refine = 5

Unknown keys and bad values stop with one line naming the entry and what is allowed.

Every run of the study uses the two-DOF carrier model (``simulation.dof = "xy"`` is set on
the machine whatever its scenario says): a speed profile acts on the carriers through the
slot walls, so the slot contact belongs in every figure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from braidsim.batch import local_processes
from braidsim.design.drive import Drive
from braidsim.design.evaluate import OBJECTIVES, check_objective, check_pair, machine_for
from braidsim.design.optimise import OptimizerOptions
from braidsim.design.profiles import Limits, ProfileFamily
from braidsim.design.robust import RobustOptions, Tolerance, check_tolerances, robust_sets
from braidsim.design.sensitivity import DEFAULT_LEVERS, Lever, make_levers
from braidsim.design.speed_limits import SpeedLimitOptions
from braidsim.errors import InputError
from braidsim.machine.spec import TOP_KEYS as MACHINE_TOP_KEYS
from braidsim.machine.spec import MachineSpec, machine_entry
from braidsim.params import SCHEMA
from braidsim.specfile import check_keys, expect_table, parse_toml, read_text, read_toml_file
from braidsim.units import to_si

TOP_KEYS = ("name", "description", "machine_spec", "design", *MACHINE_TOP_KEYS)
DESIGN_KEYS = (
    "objective",
    "pair",
    "workers",
    "drive",
    "robust",
    "levers",
    "profile",
    "limits",
    "optimizer",
    "proxy_check",
    "sensitivity",
    "speed_limit",
)
PROFILE_KEYS = ("family", "harmonics", "ramp_nodes", "amplitude")
LIMIT_KEYS = ("min_speed", "max_speed", "max_acceleration", "max_jerk")
OPTIMIZER_KEYS = ("maxiter", "popsize", "seed", "tol", "mutation", "recombination", "cycles")
PROXY_KEYS = ("profiles", "seed")
SENSITIVITY_KEYS = (
    "enabled",
    "levers",
    "span",
    "levels",
    "trajectories",
    "morris_levels",
    "seed",
    "optimised",
    "ranges",
)
DRIVE_KEYS = {
    "gear_inertia": "kg*m**2",
    "motor_inertia": "kg*m**2",
    "gear_ratio": "",
    "max_torque": "N*m",
    "max_rms_torque": "N*m",
    "max_power": "W",
    "tensioner_mass": "kg",
    "drag_torque": "N*m",
}
ROBUST_KEYS = (
    "samples",
    "check_samples",
    "statistic",
    "quantile",
    "seed",
    "check_cycles",
    "check_seed",
    "tolerances",
)
LEVER_KEYS = ("enabled", "effort")
LEVER_NAMES = ("profile", "restitution", "vibration", "clearance")
SPEED_KEYS = ("enabled", "metric", "threshold", "speeds", "points", "refine")
METRIC_UNITS = {
    "peak_force": "N",
    "mean_peak_force": "N",
    "impact_energy": "W",
    "impacts": "1/s",
    "noise": "N**2/s",
}


def _int(where: str, value: Any, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise InputError(
            f"{where}: {value!r} is not allowed; allowed an integer from {low} to {high}"
        )
    return int(value)


def _float(where: str, value: Any, unit: str = "") -> float:
    v = to_si(where, value, unit)
    if not math.isfinite(v):
        raise InputError(f"{where}: {v!r} is not finite")
    return v


def _bool(where: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise InputError(f"{where}: {value!r} is not allowed; allowed true or false")
    return value


@dataclass(frozen=True)
class SensitivityOptions:
    """What the sensitivity study runs (see :mod:`braidsim.design.sensitivity`)."""

    enabled: bool = True
    levers: tuple[Lever, ...] = ()
    levels: int = 3
    trajectories: int = 4
    morris_levels: int = 4
    seed: int = 1
    optimised: bool = True

    def to_dict(self) -> dict[str, Any]:
        return {
            "enabled": self.enabled,
            "levers": [lv.to_dict() for lv in self.levers],
            "levels": self.levels,
            "trajectories": self.trajectories,
            "morris_levels": self.morris_levels,
            "seed": self.seed,
            "optimised": self.optimised,
        }


@dataclass(frozen=True)
class SpeedLimitSettings:
    """The speed-limit study (see :mod:`braidsim.design.speed_limits`)."""

    enabled: bool = True
    metric: str = "peak_force"
    threshold: float | None = None
    options: SpeedLimitOptions = field(default_factory=SpeedLimitOptions)

    def to_dict(self) -> dict[str, Any]:
        o = self.options
        return {
            "enabled": self.enabled,
            "metric": self.metric,
            "threshold": self.threshold,
            "speeds": [o.low, o.high],
            "points": o.points,
            "refine": o.refine,
        }


@dataclass(frozen=True)
class DesignSpec:
    """A validated design spec.

    Attributes
    ----------
    name, description : str
    path : Path or None
        The design spec file.
    machine_table : dict
        The machine spec table (validated by :func:`braidsim.machine.parse_machine_spec`).
    machine_path : Path or None
        The file the machine table comes from (relative scenario paths).
    machine : MachineSpec
        The nominal machine at constant speed.
    objective, pair : str
    workers : int
    family : ProfileFamily
    limits : Limits
    optimizer : OptimizerOptions
    proxy_profiles, proxy_seed : int
        Random profiles for the proxy check and their seed.
    sensitivity : SensitivityOptions
    speed_limit : SpeedLimitSettings
    pair : str
    drive : Drive
    robust : RobustOptions
    levers : bool
        Compare the levers (:func:`braidsim.design.robust.compare_levers`).
    efforts : dict
        Lever name -> assumed effort (overrides the defaults).
    """

    name: str
    description: str
    path: Path | None
    machine_table: dict[str, Any]
    machine_path: Path | None
    machine: MachineSpec
    objective: str
    workers: int
    family: ProfileFamily
    limits: Limits
    optimizer: OptimizerOptions
    proxy_profiles: int
    proxy_seed: int
    sensitivity: SensitivityOptions
    speed_limit: SpeedLimitSettings
    pair: str = "both"
    drive: Drive = field(default_factory=Drive)
    robust: RobustOptions = field(default_factory=RobustOptions)
    levers: bool = True
    efforts: dict[str, float] = field(default_factory=dict)

    @property
    def figure(self) -> str:
        """The figure the sensitivity and speed-limit studies use: the objective's, or the
        combined peak force for ``score``."""
        return "peak_force" if self.objective == "score" else self.objective

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "description": self.description,
            "spec": str(self.path) if self.path else None,
            "machine_spec": str(self.machine_path) if self.machine_path else None,
            "objective": self.objective,
            "pair": self.pair,
            "workers": self.workers,
            "drive": self.drive.to_dict(),
            "robust": self.robust.to_dict(),
            "levers": {"enabled": self.levers, "effort": dict(self.efforts)},
            "profile_family": self.family.to_dict(),
            "limits": self.limits.to_dict(),
            "optimizer": self.optimizer.to_dict(),
            "proxy_check": {"profiles": self.proxy_profiles, "seed": self.proxy_seed},
            "sensitivity": self.sensitivity.to_dict(),
            "speed_limit": self.speed_limit.to_dict(),
        }


def _machine_table(
    data: Mapping[str, Any], path: Path | None
) -> tuple[dict[str, Any], Path | None]:
    # name and description belong to the design; the machine's come from its own spec
    inline = {
        k: v for k, v in data.items() if k in MACHINE_TOP_KEYS and k not in ("name", "description")
    }
    ref = data.get("machine_spec")
    if ref is None:
        if "machine" not in inline:
            raise InputError(
                "machine_spec: missing; allowed a machine spec file, or the machine spec's "
                "tables ([machine], scenario, ...) in this file"
            )
        return dict(inline), path
    if not isinstance(ref, str):
        raise InputError(f"machine_spec: {ref!r} is not a path")
    if inline:
        key = next(iter(inline))
        raise InputError(
            f"{key}: given together with machine_spec; allowed one of them (edit the machine "
            "spec, or put all of its keys here)"
        )
    mp = Path(ref)
    if not mp.is_absolute() and path is not None:
        mp = path.parent / mp
    if not mp.is_file():
        raise InputError(f"machine_spec: {str(mp)!r} is not a file; allowed a machine spec TOML")
    # the spec readers' checks: UTF-8, nesting depth, numbers a float can hold
    table = parse_toml(read_text(mp, "machine_spec"), f"machine_spec: {mp}")
    return table, mp


def parse_design_spec(data: Mapping[str, Any], path: Path | None = None) -> DesignSpec:
    """Validate a design spec table (already read from TOML); see the module docstring.

    Raises
    ------
    InputError
        The first problem found, naming the entry and what is allowed.
    """
    check_keys("", data, TOP_KEYS)
    name = str(data.get("name", path.stem if path else "design"))
    description = str(data.get("description", ""))
    table, mpath = _machine_table(data, path)
    mt = expect_table("machine", table.get("machine", {}))
    if "speed_profile" in mt:
        raise InputError(
            "machine.speed_profile: set by the design study (the baseline is constant speed); "
            "allowed: leave it out of the machine spec"
        )
    machine = machine_for(table, mpath)
    if machine.scenario["horn_gear.speed_harmonics"]:
        raise InputError(
            "horn_gear.speed_harmonics: the design's baseline is constant speed; allowed: "
            "leave it out of the scenario and its overrides"
        )

    d = expect_table("design", data.get("design", {}))
    check_keys("design.", d, DESIGN_KEYS)
    objective = check_objective(str(d.get("objective", "score")))
    pair = check_pair(str(d.get("pair", "both")))
    # 0: all cores, as for the other commands with local workers (at most the optimiser's 256)
    workers = min(local_processes(_int("design.workers", d.get("workers", 1), 0, 256)), 256)

    p = expect_table("design.profile", d.get("profile", {}))
    check_keys("design.profile.", p, PROFILE_KEYS)
    fam_name = p.get("family", "dip")
    if not isinstance(fam_name, str):
        raise InputError(f"design.profile.family: {fam_name!r}; allowed dip, fourier, dip+fourier")
    harmonics = _int(
        "design.profile.harmonics", p.get("harmonics", 0 if fam_name == "dip" else 2), 0, 12
    )
    family = ProfileFamily(
        fam_name,
        harmonics,
        _int("design.profile.ramp_nodes", p.get("ramp_nodes", 32), 2, 256),
        _float("design.profile.amplitude", p.get("amplitude", 0.5)),
    )

    lt = expect_table("design.limits", d.get("limits", {}))
    check_keys("design.limits.", lt, LIMIT_KEYS)
    dflt = Limits()
    limits = Limits(
        _float("design.limits.min_speed", lt.get("min_speed", dflt.min_speed)),
        _float("design.limits.max_speed", lt.get("max_speed", dflt.max_speed)),
        _float(
            "design.limits.max_acceleration",
            lt.get("max_acceleration", dflt.max_acceleration),
            "rad/s**2",
        ),
        _float("design.limits.max_jerk", lt.get("max_jerk", dflt.max_jerk), "rad/s**3"),
    )

    o = expect_table("design.optimizer", d.get("optimizer", {}))
    check_keys("design.optimizer.", o, OPTIMIZER_KEYS)
    od = OptimizerOptions()
    mut = o.get("mutation", list(od.mutation))
    if isinstance(mut, int | float) and not isinstance(mut, bool):
        mut = [mut, mut]
    if not isinstance(mut, list) or len(mut) != 2:
        raise InputError(f"design.optimizer.mutation: {mut!r}; allowed [low, high] or a number")
    optimizer = OptimizerOptions(
        maxiter=o.get("maxiter", od.maxiter),
        popsize=o.get("popsize", od.popsize),
        seed=o.get("seed", od.seed),
        tol=_float("design.optimizer.tol", o.get("tol", od.tol)),
        mutation=(
            _float("design.optimizer.mutation", mut[0]),
            _float("design.optimizer.mutation", mut[1]),
        ),
        recombination=_float(
            "design.optimizer.recombination", o.get("recombination", od.recombination)
        ),
        cycles=_float("design.optimizer.cycles", o.get("cycles", od.cycles)),
        workers=workers,
    )

    pc = expect_table("design.proxy_check", d.get("proxy_check", {}))
    check_keys("design.proxy_check.", pc, PROXY_KEYS)
    proxy_profiles = _int("design.proxy_check.profiles", pc.get("profiles", 4), 0, 1000)
    proxy_seed = _int("design.proxy_check.seed", pc.get("seed", 1), 0, 2**31 - 1)

    s = expect_table("design.sensitivity", d.get("sensitivity", {}))
    check_keys("design.sensitivity.", s, SENSITIVITY_KEYS)
    keys = s.get("levers", list(DEFAULT_LEVERS))
    if not isinstance(keys, list) or not all(isinstance(k, str) for k in keys) or not keys:
        raise InputError(
            f"design.sensitivity.levers: {keys!r}; allowed a non-empty list of scenario keys"
        )
    if len(set(keys)) != len(keys):
        raise InputError(f"design.sensitivity.levers: {keys!r} repeats a key; allowed each once")
    ranges = expect_table("design.sensitivity.ranges", s.get("ranges", {}))
    levers = make_levers(
        machine.scenario, keys, _float("design.sensitivity.span", s.get("span", 0.5)), ranges
    )
    sensitivity = SensitivityOptions(
        _bool("design.sensitivity.enabled", s.get("enabled", True)),
        tuple(levers),
        _int("design.sensitivity.levels", s.get("levels", 3), 2, 50),
        _int("design.sensitivity.trajectories", s.get("trajectories", 4), 1, 1000),
        _int("design.sensitivity.morris_levels", s.get("morris_levels", 4), 2, 20),
        _int("design.sensitivity.seed", s.get("seed", 1), 0, 2**31 - 1),
        _bool("design.sensitivity.optimised", s.get("optimised", True)),
    )

    sl = expect_table("design.speed_limit", d.get("speed_limit", {}))
    check_keys("design.speed_limit.", sl, SPEED_KEYS)
    metric = str(sl.get("metric", "peak_force" if objective == "score" else objective))
    if metric not in METRIC_UNITS:
        raise InputError(
            f"design.speed_limit.metric: {metric!r} is not allowed; allowed "
            + ", ".join(METRIC_UNITS)
        )
    threshold = None
    if "threshold" in sl:
        threshold = _float("design.speed_limit.threshold", sl["threshold"], METRIC_UNITS[metric])
        if not threshold > 0.0:
            raise InputError(
                f"design.speed_limit.threshold: {threshold:g} is out of range; allowed > 0 "
                f"{METRIC_UNITS[metric]}"
            )
    speeds = sl.get("speeds", [0.25, 2.0])
    if not isinstance(speeds, list) or len(speeds) != 2:
        raise InputError(
            f"design.speed_limit.speeds: {speeds!r}; allowed [low, high] (fractions of the mean)"
        )
    speed_limit = SpeedLimitSettings(
        _bool("design.speed_limit.enabled", sl.get("enabled", True)),
        metric,
        threshold,
        SpeedLimitOptions(
            _float("design.speed_limit.speeds", speeds[0]),
            _float("design.speed_limit.speeds", speeds[1]),
            _int("design.speed_limit.points", sl.get("points", 8), 2, 200),
            _int("design.speed_limit.refine", sl.get("refine", 5), 0, 30),
        ),
    )
    _check_runs(table, mpath, machine, sensitivity, speed_limit)
    drive = _drive(d.get("drive", {}))
    robust = _robust(d.get("robust", {}), machine.scenario)
    _check_optimisation(family, limits, optimizer, robust)
    _check_tolerances(table, mpath, machine, robust)
    lv = expect_table("design.levers", d.get("levers", {}))
    check_keys("design.levers.", lv, LEVER_KEYS)
    ef = expect_table("design.levers.effort", lv.get("effort", {}))
    check_keys("design.levers.effort.", ef, LEVER_NAMES)
    efforts = {}
    for k, v in ef.items():
        e = _float(f"design.levers.effort.{k}", v)
        if not 0.0 < e <= 100.0:
            raise InputError(
                f"design.levers.effort.{k}: {e:g} is out of range; allowed > 0 and <= 100"
            )
        efforts[k] = e
    return DesignSpec(
        name,
        description,
        path,
        table,
        mpath,
        machine,
        objective,
        workers,
        family,
        limits,
        optimizer,
        proxy_profiles,
        proxy_seed,
        sensitivity,
        speed_limit,
        pair,
        drive,
        robust,
        _bool("design.levers.enabled", lv.get("enabled", True)),
        efforts,
    )


def _drive(table: Any) -> Drive:
    dt = expect_table("design.drive", table)
    check_keys("design.drive.", dt, tuple(DRIVE_KEYS))
    kw: dict[str, Any] = {}
    for k, unit in DRIVE_KEYS.items():
        if k in dt:
            kw[k] = _float(f"design.drive.{k}", dt[k], unit)
    return Drive(**kw)


def _robust(table: Any, sc: Any) -> RobustOptions:
    rt = expect_table("design.robust", table)
    check_keys("design.robust.", rt, ROBUST_KEYS)
    dflt = RobustOptions()
    tols = list(dflt.tolerances)
    if "tolerances" in rt:
        tt = expect_table("design.robust.tolerances", rt["tolerances"])
        given: dict[str, Tolerance] = {}
        for k, v in tt.items():
            if not isinstance(v, list) or len(v) != 2:
                raise InputError(
                    f"design.robust.tolerances.{k}: {v!r}; allowed [low, high] (factors on the "
                    "nominal value; absolute values for track.vibration_phase)"
                )
            rel = k != "track.vibration_phase"
            lo = _float(f"design.robust.tolerances.{k}", v[0])
            hi = _float(f"design.robust.tolerances.{k}", v[1])
            given[k] = Tolerance(k, lo, hi, rel)
        tols = [given.pop(t.key, t) for t in tols] + list(given.values())
    check_tolerances(sc, tols)
    stat = rt.get("statistic", dflt.statistic)
    if not isinstance(stat, str):
        raise InputError(f"design.robust.statistic: {stat!r}; allowed mean, quantile")
    return RobustOptions(
        tuple(tols),
        _int("design.robust.samples", rt.get("samples", dflt.samples), 0, 10000),
        _int("design.robust.check_samples", rt.get("check_samples", dflt.check_samples), 1, 10000),
        stat,
        _float("design.robust.quantile", rt.get("quantile", dflt.quantile)),
        _int("design.robust.seed", rt.get("seed", dflt.seed), 0, 2**31 - 2),
        _float("design.robust.check_cycles", rt.get("check_cycles", dflt.check_cycles)),
        None
        if rt.get("check_seed") is None
        else _int("design.robust.check_seed", rt["check_seed"], 0, 2**31 - 1),
    )


def _check_runs(
    table: dict[str, Any],
    path: Path | None,
    machine: MachineSpec,
    sensitivity: SensitivityOptions,
    speed_limit: SpeedLimitSettings,
) -> None:
    """Build (without running) every kind of machine the study will run, so that a setting the
    machine rejects stops the study before it starts, not half-way."""
    if sensitivity.enabled or speed_limit.enabled:
        for lv in sensitivity.levers:
            for v in (lv.low, lv.high):
                try:
                    machine_for(table, path, overrides={lv.key: v})
                except InputError as exc:
                    raise InputError(
                        f"design.sensitivity.levers: {lv.key} = {v:g} is not allowed on this "
                        f"machine ({exc})"
                    ) from None
    if speed_limit.enabled:
        w = machine.mean_speed * speed_limit.options.low
        try:
            machine_for(table, path, speed=w)
        except InputError as exc:
            raise InputError(
                f"design.speed_limit: the machine cannot run at {w:g} rad/s ({exc}); allowed: "
                "set the speed with [machine] speed, or enabled = false"
            ) from None


def _check_optimisation(
    family: ProfileFamily, motion: Limits, optimizer: OptimizerOptions, robust: RobustOptions
) -> None:
    """Refuse an optimisation over the runs limit (``BRAIDSIM_MAX_RUNS``) before it starts:
    differential evolution runs at most (maxiter + 1) generations of popsize x (number of
    profile parameters) candidates, each the machine at every parameter set of the
    objective."""
    from braidsim import limits as resources

    dim = len(family.bounds(motion))
    sets = max(1, robust.samples)
    resources.check(
        "runs",
        (optimizer.maxiter + 1) * optimizer.popsize * dim * sets,
        lambda: (
            f"design.optimizer: (maxiter {optimizer.maxiter} + 1) x popsize "
            f"{optimizer.popsize} x {dim} profile parameters x {sets} parameter sets "
            "(design.robust.samples), at most"
        ),
    )


def _check_tolerances(
    table: dict[str, Any], path: Path | None, machine: MachineSpec, robust: RobustOptions
) -> None:
    """Refuse, before the study, a tolerance the machine would refuse half-way: on a key the
    machine sets (its speed, its radius, the rest start), a range whose end the machine
    refuses (a clearance the resting carrier is pressed through), or a drawn parameter set
    it refuses (ends that pass alone but not together)."""
    for t in robust.tolerances:
        where = f"design.robust.tolerances.{t.key}"
        entry = machine_entry(t.key, machine.start)
        if entry is not None:
            raise InputError(
                f"{where}: set by the machine ({entry}), the same for every sample; allowed a "
                "scenario key the machine does not set, e.g. track.clearance"
            )
        rng = f"{'x ' if t.relative else ''}[{t.low:g}, {t.high:g}]"
        for end, v in zip(
            ("low", "high"),
            t.values(float(machine.scenario[t.key]), np.array([0.0, 1.0])),
            strict=True,
        ):
            try:
                machine_for(table, path, overrides={t.key: float(v)})
            except InputError as exc:
                raise InputError(
                    f"{where}: {rng} gives {t.key} = {v:g} {SCHEMA[t.key].unit} at its {end} "
                    f"end, which this machine refuses ({exc}); allowed a range the machine "
                    "accepts at both ends"
                ) from None
    for sets, what in zip(
        robust_sets(machine.scenario, robust), ("samples", "check_samples"), strict=True
    ):
        for i, over in enumerate(sets):
            try:
                machine_for(table, path, overrides=over)
            except InputError as exc:
                drawn = ", ".join(f"{k} = {v:.4g}" for k, v in over.items())
                raise InputError(
                    f"design.robust.tolerances: parameter set {i + 1} of design.robust.{what} "
                    f"({drawn}) is refused by this machine ({exc}); allowed narrower ranges "
                    "(or another design.robust.seed)"
                ) from None


def load_design_spec(path: str | Path) -> DesignSpec:
    """Read and validate a design spec TOML file.

    Raises
    ------
    InputError
        Missing or malformed file, or any problem listed in the module docstring.
    """
    return parse_design_spec(read_toml_file(path, "design spec"), Path(path))


__all__ = ["OBJECTIVES", "DesignSpec", "load_design_spec", "parse_design_spec"]
