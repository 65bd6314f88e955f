"""The compiled kernel and the SciPy reference backend integrate the same model.

The two backends share nothing but :func:`braidsim.build_model`: different Runge-Kutta
methods (Dormand-Prince 5(4) with its own event location vs SciPy's DOP853 with terminal
events and restarts), different peak searches (golden section on the 4th-order interpolant vs
bounded Brent on DOP853's 7th-order dense output), different dissipation integrals (an extra
state vs Gauss-Legendre quadrature). At tight tolerances they must agree on every impact to
1e-5 relative; both are also checked against the closed forms of a single impact.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from braidsim import contact
from braidsim.errors import InputError, SimulationError
from braidsim.impact import FREE_MASS
from braidsim.integrate.scipy_backend import simulate_scipy
from braidsim.params import load_scenario
from braidsim.simulate import simulate

TIGHT = {
    "simulation.rtol": 1e-11,
    "simulation.atol_position": 1e-16,
    "simulation.atol_velocity": 1e-13,
}
RTOL = 1e-5  # agreement asked of the two backends

CASES: list[tuple[str, str, float, dict[str, Any], tuple[float, float]]] = [
    # id, scenario, duration [s], overrides, an extra window [s]
    ("3.1", "paper-3.1", 0.13, {}, (0.05, 0.1)),
    ("3.2", "paper-3.2", 0.10, {}, (0.02, 0.06)),
    ("3.3", "paper-3.3", 0.03, {}, (0.01, 0.02)),
    ("3.1-xy-slot", "paper-3.1", 0.02, {"simulation.dof": "xy"}, (0.005, 0.015)),
    ("3.1-transfer", "paper-3.1", 0.17, {"transfer.times": [0.14]}, (0.13, 0.15)),
    (
        "3.3-xy-harmonics-tanh",
        "paper-3.3",
        0.02,
        {
            "simulation.dof": "xy",
            "friction.law": "tanh",
            "horn_gear.speed_harmonics": [[2.0, 30.0, 0.3]],
            "track.harmonics": [[2e-5, 700.0, 0.1]],
        },
        (0.005, 0.015),
    ),
    (
        "3.3-xy-profile-stribeck-tension",
        "paper-3.3",
        0.02,
        {
            "simulation.dof": "xy",
            "friction.law": "stribeck",
            "horn_gear.speed_profile": {"times": [0, 0.01, 0.02], "speeds": [10, 14, 10]},
            # at rest in the ground frame at t = 0 (initial.vy is relative to the slot,
            # which moves at r_c omega(0) = 0.65 m/s)
            "initial.vy": "-0.65 m/s",
            "contact.allow_tension": True,
            "contact.initial_impact_velocity": 0.5,
        },
        (0.005, 0.015),
    ),
]

CLAMPED = {  # slot contacts so damped that their force is held at 0 before they end
    "simulation.dof": "xy",
    "contact.slot.model": "flores",
    "contact.slot.restitution": 0.1,
}
CASES.append(("3.1-xy-clamped", "paper-3.1", 0.02, CLAMPED, (0.005, 0.015)))

IMPACT_COLUMNS = (
    "t",
    "t_end",
    "velocity",
    "latched_velocity",
    "rebound_velocity",
    "max_depth",
    "peak_force",
    "min_damping_force",
    "max_damping_force",
    "dissipated_energy",
)


@pytest.fixture(scope="module", params=CASES, ids=[c[0] for c in CASES])
def both(request: pytest.FixtureRequest) -> tuple[Any, Any, dict[str, Any]]:
    case_id, name, duration, overrides, window = request.param
    ov = {**overrides, **TIGHT}
    compiled = simulate(name, duration, overrides=ov, windows=[window], sample_interval=0.0)
    ref = simulate_scipy(name, duration, overrides=ov, windows=[window], rtol=1e-11)
    return compiled, ref, {"id": case_id, "overrides": overrides}


def test_same_impact_sequence(both: tuple[Any, Any, dict[str, Any]]) -> None:
    a, b, info = both
    ia, ib = a.impacts, b.impacts
    assert len(ia) == len(ib) > 1
    for col in ("pair", "wall", "ongoing", "cut_by_transfer", "initial"):
        assert list(ia[col]) == list(ib[col]), col
    if info["overrides"].get("simulation.dof") == "xy":
        assert (ia["pair"] == "slot").sum() >= 2  # the slot contact is exercised
    if "transfer.times" in info["overrides"]:
        assert ia["cut_by_transfer"].sum() == 1
        assert b.stats["transfers"] == 1


@pytest.mark.parametrize("column", IMPACT_COLUMNS)
def test_impacts_agree(both: tuple[Any, Any, dict[str, Any]], column: str) -> None:
    a, b, _ = both
    x = a.impacts[column].to_numpy(dtype=float)
    y = b.impacts[column].to_numpy(dtype=float)
    # forces and depths are compared relative to the largest value of the run, so that an
    # impact that barely touches (a few mN) is not judged on its round-off
    if column in ("t", "t_end"):
        atol = 1e-12
    else:
        atol = RTOL * 1e-3 * np.nanmax(np.abs(x[np.isfinite(x)]), initial=0.0)
    np.testing.assert_allclose(y, x, rtol=RTOL, atol=atol, equal_nan=True, err_msg=column)


@pytest.mark.parametrize("window", [0, 1])
@pytest.mark.parametrize("pair", ["track", "slot"])
def test_window_ranges_agree(both: tuple[Any, Any, dict[str, Any]], pair: str, window: int) -> None:
    a, b, _ = both
    ra, rb = a.ranges_dict(pair, window), b.ranges_dict(pair, window)
    for q in ra:
        np.testing.assert_allclose(rb[q], ra[q], rtol=RTOL, atol=1e-12, err_msg=f"{pair} {q}")


def test_final_state_agrees(both: tuple[Any, Any, dict[str, Any]]) -> None:
    a, b, _ = both
    assert b.final["t"] == pytest.approx(a.final["t"], abs=1e-12)
    for k, scale in (("x", 1e-3), ("vx", 1.0), ("y", 1e-3), ("vy", 1.0)):
        assert b.final[k] == pytest.approx(a.final[k], rel=RTOL, abs=RTOL * 1e-2 * scale), k


# ---- the reference itself against closed forms (so the agreement above is not a shared bug)
def _free_impact(model: str, velocity: float) -> dict[str, Any]:
    """A free mass hitting the inner wall (no loads), as in :mod:`braidsim.impact`."""
    return {
        **FREE_MASS,
        "contact.track.model": model,
        "initial.x": 0.0,
        "initial.vx": -velocity,
        "simulation.atol_position": 1e-16,
        "simulation.atol_velocity": 1e-13,
    }


def test_scipy_elastic_impact_matches_hertz_closed_form() -> None:
    v = 0.5
    sc = load_scenario("paper-3.1", overrides=_free_impact("hertz", v))
    res = simulate_scipy(sc, duration=6e-4, rtol=1e-12)
    imp = res.impacts
    assert len(imp) == 1 and not imp["ongoing"].iloc[0]
    k = res.model.track.stiffness
    cf = contact.hertz_impact_closed_form(sc["carrier.mass"], k, 1.5, v)
    row = imp.iloc[0]
    assert row["duration"] == pytest.approx(cf["contact_duration"], rel=1e-7)
    assert row["max_depth"] == pytest.approx(cf["max_depth"], rel=1e-9)
    assert row["peak_force"] == pytest.approx(cf["max_force"], rel=1e-9)
    assert row["rebound_velocity"] == pytest.approx(v, rel=1e-9)
    assert abs(row["dissipated_energy"]) < 1e-9 * 0.5 * sc["carrier.mass"] * v**2


def test_scipy_hunt_crossley_restitution_is_exact() -> None:
    v = 0.5
    sc = load_scenario("paper-3.1", overrides=_free_impact("hunt_crossley", v))
    res = simulate_scipy(sc, duration=6e-4, rtol=1e-12)
    row = res.impacts.iloc[0]
    e = contact.effective_restitution(res.model.track.damping_factor)
    assert row["rebound_velocity"] / v == pytest.approx(e, rel=1e-7)
    # everything the carrier lost went into the contact's damping
    lost = 0.5 * sc["carrier.mass"] * (v**2 - row["rebound_velocity"] ** 2)
    assert row["dissipated_energy"] == pytest.approx(lost, rel=1e-7)


def test_scipy_bad_input_is_an_input_error() -> None:
    with pytest.raises(InputError, match="window"):
        simulate_scipy("paper-3.1", 0.01, windows=[(0.02, 0.01)])
    with pytest.raises(InputError, match="duration"):
        simulate_scipy("paper-3.1", -1.0)
    with pytest.raises(InputError, match="rtol"):
        simulate_scipy("paper-3.1", 0.01, rtol=0.0)


def test_scipy_step_budget_says_what_to_change() -> None:
    """The reference backend's spent budget gets the compiled solver's message: the time, the
    smallest step and what to raise."""
    with pytest.raises(SimulationError) as err:
        simulate_scipy("paper-3.1", 0.05, overrides={"simulation.max_steps": 50})
    msg = str(err.value)
    assert "step budget simulation.max_steps = 50 exhausted at t = " in msg
    assert "smallest step" in msg and "raise simulation.max_steps" in msg
    assert 0.0 <= err.value.time < 0.05


def test_scipy_backend_stops_at_the_clamp_of_a_contact_force() -> None:
    """Each crossing of the clamp N = max(0, F_k + F_c) is an event of the SciPy backend too
    (two here, one per slot contact), and with it the backend's vy converges to the compiled
    solver's at rtol 1e-13 (measured 5.5e-10 at rtol 1e-10; stepped over, 6.0e-9)."""
    ref = simulate("paper-3.1", 0.02, overrides={**CLAMPED, **TIGHT}, series=False)
    res = simulate_scipy("paper-3.1", 0.02, overrides=CLAMPED, rtol=1e-10)
    imp = res.impacts
    assert res.stats["events"] == len(imp) + int((~imp["ongoing"]).sum()) + 2
    assert abs(res.final["vy"] - ref.final["vy"]) <= 2e-9


# a case of a randomised comparison of the integrators (paper-3.4a, each parameter within
# +-20 %, a track vibrating at 441 Hz with 0.34 mm amplitude and a second harmonic)
SWEPT_WALL = {
    "carrier.mass": 1.2444676371010395,
    "carrier.turning_radius": 0.055390992698213716,
    "horn_gear.angular_velocity": 14.657137278091716,
    "yarn.tension_horizontal": 4.948107073094254,
    "yarn.tension_vertical": 3.097022501220067,
    "friction.carrier_horn_gear": 0.10422398120557308,
    "friction.pad_track": 0.11635273600741299,
    "friction.regularization_velocity": 0.0009876929350476087,
    "friction.law": "arctan",
    "materials.guide_pad.youngs_modulus": 217371843141.4744,
    "materials.track.youngs_modulus": 203277910850.3231,
    "materials.carrier.youngs_modulus": 203970493362.16043,
    "materials.horn_gear.youngs_modulus": 191770766162.31686,
    "track.clearance": 0.0034332265301103867,
    "track.vibration_amplitude": 0.0003442595802164618,
    "track.vibration_frequency": 441.20559473925624,
    "track.harmonics": [[2.4702721372451385e-05, 556.1609315647039, 1.3687558383155807]],
    "contact.track.restitution": 0.5310970490860474,
    "contact.initial_impact_velocity": 0.18910463264400224,
    "initial.vx": 0.00222178774514217,
    "simulation.dof": "x",
    "simulation.rtol": 1e-12,
    "simulation.atol_position": 1e-17,
    "simulation.atol_velocity": 1e-14,
}


def test_scipy_backend_sees_a_wall_sweeping_past_within_a_step() -> None:
    """In free flight the carrier's equations do not involve the walls, and SciPy checks an
    event function only for a change of sign between its step ends: at rtol 1e-12 its steps
    grew long enough that the vibrating wall swept past the carrier and back within one,
    and the fifth impact (0.0375 s, 0.0125 m/s, 2.2 ms long) was missed; the run then ended
    1 mm away. Its steps are now as short as the compiled solver's event samples."""
    sp = simulate_scipy("paper-3.4a", 0.05, overrides=SWEPT_WALL, rtol=1e-12)
    cc = simulate("paper-3.4a", 0.05, overrides=SWEPT_WALL, series=False)
    assert len(cc.impacts) == 5
    assert len(sp.impacts) == len(cc.impacts)
    np.testing.assert_allclose(sp.impacts["t"], cc.impacts["t"], rtol=0, atol=1e-10)
    assert sp.final["x"] == pytest.approx(cc.final["x"], rel=1e-8)


def test_scipy_backend_checks_a_record_with_a_law_of_ones_own() -> None:
    """An extension's law (here the Kelvin-Voigt law, which has no scenario name) in the
    scenario's record: the SciPy backend integrates the record it is given, and agrees with
    the compiled core on it; a record of another class is refused."""
    from braidsim.core import ImpactOscillator, KelvinVoigtContact, run
    from braidsim.model import build_model

    sc = load_scenario("paper-3.3")
    model = build_model(sc, 0.05)
    law = KelvinVoigtContact.for_restitution(2e7, 0.6, float(sc["carrier.mass"]))
    rec = model.record._replace(track_law=law)
    ref = simulate_scipy(sc, 0.05, record=rec, rtol=1e-11)
    raw = run(rec, model.options._replace(rtol=1e-11, atol_position=1e-16), model.y0)
    core_ep, sp_ep = raw.episodes, ref.episodes
    assert core_ep.size == sp_ep.size >= 3
    # (as the scenarios' runs above: to RTOL of each value)
    np.testing.assert_allclose(sp_ep["t"], core_ep["t"], rtol=RTOL, atol=1e-12)
    np.testing.assert_allclose(sp_ep["peak_force"], core_ep["peak_force"], rtol=RTOL)
    # not the scenario's law: the peak forces differ from the Hertz run's
    plain = simulate_scipy(sc, 0.05, rtol=1e-11)
    assert not np.allclose(plain.episodes["peak_force"][:3], sp_ep["peak_force"][:3], rtol=1e-2)
    osc = ImpactOscillator(1.0, 1.0, 0.0, 0.0, 0.0, 0.0, math.inf, 1e-3, law)
    with pytest.raises(InputError, match=r"record: a ImpactOscillator; allowed a record of the "):
        simulate_scipy(sc, 0.05, record=osc)


def test_scipy_backend_integrates_a_model_of_another_class() -> None:
    """``integrate_scipy`` takes what ``core.run`` takes: a forced impact oscillator between
    two walls (a damped power law; 18 contacts in 0.2 s, 11 on the inner and 7 on the
    outer wall) agrees with the compiled solver in every impact's onset and exit (1.8e-11
    s measured), approach speed and peak force (3e-9 and 4e-9 relative) and in the final
    state; a model record with no transfers runs with none."""
    from braidsim.core import ImpactOscillator, PowerLawContact, layout, run
    from braidsim.integrate.scipy_backend import integrate_scipy

    law = PowerLawContact(2e8, 1.5, 0.3)  # K [N/m^1.5], n, D = 0.3 s/m
    osc = ImpactOscillator(0.05, 40.0, 0.02, 3.0, 2 * math.pi * 30.0, 0.3, 1e-3, 1.5e-3, law)
    opts = layout.SolverOptions(
        rtol=1e-11,
        atol_position=1e-15,
        atol_velocity=1e-12,
        max_step=1e-4,
        max_steps=10**7,
        t_end=0.2,
    )
    y0 = np.array([0.0, 0.2, 0.0, 0.0, 0.0])
    raw = run(osc, opts, y0)
    ref = integrate_scipy(osc, opts, y0)
    core_ep, sp_ep = raw.episodes, ref.episodes
    assert core_ep.size == sp_ep.size >= 10
    assert set(core_ep["wall"]) == {-1.0, 1.0}  # both walls hit
    np.testing.assert_allclose(sp_ep["t"], core_ep["t"], rtol=0, atol=1e-10)
    np.testing.assert_allclose(sp_ep["t_end"], core_ep["t_end"], rtol=0, atol=1e-10)
    np.testing.assert_allclose(sp_ep["velocity"], core_ep["velocity"], rtol=1e-7)
    np.testing.assert_allclose(sp_ep["peak_force"], core_ep["peak_force"], rtol=1e-7)
    assert ref.state[:2] == pytest.approx(raw.y[:2], rel=1e-7)
    assert ref.final["t"] == pytest.approx(0.2)
    with pytest.raises(InputError, match=r"options.t_end: 0.0 s is out of range"):
        integrate_scipy(osc, opts._replace(t_end=0.0), y0)
