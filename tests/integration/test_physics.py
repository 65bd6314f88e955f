"""The integrator against things no one here wrote: closed forms, conservation, restitution."""

from __future__ import annotations

import numpy as np
import pytest

import braidsim
from braidsim import contact
from braidsim.impact import FREE_MASS, single_impact

# a free mass between the two track walls (3 mm apart): no load, no friction, no vibration
FREE = {**FREE_MASS, "track.clearance": 3e-3}


def test_hertz_impact_matches_closed_form() -> None:
    for v, m, n in [(0.5, 1.2, 1.5), (2.0, 0.3, 1.5), (0.05, 5.0, 1.5), (0.5, 1.2, 1.08)]:
        out = single_impact("hertz", 1.0, v, m, stiffness=2.49e10 if n == 1.5 else 2e9, exponent=n)
        cf = out["closed_form"]
        assert out["max_depth"] == pytest.approx(cf["max_depth"], rel=1e-3)
        assert out["max_force"] == pytest.approx(cf["max_force"], rel=1e-3)
        assert out["contact_duration"] == pytest.approx(cf["contact_duration"], rel=1e-3)
        # and in fact much closer than the 0.1 % asked for
        assert out["max_depth"] == pytest.approx(cf["max_depth"], rel=1e-7)
        assert out["contact_duration"] == pytest.approx(cf["contact_duration"], rel=1e-7)
        assert out["effective_restitution"] == pytest.approx(1.0, abs=1e-7)


def test_elastic_energy_conserved_over_many_impacts() -> None:
    over = dict(FREE, **{"contact.track.model": "hertz", "initial.vx": 0.5, "initial.x": 1e-3})
    res = braidsim.simulate("paper-3.1", duration=0.65, overrides=over, sample_interval=0.0)
    imp = res.impacts
    assert len(imp) >= 100
    v_in = imp["velocity"].to_numpy()
    v_out = imp["rebound_velocity"].to_numpy()
    # kinetic energy before and after each impact equals the initial one
    e0 = 0.5**2
    drift_per_impact = np.abs(np.diff(np.concatenate([[e0], v_out**2]))) / e0
    assert drift_per_impact.max() <= 1e-6
    assert np.abs(v_in**2 / e0 - 1).max() <= 1e-6 * len(imp)
    assert imp["dissipated_energy"].abs().max() < 1e-9


@pytest.mark.parametrize(
    "law",
    [n for n in contact.law_names() if contact.get_law(n).dissipative],
)
def test_restitution_depends_only_on_damping_factor(law: str) -> None:
    c_r = 5.0 / 9.0
    d = contact.get_law(law).damping_factor(c_r)
    exact = contact.effective_restitution(d)
    cases = [
        dict(velocity=0.5, mass=1.2, stiffness=2.49e10, exponent=1.5),
        dict(velocity=3.0, mass=0.2, stiffness=2.49e10, exponent=1.5),
        dict(velocity=0.01, mass=4.0, stiffness=1e8, exponent=1.5),
        dict(velocity=0.5, mass=1.2, stiffness=1e7, exponent=1.0),
        dict(velocity=0.5, mass=1.2, stiffness=1e9, exponent=1.08),
    ]
    es = [single_impact(law, c_r, **case)["effective_restitution"] for case in cases]
    for e in es:
        assert e == pytest.approx(exact, abs=1e-6)


@pytest.mark.parametrize("velocity", [1e-5, 1e-9])
def test_restitution_below_the_floor_of_latched_speeds(velocity: float) -> None:
    """Below paper-3.1's floor of latched approach speeds (1e-4 m/s) the damping term was
    latched at the floor, not at the impact's speed: at 1e-5 m/s the effective restitution
    came out 0.957 for an exact 0.689, with exit code 0; and the fixed absolute tolerances
    left it 1e-6 off. The floor now goes below the measure's speed and the tolerances
    scale with it (measured: 2.4e-9 and 2.1e-9 over the ten laws)."""
    law = "hunt_crossley"
    exact = contact.effective_restitution(contact.get_law(law).damping_factor(5.0 / 9.0))
    out = single_impact(law, 5.0 / 9.0, velocity)
    assert out["effective_restitution"] == pytest.approx(exact, abs=1e-8)


def test_dissipated_energy_matches_kinetic_loss() -> None:
    out = single_impact("lankarani_nikravesh", 0.7, 0.8, 1.2)
    loss = 0.5 * 1.2 * (0.8**2 - out["rebound_velocity"] ** 2)
    assert out["dissipated_energy"] == pytest.approx(loss, rel=1e-6)


def test_resting_depth_is_static_hertz_depth() -> None:
    res = braidsim.simulate("paper-3.1", duration=0.5, windows=[(0.4, 0.5)], sample_interval=0.0)
    load = res.model.constant_load
    assert load == pytest.approx(16.647, abs=1e-3)
    depth = contact.resting_depth(load, res.model.track.stiffness, 1.5)
    lo, hi = res.ranges_dict("track", 1)["depth"]
    assert lo == pytest.approx(-depth, rel=1e-6)
    assert hi == pytest.approx(-depth, rel=1e-6)


def test_transfer_map_reproduces_section_3_2_start() -> None:
    """A transfer at t1 maps the carrier resting on the inner wall onto the far wall with the
    2 mm/s contact speed: the impacts after it equal those of paper-3.2 shifted by t1."""
    t1 = 0.3
    res = braidsim.simulate(
        "paper-3.1", duration=t1 + 0.1, overrides={"transfer.times": [t1]}, sample_interval=0.0
    )
    after = res.impacts[res.impacts["t"] >= t1]
    ref = braidsim.simulate("paper-3.2", duration=0.1, sample_interval=0.0).impacts
    n = min(len(after), len(ref), 5)
    assert n >= 3
    np.testing.assert_allclose(
        after["t"].to_numpy()[:n] - t1, ref["t"].to_numpy()[:n], rtol=0, atol=2e-6
    )
    np.testing.assert_allclose(
        after["peak_force"].to_numpy()[:n], ref["peak_force"].to_numpy()[:n], rtol=2e-3
    )


def test_two_dof_slot_contact() -> None:
    """With y active the horn-gear slot pushes the carrier: its mean speed follows r_c omega."""
    sc = braidsim.load_scenario("paper-3.1", overrides={"simulation.dof": "xy", "initial.vy": 0.0})
    res = braidsim.simulate(sc, duration=0.2, sample_interval=1e-4)
    s = res.series
    rc_omega = sc["carrier.turning_radius"] * sc["horn_gear.angular_velocity"]
    rel = s["y"] - s["slot_position"]
    assert rel.min() > -5e-5 and rel.max() < sc["slot.clearance"] + 5e-5
    assert (s["y"][-1] - s["y"][0]) / (s["t"][-1] - s["t"][0]) == pytest.approx(rc_omega, rel=1e-2)
    assert (res.impacts["pair"] == "slot").any()


def test_speed_profile_and_harmonics_agree() -> None:
    """The same omega(t) as a harmonic and as a dense piecewise-linear table gives the same run."""
    w0, a, W = 4 * np.pi, 2.0, 2 * np.pi * 4
    base = {"simulation.dof": "xy", "initial.vy": 0.0}
    r1 = braidsim.simulate(
        "paper-3.1",
        duration=0.1,
        overrides=dict(base, **{"horn_gear.speed_harmonics": [[a, W, 0.0]]}),
        sample_interval=1e-3,
    )
    tt = np.linspace(0, 2 * np.pi / W, 2001)
    prof = {"times": list(tt), "speeds": list(w0 + a * np.cos(W * tt))}
    r2 = braidsim.simulate(
        "paper-3.1",
        duration=0.1,
        overrides=dict(base, **{"horn_gear.speed_profile": prof}),
        sample_interval=1e-3,
    )
    s1 = r1.series["kind"] == 0
    s2 = r2.series["kind"] == 0
    np.testing.assert_allclose(r1.series["omega"][s1], r2.series["omega"][s2], atol=1e-4)
    np.testing.assert_allclose(
        r1.series["slot_position"][s1], r2.series["slot_position"][s2], atol=1e-7
    )


def test_friction_laws_run_and_differ() -> None:
    peaks = {}
    for law in ("arctan", "tanh", "stribeck", "none"):
        r = braidsim.simulate(
            "paper-3.2", duration=0.05, overrides={"friction.law": law}, sample_interval=0
        )
        peaks[law] = r.impacts["peak_force"].iloc[1]
    assert peaks["none"] > peaks["arctan"]  # friction slows the crossing of the gap
    assert len({round(v, 6) for v in peaks.values()}) == 4


def test_no_contact_hides_inside_a_step() -> None:
    """A grazing approach (the carrier barely reaches the outer wall) is found even with a
    step limit far larger than the contact."""
    # 0.289 m/s is about the speed that just crosses the 3 mm gap against the 13.9 m/s^2 load
    over = {"initial.vx": 0.2895, "friction.law": "none", "simulation.max_step": 0.01}
    r = braidsim.simulate("paper-3.1", duration=0.05, overrides=over, sample_interval=0)
    assert (r.impacts["wall"] == "outer").any()


def test_results_are_deterministic() -> None:
    a = braidsim.simulate("paper-3.3", duration=0.05)
    b = braidsim.simulate("paper-3.3", duration=0.05)
    for k in a.series:
        assert np.array_equal(a.series[k], b.series[k])
    assert np.array_equal(a.episodes, b.episodes)


def test_exports(tmp_path) -> None:
    r = braidsim.simulate("paper-3.2", duration=0.05)
    ds = r.to_xarray()
    assert ds["x"].attrs["units"] == "m"
    assert ds["track_stiffness_force"].attrs["units"] == "N"
    paths = r.to_csv(tmp_path)
    assert all(p.exists() for p in paths)
    assert len(tmp_path.joinpath("impacts.csv").read_text().splitlines()) == len(r.impacts) + 1


@pytest.mark.parametrize("name", ["paper-3.3", "paper-3.2"])
def test_energy_balance_closes(name: str) -> None:
    """Kinetic + elastic energy change equals the work of loads and moving walls minus the
    contact and friction dissipation (quadratures integrated with the state)."""
    res = braidsim.simulate(name, duration=0.2, sample_interval=1e-3)
    s = res.series
    m = res.model.scenario["carrier.mass"]
    k, n = res.model.track.stiffness, res.model.track.exponent
    p = np.abs(s["track_depth"])
    energy = 0.5 * m * (s["vx"] ** 2 + s["vy"] ** 2) + k * p ** (n + 1) / (n + 1)
    supplied = s["load_work_x"] + s["track_work"] + s["load_work_y"] + s["slot_work"]
    lost = (
        s["track_dissipated"] + s["slot_dissipated"] + s["friction_work_x"] + s["friction_work_y"]
    )
    residual = (energy - energy[0]) - (supplied - lost)
    exchanged = np.max(np.abs(supplied)) + np.max(np.abs(lost))
    assert np.max(np.abs(residual)) <= 1e-6 * exchanged


def test_restart_continues_a_run_exactly() -> None:
    """Two halves joined with `start=` give the run of the whole, impact by impact."""
    whole = braidsim.simulate("paper-3.3", duration=0.1, sample_interval=0)
    first = braidsim.simulate("paper-3.3", duration=0.05, sample_interval=0)
    second = braidsim.simulate(
        "paper-3.3", duration=0.05, sample_interval=0, start=first.final_state
    )
    assert second.final["t"] == pytest.approx(0.1)
    t_whole = whole.impacts["t"].to_numpy()
    later = second.impacts[~second.impacts["initial"]]  # a contact in progress at the cut
    t_joined = np.concatenate([first.impacts["t"].to_numpy(), later["t"].to_numpy()])
    assert len(t_joined) == len(t_whole)
    np.testing.assert_allclose(t_joined, t_whole, atol=1e-7)
    assert second.final["x"] == pytest.approx(whole.final["x"], abs=1e-9)


def test_restart_inside_a_clamped_contact_keeps_the_clamp() -> None:
    """Cut in the middle of a slot contact whose force is held at its clamp (Flores, e = 0.1:
    the force is 0 from 7.98 ms while the pad is in the wall until 8.78 ms): the state says
    so, and the continued run gives the whole run's impacts and end."""
    over = {
        "simulation.dof": "xy",
        "contact.slot.model": "flores",
        "contact.slot.restitution": 0.1,
    }
    whole = braidsim.simulate("paper-3.1", duration=0.02, overrides=over, sample_interval=0)
    first = braidsim.simulate("paper-3.1", duration=0.0085, overrides=over, sample_interval=0)
    state = first.final_state
    assert state.slot_mode != 0 and state.slot_clamped == 1
    second = braidsim.simulate(
        "paper-3.1", duration=0.0115, overrides=over, sample_interval=0, start=state
    )
    later = second.impacts[~second.impacts["initial"]]
    t_joined = np.concatenate([first.impacts["t"].to_numpy(), later["t"].to_numpy()])
    # (the halves step differently after the cut: measured 3.4e-14 s and 7e-13 of vy)
    np.testing.assert_allclose(t_joined, whole.impacts["t"].to_numpy(), atol=1e-12)
    for key in ("x", "vx", "y", "vy"):
        assert second.final[key] == pytest.approx(whole.final[key], rel=1e-10, abs=1e-15)


def test_a_start_state_without_a_step_chooses_one() -> None:
    """``State.step = 0`` (a state made by hand, or from another tool) means "choose the
    first step afresh": the continued run starts as a new one would, and ends where the
    whole run does."""
    import dataclasses

    whole = braidsim.simulate("paper-3.3", duration=0.1, sample_interval=0)
    first = braidsim.simulate("paper-3.3", duration=0.05, sample_interval=0)
    fresh = dataclasses.replace(first.final_state, step=0.0, err_old=1e-4, onset_q=0.0)
    second = braidsim.simulate("paper-3.3", duration=0.05, sample_interval=0, start=fresh)
    assert second.final["t"] == pytest.approx(0.1)
    assert second.final["x"] == pytest.approx(whole.final["x"], abs=1e-7)


@pytest.mark.parametrize("divisor", [47, 48, 49, 50, 51])
def test_run_ends_exactly_at_its_duration(divisor: int) -> None:
    """Rounding must never leave a sliver before the end that the step control calls a
    collapse (a fixed step that almost divides the duration)."""
    over = dict(
        FREE,
        **{
            "contact.track.model": "hertz",
            "contact.track.exponent": 1.0,
            "contact.track.stiffness": 1e7,
            "initial.vx": -0.5,
        },
    )
    T = np.pi * np.sqrt(1.2 / 1e7)  # half period of the linear contact
    res = braidsim.simulate(
        "paper-3.1",
        duration=1.5 * T,
        sample_interval=0,
        overrides=dict(over, **{"simulation.max_step": T / divisor}),
    )
    assert res.final["t"] == pytest.approx(1.5 * T, rel=1e-15)
    assert res.impacts["duration"].iloc[0] == pytest.approx(T, rel=1e-6)


def test_restart_keeps_later_transfers() -> None:
    """A transfer after the first half is applied in the continued run."""
    over = {"transfer.times": [0.3]}
    whole = braidsim.simulate("paper-3.1", duration=0.4, overrides=over, sample_interval=0)
    first = braidsim.simulate("paper-3.1", duration=0.2, overrides=over, sample_interval=0)
    second = braidsim.simulate(
        "paper-3.1", duration=0.2, overrides=over, sample_interval=0, start=first.final_state
    )
    assert whole.stats["transfers"] == 1
    assert first.stats["transfers"] + second.stats["transfers"] == 1
    assert second.final["x"] == pytest.approx(whole.final["x"], abs=1e-10)
