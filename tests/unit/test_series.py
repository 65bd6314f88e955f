"""Taylor series of the compiled core: the jet primitives (:mod:`braidsim.core.jets`) against
closed forms, and each physics record's series (``contact_force_series``,
``friction_force_series``, ``wall_series``) against its own function evaluated along the
input series.

A series of order N of a smooth function differs from it by O(tau^(N+1)): the tests check
that the difference is the series' own terms N+1, N+2, ... (:func:`_assert_order`), on
input series with all their terms; piecewise wall motions are exact up to the end of their
piece. The series are called through small compiled wrappers, as the solver calls them
(inlined), with bounds checks on and the work arrays filled with NaN (their contents before
k = 0 are garbage).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from fractions import Fraction

import numpy as np
import pytest
from numba import njit
from numpy.polynomial import polynomial as P

import braidsim.core  # noqa: F401  (registers every record; silences numba's IR warning)
from braidsim.core.interfaces import (
    SERIES_ROWS,
    contact_force_onset_series,
    contact_force_series,
    contact_forces,
    contact_onset_power,
    friction_force,
    friction_force_series,
    friction_series_reach,
    wall_motion,
    wall_series,
)
from braidsim.core.jets import (
    HIDDEN_FALL,
    SATURATED,
    jet_atan,
    jet_cos_linear,
    jet_div,
    jet_exp,
    jet_in_sqrt,
    jet_mul,
    jet_pow,
    jet_sq,
    jet_tanh,
    saturation_reach,
)
from braidsim.core.physics import (
    CoulombViscousFriction,
    HornGear,
    KelvinVoigtContact,
    MeasuredTrack,
    PowerLawContact,
    RegularizedFriction,
    TrackHarmonics,
)
from braidsim.core.physics.excitation import horn_gear_state
from braidsim.core.physics.friction import FRICTION_CODES

ORDER = 16  # of the physics series
TOP = ORDER + 20  # the series computed beyond it, whose terms explain its difference
JET_ORDER = 20


# ---------------------------------------------------------------------------------------
# compiled callers (the generic functions are inlined into them, as into the solver)
# ---------------------------------------------------------------------------------------


@njit(boundscheck=True)
def _contact_series(law, P, v0, order, S, out):
    for k in range(order + 1):
        fk, fc, nn = contact_force_series(law, k, P, v0, S)
        out[0, k] = fk
        out[1, k] = fc
        out[2, k] = nn


@njit(boundscheck=True)
def _contact_onset_series(law, Q, v0, order, S, out):
    for k in range(order + 1):
        fc, nn = contact_force_onset_series(law, k, Q, v0, S)
        out[0, k] = fc
        out[1, k] = nn


@njit(boundscheck=True)
def _onset_power(law):
    return contact_onset_power(law)


@njit(boundscheck=True)
def _friction_series(law, V, NS, mu, order, S, out):
    for k in range(order + 1):
        out[k] = friction_force_series(law, k, V, NS, mu, S)


@njit(boundscheck=True)
def _wall_series(ex, t, order, H):
    return wall_series(ex, t, order, H)


def _work(order: int) -> np.ndarray:
    return np.full((SERIES_ROWS, order + 2), np.nan)  # garbage before k = 0


def _horner(c: np.ndarray, tau: float) -> float:
    acc = 0.0
    for ck in c[::-1]:
        acc = acc * tau + ck
    return float(acc)


def _deriv(c: np.ndarray) -> np.ndarray:
    """Coefficients of the derivative in tau."""
    return c[1:] * np.arange(1, len(c))


def _assert_order(
    coeffs: np.ndarray,
    order: int,
    exact: Callable[[float], float],
    tau_max: float,
    scale: float,
    noise: float = 2e-15,
) -> None:
    """The series of ``order`` differs from ``exact`` by O(tau^(order + 1)): by its own
    terms order + 1 .. len(coeffs) - 1 (a polynomial whose lowest power is order + 1) to
    0.2 %, at two tau where those terms are about 5e4 times the rounding of ``exact`` and
    of the sum (``noise`` times ``scale``). A coefficient m <= order wrong by a fraction d
    leaves d |C_m| tau^m, found when d > ~4e-3 tau |C_(m+1) / C_m|.

    (The higher terms explain the difference where their series is far more accurate than
    that of ``order``. The decay of the difference itself as 2^(order + 1) when tau is
    halved needs a tau where it is above the rounding and yet asymptotic, a window too
    narrow at order 16 for series with irregular coefficients.)"""
    top = len(coeffs) - 1
    assert top >= order + 8
    target = 5e4 * noise * scale

    def tail(tau: float) -> float:
        return _horner(coeffs[: top + 1], tau) - _horner(coeffs[: order + 1], tau)

    tau = tau_max
    for _ in range(400):
        if abs(tail(tau)) <= target:
            break
        tau /= 2**0.25
    assert abs(tail(tau)) > target / 100, (tau, tail(tau), scale)  # tau_max large enough
    for x in (tau, tau / 1.25):
        t_x = tail(x)
        diff = exact(x) - _horner(coeffs[: order + 1], x)
        assert abs(t_x) > 10 * noise * scale, (x, t_x, scale)
        assert abs(diff - t_x) <= 2e-3 * abs(t_x) + noise * scale, (x, diff, t_x, scale)


def _wavy(n: int, x0: float, scale: float, time: float, seed: float) -> np.ndarray:
    """Coefficients x0, scale * cos(1.7 j + seed) / time^j (j >= 1): a polynomial of
    degree n - 1 with all its terms, of time scale ``time``."""
    j = np.arange(n)
    c = scale * np.cos(1.7 * j + seed) / time**j
    c[0] = x0
    return c


# ---------------------------------------------------------------------------------------
# the jet primitives against closed forms
# ---------------------------------------------------------------------------------------


def _close(got: np.ndarray, want: np.ndarray, rtol: float = 1e-13) -> None:
    np.testing.assert_allclose(got, want, rtol=rtol, atol=0.0)


def test_jet_in_sqrt_is_the_polynomial_in_s_squared() -> None:
    """a(t + s^2) from the coefficients of a(t + tau): numpy's polynomial at tau = s^2."""
    a = _wavy(13, 0.7, 1.3, 1.0, 0.2)
    out = np.full(26, np.nan)
    out[:13] = a
    jet_in_sqrt(out, 12, 25)
    np.testing.assert_array_equal(out[0::2], a)
    np.testing.assert_array_equal(out[1::2], 0.0)
    for s in (0.3, 0.9):
        assert P.polyval(s, out) == pytest.approx(P.polyval(s * s, a), rel=1e-14)


def test_jet_mul_and_sq_are_the_polynomial_products() -> None:
    a = _wavy(JET_ORDER + 1, 0.7, 1.3, 1.0, 0.2)
    b = _wavy(JET_ORDER + 1, -1.1, 0.6, 0.8, 1.4)
    ab = np.convolve(a, b)[: JET_ORDER + 1]
    aa = np.convolve(a, a)[: JET_ORDER + 1]
    _close(np.array([jet_mul(a, b, k) for k in range(JET_ORDER + 1)]), ab, 1e-12)
    _close(np.array([jet_sq(a, k) for k in range(JET_ORDER + 1)]), aa, 1e-12)
    # two short polynomials: the product's exact coefficients, then zeros
    p = np.zeros(JET_ORDER + 1)
    q = np.zeros(JET_ORDER + 1)
    p[:3] = (1.0, 2.0, 3.0)
    q[:2] = (4.0, -5.0)
    got = [jet_mul(p, q, k) for k in range(JET_ORDER + 1)]
    assert got[:4] == [4.0, 3.0, 2.0, -15.0]
    assert all(g == 0.0 for g in got[4:])


def test_jet_div_of_one_by_one_minus_tau_is_the_geometric_series() -> None:
    one = np.zeros(JET_ORDER + 1)
    one[0] = 1.0
    b = np.zeros(JET_ORDER + 1)
    b[:2] = (1.0, -1.0)
    q = np.full(JET_ORDER + 1, np.nan)
    for k in range(JET_ORDER + 1):
        q[k] = jet_div(one, b, q, k)
    np.testing.assert_array_equal(q, np.ones(JET_ORDER + 1))
    # a general quotient: Q B = A
    a = _wavy(JET_ORDER + 1, 0.7, 1.3, 1.0, 0.2)
    b = _wavy(JET_ORDER + 1, 2.0, 0.4, 1.0, 1.4)
    for k in range(JET_ORDER + 1):
        q[k] = jet_div(a, b, q, k)
    _close(np.convolve(q, b)[: JET_ORDER + 1], a, 1e-12)


@pytest.mark.parametrize("a", [1.7, -2.3])
def test_jet_exp_of_a_tau(a: float) -> None:
    g = np.zeros(JET_ORDER + 1)
    g[1] = a
    e = np.full(JET_ORDER + 1, np.nan)
    for k in range(JET_ORDER + 1):
        e[k] = jet_exp(g, e, k)
    _close(e, np.array([a**k / math.factorial(k) for k in range(JET_ORDER + 1)]))


@pytest.mark.parametrize("n", [1.5, 2.3, -0.5, 3.0])
@pytest.mark.parametrize("a0", [1.0, 2.0])
def test_jet_pow_is_the_binomial_series(n: float, a0: float) -> None:
    """(a0 + c tau)^n = a0^n sum_k C(n, k) (c / a0)^k tau^k (n = 3: zeros above 3)."""
    c = 0.6
    a = np.zeros(JET_ORDER + 1)
    a[:2] = (a0, c)
    r = np.full(JET_ORDER + 1, np.nan)
    for k in range(JET_ORDER + 1):
        r[k] = jet_pow(a, r, n, k)
    want = np.empty(JET_ORDER + 1)
    binom = 1.0
    for k in range(JET_ORDER + 1):
        want[k] = a0**n * binom * (c / a0) ** k
        binom *= (n - k) / (k + 1)
    _close(r, want)
    if n == 3.0:
        assert np.all(r[4:] == 0.0)


def test_jet_atan_of_tau() -> None:
    """atan(tau) = tau - tau^3/3 + tau^5/5 - ..."""
    u = np.zeros(JET_ORDER + 1)
    u[1] = 1.0
    w = np.full(JET_ORDER + 1, np.nan)
    z = np.full(JET_ORDER + 1, np.nan)
    for k in range(JET_ORDER + 1):
        z[k] = jet_atan(u, w, z, k)
    want = [0.0 if k % 2 == 0 else (-1.0) ** ((k - 1) // 2) / k for k in range(JET_ORDER + 1)]
    _close(z, np.array(want))
    _close(w[:3], np.array([1.0, 0.0, 1.0]))  # 1 + tau^2
    assert np.all(w[3:] == 0.0)


def _tanh_coefficients(order: int) -> list[float]:
    """tanh x = sum_{n>=1} 2^(2n) (2^(2n) - 1) B_2n / (2n)! x^(2n-1), B the Bernoulli
    numbers (exact, by their recurrence)."""
    bern = [Fraction(1)]
    for m in range(1, order + 2):
        bern.append(-sum((math.comb(m + 1, j) * bern[j] for j in range(m)), Fraction(0)) / (m + 1))
    out = [0.0] * (order + 1)
    for k in range(1, order + 1, 2):
        n2 = k + 1
        out[k] = float(2**n2 * (2**n2 - 1) * bern[n2] / math.factorial(n2))
    return out


def test_jet_tanh_of_tau() -> None:
    want = _tanh_coefficients(JET_ORDER)
    assert want[1:8:2] == pytest.approx([1.0, -1.0 / 3.0, 2.0 / 15.0, -17.0 / 315.0], rel=1e-15)
    u = np.zeros(JET_ORDER + 1)
    u[1] = 1.0
    t = np.full(JET_ORDER + 1, np.nan)
    q = np.full(JET_ORDER + 1, np.nan)
    for k in range(JET_ORDER + 1):
        assert jet_tanh(u, t, q, k) == t[k]
    _close(t, np.array(want))
    one_minus_t2 = -np.convolve(t, t)[: JET_ORDER + 1]
    one_minus_t2[0] += 1.0
    _close(q, one_minus_t2, 1e-12)  # q = 1 - tanh^2


def test_jet_cos_linear_against_the_derivatives() -> None:
    """a cos(w (t + tau) + phase): coefficient k = a Re((i w)^k e^(i (w t + phase))) / k!;
    ``add`` accumulates."""
    a, w, ph, t = 0.8, 3.0, 0.4, 0.7
    out = np.full(JET_ORDER + 2, np.nan)
    jet_cos_linear(a, w, ph, t, JET_ORDER, out, False)
    assert np.isnan(out[JET_ORDER + 1])  # writes 0..order only
    ik = [1, 1j, -1, -1j]
    e = complex(math.cos(w * t + ph), math.sin(w * t + ph))
    want = np.array(
        [a * (ik[k % 4] * e).real * w**k / math.factorial(k) for k in range(JET_ORDER + 1)]
    )
    _close(out[: JET_ORDER + 1], want)
    jet_cos_linear(a, w, ph, t, JET_ORDER, out, True)
    _close(out[: JET_ORDER + 1], 2.0 * want)


# ---------------------------------------------------------------------------------------
# contact laws
# ---------------------------------------------------------------------------------------

CONTACT_LAWS = [
    PowerLawContact(1e9, 1.5, 0.8),  # Hertz (the fast path)
    PowerLawContact(3e8, 2.3, 0.5),
    PowerLawContact(1e6, 1.0, 0.3),  # integer exponent
    KelvinVoigtContact(2e6, 150.0),
]


@pytest.mark.parametrize("v0", [0.3, math.inf])
@pytest.mark.parametrize("law", CONTACT_LAWS, ids=lambda law: f"{type(law).__name__}")
def test_contact_force_series_converges_to_the_forces(law, v0: float) -> None:
    T = 2e-4  # time scale of the penetration [s]
    poly = _wavy(TOP + 8, 1e-5, 1e-5, T, 0.3)  # p(tau), of a degree above TOP
    dpoly = _deriv(poly)
    P = poly[: TOP + 2].copy()  # the series reads P[0..k + 1]
    out = np.full((3, TOP + 1), np.nan)
    _contact_series(law, P, v0, TOP, _work(TOP), out)

    def forces(tau: float) -> tuple[float, float, float]:
        fk, fc, _ = contact_forces.py(law, _horner(poly, tau), _horner(dpoly, tau), v0)
        return fk, fc, fk + fc  # N unclamped

    f0 = forces(0.0)
    for i in range(3):
        assert out[i, 0] == pytest.approx(f0[i], rel=1e-15, abs=0.0)
    damped = isinstance(law, KelvinVoigtContact) or not math.isinf(v0)
    if not damped:  # a power law released elastically: no damping term
        assert np.all(out[1] == 0.0)
        np.testing.assert_array_equal(out[2], out[0])
    for i in range(3 if damped else 1):

        def force(tau: float, i: int = i) -> float:
            return forces(tau)[i]

        _assert_order(out[i], ORDER, force, T, max(abs(f0[i]), abs(f0[0])))


ONSET_LAWS = [law for law in CONTACT_LAWS if not isinstance(law, PowerLawContact)] + [
    PowerLawContact(1e9, 1.5, 0.8),
    PowerLawContact(1e6, 1.0, 0.3),
    PowerLawContact(1e7, 2.0, 0.4),
]


@pytest.mark.parametrize("v0", [0.3, math.inf])
@pytest.mark.parametrize("law", ONSET_LAWS, ids=lambda law: f"{type(law).__name__}")
def test_contact_onset_series_converges_to_the_forces(law, v0: float) -> None:
    """From an onset: p(t + s^2) = s^2 q(s), q(0) > 0; (F_c, N) as series in s against the
    law's forces along p(s) and p' = dp/dt = (dp/ds) / (2 s)."""
    S_scale = 1e-2  # s scale [sqrt(s)] (1e-4 s of contact)
    qpoly = _wavy(TOP + 8, 0.4, 0.3, S_scale, 0.9)  # q(s), q0 = p'(onset) = 0.4 m/s
    ppoly = np.concatenate([[0.0, 0.0], qpoly])  # p = s^2 q
    dppoly = _deriv(ppoly)  # dp/ds, whose constant term is 0
    Q = qpoly[: TOP + 1].copy()  # the series reads Q[0..k]
    out = np.full((2, TOP + 1), np.nan)
    _contact_onset_series(law, Q, v0, TOP, _work(TOP), out)

    def forces(s: float) -> tuple[float, float]:
        rate = _horner(dppoly[1:], s) / 2.0  # (dp/ds) / (2 s)
        fk, fc, _ = contact_forces.py(law, _horner(ppoly, s), rate, v0)
        return fc, fk + fc  # N unclamped

    m = _onset_power(law)
    assert m == round(2 * getattr(law, "exponent", 1.0))
    damped = isinstance(law, KelvinVoigtContact) or not math.isinf(v0)
    if not damped:
        assert np.all(out[0] == 0.0)
    # the stiffness force starts at s^m (the damping force of Kelvin-Voigt at s^0)
    fk_series = out[1] - out[0]
    assert np.all(fk_series[:m] == 0.0)
    scale = abs(forces(S_scale)[1])
    for i in (0, 1) if damped else (1,):

        def force(s: float, i: int = i) -> float:
            return forces(s)[i]

        _assert_order(out[i], ORDER, force, S_scale, scale)


def test_a_power_law_of_non_integer_2n_has_no_onset_series() -> None:
    assert _onset_power(PowerLawContact(3e8, 2.3, 0.5)) == 0
    assert _onset_power(PowerLawContact(1e9, 1.5, 0.5)) == 3


def test_power_law_series_is_the_closed_form_on_a_linear_penetration() -> None:
    """p = p0 + v tau: F_k = K p0^n (1 + v tau / p0)^n, binomial coefficients."""
    K, n, D, v0 = 1e9, 1.5, 0.8, 0.4
    p0, v = 1e-5, 0.3
    P = np.zeros(ORDER + 2)
    P[:2] = (p0, v)
    out = np.full((3, ORDER + 1), np.nan)
    _contact_series(PowerLawContact(K, n, D), P, v0, ORDER, _work(ORDER), out)
    binom = np.ones(ORDER + 1)
    for k in range(1, ORDER + 1):
        binom[k] = binom[k - 1] * (n - k + 1) / k
    fk = K * p0**n * binom * (v / p0) ** np.arange(ORDER + 1)
    _close(out[0], fk)
    _close(out[1], fk * D * v / v0)  # p' = v constant
    _close(out[2], out[0] + out[1], 1e-15)


# ---------------------------------------------------------------------------------------
# friction laws
# ---------------------------------------------------------------------------------------

FRICTION_LAWS = [
    RegularizedFriction(FRICTION_CODES["arctan"], 0.01),
    RegularizedFriction(FRICTION_CODES["tanh"], 0.01),
    RegularizedFriction(FRICTION_CODES["stribeck"], 0.01, 1.8, 0.005),
    # a smoother sign function: the Stribeck factor and the viscous term weigh more in the
    # high coefficients
    RegularizedFriction(FRICTION_CODES["stribeck"], 0.05, 1.8, 0.005),
    CoulombViscousFriction(0.01, 2.0),
    CoulombViscousFriction(0.05, 500.0),
]


@pytest.mark.parametrize("constant_normal", [False, True])
@pytest.mark.parametrize("law", FRICTION_LAWS, ids=lambda law: f"{type(law).__name__}{law[0]}")
def test_friction_force_series_converges_to_the_force(law, constant_normal: bool) -> None:
    T, mu = 1e-3, 0.3
    vpoly = _wavy(TOP + 8, 0.004, 0.006, T, 0.9)  # v(tau) [m/s]
    npoly = _wavy(TOP + 8, 10.0, 4.0, T, 2.1)  # N(tau) [N]
    if constant_normal:
        npoly[1:] = 0.0
    V = vpoly[: TOP + 1].copy()
    NS = npoly[: TOP + 1].copy()
    out = np.full(TOP + 1, np.nan)
    _friction_series(law, V, NS, mu, TOP, _work(TOP), out)

    def force(tau: float) -> float:
        return float(friction_force.py(law, _horner(vpoly, tau), _horner(npoly, tau), mu))

    f0 = force(0.0)
    assert out[0] == pytest.approx(f0, rel=1e-15, abs=0.0)
    _assert_order(out, ORDER, force, T, abs(f0))


def test_friction_series_of_the_law_none_is_zero() -> None:
    law = RegularizedFriction(FRICTION_CODES["none"], 0.01)
    V = _wavy(ORDER + 1, 0.004, 0.006, 1e-3, 0.9)
    out = np.full(ORDER + 1, np.nan)
    _friction_series(law, V, V, 0.3, ORDER, _work(ORDER), out)
    assert np.all(out == 0.0)
    assert friction_force.py(law, V[0], 10.0, 0.3) == 0.0


def test_tanh_friction_series_is_the_closed_form_on_a_linear_speed() -> None:
    """v = v_hat tau, constant N: f = mu N tanh(tau), the Bernoulli coefficients."""
    law = RegularizedFriction(FRICTION_CODES["tanh"], 0.02)
    V = np.zeros(ORDER + 1)
    V[1] = 0.02
    NS = np.zeros(ORDER + 1)
    NS[0] = 5.0
    out = np.full(ORDER + 1, np.nan)
    _friction_series(law, V, NS, 0.4, ORDER, _work(ORDER), out)
    _close(out, 0.4 * 5.0 * np.array(_tanh_coefficients(ORDER)))


@njit(boundscheck=True)
def _friction_reach(law, V, h):
    return friction_series_reach(law, V, h)


def _linear(v0: float, a: float, order: int = 12) -> np.ndarray:
    V = np.zeros(order + 1)
    V[0], V[1] = v0, a
    return V


@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize(("scale", "power"), [(5e-4, 1), (0.01, 2)])
def test_saturation_reach_stops_where_the_exponent_has_fallen(
    sign: float, scale: float, power: int
) -> None:
    """v = v0 - a sigma from deep saturation through 0 in one step: the reach is where
    E = (|v| / scale)^power has fallen to SATURATED - HIDDEN_FALL (closed form), whether the
    samples straddle v = 0 (a long step) or land near it."""
    e_stop = (SATURATED - HIDDEN_FALL) ** (1.0 / power)
    for h in (4e-4, 5.2e-5):
        V = sign * _linear(0.5, -10400.0)
        expect = (0.5 - e_stop * scale) / 10400.0
        assert saturation_reach(V, scale, power, h) == pytest.approx(expect, rel=1e-8)


def test_saturation_reach_is_the_whole_step_where_nothing_hides() -> None:
    vh2 = 5e-4  # tanh's scale for v_hat = 1 mm/s
    # saturated throughout (E from 2000 to 1200)
    assert saturation_reach(_linear(1.0, -400.0), vh2, 1, 1e-3) == 1e-3
    # a fall of E by less than HIDDEN_FALL (20 to 15)
    assert saturation_reach(_linear(10 * vh2, -2.5 * vh2 / 1e-3), vh2, 1, 1e-3) == 1e-3
    # from the turn-over's core (E_0 = 4): tanh's poles show in its coefficients there
    assert saturation_reach(_linear(2 * vh2, -1.0), vh2, 1, 1e-3) == 1e-3
    # growing |v| (a decaying exp(-E)): its coefficients show it
    assert saturation_reach(_linear(0.02, 100.0), vh2, 1, 1e-3) == 1e-3


@pytest.mark.parametrize("law", FRICTION_LAWS, ids=lambda law: f"{type(law).__name__}{law[0]}")
def test_friction_series_reach_of_each_law(law) -> None:
    """A turn-over from v = 0.5 m/s at 10^4 m/s^2 within a step of 0.4 ms: a law with a tanh
    part stops the step before it; arctan (whose series carry its branch points) and the
    law none do not."""
    V = _linear(0.5, -1e4)
    reach = _friction_reach(law, V, 4e-4)
    saturating = isinstance(law, CoulombViscousFriction) or law.law in (
        FRICTION_CODES["tanh"],
        FRICTION_CODES["stribeck"],
    )
    if saturating:
        assert 0.0 < reach < 0.5 / 1e4
    else:
        assert reach == 4e-4


# ---------------------------------------------------------------------------------------
# wall motions
# ---------------------------------------------------------------------------------------


def _check_wall_start(ex, t: float, H: np.ndarray) -> None:
    """H[0], H[1], 2 H[2] are wall_motion's h, h', h'' at t."""
    h, hd, hdd = wall_motion.py(ex, t)
    assert H[0] == pytest.approx(h, rel=1e-15, abs=0.0)
    assert H[1] == pytest.approx(hd, rel=1e-15, abs=0.0)
    assert 2.0 * H[2] == pytest.approx(hdd, rel=1e-15, abs=0.0)


def _wall_orders(ex, t: float) -> np.ndarray:
    """H[0..TOP] of an analytic wall motion (horizon inf); its series of ORDER is their start
    (it writes H[0..ORDER] only)."""
    H = np.full(TOP + 2, np.nan)
    assert _wall_series(ex, t, TOP, H) == math.inf
    assert np.isnan(H[TOP + 1])
    h = np.full(ORDER + 2, np.nan)
    assert _wall_series(ex, t, ORDER, h) == math.inf
    assert np.isnan(h[ORDER + 1])
    np.testing.assert_array_equal(h[: ORDER + 1], H[: ORDER + 1])
    return H[: TOP + 1]


def test_track_harmonics_series_converges_to_the_motion() -> None:
    tab = np.array([[1e-3, 2 * math.pi * 50, 0.4], [2e-4, 2 * math.pi * 130, -1.1]])
    ex = TrackHarmonics(tab)
    for t in (0.0137, 1.234):
        H = _wall_orders(ex, t)
        _check_wall_start(ex, t, H)
        # the rounding of t + tau moves the phase by up to w eps |t|
        noise = 2e-15 + 4 * 2.2e-16 * tab[:, 1].max() * t

        def h(tau: float, t: float = t) -> float:
            return float(wall_motion.py(ex, t + tau)[0])

        _assert_order(H, ORDER, h, 0.05, 1.2e-3, noise)


def _horn_gear_harmonic() -> HornGear:
    harm = np.array([[0.5, 0.0, 0.3], [2.0, 30.0, 0.1], [1.0, 70.0, -0.4]])  # w = 0: constant
    e = np.zeros(0)
    return HornGear(0.04, 10.0, harm, e, e, e)


def test_horn_gear_series_converges_to_the_slot_travel() -> None:
    ex = _horn_gear_harmonic()
    for t in (0.23, 3.1):
        H = _wall_orders(ex, t)
        _check_wall_start(ex, t, H)
        s0 = float(horn_gear_state(ex, t)[1])
        # the rounding of t + tau: r_c |omega| eps t
        noise = 2e-15 + 4 * 2.2e-16 * 0.04 * 13.5 * t / abs(s0)

        def s(tau: float, t: float = t) -> float:
            return float(horn_gear_state(ex, t + tau)[1])

        _assert_order(H, ORDER, s, 0.5, abs(s0), noise)


def test_horn_gear_series_of_a_constant_speed() -> None:
    """omega = omega0 + a cos(psi) (a harmonic of frequency 0): s linear in tau."""
    e = np.zeros(0)
    ex = HornGear(0.05, 8.0, np.array([[1.5, 0.0, 0.6]]), e, e, e)
    H = np.full(ORDER + 1, np.nan)
    _wall_series(ex, 0.7, ORDER, H)
    om = 8.0 + 1.5 * math.cos(0.6)
    assert H[0] == pytest.approx(0.05 * om * 0.7, rel=1e-14)
    assert H[1] == pytest.approx(0.05 * om, rel=1e-15)
    assert np.all(H[2:] == 0.0)


def _horn_gear_profile() -> HornGear:
    pt = np.array([0.02, 0.12, 0.27, 0.42])
    pw = np.array([5.0, 9.0, 6.0, 7.0])
    pi_ = np.concatenate(([0.0], np.cumsum(0.5 * (pw[1:] + pw[:-1]) * np.diff(pt))))
    return HornGear(0.04, 0.0, np.zeros((0, 3)), pt, pw, pi_)


@pytest.mark.parametrize(
    ("t", "piece"),
    [(0.05, 0), (0.12, 1), (0.3, 2), (0.55, 1), (-0.17, 1), (0.02, 0)],
)
def test_horn_gear_profile_series_is_exact_up_to_the_piece_end(t: float, piece: int) -> None:
    ex = _horn_gear_profile()
    pt = ex.profile_times
    period = pt[-1] - pt[0]
    H = np.full(ORDER + 1, np.nan)
    horizon = _wall_series(ex, t, ORDER, H)
    # the piece holding t (at a knot, the one that starts there) ends after the horizon
    tau = (t - pt[0]) % period
    assert tau - (pt[piece] - pt[0]) >= 0.0
    assert horizon == pytest.approx(pt[piece + 1] - pt[0] - tau, abs=1e-14)
    _check_wall_start(ex, t, H)
    assert np.all(H[3:] == 0.0)

    def s(tau: float) -> float:
        return float(horn_gear_state(ex, t + tau)[1])

    scale = abs(s(0.0)) + 1.0
    for f in (0.1, 0.5, 0.9, 0.999):
        assert _horner(H, f * horizon) == pytest.approx(s(f * horizon), abs=1e-13 * scale)
    # beyond the piece's end the speed's slope changes: the series no longer holds
    nxt = (piece + 1) % (len(pt) - 1)
    beyond = horizon + 0.5 * (pt[nxt + 1] - pt[nxt])
    assert abs(_horner(H, beyond) - s(beyond)) > 1e-5


def _measured_track() -> MeasuredTrack:
    times = np.linspace(0.0, 0.2, 11)
    w = 2 * math.pi / 0.2
    h = 1e-3 * np.sin(w * times + 0.3) + 3e-4 * np.cos(3 * w * times)
    return MeasuredTrack.from_samples(times, h)


@pytest.mark.parametrize(
    ("where", "piece"), [("inside", 1), ("knot", 3), ("next period", 3), ("before start", 7)]
)
def test_measured_track_series_is_the_piece_cubic(where: str, piece: int) -> None:
    ex = _measured_track()
    ts = ex.times
    t = {"inside": 0.033, "knot": ts[3], "next period": 0.27, "before start": -0.05}[where]
    period = ts[-1] - ts[0]
    H = np.full(ORDER + 2, np.nan)
    horizon = _wall_series(ex, t, ORDER, H)
    assert np.isnan(H[ORDER + 1])
    # the piece holding t (at a knot, the one that starts there) ends after the horizon
    tau = (t - ts[0]) % period
    i = int(np.searchsorted(ts, ts[0] + tau, side="right")) - 1
    assert i == piece
    assert horizon == pytest.approx(ts[i + 1] - ts[0] - tau, abs=1e-14)
    _check_wall_start(ex, t, H)
    assert H[3] == ex.coeffs[0, i]
    assert np.all(H[4 : ORDER + 1] == 0.0)
    scale = 1.3e-3
    for f in (0.1, 0.5, 0.9, 0.999):
        got = _horner(H[: ORDER + 1], f * horizon)
        assert got == pytest.approx(wall_motion.py(ex, t + f * horizon)[0], abs=1e-14 * scale)
    beyond = horizon + 0.5 * (ts[1] - ts[0])
    assert abs(_horner(H[: ORDER + 1], beyond) - wall_motion.py(ex, t + beyond)[0]) > 1e-9
