"""Basins of attraction: which steady state each start ends in.

A grid of starts (two of ``initial.x``, ``initial.vx``, ``track.vibration_phase`` or any
other scalar parameter) is run past the transient (:mod:`braidsim.analysis.regimes`), and
the settled motions are grouped into attractors:

* two periodic (or resting, or chattering) steady states are the same attractor when they
  have the same regime label, one period divides the other, and their stroboscopic orbits
  coincide as point sets: the Hausdorff distance between the last ``q`` samples of each, in
  the coordinates (u, dx/dt / omega_h) [m], is at most ``match_tol`` * L (L the larger of
  the two length scales of rule 4, so the default 2e-2 is twice the period tolerance). A
  slowly settling orbit whose samples are not yet within ``period_tol`` is detected at a
  multiple of its period, and its points lie on the settled orbit's; the attractor is then
  represented by its member of smallest period;
* steady states without a period (``irregular``, or chattering without a period) are grouped
  by label and by the walls they hit: telling two coexisting strange attractors apart is
  beyond a stroboscopic point comparison;
* runs that failed numerically get the attractor id -1.

The samples are taken at a fixed excitation phase (``omega_h t + phase = 2 pi k``), so orbits
of runs that start at different vibration phases are compared at the same wall position.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from braidsim.analysis.bifurcation import to_si
from braidsim.analysis.regimes import (
    DEFAULT_CYCLES,
    DEFAULT_MAX_PERIOD,
    DEFAULT_PERIOD_TOL,
    DEFAULT_TRANSIENT_CYCLES,
    SteadyState,
    as_scenario,
)
from braidsim.analysis.runs import run_steady_states
from braidsim.errors import InputError
from braidsim.params import Scenario

DEFAULT_MATCH_TOL = 2e-2


@dataclass(frozen=True)
class Attractor:
    """One steady state found on the grid.

    Attributes
    ----------
    id : int
        Index in :attr:`BasinMap.attractors`.
    label : str
        Regime label.
    period : int or None
        Period in excitation cycles.
    walls : str
        Walls hit.
    points : np.ndarray
        (q, 2) stroboscopic orbit (u [m], dx/dt / omega_h [m]) of its representative (the
        first member of smallest period).
    impacts_per_cycle : float
        Of its representative.
    max_approach_speed : float
        Of its representative [m/s].
    count : int
        Number of starts that end in it.
    """

    id: int
    label: str
    period: int | None
    walls: str
    points: np.ndarray
    impacts_per_cycle: float
    max_approach_speed: float
    count: int

    def describe(self) -> str:
        """Short text, e.g. ``periodic_one_sided, period 6``."""
        per = f", period {self.period}" if self.period else ""
        return f"{self.label}{per}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (SI)."""
        return {
            "id": self.id,
            "label": self.label,
            "period": self.period,
            "walls": self.walls,
            "points": self.points.tolist(),
            "impacts_per_cycle": self.impacts_per_cycle,
            "max_approach_speed": self.max_approach_speed,
            "count": self.count,
        }


@dataclass(frozen=True)
class BasinMap:
    """Attractor id of every start on a 2-D grid.

    Attributes
    ----------
    scenario : str
        Base scenario name.
    x_key, y_key : str
        The two parameters of the grid.
    x_values, y_values : np.ndarray
        Their values [SI].
    ids : np.ndarray
        (len(y_values), len(x_values)) attractor ids, -1 for a failed run.
    attractors : tuple of Attractor
        The distinct steady states, by first appearance on the grid (row by row).
    states : tuple of SteadyState
        All steady states, row by row (y outer, x inner).
    """

    scenario: str
    x_key: str
    y_key: str
    x_values: np.ndarray
    y_values: np.ndarray
    ids: np.ndarray
    attractors: tuple[Attractor, ...]
    states: tuple[SteadyState, ...]

    def to_dict(self, samples: bool = False) -> dict[str, Any]:
        """JSON-ready form (SI)."""
        return {
            "scenario": self.scenario,
            "x": {"parameter": self.x_key, "values": self.x_values.tolist()},
            "y": {"parameter": self.y_key, "values": self.y_values.tolist()},
            "ids": self.ids.tolist(),
            "attractors": [a.to_dict() for a in self.attractors],
            "failed": int(np.count_nonzero(self.ids < 0)),
            "states": [s.to_dict(samples=samples) for s in self.states] if samples else None,
        }


def _orbit(s: SteadyState) -> np.ndarray:
    z = s.strobe_points()
    q = s.regime.period
    return z[-q:] if q else z


def hausdorff(a: np.ndarray, b: np.ndarray) -> float:
    """Hausdorff distance of two point sets (rows), infinity norm per point."""
    if a.size == 0 or b.size == 0:
        return float("inf")
    d = np.max(np.abs(a[:, None, :] - b[None, :, :]), axis=2)
    return float(max(d.min(axis=1).max(), d.min(axis=0).max()))


def same_attractor(a: SteadyState, b: SteadyState, match_tol: float = DEFAULT_MATCH_TOL) -> bool:
    """Whether two steady states are the same attractor (rules in the module docstring)."""
    ra, rb = a.regime, b.regime
    if ra.label == "failed" or rb.label == "failed" or ra.label != rb.label:
        return False
    if ra.period is None or rb.period is None:
        return ra.period is None and rb.period is None and ra.walls == rb.walls
    if max(ra.period, rb.period) % min(ra.period, rb.period) != 0:
        return False
    L = max(a.length_scale, b.length_scale)
    return hausdorff(_orbit(a), _orbit(b)) <= match_tol * L


def group_attractors(
    states: Sequence[SteadyState], match_tol: float = DEFAULT_MATCH_TOL
) -> tuple[np.ndarray, list[Attractor]]:
    """Attractor id per state and the distinct attractors, in order of first appearance."""
    ids = np.full(len(states), -1, dtype=int)
    reps: list[SteadyState] = []
    counts: list[int] = []
    for i, s in enumerate(states):
        if s.regime.label == "failed":
            continue
        for j, r in enumerate(reps):
            if same_attractor(s, r, match_tol):
                ids[i] = j
                counts[j] += 1
                if (s.regime.period or 0) < (r.regime.period or 0):
                    reps[j] = s  # represented by the member of smallest period
                break
        else:
            ids[i] = len(reps)
            reps.append(s)
            counts.append(1)
    attractors = [
        Attractor(
            j,
            r.regime.label,
            r.regime.period,
            r.regime.walls,
            _orbit(r),
            r.regime.impacts_per_cycle,
            r.max_approach_speed,
            counts[j],
        )
        for j, r in enumerate(reps)
    ]
    return ids, attractors


def basins(
    scenario: Scenario | str | Any,
    x_key: str,
    x_values: Sequence[Any] | np.ndarray,
    y_key: str,
    y_values: Sequence[Any] | np.ndarray,
    overrides: Mapping[str, Any] | None = None,
    *,
    transient_cycles: float = DEFAULT_TRANSIENT_CYCLES,
    cycles: int = DEFAULT_CYCLES,
    period_tol: float = DEFAULT_PERIOD_TOL,
    max_period: int = DEFAULT_MAX_PERIOD,
    match_tol: float = DEFAULT_MATCH_TOL,
    workers: int = 1,
    on_done: Callable[[int], None] | None = None,
) -> BasinMap:
    """Basins of attraction over a grid of two parameters (usually initial conditions).

    Parameters
    ----------
    scenario : Scenario, str, Path or mapping
        The base scenario (e.g. ``paper-3.3``).
    x_key, y_key : str
        Scalar parameters of the grid, e.g. ``initial.x`` [m], ``initial.vx`` [m/s],
        ``track.vibration_phase`` [rad].
    x_values, y_values : sequence
        Their values (SI numbers or unit strings).
    overrides : mapping, optional
        Applied to the base scenario first.
    transient_cycles, cycles, period_tol, max_period
        As in :func:`braidsim.analysis.regimes.steady_state`.
    match_tol : float
        Relative tolerance of the orbit comparison (module docstring).
    workers : int
        Local processes (1: this process; 0 or less: all cores).
    on_done : callable, optional
        Called with the number of runs just finished (progress displays).
    """
    if x_key == y_key:
        raise InputError(f"basins: x and y are both {x_key!r}; allowed two different parameters")
    if not match_tol > 0:
        raise InputError(f"match_tol: {match_tol!r} is out of range; allowed > 0")
    base = as_scenario(scenario, overrides)
    xs = np.array([to_si(x_key, v) for v in x_values], dtype=float)
    ys = np.array([to_si(y_key, v) for v in y_values], dtype=float)
    if xs.size == 0 or ys.size == 0:
        raise InputError("basins: empty grid; allowed at least one value per axis")
    sets = [{x_key: float(x), y_key: float(y)} for y in ys for x in xs]
    states = run_steady_states(
        base,
        sets,
        transient_cycles=transient_cycles,
        cycles=cycles,
        period_tol=period_tol,
        max_period=max_period,
        workers=workers,
        on_done=on_done,
    )
    ids, attractors = group_attractors(states, match_tol)
    return BasinMap(
        base.name,
        x_key,
        y_key,
        xs,
        ys,
        ids.reshape(ys.size, xs.size),
        tuple(attractors),
        tuple(states),
    )
