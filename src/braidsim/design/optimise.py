"""The speed-profile optimiser: a seeded global search over a profile family, with the
motion limits as constraints and the mean speed held by construction.

Method
------
:func:`scipy.optimize.differential_evolution` (Storn & Price 1997), because the objective is
multimodal: whether a bounce lands while the gears speed up decides between a peak force of
2 kN and one of 4 kN for neighbouring ramp timings, so local methods stall on the first ridge.
Settings that matter:

* constraints (:class:`scipy.optimize.NonlinearConstraint`) are the limit margins of
  :func:`braidsim.design.profiles.limit_margins`, normalised (fractions of the mean speed,
  1 - value/limit for acceleration and jerk); they cost no simulation, and SciPy evaluates
  the objective only for candidates that satisfy them (Lampinen's feasibility rule), so every
  simulated candidate respects the limits;
* the constant profile is put into the first population (``x0``): the result is never worse
  than constant speed on the proxy;
* ``updating="deferred"`` evaluates a whole generation at once, so the candidates, hence the
  result, do not depend on the number of worker processes; ``rng`` = the seed;
* no gradient polish (the objective is piecewise smooth with jumps).

The objective of a candidate is the proxy run (:func:`braidsim.design.evaluate.evaluate`
with ``cycles``), one carrier per class, weighted.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from braidsim.design.drive import DriveModel
from braidsim.design.evaluate import (
    METRIC_KEYS,
    Evaluation,
    check_objective,
    check_pair,
    evaluate,
)
from braidsim.design.profiles import (
    Limits,
    ProfileFamily,
    SpeedProfile,
    feasible,
    limit_margins,
)
from braidsim.design.robust import RobustObjective
from braidsim.errors import InputError

CONSTRAINTS = (
    "fit",
    "min_speed",
    "max_speed",
    "acceleration",
    "jerk",
    "torque",
    "rms_torque",
    "power",
)


@dataclass(frozen=True)
class OptimizerOptions:
    """Budget and settings of the differential evolution.

    Attributes
    ----------
    maxiter : int
        Generations after the first population.
    popsize : int
        Population = popsize x number of parameters.
    seed : int
        Random seed (initial Latin hypercube, mutation, crossover).
    tol : float
        SciPy's relative convergence tolerance on the population's spread.
    mutation : tuple of float
        Dithered differential weight F.
    recombination : float
        Crossover probability CR.
    cycles : float
        Proxy length in transfer cycles.
    workers : int
        Processes evaluating a generation (1: this one).
    """

    maxiter: int = 20
    popsize: int = 8
    seed: int = 1
    tol: float = 0.0
    mutation: tuple[float, float] = (0.5, 1.0)
    recombination: float = 0.7
    cycles: float = 16.0
    workers: int = 1

    def __post_init__(self) -> None:
        checks = (
            ("maxiter", self.maxiter, 0, 10000),
            ("popsize", self.popsize, 2, 1000),
            ("workers", self.workers, 1, 256),
        )
        for name, v, lo, hi in checks:
            if isinstance(v, bool) or not isinstance(v, int):
                raise InputError(
                    f"design.optimizer.{name}: {v!r} is not an integer; allowed an integer from "
                    f"{lo} to {hi}"
                )
            if not lo <= v <= hi:
                raise InputError(
                    f"design.optimizer.{name}: {v!r} is out of range; allowed an integer from "
                    f"{lo} to {hi}"
                )
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise InputError(f"design.optimizer.seed: {self.seed!r}; allowed an integer >= 0")
        if not (math.isfinite(self.tol) and self.tol >= 0.0):
            raise InputError(f"design.optimizer.tol: {self.tol!r}; allowed >= 0")
        f_lo, f_hi = self.mutation
        if not 0.0 <= f_lo <= f_hi < 2.0:
            raise InputError(
                f"design.optimizer.mutation: {list(self.mutation)}; allowed [lo, hi] with "
                "0 <= lo <= hi < 2"
            )
        if not 0.0 <= self.recombination <= 1.0:
            raise InputError(
                f"design.optimizer.recombination: {self.recombination!r}; allowed 0 to 1"
            )
        if not (math.isfinite(self.cycles) and 1.0 <= self.cycles <= 10000.0):
            raise InputError(
                f"design.optimizer.cycles: {self.cycles!r} is out of range; allowed 1 to 10000 "
                "transfer cycles"
            )

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": "scipy.optimize.differential_evolution",
            "maxiter": self.maxiter,
            "popsize": self.popsize,
            "seed": self.seed,
            "tol": self.tol,
            "mutation": list(self.mutation),
            "recombination": self.recombination,
            "cycles": self.cycles,
            "workers": self.workers,
            "updating": "deferred",
            "polish": False,
        }


class ProfileObjective:
    """x -> robust objective of the profile (:class:`braidsim.design.robust.RobustObjective`);
    picklable, so that a process pool can evaluate it."""

    def __init__(self, robust: RobustObjective, family: ProfileFamily) -> None:
        self.robust = robust
        self.family = family
        self.log: list[tuple[np.ndarray, float]] = []

    def __call__(self, x: np.ndarray) -> float:
        v = self.robust(self.family.profile(x))
        # in this process only (a pool's workers keep their own copies)
        self.log.append((np.array(x, dtype=float), v))
        return v


class ProfileConstraints:
    """x -> normalised limit margins (>= 0 satisfied), in the order of :data:`CONSTRAINTS`:
    the motion limits (:func:`braidsim.design.profiles.limit_margins`) and, with a drive
    model, the motor's torque, RMS torque and power (:meth:`DriveModel.margins`)."""

    def __init__(
        self,
        family: ProfileFamily,
        limits: Limits,
        mean_speed: float,
        cycle_time: float,
        drive: DriveModel | None = None,
    ) -> None:
        self.family = family
        self.limits = limits
        self.mean_speed = mean_speed
        self.cycle_time = cycle_time
        self.drive = drive

    def margins(self, x: np.ndarray) -> dict[str, float]:
        return limit_margins(self.family.profile(x), self.limits, self.mean_speed, self.cycle_time)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        m = self.margins(x)
        if m["fit"] < 0.0:
            return np.array([m["fit"]] + [-1.0] * (len(CONSTRAINTS) - 1))
        L = self.limits
        out = [
            m["fit"],
            m["min_speed"],
            m["max_speed"],
            m["acceleration"] / L.max_acceleration,
            m["jerk"] / L.max_jerk,
        ]
        if self.drive is not None:
            d = self.drive.margins(self.family.profile(x))
            out += [d["torque"], d["rms_torque"], d["power"]]
        else:
            out += [1.0, 1.0, 1.0]
        return np.array(out)


@dataclass
class OptimizationResult:
    """What :func:`optimise_profile` returns.

    Attributes
    ----------
    family : ProfileFamily
    limits : Limits
    options : OptimizerOptions
    objective : str
    x : np.ndarray
        Best parameters.
    profile : SpeedProfile
        Best profile.
    value : float
        Its robust objective on the optimiser's parameter sets (a ratio to constant speed).
    baseline_value : float
        The constant profile's (1 by construction).
    margins : dict
        Limit margins of the best profile (:func:`limit_margins`), with the drive's.
    history : list of dict
        Per generation after the first population: best value, evaluations so far,
        elapsed time.
    evaluations : int
        Simulated candidates (feasible ones; infeasible ones cost no run).
    elapsed : float
        Wall time [s].
    message : str
        SciPy's termination message.
    candidates : list of (x, value)
        Every simulated candidate in evaluation order, the constant profile first (recorded
        with ``workers == 1`` only; empty otherwise).
    """

    family: ProfileFamily
    limits: Limits
    options: OptimizerOptions
    objective: str
    pair: str
    x: np.ndarray
    profile: SpeedProfile
    value: float
    baseline_value: float
    margins: dict[str, float]
    history: list[dict[str, float]] = field(default_factory=list)
    evaluations: int = 0
    elapsed: float = 0.0
    message: str = ""
    candidates: list[tuple[np.ndarray, float]] = field(default_factory=list)

    def recent_gain(self) -> tuple[int, float]:
        """(k, g): the relative fall of the best proxy value over the last k generations,
        g = 1 - best_last / best_(last - k), with k = max(1, generations // 4).

        With ``tol`` = 0 (the default) the search runs to its iteration cap; g > 0 there
        says that it was still finding better profiles when it stopped, so a larger
        ``maxiter`` may find a better one. (0, nan) with fewer than two generations.
        """
        best = [row["best"] for row in self.history]
        if len(best) < 2:
            return 0, math.nan
        k = max(1, len(best) // 4)
        before = best[-1 - k]
        return k, 1.0 - best[-1] / before if before else math.nan

    def still_improving(self) -> bool:
        """Stopped at its iteration cap with the best value falling over the last
        generations (:meth:`recent_gain`)."""
        k, gain = self.recent_gain()
        return len(self.history) >= self.options.maxiter and k > 0 and gain > 0.0

    def to_dict(self) -> dict[str, Any]:
        k, gain = self.recent_gain()
        return {
            "objective": self.objective,
            "pair": self.pair,
            "family": self.family.to_dict(),
            "limits": self.limits.to_dict(),
            "options": self.options.to_dict(),
            "parameters": dict(zip(self.family.names, self.x.tolist(), strict=True)),
            "robust_value": self.value,
            "robust_baseline_value": self.baseline_value,
            "robust_improvement": 1.0 - self.value / self.baseline_value
            if self.baseline_value
            else math.nan,
            "margins": self.margins,
            "history": self.history,
            "evaluations": self.evaluations,
            "elapsed_s": self.elapsed,
            "message": self.message,
            "generations": len(self.history),
            "recent_generations": k,
            "recent_gain": gain if math.isfinite(gain) else None,
            "still_improving": self.still_improving(),
        }


def optimise_profile(
    base: Mapping[str, Any],
    path: Path | None,
    family: ProfileFamily,
    limits: Limits,
    objective: str = "score",
    options: OptimizerOptions | None = None,
    progress: Callable[[dict[str, float]], None] | None = None,
    pair: str = "both",
    drive: DriveModel | None = None,
    samples: Sequence[Mapping[str, float]] = (),
    statistic: str = "mean",
    quantile: float = 0.9,
) -> OptimizationResult:
    """Find the profile of ``family`` that minimises the robust ``objective`` within
    ``limits`` and the drive's limits.

    Parameters
    ----------
    base, path
        The design's machine table and file (see :func:`braidsim.design.evaluate.evaluate`).
    family : ProfileFamily
        Parametrisation.
    limits : Limits
        Motion limits (constraints).
    objective, pair : str
        See :func:`braidsim.design.evaluate.objective_ratio`.
    options : OptimizerOptions
        Budget, seed, proxy length, workers.
    progress : callable, optional
        Called after each generation with the history row.
    drive : DriveModel, optional
        Adds the motor's torque, RMS torque and power limits to the constraints.
    samples : sequence of dict
        Parameter sets (scenario overrides) of the robust objective; empty: the nominal
        machine (:class:`braidsim.design.robust.RobustObjective`).
    statistic, quantile
        The robust statistic of the ratios.

    Raises
    ------
    InputError
        A bad objective or pair.

    Notes
    -----
    The search is global only. A local refinement of the best candidate by the exact
    sensitivities of the run (not available yet) would go after the global search, on the
    same robust objective and constraints.
    """
    from scipy.optimize import NonlinearConstraint, differential_evolution

    from braidsim.design.evaluate import machine_for

    opt = options or OptimizerOptions()
    check_objective(objective)
    check_pair(pair)
    spec = machine_for(base, path)
    robust = RobustObjective(base, path, objective, pair, opt.cycles, samples, statistic, quantile)
    func = ProfileObjective(robust, family)
    cons = ProfileConstraints(family, limits, spec.mean_speed, spec.cycle_time, drive)
    x0 = family.constant()
    baseline = func(x0)
    bounds = family.bounds(limits)
    history: list[dict[str, float]] = []
    t0 = time.perf_counter()

    def callback(intermediate_result: Any) -> None:
        row = {
            "generation": float(len(history)),
            "best": float(intermediate_result.fun),
            "evaluations": float(intermediate_result.nfev),
            "elapsed_s": time.perf_counter() - t0,
        }
        history.append(row)
        if progress is not None:
            progress(row)

    pool = None
    mapper: Any = 1
    if opt.workers > 1:
        import multiprocessing

        from braidsim.batch import process_pool

        pool = process_pool(opt.workers, multiprocessing.get_context("forkserver"))
        mapper = pool.map
    try:
        res = differential_evolution(
            func,
            bounds,
            maxiter=opt.maxiter,
            popsize=opt.popsize,
            tol=opt.tol,
            mutation=opt.mutation,
            recombination=opt.recombination,
            rng=opt.seed,
            callback=callback,
            polish=False,
            init="latinhypercube",
            updating="deferred",
            workers=mapper,
            constraints=NonlinearConstraint(cons, 0.0, np.inf),
            x0=x0,
        )
    finally:
        if pool is not None:
            pool.shutdown()
    x = np.asarray(res.x, dtype=float)
    value = float(res.fun)
    if not (value < baseline) or not np.all(cons(x) >= 0.0):
        # nothing feasible beat constant speed: keep it exactly (its parameters may differ
        # from x0 only in the dip geometry, which has no effect at level 1)
        x, value = x0, baseline
    best = family.profile(x)
    margins = limit_margins(best, limits, spec.mean_speed, spec.cycle_time)
    if drive is not None:
        margins.update({f"drive_{k}": v for k, v in drive.margins(best).items()})
    if not feasible(margins):  # pragma: no cover - SciPy keeps feasible solutions first
        raise AssertionError(f"optimiser returned an infeasible profile: {margins}")
    return OptimizationResult(
        family,
        limits,
        opt,
        objective,
        pair,
        x,
        best,
        value,
        baseline,
        margins,
        history,
        int(res.nfev) + 1,
        time.perf_counter() - t0,
        str(res.message),
        list(func.log) if opt.workers == 1 else [],
    )


def compare(
    base: Mapping[str, Any],
    path: Path | None,
    profile: SpeedProfile,
    workers: int | None = None,
) -> tuple[Evaluation, Evaluation]:
    """The full machine run (every carrier, the spec's duration) at constant speed and with
    ``profile``: the before/after numbers of the report."""
    before = evaluate(base, path, None, full=True, workers=workers)
    after = evaluate(base, path, profile, full=True, workers=workers)
    return before, after


def reductions(before: Mapping[str, float], after: Mapping[str, float]) -> dict[str, float]:
    """1 - after/before for every objective."""
    out = {}
    for k in METRIC_KEYS:
        b, a = before.get(k, math.nan), after.get(k, math.nan)
        out[k] = 1.0 - a / b if b and math.isfinite(a) and math.isfinite(b) else math.nan
    return out
