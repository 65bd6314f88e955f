"""Two-parameter continuation of fold, period-doubling and grazing points: boundary curves.

A special point found on a branch in parameter lambda_1 is followed as a second parameter
lambda_2 changes. At each step of lambda_2 (linear predictor for lambda_1 from the last two
points of the curve) the point is located again by a short pseudo-arclength run in
lambda_1 through a window around the prediction, started from the orbit next to the last
point on the side it was approached from, with the detection and location of
:mod:`braidsim.continuation.branch` (a fold by the sign change of the tangent's parameter
component, a period doubling by det(M + I), a grazing by the change of contact structure).
The curve ends where the point is no longer found in its window (it left the parameter
range, or the special point disappeared: e.g. a fold curve ending in a cusp).

The curves over (h_a, omega) or (eps_g, omega) bound the regions with one kind of motion:
resting on the wall below the lift-off grazing curve, impacting above it, and so on; drawn
over a brute-force regime map of the same range they form the safe operating map
(:func:`braidsim.continuation.plots.plot_operating_map`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from braidsim.continuation.branch import Branch, Continuer, SpecialPoint, signature
from braidsim.continuation.orbit import ContinuationError, Orbit, solve_fixed
from braidsim.errors import SimulationError


@dataclass
class BoundaryCurve:
    """A special point followed in two parameters.

    Attributes
    ----------
    type : str
        ``fold``, ``period_doubling`` or ``grazing``.
    key1, key2 : str
        The branch's parameter and the second one.
    period : int
        Period of the orbit [forcing cycles].
    p1, p2 : list of float
        The curve [SI].
    stop : str
        Why it ended.
    """

    type: str
    key1: str
    key2: str
    period: int
    p1: list[float] = field(default_factory=list)
    p2: list[float] = field(default_factory=list)
    stop: str = ""
    detail: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (SI)."""
        return {
            "type": self.type,
            "parameters": [self.key1, self.key2],
            "period": self.period,
            "points": [[a, b] for a, b in zip(self.p1, self.p2, strict=True)],
            "stop": self.stop,
            "detail": self.detail,
        }


def _with(o: Orbit, values: dict[str, float]) -> dict[str, float]:
    v = dict(o.values)
    v.update(values)
    return v


def trace_boundary(
    system: Any,
    branch: Branch,
    sp: SpecialPoint,
    key2: str,
    to2: float,
    *,
    steps: int = 10,
    window: float = 0.04,
    method: str = "auto",
    tol: float = 1e-8,
    range1: tuple[float, float] | None = None,
    on_point: Callable[[float, float], None] | None = None,
) -> BoundaryCurve:
    """Follow the special point ``sp`` of ``branch`` as ``key2`` goes to ``to2`` [SI] in
    ``steps`` equal steps (module docstring). ``window``: half-width of the search window in
    the first parameter, as a fraction of ``range1`` (default the branch's range)."""
    system.check_key(key2)
    key1 = branch.key
    anchor = branch.points[sp.index]
    p2_0 = float(anchor.values.get(key2, system.value(key2)))
    anchor = replace(anchor, values={**anchor.values, key2: p2_0})
    if range1 is None:
        v = branch.values
        a, b = float(v.min()), float(v.max())
        # the branch's range and half as much again each side (not below 0 for a range >= 0)
        lo1, hi1 = a - 0.5 * (b - a), b + 0.5 * (b - a)
        if a >= 0.0:
            lo1 = max(lo1, 0.0)
    else:
        lo1, hi1 = range1
    span = max(hi1 - lo1, 1e-12)
    curve = BoundaryCurve(sp.type, key1, key2, sp.period, [sp.value], [p2_0], detail=sp.detail)
    side = (
        math.copysign(1.0, anchor.values[key1] - sp.value)
        if anchor.values[key1] != sp.value
        else -1.0
    )
    offset = max(abs(anchor.values[key1] - sp.value), 0.3 * window * span)
    if on_point:
        on_point(sp.value, p2_0)
    for p2 in np.linspace(p2_0, to2, steps + 1)[1:]:
        if len(curve.p1) >= 2:
            s = (curve.p1[-1] - curve.p1[-2]) / (curve.p2[-1] - curve.p2[-2])
            pred = curve.p1[-1] + s * (p2 - curve.p2[-1])
        else:
            pred = curve.p1[-1]
        start = None
        # the orbit next to the point, carried to the new key2 by continuation in key2 at
        # fixed key1 (robust where the orbit moves much between two steps of key2) ...
        p2_prev = float(anchor.values[key2])
        try:
            mover = Continuer(
                system,
                key2,
                (min(p2_prev, p2), max(p2_prev, p2)),
                method=method,
                tol=tol,
                step=0.2,
                max_step=0.5,
                max_points=30,
                pscale=abs(p2 - p2_prev) or 1.0,
            )
            moved = mover.run(anchor, 1.0 if p2 > p2_prev else -1.0)
            last = moved.points[-1]
            if abs(last.values[key2] - p2) <= 1e-9 * max(abs(p2), 1.0) and signature(
                last
            ) == signature(anchor):
                start = last
        except (ContinuationError, SimulationError, np.linalg.LinAlgError):
            start = None
        # ... or solved there afresh, a little further from the predicted point
        for grow in () if start is not None else (1.0, 3.0, 9.0):
            start_val = min(max(pred + side * offset * grow, lo1), hi1)
            vals = _with(anchor, {key1: start_val, key2: float(p2)})
            try:
                cand = solve_fixed(
                    system, vals, anchor.period, anchor.phase, anchor.cuts, anchor.z, method, tol
                )
            except (ContinuationError, SimulationError, np.linalg.LinAlgError):
                continue
            if signature(cand) == signature(anchor):
                start = cand
                break
        if start is None:
            curve.stop = f"no orbit next to the {sp.type} point at {key2} = {p2:.6g}"
            break
        w = window * span
        cont = Continuer(
            system,  # the orbit's values carry key2 = p2
            key1,
            (lo1, hi1),
            method=method,
            tol=tol,
            step=0.5 * w / span,
            max_step=2 * w / span,
            max_points=60,
            pscale=span,
            stop_on=sp.type,
        )
        try:
            local = cont.run(start, -side)
        except (ContinuationError, SimulationError) as exc:
            curve.stop = f"continuation failed at {key2} = {p2:.6g} ({exc})"
            break
        found = [s for s in local.special if s.type == sp.type]
        if not found:
            curve.stop = f"no {sp.type} point found at {key2} = {p2:.6g} (local run: {local.stop})"
            break
        best = min(found, key=lambda s: abs(s.value - pred))
        curve.p1.append(float(best.value))
        curve.p2.append(float(p2))
        if on_point:
            on_point(float(best.value), float(p2))
        anchor = local.points[best.index]
        if anchor.values[key1] != best.value:
            side = math.copysign(1.0, anchor.values[key1] - best.value)
        offset = max(abs(anchor.values[key1] - best.value), 0.3 * window * span)
    else:
        curve.stop = f"reached {key2} = {to2:.6g}"
    return curve
