"""Time scales of a scenario's motion in closed form, to check a record's time column
before any simulation (:func:`braidsim.fit.estimate.fit_record`).

Two bounds, each the largest over the variants of the scenario that the fit may reach
(:func:`variants`: the start values, the corners of the free parameters' box and the
contact laws compared):

- :func:`pulse_duration`: the elastic contact duration of an impact of a given peak force,
  ``T = 2 p_m / v0 * B(1/(n+1), 1/2) / (n+1)`` with the depth ``p_m = (F / K)^(1/n)`` and
  the approach speed ``v0 = sqrt(2 K p_m^(n+1) / ((n+1) m))`` of that impact [s];
- :func:`longest_flight`: the longest flight of the carrier between two track impacts,
  ``2 sqrt(2 H / a)`` with ``H`` the clearance plus twice the walls' excursion [m] and
  ``a = (L_min - f_max) / m`` the least net acceleration towards the inner wall [m/s^2]:
  the constant load less the largest friction force.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

from braidsim.errors import InputError
from braidsim.fit.spec import FreeParameter, scenario_values
from braidsim.params import Scenario

#: corners of the free parameters' box evaluated at most (2^10); with more free parameters,
#: each at its two bounds alone, the others at their start
MAX_CORNERS = 1024


def variants(
    scenario: Scenario, free: Sequence[FreeParameter], laws: Sequence[str] = ()
) -> list[Scenario]:
    """``scenario`` at the start values and at every corner of the box of the ``free``
    parameters (each at its start and both bounds where the corners would be more than
    :data:`MAX_CORNERS`), each with the track law of the scenario and of ``laws``.

    A corner the scenario refuses (an override out of its range) is left out."""
    start = {p.key: p.start for p in free}
    if 2 ** len(free) <= MAX_CORNERS:
        points = [start] + [
            dict(zip(start, c, strict=True))
            for c in itertools.product(*((p.low, p.high) for p in free))
        ]
    else:
        points = [start] + [{**start, p.key: v} for p in free for v in (p.low, p.high)]
    own = str(scenario["contact.track.model"])
    out = []
    for point in points:
        for law in dict.fromkeys([own, *laws]):
            try:
                out.append(
                    scenario.with_overrides(
                        {**scenario_values(point), "contact.track.model": law}, check_start=False
                    )
                )
            except InputError:
                continue
    return out


def pulse_duration(scenario: Scenario, peak_force: float) -> float:
    """Contact duration [s] of an elastic impact ``m p'' = -K p^n`` of the track contact
    whose peak force is ``peak_force`` [N] (see the module docstring); inf for a force
    <= 0.

    At a given peak force ``T`` scales as ``sqrt(m / K) (F / K)^((1 - n) / (2 n))``: for
    n > 1 the impact of the smallest peak lasts longest."""
    from scipy import special

    from braidsim.model import pair_model

    if not peak_force > 0:
        return math.inf
    pm = pair_model(scenario, "track")
    k, n, m = pm.stiffness, pm.exponent, float(scenario["carrier.mass"])
    # In logarithms: with v0 eliminated, T = 2 B / (n+1) sqrt((n+1) m / (2 K))
    # p_m^((1-n)/2). The powers p_m^(n+1) of the direct form overflow for a peak force far
    # beyond the physical (a glitch of 1e200 m/s^2 in a record raised OverflowError), where
    # this one only gives a duration of 0 or inf.
    log_depth = (math.log(peak_force) - math.log(k)) / n
    log_t = (
        math.log(2.0 * float(special.beta(1.0 / (n + 1.0), 0.5)) / (n + 1.0))
        + 0.5 * math.log((n + 1.0) * m / (2.0 * k))
        + 0.5 * (1.0 - n) * log_depth
    )
    return math.exp(log_t) if log_t < 700.0 else math.inf


def longest_flight(scenario: Scenario) -> float:
    """The longest flight [s] of the carrier between two track impacts, ``2 sqrt(2 H / a)``
    (see the module docstring); inf where the least load does not exceed the largest
    friction force (the carrier may then stop between the walls).

    A flight rises against ``a_up = (L + f) / m >= a`` and falls back with ``a_down =
    (L - f) / m >= a``, and its apex lies below the outer wall's highest position, at most
    ``H`` above the inner wall's lowest one: each half lasts at most ``sqrt(2 H / a)``,
    however the carrier was launched (a wall, a transfer).

    ``L_min = T1 cos(phi) + m r_c omega_min^2`` [N] (omega_min the horn gear's slowest
    speed: its mean less its harmonics' amplitudes, or the profile's slowest knot, and 0
    where the speed may change sign) and ``f_max = mu1 r_s |m g - T2|`` [N] (r_s the static
    ratio of the Stribeck law, 1 otherwise).
    """
    from braidsim.model import build_model

    rec = build_model(scenario).record
    hg = rec.horn_gear
    if hg.profile_speeds.size:
        omega_min = max(float(hg.profile_speeds.min()), 0.0)
    else:
        omega_min = max(hg.omega0 - float(abs(hg.harmonics[:, 0]).sum()), 0.0)
    load = rec.load_x + rec.mass_radius * omega_min**2
    law = scenario["friction.law"]
    friction = 0.0 if law == "none" else rec.mu_x * rec.normal_x
    if law == "stribeck":
        friction *= rec.friction.static_ratio
    a = (load - friction) / rec.mass
    if not a > 0:
        return math.inf
    excursion = float(abs(rec.track.table[:, 0]).sum())
    height = rec.track_clearance + 2.0 * excursion
    return 2.0 * math.sqrt(2.0 * height / a)
