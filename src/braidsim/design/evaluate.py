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
``peak_force``: the largest peak contact force of any track impact of any carrier [N];
``impact_energy``: impact energy per second, sum over impacts of m v^2/2 (v the approach
speed) divided by the simulated time [W]; ``impacts``: impacts per second [1/s];
``mean_peak_force``: the mean over complete transfers of the largest peak force after each
transfer [N]. The definitions are those of :mod:`braidsim.machine.run`.
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

OBJECTIVES = {
    "peak_force": ("largest peak transfer force", "N"),
    "impact_energy": ("impact energy per second", "W"),
    "impacts": ("impacts per second", "1/s"),
    "mean_peak_force": ("mean peak force per transfer", "N"),
}
METRIC_KEYS = tuple(OBJECTIVES)
PENALTY = 1e12
"""Objective value of a candidate whose run failed numerically (never the optimum)."""


def check_objective(name: str) -> str:
    """``name`` if it is an objective, else an InputError naming the allowed ones."""
    if name not in OBJECTIVES:
        raise InputError(
            f"design.objective: {name!r} is not allowed; allowed {', '.join(OBJECTIVES)}"
        )
    return name


def machine_for(
    base: Mapping[str, Any],
    path: Path | None,
    profile: SpeedProfile | None = None,
    overrides: Mapping[str, Any] | None = None,
    speed: float | None = None,
) -> MachineSpec:
    """The machine of the design's base table with a speed profile, scenario overrides and a
    mean speed [rad/s] applied (each optional), validated by the machine's own parser."""
    d = copy.deepcopy(dict(base))
    d["animation"] = {"enabled": False}
    m = dict(d.get("machine", {}))
    if profile is not None and not profile.is_constant:
        ph, fa = profile.table()
        m["speed_profile"] = {"phase": ph, "factor": fa}
    if speed is not None:
        m["speed"] = float(speed)
    d["machine"] = m
    if overrides:
        ov = dict(d.get("overrides", {}))
        ov.update(overrides)
        d["overrides"] = ov
    return parse_machine_spec(d, path)


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
    """Objectives (module docstring) of a machine run; ``weights`` counts each run carrier
    for that many identical carriers (default 1 each)."""
    ca = run.carriers
    w = np.array([float((weights or {}).get(c, 1)) for c in ca["carrier"]])
    T = run.duration
    tr = run.transfers
    out = {
        "peak_force": float(ca["max_peak_force"].max()) if len(ca) else 0.0,
        "impact_energy": float(np.sum(w * ca["impact_energy"].to_numpy()) / T),
        "impacts": float(np.sum(w * ca["impacts"].to_numpy()) / T),
        "dissipated_power": float(np.sum(w * ca["dissipated_energy"].to_numpy()) / T),
        "carriers": float(w.sum()),
        "duration": T,
    }
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
    """

    metrics: dict[str, float]
    run: MachineRun | None
    weights: dict[str, int]
    error: str = ""


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
        return Evaluation(bad, None, weights, str(exc))
    return Evaluation(metrics(run, weights), run, weights)


def objective_value(ev: Evaluation, objective: str) -> float:
    """The objective of an evaluation (:data:`PENALTY` when its run failed)."""
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
