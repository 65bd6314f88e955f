"""Continuation of the xy carrier (``simulation.dof = "xy"``), whose y the horn-gear slot
carries along: its orbits repeat in the slot's frame, y - s(t), not in the ground frame.

References no one here wrote: a brute-force run from the scenario's start (its resting
contact latched at the continuation's resting speed) settles on the orbit's state at the
cut; the parameters' columns of the exact map in the slot's frame against central
differences of the runs themselves (which convert nothing but the start and the end); and
the x-only carrier's own grazing, which the slot's impacts barely move.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import braidsim
from braidsim.continuation import ScenarioSystem, seed_orbit
from braidsim.continuation.branch import continue_orbit
from braidsim.continuation.orbit import evaluate_map

HA = "track.vibration_amplitude"
OMEGA = "horn_gear.angular_velocity"


@pytest.fixture(scope="module")
def system() -> ScenarioSystem:
    return ScenarioSystem(braidsim.load_scenario("paper-3.3", overrides={"simulation.dof": "xy"}))


@pytest.fixture(scope="module")
def resting(system: ScenarioSystem):
    """At h_a = 0.05 mm the carrier rests on the inner wall and strikes the slot's front
    flank once a cycle (the run before this change failed in its seed: the cut's y was the
    ground frame's after 300 cycles, 4.1 m down the track, its time that of the first)."""
    return seed_orbit(system, {HA: 0.05e-3}, 1, method="exact")


def test_the_orbit_is_the_brute_force_runs_steady_state_in_the_slots_frame(system, resting) -> None:
    o = resting
    assert [c.modes for c in o.cuts] == [(-1, 0)]
    assert list(zip(o.profile.onset_pairs, o.profile.onset_walls, strict=True)) == [(1, 1)]
    prep = system.prepare(o.values)
    t0 = o.phase / prep.omega
    cycles = 120  # (|mu| = 0.69: 1e-19 of the start's distance left)
    sc = system.scenario.with_overrides(
        {
            HA: 0.05e-3,
            "simulation.duration": t0 + cycles * prep.period,
            "simulation.rtol": 1e-11,
            "simulation.atol_position": 1e-16,
            "simulation.atol_velocity": 1e-13,
            # the resting contact latched as continuation latches it (its module docstring)
            "contact.initial_impact_velocity": system.scenario["contact.min_impact_velocity"],
            "simulation.max_steps": 20_000_000,
        }
    )
    fs = braidsim.simulate(sc, series=False).final_state
    assert fs.track_mode == -1 and fs.slot_mode == 0
    s, _ = prep.slot_travel(fs.t)
    assert s > 1.0  # the slot carried the carrier 1.6 m in 2 s
    ground = np.array(fs.y[:4])
    L, V = system.scales(o.values)
    scale = np.array([L, V, L, V])
    off = (prep.to_slot(fs.t, ground) - o.z[0]) / scale
    assert np.abs(off).max() < 1e-7
    # one period of either map returns to the cut's state, in the slot's frame
    c0 = o.cuts[0]
    for method in ("exact", "fd"):
        fm = evaluate_map(
            system, o.values, t0, t0 + prep.period, o.z[0], c0.modes, c0.v0s(o.z[0][4:]), (),
            method,
        )  # fmt: skip
        assert np.abs((fm.y1 - o.z[0]) / scale).max() < 1e-8


def test_the_maps_parameter_columns_hold_the_slots_travel(system, resting) -> None:
    """d(y1 - s(t1))/dp at fixed y0 - s(t0): against central differences of the runs
    themselves (1e-5 relative, the differences' own error), and, for the horn-gear speed,
    against the ground frame's column of the same map with the slot's travel s = r_c omega t
    taken out by hand (paper-3.3 has no speed harmonics)."""
    from braidsim.sensitivity import flow_map

    o = resting
    prep = system.prepare(o.values)
    t0 = o.phase / prep.omega
    t1 = t0 + prep.period
    c0 = o.cuts[0]
    v0 = c0.v0s(o.z[0][4:])
    args = (t0, t1, o.z[0], c0.modes, v0, (OMEGA, HA))
    exact = evaluate_map(system, o.values, *args, "exact")
    fd = evaluate_map(system, o.values, *args, "fd")
    assert np.allclose(exact.jac_p, fd.jac_p, rtol=2e-5, atol=1e-9 * np.abs(fd.jac_p).max())
    assert np.allclose(exact.jac_y, fd.jac_y, rtol=0, atol=1e-4 * np.abs(fd.jac_y).max())
    ground = flow_map(
        system.scenario_at(o.values), t0, t1, y0=prep.to_ground(t0, o.z[0]), modes=c0.modes,
        v0s=tuple(v0), keys=(OMEGA, HA), check_start=False,
    )  # fmt: skip
    r_c = float(prep.record.horn_gear.turning_radius)
    assert not prep.record.horn_gear.harmonics.size
    by_hand = ground.jac_p[:, 0] + ground.jac_y[:, 2] * r_c * t0
    by_hand[2] -= r_c * t1
    assert np.allclose(exact.jac_p[:, 0], by_hand, rtol=1e-9, atol=1e-12)
    assert np.allclose(exact.y1, prep.to_slot(t1, ground.y1), rtol=0, atol=1e-15)
    # the slot's travel is no small correction: r_c t1 against the column's y entry
    assert r_c * t1 > 3 * abs(exact.jac_p[2, 0])


def test_the_residuals_frequency_column_moves_the_cuts_in_the_slots_frame(system, resting) -> None:
    """With the track frequency free the cut times t_j = theta_j / Omega move with it: the
    residual's column holds the flows' rates at both ends in the slot's frame (y' - s'(t)).
    Against central differences of the residual itself (1e-5 of each column: the maps' y
    error floor, docs/continuation.md)."""
    from braidsim.continuation.orbit import Shooter, frequency_key
    from reference.central_differences import residual_jacobian

    o = resting
    w = system.prepare(o.values).omega
    key = frequency_key(system)
    sh = Shooter(system, dict(o.values), key, o.period, o.phase, o.cuts, "exact", pscale=w)
    U = sh.pack(o.z, w)
    _, DR, _ = sh.residual(U)
    fd = residual_jacobian(sh, U)
    assert np.all(np.abs(DR - fd) <= 2e-5 * np.abs(fd).max(axis=0))


@pytest.mark.slow
def test_a_branch_past_the_lift_off_finds_the_x_only_carriers_next_grazing(system, resting) -> None:
    """Past the resting contact's lift-off (0.09829 mm) the contact open at the cut
    re-latches every cycle: its latched speed joins the state, and the branch re-solves the
    orbit with that cut (before, that failed silently from the resting speed, and the
    branch went on with orbits of another map). The next grazing, where the flight after
    the lift-off first touches the wall again, is where the x-only carrier has it (the
    slot's impacts barely move it) and where central differences find it. With long steps
    the grazing's bisection, cut inside that contact, met Newton failures at 0.1037 mm
    with the distance to grazing still 2.2e-7 m and reported a grazing there; it is now cut
    anew and carried on."""
    br = continue_orbit(
        system, resting, HA, 0.1075e-3, method="exact", switch=False, step=0.05, max_step=0.25
    )
    graz = [s for s in br.special if s.type == "grazing"]
    assert len(graz) == 2
    assert graz[0].value == pytest.approx(0.09829023e-3, rel=1e-7)
    for p in br.points:
        c = p.cuts[0]
        relatched = bool(np.any(p.profile.onset_pairs == 0))
        assert c.modes[0] == 0 or c.v0_state[0] == relatched, (p.values[HA], c)
    x_only = ScenarioSystem(braidsim.load_scenario("paper-3.3"))
    ox = seed_orbit(x_only, {HA: 0.104e-3}, 1, method="fd")
    bx = continue_orbit(x_only, ox, HA, 0.107e-3, method="fd", switch=False, step=0.01)
    (gx,) = [s for s in bx.special if s.type == "grazing"]
    assert gx.value == pytest.approx(1.0586878e-4, rel=1e-7)
    assert graz[1].value == pytest.approx(gx.value, rel=1e-7)
    assert math.isfinite(graz[1].orbit.profile.approach)
