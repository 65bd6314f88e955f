"""The whole design study of a spec: baseline, proxy check, the drive model, the robust
optimised profile, before/after on the full machine (both contact pairs, the drive's torque
and power), the improvement distribution over held-out tolerance samples, the levers
compared on the same samples, sensitivity of the other levers, speed limits.

:func:`run_design` does the computing and returns a :class:`DesignResult`;
:func:`braidsim.design.report.write_report` turns it into files.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from braidsim.design.drive import DriveModel
from braidsim.design.evaluate import (
    CarrierClass,
    Evaluation,
    Fidelity,
    carrier_classes,
    evaluate,
    proxy_fidelity,
)
from braidsim.design.optimise import OptimizationResult, optimise_profile, reductions
from braidsim.design.profiles import SpeedProfile, feasible, limit_margins
from braidsim.design.robust import (
    Improvement,
    LeverResult,
    compare_levers,
    default_moves,
    improvement,
    robust_sets,
)
from braidsim.design.sensitivity import (
    Lever,
    MorrisResult,
    OneAtATime,
    morris,
    one_at_a_time,
    run_tasks,
)
from braidsim.design.spec import DesignSpec
from braidsim.design.speed_limits import (
    SpeedLimit,
    SpeedLimitOptions,
    chatter_speed,
    transfer_speed_estimate,
    transfer_speed_limit,
)
from braidsim.errors import InputError


def random_profiles(spec: DesignSpec, n: int, seed: int, tries: int = 20000) -> list[SpeedProfile]:
    """``n`` profiles drawn uniformly in the family's bounds that satisfy the limits (by
    rejection, seeded), for the proxy check."""
    fam = spec.family
    b = np.array(fam.bounds(spec.limits))
    rng = np.random.default_rng(seed)
    out: list[SpeedProfile] = []
    m = spec.machine
    for _ in range(tries):
        if len(out) >= n:
            break
        x = b[:, 0] + rng.random(b.shape[0]) * (b[:, 1] - b[:, 0])
        pr = fam.profile(x)
        if feasible(limit_margins(pr, spec.limits, m.mean_speed, m.cycle_time)):
            out.append(pr)
    return out


@dataclass(frozen=True)
class SpeedLimitTask:
    """One lever setting's transfer speed limit (plain data, picklable for a pool)."""

    base: dict[str, Any]
    path: Path | None
    overrides: dict[str, float]
    threshold: float
    metric: str
    options: SpeedLimitOptions
    nominal_speed: float
    cycles: float

    def __call__(self) -> SpeedLimit:
        return transfer_speed_limit(
            self.base,
            self.path,
            self.threshold,
            self.metric,
            self.overrides,
            None,
            self.options,
            nominal_speed=self.nominal_speed,
            cycles=self.cycles,
        )


@dataclass
class LeverLimits:
    """Speed limits of one lever at each of its values.

    Attributes
    ----------
    lever : Lever
    values : list of float
        SI values of the lever.
    limits : list of SpeedLimit
        Simulated transfer limits.
    estimates : list of float
        Closed-form first-impact limits [rad/s] (NaN unless the metric is the peak force).
    chatter : list of float
        Chatter speeds [rad/s].
    curve : dict
        The closed forms on a fine grid of the lever's range: ``values``, ``estimate`` and
        ``chatter`` [SI, rad/s].
    """

    lever: Lever
    values: list[float]
    limits: list[SpeedLimit]
    estimates: list[float]
    chatter: list[float]
    curve: dict[str, list[float]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            **self.lever.to_dict(),
            "values": self.values,
            "transfer_limit": [lim.to_dict() for lim in self.limits],
            "closed_form_estimate": self.estimates,
            "chatter_speed": self.chatter,
            "closed_form_curves": self.curve,
        }


@dataclass
class DesignResult:
    """Everything the report shows.

    Attributes
    ----------
    spec : DesignSpec
    baseline_proxy : dict
        Proxy metrics at constant speed.
    fidelity : Fidelity or None
        Proxy against full run on random feasible profiles.
    optimisation : OptimizationResult
    before, after : Evaluation
        Full machine runs (every carrier, the machine spec's duration) at constant speed and
        with the optimised profile.
    reductions : dict
        1 - after/before per objective.
    production : dict
        Mean speed and transfer rate measured before and after.
    oat : list of OneAtATime
        One-at-a-time studies (constant, optimised).
    morris : MorrisResult or None
    speed_limits : list of LeverLimits
    nominal_speed_limit : SpeedLimit or None
        The transfer limit at the nominal setting.
    threshold : float
        The speed-limit threshold used.
    timings : dict
        Wall time of each stage [s].
    classes : list of CarrierClass
        Identical carriers over the proxy's length (one of each is run).
    drive : DriveModel or None
    drive_before, drive_after : dict
        :meth:`DriveModel.figures` at constant speed and with the optimised profile.
    robust : Improvement or None
        The improvement distribution over the held-out sets.
    check_samples : list of dict
        The held-out parameter sets.
    check_before, check_after : list of dict
        Their metrics at constant speed and with the profile.
    levers : list of LeverResult
        The levers compared on the held-out sets, best per effort first.
    """

    spec: DesignSpec
    baseline_proxy: dict[str, float]
    fidelity: Fidelity | None
    optimisation: OptimizationResult
    before: Evaluation
    after: Evaluation
    reductions: dict[str, float]
    production: dict[str, float]
    oat: list[OneAtATime] = field(default_factory=list)
    morris: MorrisResult | None = None
    speed_limits: list[LeverLimits] = field(default_factory=list)
    nominal_speed_limit: SpeedLimit | None = None
    threshold: float = math.nan
    timings: dict[str, float] = field(default_factory=dict)
    classes: list[CarrierClass] = field(default_factory=list)
    drive: DriveModel | None = None
    drive_before: dict[str, float] = field(default_factory=dict)
    drive_after: dict[str, float] = field(default_factory=dict)
    robust: Improvement | None = None
    check_samples: list[dict[str, float]] = field(default_factory=list)
    check_before: list[dict[str, float]] = field(default_factory=list)
    check_after: list[dict[str, float]] = field(default_factory=list)
    levers: list[LeverResult] = field(default_factory=list)


def _production(ev: Evaluation) -> dict[str, float]:
    run = ev.run
    if run is None:
        return {"mean_speed": math.nan, "transfers_per_second": math.nan}
    T = run.duration
    _, ang = run.speed.rotation([T])
    # a transfer due exactly at the end of the run can come out of the inversion of
    # Omega(t) some 1e-15 s early and be listed; it is not part of the run
    n = int((run.transfers["t"] < T * (1.0 - 1e-12)).sum()) if len(run.transfers) else 0
    return {
        "mean_speed": float(ang[0] / T),
        "mean_speed_rpm": float(ang[0] / T * 30.0 / math.pi),
        "transfers_per_second": n / T,
    }


def run_design(
    spec: DesignSpec,
    progress: Callable[[str], None] | None = None,
    full_workers: int | None = None,
) -> DesignResult:
    """Run the whole study (module docstring).

    Parameters
    ----------
    spec : DesignSpec
    progress : callable, optional
        Receives one line per stage.
    full_workers : int, optional
        Processes for the two full machine runs (default: the spec's workers).
    """
    if not isinstance(spec, DesignSpec):
        raise InputError(
            f"spec: {spec!r} is not a DesignSpec; allowed what load_design_spec(path) or "
            "parse_design_spec(table) returns"
        )
    say = progress or (lambda _s: None)
    base, mpath = spec.machine_table, spec.machine_path
    cycles = spec.optimizer.cycles
    W = spec.workers
    timings: dict[str, float] = {}

    t = time.perf_counter()
    # the study compares everything with these runs: if one fails there is nothing to report
    baseline = (
        evaluate(base, mpath, None, cycles=cycles)
        .required(
            f"the constant-speed run of the machine over {cycles:g} transfer cycles "
            "(design.optimizer.cycles)"
        )
        .metrics
    )
    fid = None
    if spec.proxy_profiles > 0:
        profs = random_profiles(spec, spec.proxy_profiles, spec.proxy_seed)
        say(f"proxy check: {len(profs)} random profiles, proxy and full runs")
        fid = proxy_fidelity(base, mpath, profs, cycles, workers=1)
    timings["proxy_check"] = time.perf_counter() - t

    m = spec.machine
    drag = (baseline["dissipated_power"] + baseline["friction_power"]) / m.mean_speed
    drive = DriveModel.build(
        spec.drive,
        m.geometry.N,
        m.geometry.pitch_radius,
        len(m.loading.carriers),
        float(m.scenario["carrier.mass"]),
        float(m.scenario["carrier.turning_radius"]),
        m.mean_speed,
        m.cycle_time,
        drag,
    )
    R = spec.robust
    opt_sets, check = robust_sets(m.scenario, R)
    say(
        f"optimising ({spec.family.name}, {spec.objective} of {spec.pair}, {R.statistic} over "
        f"{len(opt_sets) or 1} parameter sets, maxiter {spec.optimizer.maxiter}, "
        f"popsize {spec.optimizer.popsize}, seed {spec.optimizer.seed})"
    )
    t = time.perf_counter()
    opt = optimise_profile(
        base,
        mpath,
        spec.family,
        spec.limits,
        spec.objective,
        spec.optimizer,
        progress=lambda row: say(
            f"  generation {int(row['generation'])}: best {row['best']:.6g} "
            f"({int(row['evaluations'])} candidates, {row['elapsed_s']:.0f} s)"
        ),
        pair=spec.pair,
        drive=drive,
        samples=opt_sets,
        statistic=R.statistic,
        quantile=R.quantile,
    )
    timings["optimisation"] = time.perf_counter() - t

    say("full machine runs: constant speed and optimised profile")
    t = time.perf_counter()
    fw = W if full_workers is None else full_workers
    before = evaluate(base, mpath, None, full=True, workers=fw).required(
        "the full run of the machine at constant speed"
    )
    after = evaluate(base, mpath, opt.profile, full=True, workers=fw).required(
        "the full run of the machine with the optimised profile"
    )
    timings["full_runs"] = time.perf_counter() - t
    red = reductions(before.metrics, after.metrics)
    prod = {f"before_{k}": v for k, v in _production(before).items()}
    prod.update({f"after_{k}": v for k, v in _production(after).items()})

    result = DesignResult(spec, baseline, fid, opt, before, after, red, prod, timings=timings)
    result.classes = carrier_classes(spec.machine, cycles * spec.machine.cycle_time)
    result.drive = drive
    result.drive_before = drive.figures(None)
    result.drive_after = drive.figures(opt.profile)

    t = time.perf_counter()
    say(
        f"robustness: {len(check)} held-out parameter sets, {R.check_cycles:g} cycles, "
        "constant speed and optimised profile"
    )
    imp, cb, ca = improvement(
        base, mpath, check, spec.objective, spec.pair, R.check_cycles, opt.profile
    )
    result.robust, result.check_samples = imp, check
    result.check_before, result.check_after = cb, ca
    timings["robustness"] = time.perf_counter() - t
    if spec.levers:
        t = time.perf_counter()
        moves = [
            replace(mv, effort=spec.efforts.get(mv.name, mv.effort))
            for mv in default_moves(m.scenario)
        ]
        say(f"levers: {len(moves) - 1} changes of the machine on the same sets")
        result.levers = compare_levers(
            base,
            mpath,
            moves,
            check,
            spec.objective,
            spec.pair,
            R.check_cycles,
            opt.profile,
            cb,
            imp,
        )
        timings["levers"] = time.perf_counter() - t

    sens = spec.sensitivity
    if sens.enabled:
        t = time.perf_counter()
        levers = list(sens.levers)
        say(f"sensitivity: one at a time, {len(levers)} levers")
        result.oat.append(
            one_at_a_time(base, mpath, levers, sens.levels, cycles, None, "constant", W)
        )
        if sens.optimised and not opt.profile.is_constant:
            result.oat.append(
                one_at_a_time(base, mpath, levers, sens.levels, cycles, opt.profile, "optimised", W)
            )
        say(f"sensitivity: Morris, {sens.trajectories} trajectories (seed {sens.seed})")
        result.morris = morris(
            base,
            mpath,
            levers,
            spec.figure,
            sens.trajectories,
            sens.morris_levels,
            sens.seed,
            cycles,
            None,
            W,
        )
        timings["sensitivity"] = time.perf_counter() - t

    sl = spec.speed_limit
    if sl.enabled:
        t = time.perf_counter()
        thr = sl.threshold if sl.threshold is not None else baseline[sl.metric]
        result.threshold = thr
        levers = list(sens.levers)
        values = {lv.key: _oat_values(result.oat, lv) for lv in levers}

        def task(over: dict[str, float]) -> SpeedLimitTask:
            return SpeedLimitTask(
                dict(base), mpath, over, thr, sl.metric, sl.options, spec.machine.mean_speed, cycles
            )

        tasks = [task({})]
        for lv in levers:
            tasks += [task({lv.key: v}) for v in values[lv.key]]
        say(f"speed limits: {len(tasks)} settings")
        lims = run_tasks(tasks, W)
        result.nominal_speed_limit = lims[0]
        i = 1
        for lv in levers:
            n = len(values[lv.key])
            chat, est = _closed_forms(spec, lv.key, values[lv.key], thr)
            grid = np.linspace(lv.low, lv.high, 25).tolist()
            gc, ge = _closed_forms(spec, lv.key, grid, thr)
            result.speed_limits.append(
                LeverLimits(
                    lv,
                    values[lv.key],
                    list(lims[i : i + n]),
                    est,
                    chat,
                    {"values": grid, "estimate": ge, "chatter": gc},
                )
            )
            i += n
        timings["speed_limits"] = time.perf_counter() - t
    return result


def _closed_forms(
    spec: DesignSpec, key: str, values: list[float], threshold: float
) -> tuple[list[float], list[float]]:
    """Chatter speeds and closed-form transfer limits [rad/s] of ``key`` at ``values`` (the
    latter NaN unless the speed-limit metric is the peak force)."""
    chat, est = [], []
    for v in values:
        sc = spec.machine.scenario.with_overrides({key: v})
        chat.append(chatter_speed(sc))
        peak = spec.speed_limit.metric == "peak_force"
        est.append(transfer_speed_estimate(sc, threshold) if peak else math.nan)
    return chat, est


def _oat_values(oat: list[OneAtATime], lever: Lever) -> list[float]:
    from braidsim.design.sensitivity import lever_values

    for o in oat:
        if lever.key in o.values:
            return list(o.values[lever.key])
    return lever_values(lever, 3)


__all__ = [
    "DesignResult",
    "LeverLimits",
    "SpeedLimitOptions",
    "random_profiles",
    "run_design",
]
