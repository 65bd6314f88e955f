"""Sensitivity of the design objective to the other levers: clearance, restitution (material),
track vibration amplitude and frequency, carrier mass, yarn tension.

Two studies, both on the proxy run (:func:`braidsim.design.evaluate.evaluate`):

One at a time (:func:`one_at_a_time`)
    Each lever at ``levels`` values evenly spaced over its range, the others nominal. The
    bars of the report are the objective at the two ends of each range against the nominal
    value; each setting also gets its speed limits (:mod:`braidsim.design.speed_limits`).

Elementary effects (:func:`morris`; Morris 1991, Technometrics 33:161; mu* of Campolongo,
Cariboni & Saltelli 2007, Environ. Model. Softw. 22:1509)
    The ranking. Each lever is scaled to [0, 1] over its range, on a grid of ``p`` levels;
    ``r`` trajectories start at random grid points and move one lever at a time (in random
    order) by ``Delta = p / (2 (p - 1))`` (down when up would leave [0, 1]). The elementary
    effect of lever i is ``EE_i = (Y(x + Delta e_i) - Y(x)) / Delta``: the change of the
    objective over the lever's whole range, measured at a random point of the others, so that
    interactions count. ``mu*_i = mean |EE_i|`` ranks the levers, ``sigma_i = std EE_i``
    shows interaction or non-linearity. ``r (k + 1)`` runs; the random choices come from
    ``numpy.random.default_rng(seed)``, so a seed gives the same ranking bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from braidsim.design.evaluate import METRIC_KEYS, evaluate
from braidsim.design.profiles import SpeedProfile
from braidsim.errors import InputError
from braidsim.params import SCHEMA, Scenario
from braidsim.units import to_si

DEFAULT_LEVERS = (
    "track.clearance",
    "contact.track.restitution",
    "track.vibration_amplitude",
    "track.vibration_frequency",
    "carrier.mass",
    "yarn.tension_horizontal",
)
T = TypeVar("T")

LABELS = {
    "track.clearance": ("clearance eps_g", "mm", 1e3),
    "contact.track.restitution": ("restitution c_r", "", 1.0),
    "track.vibration_amplitude": ("vibration amplitude h_a", "mm", 1e3),
    "track.vibration_frequency": ("vibration frequency omega_h", "Hz", 1.0 / (2.0 * math.pi)),
    "carrier.mass": ("carrier mass m", "kg", 1.0),
    "yarn.tension_horizontal": ("yarn tension T1", "N", 1.0),
}


@dataclass(frozen=True)
class Lever:
    """One parameter the designer may change.

    Attributes
    ----------
    key : str
        Scenario key.
    nominal, low, high : float
        Values in SI.
    """

    key: str
    nominal: float
    low: float
    high: float

    @property
    def label(self) -> str:
        name, unit, _ = LABELS.get(self.key, (self.key, SCHEMA[self.key].unit, 1.0))
        return f"{name} [{unit}]" if unit else name

    def display(self, v: float) -> float:
        """Value in the plotted unit (mm, Hz, ...)."""
        return v * LABELS.get(self.key, ("", "", 1.0))[2]

    def value(self, u: float) -> float:
        """SI value at the scaled position u in [0, 1]."""
        return self.low + u * (self.high - self.low)

    def to_dict(self) -> dict[str, Any]:
        return {"key": self.key, "nominal": self.nominal, "low": self.low, "high": self.high}


def make_levers(
    sc: Scenario,
    keys: Sequence[str] = DEFAULT_LEVERS,
    span: float = 0.5,
    ranges: Mapping[str, Sequence[Any]] | None = None,
) -> list[Lever]:
    """Levers at the scenario's nominal values; range ``nominal * (1 -+ span)`` unless given
    in ``ranges`` ({key: [low, high]}, numbers in SI or unit strings), clipped to the key's
    allowed range.

    Raises
    ------
    InputError
        Unknown key, a range that does not hold the nominal value, or one outside the key's
        allowed range.
    """
    if not (0.0 < span < 1.0):
        raise InputError(f"design.sensitivity.span: {span:g} is out of range; allowed 0 to 1")
    ranges = dict(ranges or {})
    out = []
    for key in keys:
        if key not in SCHEMA or SCHEMA[key].kind != "float":
            raise InputError(
                f"design.sensitivity.levers: {key!r} is not a numeric scenario key; allowed "
                f"e.g. {', '.join(DEFAULT_LEVERS)}"
            )
        ps = SCHEMA[key]
        nom = float(sc[key])
        if key in ranges:
            r = ranges.pop(key)
            if not isinstance(r, list | tuple) or len(r) != 2:
                raise InputError(
                    f"design.sensitivity.ranges.{key}: expected [low, high], got {r!r}"
                )
            lo = to_si(f"design.sensitivity.ranges.{key}", r[0], ps.unit)
            hi = to_si(f"design.sensitivity.ranges.{key}", r[1], ps.unit)
        else:
            lo, hi = nom * (1.0 - span), nom * (1.0 + span)
            lo, hi = max(lo, ps.low), min(hi, ps.high)
        if not (lo < hi and lo <= nom <= hi):
            raise InputError(
                f"design.sensitivity.ranges.{key}: [{lo:g}, {hi:g}] is not allowed; allowed "
                f"low < high around the nominal {nom:g} {ps.unit}"
            )
        for v in (lo, hi):
            if v < ps.low or v > ps.high or (ps.low_open and v == ps.low):
                raise InputError(
                    f"design.sensitivity.ranges.{key}: {v:g} is out of range; allowed "
                    f"{ps.range_text()}"
                )
        out.append(Lever(key, nom, lo, hi))
    if ranges:
        extra = next(iter(ranges))
        raise InputError(
            f"design.sensitivity.ranges.{extra}: not among the levers; allowed one of "
            + ", ".join(keys)
        )
    return out


@dataclass(frozen=True)
class Task:
    """One proxy run: a setting (overrides), a profile and a speed; picklable for a pool."""

    base: dict[str, Any]
    path: Path | None
    profile: SpeedProfile | None
    overrides: dict[str, float]
    speed: float | None
    cycles: float

    def __call__(self) -> dict[str, float]:
        ev = evaluate(self.base, self.path, self.profile, self.overrides, self.speed, self.cycles)
        return ev.metrics


def _call(task: Callable[[], T]) -> T:
    return task()


def run_tasks(tasks: Sequence[Callable[[], T]], workers: int = 1) -> list[T]:
    """Every task, in order (a process pool when ``workers > 1``; the same results)."""
    if workers <= 1 or len(tasks) < 2:
        return [t() for t in tasks]
    import multiprocessing

    from braidsim.batch import process_pool

    with process_pool(workers, multiprocessing.get_context("forkserver")) as pool:
        return list(pool.map(_call, tasks))


@dataclass
class MorrisResult:
    """Elementary effects (module docstring).

    Attributes
    ----------
    levers : list of Lever
    objective : str
    seed, trajectories, levels : int
    points : np.ndarray
        (r (k+1), k) scaled design points in run order.
    values : np.ndarray
        (r (k+1),) objective at each point.
    effects : np.ndarray
        (r, k) elementary effects [objective unit per lever range].
    mu_star, mu, sigma : np.ndarray
        (k,) mean |EE|, mean EE, standard deviation of EE.
    ranking : list of str
        Lever keys by decreasing mu*.
    """

    levers: list[Lever]
    objective: str
    seed: int
    trajectories: int
    levels: int
    points: np.ndarray
    values: np.ndarray
    effects: np.ndarray
    mu_star: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mu: np.ndarray = field(default_factory=lambda: np.zeros(0))
    sigma: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ranking: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": "Morris elementary effects (mu* = mean |EE|)",
            "objective": self.objective,
            "seed": self.seed,
            "trajectories": self.trajectories,
            "levels": self.levels,
            "runs": int(self.values.size),
            "levers": [
                {
                    **lv.to_dict(),
                    "mu_star": float(self.mu_star[i]),
                    "mu": float(self.mu[i]),
                    "sigma": float(self.sigma[i]),
                }
                for i, lv in enumerate(self.levers)
            ],
            "ranking": self.ranking,
        }


def morris_design(
    k: int, trajectories: int, levels: int, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scaled points (r (k+1), k), the lever moved at each step (r, k) and the signed step
    (r, k) of ``trajectories`` Morris trajectories (module docstring)."""
    if isinstance(levels, bool) or not 2 <= levels <= 20:
        raise InputError(f"design.sensitivity.levels: {levels!r}; allowed 2 to 20")
    if isinstance(trajectories, bool) or not 1 <= trajectories <= 1000:
        raise InputError(f"design.sensitivity.trajectories: {trajectories!r}; allowed 1 to 1000")
    rng = np.random.default_rng(seed)
    grid = np.arange(levels) / (levels - 1)
    delta = levels / (2.0 * (levels - 1))
    pts = np.empty((trajectories * (k + 1), k))
    moved = np.empty((trajectories, k), dtype=int)
    steps = np.empty((trajectories, k))
    for r in range(trajectories):
        x = rng.choice(grid, size=k)
        order = rng.permutation(k)
        pts[r * (k + 1)] = x
        for j, i in enumerate(order):
            d = delta if x[i] + delta <= 1.0 + 1e-12 else -delta
            x = x.copy()
            x[i] = min(1.0, max(0.0, x[i] + d))
            pts[r * (k + 1) + j + 1] = x
            moved[r, j] = i
            steps[r, j] = d
    return pts, moved, steps


def elementary_effects(
    func: Callable[[np.ndarray], np.ndarray],
    k: int,
    trajectories: int,
    levels: int,
    seed: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Morris elementary effects of a function of ``k`` scaled inputs in [0, 1].

    ``func`` maps the (n, k) design points to their n outputs (all at once, so that the
    caller may evaluate them in parallel). Returns (points, values, effects (r, k), mu*, mu,
    sigma) as in the module docstring.
    """
    pts, moved, steps = morris_design(k, trajectories, levels, seed)
    y = np.asarray(func(pts), dtype=float).reshape(-1)
    if y.size != pts.shape[0]:
        raise ValueError(f"func returned {y.size} values for {pts.shape[0]} points")
    ee = np.full((trajectories, k), np.nan)
    for r in range(trajectories):
        for j in range(k):
            a, b = r * (k + 1) + j, r * (k + 1) + j + 1
            ee[r, moved[r, j]] = (y[b] - y[a]) / steps[r, j]
    mu_star = np.nanmean(np.abs(ee), axis=0)
    mu = np.nanmean(ee, axis=0)
    sigma = np.nanstd(ee, axis=0, ddof=1) if trajectories > 1 else np.zeros(k)
    return pts, y, ee, mu_star, mu, sigma


def morris(
    base: Mapping[str, Any],
    path: Path | None,
    levers: Sequence[Lever],
    objective: str,
    trajectories: int = 4,
    levels: int = 4,
    seed: int = 1,
    cycles: float = 16.0,
    profile: SpeedProfile | None = None,
    workers: int = 1,
) -> MorrisResult:
    """Morris elementary effects of ``levers`` on ``objective`` (module docstring)."""
    k = len(levers)
    if k == 0:
        raise InputError("design.sensitivity.levers: empty; allowed at least one lever")

    def func(pts: np.ndarray) -> np.ndarray:
        tasks = [
            Task(
                dict(base),
                path,
                profile,
                {lv.key: lv.value(float(u)) for lv, u in zip(levers, p, strict=True)},
                None,
                cycles,
            )
            for p in pts
        ]
        return np.array([r[objective] for r in run_tasks(tasks, workers)])

    pts, y, ee, mu_star, mu, sigma = elementary_effects(func, k, trajectories, levels, seed)
    order = sorted(range(k), key=lambda i: (-mu_star[i], levers[i].key))
    return MorrisResult(
        list(levers),
        objective,
        seed,
        trajectories,
        levels,
        pts,
        y,
        ee,
        mu_star,
        mu,
        sigma,
        [levers[i].key for i in order],
    )


@dataclass
class OneAtATime:
    """Objective (and every metric) of each lever at each of its values, others nominal.

    Attributes
    ----------
    levers : list of Lever
    values : dict
        key -> list of SI values.
    metrics : dict
        key -> list of metric dicts (one per value).
    nominal : dict
        Metrics at the nominal setting.
    profile : str
        Which profile the runs used (``constant`` or ``optimised``).
    """

    levers: list[Lever]
    values: dict[str, list[float]]
    metrics: dict[str, list[dict[str, float]]]
    nominal: dict[str, float]
    profile: str

    def swing(self, objective: str) -> dict[str, tuple[float, float]]:
        """key -> (objective at the low end, at the high end)."""
        return {
            lv.key: (self.metrics[lv.key][0][objective], self.metrics[lv.key][-1][objective])
            for lv in self.levers
        }

    def to_dict(self) -> dict[str, Any]:
        return {
            "profile": self.profile,
            "nominal": self.nominal,
            "levers": [
                {
                    **lv.to_dict(),
                    "values": self.values[lv.key],
                    "metrics": {m: [row[m] for row in self.metrics[lv.key]] for m in METRIC_KEYS},
                }
                for lv in self.levers
            ],
        }


def lever_values(lever: Lever, levels: int) -> list[float]:
    """``levels`` values evenly over the range (>= 2), with the nominal value added (a grid
    value within 1e-9 of the range of the nominal is the nominal, not a near-copy of it)."""
    out = [lever.nominal]
    tol = 1e-9 * (lever.high - lever.low)
    for v in np.linspace(lever.low, lever.high, max(2, levels)).tolist():
        if all(abs(v - u) > tol for u in out):
            out.append(float(v))
    return sorted(out)


def one_at_a_time(
    base: Mapping[str, Any],
    path: Path | None,
    levers: Sequence[Lever],
    levels: int = 5,
    cycles: float = 16.0,
    profile: SpeedProfile | None = None,
    profile_name: str = "constant",
    workers: int = 1,
    progress: Callable[[str], None] | None = None,
) -> OneAtATime:
    """Every lever at :func:`lever_values`, the others nominal (module docstring)."""
    tasks = [Task(dict(base), path, profile, {}, None, cycles)]
    index: list[tuple[str, float]] = [("", math.nan)]
    values: dict[str, list[float]] = {}
    for lv in levers:
        values[lv.key] = lever_values(lv, levels)
        for v in values[lv.key]:
            tasks.append(Task(dict(base), path, profile, {lv.key: v}, None, cycles))
            index.append((lv.key, v))
    if progress:
        progress(f"{len(tasks)} runs ({profile_name} profile)")
    res = run_tasks(tasks, workers)
    metrics: dict[str, list[dict[str, float]]] = {lv.key: [] for lv in levers}
    for (key, _), r in zip(index[1:], res[1:], strict=True):
        metrics[key].append(r)
    return OneAtATime(list(levers), values, metrics, res[0], profile_name)


def swing_ranking(oat: OneAtATime, objective: str) -> list[str]:
    """Levers by decreasing largest |objective - nominal| over their values."""
    nom = oat.nominal[objective]

    def size(lv: Lever) -> float:
        vals = [row[objective] for row in oat.metrics[lv.key]]
        return max(abs(v - nom) for v in vals if math.isfinite(v)) if vals else 0.0

    return [lv.key for lv in sorted(oat.levers, key=lambda lv: (-size(lv), lv.key))]
