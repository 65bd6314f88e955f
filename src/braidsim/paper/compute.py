"""Our value of each paper item: run the item's scenario, read the exact window extremes.

The ranges come from :meth:`braidsim.result.Result.ranges_dict`: the kernel keeps, for every
window asked for, the smallest and largest depth and forces, refined on the integrator's
interpolant (not read off the sampled series), so a 0.1 ms contact peak is not missed.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from braidsim.paper.values import PaperItem, RunSpec
from braidsim.params import Scenario, load_scenario
from braidsim.result import Result
from braidsim.simulate import simulate

#: Young's modulus printed in section 3 [Pa] (docs/model.md §1: it does not fit)
PRINTED_MODULUS = 2e9
MATERIALS = ("guide_pad", "track", "carrier", "horn_gear")
VARIANTS = ("calibrated", "printed")


def printed_overrides() -> dict[str, float]:
    """Overrides that turn a scenario into the as-printed preset (E_i = 2 GPa)."""
    return {f"materials.{m}.youngs_modulus": PRINTED_MODULUS for m in MATERIALS}


def scenario_for(spec: RunSpec, variant: str = "calibrated") -> Scenario:
    """The scenario of a run: ``calibrated`` (E = 200 GPa) or ``printed`` (E = 2 GPa)."""
    if variant == "calibrated":
        return load_scenario(spec.scenario)
    if variant != "printed":
        raise ValueError(f"variant {variant!r}; allowed {VARIANTS}")
    if spec.printed:
        return load_scenario(spec.printed)
    sc = load_scenario(spec.scenario, overrides=printed_overrides())
    return sc.with_overrides(name=f"{spec.scenario}-printed")


def run_spec(
    spec: RunSpec,
    variant: str = "calibrated",
    *,
    overrides: Mapping[str, Any] | None = None,
    duration: float | None = None,
    series: bool = False,
) -> Result:
    """Simulate one run with all its windows.

    Parameters
    ----------
    spec : RunSpec
    variant : str
        ``calibrated`` or ``printed``.
    overrides : mapping, optional
        Extra parameter overrides (evidence runs).
    duration : float, optional
        Shorter run [s]; windows that end after it are dropped.
    series : bool
        Keep the sampled time series (for figures); otherwise only the exact ranges and the
        impact table are computed, which is several times faster.
    """
    sc = scenario_for(spec, variant)
    if overrides:
        sc = sc.with_overrides(overrides)
    T = spec.duration if duration is None else float(duration)
    windows = [w for w in spec.windows.values() if w[1] <= T + 1e-12]
    if series:
        return simulate(sc, duration=T, windows=windows)
    return simulate(sc, duration=T, windows=windows, sample_interval=0.0)


@dataclass(frozen=True)
class Measured:
    """Our value of one item.

    Attributes
    ----------
    value : float
        SI value (N or m), signed as in the paper.
    low, high : float
        The window's exact range of the quantity [SI].
    """

    value: float
    low: float
    high: float

    @property
    def spread(self) -> float:
        """high - low [SI] (for a ``rest`` item: how far from rest the window is)."""
        return self.high - self.low


def measure(item: PaperItem, result: Result, spec: RunSpec) -> Measured:
    """Our value of ``item`` from a run of ``spec``.

    ``min``/``max``: the window's extreme; ``rest``: the mid-range (the carrier is at rest
    when the spread is negligible); ``absmax``: the largest magnitude.
    """
    t0, t1 = spec.windows[item.window]
    lo, hi = result.ranges_dict("track", result.window_index(t0, t1))[item.quantity]
    if item.statistic == "min":
        v = lo
    elif item.statistic == "max":
        v = hi
    elif item.statistic == "rest":
        v = 0.5 * (lo + hi)
    else:
        v = max(abs(lo), abs(hi))
    return Measured(float(v), float(lo), float(hi))


@dataclass(frozen=True)
class Comparison:
    """Paper value against ours.

    Attributes
    ----------
    deviation : float or None
        ours / paper - 1 (positive: ours is larger in magnitude); None for a printed zero.
    abs_deviation : float
        ours - paper, in the paper's unit.
    within : bool
        Inside the item's tolerance (relative, or ``abs_tol`` for a printed zero).
    """

    deviation: float | None
    abs_deviation: float
    within: bool


def compare(item: PaperItem, ours_si: float) -> Comparison:
    """Compare our SI value with the item's printed value."""
    ours = ours_si / item.scale
    diff = ours - item.value
    if item.value == 0.0:
        tol = item.abs_tol if item.abs_tol is not None else 0.0
        return Comparison(None, diff, abs(diff) <= tol)
    dev = ours / item.value - 1.0
    return Comparison(dev, diff, math.isfinite(dev) and abs(dev) <= item.tolerance)
