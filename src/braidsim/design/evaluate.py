"""Objectives of a design: the machine run of a speed profile (or of changed parameters),
reduced to peak transfer force, impact energy per second and impacts per second.

The machine and its carriers
----------------------------
A candidate is a machine spec (:mod:`braidsim.machine.spec`) with a horn-gear speed profile
and scenario overrides; :func:`machine_for` builds it from the design's base table, so every
candidate goes through the machine's own validation and rest start (the carriers start at
rest on the inner wall under the load at ``omega(0)``).

Identical carriers, run once (exact)
------------------------------------
Every carrier is the same single-carrier model; carriers differ only by their transfer times
(through the phase of the track vibration at each transfer and the start of the run). The
transfer times follow from the horn-gear *angles* of a carrier's crossings
(:meth:`~braidsim.machine.geometry.MachineGeometry.transfer_events`) by inverting the common
rotation ``Omega(t)``, so carriers whose crossing angles agree have the same transfer times
for *every* speed profile and their runs are the same, bit for bit. :func:`carrier_classes`
groups them; a run of one carrier per class, each weighted by the size of its class, gives
exactly the machine's totals (``tests/unit/test_design.py`` checks it against the full run).
The paper's 16-carrier machine has 4 classes.

The proxy
---------
The optimiser evaluates each candidate over ``cycles`` transfer cycles (16 by default: 1 s
at 120 rpm, half a carrier revolution, two or more transfers of every class) instead of the
whole revolution of the final comparison; :func:`proxy_fidelity` measures how well this
proxy ranks and values profiles against the full run (the report states it).

Objectives [SI]
---------------
Every candidate runs the two-DOF (``xy``) carrier model: the carrier meets the track walls
(radial, ``x``) and the horn-gear slot walls (along the path, ``y``). Each contact pair gets
four figures, ``<pair>.<figure>`` with ``pair`` = ``track`` or ``slot``:

``peak_force``
    the largest peak contact force of any impact of any carrier [N];
``impact_energy``
    impact energy per second: sum over impacts of m v^2 / 2 (v the approach speed at the
    onset) divided by the simulated time [W];
``impacts``
    impacts per second [1/s];
``noise``
    the noise proxy: sum over impacts of the squared peak force, per second [N^2/s], also
    given as a level ``10 log10(noise / 1 N^2/s)`` [dB]. Why this one: an impact radiates
    mostly "acceleration noise" (Richards, Westcott & Jeyapalan 1979, "On the prediction of
    impact noise, I: acceleration noise", J. Sound Vib. 62(4):547-575; Akay 1978, "A review
    of impact noise", J. Acoust. Soc. Am. 64(4):977-987): the sound energy of one impact
    grows with the square of the peak
    acceleration F/m of the bodies for a given pulse shape. The Hertzian pulse duration
    changes only as v^(-1/5), so the squared peak force ranks impacts as their radiated
    energy does, where the sum of m v^2 (the impact energy) would not: F ~ v^(6/5), so a few
    hard impacts weigh more than many soft ones. No radiation efficiency, no A-weighting
    (the pulses of steel contacts last about 0.1 ms, so most of their energy lies in the
    1-10 kHz band, where the A-weighting is within a few dB of flat).

The combined figure of both pairs (no prefix): the larger peak force, and the sums of the
others. ``mean_peak_force``: the mean over complete transfers of the largest track peak
force after each transfer [N]. The definitions of the track figures are those of
:mod:`braidsim.machine.run`.

The design objective (:func:`objective_ratio`) is a ratio to constant speed at the same
parameters, so that it is dimensionless and comparable over tolerance samples: for one
figure ``J = figure(profile) / figure(constant)``; for ``score`` (the default), the mean of
the four figures' ratios. ``pair`` chooses ``both`` (default), ``track`` or ``slot``.
Improvement = 1 - J (positive = better).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from braidsim.design.profiles import SpeedProfile
from braidsim.errors import InputError, SimulationError
from braidsim.machine.geometry import custom_loading
from braidsim.machine.run import MachineRun, plan_transfers, run_machine
from braidsim.machine.spec import MachineSpec, parse_machine_spec

PAIRS = ("track", "slot")
FIGURES = {
    "peak_force": ("largest peak contact force", "N"),
    "impact_energy": ("impact energy per second", "W"),
    "impacts": ("impacts per second", "1/s"),
    "noise": ("noise proxy: sum of squared peak forces per second", "N^2/s"),
}
OBJECTIVES = {"score": ("mean of the four figures' ratios to constant speed", ""), **FIGURES}
OBJECTIVE_PAIRS = ("both", "track", "slot")
METRIC_KEYS = (
    *FIGURES,
    *(f"{p}.{k}" for p in PAIRS for k in FIGURES),
    "mean_peak_force",
)
PENALTY = 1e12
"""Objective value of a candidate whose run failed numerically (never the optimum)."""


def check_objective(name: str) -> str:
    """``name`` if it is an objective, else an InputError naming the allowed ones."""
    if name not in OBJECTIVES:
        raise InputError(
            f"design.objective: {name!r} is not allowed; allowed {', '.join(OBJECTIVES)}"
        )
    return name


def check_pair(name: str) -> str:
    """``name`` if it is a pair choice, else an InputError naming the allowed ones."""
    if name not in OBJECTIVE_PAIRS:
        raise InputError(
            f"design.pair: {name!r} is not allowed; allowed {', '.join(OBJECTIVE_PAIRS)}"
        )
    return name


def figure_key(figure: str, pair: str) -> str:
    """The metrics key of ``figure`` for ``pair`` (``both``: the combined figure)."""
    return figure if pair == "both" else f"{pair}.{figure}"


def metric_label(key: str) -> tuple[str, str]:
    """(title, unit) of a metrics key."""
    if key == "mean_peak_force":
        return ("mean largest track force per transfer", "N")
    pair, _, fig = key.rpartition(".")
    title, unit = FIGURES[fig]
    return (f"{pair} {title}" if pair else f"{title} (both pairs)", unit)


def _ratio(a: float, b: float) -> float:
    """a / b for figures >= 0; 1 when both are 0, 1 + a when only b is 0 (a new kind of
    impact where constant speed had none counts as worse)."""
    if not (math.isfinite(a) and math.isfinite(b)):
        return PENALTY
    if b > 0.0:
        return a / b
    return 1.0 if a == 0.0 else 1.0 + a


def objective_ratio(
    metrics: Mapping[str, float], baseline: Mapping[str, float], objective: str, pair: str
) -> float:
    """J = objective(profile) / objective(constant speed) (module docstring); PENALTY when the
    run failed."""
    figs = list(FIGURES) if objective == "score" else [objective]
    r = [_ratio(metrics[figure_key(f, pair)], baseline[figure_key(f, pair)]) for f in figs]
    return float(np.mean(r)) if all(v < PENALTY for v in r) else PENALTY


def noise_level(noise: float) -> float:
    """The noise proxy as a level [dB re 1 N^2/s] (-inf for no impact)."""
    return 10.0 * math.log10(noise) if noise > 0.0 else -math.inf


def machine_for(
    base: Mapping[str, Any],
    path: Path | None,
    profile: SpeedProfile | None = None,
    overrides: Mapping[str, Any] | None = None,
    speed: float | None = None,
) -> MachineSpec:
    """The machine of the design's base table with a speed profile, scenario overrides and a
    mean speed [rad/s] applied (each optional), validated by the machine's own parser.

    The carriers always run the two-DOF model (``simulation.dof = "xy"``): a profile that
    speeds the gears up and slows them down drives the carriers through the slot walls, so
    the slot contact is part of every design figure."""
    d = copy.deepcopy(dict(base))
    d["animation"] = {"enabled": False}
    m = dict(_table(d, "machine"))
    if profile is not None and not profile.is_constant:
        ph, fa = profile.table()
        m["speed_profile"] = {"phase": ph, "factor": fa}
    if speed is not None:
        m["speed"] = float(speed)
    d["machine"] = m
    ov = dict(_table(d, "overrides"))
    ov.update(overrides or {})
    ov["simulation.dof"] = "xy"
    d["overrides"] = ov
    return parse_machine_spec(d, path)


def _table(d: Mapping[str, Any], name: str) -> Mapping[str, Any]:
    """The sub-table ``name`` of a spec (absent or None: empty); anything else is refused."""
    t = d.get(name)
    if t is None:
        return {}
    if not isinstance(t, Mapping):
        raise InputError(f"[{name}]: expected a table of KEY = VALUE, got {type(t).__name__}")
    return t


@dataclass(frozen=True)
class CarrierClass:
    """Carriers with the same crossing angles (hence the same run).

    Attributes
    ----------
    representative : str
        The carrier that is run.
    members : tuple of str
        Every carrier of the class.
    """

    representative: str
    members: tuple[str, ...]

    @property
    def weight(self) -> int:
        return len(self.members)


def carrier_classes(spec: MachineSpec, duration: float) -> list[CarrierClass]:
    """Group the carriers of ``spec`` by their crossing angles over ``duration`` [s]."""
    _, plans = plan_transfers(spec, duration)
    groups: dict[tuple[int, ...], list[str]] = {}
    for p in plans:
        groups.setdefault(tuple(e.angle for e in p.events), []).append(p.carrier)
    return [CarrierClass(v[0], tuple(v)) for v in groups.values()]


def representatives_spec(spec: MachineSpec, classes: list[CarrierClass]) -> MachineSpec:
    """``spec`` loaded with one carrier per class only."""
    lanes: dict[str, list[int]] = {"A": [], "B": []}
    for c in classes:
        lanes[c.representative[0]].append(int(c.representative[1:]))
    return replace(spec, loading=custom_loading(spec.geometry, lanes["A"], lanes["B"]))


def metrics(run: MachineRun, weights: Mapping[str, int] | None = None) -> dict[str, float]:
    """Figures (module docstring) of a machine run; ``weights`` counts each run carrier for
    that many identical carriers (default 1 each)."""
    ca = run.carriers
    w = np.array([float((weights or {}).get(c, 1)) for c in ca["carrier"]])
    T = run.duration
    tr = run.transfers
    cols = {
        "track": ("max_peak_force", "impact_energy", "impacts", "peak_force_squares"),
        "slot": (
            "slot_max_peak_force",
            "slot_impact_energy",
            "slot_impacts",
            "slot_peak_force_squares",
        ),
    }
    out: dict[str, float] = {}
    for pair, (pk, en, n, sq) in cols.items():
        out[f"{pair}.peak_force"] = float(ca[pk].max()) if len(ca) else 0.0
        out[f"{pair}.impact_energy"] = float(np.sum(w * ca[en].to_numpy()) / T)
        out[f"{pair}.impacts"] = float(np.sum(w * ca[n].to_numpy()) / T)
        out[f"{pair}.noise"] = float(np.sum(w * ca[sq].to_numpy()) / T)
    out["peak_force"] = max(out["track.peak_force"], out["slot.peak_force"])
    for k in ("impact_energy", "impacts", "noise"):
        out[k] = out[f"track.{k}"] + out[f"slot.{k}"]
    out["dissipated_power"] = float(np.sum(w * ca["dissipated_energy"].to_numpy()) / T)
    out["friction_power"] = float(np.sum(w * ca["friction_energy"].to_numpy()) / T)
    out["carriers"] = float(w.sum())
    out["duration"] = T
    done = tr[tr["complete"]] if len(tr) else tr
    if len(done):
        wt = np.array([float((weights or {}).get(c, 1)) for c in done["carrier"]])
        out["mean_peak_force"] = float(np.sum(wt * done["peak_force"].to_numpy()) / wt.sum())
    else:
        out["mean_peak_force"] = math.nan
    return out


@dataclass(frozen=True)
class Evaluation:
    """One evaluated candidate.

    Attributes
    ----------
    metrics : dict
        Objectives and totals (module docstring); NaN-free unless the run failed.
    run : MachineRun or None
        The run (one carrier per class, or every carrier with ``full``).
    weights : dict
        Carrier -> number of carriers it stands for.
    error : str
        The numerical failure, if any ("" otherwise).
    error_time : float
        Simulated time of that failure [s] (NaN when none or unknown).
    """

    metrics: dict[str, float]
    run: MachineRun | None
    weights: dict[str, int]
    error: str = ""
    error_time: float = math.nan

    def required(self, what: str) -> Evaluation:
        """This evaluation, or the :class:`~braidsim.errors.SimulationError` of its failed run
        prefixed with ``what`` (for the runs a study cannot go on without: a candidate's
        failure only costs it the :data:`PENALTY`)."""
        if self.run is None:
            # the run's own message names the carrier, the time and the scenario keys to
            # change; in a design those keys live in the machine spec's [overrides]
            raise SimulationError(
                f"{what}: {self.error} (scenario keys: the machine spec's [overrides])",
                self.error_time,
            )
        return self


def evaluate(
    base: Mapping[str, Any],
    path: Path | None,
    profile: SpeedProfile | None = None,
    overrides: Mapping[str, Any] | None = None,
    speed: float | None = None,
    cycles: float | None = None,
    full: bool = False,
    workers: int | None = 1,
) -> Evaluation:
    """Run a candidate machine and reduce it.

    Parameters
    ----------
    base, path
        The design's machine table and its file (relative scenario paths).
    profile, overrides, speed
        See :func:`machine_for`.
    cycles : float, optional
        Simulated time in transfer cycles of the candidate's mean speed (default: the
        machine spec's duration).
    full : bool
        Run every carrier (default: one per class, weighted: the same totals).
    workers : int or None
        Processes for the carriers (:func:`braidsim.machine.run.run_machine`).
    """
    spec = machine_for(base, path, profile, overrides, speed)
    T = spec.duration if cycles is None else float(cycles) * spec.cycle_time
    weights: dict[str, int] = {}
    if not full:
        classes = carrier_classes(spec, T)
        spec = representatives_spec(spec, classes)
        weights = {c.representative: c.weight for c in classes}
    try:
        run = run_machine(spec, duration=T, workers=workers, frames=0)
    except SimulationError as exc:
        bad = dict.fromkeys(METRIC_KEYS, math.nan)
        return Evaluation(bad, None, weights, str(exc), exc.time)
    return Evaluation(metrics(run, weights), run, weights)


def objective_value(ev: Evaluation, objective: str) -> float:
    """A figure of an evaluation (``objective`` a metrics key; :data:`PENALTY` when its run
    failed)."""
    v = ev.metrics.get(objective, math.nan)
    return float(v) if math.isfinite(v) else PENALTY


@dataclass(frozen=True)
class Fidelity:
    """How the proxy compares with the full run over a set of profiles.

    Attributes
    ----------
    proxy, full : np.ndarray
        (profiles, objectives) values in the order of :data:`METRIC_KEYS`.
    rank_correlation : dict
        Spearman's rank correlation per objective.
    median_relative_error : dict
        Median |proxy - full| / full per objective.
    """

    proxy: np.ndarray
    full: np.ndarray
    rank_correlation: dict[str, float]
    median_relative_error: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        return {
            "profiles": int(self.proxy.shape[0]),
            "rank_correlation": self.rank_correlation,
            "median_relative_error": self.median_relative_error,
        }


def _ranks(v: np.ndarray) -> np.ndarray:
    order = np.argsort(v, kind="stable")
    r = np.empty(v.size)
    r[order] = np.arange(v.size, dtype=float)
    return r


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman's rank correlation of two samples (Pearson correlation of the ranks)."""
    ra, rb = _ranks(np.asarray(a, float)), _ranks(np.asarray(b, float))
    if ra.std() == 0.0 or rb.std() == 0.0:
        return math.nan
    return float(np.corrcoef(ra, rb)[0, 1])


def proxy_fidelity(
    base: Mapping[str, Any],
    path: Path | None,
    profiles: list[SpeedProfile],
    cycles: float,
    workers: int | None = 1,
) -> Fidelity:
    """Evaluate ``profiles`` with the proxy (``cycles``) and with the full run (the machine
    spec's duration, every class) and compare."""
    P = np.zeros((len(profiles), len(METRIC_KEYS)))
    F = np.zeros_like(P)
    for i, pr in enumerate(profiles):
        a = evaluate(base, path, pr, cycles=cycles, workers=workers)
        b = evaluate(base, path, pr, workers=workers)
        P[i] = [a.metrics[k] for k in METRIC_KEYS]
        F[i] = [b.metrics[k] for k in METRIC_KEYS]
    rc = {}
    err = {}
    for j, k in enumerate(METRIC_KEYS):
        ok = np.isfinite(P[:, j]) & np.isfinite(F[:, j])
        rc[k] = spearman(P[ok, j], F[ok, j]) if ok.sum() > 2 else math.nan
        rel = np.abs(P[ok, j] - F[ok, j]) / np.maximum(np.abs(F[ok, j]), 1e-300)
        err[k] = float(np.median(rel)) if rel.size else math.nan
    return Fidelity(P, F, rc, err)
