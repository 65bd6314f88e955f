"""The closed-form piecewise-linear impact oscillator (``tests/reference``) checked against
itself where closed forms overlap and against finite differences, then braidsim's solver
checked against it: an orbit found by matching closed-form phases must be an orbit of
braidsim's ImpactOscillator with a Kelvin-Voigt wall that may pull, with the same impacts.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

from braidsim.core import layout as L
from braidsim.core import run
from reference.pwl_braidsim import braidsim_oscillator
from reference.pwl_oscillator import (
    CONTACT,
    FREE,
    ORBIT_GUESSES,
    PARAMETER_SETS,
    PWLParams,
    bifurcation_function,
    critical_parameter,
    floquet_multipliers,
    grazing_force_amplitude,
    monodromy,
    periodic_orbit,
    phase_jacobian,
    phase_solution,
    phases,
    saltation_from_fields,
    saltation_matrix,
    simulate,
    stroboscopic_jacobian_fd,
    stroboscopic_map,
    switching_time,
)

BASE = PARAMETER_SETS["stable_p1"]

# (parameter set, period k): the documented orbits
ORBITS = [
    ("stable_p1", 1),
    ("stable_p1_stiff", 1),
    ("period_doubled", 1),
    ("period_doubled", 2),
]


def _orbit(name: str, k: int):
    return periodic_orbit(PARAMETER_SETS[name], k, ORBIT_GUESSES[(name, k)])


# ---- the closed forms on their own ------------------------------------------------------------


@pytest.mark.parametrize(
    ("stiffness", "damping"),
    [(1.0, 0.1), (1.0, 3.0), (1.0, 2.0), (1.0, 2.0 + 1e-9), (0.0, 0.5), (0.0, 0.0)],
    ids=["under", "over", "critical", "near-critical", "no-spring", "free-mass"],
)
def test_phase_exponential_is_scipys_expm(stiffness: float, damping: float) -> None:
    """The eigenvalue formula of exp(A t) against scipy's Pade exponential, for under-,
    over- and critically damped phases and a free mass."""
    p = BASE._replace(stiffness=stiffness, damping=damping)
    for phase in (FREE, CONTACT):
        A = phases(p)[phase].A
        for dt in (1e-6, 0.3, 2.0, 7.5):
            np.testing.assert_allclose(
                phase_jacobian(p, phase, dt), expm(A * dt), rtol=1e-12, atol=1e-14
            )


@pytest.mark.parametrize("phase", [FREE, CONTACT])
def test_phase_solution_solves_its_equation(phase: int) -> None:
    """z(t0) = z0, and m x'' + C x' + K x = F cos(Omega t + phi) + d by central differences
    of the closed form."""
    p = BASE
    t0, z0 = 0.3, (0.12, -0.4)
    np.testing.assert_allclose(phase_solution(p, phase, t0, z0, t0), z0, atol=1e-15)
    K = p.stiffness + (p.contact_stiffness if phase == CONTACT else 0.0)
    C = p.damping + (p.contact_damping if phase == CONTACT else 0.0)
    d = p.contact_stiffness * p.gap if phase == CONTACT else 0.0
    h = 1e-4
    for t in (0.5, 1.7, 4.0):
        zm, z, zp = phase_solution(p, phase, t0, z0, np.array([t - h, t, t + h])).T
        acc = (zp[0] - 2.0 * z[0] + zm[0]) / h**2
        vel = (zp[0] - zm[0]) / (2.0 * h)
        assert vel == pytest.approx(z[1], rel=1e-7)
        force = p.force_amplitude * math.cos(p.force_frequency * t + p.force_phase) + d
        assert p.mass * acc + C * z[1] + K * z[0] == pytest.approx(force, abs=1e-6)


@pytest.mark.parametrize("e", [0.3, 0.8])
def test_free_impact_lasts_half_a_damped_period(e: float) -> None:
    """A free mass (no spring, no forcing) on the wall: the contact lasts pi / w_d and
    rebounds at e = exp(-zeta pi / sqrt(1 - zeta^2)) (Goldsmith 1960)."""
    m, kc, v = 1.3, 400.0, 0.7
    ln_e = math.log(e)
    zeta = -ln_e / math.sqrt(math.pi**2 + ln_e**2)
    cc = 2.0 * zeta * math.sqrt(kc * m)
    p = PWLParams(m, 0.0, 0.0, 0.0, 1.0, 0.0, 0.05, kc, cc)
    t_exit = switching_time(p, CONTACT, 0.2, (p.gap, v), 10.0)
    w_d = math.sqrt(kc / m) * math.sqrt(1.0 - zeta**2)
    assert t_exit is not None
    assert t_exit - 0.2 == pytest.approx(math.pi / w_d, rel=1e-14)
    _, v_out = phase_solution(p, CONTACT, 0.2, (p.gap, v), t_exit)
    assert v_out == pytest.approx(-e * v, rel=1e-13)


def test_a_gap_that_closes_between_samples_is_found() -> None:
    """x = A cos(w t), undamped and unforced, with the wall 1e-9 A inside the amplitude: the
    contact window (about 9e-5 / w wide) lies between two samples; its first root is
    -arccos(g / A) / w."""
    w, A = 1.0, 1.0
    p = PWLParams(1.0, w * w, 0.0, 0.0, 1.0, 0.0, A * (1.0 - 1e-9), 50.0, 0.0)
    t0 = -2.0
    z0 = (A * math.cos(w * t0), -A * w * math.sin(w * t0))
    t_on = switching_time(p, FREE, t0, z0, 5.0, on_surface=False)
    assert t_on is not None
    assert t_on == pytest.approx(-math.acos(p.gap / A) / w, abs=1e-12)
    # a wall just beyond the amplitude is never reached
    p_out = p._replace(gap=A * (1.0 + 1e-9))
    assert switching_time(p_out, FREE, t0, z0, 5.0, on_surface=False) is None


def test_saltation_matrices_are_the_general_formula_on_the_orbit() -> None:
    """[[1, 0], [-/+ c_c / m, 1]] against I + (f+ - f-) n^T / (n^T f-) with the two vector
    fields at the orbit's onset and exit."""
    orbit = _orbit("stable_p1", 1)
    g = BASE.gap
    for kind, t, v in (
        ("onset", orbit.t_on[0], orbit.v_on[0]),
        ("exit", orbit.t_off[0], orbit.v_off[0]),
    ):
        np.testing.assert_allclose(
            saltation_from_fields(BASE, kind, t, (g, v)), saltation_matrix(BASE, kind), atol=1e-13
        )


def test_orbit_without_contact_is_the_harmonic_steady_state() -> None:
    """A wall beyond the harmonic amplitude: the orbit is x = Re(X e^{i(Omega t + phi)}),
    X = F / (k - m Omega^2 + i c Omega), a fixed point of the stroboscopic map, with
    multipliers exp(lambda T), lambda the roots of m lambda^2 + c lambda + k."""
    p = BASE._replace(gap=2.0, force_phase=0.4)
    orbit = periodic_orbit(p, 1, ((), (), (), ()))
    X = p.force_amplitude / complex(
        p.stiffness - p.mass * p.force_frequency**2, p.damping * p.force_frequency
    )
    z_exact = (
        (X * np.exp(1j * p.force_phase)).real,
        (1j * p.force_frequency * X * np.exp(1j * p.force_phase)).real,
    )
    np.testing.assert_allclose(orbit.z_section, z_exact, rtol=1e-14)
    np.testing.assert_allclose(stroboscopic_map(p, orbit.z_section), z_exact, rtol=1e-12)
    assert simulate(p, 0.0, z_exact, 10 * p.period).events == []
    lam = np.roots([p.mass, p.damping, p.stiffness])
    expected = np.sort_complex(np.exp(lam * p.period))
    np.testing.assert_allclose(np.sort_complex(floquet_multipliers(orbit)), expected, rtol=1e-13)
    fd = np.linalg.eigvals(stroboscopic_jacobian_fd(p, orbit.z_section))
    np.testing.assert_allclose(np.sort_complex(fd), expected, rtol=1e-8)
    with pytest.raises(ValueError, match="reaches the wall"):
        periodic_orbit(BASE, 1, ((), (), (), ()))


def test_grazing_amplitude_of_the_orbit_without_impacts() -> None:
    """Just below F = g |k - m Omega^2 + i c Omega| the harmonic orbit stays off the wall
    (its peak is (F / F_g) g) and never switches; just above it touches the wall within a
    period."""
    p = BASE._replace(force_frequency=2.6)
    f_g = grazing_force_amplitude(p)
    below = p._replace(force_amplitude=f_g * (1.0 - 1e-6))
    orbit = periodic_orbit(below, 1, ((), (), (), ()))
    peak = np.max(phases(below)[FREE].steady(np.linspace(0.0, below.period, 20001))[0])
    assert peak == pytest.approx(below.gap * (1.0 - 1e-6), rel=5e-8)  # sampled peak
    assert simulate(below, 0.0, orbit.z_section, 5 * below.period).events == []
    above = p._replace(force_amplitude=f_g * (1.0 + 1e-6))
    with pytest.raises(ValueError, match="reaches the wall"):
        periodic_orbit(above, 1, ((), (), (), ()))
    z = phases(above)[FREE].steady(0.0)
    assert simulate(above, 0.0, z, above.period).onsets.size == 1


@pytest.mark.parametrize(("name", "k"), ORBITS)
def test_orbit_is_periodic_when_stepped_through_the_phases(name: str, k: int) -> None:
    """The matched orbit, flowed phase by phase (each switching a new root) for k T,
    returns to its start with the same onsets and exits."""
    orbit = _orbit(name, k)
    p = orbit.params
    assert orbit.residual < 1e-13
    traj = simulate(p, 0.0, orbit.z_section, 3 * orbit.period)
    np.testing.assert_allclose(traj.z, orbit.z_section, rtol=1e-11, atol=1e-13)
    on = np.concatenate([orbit.t_on + j * orbit.period for j in range(3)])
    off = np.concatenate([orbit.t_off + j * orbit.period for j in range(3)])
    np.testing.assert_allclose(traj.onsets, on[on < 3 * orbit.period], atol=1e-12)
    np.testing.assert_allclose(traj.exits, off[off < 3 * orbit.period], atol=1e-12)


@pytest.mark.parametrize(("name", "k"), ORBITS)
def test_multipliers_match_a_finite_difference_of_the_map(name: str, k: int) -> None:
    """The monodromy (phase exponentials and saltation matrices) against central
    differences of the closed-form stroboscopic map, which uses neither."""
    orbit = _orbit(name, k)
    M = monodromy(orbit)
    J = stroboscopic_jacobian_fd(orbit.params, orbit.z_section, 0.0, k)
    np.testing.assert_allclose(M, J, rtol=1e-7, atol=1e-7 * np.abs(M).max())


def test_multipliers_do_not_depend_on_the_section() -> None:
    """Sections in free flight and in contact give similar monodromies: same multipliers,
    whose product is exp(-int C/m dt) (Liouville; det S = 1)."""
    orbit = _orbit("period_doubled", 2)
    p = orbit.params
    ref = floquet_multipliers(orbit)
    mid_contact = 0.5 * (orbit.t_on[1] + orbit.t_off[1])
    assert orbit.phase_at(mid_contact) == CONTACT
    for t0 in (0.3, mid_contact, 7.0):
        np.testing.assert_allclose(floquet_multipliers(orbit, t0), ref, rtol=1e-12, atol=1e-14)
    t_contact = float(np.sum(orbit.t_off - orbit.t_on))
    decay = -(p.damping * orbit.period + p.contact_damping * t_contact) / p.mass
    assert np.prod(ref).real == pytest.approx(math.exp(decay), rel=1e-12)


def test_period_doubling_of_the_period_one_orbit() -> None:
    """Omega from 2.2 to 2.4 rad/s: the period-1 orbit meets a multiplier -1 at the
    documented frequency; past it the orbit is unstable and the period-2 orbit stable."""
    w, orbit = critical_parameter(BASE, "force_frequency", 2.2, 2.4, steps=4)
    assert w == pytest.approx(2.29213915, abs=1e-8)
    assert np.min(floquet_multipliers(orbit).real) == pytest.approx(-1.0, abs=1e-9)
    assert bifurcation_function(orbit, "period_doubling") == pytest.approx(0.0, abs=1e-10)
    assert np.max(np.abs(floquet_multipliers(_orbit("period_doubled", 1)))) > 1.5
    assert np.max(np.abs(floquet_multipliers(_orbit("period_doubled", 2)))) < 0.6


def test_a_guess_far_from_an_orbit_is_refused() -> None:
    """A guess near no orbit is refused in one clear message."""
    with pytest.raises(ValueError, match="did not converge"):
        periodic_orbit(BASE._replace(gap=1.5), 1, ((1.0,), (1.2,), (0.1,), (-0.1,)))


def test_a_matching_solution_that_crosses_the_wall_is_refused() -> None:
    """One impact per two periods of "stable_p1": the matching equations have a solution,
    but its long free phase passes through the wall on the way (the flow would switch
    there), so it is no orbit of the system."""
    guess = ORBIT_GUESSES[("stable_p1", 1)]
    with pytest.raises(ValueError, match="not admissible: the free phase"):
        periodic_orbit(BASE, 2, guess)
    orbit = periodic_orbit(BASE, 2, guess, check=False)
    assert orbit.residual < 1e-13
    t_next = orbit.t_on[0] + orbit.period
    t_hit = switching_time(BASE, FREE, orbit.t_off[0], (BASE.gap, orbit.v_off[0]), t_next)
    assert t_hit is not None
    assert t_hit < t_next - 1.0


# ---- braidsim against the reference -----------------------------------------------------------


def _options(t_end: float, rtol: float) -> L.SolverOptions:
    return L.SolverOptions(
        rtol=rtol,
        atol_position=1e-14,
        atol_velocity=1e-13,
        max_step=0.05,
        max_steps=10**6,
        t_end=t_end,
        energy=False,
    )


@pytest.mark.parametrize(("name", "k"), ORBITS)
def test_braidsim_stays_on_the_orbit_with_the_same_impacts(name: str, k: int) -> None:
    """From the orbit's state at t = 0, braidsim (rtol 1e-10) returns to it after each of
    6 periods k T (the unstable orbit too, for so few periods) with the orbit's onset and
    exit times."""
    orbit = _orbit(name, k)
    p = orbit.params
    n_per = 6
    sample_t = orbit.period * np.arange(1, n_per + 1)
    raw = run(
        braidsim_oscillator(p),
        _options(n_per * orbit.period, 1e-10),
        np.array(orbit.z_section),
        sample_times=sample_t,
    )
    assert raw.status == L.ST_OK
    assert raw.series is not None
    rows = raw.series[raw.series[:, -1] == L.KIND_SAMPLE]
    np.testing.assert_array_equal(rows[:, 0], sample_t)
    scale = np.abs(orbit.z_section)
    assert np.max(np.abs(rows[:, 1:3] - orbit.z_section) / scale) < 1e-8
    on = np.concatenate([orbit.t_on + j * orbit.period for j in range(n_per)])
    off = np.concatenate([orbit.t_off + j * orbit.period for j in range(n_per)])
    ep = raw.episodes
    assert ep.size == on.size
    np.testing.assert_allclose(ep["t"], on, rtol=0.0, atol=1e-8 * p.period)
    np.testing.assert_allclose(ep["velocity"], np.tile(orbit.v_on, n_per), rtol=1e-8)
    closed = ep["end_reason"] == L.END_EXIT
    np.testing.assert_allclose(ep["t_end"][closed], off[closed], rtol=0.0, atol=1e-8 * p.period)
    np.testing.assert_allclose(
        -ep["rebound_velocity"][closed], np.tile(orbit.v_off, n_per)[closed], rtol=1e-8
    )


@pytest.mark.parametrize(("name", "k"), ORBITS)
def test_braidsims_stroboscopic_map_has_the_reference_monodromy(name: str, k: int) -> None:
    """Central differences of braidsim's stroboscopic map (rtol 1e-12) at the orbit point
    against the closed-form monodromy, saltation at onset and exit included (the map a
    shooting method built on braidsim differentiates)."""
    orbit = _orbit(name, k)
    p = orbit.params
    model = braidsim_oscillator(p)
    opts = _options(orbit.period, 1e-12)
    z = np.array(orbit.z_section)
    J = np.empty((2, 2))
    for i in range(2):
        e = np.zeros(2)
        e[i] = 1e-5 * max(abs(z[i]), p.gap)
        plus = run(model, opts, z + e).y
        minus = run(model, opts, z - e).y
        J[:, i] = (plus - minus) / (2.0 * e[i])
    M = monodromy(orbit)
    # measured: 1.4e-8 of the largest entry for the period-2 orbit, 4e-10 for the others
    np.testing.assert_allclose(J, M, rtol=0.0, atol=1e-7 * np.abs(M).max())
    np.testing.assert_allclose(
        np.sort_complex(np.linalg.eigvals(J)),
        np.sort_complex(floquet_multipliers(orbit)),
        rtol=1e-6,
    )
