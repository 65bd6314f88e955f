"""The implicit (Radau IIA) step of resting contacts against closed forms, and the guarantees
the explicit solver gives (the same bits across restarts; nothing changes where no contact
rests).

The textbook case: a mass pressed onto a linear spring-dashpot wall by a slowly varying force,
m p'' + c p' + k p = F cos(Omega t), heavily overdamped (zeta = 50: eigenvalues about -k/c =
-10 and -c/m = -1e5 1/s), so that an explicit method is held by the fast mode for the whole
contact. Its solution is the sum of the harmonic particular solution and two exponentials.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from numba import njit

from braidsim.core import ImpactOscillator, KelvinVoigtContact, RawRun, run
from braidsim.core import layout as L
from braidsim.core.solver import radau
from braidsim.params import load_scenario
from braidsim.simulate import simulate

M, KC, CC = 1.0, 1e6, 1e5  # mass [kg], wall stiffness [N/m] and damping [N s/m]
F, OMEGA = 10.0, 2.0  # pressing force amplitude [N] and its angular frequency [rad/s]
GAP, V0, T_END = 1e-3, 1e-4, 0.3  # the wall at x = GAP; the body on it moving in at V0


# the solver's helpers are compiled to be called from compiled code, as the solver calls them
@njit
def _finish(y, Z, n, y1, RC):
    radau._finish(y, Z, n, y1, RC)


@njit
def _factor(J, h, m, LUR, pivr, LUC, pivc):
    return radau._factor(J, h, m, LUR, pivr, LUC, pivc)


@njit
def _solve_real(J, LUR, pivr, h, n, m, b):
    radau._solve_real(J, LUR, pivr, h, n, m, b)


@njit
def _solve_complex(J, LUC, pivc, h, n, m, br, bi, v):
    radau._solve_complex(J, LUC, pivc, h, n, m, br, bi, v)


def _closed_form(t: float) -> tuple[float, float]:
    """p(t), p'(t) of m p'' + c p' + k p = F cos(Omega t), p(0) = 0, p'(0) = V0."""
    a = KC - M * OMEGA**2
    b = CC * OMEGA
    P = F * a / (a * a + b * b)  # particular solution P cos + Q sin
    Q = F * b / (a * a + b * b)
    disc = math.sqrt(CC * CC - 4.0 * M * KC)
    l1 = (-CC + disc) / (2.0 * M)
    l2 = (-CC - disc) / (2.0 * M)
    # A + B = -P, l1 A + l2 B = V0 - Q Omega
    B = (V0 - Q * OMEGA + l1 * P) / (l2 - l1)
    A = -P - B
    p = P * math.cos(OMEGA * t) + Q * math.sin(OMEGA * t) + A * math.exp(l1 * t)
    p += B * math.exp(l2 * t)
    v = -P * OMEGA * math.sin(OMEGA * t) + Q * OMEGA * math.cos(OMEGA * t)
    v += A * l1 * math.exp(l1 * t) + B * l2 * math.exp(l2 * t)
    return p, v


def _pressed(implicit: bool, omega: float = OMEGA, t_end: float = T_END, **kw: Any) -> RawRun:
    model = ImpactOscillator(
        M, 0.0, 0.0, F, omega, 0.0, math.inf, GAP, KelvinVoigtContact(KC, CC, True)
    )
    opts = L.SolverOptions(
        rtol=1e-8,
        atol_position=1e-14,
        atol_velocity=1e-10,
        max_step=1e-2,
        max_steps=10**7,
        t_end=t_end,
    )
    return run(model, opts, np.array([GAP, V0, 0.0, 0.0, 0.0]), implicit=implicit, **kw)


def test_the_collocation_polynomial_is_the_one_of_the_stages() -> None:
    """The dense output passes through the stages (y + Z_i at c_i) and ends at y + Z_3."""
    rng = np.random.default_rng(7)
    n = 3
    y = rng.normal(size=n)
    Z = rng.normal(size=(3, n))
    y1 = np.empty(n)
    RC = np.empty((5, n))
    _finish(y, Z, n, y1, RC)
    np.testing.assert_allclose(y1, y + Z[2], rtol=1e-15)
    for c, z in ((radau.NODE1, Z[0]), (radau.NODE2, Z[1]), (1.0, Z[2])):
        th1 = 1.0 - c
        val = RC[0] + c * (RC[1] + th1 * (RC[2] + c * (RC[3] + th1 * RC[4])))
        np.testing.assert_allclose(val, y + z, rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize("m", [2, 4])
def test_the_newton_systems_are_solved_exactly(m: int) -> None:
    """(mu / h - J) x = b for the real and the complex eigenvalue of the method, J with two
    quadrature rows (columns over the coordinates and speeds only), against numpy's dense
    complex solve; pivoting is exercised by a J with a small leading entry."""
    rng = np.random.default_rng(m)
    n = m + 2
    J = rng.normal(size=(n, m)) * 1e3
    J[0, 0] = 1e-9
    h = 1e-4
    W = L.implicit_work(n, m)
    assert _factor(J, h, m, W.LUR, W.pivr, W.LUC, W.pivc)
    Jf = np.zeros((n, n))
    Jf[:, :m] = J
    br, bi = rng.normal(size=n), rng.normal(size=n)
    x = br.copy()
    _solve_real(J, W.LUR, W.pivr, h, n, m, x)
    ref = np.linalg.solve(radau.MU_REAL / h * np.eye(n) - Jf, br)
    np.testing.assert_allclose(x, ref, rtol=1e-12)
    xr, xi = br.copy(), bi.copy()
    _solve_complex(J, W.LUC, W.pivc, h, n, m, xr, xi, W.V)
    mu = complex(radau.MU_RE, radau.MU_IM) / h
    ref_c = np.linalg.solve(mu * np.eye(n) - Jf, br + 1j * bi)
    np.testing.assert_allclose(xr + 1j * xi, ref_c, rtol=1e-12)


def test_a_pressed_overdamped_contact_follows_its_closed_form() -> None:
    """Both methods give the closed form to the tolerance; the implicit one takes over the
    resting contact and needs far fewer steps and evaluations."""
    p_ref, v_ref = _closed_form(T_END)
    runs = {imp: _pressed(imp) for imp in (False, True)}
    for raw in runs.values():
        assert raw.status == L.ST_OK
        assert raw.episodes.size == 1  # pressed on the wall throughout
        assert raw.y[0] - GAP == pytest.approx(p_ref, rel=1e-7)
        assert raw.y[1] == pytest.approx(v_ref, abs=1e-10 + 1e-7 * abs(v_ref))
    exp, imp = runs[False].stats[0], runs[True].stats[0]
    assert exp["implicit_steps"] == 0
    assert imp["implicit_steps"] > 0.5 * imp["steps"]
    assert imp["steps"] < exp["steps"] / 20
    assert imp["rhs_evaluations"] < exp["rhs_evaluations"] / 5


def test_an_explicit_step_held_far_below_the_maximum_step_stops_as_stiff() -> None:
    """The pressed wall (its force varying a hundred times slower, so that it presses for
    minutes) with Dormand-Prince over 4 s: its steps sit on the stability boundary of the
    fast mode (h ~ 3e-5 s, 1/300 of the 1e-2 s maximum step), and the run stops after
    STIFF_LIMIT of them, before 4 s."""
    raw = _pressed(False, omega=OMEGA / 100, t_end=4.0)
    assert raw.status == L.ST_STIFF
    assert 1.0 < raw.t < 4.0


def test_the_energy_quadratures_balance_through_the_implicit_steps() -> None:
    """m v^2/2 + k p^2/2 = m V0^2/2 + forcing work - energy the dashpot dissipated."""
    raw = _pressed(True)
    x, v, diss, _, work = raw.y
    p = x - GAP
    e1 = 0.5 * M * v * v + 0.5 * KC * p * p
    assert e1 == pytest.approx(0.5 * M * V0 * V0 + work - diss, rel=1e-7)
    assert diss > 0.0 and work > 0.0


def test_restarts_through_an_implicit_phase_give_the_same_bits() -> None:
    """Buffers handed back (and the loop resumed from the restart record) in the middle of
    the implicit phase: the series and the end state are those of one uninterrupted pass."""
    st = np.linspace(0.0, T_END, 3001)
    whole = _pressed(True, sample_times=st)
    chunked = _pressed(True, sample_times=st, row_chunk=5)
    assert whole.stats[0]["implicit_steps"] > 10
    np.testing.assert_array_equal(chunked.series, whole.series)
    np.testing.assert_array_equal(chunked.y, whole.y)


def test_a_carrier_resting_on_the_outer_wall_is_not_held_by_newtons_convergence_test() -> None:
    """paper-3.3 pulled outwards by the yarn (phi = pi) rests on the outer wall. Started from
    Z_i = c_i h f at every step, the Newton iterations' first increment was ~1e4 tolerances
    and their convergence test rejected 3,141 steps for 1,739 accepted (rtol 1e-6); started
    from the previous step's polynomial, few are rejected, and the end state is the
    explicit method's to the tolerance."""
    sc = load_scenario("paper-3.3").with_overrides(
        {
            "track.vibration_amplitude": 5e-5,
            "yarn.angle": math.pi,
            "yarn.tension_horizontal": 45.0,
            "initial.x": 3.05e-3,
            "initial.vx": 1e-5,
            "simulation.duration": 0.3,
            "simulation.rtol": 1e-6,
            "simulation.atol_position": 1e-11,
            "simulation.atol_velocity": 1e-7,
        }
    )
    exp = simulate(sc.with_overrides({"simulation.resting_contacts": "explicit"}), series=False)
    imp = simulate(sc.with_overrides({"simulation.resting_contacts": "implicit"}), series=False)
    s = imp.stats
    assert imp.episodes["wall"].tolist() == [1.0]  # one contact, on the outer wall
    assert s["implicit_steps"] > 0.9 * s["steps"]
    assert s["rejected_steps"] < 0.1 * s["steps"]
    assert s["rhs_evaluations"] < exp.stats["rhs_evaluations"] / 10
    assert imp.final["x"] == pytest.approx(exp.final["x"], abs=1e-10)
    assert imp.final["vx"] == pytest.approx(exp.final["vx"], abs=1e-7)


@pytest.mark.parametrize("name", ["paper-3.3", "paper-3.4a"])
def test_runs_where_no_contact_rests_are_those_of_the_explicit_solver(name: str) -> None:
    """Impacts only: the switch never fires, and the results are bit for bit those of the
    explicit solver."""
    sc = load_scenario(name).with_overrides({"simulation.duration": 0.2})
    a = simulate(sc.with_overrides({"simulation.resting_contacts": "explicit"}), series=False)
    b = simulate(sc.with_overrides({"simulation.resting_contacts": "implicit"}), series=False)
    assert b.stats["implicit_steps"] == 0
    for col in ("t", "peak_force", "max_depth", "rebound_velocity"):
        np.testing.assert_array_equal(a.impacts[col].to_numpy(), b.impacts[col].to_numpy())


def test_the_continuation_passes_the_choice_to_its_flow_maps() -> None:
    """``simulation.resting_contacts`` reaches the finite-difference flow map's runs (and
    only when asked): one forcing period of paper-3.3's resting orbit (h_a 0.05 mm, 4 pi
    rad/s) ends in the same state either way, to the tolerances."""
    from braidsim.continuation import ScenarioSystem, seed_orbit
    from braidsim.continuation.fdmap import advance

    ha = {"track.vibration_amplitude": 0.05e-3}
    base = load_scenario("paper-3.3")
    orbit = seed_orbit(ScenarioSystem(base), ha, 1, method="fd")
    ends = {}
    for choice in ("explicit", "implicit"):
        system = ScenarioSystem(base.with_overrides({"simulation.resting_contacts": choice}))
        prep = system.prepare(ha)
        assert prep.implicit is (choice == "implicit")
        seg = advance(prep, 0.0, prep.period, orbit.z[0], orbit.cuts[0].modes, (1e-4, math.nan))
        ends[choice] = seg.y1
    # x to 1e-7, x' to the scenario's velocity tolerance (1e-9 m/s)
    assert ends["implicit"][0] == pytest.approx(ends["explicit"][0], rel=1e-7)
    assert ends["implicit"][1] == pytest.approx(ends["explicit"][1], abs=1e-9)
