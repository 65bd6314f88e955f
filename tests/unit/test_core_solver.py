"""The compiled core's solver on its own: numerical helpers against independent
evaluations, the impact oscillator against closed forms, and the driver's guarantees (one
pass, the same bits whatever the buffers and recorders).

The helpers are the pieces the step loop relies on without re-checking: the time derivative
of the continuous extension (used to locate peaks) and the slopes dN/dt, dF_c/dt of a pair
summary (whose signs decide whether a step holds a peak).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba.core.caching
import numpy as np
import numpy.polynomial.polynomial as P
import pandas as pd
import pytest
from numba import njit

from braidsim import contact
from braidsim.core import ImpactOscillator, PowerLawContact, derivatives, run, state_size
from braidsim.core import layout as L
from braidsim.core.generic import by_ref
from braidsim.core.interfaces import pair_gaps, pair_law
from braidsim.core.solver.dense import StepPolynomial, dense_deriv, dense_eval
from braidsim.core.solver.dopri5 import dense_coeffs, rk_step
from braidsim.core.solver.events import N_SUB, locate_event
from braidsim.core.solver.pairs import I_DFC, I_DN, I_FC, I_FK, I_N, I_P, I_PD, NI, pair_info
from braidsim.model import build_model
from braidsim.params import load_scenario
from braidsim.simulate import simulate

# the solver's helpers are compiled to be called from compiled code, as the solver calls them


@njit
def _step_and_interpolant(rec, t, y, h, K, modes, v0s, n, yt, y1, RC):
    rk_step(rec, t, y, h, K, modes, v0s, n, yt, y1)
    dense_coeffs(y, y1, h, K, RC, n)


@njit
def _deriv(theta, h, RC, out, n):
    # (dense_deriv is chosen by the type of RC when its caller is compiled; called from
    # Python it runs its Python reference)
    dense_deriv(theta, h, RC, out, n)


@njit
def _pair_info(rec, pair, t, y, f, mode, v0, out):
    pair_info(rec, pair, t, y, f, mode, v0, out)


def _one_contact_step() -> tuple[object, np.ndarray, float, float, np.ndarray, int]:
    """One Dormand-Prince step of the paper-3.4a carrier 2 um deep in the inner track wall,
    moving into it."""
    model = build_model(load_scenario("paper-3.4a"), 0.01)
    rec = model.record
    n = state_size(rec, True)
    y = np.zeros(n)
    t, h = 0.01, 2e-6
    a = rec.track.table[0]
    h0 = a[0] * math.cos(a[1] * t + a[2])
    hd0 = -a[0] * a[1] * math.sin(a[1] * t + a[2])
    y[0] = h0 - 2e-6
    y[1] = hd0 - 0.05
    modes = np.array([-1, 0])
    v0s = np.array([0.3, 1.0])
    K = np.empty((7, n))
    derivatives.py(rec, t, y, modes, v0s, n, K[0])
    yt, y1, RC = np.empty(n), np.empty(n), np.empty((5, n))
    _step_and_interpolant(rec, t, y, h, K, modes, v0s, n, yt, y1, RC)
    return rec, K, t, h, RC, n


def test_dense_derivative_matches_the_stages_and_finite_differences() -> None:
    _, K, _, h, RC, n = _one_contact_step()
    d = np.empty(n)
    _deriv(0.0, h, RC, d, 2)
    np.testing.assert_allclose(d[:2], K[0, :2], rtol=1e-9, atol=1e-12)
    _deriv(1.0, h, RC, d, 2)
    np.testing.assert_allclose(d[:2], K[6, :2], rtol=1e-9, atol=1e-12)
    yp, ym = np.empty(n), np.empty(n)
    for theta in (0.2, 0.5, 0.9):
        e = 1e-5
        dense_eval(theta + e, RC, yp, n)
        dense_eval(theta - e, RC, ym, n)
        _deriv(theta, h, RC, d, 2)
        fd = (yp[:2] - ym[:2]) / (2 * e * h)
        np.testing.assert_allclose(d[:2], fd, rtol=1e-6)


def test_a_step_polynomial_reads_as_its_interpolant_or_as_numpys_polynomial() -> None:
    """In a loop with Taylor steps the readers get all three polynomials: the
    interpolant's values to the bit, the Taylor polynomial's as numpy's polyval and polyder
    give them, the onset step's in sqrt(theta) likewise; compiled and in Python alike."""
    rng = np.random.default_rng(7)
    RC, RT = rng.standard_normal((5, 3)), rng.standard_normal((13, 3))
    RS = rng.standard_normal((25, 3))
    RS[1] = 0.0  # (dy/ds = 2 s dy/dt)
    h = 2e-4

    def kind(k: int) -> np.ndarray:
        return np.full(1, k, dtype=np.int64)

    out, ref = np.empty(3), np.empty(3)
    for theta in (0.0, 0.37, 1.0):
        dense_eval(theta, StepPolynomial(RC, RT, kind(0), RS), out, 3)
        dense_eval(theta, RC, ref, 3)
        assert np.array_equal(out, ref)
        _deriv(theta, h, StepPolynomial(RC, RT, kind(0), RS), out, 3)
        _deriv(theta, h, RC, ref, 3)
        assert np.array_equal(out, ref)
        onset = StepPolynomial(RC, RT, kind(2), RS)
        sigma = np.sqrt(theta)
        dense_eval(theta, onset, out, 3)
        np.testing.assert_allclose(out, P.polyval(sigma, RS), rtol=1e-13, atol=1e-13)
        _deriv(theta, h, onset, out, 3)
        # d/dt = (d/dsigma) / (2 sigma h); at sigma = 0 (where RS[1] = 0) 2 RS[2] / (2 h)
        if theta > 0.0:
            d_ref = P.polyval(sigma, P.polyder(RS)) / (2 * sigma * h)
        else:
            d_ref = RS[2] / h
        np.testing.assert_allclose(out, d_ref, rtol=1e-12, atol=1e-12 / h)
        dense_deriv(theta, h, onset, ref, 3)  # the Python reference
        np.testing.assert_allclose(ref, d_ref, rtol=1e-12, atol=1e-12 / h)
        taylor = StepPolynomial(RC, RT, kind(1), RS)
        dense_eval(theta, taylor, out, 3)
        np.testing.assert_allclose(out, P.polyval(theta, RT), rtol=1e-13, atol=1e-13)
        _deriv(theta, h, taylor, out, 3)
        d_ref = P.polyval(theta, P.polyder(RT)) / h
        np.testing.assert_allclose(out, d_ref, rtol=1e-13, atol=1e-13 / h)
        dense_deriv(theta, h, taylor, ref, 3)  # the Python reference
        np.testing.assert_allclose(ref, d_ref, rtol=1e-13, atol=1e-13 / h)


def test_pair_summary_slopes_are_the_time_derivatives_of_the_forces() -> None:
    rec, _, t, h, RC, n = _one_contact_step()
    v0 = 0.3
    info, ip, im = np.empty(NI), np.empty(NI), np.empty(NI)
    ys, yd = np.empty(n), np.empty(n)
    e = 1e-4
    for theta in (0.3, 0.7):
        for th, out in ((theta, info), (theta + e, ip), (theta - e, im)):
            dense_eval(th, RC, ys, n)
            _deriv(th, h, RC, yd, 2)
            _pair_info(rec, 0, t + th * h, ys, yd, -1, v0, out)
        dt = 2 * e * h
        assert info[I_P] > 0.0
        assert info[I_N] == pytest.approx(info[I_FK] + info[I_FC], rel=1e-14)
        assert info[I_DN] == pytest.approx((ip[I_N] - im[I_N]) / dt, rel=1e-5)
        assert info[I_DFC] == pytest.approx((ip[I_FC] - im[I_FC]) / dt, rel=1e-5)
        assert info[I_PD] == pytest.approx((ip[I_P] - im[I_P]) / dt, rel=1e-5)


# ---- the impact oscillator ----------------------------------------------------------------

TIGHT = L.SolverOptions(
    rtol=1e-11, atol_position=1e-15, atol_velocity=1e-13, max_step=1e-4, max_steps=10**7, t_end=0.0
)


def _free_flight_into_wall(v: float = 0.5, gap: float = 1e-3) -> L.SolverOptions:
    """Options for a free mass starting at x = 0 with speed v towards a wall at x = gap."""
    return TIGHT._replace(t_end=gap / v + 0.01)


def test_the_xy_carrier_converges_through_a_clamped_slot_contact() -> None:
    """On paper-3.3 the xy carrier's first slot contact ends clamped: its force is 0 (the
    damping term outpulls the stiffness term) for 1.3 ms before the pad leaves the wall.
    The steps are cut at that kink, so vy at 1.4 ms converges with the tolerance (measured:
    2.1e-11 and 2.1e-13 from the rtol 1e-13 value at rtol 1e-10 and 1e-11; with the kink
    stepped over, 7.4e-9 and 8.5e-10, and 1.0e-9 at rtol 1e-12)."""
    sc = load_scenario("paper-3.3").with_overrides({"simulation.dof": "xy"})

    def vy(rtol: float) -> float:
        tol = {
            "simulation.rtol": rtol,
            "simulation.atol_position": 1e-5 * rtol,
            "simulation.atol_velocity": 0.1 * rtol,
        }
        return float(simulate(sc.with_overrides(tol), 0.0014, series=False).final["vy"])

    ref = vy(1e-13)
    for rtol in (1e-10, 1e-11):
        assert abs(vy(rtol) - ref) <= 20.0 * rtol * abs(ref)


def test_each_crossing_of_a_clamp_is_one_event() -> None:
    """Slot contacts so damped (Flores, e = 0.1) that each ends clamped: the run's events are
    its onsets, its exits and one per crossing of the unclamped force F_k + F_c through 0,
    counted here on a 1-us series of that force (in the series, signed as the contact force
    is: the clamp is where it turns positive). Read from the force's sign at the start of
    each step, the same kink was found up to 4 times over."""
    sc = load_scenario("paper-3.1").with_overrides(
        {
            "simulation.dof": "xy",
            "contact.slot.model": "flores",
            "contact.slot.restitution": 0.1,
            "simulation.sample_interval": 1e-6,
        }
    )
    res = simulate(sc, 0.02)
    s = res.series
    crossings = 0
    for pair in ("track", "slot"):
        f = s[f"{pair}_stiffness_force"] + s[f"{pair}_damping_force"]
        both_in = (s[f"{pair}_depth"][1:] != 0) & (s[f"{pair}_depth"][:-1] != 0)
        crossings += int(np.sum((np.sign(f[1:]) != np.sign(f[:-1])) & both_in))
    imp = res.impacts
    exits = int((~imp["ongoing"]).sum())
    assert crossings == 2
    assert res.stats["events"] == len(imp) + exits + crossings


def test_oscillator_without_walls_is_the_harmonic_oscillator() -> None:
    """m x'' + k x = 0 from x0: x = x0 cos(w t), v = -x0 w sin(w t), energy conserved."""
    m, k, x0 = 2.0, 800.0, 0.01
    model = ImpactOscillator(
        m, k, 0.0, 0.0, 0.0, 0.0, math.inf, math.inf, PowerLawContact(1e9, 1.5, 0.0)
    )
    w = math.sqrt(k / m)
    T = 0.73
    raw = run(model, TIGHT._replace(t_end=T), np.array([x0, 0.0, 0.0, 0.0, 0.0]))
    assert raw.status == L.ST_OK
    assert raw.y[0] == pytest.approx(x0 * math.cos(w * T), abs=1e-11)
    assert raw.y[1] == pytest.approx(-x0 * w * math.sin(w * T), abs=1e-9)
    assert raw.episodes.size == 0


def test_elastic_hertz_impact_closed_form() -> None:
    """A free mass on a Hertz wall (D = 0): rebound speed = approach speed, maximum depth
    ((n+1) m v^2 / (2 K))^(1/(n+1)), peak force K p_m^n, no energy dissipated."""
    m, K, v, gap = 1.0, 1e9, 0.5, 1e-3
    law = PowerLawContact(K, 1.5, 0.0)
    model = ImpactOscillator(m, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, gap, law)
    raw = run(model, _free_flight_into_wall(), np.array([0.0, v, 0.0, 0.0, 0.0]))
    (ep,) = raw.episodes
    p_m = (2.5 * m * v * v / (2 * K)) ** (1 / 2.5)
    assert ep["t"] == pytest.approx(gap / v, rel=1e-12)
    assert ep["velocity"] == pytest.approx(v, rel=1e-12)
    assert ep["rebound_velocity"] == pytest.approx(v, rel=1e-9)
    assert ep["max_depth"] == pytest.approx(p_m, rel=1e-9)
    assert ep["peak_force"] == pytest.approx(K * p_m**1.5, rel=1e-9)
    assert abs(ep["dissipated_energy"]) < 1e-12
    assert raw.y[1] == pytest.approx(-v, rel=1e-9)


def test_an_int_given_for_a_float_field_neither_compiles_again_nor_changes_a_bit() -> None:
    """numba compiles the solver for the types of the record's fields: ``run`` makes an int
    given where a float is declared a float first (core.driver.as_declared)."""
    from braidsim.core.solver.loop import integrate

    m, K, v, gap = 1, 2e9, 0.5, 1e-3
    floats = ImpactOscillator(
        float(m), 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, gap, PowerLawContact(K, 1.5, 0.0)
    )
    ints = ImpactOscillator(m, 0, 0, 0, 0, 0, math.inf, gap, PowerLawContact(K, 1.5, 0))
    y0 = np.array([0.0, v, 0.0, 0.0, 0.0])
    a = run(floats, _free_flight_into_wall(), y0)
    compiled = len(integrate.signatures)
    b = run(ints, _free_flight_into_wall()._replace(max_steps=10**7, t_end=1), y0)
    assert len(integrate.signatures) == compiled
    c = run(floats, _free_flight_into_wall()._replace(max_steps=10**7, t_end=1.0), y0)
    assert np.array_equal(b.y, c.y)
    assert b.episodes.tobytes() == c.episodes.tobytes()
    assert a.episodes.size == b.episodes.size == 1


def test_declared_model_walks_a_record_once_and_knows_it_by_identity() -> None:
    """``declared_model`` keeps the last records by identity: the same record comes back
    declared without a second walk, an equal but distinct record is walked afresh."""
    from braidsim.core import driver

    law = PowerLawContact(2e9, 1.5, 0, True)
    model = ImpactOscillator(1, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, 1e-3, law)
    first = driver.declared_model(model)
    assert type(first.mass) is float and type(first.law.damping) is float
    assert driver.declared_model(model) is first
    twin = ImpactOscillator(1, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, 1e-3, law)
    again = driver.declared_model(twin)
    assert again is not first and again == first
    for i in range(driver._DECLARED_KEPT + 1):  # older records leave the memo
        driver.declared_model(model._replace(gap_outer=1e-3 + i * 1e-6))
    assert id(model) not in driver._DECLARED
    assert driver.declared_model(model) == first


def test_runs_of_known_argument_types_call_the_kept_entry_point_with_the_same_bits(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A run whose solver arguments have the fingerprints of an earlier run's calls the
    compiled entry point kept for them, not numba's dispatcher (which types every argument
    at every call), and gives the same bits; with none kept, the run goes through
    ``integrate`` (numba's dispatcher), and where that has no overloads to read nothing is
    kept."""
    from braidsim.core import driver

    sc = load_scenario("paper-3.4a")
    first = simulate(sc, 0.01, series=False)
    real = driver.integrate
    calls: list[int] = []

    def dispatcher(*args: Any) -> Any:
        calls.append(1)
        return real(*args)

    monkeypatch.setattr(driver, "integrate", dispatcher)
    kept = simulate(sc, 0.01, series=False)
    assert not calls
    monkeypatch.setattr(driver, "_ENTRIES", {})
    through = simulate(sc, 0.01, series=False)
    assert calls and not driver._ENTRIES
    for res in (kept, through):
        assert res.episodes.tobytes() == first.episodes.tobytes()
        assert res.ranges.tobytes() == first.ranges.tobytes()
        assert repr(res.final_state) == repr(first.final_state)  # (NaN quadratures)
        assert res.stats == first.stats


def test_as_declared_makes_ints_floats_only_where_a_float_is_declared() -> None:
    """Python and numpy ints in float fields become floats, nested records included; a bool
    field, an array and a record with nothing to change are left as they are (the same
    object comes back)."""
    from braidsim.core.driver import as_declared

    law = PowerLawContact(np.int64(2), 1.5, 0, True)
    model = ImpactOscillator(1, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, 1e-3, law)
    out = as_declared(model)
    assert type(out.mass) is float and out.mass == 1.0
    assert type(out.law.stiffness) is float and out.law.stiffness == 2.0
    assert type(out.law.damping) is float
    assert out.law.allow_tension is True
    assert as_declared(out) is out
    arr = np.arange(3)
    assert as_declared(arr) is arr
    rec = L.new_stats()
    rec[0]["steps"] = 7
    fields = L.record_view(rec)
    assert fields.steps == 7 and fields.min_step == math.inf
    assert fields._fields == L.STATS_DTYPE.names


def test_record_view_reads_the_first_record_as_numpy_does() -> None:
    """The named view of a record holds what numpy's ``item()`` gives, field by field, for
    the packed float64 records (read from their bytes), another layout and a strided
    array (read by numpy)."""
    rs = L.new_restart()
    rs[0]["t"], rs[0]["mode_1"], rs[0]["v0_0"] = 0.25, -1.0, math.inf
    mixed = np.zeros(3, dtype=[("a", "<f8"), ("n", "<i4"), ("b", "<f8")])
    mixed[0] = (1.5, 7, -2.0)
    strided = np.zeros(4, dtype=L.STATS_DTYPE)[::2]
    strided[0]["steps"] = 3.0
    for records in (rs, L.new_stats(), mixed, strided):
        view = L.record_view(records)
        assert view._fields == records.dtype.names
        expected = records[0].item()
        assert tuple(view) == expected
        assert [type(v) for v in view] == [type(v) for v in expected]
    assert L.record_view(rs).t == 0.25 and L.record_view(rs).v0_0 == math.inf
    assert L.record_view(mixed).n == 7


def test_declared_options_are_kept_by_value_and_field_types() -> None:
    """Options equal in value but with an int where a float is declared come back declared
    (floats), not as the float twin kept before them; a bool given as 1 stays 1."""
    from braidsim.core import driver

    opts = _free_flight_into_wall()._replace(t_end=1.0)
    kept = driver.declared_options(opts)  # (an equal record declared earlier may be kept)
    assert kept == opts and list(map(type, kept)) == list(map(type, opts))
    as_int = opts._replace(t_end=1)
    out = driver.declared_options(as_int)
    assert out == opts and type(out.t_end) is float
    one = opts._replace(record_events=1)
    assert driver.declared_options(one).record_events == 1
    assert type(driver.declared_options(one).record_events) is int
    assert driver.declared_options(as_int) is out  # (kept)


def test_records_copied_by_their_bytes_are_writable_copies() -> None:
    """``copy_records`` gives the same bytes in a new, writable array; the original is left
    as it was when the copy is written."""
    ep = np.zeros(3, dtype=L.EPISODE_DTYPE)
    ep["t"] = [0.1, 0.2, math.nan]
    ep["pair"] = [0, 1, 0]
    cp = L.copy_records(ep[:2])
    assert cp.dtype == L.EPISODE_DTYPE and cp.shape == (2,)
    assert cp.tobytes() == ep[:2].tobytes()
    cp["t"][0] = 5.0
    assert ep["t"][0] == 0.1
    rs = L.copy_records(L.new_restart())
    rs[0]["t"] = 2.0
    assert L.new_restart()[0]["t"] != 2.0


def test_the_open_episode_is_the_last_of_its_pair_without_an_end() -> None:
    from braidsim.core.driver import _last_open

    ep = np.zeros(5, dtype=L.EPISODE_DTYPE)
    ep["pair"] = [0, 1, 0, 1, 0]
    ep["t_end"] = [1.0, math.nan, math.nan, 2.0, 3.0]
    assert _last_open(ep, 0) == 2
    assert _last_open(ep, 1) == 1
    ep["t_end"][1] = 0.5
    assert _last_open(ep, 1) == -1
    assert _last_open(ep[:0], 0) == -1


@pytest.mark.parametrize("name", ["hunt_crossley", "flores", "lankarani_nikravesh", "gonthier"])
def test_restitution_of_a_free_impact_is_the_laws_exact_value(name: str) -> None:
    """With D(c_r) from the law, one free impact rebounds at the exact restitution of
    :func:`braidsim.contact.effective_restitution` (an independent quadrature), and the
    dissipated energy is the lost kinetic energy."""
    m, K, v, gap = 1.2, 2.49e10, 0.3, 2e-4
    law_def = contact.get_law(name)
    d = law_def.damping_factor(0.7)
    law = PowerLawContact(K, 1.5, d)
    model = ImpactOscillator(m, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, gap, law)
    raw = run(model, _free_flight_into_wall(v, gap), np.array([0.0, v, 0.0, 0.0, 0.0]))
    (ep,) = raw.episodes
    e = ep["rebound_velocity"] / ep["velocity"]
    assert e == pytest.approx(contact.effective_restitution(d), rel=1e-6)
    assert ep["dissipated_energy"] == pytest.approx(0.5 * m * v * v * (1 - e * e), rel=1e-6)


def test_energy_balance_of_the_forced_oscillator() -> None:
    """Kinetic + spring + elastic contact energy at the end = at the start - contact and
    dashpot dissipation + forcing work (the quadratures integrated with the motion)."""
    m, k, c, K = 1.0, 400.0, 0.8, 1e8
    law = PowerLawContact(K, 1.5, 0.4)
    model = ImpactOscillator(m, k, c, 30.0, 25.0, 0.2, 2e-3, 1.5e-3, law)
    raw = run(model, TIGHT._replace(t_end=2.0), np.array([0.0, 0.2, 0.0, 0.0, 0.0]))
    assert raw.episodes.size > 10
    x, v, diss, visc, work = raw.y

    def elastic(x: float) -> float:
        p = max(0.0, -(x + 2e-3), x - 1.5e-3)
        return K * p**2.5 / 2.5

    e0 = 0.5 * m * 0.2**2
    e1 = 0.5 * m * v * v + 0.5 * k * x * x + elastic(x)
    assert e1 == pytest.approx(e0 - diss - visc + work, abs=1e-9 * max(1.0, work))


def test_a_carrier_at_rest_on_a_still_wall_runs_on_at_the_stability_boundary() -> None:
    """paper-3.1 (no vibration) comes to rest on the inner wall after 0.12 s; the explicit
    step then sits on the stability boundary of the contact at about the maximum step,
    which is no crawl: 150 s run to the end (it stopped as stiff at 132.8 s), at the static
    depth (F / K)^(1/n) of the constant load."""
    model = build_model(load_scenario("paper-3.1"), 150.0)
    raw = run(model.record, model.options, model.y0, series=False)
    assert raw.status == L.ST_OK and raw.t == 150.0
    depth = contact.resting_depth(model.constant_load, model.track.stiffness, model.track.exponent)
    assert -raw.y[0] == pytest.approx(depth, rel=1e-7)


# ---- the driver ---------------------------------------------------------------------------


# the 2-DOF carrier started overlapping both the track and the slot: two contacts at t = 0
XY_BOTH_IN_CONTACT = {
    "simulation.dof": "xy",
    "track.vibration_amplitude": 5e-5,
    "initial.x": 5e-5,
    "initial.vx": -1e-5,
    "initial.y": 1e-4,
    "initial.vy": 1e-5,
}


@pytest.mark.parametrize("overrides", [{}, XY_BOTH_IN_CONTACT], ids=["paper-3.3", "xy-two-at-t0"])
def test_buffers_of_any_size_give_the_same_bits(overrides: dict[str, Any]) -> None:
    """The solver hands full buffers back at step boundaries and goes on: the series and the
    impact table do not depend on the buffer sizes (one pass, nothing integrated twice), the
    order of two contacts that begin at the same instant included."""
    model = build_model(load_scenario("paper-3.3").with_overrides(overrides), 0.3)
    st = np.linspace(0.0, 0.3, 601)
    W = np.array([[0.0, 0.3], [0.1, 0.2]])
    args = dict(sample_times=st, transfer_times=model.transfer_times, windows=W)
    big = run(model.record, model.options, model.y0, **args)
    small = run(model.record, model.options, model.y0, row_chunk=7, episode_chunk=8, **args)
    assert big.episodes.size > 10
    assert small.rows_written == big.rows_written
    np.testing.assert_array_equal(small.series, big.series)
    for name in L.EPISODE_COLUMNS:  # field by field: NaN (an ongoing contact's end) equals NaN
        np.testing.assert_array_equal(small.episodes[name], big.episodes[name], err_msg=name)
    np.testing.assert_array_equal(small.ranges, big.ranges)
    np.testing.assert_array_equal(small.xsq, big.xsq)
    np.testing.assert_array_equal(small.y, big.y)


def test_streamed_series_equals_the_kept_series() -> None:
    model = build_model(load_scenario("paper-3.4a"), 0.2)
    st = np.linspace(0.0, 0.2, 2001)
    kept = run(model.record, model.options, model.y0, sample_times=st)
    chunks: list[np.ndarray] = []
    streamed = run(
        model.record, model.options, model.y0, sample_times=st, series=chunks.append, row_chunk=100
    )
    assert streamed.series is None
    assert len(chunks) > 5
    np.testing.assert_array_equal(np.concatenate(chunks), kept.series)


def test_the_lean_path_and_the_energy_switch_change_no_bit_of_the_motion() -> None:
    """Without series, x^2 integrals or energy quadratures, the impacts, ranges and final
    motion are those of the full run, bit for bit (recorders only read the motion)."""
    model = build_model(load_scenario("paper-3.3"), 0.3)
    W = np.array([[0.0, 0.3]])
    full = run(
        model.record, model.options, model.y0, sample_times=np.linspace(0, 0.3, 31), windows=W
    )
    lean_opts = model.options._replace(energy=False, record_events=False)
    lean = run(model.record, lean_opts, model.y0[:2], windows=W, series=False, xsq=False)
    assert lean.series is None and lean.xsq is None
    for name in ("t", "t_end", "velocity", "peak_force", "max_depth", "rebound_velocity"):
        np.testing.assert_array_equal(lean.episodes[name], full.episodes[name])
    assert np.isnan(lean.episodes["dissipated_energy"]).all()
    np.testing.assert_array_equal(lean.ranges, full.ranges)
    np.testing.assert_array_equal(lean.y, full.y[:2])


@pytest.mark.parametrize("name", ["paper-3.3", "paper-3.4a"])
def test_the_dissipation_quadratures_alone_give_the_impact_table_of_the_full_run(name) -> None:
    """The lean path integrates only the energy each contact dissipates (the first n_pairs
    quadratures): the motion, the impact table (its dissipated energies included) and the
    dissipation integrals are those of the run with every quadrature, bit for bit; the works
    it did not integrate come back as NaN, and a run continued from that state integrates
    them from its own start."""
    sc = load_scenario(name)
    model = build_model(sc, 0.2)
    W = np.array([[0.0, 0.2]])
    n_pairs = 2 if model.two_dof else 1
    n_coord2 = 4 if model.two_dof else 2
    full = run(model.record, model.options, model.y0, windows=W, series=False)
    opts = model.options._replace(quadratures=n_pairs)
    diss = run(model.record, opts, model.y0[: n_coord2 + n_pairs], windows=W, series=False)
    assert diss.y.shape == (n_coord2 + n_pairs,)
    assert np.isfinite(full.episodes["dissipated_energy"]).all()
    for name_ in full.episodes.dtype.names:
        np.testing.assert_array_equal(diss.episodes[name_], full.episodes[name_])
    np.testing.assert_array_equal(diss.y, full.y[: n_coord2 + n_pairs])
    assert full.stats[0]["rhs_evaluations"] == diss.stats[0]["rhs_evaluations"]

    lean = simulate(sc, 0.2, series=False)
    whole = simulate(sc, 0.2)
    pd.testing.assert_frame_equal(lean.impacts, whole.impacts)
    y_lean = np.array(lean.final_state.y)
    assert y_lean.shape == (len(whole.final_state.y),)
    np.testing.assert_array_equal(
        y_lean[: n_coord2 + n_pairs], whole.final_state.y[: n_coord2 + n_pairs]
    )
    assert np.isnan(y_lean[n_coord2 + n_pairs :]).all()
    # continued from the lean state: the motion is the continued full run's, the works
    # not integrated before start from zero
    after_lean = simulate(sc, 0.05, start=lean.final_state)
    after_full = simulate(sc, 0.05, start=whole.final_state)
    np.testing.assert_array_equal(
        after_lean.final_state.y[:n_coord2], after_full.final_state.y[:n_coord2]
    )
    rest = np.array(after_lean.final_state.y[n_coord2 + n_pairs :])
    assert np.isfinite(rest).all()


@pytest.mark.parametrize("integrator", ["dormand-prince", "taylor"])
def test_the_rms_of_x_is_integrated_where_asked_and_changes_no_bit(integrator: str) -> None:
    """The lean path integrates no x^2 unless ``rms=True``; asked for, its RMS is the full
    run's to the bit, and with it or without the impacts, ranges and final state are the
    same bits (the recorder only reads the motion)."""
    sc = load_scenario("paper-3.3").with_overrides({"simulation.integrator": integrator})
    windows = [(0.01, 0.05)]
    lean = simulate(sc, 0.1, series=False, windows=windows)
    asked = simulate(sc, 0.1, series=False, windows=windows, rms=True)
    whole = simulate(sc, 0.1, windows=windows)
    without = simulate(sc, 0.1, windows=windows, rms=False)
    assert lean.rms_x is None and without.rms_x is None
    assert asked.rms_x is not None and whole.rms_x is not None
    np.testing.assert_array_equal(asked.rms_x, whole.rms_x)
    assert asked.rms_x.shape == (2,) and np.all(asked.rms_x > 0.0)
    pd.testing.assert_frame_equal(lean.impacts, asked.impacts)
    pd.testing.assert_frame_equal(whole.impacts, without.impacts)
    np.testing.assert_array_equal(lean.ranges, asked.ranges)
    np.testing.assert_array_equal(whole.ranges, without.ranges)
    np.testing.assert_array_equal(lean.final_state.y, asked.final_state.y)  # (NaN: not integrated)
    assert lean.final_state.t == asked.final_state.t
    for name in whole.series:
        np.testing.assert_array_equal(whole.series[name], without.series[name])


@pytest.mark.parametrize("dof", ["x", "xy"])
def test_gaps_along_rows_are_the_per_row_gaps_to_the_bit(dof: str) -> None:
    """One compiled call over many rows gives what the model's pair_gaps gives row by row
    (both pairs of the xy carrier), and the gap to the inner wall is x - h(t) with the
    track's closed-form motion."""
    from braidsim.core import gaps_along, pair_gaps, wall_motion

    model = build_model(load_scenario("paper-3.3").with_overrides({"simulation.dof": dof}), 0.05)
    assert model.two_dof == (dof == "xy")
    rec = model.record
    n = state_size(rec, False)
    rng = np.random.default_rng(7)
    t = np.sort(rng.uniform(0.0, 0.05, 64))
    Y = rng.normal(0.0, 1e-4, (64, n))
    pairs = 2 if model.two_dof else 1
    for p in range(pairs):
        G = np.column_stack(gaps_along(rec, p, t, Y.T))
        rows = np.array([pair_gaps.py(rec, p, ti, yi) for ti, yi in zip(t, Y, strict=True)])
        assert G.shape == (64, 3)
        assert np.array_equal(G, rows)
    h = np.array([wall_motion.py(rec.track, ti)[0] for ti in t])
    assert np.allclose(gaps_along(rec, 0, t, Y.T)[0], Y[:, 0] - h, rtol=0, atol=1e-18)


class _CountingWall(NamedTuple):
    """A test record: a coordinate over a still wall at 0 (and none above), whose gap
    function counts its calls."""

    calls: np.ndarray


@pair_gaps.register(_CountingWall)
def _counting_gaps(model, pair, t, y):  # type: ignore[no-untyped-def]
    model.calls[0] += 1.0
    return y[0], math.inf, y[1]


@pair_law.register(_CountingWall)
def _counting_law(model, pair, p, p_dot, v0):  # type: ignore[no-untyped-def]
    # (compiled with the event functions, which include the clamps of contact forces)
    return 0.0, 0.0, 0.0


@njit
def _locate(rec, j, t0, h, RC, modes, n, ys, GS):
    return locate_event(by_ref(rec), j, t0, h, RC, modes, np.ones(1), n, ys, GS)


@pytest.mark.parametrize(("root", "curve"), [(0.3183, 0.0), (0.61, 1.2), (0.905, -1.0), (0.5, 1.9)])
def test_event_location_converges_superlinearly_to_the_closed_form_root(
    root: float, curve: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The gap x(theta) = a (root - theta)(1 + curve (theta - root)) of a Taylor step
    polynomial: the event is located at ``root`` to the solver's tolerance (1e-15 of the
    time) in few evaluations of the gap. The Illinois method converges superlinearly;
    bisection, which the solver's secant step fell back to when its sign was wrong, takes
    about 37 from a bracket of 1/8. (|curve| < 1 / max(root, 1 - root): one root in [0, 1].)
    """
    # the solver's helpers compiled here for the test's record are not written to numba's
    # cache: a process that cannot import this module would fail to read their index
    monkeypatch.setattr(numba.core.caching.Cache, "save_overload", lambda *a: None)
    a, h, t0 = 1e-6, 1e-5, 0.0
    # (root - theta)(1 + curve theta - curve root) in powers of theta
    coef = np.array([root * (1 - curve * root), curve * root - 1 + curve * root, -curve])
    RT = np.zeros((13, 2))
    RT[: coef.size, 0] = a * coef
    RT[: coef.size - 1, 1] = a * P.polyder(coef) / h
    out = StepPolynomial(np.zeros((5, 2)), RT, np.ones(1, dtype=np.int64), np.zeros((25, 2)))
    GS = np.ones((2, N_SUB + 1))
    GS[0] = [P.polyval(k / N_SUB, a * coef) for k in range(N_SUB + 1)]
    rec = _CountingWall(np.zeros(1))
    theta = _locate(rec, 0, t0, h, out, np.zeros(1, dtype=np.int64), 2, np.empty(2), GS)
    tol = 1e-15
    assert root - tol <= theta <= root + 2 * tol
    assert rec.calls[0] <= 12


def test_sensitivity_work_is_typed_as_numba_types_it() -> None:
    """The fingerprint-keyed types of the tangent records and of the sensitivity work record
    are the types numba's own typeof gives (else the solver would be compiled again)."""
    from numba.core.typing import typeof as numba_typeof

    from braidsim.core import driver
    from braidsim.core.driver import Tangents

    model = build_model(load_scenario("paper-3.3"), 0.01)
    rec = model.record
    recs = [rec, rec._replace(mass=2.0)]
    typed_list = driver._typed_records(recs)
    assert typed_list._numba_type_.item_type == numba_typeof.typeof(rec)
    assert len(typed_list) == 2 and typed_list[1].mass == 2.0
    ep = np.empty(8, dtype=L.EPISODE_DTYPE)
    tangents = Tangents(recs, np.eye(2), np.zeros((2, 2)), np.zeros((2, 0)), np.ones(2))
    work = driver._sensitivity_work(
        tangents, ep, None, np.zeros(0), False, None, model.options, rec, 5
    )
    ctx = numba_typeof._TypeofContext(numba_typeof.Purpose.argument)
    for _ in range(2):  # (made, then kept)
        assert driver._typeof_sensitivity_work(work, ctx) == numba_typeof._typeof_tuple(work, ctx)
