"""Continuation of periodic orbits of the forced carrier (and of any forced model of the
compiled core): Newton shooting, pseudo-arclength continuation, Floquet stability,
bifurcations and grazing, two-parameter boundaries (the safe operating map).

See ``docs/continuation.md`` for the method and its checks.
"""

from braidsim.continuation.fdmap import FlowMap, fd_flow_map
from braidsim.continuation.orbit import (
    ContinuationError,
    Cut,
    Orbit,
    Profile,
    evaluate_map,
    exact_available,
    reseat,
    seed_orbit,
    solve_fixed,
)
from braidsim.continuation.system import ModelSystem, ScenarioSystem, check_continuable

__all__ = [
    "ContinuationError",
    "Cut",
    "FlowMap",
    "ModelSystem",
    "Orbit",
    "Profile",
    "ScenarioSystem",
    "check_continuable",
    "evaluate_map",
    "exact_available",
    "fd_flow_map",
    "reseat",
    "seed_orbit",
    "solve_fixed",
]
