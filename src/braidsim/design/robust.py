"""Robust design: the objective over tolerance distributions of the machine's parameters, and
the other levers compared with the profile on the same footing.

Tolerances
----------
A real machine is not the nominal one: the track clearance grows with wear, carriers differ
in mass with their bobbins, the yarn tension is set by hand, the restitution of the contact
varies with surface state and the track vibration with mounting. :class:`Tolerance` gives
each such parameter a uniform distribution (``relative``: a factor on the nominal value in
``[low, high]``; otherwise absolute values). :data:`DEFAULT_TOLERANCES` (assumed spreads,
the ranges over which the nominal design was found sensitive or not):

==============================  ==============  =============================================
``track.clearance``             x [0.8, 1.3]    +-20 % manufacturing, up to +30 % with wear
``carrier.mass``                x [0.8, 1.2]    full to nearly empty bobbin
``yarn.tension_horizontal``     x [0.8, 1.2]    tensioner setting
``contact.track.restitution``   x [0.9, 1.1]    surface state
``track.vibration_amplitude``   x [0.5, 1.5]    mounting, neighbouring machines
``track.vibration_phase``       [0, 2 pi) rad   the vibration is not locked to the gears
==============================  ==============  =============================================

:func:`draw_samples` draws ``n`` parameter sets by Latin hypercube sampling
(:class:`scipy.stats.qmc.LatinHypercube`, McKay, Beckman & Conover 1979, Technometrics
21:239) from ``numpy.random.default_rng(seed)``: the same seed gives the same sets.

The robust objective
--------------------
For a profile ``p`` and parameter set ``theta_s`` the ratio ``r_s = J(p, theta_s) /
J(constant, theta_s)`` (:func:`braidsim.design.evaluate.objective_ratio`): each set is
compared with constant speed on the same machine, so the improvement ``1 - r_s`` is what the
profile gains on that machine. :class:`RobustObjective` returns the mean of ``r_s`` over the
sets (``statistic = "mean"``) or its ``quantile`` (``"quantile"``, e.g. 0.9: the profile is
judged by the machines on which it does worst). The sets are drawn once and kept for every
candidate (common random numbers), so that differences between candidates are not noise of
the sampling. The constant-speed runs of the sets are made once.

The distribution of the improvement is then measured on *other* sets (a held-out draw, seed
+ 1) and over a longer run (``check_cycles``): the optimiser's own sets would flatter it.

Levers on the same footing
--------------------------
:func:`compare_levers`: each lever of the paper's advice is a change of the machine
(:class:`LeverMove`: scenario overrides, or the optimised profile), measured as the
improvement distribution over the same held-out sets against the unchanged machine at
constant speed. The model gives the effect; the effort (``effort``, 1 = a setting, 5 = a
redesign) is an assumption of the study, stated beside it, and the ranking is by median
improvement per unit of effort.

Local refinement
----------------
The global search (differential evolution) is all there is now. The exact sensitivities of
the objective through the impacts (derivatives of a run with respect to the profile's
parameters) are not available yet; when they are, a gradient refinement of the best
candidate on the same robust objective belongs in :func:`braidsim.design.optimise.optimise_profile`,
after the global search and before the held-out check.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from braidsim.design.evaluate import PENALTY, evaluate, objective_ratio
from braidsim.design.profiles import SpeedProfile
from braidsim.errors import InputError
from braidsim.params import SCHEMA, Scenario

STATISTICS = ("mean", "quantile")


@dataclass(frozen=True)
class Tolerance:
    """A uniform distribution of one scenario parameter.

    Attributes
    ----------
    key : str
        Scenario key.
    low, high : float
        Range: factors on the nominal value (``relative``) or SI values.
    relative : bool
    """

    key: str
    low: float
    high: float
    relative: bool = True

    def values(self, nominal: float, u: np.ndarray) -> np.ndarray:
        """Values at the uniform deviates ``u`` in [0, 1)."""
        lo, hi = (
            (self.low * nominal, self.high * nominal) if self.relative else (self.low, self.high)
        )
        return lo + u * (hi - lo)

    def to_dict(self) -> dict[str, Any]:
        return {"key": self.key, "low": self.low, "high": self.high, "relative": self.relative}


DEFAULT_TOLERANCES = (
    Tolerance("track.clearance", 0.8, 1.3),
    Tolerance("carrier.mass", 0.8, 1.2),
    Tolerance("yarn.tension_horizontal", 0.8, 1.2),
    Tolerance("contact.track.restitution", 0.9, 1.1),
    Tolerance("track.vibration_amplitude", 0.5, 1.5),
    Tolerance("track.vibration_phase", 0.0, 2.0 * math.pi, relative=False),
)


def check_tolerances(sc: Scenario, tolerances: Sequence[Tolerance]) -> None:
    """InputError unless every tolerance is a numeric key whose whole range is allowed."""
    for t in tolerances:
        where = f"design.robust.tolerances.{t.key}"
        if t.key not in SCHEMA or SCHEMA[t.key].kind != "float":
            raise InputError(f"{where}: not a numeric scenario key; allowed e.g. track.clearance")
        if not (math.isfinite(t.low) and math.isfinite(t.high) and t.low <= t.high):
            raise InputError(f"{where}: [{t.low:g}, {t.high:g}]; allowed low <= high")
        ps = SCHEMA[t.key]
        nom = float(sc[t.key])
        for v in t.values(nom, np.array([0.0, 1.0])):
            if v < ps.low or v > ps.high or (ps.low_open and v == ps.low):
                raise InputError(
                    f"{where}: {v:g} {ps.unit} is out of range; allowed {ps.range_text()}"
                )


def robust_sets(
    sc: Scenario, options: RobustOptions
) -> tuple[list[dict[str, float]], list[dict[str, float]]]:
    """The parameter sets of a study: the optimiser's (``options.samples``, seed ``seed``)
    and the held-out ones (``options.check_samples``, seed ``held_out_seed``); the spec's check
    and the study draw them here, so that they check what runs."""
    R = options
    return (
        draw_samples(sc, R.tolerances, R.samples, R.seed),
        draw_samples(sc, R.tolerances, R.check_samples, R.held_out_seed),
    )


def draw_samples(
    sc: Scenario, tolerances: Sequence[Tolerance], n: int, seed: int
) -> list[dict[str, float]]:
    """``n`` parameter sets (scenario overrides), Latin hypercube, seeded (module
    docstring)."""
    from scipy.stats import qmc

    if n <= 0 or not tolerances:
        return []
    u = qmc.LatinHypercube(d=len(tolerances), rng=np.random.default_rng(seed)).random(n)
    out = []
    for row in u:
        out.append(
            {
                t.key: float(t.values(float(sc[t.key]), np.array([ui]))[0])
                for t, ui in zip(tolerances, row, strict=True)
            }
        )
    return out


@dataclass(frozen=True)
class RobustOptions:
    """Settings of the robust study.

    Attributes
    ----------
    tolerances : tuple of Tolerance
    samples : int
        Parameter sets the optimiser averages over (0: the nominal machine only).
    check_samples : int
        Held-out sets of the improvement distribution.
    statistic : str
        ``mean`` or ``quantile``.
    quantile : float
        The quantile of the ratio with ``statistic = "quantile"``.
    seed : int
        Seed of the optimiser's sets.
    check_cycles : float
        Run length of the held-out check [transfer cycles].
    check_seed : int or None
        Seed of the held-out sets (None: ``seed + 1``); another draw of them checks the
        same optimum on other sets (:attr:`held_out_seed`).
    """

    tolerances: tuple[Tolerance, ...] = DEFAULT_TOLERANCES
    samples: int = 8
    check_samples: int = 32
    statistic: str = "mean"
    quantile: float = 0.9
    seed: int = 1
    check_cycles: float = 32.0
    check_seed: int | None = None

    @property
    def held_out_seed(self) -> int:
        """The seed of the held-out sets: ``check_seed``, else ``seed + 1``."""
        return self.seed + 1 if self.check_seed is None else self.check_seed

    def __post_init__(self) -> None:
        if self.statistic not in STATISTICS:
            raise InputError(
                f"design.robust.statistic: {self.statistic!r} is not allowed; allowed "
                + ", ".join(STATISTICS)
            )
        if not 0.0 < self.quantile < 1.0:
            raise InputError(
                f"design.robust.quantile: {self.quantile:g} is out of range; allowed 0 to 1"
            )
        if self.check_seed is not None and self.check_seed == self.seed:
            raise InputError(
                f"design.robust.check_seed: {self.check_seed} is the optimiser's seed "
                "(design.robust.seed); allowed another (the held-out sets must be other sets)"
            )
        if not (math.isfinite(self.check_cycles) and 1.0 <= self.check_cycles <= 10000.0):
            raise InputError(
                f"design.robust.check_cycles: {self.check_cycles:g} is out of range; allowed "
                "1 to 10000"
            )

    def to_dict(self) -> dict[str, Any]:
        return {
            "tolerances": [t.to_dict() for t in self.tolerances],
            "samples": self.samples,
            "check_samples": self.check_samples,
            "statistic": self.statistic,
            "quantile": self.quantile,
            "seed": self.seed,
            "check_cycles": self.check_cycles,
            "check_seed": self.held_out_seed,
            "sampling": "Latin hypercube (scipy.stats.qmc), numpy default_rng(seed)",
        }


def reduce_ratios(r: np.ndarray, statistic: str, quantile: float) -> float:
    """The robust statistic of the ratios ``r`` (PENALTY if any run failed)."""
    if r.size == 0 or not np.all(r < PENALTY):
        return PENALTY
    if statistic == "mean":
        return float(np.mean(r))
    return float(np.quantile(r, quantile))


class RobustObjective:
    """profile -> robust statistic of J(profile, theta_s) / J(constant, theta_s) over the
    parameter sets (module docstring); picklable for a process pool.

    With no sets, the nominal machine alone (one set with no overrides)."""

    def __init__(
        self,
        base: Mapping[str, Any],
        path: Path | None,
        objective: str,
        pair: str,
        cycles: float,
        samples: Sequence[Mapping[str, float]],
        statistic: str = "mean",
        quantile: float = 0.9,
    ) -> None:
        self.base = dict(base)
        self.path = path
        self.objective = objective
        self.pair = pair
        self.cycles = cycles
        self.samples = [dict(s) for s in samples] or [{}]
        self.statistic = statistic
        self.quantile = quantile
        self.baselines = [self._metrics(None, s) for s in self.samples]

    def _metrics(self, profile: SpeedProfile | None, over: dict[str, float]) -> dict[str, float]:
        return evaluate(self.base, self.path, profile, over, cycles=self.cycles).metrics

    def ratios(self, profile: SpeedProfile | None) -> np.ndarray:
        """r_s for every set."""
        out = []
        for s, b in zip(self.samples, self.baselines, strict=True):
            m = b if profile is None or profile.is_constant else self._metrics(profile, s)
            out.append(objective_ratio(m, b, self.objective, self.pair))
        return np.array(out)

    def __call__(self, profile: SpeedProfile | None) -> float:
        return reduce_ratios(self.ratios(profile), self.statistic, self.quantile)


#: resamples of the bootstrap standard errors of :meth:`Improvement.stats` (seeded: the
#: same values give the same errors)
BOOTSTRAP_RESAMPLES = 2000


def _bootstrap_se(values: np.ndarray, q: float) -> float:
    """Bootstrap standard error of the q-quantile of ``values`` (NaN for fewer than 2
    values, or all equal: no spread to resample)."""
    from scipy import stats

    if values.size < 2 or np.ptp(values) == 0.0:
        return 0.0 if values.size >= 2 else math.nan
    res = stats.bootstrap(
        (values,),
        lambda x, axis: np.quantile(x, q, axis=axis),
        n_resamples=BOOTSTRAP_RESAMPLES,
        method="percentile",
        rng=np.random.default_rng(0),
    )
    return float(res.standard_error)


@dataclass
class Improvement:
    """The improvement distribution of one change against constant speed.

    Attributes
    ----------
    values : np.ndarray
        1 - r_s per held-out set (positive = better).
    samples : int
    """

    values: np.ndarray

    @property
    def samples(self) -> int:
        return int(self.values.size)

    def stats(self) -> dict[str, float]:
        """Median, 5th and 95th percentiles, mean, worst and the fraction of sets made
        better, with bootstrap standard errors of the median and the 5th percentile
        (``*_se``: how far another draw of as many sets would move them; Efron &
        Tibshirani 1993, doi:10.1007/978-1-4899-4541-9)."""
        v = self.values
        ok = v[np.isfinite(v)]
        if ok.size == 0:
            nan = math.nan
            return {"median_improvement": nan, "p5_improvement": nan, "samples": v.size}
        return {
            "median_improvement": float(np.median(ok)),
            "median_improvement_se": _bootstrap_se(ok, 0.5),
            "p5_improvement": float(np.quantile(ok, 0.05)),
            "p5_improvement_se": _bootstrap_se(ok, 0.05),
            "p95_improvement": float(np.quantile(ok, 0.95)),
            "mean_improvement": float(np.mean(ok)),
            "worst_improvement": float(np.min(ok)),
            "fraction_better": float(np.mean(ok > 0.0)),
            "samples": int(v.size),
        }


def improvement(
    base: Mapping[str, Any],
    path: Path | None,
    samples: Sequence[Mapping[str, float]],
    objective: str,
    pair: str,
    cycles: float,
    profile: SpeedProfile | None = None,
    overrides: Mapping[str, float] | None = None,
    baselines: Sequence[Mapping[str, float]] | None = None,
) -> tuple[Improvement, list[dict[str, float]], list[dict[str, float]]]:
    """1 - J(change, theta_s) / J(constant, theta_s) over ``samples``; the change is a
    profile and/or scenario ``overrides`` applied on top of each set (a lever that sets a
    parameter replaces its tolerance draw).

    Returns
    -------
    Improvement, the baselines' metrics, the changed machines' metrics.
    """
    sets = [dict(s) for s in samples] or [{}]
    if baselines is None:
        baselines = [evaluate(base, path, None, s, cycles=cycles).metrics for s in sets]
    after = []
    vals = []
    for s, b in zip(sets, baselines, strict=True):
        m = evaluate(base, path, profile, {**s, **dict(overrides or {})}, cycles=cycles).metrics
        after.append(m)
        r = objective_ratio(m, b, objective, pair)
        vals.append(1.0 - r if r < PENALTY else math.nan)
    return Improvement(np.array(vals)), [dict(b) for b in baselines], after


@dataclass(frozen=True)
class LeverMove:
    """One design change of the comparison (module docstring).

    Attributes
    ----------
    name : str
    description : str
    overrides : dict
        Scenario overrides (SI), or empty for the profile.
    profile : bool
        True: the optimised speed profile.
    effort : float
        Assumed cost or effort, 1 (a setting) to 5 (a redesign).
    effort_reason : str
    """

    name: str
    description: str
    overrides: dict[str, float] = field(default_factory=dict)
    profile: bool = False
    effort: float = 1.0
    effort_reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "description": self.description,
            "overrides": dict(self.overrides),
            "profile": self.profile,
            "effort": self.effort,
            "effort_reason": self.effort_reason,
        }


def default_moves(sc: Scenario) -> list[LeverMove]:
    """The paper's levers as changes of the nominal machine, with assumed efforts."""
    e = float(sc["contact.track.restitution"])
    h = float(sc["track.vibration_amplitude"])
    c = float(sc["track.clearance"])
    return [
        LeverMove(
            "profile",
            "the optimised horn-gear speed profile",
            profile=True,
            effort=2.0,
            effort_reason="a servo drive and its motion program (more if the machine has a "
            "mains-fed motor and a mechanical gear train only)",
        ),
        LeverMove(
            "restitution",
            f"track contact restitution {e:.3g} -> {min(0.9, e + 0.25):.3g} (harder, "
            "more elastic surface: hardened or coated steel)",
            {"contact.track.restitution": min(0.9, e + 0.25)},
            effort=3.0,
            effort_reason="new track inserts and carrier pads on every carrier",
        ),
        LeverMove(
            "vibration",
            f"track vibration amplitude set to {0.5 * h * 1e3:.3g} mm in every sample "
            f"(nominal {h * 1e3:.3g} mm; stiffer mounting, balancing, isolation)",
            {"track.vibration_amplitude": 0.5 * h},
            effort=2.0,
            effort_reason="machine mounting and balancing, no new parts on the carriers",
        ),
        LeverMove(
            "clearance",
            f"track clearance set to {0.5 * c * 1e3:.3g} mm in every sample (nominal "
            f"{c * 1e3:.3g} mm; tighter guide pads, kept by maintenance)",
            {"track.clearance": 0.5 * c},
            effort=3.0,
            effort_reason="tighter tolerances of the track and pads, and replacing pads as "
            "they wear",
        ),
    ]


@dataclass
class LeverResult:
    """A move's improvement distribution and its rank."""

    move: LeverMove
    improvement: Improvement

    def to_dict(self) -> dict[str, Any]:
        st = self.improvement.stats()
        med = st["median_improvement"]
        return {
            **self.move.to_dict(),
            **st,
            "improvement_per_effort": med / self.move.effort if math.isfinite(med) else math.nan,
        }


def compare_levers(
    base: Mapping[str, Any],
    path: Path | None,
    moves: Sequence[LeverMove],
    samples: Sequence[Mapping[str, float]],
    objective: str,
    pair: str,
    cycles: float,
    profile: SpeedProfile | None,
    baselines: Sequence[Mapping[str, float]],
    profile_improvement: Improvement | None = None,
) -> list[LeverResult]:
    """Every move measured on the same sets and baselines, ranked by median improvement per
    unit of effort (best first). The profile move reuses ``profile_improvement`` when given
    (the same runs)."""
    out = []
    for mv in moves:
        if mv.profile and profile_improvement is not None:
            imp = profile_improvement
        else:
            imp, _, _ = improvement(
                base,
                path,
                samples,
                objective,
                pair,
                cycles,
                profile if mv.profile else None,
                mv.overrides,
                baselines,
            )
        out.append(LeverResult(mv, imp))

    def key(r: LeverResult) -> float:
        v = r.to_dict()["improvement_per_effort"]
        return -v if math.isfinite(v) else math.inf

    return sorted(out, key=key)


__all__ = [
    "DEFAULT_TOLERANCES",
    "Improvement",
    "LeverMove",
    "LeverResult",
    "RobustObjective",
    "RobustOptions",
    "Tolerance",
    "compare_levers",
    "default_moves",
    "draw_samples",
    "improvement",
]
