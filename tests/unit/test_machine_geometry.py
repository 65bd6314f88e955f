"""Machine geometry and kinematics: ring, paths, slots, transfers, loadings, speed law.

The checks compare the exact (integer) geometry with plain floating-point constructions
(circle centres, tangency points, slot directions) and with the braiding literature's
statements: full loading of 4-slot horn gears braids 2/2, half of it 1/1, and 3/3 Hercules
needs 6-slot gears (Kyosev, Braiding Technology for Textiles, 2015, ch. 3).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

import braidsim
from braidsim.errors import InputError
from braidsim.machine.geometry import (
    Loading,
    MachineGeometry,
    braid_pattern,
    custom_loading,
    find_collisions,
    interlacing,
    loading_pattern,
)
from braidsim.machine.kinematics import (
    SpeedLaw,
    braid_angle,
    carrier_angular_speed,
    cycle_profile,
    revolution_time,
    take_up_speed,
)
from braidsim.model import build_model

SIZES = [(4, 4), (6, 4), (8, 4), (12, 4), (8, 6), (10, 6), (8, 8)]
R = 0.065


def _polar(p: np.ndarray) -> np.ndarray:
    return np.arctan2(p[..., 1], p[..., 0])


@pytest.mark.parametrize(("N", "S"), SIZES)
def test_ring_of_tangent_pitch_circles(N: int, S: int) -> None:
    g = MachineGeometry(N, S, pitch_radius=R)
    c = g.gear_centres
    assert g.ring_radius == pytest.approx(R / math.sin(math.pi / N), rel=1e-14)
    # neighbouring pitch circles touch: centre distance 2 r, crossing r from both centres
    d = np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1)
    np.testing.assert_allclose(d, 2 * R, rtol=1e-13)
    for k in range(N):
        for gear in (k, (k + 1) % N):
            assert np.linalg.norm(g.crossings[k] - c[gear]) == pytest.approx(R, rel=1e-12)
    np.testing.assert_allclose(
        np.linalg.norm(g.crossings, axis=1), g.ring_radius * math.cos(math.pi / N), rtol=1e-13
    )
    # the same machine from its ring radius
    g2 = MachineGeometry(N, S, ring_radius=g.ring_radius)
    assert g2.pitch_radius == pytest.approx(R, rel=1e-14)
    # adjacent gears counter-rotate, all the way round the ring
    assert all(g.sense(i) == -g.sense((i + 1) % N) for i in range(N))


@pytest.mark.parametrize(("N", "S"), SIZES)
def test_paths_closed_alternating_arcs_switch_at_tangency_points(N: int, S: int) -> None:
    g = MachineGeometry(N, S, pitch_radius=R)
    q = g.quantum
    for group in ("A", "B"):
        arcs = g.paths[group]
        angles = [a.angle * q for a in arcs]
        # arc angles add up to N pi; inner and outer alternate and make a full turn together
        assert sum(angles) == pytest.approx(N * math.pi, rel=1e-14)
        sides = [a.side for a in arcs]
        assert all(s1 != s2 for s1, s2 in zip(sides, sides[1:] + sides[:1], strict=True))
        assert g.inner_arc * q == pytest.approx(math.pi - 2 * math.pi / N)
        assert g.outer_arc * q == pytest.approx(math.pi + 2 * math.pi / N)
        assert g.outer_arc > g.inner_arc
        # closed: the end of the last arc is the start of the first
        b = g.path_boundaries(group)
        p0, p1 = g.path_point(group, np.array([0.0, float(g.path_period) - 1e-9]))
        assert np.linalg.norm(p0 - p1) < 1e-9
        # every arc ends on the tangency point of its crossing, and the next arc starts there
        for m, a in enumerate(arcs):
            end = float(b[m + 1])
            before, after = g.path_point(group, np.array([end - 1e-7, end + 1e-7]))
            x = g.crossings[a.crossing_out]
            assert np.linalg.norm(before - x) < 1e-8 and np.linalg.norm(after - x) < 1e-8
            assert arcs[(m + 1) % N].crossing_in == a.crossing_out
            nxt = arcs[(m + 1) % N].gear
            assert {a.gear, nxt} == {a.crossing_out, (a.crossing_out + 1) % N}
        # group A outside on counter-clockwise (even) gears, group B inside there
        for a in arcs:
            outer_expected = (a.gear % 2 == 0) == (group == "A")
            assert (a.side == "outer") == outer_expected
            mid = g.path_point(group, np.array([a.path_start + 0.5 * a.angle]))[0]
            r_mid = np.linalg.norm(mid)
            assert (r_mid > g.ring_radius) == (a.side == "outer")


@pytest.mark.parametrize(("N", "S"), SIZES)
def test_slots_meet_at_every_crossing_and_lanes_ride_in_slots(N: int, S: int) -> None:
    g = MachineGeometry(N, S, pitch_radius=R)
    q = g.quantum
    assert g.slot_misalignment("A") == [0] * N
    assert g.slot_misalignment("B") == [0] * N
    c = g.gear_centres
    for k in range(N):
        om = g.meshing_phase(k) * q
        # a slot of each of the two gears points at the tangency point at the same rotation
        for gear in (k, (k + 1) % N):
            ang = g.slot_angles(gear, om)
            tips = c[gear] + R * np.column_stack([np.cos(ang), np.sin(ang)])
            assert np.min(np.linalg.norm(tips - g.crossings[k], axis=1)) < 1e-12
    # every lane sits in a slot of the gear it is on, at any rotation
    carriers = [("A", k) for k in range(g.lanes)] + [("B", k) for k in range(g.lanes)]
    oms = np.array([0.1234, 1.0, 2.5, 7.77])
    pos = g.carrier_points(carriers, oms)
    for i, om in enumerate(oms):
        for j, (grp, lane) in enumerate(carriers):
            gear = g.carrier_gear(grp, lane, om)
            ang = g.slot_angles(gear, om)
            tips = c[gear] + R * np.column_stack([np.cos(ang), np.sin(ang)])
            assert np.min(np.linalg.norm(tips - pos[i, j], axis=1)) < 1e-12


def test_groups_travel_in_opposite_directions() -> None:
    g = MachineGeometry(8, 4, pitch_radius=R)
    om = np.linspace(0.0, 8 * math.pi, 4001)
    pos = g.carrier_points([("A", 0), ("B", 1)], om)
    da = np.diff(np.unwrap(_polar(pos[:, 0])))
    db = np.diff(np.unwrap(_polar(pos[:, 1])))
    assert np.all(da >= -1e-12) and np.all(db <= 1e-12)
    # one revolution round the machine per N pi of horn-gear rotation
    assert np.unwrap(_polar(pos[:, 0]))[-1] - _polar(pos[0, 0]) == pytest.approx(2 * math.pi)
    assert np.unwrap(_polar(pos[:, 1]))[-1] - _polar(pos[0, 1]) == pytest.approx(-2 * math.pi)


@pytest.mark.parametrize(("N", "S"), [(8, 4), (6, 4), (8, 6)])
def test_transfer_events_follow_arcs_and_land_on_crossings(N: int, S: int) -> None:
    g = MachineGeometry(N, S, pitch_radius=R)
    q = g.quantum
    for group, lane in (("A", 0), ("A", 3), ("B", 1), ("B", 2)):
        ev = g.transfer_events(group, lane, 3 * g.path_period)
        assert len(ev) == 3 * N
        gaps = {b.angle - a.angle for a, b in itertools.pairwise(ev)}
        assert gaps == {g.inner_arc, g.outer_arc}
        for a, b in itertools.pairwise(ev):
            # the gap after a transfer is the arc it starts
            assert b.angle - a.angle == (g.inner_arc if a.next_side == "inner" else g.outer_arc)
            step = 1 if group == "A" else -1
            assert b.from_gear == a.to_gear and (a.to_gear - a.from_gear) % N == step % N
        for e in ev[:N]:
            # at the transfer the carrier is on the tangency point ...
            p = g.carrier_points([(group, lane)], np.array([e.angle * q]))[0, 0]
            assert np.linalg.norm(p - g.crossings[e.crossing]) < 1e-12
            # ... and the slots meet there: every transfer is on a slot meeting of its crossing
            assert (e.angle - g.meshing_phase(e.crossing)) % g.slot_pitch == 0
            assert e.angle % g.transfer_cycle in g.transfer_phases
    g8 = MachineGeometry(8, 4, pitch_radius=R)
    assert g8.transfer_cycle * g8.quantum == pytest.approx(math.pi / 4)
    assert g8.transfer_phases == (0,)


@pytest.mark.parametrize(
    ("N", "S", "pattern", "braid", "per_group"),
    [
        (8, 4, "full", "2/2", 8),
        (8, 4, "regular", "2/2", 8),
        (8, 4, "diamond", "1/1", 4),
        (12, 4, "diamond", "1/1", 6),
        (8, 6, "hercules", "3/3", 12),
        (8, 6, "regular", "2/2", 8),
        (8, 8, "full", "4/4", 16),
    ],
)
def test_named_loadings_are_collision_free_with_their_braid(
    N: int, S: int, pattern: str, braid: str, per_group: int
) -> None:
    g = MachineGeometry(N, S, pitch_radius=R)
    ld = loading_pattern(g, pattern)
    assert len(ld.lanes_a) == len(ld.lanes_b) == per_group
    assert find_collisions(g, ld) == []
    assert braid_pattern(g, ld) == braid
    k = int(braid[0])
    assert all(v == [k] * N for v in interlacing(g, ld).values())


def test_full_loading_keeps_carriers_apart_geometrically() -> None:
    """Independent of the exact check: on a fine grid of rotations no two carriers of the
    full loading come close, while the two carriers of a reported collision meet."""
    g = MachineGeometry(8, 4, pitch_radius=R)
    full = loading_pattern(g, "full")
    om = np.linspace(0.0, 8 * math.pi, 16001)
    pos = g.carrier_points(full.carriers, om)
    d = np.linalg.norm(pos[:, :, None, :] - pos[:, None, :, :], axis=-1)
    d[:, np.arange(d.shape[1]), np.arange(d.shape[1])] = np.inf
    assert d.min() > 0.3 * R
    # A0 with B2 collides (exact check); the two carriers do meet
    bad = Loading("custom", (0,), (2,))
    hits = find_collisions(g, bad)
    assert hits
    p = g.carrier_points(bad.carriers, om)
    assert np.linalg.norm(p[:, 0] - p[:, 1], axis=-1).min() < 1e-3 * R


def test_colliding_patterns_are_rejected_naming_the_pattern() -> None:
    g = MachineGeometry(8, 4, pitch_radius=R)
    # 3/3 on 4-slot gears is more than a full loading (2/2): said so, not as a collision
    with pytest.raises(InputError, match=r"'hercules' \(3/3\) needs at least 6 slots per"):
        loading_pattern(g, "hercules")
    with pytest.raises(InputError, match=r"pattern 'custom' is not collision-free: carriers A0"):
        custom_loading(g, [0], [2])
    with pytest.raises(InputError, match=r"share one slot"):
        custom_loading(g, [2, 2], [])
    with pytest.raises(InputError, match=r"lane 16 of group A does not exist"):
        custom_loading(g, [16], [])
    with pytest.raises(InputError, match=r"did you mean 'diamond'"):
        loading_pattern(g, "diamnd")
    # at most N S / 2 carriers fit (one per slot meeting at every crossing)
    lanes = list(range(0, 16, 2))
    ok = custom_loading(g, lanes, [k + 1 for k in lanes])
    assert len(ok.carriers) == 16
    assert len(custom_loading(g, list(range(16)), []).carriers) == 16  # one group alone
    with pytest.raises(InputError, match="at most N S/2 = 16 carriers in all"):
        custom_loading(g, [*lanes, 1], [k + 1 for k in lanes])


@pytest.mark.parametrize(
    ("N", "S", "ring"), [(3, 4, None), (8, 3, None), (2, 4, None), (8, 4, -1.0)]
)
def test_bad_machine_numbers(N: int, S: int, ring: float | None) -> None:
    with pytest.raises(InputError, match=r"machine\."):
        if ring is None:
            MachineGeometry(N, S, pitch_radius=R)
        else:
            MachineGeometry(N, S, ring_radius=ring)
    with pytest.raises(InputError, match="exactly one"):
        MachineGeometry(8, 4)


# ----------------------------------------------------------------------------------------
# kinematics
# ----------------------------------------------------------------------------------------


def test_designer_kinematics_closed_forms() -> None:
    w = 4 * math.pi  # 120 rpm
    wc = carrier_angular_speed(w, 8)
    assert wc == pytest.approx(math.pi)  # 30 revolutions per minute round the machine
    assert revolution_time(w, 8) == pytest.approx(2.0)
    r_m = 0.01
    # tan(alpha) = omega_c r / v: 45 deg when the take-up equals the carrier's surface speed
    assert braid_angle(wc, r_m, wc * r_m) == pytest.approx(math.pi / 4)
    assert math.tan(braid_angle(wc, r_m, 0.005)) == pytest.approx(wc * r_m / 0.005)
    assert take_up_speed(wc, r_m, braid_angle(wc, r_m, 0.007)) == pytest.approx(0.007)


def _profile_rotation(times: np.ndarray, speeds: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Omega(t) of a periodic piecewise-linear profile by the trapezoidal rule on its own
    breakpoints (exact for linear pieces), independent of the kernel."""
    period = times[-1] - times[0]
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (speeds[1:] + speeds[:-1]) * np.diff(times))])
    out = np.empty_like(t)
    for i, ti in enumerate(t):
        k, tau = divmod(ti - times[0], period)
        j = min(np.searchsorted(times, times[0] + tau, side="right") - 1, times.size - 2)
        dt = times[0] + tau - times[j]
        slope = (speeds[j + 1] - speeds[j]) / (times[j + 1] - times[j])
        out[i] = k * cum[-1] + cum[j] + speeds[j] * dt + 0.5 * slope * dt * dt
    return out


def test_cycle_profile_holds_the_mean_and_the_speed_law_inverts_it() -> None:
    w = 4 * math.pi
    cyc = math.pi / 4
    table, scale = cycle_profile([0, 0.1, 0.5, 0.9, 1], [0.6, 0.8, 1.3, 0.8, 0.6], w, cyc)
    t = np.array(table["times"])
    s = np.array(table["speeds"])
    assert t[-1] == pytest.approx(cyc / w)
    # time mean of the piecewise-linear speed is the mean speed: one cycle turns Theta_c
    assert np.trapezoid(s, t) / t[-1] == pytest.approx(w, rel=1e-14)
    assert scale == pytest.approx(1 / 0.98)
    sc = braidsim.load_scenario("paper-3.2", overrides={"horn_gear.speed_profile": table})
    law = SpeedLaw.from_model(build_model(sc, 1.0))
    assert law.mean == pytest.approx(w, rel=1e-14)
    tt = np.linspace(0.0, 1.0, 37)
    om, ang = law.rotation(tt)
    np.testing.assert_allclose(ang, _profile_rotation(t, s, tt), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(om, np.interp(tt % t[-1], t, s), rtol=1e-13)
    # whole cycles at whole multiples of the cycle time
    np.testing.assert_allclose(ang[::1][tt * 16 % 1 == 0], tt[tt * 16 % 1 == 0] * w, rtol=1e-13)
    # the inverse
    targets = np.array([0.0, 0.3, math.pi / 4, 1.0, 5.0, 11.0])
    back = law.rotation(law.time_at_angle(targets))[1]
    np.testing.assert_allclose(back, targets, rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(
        law.time_at_angle([k * cyc for k in range(1, 9)]), np.arange(1, 9) / 16
    )


def test_speed_law_with_harmonics_and_its_limits() -> None:
    sc = braidsim.load_scenario(
        "paper-3.2", overrides={"horn_gear.speed_harmonics": [[3.0, 20.0, 0.3]]}
    )
    law = SpeedLaw.from_model(build_model(sc, 1.0))
    assert law.mean == pytest.approx(4 * math.pi)
    t = np.array([0.05, 0.2, 0.77])
    exact = 4 * math.pi * t + 3.0 / 20.0 * (np.sin(20.0 * t + 0.3) - math.sin(0.3))
    np.testing.assert_allclose(law.rotation(t)[1], exact, rtol=1e-14)
    np.testing.assert_allclose(law.time_at_angle(exact), t, rtol=1e-13)
    bad = sc.with_overrides({"horn_gear.speed_harmonics": [[13.0, 20.0, 0.0]]})
    with pytest.raises(InputError, match="allowed > 0 rad/s"):
        SpeedLaw.from_model(build_model(bad, 1.0))


@pytest.mark.parametrize(
    ("phase", "factor", "match"),
    [
        ([0, 0.5], [1, 1], "strictly increasing from 0 to 1"),
        ([0, 0.5, 1], [1, 0, 1], "<= 0"),
        ([0, 0.5, 1], [1, 2, 1.5], "first .* and last .* differ"),
        ([0, 1], [1], "same length"),
    ],
)
def test_cycle_profile_rejects(phase: list[float], factor: list[float], match: str) -> None:
    with pytest.raises(InputError, match=match):
        cycle_profile(phase, factor, 4 * math.pi, math.pi / 4)
