"""Stroboscopic bifurcation diagrams against any scalar parameter, and locating transitions.

For each value of the parameter the carrier is simulated from the scenario's initial
conditions past a transient, and its settled motion is sampled once per excitation period
(:mod:`braidsim.analysis.regimes`). The diagram plots those stroboscopic samples against the
parameter: one point per value for a period-1 motion, q points for period q, a cloud for an
irregular motion. Changes of regime or period between neighbouring values are the
bifurcations; :func:`refine_transition` brackets one by bisection.

The generic pieces (:func:`~braidsim.analysis.regimes.detect_period`,
:func:`refine_transition`, :func:`transitions`) are checked on the logistic map, whose
period doublings are known in closed form (r = 3 and r = 1 + sqrt 6; May, Nature 261 (1976)
459-467), in ``tests/unit/test_analysis_methods.py``.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from braidsim.analysis.regimes import (
    DEFAULT_CYCLES,
    DEFAULT_MAX_PERIOD,
    DEFAULT_PERIOD_TOL,
    DEFAULT_TRANSIENT_CYCLES,
    SteadyState,
    as_scenario,
    steady_state,
)
from braidsim.analysis.runs import run_steady_states
from braidsim.errors import InputError
from braidsim.params import SCHEMA, Scenario, convert

SWEEPABLE_EXAMPLES = (
    "track.vibration_amplitude",
    "track.vibration_frequency",
    "horn_gear.angular_velocity",
    "track.clearance",
    "contact.track.restitution",
)


def check_scalar_key(key: str) -> None:
    """InputError unless ``key`` is a scalar (float) parameter of the schema."""
    if key not in SCHEMA:
        import difflib

        close = difflib.get_close_matches(key, list(SCHEMA), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise InputError(
            f"parameter: unknown key {key!r}{hint}; allowed a scalar key, e.g. "
            + ", ".join(SWEEPABLE_EXAMPLES)
        )
    if SCHEMA[key].kind != "float":
        raise InputError(
            f"parameter: {key!r} is not a scalar number; allowed a scalar key, e.g. "
            + ", ".join(SWEEPABLE_EXAMPLES)
        )


def to_si(key: str, value: Any) -> float:
    """A value of ``key`` (number in SI or unit string) in SI, checked against its range."""
    check_scalar_key(key)
    v = convert(SCHEMA[key], value)
    if v is None:
        raise InputError(f"{key}: a value is needed; allowed {SCHEMA[key].range_text()}")
    return float(v)


def parameter_values(key: str, start: Any, stop: Any, points: int) -> np.ndarray:
    """``points`` evenly spaced values of ``key`` from ``start`` to ``stop`` (SI)."""
    if int(points) != points or points < 1:
        raise InputError(f"points: {points!r} is out of range; allowed an integer >= 1")
    a, b = to_si(key, start), to_si(key, stop)
    return np.linspace(a, b, int(points))


@dataclass(frozen=True)
class BifurcationDiagram:
    """Stroboscopic samples of the settled motion against one parameter.

    Attributes
    ----------
    scenario : str
        Name of the base scenario.
    key : str
        The swept parameter.
    values : np.ndarray
        Its values [SI].
    states : tuple of SteadyState
        The steady state of each value.
    """

    scenario: str
    key: str
    values: np.ndarray
    states: tuple[SteadyState, ...]

    @property
    def labels(self) -> list[str]:
        """Regime label per value."""
        return [s.regime.label for s in self.states]

    @property
    def periods(self) -> list[int | None]:
        """Period in excitation cycles per value (None: no period found)."""
        return [s.regime.period for s in self.states]

    def points(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All stroboscopic points: (parameter [SI], u = x - h [m], dx/dt [m/s]), flat."""
        p = [np.full(s.strobe_u.size, v) for v, s in zip(self.values, self.states, strict=True)]
        u = [s.strobe_u for s in self.states]
        vx = [s.strobe_vx for s in self.states]
        if not p:
            return np.zeros(0), np.zeros(0), np.zeros(0)
        return np.concatenate(p), np.concatenate(u), np.concatenate(vx)

    def transitions(self) -> list[dict[str, Any]]:
        """Where the (regime, period) class changes between neighbouring values."""
        classes = [(s.regime.label, s.regime.period) for s in self.states]
        return transitions(self.values, classes)

    def to_dict(self, samples: bool = True) -> dict[str, Any]:
        """JSON-ready form (SI)."""
        return {
            "scenario": self.scenario,
            "parameter": self.key,
            "values": self.values.tolist(),
            "labels": self.labels,
            "periods": self.periods,
            "transitions": self.transitions(),
            "states": [s.to_dict(samples=samples) for s in self.states],
        }


def class_text(cls: Hashable) -> str:
    """A (regime label, period) class as printed: ``periodic_one_sided (period 2)``, or the
    label alone where the period is None (``irregular``)."""
    if isinstance(cls, tuple) and len(cls) == 2:
        label, period = cls
        return str(label) if period is None else f"{label} (period {period})"
    return str(cls)


def transitions(
    values: Sequence[float] | np.ndarray, classes: Sequence[Hashable]
) -> list[dict[str, Any]]:
    """Brackets [values[i], values[i+1]] where ``classes`` changes.

    Returns a list of ``{"lower", "upper", "from", "to"}`` (classes as given).
    """
    out = []
    for i in range(len(classes) - 1):
        if classes[i] != classes[i + 1]:
            out.append(
                {
                    "lower": float(values[i]),
                    "upper": float(values[i + 1]),
                    "from": classes[i],
                    "to": classes[i + 1],
                }
            )
    return out


def refine_transition(
    classify: Callable[[float], Hashable],
    lower: float,
    upper: float,
    tol: float,
    max_iter: int = 60,
) -> tuple[float, float]:
    """Bisect a bracket whose ends classify differently down to a width <= ``tol``.

    The bracket keeps ``classify(lower)``'s class at its lower end and any other class at its
    upper end, so it closes on the first change seen from ``lower``.

    Raises
    ------
    InputError
        Both ends in the same class (no transition bracketed), or ``tol`` <= 0.
    """
    if not tol > 0:
        raise InputError(f"tol: {tol!r} is out of range; allowed > 0")
    lo, hi = float(lower), float(upper)
    c_lo = classify(lo)
    if classify(hi) == c_lo:
        raise InputError(
            f"refine_transition: both ends ({lo:g}, {hi:g}) are in class {c_lo!r}; "
            "allowed a bracket of two different classes"
        )
    for _ in range(max_iter):
        if abs(hi - lo) <= tol:
            break
        mid = 0.5 * (lo + hi)
        if classify(mid) == c_lo:
            lo = mid
        else:
            hi = mid
    return lo, hi


def bifurcation(
    scenario: Scenario | str | Any,
    key: str,
    values: Sequence[Any] | np.ndarray,
    overrides: Mapping[str, Any] | None = None,
    *,
    transient_cycles: float = DEFAULT_TRANSIENT_CYCLES,
    cycles: int = DEFAULT_CYCLES,
    strobe_phase: float = 0.0,
    period_tol: float = DEFAULT_PERIOD_TOL,
    max_period: int = DEFAULT_MAX_PERIOD,
    workers: int = 1,
    on_done: Callable[[int], None] | None = None,
) -> BifurcationDiagram:
    """Bifurcation diagram of the stroboscopic samples against parameter ``key``.

    Parameters
    ----------
    scenario : Scenario, str, Path or mapping
        The base scenario.
    key : str
        A scalar parameter, e.g. ``track.vibration_amplitude`` (h_a),
        ``track.vibration_frequency`` (omega_h), ``horn_gear.angular_velocity`` (omega),
        ``track.clearance`` (eps_g), ``contact.track.restitution`` (c_r).
    values : sequence
        Its values (SI numbers or unit strings).
    overrides : mapping, optional
        Applied to the base scenario first.
    transient_cycles, cycles, strobe_phase, period_tol, max_period
        As in :func:`braidsim.analysis.regimes.steady_state`.
    workers : int
        Local processes (1: this process; 0 or less: all cores).
    on_done : callable, optional
        Called with the number of runs just finished (progress displays).
    """
    base = as_scenario(scenario, overrides)
    vals = np.array([to_si(key, v) for v in values], dtype=float)
    if vals.size == 0:
        raise InputError("values: no parameter values given; allowed one or more")
    states = run_steady_states(
        base,
        [{key: float(v)} for v in vals],
        transient_cycles=transient_cycles,
        cycles=cycles,
        strobe_phase=strobe_phase,
        period_tol=period_tol,
        max_period=max_period,
        workers=workers,
        on_done=on_done,
    )
    return BifurcationDiagram(base.name, key, vals, tuple(states))


def locate_transition(
    scenario: Scenario | str | Any,
    key: str,
    lower: Any,
    upper: Any,
    tol: float,
    overrides: Mapping[str, Any] | None = None,
    *,
    by: str = "label",
    **options: Any,
) -> tuple[float, float]:
    """Bracket, to width ``tol`` [SI], where the carrier's steady state changes along ``key``.

    ``by="label"`` compares regime labels, ``"period"`` (label, period) pairs. ``options``
    go to :func:`braidsim.analysis.regimes.steady_state`.
    """
    if by not in ("label", "period"):
        raise InputError(f"by: {by!r} is not allowed; allowed 'label' or 'period'")
    base = as_scenario(scenario, overrides)
    a, b = to_si(key, lower), to_si(key, upper)

    def cls(v: float) -> Hashable:
        st = steady_state(base, {key: v}, **options)
        return st.regime.label if by == "label" else (st.regime.label, st.regime.period)

    return refine_transition(cls, a, b, tol)
