"""The power-law contact family: N = K p^n (1 + D p' / v0), clamped at 0.

Every law of the paper's Eqs. (3)-(13) (Hertz, Brandlein, Hunt-Crossley, Herbert-McWhannell,
Lee-Wang, Lankarani-Nikravesh, Gonthier, Zhiying-Qishao, Flores) and Carvalho-Martins is of
this form and differs only in its damping factor D(c_r) (:mod:`braidsim.contact` computes it
from the restitution); one record class, compiled once, serves them all:

    F_k = K p^n                    stiffness-related force [N]
    F_c = K p^n D p' / v0          damping-related force [N]
    N   = max(0, F_k + F_c)        (no clamp when tension is allowed)

K [N/m^n] stiffness, n exponent, D damping factor, p >= 0 penetration [m], p' its rate
[m/s], v0 the approach speed latched at onset [m/s]. Hunt, K. H. and Crossley, F. R. E.
(1975), Coefficient of restitution interpreted as damping in vibroimpact, J. Appl. Mech.
42(2), 440-445, doi:10.1115/1.3423596.
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
from braidsim.core.jets import jet_pow


class PowerLawContact(NamedTuple):
    """K p^n (1 + D p'/v0) (see the module docstring)."""

    stiffness: float  # K [N/m^n]
    exponent: float  # n [-]
    damping: float  # D [-]
    allow_tension: bool = False  # keep N < 0 (no clamp) when the damping term pulls


@contact_forces.register(PowerLawContact)
def _forces(law, p, p_dot, v0):
    k = law.stiffness
    n = law.exponent
    # the Hertz exponent 3/2 is by far the most common: p sqrt(p) is cheaper than pow
    fk = k * p * math.sqrt(p) if n == 1.5 else k * p**n
    fc = fk * law.damping * p_dot / v0
    nn = fk + fc
    if nn < 0.0 and not law.allow_tension:
        nn = 0.0
    return fk, fc, nn


@contact_force_series.register(PowerLawContact)
def _forces_series(law, k, P, v0, S):
    # F_k = K p^n by the power recurrence, which is linear in its result's coefficients, so
    # row 0 of S holds those of K p^n directly; F_c = (D / v0) (F_k p')_k with
    # p'_j = (j + 1) P[j + 1] in row 1; N = F_k + F_c unclamped
    F = S[0]
    if k == 0:
        p = P[0]
        n = law.exponent
        fk = law.stiffness * p * math.sqrt(p) if n == 1.5 else law.stiffness * p**n
    else:
        fk = jet_pow(P, F, law.exponent, k)
    F[k] = fk
    if math.isinf(v0):  # a contact released elastically: no damping term
        return fk, 0.0, fk
    if k == 0:
        S[1, 0] = P[1]
        fc = fk * law.damping * P[1] / v0
    else:
        # (the rate p' kept in row 1 as it grows, so the sum converts no index)
        D = S[1]
        D[k] = (k + 1) * P[k + 1]
        acc = 0.0
        for j in range(k + 1):
            acc += F[j] * D[k - j]
        fc = law.damping * acc / v0
    return fk, fc, fk + fc


@contact_onset_power.register(PowerLawContact)
def _onset_power(law):
    # K p^n = K s^(2n) q^n is a series in s where 2n is an integer (Hertz: s^3)
    m = 2.0 * law.exponent
    if m >= 1.0 and m == math.floor(m):
        return int(m)
    return 0


@contact_force_onset_series.register(PowerLawContact)
def _forces_onset_series(law, k, Q, v0, S):
    # p = s^2 q, so F_k = K s^m q^n (m = 2n): row 0 holds R = q^n (the power recurrence,
    # Q[0] > 0), row 1 the rate p' = dp/dt = (j + 2) Q[j] / 2, row 2 F_k; F_c = (D / v0)
    # (F_k p')_k, whose terms start at F_k's s^m, so that p' is read to k - m <= k
    m = contact_onset_power(law)
    F = S[2]
    j = k - m
    if j < 0:
        F[k] = 0.0
        return 0.0, 0.0
    R = S[0]
    n = law.exponent
    if j == 0:
        q0 = Q[0]
        r = q0 * math.sqrt(q0) if n == 1.5 else q0**n
    else:
        r = jet_pow(Q, R, n, j)
    R[j] = r
    fk = law.stiffness * r
    F[k] = fk
    if math.isinf(v0):  # a contact released elastically: no damping term
        return 0.0, fk
    PD = S[1]
    PD[j] = 0.5 * (j + 2) * Q[j]
    acc = 0.0
    for i in range(m, k + 1):
        acc += F[i] * PD[k - i]
    fc = law.damping * acc / v0
    return fc, fk + fc


@contact_forces_jvp.register(PowerLawContact)
def _forces_jvp(law, dlaw, p, dp, p_dot, dp_dot, v0, dv0):
    # dF_k = dK p^n + K n p^(n-1) dp + K p^n ln(p) dn
    # dF_c = (dF_k D + F_k dD) p'/v0 + F_k D (dp'/v0 - p' dv0/v0^2)
    k = law.stiffness
    n = law.exponent
    if p > 0.0:
        pn = p * math.sqrt(p) if n == 1.5 else p**n
        fk = k * pn
        dfk = dlaw.stiffness * pn + n * fk / p * dp + fk * math.log(p) * dlaw.exponent
    else:
        fk = 0.0
        dfk = k * dp if n == 1.0 else 0.0
    if math.isinf(v0):  # a contact released elastically: no damping term
        return dfk, 0.0, dfk
    d = law.damping
    fc = fk * d * p_dot / v0
    dfc = (dfk * d + fk * dlaw.damping) * p_dot / v0 + fk * d * (
        dp_dot / v0 - p_dot * dv0 / (v0 * v0)
    )
    if fk + fc < 0.0 and not law.allow_tension:
        return dfk, dfc, 0.0
    return dfk, dfc, dfk + dfc


@contact_potential.register(PowerLawContact)
def _potential(law, p):
    n1 = law.exponent + 1.0
    return law.stiffness * p**n1 / n1


@contact_force_rates.register(PowerLawContact)
def _rates(law, p, p_dot, p_ddot, v0, f_k, f_c):
    # dN/dt   = K n p^(n-1) p' (1 + D p'/v0) + K p^n D p''/v0
    # dF_c/dt = D/v0 (K n p^(n-1) p'^2 + K p^n p'')
    # with K n p^(n-1) replaced by 1 at p = 0 (only the signs are used there)
    dfk = law.exponent * f_k / p * p_dot if p > 0.0 else p_dot
    d_v0 = law.damping / v0
    return dfk * (1.0 + d_v0 * p_dot) + f_k * d_v0 * p_ddot, d_v0 * (dfk * p_dot + f_k * p_ddot)


@contact_onset_step.register(PowerLawContact)
def _onset(law, mass, v):
    # the elastic closed form: maximum depth p_m = ((n+1) m v^2 / (2 K))^(1/(n+1)), duration
    # about 3 p_m / v; the first step is a twelfth of that
    n1 = law.exponent + 1.0
    p_m = (n1 * mass * v * v / (2.0 * law.stiffness)) ** (1.0 / n1)
    return 0.25 * p_m / v, n1
