"""Continuation against references computed another way (slow: tens of seconds each).

* The stable branches against the brute-force stroboscopic bifurcation diagram of
  :mod:`braidsim.analysis` over the same range (settled runs, no Newton), and the detected
  period doubling against the diagram's change from period 1 to period 2.
* The lift-off (the grazing where the resting contact's depth first touches zero) against
  the analytic contact-loss bound h_a omega_h^2 = a_p of a rigid contact, approached as the
  contact stiffness grows, and against plain runs: where the resting carrier stays on the
  wall, and where its least depth over a settled cycle extrapolates to zero.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest

import braidsim
from braidsim.analysis import bifurcation
from braidsim.analysis.regimes import contact_loss_bound
from braidsim.continuation import ScenarioSystem, seed_orbit, solve_fixed
from braidsim.continuation.branch import continue_orbit, orbit_at

HA = "track.vibration_amplitude"
pytestmark = pytest.mark.slow


def test_stable_branch_and_doubling_match_brute_force() -> None:
    sc = braidsim.load_scenario("paper-3.3")
    system = ScenarioSystem(sc)
    seed = seed_orbit(system, {HA: 0.1e-3}, 1, method="fd")
    br = continue_orbit(
        system,
        seed,
        HA,
        0.125e-3,
        both_directions=True,
        bounds=(0.09e-3, 0.125e-3),
        method="fd",
        max_depth=1,
    )
    (pd,) = [s for s in br.special if s.type == "period_doubling"]
    values = np.array([0.095, 0.0975, 0.1, 0.1025, 0.115, 0.1175, 0.1225]) * 1e-3
    diag = bifurcation(sc, HA, values, transient_cycles=300, cycles=24)
    L = 1e-4
    matched = 0
    for v, st in zip(values, diag.states, strict=True):
        if st.regime.label != "periodic_one_sided":
            continue  # another attractor (chatter) that the start happened to find
        if st.regime.period == 1:
            o = orbit_at(system, br, float(v), method="fd")
            assert o.stable
            assert abs(o.profile.strobe_u[0] - np.median(st.strobe_u)) < 1e-3 * L
            matched += 1
        elif st.regime.period == 2:
            # beyond the doubling: the period-2 branch switched to there
            assert v > pd.value
            (child,) = br.children
            o2 = orbit_at(system, child, float(v), method="fd")
            assert o2.stable
            brute = np.sort(np.unique(np.round(st.strobe_u, 9)))[[0, -1]]
            assert np.allclose(np.sort(o2.profile.strobe_u), brute, atol=1e-2 * L)
            matched += 1
    assert matched >= 6
    # the diagram's period 1 -> 2 change brackets the located doubling
    per = dict(zip(values, diag.periods, strict=True))
    assert per[0.1175e-3] == 1 and per[0.1225e-3] == 2
    assert 0.1175e-3 < pd.value < 0.1225e-3


def test_lift_off_approaches_the_rigid_contact_bound() -> None:
    """|h_lift / (a_p / omega_h^2) - 1| falls as K grows (friction off, as the bound
    assumes) and is below 2 % at K = 1e11 N/m^1.5 (the resting contact latched at the
    speed floor is overdamped: it holds on past the bound at low stiffness)."""
    errors = []
    for K in (1e8, 1e9, 1e10, 1e11):
        sc = braidsim.load_scenario(
            "paper-3.3", overrides={"friction.law": "none", "contact.track.stiffness": K}
        )
        system = ScenarioSystem(sc)
        o = seed_orbit(system, {HA: 0.05e-3}, 1, method="exact")
        assert o.profile.impacts == 0  # resting on the inner wall
        br = continue_orbit(system, o, HA, 0.12e-3, method="exact", switch=False, max_points=60)
        g = [s for s in br.special if s.type == "grazing"]
        bound = contact_loss_bound(sc)["critical_amplitude"]
        errors.append(g[0].value / bound - 1.0)
    print("lift-off / bound - 1:", errors)
    assert all(abs(b) < abs(a) for a, b in itertools.pairwise(errors))
    assert abs(errors[-1]) < 0.02


def test_period_doubling_curve_of_the_carrier_against_branches() -> None:
    """The 4 pi rad/s period doubling followed in omega on the augmented system ends on
    omega = 5 pi rad/s where a branch in h_a at 5 pi rad/s through the curve's orbit has its
    doubling (the one-parameter root solve), and plain runs of the simulator started on
    the orbit settle on period 1 at 2 % below it and on period 2 at 3 % above it."""
    import math

    om = "horn_gear.angular_velocity"
    sc = braidsim.load_scenario("paper-3.3")
    system = ScenarioSystem(sc)
    seed = seed_orbit(system, {HA: 0.1e-3}, 1, method="exact")
    br = continue_orbit(system, seed, HA, 0.13e-3, method="exact", switch=False)
    (pd,) = [s for s in br.special if s.type == "period_doubling"]
    from braidsim.continuation.twopar import trace_boundary

    c = trace_boundary(
        system, br, pd, om, 5 * math.pi, steps=4, method="exact", range1=(0.05e-3, 0.3e-3)
    )
    assert c.p2[-1] == pytest.approx(5 * math.pi)
    h_pd = c.p1[-1]
    end = c.orbits[-1]
    assert end is not None and end.profile.impacts == 1
    from braidsim.continuation.fdmap import advance
    from braidsim.continuation.orbit import solve_fixed

    # a branch in h_a at 5 pi rad/s through the end point locates the same doubling
    below = solve_fixed(
        system, {**end.values, HA: 0.97 * h_pd}, 1, end.phase, end.cuts, end.z, "exact"
    )
    b5 = continue_orbit(
        system, below, HA, 1.03 * h_pd, method="exact", switch=False, step=0.05, max_step=0.2
    )
    (pd5,) = [s for s in b5.special if s.type == "period_doubling"]
    assert h_pd == pytest.approx(pd5.value, rel=1e-6)
    # brute force: runs from the orbit settle on period 1 below it and period 2 above it
    for f, period in ((0.98, 1), (1.03, 2)):
        vals = {**end.values, HA: f * h_pd}
        prep = system.prepare(vals)
        T = prep.period
        t0 = end.phase / prep.omega
        c0 = end.cuts[0]
        run = advance(prep, t0, t0 + 1500 * T, end.z[0][:2], c0.modes, c0.v0s(end.z[0][2:]))
        st = t0 + 1500 * T + T * np.arange(9)
        seg = advance(prep, st[0], st[-1], run.y1, run.modes1, run.v0s1, st)
        assert seg.series is not None
        rows = seg.series[np.isin(seg.series[:, 0], st)]
        _, first = np.unique(rows[:, 0], return_index=True)  # (an event row may repeat one)
        x = rows[first, 1]
        assert x.size == 9
        spread = np.ptp(x[::2]), np.ptp(x[1::2]), abs(x[0] - x[1])
        if period == 1:
            assert abs(x[0] - x[1]) < 1e-9
        else:
            assert spread[0] < 1e-9 and spread[1] < 1e-9 and spread[2] > 1e-7


def _onsets_after(system, orbit, values, cycles: int) -> int:
    """Contact onsets in the last 20 of ``cycles`` forcing cycles of a plain run started on
    ``orbit``'s state at ``values``."""
    from braidsim.continuation.fdmap import advance

    prep = system.prepare(values)
    T = prep.period
    t0 = orbit.phase / prep.omega
    c0 = orbit.cuts[0]
    run = advance(
        prep, t0, t0 + (cycles - 20) * T, orbit.z[0][:2], c0.modes, c0.v0s(orbit.z[0][2:])
    )
    t1 = t0 + (cycles - 20) * T
    seg = advance(prep, t1, t1 + 20 * T, run.y1, run.modes1, run.v0s1, t1 + T * np.arange(21))
    return int(np.count_nonzero(seg.episodes["initial"] == 0.0))


def _least_depth_after(system, orbit, values, cycles: int) -> float:
    """The least depth into the inner wall [m] over the last of ``cycles`` forcing cycles of
    a plain run started on ``orbit``'s state at ``values`` (a carrier resting on it)."""
    from braidsim.continuation.fdmap import advance
    from braidsim.core.models.carrier import CARRIER_COLUMNS

    prep = system.prepare(values)
    T = prep.period
    t0 = orbit.phase / prep.omega
    c0 = orbit.cuts[0]
    run = advance(prep, t0, t0 + (cycles - 1) * T, orbit.z[0][:2], c0.modes, c0.v0s(orbit.z[0][2:]))
    t1 = t0 + (cycles - 1) * T
    seg = advance(prep, t1, t1 + T, run.y1, run.modes1, run.v0s1, np.linspace(t1, t1 + T, 4001))
    assert seg.series is not None and seg.episodes.size == 1  # on the wall throughout
    return float(-np.max(seg.series[:, CARRIER_COLUMNS.index("track_depth")]))


def test_lift_off_in_the_clearance_speed_plane() -> None:
    """The resting carrier's lift-off on the (clearance, speed) map at h_a = 0.1 mm, met by
    a branch over the speed and followed in the clearance: it does not depend on the
    clearance (the resting carrier never nears the outer wall); a branch over h_a at that
    speed lifts off at h_a = 0.1 mm; a plain run started on the resting orbit stays on the
    wall 1 % above that speed and leaves it 1 % below."""
    import math

    from braidsim.continuation.twopar import crossing_boundaries

    om, cl = "horn_gear.angular_velocity", "track.clearance"
    sc = braidsim.load_scenario("paper-3.3", overrides={HA: 0.1e-3})
    system = ScenarioSystem(sc)
    _, (c,) = crossing_boundaries(
        system,
        cl,
        1.2e-3,
        om,
        6 * math.pi,
        3 * math.pi,
        0.2e-3,
        steps=2,
        method="fd",
        branch_options={"max_points": 12, "step": 0.05, "max_step": 0.25},
    )
    assert c.name == "lift-off" and c.key1 == om and c.key2 == cl
    assert c.p2[0] == pytest.approx(1.2e-3) and c.p2[-1] == pytest.approx(0.2e-3)
    w_lift = c.p1[0]
    assert 4 * math.pi < w_lift < 4.5 * math.pi
    assert np.allclose(c.p1, w_lift, rtol=1e-5, atol=0)
    # the same lift-off met along h_a at that speed
    sys_w = ScenarioSystem(braidsim.load_scenario("paper-3.3", overrides={om: w_lift}))
    rest = seed_orbit(sys_w, {HA: 0.05e-3}, 1, method="fd")
    assert rest.profile.impacts == 0
    b = continue_orbit(sys_w, rest, HA, 0.12e-3, method="fd", switch=False, max_points=40)
    g = [s for s in b.special if s.type == "grazing"]
    assert g[0].value == pytest.approx(0.1e-3, rel=1e-6)  # (measured: 2e-13)
    # plain runs from the resting orbit next to the lift-off (the curve's last point)
    o = c.orbits[-1]
    assert o is not None and o.profile.impacts == 0
    assert _onsets_after(system, o, {**o.values, om: 1.01 * w_lift}, 300) == 0
    assert _onsets_after(system, o, {**o.values, om: 0.99 * w_lift}, 300) > 0


def test_lift_off_does_not_depend_on_the_seed() -> None:
    """The resting contact's latched speed is the law's floor, whatever run seeded the
    orbit: the lift-off curve followed in omega from a branch seeded at 4 pi rad/s, and a
    branch over h_a seeded by its own run at the curve's last speed, lift off at the same
    h_a (the seeding runs latch different speeds, 2.0e-3 m/s at 4 pi and 6.3e-3 m/s at
    4.5 pi; kept, they moved the lift-off by 0.4 %)."""
    import math

    from braidsim.continuation.twopar import trace_boundary

    om = "horn_gear.angular_velocity"
    system = ScenarioSystem(braidsim.load_scenario("paper-3.3"))
    rest = seed_orbit(system, {HA: 0.05e-3}, 1, method="fd")
    assert rest.cuts[0].v0_fixed[0] == pytest.approx(1e-4)
    br = continue_orbit(system, rest, HA, 0.15e-3, method="fd", switch=False, max_points=40)
    (g, *_) = [s for s in br.special if s.type == "grazing"]
    c = trace_boundary(
        system, br, g, om, 4.5 * math.pi, steps=2, method="fd", range1=(0.05e-3, 0.2e-3)
    )
    w2, h2 = c.p2[-1], c.p1[-1]
    assert w2 > 4.2 * math.pi
    sys2 = ScenarioSystem(braidsim.load_scenario("paper-3.3", overrides={om: w2}))
    rest2 = seed_orbit(sys2, {HA: 0.05e-3}, 1, method="fd")
    assert rest2.cuts[0].v0_fixed[0] == pytest.approx(1e-4)
    br2 = continue_orbit(sys2, rest2, HA, 0.15e-3, method="fd", switch=False, max_points=40)
    (g2, *_) = [s for s in br2.special if s.type == "grazing"]
    print("lift-off:", w2 / math.pi, h2, g2.value, c.stop)
    assert h2 == pytest.approx(g2.value, rel=1e-4)


def test_lift_off_where_newton_meets_the_maps_noise() -> None:
    """At 4.5 pi rad/s the resting orbit's least depth falls to zero at h_a = 0.11853 mm,
    where plain runs started on it (its least depth, from 4001 samples of a settled cycle,
    extrapolated linearly from 0.995, 0.997 and 0.999 of that h_a) put it too. Next to it
    the flow map's noise (1e-9 to 1e-8 of the scaled residual: the force of the damped
    contact sits at zero for a tenth of the cycle) makes Newton's method at the
    continuation's tolerance fail erratically; the branch located the lift-off 0.37 % short,
    at 0.11809 mm, where it first failed."""
    import math

    om = "horn_gear.angular_velocity"
    system = ScenarioSystem(braidsim.load_scenario("paper-3.3", overrides={om: 4.5 * math.pi}))
    rest = seed_orbit(system, {HA: 0.05e-3}, 1, method="fd")
    br = continue_orbit(system, rest, HA, 0.15e-3, method="fd", switch=False, max_points=40)
    (g, *_) = [s for s in br.special if s.type == "grazing"]
    (o, *_) = [p for p in reversed(br.points) if p.values[HA] < g.value]
    levels = np.array([0.995, 0.997, 0.999]) * g.value
    depths = []
    for a in np.linspace(o.values[HA], levels[0], 4)[1:].tolist() + levels[1:].tolist():
        # the resting orbit carried up in short steps, a plain run started on it at each
        # level (a jump in h_a would move the wall under the carrier and kick it off)
        o = solve_fixed(system, {HA: a}, o.period, o.phase, o.cuts, o.z, "fd")
        assert o.profile.impacts == 0
        if a >= levels[0]:
            depths.append(_least_depth_after(system, o, {HA: a}, 300))
    slope, icpt = np.polyfit(levels, depths, 1)
    print("lift-off:", g.value, "least depths:", depths, "their zero:", -icpt / slope)
    assert -icpt / slope == pytest.approx(g.value, rel=2e-4)  # (measured: 7e-5)


def test_period_doubling_curve_ends_where_its_orbit_grazes_the_outer_wall() -> None:
    """The carrier's doubling curve over (h_a, omega), followed from 4 pi rad/s, goes on
    past 7.39 pi rad/s, where the corrector used to stall on the central-difference
    monodromy's noise (the exact map takes over), and ends where its orbit's flight reaches
    the outer wall: a grazing-doubling point, the multiplier -1 there and the gap to the
    wall down to the integrator's noise."""
    import math

    from braidsim.continuation.twopar import trace_boundary

    om = "horn_gear.angular_velocity"
    system = ScenarioSystem(braidsim.load_scenario("paper-3.3"))
    seed = seed_orbit(system, {HA: 0.1e-3}, 1, method="fd")
    br = continue_orbit(system, seed, HA, 0.13e-3, method="fd", switch=False)
    (pd,) = [s for s in br.special if s.type == "period_doubling"]
    c = trace_boundary(
        system, br, pd, om, 10 * math.pi, steps=8, method="fd", range1=(0.02e-3, 0.6e-3)
    )
    assert c.end == "grazing", c.stop
    end = c.orbits[-1]
    assert end is not None
    assert 9.4 * math.pi < c.p2[-1] < 9.6 * math.pi
    assert 0.5e-3 < c.p1[-1] < 0.53e-3
    assert end.profile.min_gap < 1e-7
    # the flight's highest point is at the outer wall (the clearance)
    assert end.profile.u_max == pytest.approx(system.value("track.clearance"), abs=1e-7)
    assert abs(end.multipliers[0] + 1) < 1e-6
    # the curve is the doubling all along: at most the corrector's noise in det(M + I)
    assert max(abs(r) for r in c.residuals) < 1e-5


def test_lift_off_curve_of_the_paper_example_reaches_the_edge_of_its_range() -> None:
    """`examples/continuation_paper.toml` with the implicit step for resting contacts: the
    lift-off curve followed in omega ends with a point on the range's edge, 5 pi rad/s, at
    the h_a where a branch over h_a at 5 pi lifts off. (That point was lost: the search
    along the edge started from the last point's h_a, and Newton's method carried the
    resting orbit from orbits next to the lift-off onto the coexisting bouncing one.)"""
    import math
    from pathlib import Path

    from braidsim.continuation.study import load_spec, run_study

    om = "horn_gear.angular_velocity"
    ex = Path(__file__).resolve().parents[2] / "examples" / "continuation_paper.toml"
    spec = load_spec(ex)
    over = {"simulation.resting_contacts": "implicit"}
    spec = replace(spec, scenario=spec.scenario.with_overrides(over))
    (c,) = run_study(spec).curves
    assert c.name == "lift-off" and c.stop == f"left the range of {om} at {5 * math.pi:.6g}"
    assert len(c.p1) == 3 and c.p2[-1] == pytest.approx(5 * math.pi, rel=1e-12)
    system = ScenarioSystem(braidsim.load_scenario("paper-3.3", overrides={**over, om: c.p2[-1]}))
    rest = seed_orbit(system, {HA: 0.05e-3}, 1, method="fd")
    br = continue_orbit(system, rest, HA, 0.15e-3, method="fd", switch=False, max_points=40)
    (g, *_) = [s for s in br.special if s.type == "grazing"]
    print("edge:", c.p1[-1], "branch:", g.value)
    assert c.p1[-1] == pytest.approx(g.value, rel=1e-6)  # (measured: 3e-9)
