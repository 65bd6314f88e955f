"""The Taylor-series step of the solver against closed forms, exact restitution, energy
balances and the Dormand-Prince runs of the same models.

A run with ``taylor=12`` takes Taylor steps wherever they are longer than the Dormand-Prince
step; these tests check that most of its steps are Taylor steps, so that they test them.
Those that compile the solver once more for a model or an output of their own are marked
slow (``pytest -m slow``)."""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
import pytest

from braidsim import contact
from braidsim.core import (
    CoulombViscousFriction,
    ImpactOscillator,
    KelvinVoigtContact,
    PowerLawContact,
    TrackHarmonics,
    run,
    state_size,
)
from braidsim.core import layout as L
from braidsim.core.driver import taylor_capable
from braidsim.core.interfaces import (
    contact_force_rates,
    contact_forces,
    contact_onset_step,
    contact_potential,
    friction_force,
    friction_force_series,
)
from braidsim.core.physics.friction import FRICTION_CODES
from braidsim.model import build_model
from braidsim.params import load_scenario
from braidsim.simulate import run_model
from braidsim.simulate import simulate as braidsim_simulate

ORDER = 12
TIGHT = L.SolverOptions(
    rtol=1e-12, atol_position=1e-16, atol_velocity=1e-14, max_step=1e-3, max_steps=10**7, t_end=0.0
)


def _taylor_share(raw: Any) -> float:
    st = raw.stats[0]
    return float(st["taylor_steps"] / st["steps"])


def test_harmonic_oscillator_in_taylor_steps() -> None:
    """No walls: x = x0 cos(w t), to the tolerance, almost all in Taylor steps."""
    m, k, x0, T = 0.3, 2000.0, 0.01, 0.73
    model = ImpactOscillator(
        m, k, 0.0, 0.0, 0.0, 0.0, math.inf, math.inf, PowerLawContact(1e9, 1.5, 0.0)
    )
    w = math.sqrt(k / m)
    raw = run(model, TIGHT._replace(t_end=T), np.array([x0, 0.0, 0.0, 0.0, 0.0]), taylor=ORDER)
    assert raw.status == L.ST_OK
    assert raw.y[0] == pytest.approx(x0 * math.cos(w * T), abs=1e-12)
    assert raw.y[1] == pytest.approx(-x0 * w * math.sin(w * T), abs=1e-10)
    assert _taylor_share(raw) > 0.95


def _into_wall(v: float = 0.5, gap: float = 1e-3) -> L.SolverOptions:
    return TIGHT._replace(t_end=gap / v + 0.004, max_step=1e-3)


@pytest.mark.parametrize(
    ("n", "onset"),
    [
        (1.5, True),
        # (its own compile of the solver, without the onset step, ~40 s)
        pytest.param(1.5, False, marks=pytest.mark.slow),
        (2.0, True),
        (2.3, True),
    ],
    ids=["hertz-onset-step", "hertz-runge-kutta-onset", "n2-onset-step", "n2.3-no-onset-series"],
)
def test_elastic_power_law_impact_closed_form(n: float, onset: bool) -> None:
    """Elastic impact from free flight, K p^n: depth, peak force and rebound of the closed
    form, with the contact started by an onset step in sqrt(t - t_onset) where 2n is an
    integer and onset steps are asked for, else by a Dormand-Prince step."""
    m, v, gap = 0.5, 0.5, 1e-3
    K = 2e9 * 2e-5 ** (1.5 - n)  # (a depth of about 20 um for each n)
    model = ImpactOscillator(m, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, gap, PowerLawContact(K, n, 0))
    y0 = np.array([0.0, v, 0.0, 0.0, 0.0])
    raw = run(model, _into_wall(), y0, taylor=ORDER, taylor_onset=onset)
    (ep,) = raw.episodes
    n1 = n + 1.0
    p_m = (n1 * m * v * v / (2 * K)) ** (1 / n1)
    assert ep["t"] == pytest.approx(gap / v, rel=1e-12)
    assert ep["rebound_velocity"] == pytest.approx(v, rel=1e-9)
    assert ep["max_depth"] == pytest.approx(p_m, rel=1e-9)
    assert ep["peak_force"] == pytest.approx(K * p_m**n, rel=1e-9)
    assert abs(ep["dissipated_energy"]) < 1e-12
    assert raw.stats[0]["taylor_steps"] > 10
    assert raw.stats[0]["onset_steps"] == (1 if onset and n != 2.3 else 0)
    # the deepest point half-way through the contact, whose duration is
    # 2 (p_m / v) int_0^1 du / sqrt(1 - u^(n+1)) = 2 (p_m / v) sqrt(pi) G(1 + a) / G(1/2 + a),
    # a = 1 / (n + 1); the extremes are found on the Taylor step's series
    a = 1.0 / n1
    half = (p_m / v) * math.sqrt(math.pi) * math.gamma(1.0 + a) / math.gamma(0.5 + a)
    assert ep["t_end"] - ep["t"] == pytest.approx(2.0 * half, rel=1e-9)
    assert ep["t_max_depth"] - ep["t"] == pytest.approx(half, rel=1e-8)
    assert ep["t_peak_force"] - ep["t"] == pytest.approx(half, rel=1e-8)


def test_the_turn_of_a_series_is_found_on_its_polynomial() -> None:
    """``series_extreme``: the root of a polynomial's slope in a step, by Newton's method
    from the secant, against closed forms; -1 where the slope does not go from > 0 to <= 0
    (the caller then refines on the interpolant)."""
    from numba import njit

    from braidsim.core.solver.recorders import series_extreme

    @njit
    def turn(A, m, sign, h):  # (a helper is called from compiled code)
        return series_extreme(A, m, sign, h)

    h = 2e-4
    # q = -(tau - tau0)^2 (tau + c): q' = -(tau - tau0) (3 tau + 2 c - tau0), one root in (0, h)
    tau0, c = 0.37 * h, 0.5 * h
    A = np.zeros(13)
    A[:4] = (
        np.polynomial.polynomial.polymul(
            np.polynomial.polynomial.polymul([-tau0, 1.0], [-tau0, 1.0]), [c, 1.0]
        )
        * -1.0
    )
    assert turn(A, 12, 1.0, h) == pytest.approx(0.37, abs=1e-15)
    # a sine's series, sin(w tau + phi), its maximum at w tau = pi/2 - phi
    w, phi = 3000.0, 0.4
    A = np.array([w**k / math.factorial(k) * math.sin(phi + k * math.pi / 2) for k in range(25)])
    theta = turn(A, 24, 1.0, 1e-3)
    assert theta * 1e-3 == pytest.approx((math.pi / 2 - phi) / w, rel=1e-13)
    # a minimum of -sin (sign -1): the same turn
    assert turn(-A, 24, -1.0, 1e-3) == theta
    # no turn inside: rising throughout, or falling from the start
    assert turn(A, 24, 1.0, 1e-4) == -1.0
    assert turn(-A, 24, 1.0, 1e-3) == -1.0
    assert turn(A, 1, 1.0, 1e-3) == -1.0


@pytest.mark.parametrize("name", ["hunt_crossley", "lankarani_nikravesh", "flores"])
def test_restitution_of_a_free_impact_is_the_laws_exact_value(name: str) -> None:
    """The laws' exact restitution (an independent quadrature) from Taylor steps in contact."""
    m, v, gap, K = 0.5, 0.5, 1e-3, 2e9
    d = contact.get_law(name).damping_factor(0.6)
    model = ImpactOscillator(m, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, gap, PowerLawContact(K, 1.5, d))
    raw = run(model, _into_wall(), np.array([0.0, v, 0.0, 0.0, 0.0]), taylor=ORDER)
    (ep,) = raw.episodes
    e = ep["rebound_velocity"] / ep["velocity"]
    assert e == pytest.approx(contact.effective_restitution(d), rel=1e-6)
    assert ep["dissipated_energy"] == pytest.approx(0.5 * m * v * v * (1 - e * e), rel=1e-6)
    assert raw.stats[0]["onset_steps"] == 1


def test_energy_balance_of_the_forced_oscillator() -> None:
    """The quadratures' series close the energy balance over many impacts."""
    m, k, c, K = 1.0, 400.0, 0.8, 1e8
    model = ImpactOscillator(m, k, c, 30.0, 25.0, 0.2, 2e-3, 1.5e-3, PowerLawContact(K, 1.5, 0.4))
    raw = run(model, TIGHT._replace(t_end=2.0), np.array([0.0, 0.2, 0.0, 0.0, 0.0]), taylor=ORDER)
    assert raw.episodes.size > 10
    assert _taylor_share(raw) > 0.5
    # every contact from free flight started with an onset step, whose quadratures count
    assert raw.stats[0]["onset_steps"] == raw.episodes.size
    x, v, diss, visc, work = raw.y

    def elastic(x: float) -> float:
        p = max(0.0, -(x + 2e-3), x - 1.5e-3)
        return K * p**2.5 / 2.5

    e1 = 0.5 * m * v * v + 0.5 * k * x * x + elastic(x)
    assert e1 == pytest.approx(0.5 * m * 0.2**2 - diss - visc + work, abs=1e-9 * max(1.0, work))


@pytest.mark.slow  # (its own compile of the solver, ~30 s)
@pytest.mark.parametrize("tension", [True, False])
def test_kelvin_voigt_impact(tension: bool) -> None:
    """With tension allowed, half a damped period at exactly e; clamped, the Taylor steps
    must hand the end of the contact (N = 0 at p > 0) to the Runge-Kutta step, and the run
    agrees with a Dormand-Prince run."""
    m, k, v, gap, e = 1.2, 5e7, 0.4, 1e-3, 0.5
    law = KelvinVoigtContact.for_restitution(k, e, m, allow_tension=tension)
    model = ImpactOscillator(m, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, gap, law)
    opts = TIGHT._replace(t_end=gap / v + 0.01, max_step=1e-4)
    y0 = np.array([0.0, v, 0.0, 0.0, 0.0])
    (ep,) = run(model, opts, y0, taylor=ORDER).episodes
    (ref,) = run(model, opts, y0).episodes
    if tension:
        zeta = law.damping / (2.0 * math.sqrt(k * m))
        w_d = math.sqrt(k / m) * math.sqrt(1.0 - zeta**2)
        assert ep["t_end"] - ep["t"] == pytest.approx(math.pi / w_d, rel=1e-9)
        assert ep["rebound_velocity"] / ep["velocity"] == pytest.approx(e, rel=1e-8)
    for col in ("t_end", "rebound_velocity", "peak_force", "max_depth", "dissipated_energy"):
        assert ep[col] == pytest.approx(ref[col], rel=1e-8), col


@pytest.mark.slow  # (its own compile of the solver, ~30 s)
def test_viscous_friction_decays_the_speed_exponentially() -> None:
    """The carrier in a wide gap, friction b v only: x' = v0 exp(-b t / m)."""
    b, v0, T = 3.0, 0.2, 0.4
    sc_model = build_model(load_scenario("paper-3.1"), 1.0)
    rec = sc_model.record._replace(
        friction=CoulombViscousFriction(1e-3, b),
        mu_x=0.0,
        load_x=0.0,
        mass_radius=0.0,
        track_clearance=1.0,
        track=TrackHarmonics(np.zeros((0, 3))),
    )
    y0 = np.zeros(state_size(rec, True))
    y0[:2] = (0.5, v0)
    raw = run(rec, TIGHT._replace(t_end=T), y0, taylor=ORDER)
    decay = math.exp(-b * T / rec.mass)
    assert raw.y[1] == pytest.approx(v0 * decay, rel=1e-10)
    assert raw.y[0] == pytest.approx(0.5 + v0 * rec.mass / b * (1 - decay), rel=1e-11)
    assert raw.y[3] == pytest.approx(0.5 * rec.mass * v0 * v0 * (1 - decay**2), rel=1e-9)
    assert _taylor_share(raw) > 0.95


@pytest.mark.parametrize("law", ["tanh", "stribeck", "arctan"])
@pytest.mark.parametrize("integrator", ["taylor", "dormand-prince"])
def test_a_friction_turn_over_is_not_stepped_over(law: str, integrator: str) -> None:
    """Free flight through x' = 0 at about 10^4 m/s^2 (a horn gear at 400 rad/s, no track
    motion): m x'' = -L - f(x'), so t(v) = int_v^v0 m dw / (L + f(w)), by quadrature
    (scipy.integrate.quad, through the turn-over at w = 0). tanh and the Stribeck term
    saturate: far from v = 0 their series are flat to the last bit (1 - tanh(u)^2 = 0), and
    a step from v0 = 0.5 m/s (u = 500) crossed the turn-over in one Taylor step, missing it
    (a velocity error of 5e-4 m/s, friction never reversed)."""
    from scipy.integrate import quad

    v0, T = 0.5, 4e-4
    sc = load_scenario("paper-3.3").with_overrides(
        {
            "friction.law": law,
            "simulation.integrator": integrator,
            "track.vibration_amplitude": 0.0,
            "horn_gear.angular_velocity": 400.0,
            "initial.x": 1.5e-3,
            "initial.vx": v0,
            "simulation.rtol": 1e-10,
            "simulation.atol_position": 1e-15,
            "simulation.atol_velocity": 1e-11,
        }
    )
    model = build_model(sc, T)
    rec = model.record
    assert rec.friction.law == FRICTION_CODES[law]
    load = rec.mass_radius * rec.horn_gear.omega0**2 + rec.load_x
    mu_n, vh = rec.mu_x * rec.normal_x, rec.friction.regularization_velocity
    vs, rs = rec.friction.stribeck_velocity, rec.friction.static_ratio

    def force(w: float) -> float:
        if law == "arctan":
            return mu_n * 2.0 / math.pi * math.atan(w / vh)
        g = math.tanh(w / vh)
        if law == "stribeck":
            return mu_n * (1.0 + (rs - 1.0) * math.exp(-((w / vs) ** 2))) * g
        return mu_n * g

    raw = run_model(model, series=False, energy=True)
    assert raw.episodes.size == 0  # (free flight throughout)
    v = float(raw.y[1])
    assert v < -1.0  # through the turn-over and back
    t_of_v = quad(
        lambda w: rec.mass / (load + force(w)),
        v,
        v0,
        points=[0.0],
        epsabs=0.0,
        epsrel=1e-13,
        limit=400,
    )[0]
    # the velocity's error: the time's times the deceleration there
    assert abs(t_of_v - T) * (load + force(v)) / rec.mass < 2e-9


def test_a_contact_from_rest_in_taylor_steps() -> None:
    """Table 1's Hertz row starts the carrier at rest on the wall: its contact begins with an
    onset at zero speed, whose branch point is femtoseconds away, so the first steps are
    femtoseconds long. The run failed there (a step collapse of the Runge-Kutta step carried
    over the Taylor steps, 2e-15 s, checked against an absolute 3.2e-15 s), and, with that
    check made relative to t, at 0.18 s (the same carried step, never grown through 0.18 s of
    Taylor steps in a resting contact). The resting contact's force and the final depth at
    the scenario's tolerances against Dormand-Prince at tight ones (itself 5e-8 from it in
    the peak force and 1.5e-6 in x at the scenario's). Measured: the peak force 1.6e-7, x
    7.4e-9 (the peak 2e-8 before Runge-Kutta steps took the depth's returns towards 0,
    test_a_depth_returning_towards_zero_in_taylor_steps)."""
    sc = load_scenario("table1-hertz")
    tight = {
        "simulation.rtol": 1e-12,
        "simulation.atol_position": 1e-17,
        "simulation.atol_velocity": 1e-13,
    }
    ref = braidsim_simulate(sc.with_overrides(tight), 0.3, series=False)
    tay = braidsim_simulate(sc.with_overrides({"simulation.integrator": "taylor"}), 0.3)
    assert tay.stats["taylor_steps"] > 0.5 * tay.stats["steps"]
    assert len(tay.impacts) == len(ref.impacts) == 1  # (the contact present at the start)
    assert tay.impacts["peak_force"].iloc[0] == pytest.approx(
        ref.impacts["peak_force"].iloc[0], rel=1e-6
    )
    assert tay.final["x"] == pytest.approx(ref.final["x"], rel=1e-7)


@pytest.mark.parametrize(
    ("scenario", "dof", "friction"),
    [
        ("paper-3.3", "x", "arctan"),
        ("paper-3.3", "x", "tanh"),
        pytest.param("paper-3.4a", "x", "arctan", marks=pytest.mark.slow),
        pytest.param("paper-3.4a", "xy", "arctan", marks=pytest.mark.slow),
    ],
)
def test_carrier_runs_agree_with_dormand_prince(scenario: str, dof: str, friction: str) -> None:
    """The x-only carrier of paper-3.3 and 3.4a, and the xy carrier: impact table of the
    Taylor run against the Dormand-Prince run, both at tight tolerances, and the same
    energy quadratures. With tanh friction as well, whose turn-overs inside the contacts the
    Taylor steps must not step over (test_a_friction_turn_over_is_not_stepped_over)."""
    sc = load_scenario(scenario).with_overrides(
        {
            "friction.law": friction,
            "simulation.dof": dof,
            "simulation.rtol": 1e-12,
            "simulation.atol_position": 1e-16,
            "simulation.atol_velocity": 1e-13,
        }
    )
    # the lean path (the compiled loop the other tests use) with all the energy quadratures
    ref = run_model(build_model(sc, 0.1), series=False, energy=True)
    sc_t = sc.with_overrides({"simulation.integrator": "taylor"})
    tay = run_model(build_model(sc_t, 0.1), series=False, energy=True)
    st = tay.stats[0]
    assert st["taylor_steps"] > 0.5 * st["steps"]
    a, b = ref.episodes, tay.episodes
    assert len(a) == len(b) and len(a) > 3
    # the carrier starts its contacts with onset steps, but where its other pair is in
    # contact (the xy carrier)
    onsets = int(np.sum(b["initial"] == 0))
    if dof == "x":
        assert st["onset_steps"] == onsets
    else:
        assert 0 < st["onset_steps"] <= onsets
    for col in ("t", "t_end", "velocity", "peak_force", "max_depth"):
        # (the xy carrier has contacts that start at t ~ 1e-20 s)
        atol = 1e-15 if col.startswith("t") else 0.0
        np.testing.assert_allclose(b[col], a[col], rtol=1e-7, atol=atol, err_msg=col)
    np.testing.assert_allclose(
        b["dissipated_energy"], a["dissipated_energy"], rtol=1e-6, atol=1e-12
    )
    # all the energy quadratures, through the onset steps too (the step control does not
    # hold the quadratures: the xy carrier's slot dissipation differs by 5e-7 between the
    # two methods)
    np.testing.assert_allclose(tay.y, ref.y, rtol=2e-6, atol=1e-12)


def test_a_step_from_an_exit_that_spans_the_next_contact_finds_that_contact() -> None:
    """After an exit the state lies within the step's error on the wall's side (here 2.5e-15
    m of depth at 1 mm/s out of it), and the next step, a Taylor step of 1 ms in free flight,
    had its first sample past the carrier's next contact, 75 us later: the event was located
    at the step's start, a contact of 2.6e-12 s at an approach speed of -9.6e-4 m/s
    (paper-3.3, h_a = 0.13 mm, at 0.8107 s; in 2 of the batch benchmark's 64 sets). The
    contact is now found where it starts, after the gap has opened."""
    sc = load_scenario("paper-3.3").with_overrides(
        {"track.vibration_amplitude": 0.13e-3, "simulation.integrator": "taylor"}
    )
    im = braidsim_simulate(sc, 0.812, series=False).impacts
    later = im[~im["initial"]]
    assert (later["velocity"] > 0.0).all()
    assert later["duration"].min() > 1e-5
    # the contact after the exit at 0.810749 s starts at 0.810824 s (measured)
    after = later[(later["t"] > 0.8107) & (later["t"] < 0.8109)]
    assert after["t"].tolist() == [pytest.approx(0.810824, abs=1e-6)]


def test_a_depth_returning_towards_zero_in_taylor_steps() -> None:
    """An elastic contact from rest without friction (table1-hertz): the carrier rocks in
    its Hertz well and the depth returns almost to 0 every 1.26 ms (1.1e-12 m against 1.4e-6
    m at the deepest). There the force's branch point p^1.5 = 0 is a complex pair of roots
    of the depth a few 1e-7 s off the real axis, which the last terms of the series did not
    show: the steps passed it, and the speed came out 5e-6 m/s wrong at rtol 1e-11 (2e-7 at
    1e-12), where Dormand-Prince is right to 5e-12. Runge-Kutta steps there
    (taylor.depth_root_reach): 3.3e-13 (measured; 6e-14 at 1e-12)."""
    sc = load_scenario("table1-hertz").with_overrides(
        {
            "friction.law": "none",
            "simulation.rtol": 1e-13,
            "simulation.atol_position": 1e-18,
            "simulation.atol_velocity": 1e-15,
        }
    )
    ref = run_model(build_model(sc, 0.0025), series=False, energy=True)
    tay_sc = sc.with_overrides(
        {
            "simulation.integrator": "taylor",
            "simulation.rtol": 1e-11,
            "simulation.atol_position": 1e-16,
            "simulation.atol_velocity": 1e-13,
        }
    )
    tay = run_model(build_model(tay_sc, 0.0025), series=False, energy=True)
    assert tay.stats[0]["taylor_steps"] > 0
    assert abs(tay.y[1] - ref.y[1]) < 1e-11
    assert abs(tay.y[0] - ref.y[0]) < 1e-14


@pytest.mark.parametrize(
    ("base", "extra", "rtol"),
    [
        ("table1-hertz", {}, 1e-13),
        pytest.param(
            "table1-hertz",
            {
                "simulation.dof": "xy",
                "contact.track.model": "hertz",
                "friction.carrier_horn_gear": 0.001,
                "horn_gear.angular_velocity": 12.577026930594139,
                "carrier.mass": 1.1116301971329747,
                "yarn.tension_horizontal": 4.629159600612151,
            },
            1e-12,
            marks=pytest.mark.slow,  # (the xy carrier with Taylor steps: its own compile)
        ),
    ],
)
def test_taylor_steps_near_depth_returns_at_tight_tolerances(
    base: str, extra: dict, rtol: float
) -> None:
    """Rocking contacts at tight absolute tolerances (atol 1e-5 rtol m). Bounding the
    Taylor step by every root of the depth (exits and the onset behind too), or taking
    Taylor steps bounded short of a return, made the steps creep towards the root until they
    collapsed: both runs failed at those two versions (the second is one of a randomised
    set). They run now, as Dormand-Prince does, and agree with it."""
    tol = {
        "friction.law": "none",
        "simulation.rtol": rtol,
        "simulation.atol_position": rtol * 1e-5,
        "simulation.atol_velocity": rtol * 1e-2,
    }
    sc = load_scenario(base).with_overrides({**extra, **tol})
    ref = run_model(build_model(sc, 0.006), series=False, energy=True)
    tay_sc = sc.with_overrides({"simulation.integrator": "taylor"})
    tay = run_model(build_model(tay_sc, 0.006), series=False, energy=True)
    assert tay.status == ref.status == 0
    np.testing.assert_allclose(tay.y[:2], ref.y[:2], rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("times", [(0.0, 0.01, 0.02), (0.0, 0.007, 0.02)])
def test_a_speed_profile_in_taylor_steps(times: tuple[float, ...]) -> None:
    """A horn-gear speed profile: the series of the slot's motion holds up to the next knot.
    At a knot of a later period (0.03 s of a 0.02-s profile, reduced to one period as
    0.009999999999999998) that horizon was 2e-18 s, and the run failed on steps below the
    rounding of t; it now takes the next piece's series there. Against Dormand-Prince at
    tight tolerances (measured: final x 4e-11 relative apart)."""
    sc = load_scenario("paper-3.1").with_overrides(
        {
            "horn_gear.speed_profile": {"times": list(times), "speeds": [12.0, 14.0, 10.0]},
            "simulation.rtol": 1e-12,
            "simulation.atol_position": 1e-16,
            "simulation.atol_velocity": 1e-13,
        }
    )
    ref = run_model(build_model(sc, 0.05), series=False, energy=True)
    tay = run_model(
        build_model(sc.with_overrides({"simulation.integrator": "taylor"}), 0.05),
        series=False,
        energy=True,
    )
    assert tay.stats[0]["taylor_steps"] > 0
    assert len(tay.episodes) == len(ref.episodes) >= 2
    np.testing.assert_allclose(tay.episodes["peak_force"], ref.episodes["peak_force"], rtol=1e-8)
    np.testing.assert_allclose(tay.y[:2], ref.y[:2], rtol=1e-8)


@pytest.mark.slow  # (its own compile of the solver, with a series buffer, ~30 s)
def test_restarts_give_the_same_bits() -> None:
    """A Taylor run flushed through a tiny impact table and series buffer equals the run in
    one pass to the bit (the Taylor step keeps its state in the restart record)."""
    model = build_model(load_scenario("paper-3.3"), 0.1)
    args = dict(sample_times=np.linspace(0.0, 0.1, 2001), taylor=ORDER)
    big = run(model.record, model.options, model.y0, **args)
    small = run(model.record, model.options, model.y0, row_chunk=7, episode_chunk=8, **args)
    assert big.episodes.size > 3 and big.stats[0]["taylor_steps"] > 100
    np.testing.assert_array_equal(small.series, big.series)
    for name in L.EPISODE_COLUMNS:
        np.testing.assert_array_equal(small.episodes[name], big.episodes[name], err_msg=name)
    np.testing.assert_array_equal(small.y, big.y)


class _NoSeriesLaw(NamedTuple):
    stiffness: float


@contact_forces.register(_NoSeriesLaw)
def _no_series_forces(law, p, p_dot, v0):  # type: ignore[no-untyped-def]
    fk = law.stiffness * p
    return fk, 0.0, fk


# (the rest of what a run needs of a contact law: the check of Taylor steps is the one that
# fails)
@contact_potential.register(_NoSeriesLaw)
def _no_series_potential(law, p):  # type: ignore[no-untyped-def]
    return 0.5 * law.stiffness * p * p


@contact_force_rates.register(_NoSeriesLaw)
def _no_series_rates(law, p, p_dot, p_ddot, v0, f_k, f_c):  # type: ignore[no-untyped-def]
    return law.stiffness * p_dot, 0.0


@contact_onset_step.register(_NoSeriesLaw)
def _no_series_onset(law, mass, v):  # type: ignore[no-untyped-def]
    return 0.1 * math.sqrt(mass / law.stiffness), 2.0


class _NoReachFriction(NamedTuple):
    regularization_velocity: float


@friction_force.register(_NoReachFriction)
def _no_reach_force(law, v, normal, mu):  # type: ignore[no-untyped-def]
    return mu * normal * math.tanh(v / law.regularization_velocity)


@friction_force_series.register(_NoReachFriction)
def _no_reach_series(law, k, V, NS, mu, S):  # type: ignore[no-untyped-def]
    return 0.0  # (never run: the run is refused first)


def test_a_friction_law_without_its_reach_is_named() -> None:
    """A friction law with a series but no friction_series_reach cannot take Taylor steps:
    the solver could not know whether its series hides a turn-over."""
    rec = build_model(load_scenario("paper-3.3"), 0.01).record
    rec = rec._replace(friction=_NoReachFriction(1e-3))
    assert "_NoReachFriction (friction)" in taylor_capable(rec)
    assert "friction_series_reach" in taylor_capable(rec)


def test_a_record_without_series_is_named() -> None:
    m = ImpactOscillator(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, 1e-3, _NoSeriesLaw(1e6))
    assert "_NoSeriesLaw (law)" in taylor_capable(m)
    with pytest.raises(ValueError, match="contact_force_series"):
        run(m, _into_wall(), np.array([0.0, 0.5, 0.0, 0.0, 0.0]), taylor=ORDER)
    ok = ImpactOscillator(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, 1e-3, PowerLawContact(1, 1.5, 0))
    assert taylor_capable(ok) == ""


def test_a_run_with_sensitivities_says_it_took_dormand_prince_steps() -> None:
    """Tangents are carried by Dormand-Prince steps only: a scenario that asks for Taylor
    steps (or implicit steps at rest) gets them in a plain run, and a run with sensitivities
    says in its statistics that it took neither. (Each run is of a kind other tests
    compile as well.)"""
    sc = load_scenario("paper-3.3")
    taylor = sc.with_overrides({"simulation.integrator": "taylor"})
    plain = run_model(build_model(taylor, 0.01), series=False, energy=True)
    assert (plain.integrator, plain.resting_contacts) == ("taylor", "explicit")
    assert plain.stats[0]["taylor_steps"] > 0
    implicit = braidsim_simulate(
        sc.with_overrides({"simulation.resting_contacts": "implicit"}), 0.01, series=False
    )
    assert implicit.stats["integrator"] == "dormand-prince"
    assert implicit.stats["resting_contacts"] == "implicit"
    both = taylor.with_overrides({"simulation.resting_contacts": "implicit"})
    sens = braidsim_simulate(both, 0.01, sensitivities=["track.clearance"])
    assert sens.stats["integrator"] == "dormand-prince"
    assert sens.stats["resting_contacts"] == "explicit"
    assert sens.stats["taylor_steps"] == 0 and sens.stats["implicit_steps"] == 0
