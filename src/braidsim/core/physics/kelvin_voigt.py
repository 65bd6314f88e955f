"""The linear spring-dashpot (Kelvin-Voigt) contact: a law outside the power-law family.

    F_k = k p,   F_c = c p',   N = max(0, F_k + F_c)   (no clamp when tension is allowed)

k [N/m] stiffness, c [N s/m] damping, p >= 0 penetration [m], p' its rate [m/s]. Unlike the
laws of :mod:`~braidsim.core.physics.contact_laws` the damping does not scale with the
elastic force, so the force jumps to c v at onset and the restitution depends on the mass.
A free impact of a body of mass m on this wall (tension allowed) is half a period of a
damped oscillator, with

    duration T = pi / w_d,   w_d = w_n sqrt(1 - zeta^2),   w_n = sqrt(k / m),
    restitution e = exp(-zeta pi / sqrt(1 - zeta^2)),      zeta = c / (2 sqrt(k m)),

so c = 2 zeta sqrt(k m) with zeta = -ln e / sqrt(pi^2 + ln^2 e) gives restitution e
(:meth:`KelvinVoigtContact.for_restitution`). Goldsmith, W. (1960), Impact: The Theory and
Physical Behaviour of Colliding Solids, Edward Arnold; Gilardi, G. and Sharf, I. (2002),
Literature survey of contact dynamics modelling, Mech. Mach. Theory 37(10), 1213-1239,
doi:10.1016/S0094-114X(02)00045-9.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from braidsim.core.interfaces import (
    contact_force_onset_series,
    contact_force_rates,
    contact_force_series,
    contact_forces,
    contact_forces_jvp,
    contact_onset_power,
    contact_onset_step,
    contact_potential,
)


class KelvinVoigtContact(NamedTuple):
    """k p + c p' (see the module docstring)."""

    stiffness: float  # k [N/m]
    damping: float  # c [N s/m]
    allow_tension: bool = False

    @classmethod
    def for_restitution(
        cls, stiffness: float, restitution: float, mass: float, allow_tension: bool = False
    ) -> KelvinVoigtContact:
        """The law whose free impact of ``mass`` [kg] rebounds with ``restitution`` (0 < e <= 1),
        exactly when tension is allowed."""
        if not 0.0 < restitution <= 1.0:
            raise ValueError(f"restitution {restitution!r} out of range; allowed 0 < e <= 1")
        ln_e = math.log(restitution)
        zeta = -ln_e / math.sqrt(math.pi**2 + ln_e**2)
        return cls(stiffness, 2.0 * zeta * math.sqrt(stiffness * mass), allow_tension)


@contact_forces.register(KelvinVoigtContact)
def _forces(law, p, p_dot, v0):
    fk = law.stiffness * p
    fc = law.damping * p_dot
    nn = fk + fc
    if nn < 0.0 and not law.allow_tension:
        nn = 0.0
    return fk, fc, nn


@contact_force_series.register(KelvinVoigtContact)
def _forces_series(law, k, P, v0, S):
    # linear: F_k = K P[k], F_c = c (k + 1) P[k + 1] (K stiffness, c damping)
    fk = law.stiffness * P[k]
    fc = law.damping * ((k + 1) * P[k + 1])
    return fk, fc, fk + fc


@contact_onset_power.register(KelvinVoigtContact)
def _onset_power(law):
    return 2  # k p = k s^2 q


@contact_force_onset_series.register(KelvinVoigtContact)
def _forces_onset_series(law, k, Q, v0, S):
    # p = s^2 q: F_k = k s^2 q, F_c = c p' with p' = sum_j (j + 2) Q[j] s^j / 2 (the force
    # jumps to c p'(t_onset) at the onset)
    fk = law.stiffness * Q[k - 2] if k >= 2 else 0.0
    fc = law.damping * (0.5 * (k + 2) * Q[k])
    return fc, fk + fc


@contact_forces_jvp.register(KelvinVoigtContact)
def _forces_jvp(law, dlaw, p, dp, p_dot, dp_dot, v0, dv0):
    dfk = dlaw.stiffness * p + law.stiffness * dp
    dfc = dlaw.damping * p_dot + law.damping * dp_dot
    if law.stiffness * p + law.damping * p_dot < 0.0 and not law.allow_tension:
        return dfk, dfc, 0.0
    return dfk, dfc, dfk + dfc


@contact_potential.register(KelvinVoigtContact)
def _potential(law, p):
    return 0.5 * law.stiffness * p * p


@contact_force_rates.register(KelvinVoigtContact)
def _rates(law, p, p_dot, p_ddot, v0, f_k, f_c):
    dfc = law.damping * p_ddot
    return law.stiffness * p_dot + dfc, dfc


@contact_onset_step.register(KelvinVoigtContact)
def _onset(law, mass, v):
    # a contact lasts about half a period pi sqrt(m / k); the force grows as p (q = n + 1 = 2)
    return math.pi * math.sqrt(mass / law.stiffness) / 12.0, 2.0
