"""Contact force laws: Hertz stiffness (Eq. 4) and the laws of Eqs. (3)-(13).

Every law of the paper has the form

    F_n = K p^n (1 + D(c_r) pdot / v0)                                   [N]

with p >= 0 the penetration [m], pdot its rate [m/s], v0 > 0 the approach speed latched at
contact onset [m/s], K the contact stiffness [N/m^n], n the exponent, and D the
dimensionless *damping factor* of the law, a function of the coefficient of restitution
c_r only. The stiffness-related force of the paper is F_kg = K p^n and the damping-related
force F_cg = K p^n D pdot / v0. An elastic law has D = 0.

Because all laws share this form, one impact of a free mass obeys (divide
m v dv/dp = -K p^n (1 + D v / v0) by 1 + D v / v0 and integrate over the whole impact)

    1 - D e = (1 + D) exp(-D (1 + e))                                     (exact)

for the effective restitution e = -v_rebound / v0, whatever m, K, n and v0. Its solution is
``e = (1 + W0(-(1 + D) exp(-(1 + D)))) / D`` with W0 the principal branch of the Lambert W
function (:func:`effective_restitution`). The laws differ only in D(c_r); a law whose e
equals c_r exactly is obtained by solving this relation for D (:func:`exact_damping_factor`,
law ``carvalho_martins``).

References
----------
The laws are those of the reproduced paper (Zhang, Meng, Du & Sun, Eqs. 3-13), each with its
original source. A DOI is given where it was checked against a second, independent listing;
the docs page *Contact and friction laws* (docs/laws.md) has the formulas and the same list.

.. [HZ] Hertz H. (1882) Ueber die Beruehrung fester elastischer Koerper. J. reine angew. Math.
   92:156-171. doi:10.1515/crll.1882.92.156
.. [JO] Johnson K.L. (1985) Contact Mechanics. Cambridge University Press.
   doi:10.1017/CBO9781139171731
.. [BR] Braendlein J., Eschmann P., Hasbargen L., Weigand K. (1999) Ball and Roller Bearings:
   Theory, Design and Application, 3rd ed. Wiley (n = 1.08 for line contact).
.. [HC] Hunt K.H., Crossley F.R.E. (1975) Coefficient of restitution interpreted as damping in
   vibroimpact. J. Appl. Mech. 42:440-445. doi:10.1115/1.3423596
.. [HM] Herbert R.G., McWhannell D.C. (1977) Shape and frequency composition of pulses from an
   impact pair. J. Eng. Ind. 99:513-518.
.. [LW] Lee T.W., Wang A.C. (1983) On the dynamics of intermittent-motion mechanisms, Part 1:
   Dynamic model and response. J. Mech. Trans. Autom. Des. 105:534-540.
.. [LN] Lankarani H.M., Nikravesh P.E. (1990) A contact force model with hysteresis damping for
   impact analysis of multibody systems. J. Mech. Des. 112(3):369-376. doi:10.1115/1.2912617
.. [LN94] Lankarani H.M., Nikravesh P.E. (1994) Continuous contact force models for impact
   analysis in multibody systems. Nonlinear Dyn. 5:193-207. doi:10.1007/BF00045676
.. [GO] Gonthier Y., McPhee J., Lange C., Piedboeuf J.-C. (2004) A regularized contact model
   with asymmetric damping and dwell-time dependent friction. Multibody Syst. Dyn. 11:209-233.
   doi:10.1023/B:MUBO.0000029392.21648.bc
.. [ZQ] Zhiying Q., Qishao L. (2006) Analysis of impact process based on restitution
   coefficient. J. Dyn. Control 4:294-298 (in Chinese).
.. [FL] Flores P., Machado M., Silva M.T., Martins J.M. (2011) On the continuous contact force
   models for soft materials in multibody dynamics. Multibody Syst. Dyn. 25:357-375.
   doi:10.1007/s11044-010-9237-4
.. [CM] Carvalho A.S., Martins J.M. (2019) Exact restitution and generalizations for the
   Hunt-Crossley contact model. Mech. Mach. Theory 139:174-194.
   doi:10.1016/j.mechmachtheory.2019.03.028
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from braidsim.errors import InputError

# scipy is imported inside the functions that need it: it is the largest part of the
# package's import time, and a run of the command line with a built-in law never needs it.

# ----------------------------------------------------------------------------------------
# Damping factors D(c_r), one small function each (Eqs. 5-13 of the paper)
# ----------------------------------------------------------------------------------------


def damping_elastic(c_r: float) -> float:
    """Elastic contact (Hertz 1882, Eq. 3; Braendlein 1999): D = 0, no dissipation."""
    return 0.0


def damping_hunt_crossley(c_r: float) -> float:
    """Hunt & Crossley (1975), Eq. (5): D = 3 (1 - c_r) / 2.

    doi:10.1115/1.3423596. Derived for small losses (c_r near 1).
    """
    return 1.5 * (1.0 - c_r)


def damping_herbert_mcwhannell(c_r: float) -> float:
    """Herbert & McWhannell (1977), Eqs. (6)-(7): D = 6 (1 - c_r) / ((2 c_r - 1)^2 + 3).

    J. Eng. Ind. 99:513-518.
    """
    return 6.0 * (1.0 - c_r) / ((2.0 * c_r - 1.0) ** 2 + 3.0)


def damping_lee_wang(c_r: float) -> float:
    """Lee & Wang (1983), Eq. (8): D = 3 (1 - c_r) / 4.

    J. Mech. Trans. Autom. Des. 105:534-540.
    """
    return 0.75 * (1.0 - c_r)


def damping_lankarani_nikravesh(c_r: float) -> float:
    """Lankarani & Nikravesh (1990), Eq. (9): D = 3 (1 - c_r^2) / 4.

    J. Mech. Des. 112(3):369-376, doi:10.1115/1.2912617; the paper cites their 1994 review,
    Nonlinear Dyn. 5:193-207, doi:10.1007/BF00045676. Energy balance for c_r near 1.
    """
    return 0.75 * (1.0 - c_r**2)


def damping_gonthier(c_r: float) -> float:
    """Gonthier et al. (2004), Eq. (10): D = (1 - c_r^2) / c_r.

    Multibody Syst. Dyn. 11:209-233, doi:10.1023/B:MUBO.0000029392.21648.bc.
    """
    return (1.0 - c_r**2) / c_r


def damping_zhiying_qishao(c_r: float) -> float:
    """Zhiying & Qishao (2006), Eqs. (11)-(12): D = 3 (1 - c_r^2) exp(2 (1 - c_r)) / 4.

    J. Dyn. Control 4:294-298 (in Chinese).
    """
    return 0.75 * (1.0 - c_r**2) * math.exp(2.0 * (1.0 - c_r))


def damping_flores(c_r: float) -> float:
    """Flores et al. (2011), Eq. (13): D = 8 (1 - c_r) / (5 c_r).

    Multibody Syst. Dyn. 25:357-375, doi:10.1007/s11044-010-9237-4 (the paper's reference [25]
    is a different Flores & Ambrosio paper, on contact detection).
    """
    return 8.0 * (1.0 - c_r) / (5.0 * c_r)


def _lambert_w0(z: float) -> float:
    """The principal branch W0 of the Lambert W function (w e^w = z) for -1/e <= z < 0.

    Halley's iteration (Corless, Gonnet, Hare, Jeffrey & Knuth 1996, On the Lambert W
    function, Adv. Comput. Math. 5:329-359, doi:10.1007/BF02124750, Eq. 5.9) from the
    series about the branch point, w = -1 + p - p^2/3 + 11 p^3/72 with p = sqrt(2 (e z + 1))
    (their Eq. 4.22), until the correction is within a few units of the last place or stops
    shrinking (near the branch point, where the rounding of w e^w bounds it): one to four
    evaluations of w e^w over the whole interval. Written out here rather than taken from
    ``scipy.special.lambertw`` because every model asks it for its pairs, and importing
    scipy.special cost a run of the command line 0.08-0.1 s of CPU; on this interval the two
    agree to 3e-14 (tests/unit/test_contact.py).
    """
    p = math.sqrt(max(2.0 * (math.e * z + 1.0), 0.0))
    w = -1.0 + p * (1.0 + p * (-1.0 / 3.0 + p * (11.0 / 72.0)))
    last = math.inf
    for _ in range(30):
        ew = math.exp(w)
        f = w * ew - z
        w1 = w + 1.0
        if f == 0.0 or w1 == 0.0:
            break
        dw = f / (ew * w1 - (w + 2.0) * f / (2.0 * w1))
        if abs(dw) >= last:
            # no more progress: the corrections have reached the rounding of f, which near
            # the branch point (W0 ill-conditioned, dW/dz = W / (z (1 + W))) stays above the
            # test below and alternates in sign
            break
        w -= dw
        last = abs(dw)
        if abs(dw) <= 1e-15 * (1.0 + abs(w)):
            break
    return w


# (every model built asks it for both pairs, a W0 and a Newton polish: kept per factor)
@functools.lru_cache(maxsize=1024)
def effective_restitution(damping_factor: float) -> float:
    """Exact restitution e of one impact under ``F = K p^n (1 + D pdot / v0)``.

    ``e = (1 + W0(-(1 + D) exp(-(1 + D)))) / D`` for D > 0 and e = 1 for D = 0; it does not
    depend on mass, stiffness, exponent or approach speed (see the module docstring).

    Parameters
    ----------
    damping_factor : float
        D >= 0 [-].
    """
    d = float(damping_factor)
    if d < 0.0:
        raise InputError(f"damping factor: {d} is negative; allowed D >= 0")
    if d == 0.0:
        return 1.0
    if d < 1e-2:
        # W0 near its branch point -1/e loses digits; start from the series about D = 0
        e = 1.0 - 2.0 * d / 3.0 + 10.0 * d * d / 9.0
    else:
        e = (1.0 + _lambert_w0(-(1.0 + d) * math.exp(-(1.0 + d)))) / d
    # Newton polish on F(e) = ln(1 - D e) - ln(1 + D) + D (1 + e) = 0 (the relation in logs)
    for _ in range(4):
        if d * e >= 1.0:
            # large D: e = (1 - (1 + D) exp(-(1 + D)) ...) / D rounds to 1/D, the log form
            # is undefined there and the Lambert value is already exact to rounding
            break
        f = math.log1p(-d * e) - math.log1p(d) + d * (1.0 + e)
        fp = d - d / (1.0 - d * e)
        if fp == 0.0:
            break
        e -= f / fp
    return e


def exact_damping_factor(c_r: float) -> float:
    """Damping factor D whose exact restitution equals ``c_r`` (Carvalho & Martins 2019).

    Mech. Mach. Theory 139:174-194, doi:10.1016/j.mechmachtheory.2019.03.028.

    Solves ``1 - D c_r = (1 + D) exp(-D (1 + c_r))`` for D > 0 (D = 0 at c_r = 1). The root is
    bracketed because e(D) falls monotonically from 1 (D = 0) towards 0 (D -> inf).
    """
    if c_r >= 1.0:
        return 0.0
    from scipy import optimize

    # e(D) ~ 1/D for large D, so D = 2/c_r brackets from above.
    hi = 2.0 / c_r + 10.0
    return float(
        optimize.brentq(lambda d: effective_restitution(d) - c_r, 1e-10, hi, xtol=1e-15, rtol=1e-15)
    )


def damping_carvalho_martins(c_r: float) -> float:
    """Carvalho & Martins (2019): the D that makes the Hunt-Crossley form restitute exactly c_r.

    D solves ``1 - D c_r = (1 + D) exp(-D (1 + c_r))``; see :func:`exact_damping_factor`.
    """
    return exact_damping_factor(c_r)


# ----------------------------------------------------------------------------------------
# Their inverses c_r(D) in closed form, where one exists (ContactLaw.restitution_at)
# ----------------------------------------------------------------------------------------


def restitution_hunt_crossley(d: float) -> float:
    """c_r = 1 - 2 D / 3, the inverse of Eq. (5)."""
    return 1.0 - d / 1.5


def restitution_herbert_mcwhannell(d: float) -> float:
    """c_r of Eqs. (6)-(7): the root in [0, 1] of 4 D c^2 + (6 - 4 D) c + 4 D - 6 = 0,
    c_r = 2 (4 D - 6) / (4 D - 6 - sqrt(12 (3 + 4 D - 4 D^2))) (the form without the
    cancellation of the usual one at small D); 0 for D >= 3/2, where no c_r gives D."""
    disc = 12.0 * (3.0 + 4.0 * d - 4.0 * d * d)
    if d >= 1.5 or disc <= 0.0:
        return 0.0
    return 2.0 * (4.0 * d - 6.0) / (4.0 * d - 6.0 - math.sqrt(disc))


def restitution_lee_wang(d: float) -> float:
    """c_r = 1 - 4 D / 3, the inverse of Eq. (8)."""
    return 1.0 - d / 0.75


def restitution_lankarani_nikravesh(d: float) -> float:
    """c_r = sqrt(1 - 4 D / 3), the inverse of Eq. (9); 0 for D >= 3/4."""
    return math.sqrt(max(1.0 - d / 0.75, 0.0))


def restitution_gonthier(d: float) -> float:
    """c_r = 2 / (D + sqrt(D^2 + 4)), the positive root of c^2 + D c - 1 = 0 (Eq. 10)."""
    return 2.0 / (d + math.sqrt(d * d + 4.0))


def restitution_flores(d: float) -> float:
    """c_r = 8 / (8 + 5 D), the inverse of Eq. (13)."""
    return 8.0 / (8.0 + 5.0 * d)


@dataclass(frozen=True)
class ContactLaw:
    """A named contact force law ``F = K p^n (1 + D(c_r) pdot / v0)``.

    Attributes
    ----------
    name : str
        Registry name (``braidsim models``).
    damping : callable
        D(c_r) [-].
    default_exponent : float
        n used when ``contact.<pair>.exponent`` is not set.
    dissipative : bool
        False for the elastic laws (no restitution parameter used).
    equation : str
        Where the law stands in the paper.
    reference : str
        Citation.
    inverse : callable, optional
        c_r(D), the closed-form inverse of ``damping`` on (0, 1], where one exists
        (:meth:`restitution_at`).
    """

    name: str
    damping: Callable[[float], float]
    default_exponent: float
    dissipative: bool
    equation: str
    reference: str
    inverse: Callable[[float], float] | None = None

    def damping_factor(self, c_r: float) -> float:
        """D(c_r) of this law [-]."""
        return float(self.damping(c_r)) if self.dissipative else 0.0

    def restitution_at(self, damping_factor: float) -> float:
        """The nominal restitution c_r in [0, 1] at which D(c_r) equals ``damping_factor``
        [-]: the closed-form inverse where the law has one (``inverse``), else Brent's
        method on (0, 1], where every law's D falls from its value at c_r -> 0 to D(1) = 0.

        1 for a factor <= 0; 0 for a factor above every D of the law (its limit c_r -> 0:
        Hunt-Crossley's D stays below 3/2); nan for an elastic law (D does not depend on
        c_r).
        """
        if not self.dissipative:
            return math.nan
        d = float(damping_factor)
        if not d > 0.0:
            return 1.0
        if self.inverse is not None:
            return min(max(float(self.inverse(d)), 0.0), 1.0)
        from scipy import optimize

        low = 1e-12
        if self.damping(low) <= d:
            return 0.0
        return float(
            optimize.brentq(lambda c: self.damping(c) - d, low, 1.0, xtol=1e-15, rtol=1e-15)
        )

    @property
    def formula(self) -> str:
        """First line of the damping function's docstring: the formula of D."""
        doc = self.damping.__doc__ or ""
        return doc.strip().splitlines()[0]


_LAWS: dict[str, ContactLaw] = {
    law.name: law
    for law in (
        ContactLaw(
            "hertz",
            damping_elastic,
            1.5,
            False,
            "Eq. (3)",
            "Hertz (1882) doi:10.1515/crll.1882.92.156",
        ),
        ContactLaw(
            "brandlein",
            damping_elastic,
            1.08,
            False,
            "Eq. (3), n = 1.08",
            "Braendlein et al. (1999), Ball and Roller Bearings, Wiley",
        ),
        ContactLaw(
            "hunt_crossley",
            damping_hunt_crossley,
            1.5,
            True,
            "Eq. (5)",
            "Hunt & Crossley (1975) doi:10.1115/1.3423596",
            restitution_hunt_crossley,
        ),
        ContactLaw(
            "herbert_mcwhannell",
            damping_herbert_mcwhannell,
            1.5,
            True,
            "Eqs. (6)-(7)",
            "Herbert & McWhannell (1977) J. Eng. Ind. 99:513",
            restitution_herbert_mcwhannell,
        ),
        ContactLaw(
            "lee_wang",
            damping_lee_wang,
            1.5,
            True,
            "Eq. (8)",
            "Lee & Wang (1983) J. Mech. Trans. Autom. Des. 105:534",
            restitution_lee_wang,
        ),
        ContactLaw(
            "lankarani_nikravesh",
            damping_lankarani_nikravesh,
            1.5,
            True,
            "Eq. (9)",
            "Lankarani & Nikravesh (1990) doi:10.1115/1.2912617",
            restitution_lankarani_nikravesh,
        ),
        ContactLaw(
            "gonthier",
            damping_gonthier,
            1.5,
            True,
            "Eq. (10)",
            "Gonthier et al. (2004) doi:10.1023/B:MUBO.0000029392.21648.bc",
            restitution_gonthier,
        ),
        ContactLaw(
            "zhiying_qishao",
            damping_zhiying_qishao,
            1.5,
            True,
            "Eqs. (11)-(12)",
            "Zhiying & Qishao (2006) J. Dyn. Control 4:294",
        ),
        ContactLaw(
            "flores",
            damping_flores,
            1.5,
            True,
            "Eq. (13)",
            "Flores et al. (2011) doi:10.1007/s11044-010-9237-4",
            restitution_flores,
        ),
        ContactLaw(
            "carvalho_martins",
            damping_carvalho_martins,
            1.5,
            True,
            "not in the paper (exact restitution)",
            "Carvalho & Martins (2019) doi:10.1016/j.mechmachtheory.2019.03.028",
            effective_restitution,
        ),
    )
}


def law_names() -> list[str]:
    """Names of all contact laws, in registry order."""
    return list(_LAWS)


def get_law(name: str) -> ContactLaw:
    """The law called ``name``; an :class:`InputError` naming the closest law otherwise."""
    try:
        return _LAWS[name]
    except KeyError:
        import difflib

        close = difflib.get_close_matches(name, list(_LAWS), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise InputError(
            f"contact model: unknown law {name!r}{hint}; known: {', '.join(_LAWS)}"
        ) from None


# ----------------------------------------------------------------------------------------
# Stiffness, Eq. (4)
# ----------------------------------------------------------------------------------------

GEOMETRIES = ("concave", "convex", "flat")


def _check(
    name: str, value: float, low: float, high: float = math.inf, low_open: bool = True
) -> float:
    """``value`` as a float when low < value (or <=, ``low_open=False``) and value < high;
    an :class:`InputError` naming ``name`` and the allowed range otherwise (the public
    functions of this module are called from the API with numbers the scenario checks do
    not see)."""
    v = float(value)
    ok = (v > low if low_open else v >= low) and v < high and math.isfinite(v)
    if not ok:
        rel = ">" if low_open else ">="
        upper = f" and < {high:g}" if math.isfinite(high) else ""
        raise InputError(f"{name}: {value!r} is out of range; allowed {rel} {low:g}{upper}")
    return v


def effective_modulus(e1: float, nu1: float, e2: float, nu2: float) -> float:
    """E* = ((1 - nu1^2)/E1 + (1 - nu2^2)/E2)^-1 [Pa] (Eq. 4); E > 0, -1 < nu < 0.5."""
    e1, e2 = _check("e1", e1, 0.0), _check("e2", e2, 0.0)
    nu1, nu2 = _check("nu1", nu1, -1.0, 0.5), _check("nu2", nu2, -1.0, 0.5)
    return 1.0 / ((1.0 - nu1**2) / e1 + (1.0 - nu2**2) / e2)


def effective_radius(r1: float, r2: float, geometry: str) -> float:
    """Effective radius of two curved bodies [m] (Eq. 4).

    ``concave``: a body of radius r1 inside a hollow of radius r2 > r1 (the guide pad in the
    track), R = (1/r1 - 1/r2)^-1. ``convex``: two convex bodies, R = (1/r1 + 1/r2)^-1.
    ``flat``: a body of radius r1 on a plane, R = r1 (r2 is not used).
    """
    r1 = _check("r1", r1, 0.0)
    if geometry in ("convex", "concave") and not float(r2) > 0.0:  # (+inf: a plane)
        raise InputError(f"r2: {r2!r} is out of range; allowed > 0 (inf for a plane)")
    if geometry == "flat":
        return r1
    if geometry == "convex":
        return 1.0 / (1.0 / r1 + 1.0 / r2)
    if geometry == "concave":
        if r2 <= r1:
            raise InputError(
                f"contact geometry: concave contact needs the hollow radius ({r2} m) larger than "
                f"the body radius ({r1} m)"
            )
        return 1.0 / (1.0 / r1 - 1.0 / r2)
    raise InputError(f"contact geometry: unknown {geometry!r}; allowed: {', '.join(GEOMETRIES)}")


def hertz_stiffness(
    e1: float, nu1: float, r1: float, e2: float, nu2: float, r2: float, geometry: str
) -> float:
    """Hertz contact stiffness K = 4/3 E* R^(1/2) [N/m^1.5] (Eq. 4 of the paper).

    Johnson (1985), Contact Mechanics, Sect. 4.2, doi:10.1017/CBO9781139171731.
    """
    return (
        4.0
        / 3.0
        * effective_modulus(e1, nu1, e2, nu2)
        * math.sqrt(effective_radius(r1, r2, geometry))
    )


# ----------------------------------------------------------------------------------------
# Closed forms of an elastic impact (tests, `braidsim impact` cross-checks)
# ----------------------------------------------------------------------------------------


def hertz_impact_closed_form(
    mass: float, stiffness: float, exponent: float, velocity: float
) -> dict[str, float]:
    """Closed forms of one elastic impact ``m p'' = -K p^n`` with approach speed v0.

    max depth      p_m = ((n + 1) m v0^2 / (2 K))^(1/(n+1))                       [m]
    peak force     F_m = K p_m^n                                                 [N]
    duration       T = 2 p_m / v0 * B(1/(n+1), 1/2) / (n + 1)                     [s]

    (T follows from dt = dp / sqrt(v0^2 - 2 K p^(n+1) / ((n+1) m)); for n = 3/2 the factor
    2 B(2/5, 1/2) / (5/2) is 2.9432, Johnson 1985, Sect. 11.4.)
    """
    n1 = exponent + 1.0
    p_m = (n1 * mass * velocity**2 / (2.0 * stiffness)) ** (1.0 / n1)
    from scipy import special

    duration = 2.0 * p_m / velocity * special.beta(1.0 / n1, 0.5) / n1
    return {
        "max_depth": p_m,
        "max_force": stiffness * p_m**exponent,
        "contact_duration": float(duration),
    }


def resting_depth(load: float, stiffness: float, exponent: float) -> float:
    """Static penetration under a constant load: (F / K)^(1/n) [m]; F >= 0, K > 0, n > 0."""
    load = _check("load", load, 0.0, low_open=False)
    stiffness = _check("stiffness", stiffness, 0.0)
    exponent = _check("exponent", exponent, 0.0)
    return float((load / stiffness) ** (1.0 / exponent))


def damping_factors(c_r: float) -> dict[str, float]:
    """D(c_r) of every law, keyed by name; 0 < c_r <= 1 (the scenario's range of a
    restitution coefficient)."""
    c = _check("c_r", c_r, 0.0)
    if c > 1.0:
        raise InputError(f"c_r: {c_r!r} is out of range; allowed > 0 and <= 1")
    return {name: law.damping_factor(c) for name, law in _LAWS.items()}


def restitution_table(c_values: np.ndarray) -> dict[str, np.ndarray]:
    """Exact effective restitution of every law over the nominal values ``c_values``."""
    return {
        name: np.array([effective_restitution(law.damping_factor(float(c))) for c in c_values])
        for name, law in _LAWS.items()
    }
