"""Speed limits: how fast the horn gears may turn (at constant speed) for a given setting.

Two speeds bound the operating window of a setting, both for constant horn-gear speed omega:

Transfer limit (upper bound, simulated)
    The largest constant speed at which the design's metric (by default the largest peak
    transfer force of the machine) stays at or below a threshold (by default its value at the
    nominal speed with nominal parameters: "how fast could the machine run with this setting
    without hitting harder than it does today"). Every transfer makes the carrier cross the
    clearance under the load ``T1 cos(phi) + m r_c omega^2`` and hit the inner wall, so
    transfer impacts exist at every speed; what grows with speed is their force. Found by
    scanning ``points`` speeds over ``[lo, hi]`` times the nominal mean speed, taking the first
    crossing of the threshold from below and bisecting that bracket ``refine`` times
    (:func:`transfer_speed_limit`). The status says when the threshold is already exceeded at
    the lowest speed (``below_range``) or never reached (``above_range``).

Closed-form estimate of the transfer limit
    Energy over the gap (no vibration, friction saturated at ``f = mu1 |m g - T2|``): the
    carrier hits the inner wall at ``v = sqrt(v_c^2 + 2 (F - f) eps_g / m)``, v_c the
    transfer contact speed; a Hunt-Crossley (or any law whose damping term scales with
    pdot / v0) impact peaks at ``F_max = F_ref (v / v_ref)^(2n/(n+1))`` (v^(6/5) for n = 3/2,
    exact by dimensional analysis); so the speed at which the *first* impact reaches a force
    limit is ``omega = sqrt((m (v_lim^2 - v_c^2) / (2 eps_g) + f - T1 cos(phi)) / (m r_c))``
    (:func:`first_impact_speed`, :func:`transfer_speed_estimate`). It ignores later bounces
    and the vibration; the simulated limit is the reference.

Chatter limit (lower bound, closed form; docs/model.md §7)
    Between transfers the carrier rests on the inner wall, pressed with the acceleration
    ``a_p = (T1 cos(phi) + m r_c omega^2) / m``; a wall vibrating as ``h_a cos(omega_h t)``
    accelerates away at up to ``h_a omega_h^2``, so the carrier stays on it (no impacts
    between transfers) only while ``a_p >= h_a omega_h^2``, i.e. above
    ``omega_ch = sqrt(max(0, h_a omega_h^2 - T1 cos(phi) / m) / r_c)`` (:func:`chatter_speed`;
    0 when the yarn load alone keeps it on the wall). Contact compliance and friction move the
    measured boundary slightly (tests/integration/test_design.py checks it by simulation).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from braidsim.design.evaluate import evaluate
from braidsim.design.profiles import SpeedProfile
from braidsim.errors import InputError
from braidsim.params import Scenario


def chatter_speed(sc: Scenario) -> float:
    """omega_ch [rad/s] below which a resting carrier leaves the vibrating wall (module
    docstring), from the scenario's h_a, omega_h, T1, phi, m and r_c."""
    m = sc["carrier.mass"]
    need = sc["track.vibration_amplitude"] * sc["track.vibration_frequency"] ** 2
    need -= sc["yarn.tension_horizontal"] * math.cos(sc["yarn.angle"]) / m
    return math.sqrt(max(0.0, need) / sc["carrier.turning_radius"])


def _friction_x(sc: Scenario) -> float:
    return sc["friction.carrier_horn_gear"] * abs(
        sc["carrier.mass"] * sc["gravity"] - sc["yarn.tension_vertical"]
    )


def first_impact_speed(sc: Scenario, omega: float) -> float:
    """Speed [m/s] at which a transferred carrier reaches the inner wall at constant horn-gear
    speed ``omega`` [rad/s]: ``sqrt(v_c^2 + 2 (T1 cos(phi) + m r_c omega^2 - f) eps_g / m)``
    (no vibration, saturated friction f = mu1 |m g - T2|)."""
    m = sc["carrier.mass"]
    load = sc["yarn.tension_horizontal"] * math.cos(sc["yarn.angle"])
    load += m * sc["carrier.turning_radius"] * omega * omega
    vc = sc["transfer.contact_speed"]
    return math.sqrt(max(0.0, vc * vc + 2.0 * (load - _friction_x(sc)) * sc["track.clearance"] / m))


def transfer_speed_estimate(sc: Scenario, force_limit: float) -> float:
    """Closed-form constant speed [rad/s] at which the first transfer impact peaks at
    ``force_limit`` [N] (module docstring); 0 when even omega = 0 exceeds it.

    The reference peak force comes from one simulated impact at the nominal first-impact
    speed (:func:`braidsim.impact.single_impact` with the scenario's law, restitution, mass and
    stiffness) and is scaled by (v / v_ref)^(2n/(n+1)).
    """
    from braidsim.impact import single_impact
    from braidsim.model import pair_model

    pm = pair_model(sc, "track")
    v_ref = max(first_impact_speed(sc, sc["horn_gear.angular_velocity"]), 1e-3)
    ref = single_impact(
        model=sc["contact.track.model"],
        restitution=sc["contact.track.restitution"],
        velocity=v_ref,
        mass=sc["carrier.mass"],
        stiffness=pm.stiffness,
        exponent=pm.exponent,
    )
    n = pm.exponent
    v_lim = v_ref * (force_limit / ref["max_force"]) ** ((n + 1.0) / (2.0 * n))
    m = sc["carrier.mass"]
    need = m * (v_lim**2 - sc["transfer.contact_speed"] ** 2) / (2.0 * sc["track.clearance"])
    need += _friction_x(sc) - sc["yarn.tension_horizontal"] * math.cos(sc["yarn.angle"])
    return math.sqrt(need / (m * sc["carrier.turning_radius"])) if need > 0.0 else 0.0


@dataclass(frozen=True)
class SpeedLimitOptions:
    """How :func:`transfer_speed_limit` searches.

    Attributes
    ----------
    low, high : float
        Scanned range as fractions of the nominal mean speed.
    points : int
        Scanned speeds (evenly spaced).
    refine : int
        Bisection steps in the bracket of the first crossing.
    """

    low: float = 0.25
    high: float = 2.0
    points: int = 8
    refine: int = 5

    def __post_init__(self) -> None:
        if not (0.0 < self.low < self.high <= 20.0):
            raise InputError(
                f"design.speed_limit.speeds: [{self.low:g}, {self.high:g}] is not allowed; "
                "allowed 0 < low < high <= 20 (fractions of the mean speed)"
            )
        if isinstance(self.points, bool) or not 2 <= self.points <= 200:
            raise InputError(
                f"design.speed_limit.points: {self.points!r} is out of range; allowed 2 to 200"
            )
        if isinstance(self.refine, bool) or not 0 <= self.refine <= 30:
            raise InputError(
                f"design.speed_limit.refine: {self.refine!r} is out of range; allowed 0 to 30"
            )


@dataclass(frozen=True)
class SpeedLimit:
    """A transfer speed limit.

    Attributes
    ----------
    speed : float
        The limit [rad/s] (NaN unless ``status == "found"``).
    status : str
        ``found``, ``below_range`` (threshold exceeded at the lowest speed) or ``above_range``
        (never reached).
    speeds, values : list of float
        Every evaluated speed [rad/s] and the metric there, in evaluation order.
    bracket : tuple of float
        Last speed at or below the threshold and first above it [rad/s].
    """

    speed: float
    status: str
    speeds: list[float] = field(default_factory=list)
    values: list[float] = field(default_factory=list)
    bracket: tuple[float, float] = (math.nan, math.nan)

    def to_dict(self) -> dict[str, Any]:
        return {
            "speed": self.speed,
            "speed_rpm": self.speed * 30.0 / math.pi,
            "status": self.status,
            "bracket": list(self.bracket),
            "speeds": self.speeds,
            "values": self.values,
        }


def transfer_speed_limit(
    base: Mapping[str, Any],
    path: Path | None,
    threshold: float,
    metric: str = "peak_force",
    overrides: Mapping[str, Any] | None = None,
    profile: SpeedProfile | None = None,
    options: SpeedLimitOptions | None = None,
    nominal_speed: float | None = None,
    cycles: float = 16.0,
) -> SpeedLimit:
    """The largest constant speed at which ``metric`` <= ``threshold`` (module docstring).

    Parameters
    ----------
    base, path
        The design's machine table and file.
    threshold : float
        Limit of the metric (its SI unit).
    metric : str
        An objective name (:data:`braidsim.design.evaluate.OBJECTIVES`).
    overrides : mapping, optional
        Scenario overrides (the setting).
    profile : SpeedProfile, optional
        Relative speed profile scaled with the mean (default constant).
    options : SpeedLimitOptions
        Scan range and refinement.
    nominal_speed : float, optional
        The speed the range is relative to [rad/s] (default: the machine's mean speed).
    cycles : float
        Simulated transfer cycles per speed.
    """
    opt = options or SpeedLimitOptions()
    if nominal_speed is None:
        from braidsim.design.evaluate import machine_for

        nominal_speed = machine_for(base, path, overrides=overrides).mean_speed
    speeds: list[float] = []
    values: list[float] = []

    def value(w: float) -> float:
        ev = evaluate(base, path, profile, overrides, speed=w, cycles=cycles)
        v = ev.metrics[metric]
        speeds.append(w)
        values.append(v)
        return v if math.isfinite(v) else math.inf

    grid = np.linspace(opt.low, opt.high, opt.points) * nominal_speed
    lo_ok = math.nan
    hi_bad = math.nan
    for w in grid:
        if value(float(w)) <= threshold:
            lo_ok = float(w)
        else:
            hi_bad = float(w)
            break
    if math.isnan(lo_ok):
        return SpeedLimit(math.nan, "below_range", speeds, values, (math.nan, hi_bad))
    if math.isnan(hi_bad):
        return SpeedLimit(math.nan, "above_range", speeds, values, (lo_ok, math.nan))
    a, b = lo_ok, hi_bad
    for _ in range(opt.refine):
        mid = 0.5 * (a + b)
        if value(mid) <= threshold:
            a = mid
        else:
            b = mid
    # the limit lies in [a, b]; report its midpoint
    return SpeedLimit(0.5 * (a + b), "found", speeds, values, (a, b))
