"""Contact laws: damping factors as printed in the paper, exact restitution, Hertz stiffness."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import integrate

from braidsim import contact
from braidsim.errors import InputError

C = 5.0 / 9.0

# D(c_r) at c_r = 5/9 evaluated by hand from the printed Eqs. (5)-(13)
PRINTED_D = {
    "hunt_crossley": 3 * (1 - C) / 2,
    "herbert_mcwhannell": 6 * (1 - C) / ((2 * C - 1) ** 2 + 3),
    "lee_wang": 3 * (1 - C) / 4,
    "lankarani_nikravesh": 3 * (1 - C**2) / 4,
    "gonthier": (1 - C**2) / C,
    "zhiying_qishao": 3 * (1 - C**2) * math.exp(2 * (1 - C)) / 4,
    "flores": 8 * (1 - C) / (5 * C),
    "hertz": 0.0,
    "brandlein": 0.0,
}


@pytest.mark.parametrize(("name", "d"), PRINTED_D.items())
def test_damping_factor_matches_printed_formula(name: str, d: float) -> None:
    assert contact.get_law(name).damping_factor(C) == pytest.approx(d, rel=1e-14, abs=0)


def test_every_law_documents_formula_and_reference() -> None:
    for name in contact.law_names():
        law = contact.get_law(name)
        assert law.reference
        assert law.equation
        assert "D" in law.formula, name


def _restitution_by_quadrature(d: float) -> float:
    """Restitution of m v dv/dp = -K p^n (1 + d v / v0), integrated independently.

    With w = v / v0 the energy-like integral of the module docstring gives, for the two
    half-impacts, int_{w}^{1} w/(1 + d w) dw = int_0^{e} w/(1 - d w) dw (equal elastic work),
    solved here by root finding on numerical quadrature.
    """
    from scipy.optimize import brentq

    comp = integrate.quad(lambda w: w / (1 + d * w), 0.0, 1.0, limit=200)[0]

    def f(e: float) -> float:
        return integrate.quad(lambda w: w / (1 - d * w), 0.0, e, limit=200)[0] - comp

    # the rebound never makes 1 - d w vanish (e d < 1), so the bracket stops short of 1/d
    return brentq(f, 1e-9, min(1.0, (1.0 - 1e-6) / d), xtol=1e-14)


@pytest.mark.parametrize("d", [1e-6, 1e-3, 0.05, 0.3, 2.0 / 3.0, 1.0, 1.28, 3.0])
def test_exact_restitution_against_quadrature(d: float) -> None:
    assert contact.effective_restitution(d) == pytest.approx(
        _restitution_by_quadrature(d), rel=1e-9
    )


def test_lambert_w0_against_scipy() -> None:
    """The principal branch written out for the exact restitution solves w e^w = z to
    rounding over -1/e <= z < 0 (up to the branch point, where W0 is ill-conditioned), and
    agrees with SciPy's at the arguments the restitution asks for (D >= 1e-2)."""
    from scipy import special

    z = np.concatenate(
        [-np.exp(-1.0) * (1.0 - np.logspace(-16, 0, 400))[:-1], -np.logspace(-300, -0.44, 400)]
    )
    w = np.array([contact._lambert_w0(float(v)) for v in z])
    assert np.all((w >= -1.0) & (w < 0.0))
    assert np.all(np.abs(w * np.exp(w) - z) <= 4e-16 * np.abs(z))
    assert contact._lambert_w0(-math.exp(-1.0)) == pytest.approx(-1.0, abs=2e-8)
    d = np.logspace(-2, 2.8, 2000)  # (z underflows past D ~ 700)
    z = -(1.0 + d) * np.exp(-(1.0 + d))
    w = np.array([contact._lambert_w0(float(v)) for v in z])
    ref = special.lambertw(z, 0).real
    assert np.max(np.abs(w - ref) / np.abs(ref)) < 3e-14


def test_exact_restitution_limits() -> None:
    assert contact.effective_restitution(0.0) == 1.0
    es = [contact.effective_restitution(d) for d in np.linspace(0.01, 10, 50)]
    assert all(a > b for a, b in itertools.pairwise(es))


@pytest.mark.parametrize("c_r", [0.1, 0.3, C, 0.8, 0.95, 0.999])
def test_carvalho_martins_restitutes_exactly(c_r: float) -> None:
    d = contact.get_law("carvalho_martins").damping_factor(c_r)
    assert contact.effective_restitution(d) == pytest.approx(c_r, abs=1e-12)


@pytest.mark.parametrize("name", contact.law_names())
def test_restitution_at_inverts_the_damping_factor(name: str) -> None:
    """c_r(D) of each law (closed form, or Brent's method for Zhiying-Qishao) gives back
    the c_r of D(c_r) over (0, 1]; 1 at D = 0, 0 beyond the law's largest D (its value at
    c_r -> 0), nan for the elastic laws, whose D does not depend on c_r."""
    law = contact.get_law(name)
    if not law.dissipative:
        assert math.isnan(law.restitution_at(0.5))
        return
    for c_r in np.linspace(0.01, 1.0, 100):
        assert law.restitution_at(law.damping_factor(float(c_r))) == pytest.approx(c_r, abs=1e-13)
    assert law.restitution_at(0.0) == 1.0
    top = {
        "hunt_crossley": 1.5,
        "herbert_mcwhannell": 1.5,
        "lee_wang": 0.75,
        "lankarani_nikravesh": 0.75,
        "zhiying_qishao": 0.75 * math.e**2,
    }
    if name in top:
        assert law.restitution_at(top[name] * 1.01) == 0.0


def test_hertz_stiffness_eq4_calibrated_and_printed() -> None:
    # docs/model.md §1: K = 2.4904e10 N/m^1.5 at E = 200 GPa, 2.490e8 at the printed 2 GPa
    k200 = contact.hertz_stiffness(200e9, 0.3, 0.020, 200e9, 0.3, 0.065, "concave")
    k2 = contact.hertz_stiffness(2e9, 0.3, 0.020, 2e9, 0.3, 0.065, "concave")
    assert k200 == pytest.approx(2.4904e10, rel=1e-4)
    assert k2 == pytest.approx(2.4904e8, rel=1e-4)
    # the reported forces follow from it (section 3.3: 0.120 mm -> 32737 N; 3.4: 0.4 mm -> 199229 N)
    assert k200 * (1.2e-4) ** 1.5 == pytest.approx(32737, rel=1e-4)
    assert k200 * (4e-4) ** 1.5 == pytest.approx(199229, rel=1e-4)


def test_effective_radius_geometries() -> None:
    assert contact.effective_radius(0.02, 0.065, "concave") == pytest.approx(
        1 / (1 / 0.02 - 1 / 0.065)
    )
    assert contact.effective_radius(0.02, 0.065, "convex") == pytest.approx(
        1 / (1 / 0.02 + 1 / 0.065)
    )
    assert contact.effective_radius(0.01, math.inf, "flat") == 0.01


def test_hertz_closed_form_duration_factor() -> None:
    # Johnson (1985): T = 2.94 p_m / v0 for n = 3/2
    cf = contact.hertz_impact_closed_form(1.0, 1e10, 1.5, 1.0)
    assert cf["contact_duration"] * 1.0 / cf["max_depth"] == pytest.approx(2.9432, rel=1e-4)


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda: contact.hertz_stiffness(-2e9, 0.3, 0.02, 2e11, 0.3, 0.065, "concave"), "e1"),
        (lambda: contact.hertz_stiffness(2e9, 0.6, 0.02, 2e11, 0.3, 0.065, "concave"), "nu1"),
        (lambda: contact.hertz_stiffness(2e9, 0.3, 0.0, 2e11, 0.3, 0.065, "flat"), "r1"),
        (lambda: contact.effective_radius(0.02, -1.0, "convex"), "r2"),
        (lambda: contact.resting_depth(-1.0, 1e9, 1.5), "load"),
        (lambda: contact.resting_depth(1.0, 0.0, 1.5), "stiffness"),
        (lambda: contact.damping_factors(0.0), "c_r"),
        (lambda: contact.damping_factors(2.0), "c_r"),
    ],
)
def test_the_public_formulas_refuse_out_of_range_arguments_by_name(call, name: str) -> None:
    """One InputError naming the argument and its range, not a ZeroDivisionError, a complex
    number or a negative damping factor."""
    with pytest.raises(InputError) as err:
        call()
    msg = str(err.value)
    assert msg.startswith(f"{name}: ") and "allowed" in msg and "\n" not in msg


def test_a_plane_is_an_infinite_radius() -> None:
    assert contact.effective_radius(0.02, math.inf, "convex") == pytest.approx(0.02)
    assert contact.resting_depth(0.0, 1e9, 1.5) == 0.0
