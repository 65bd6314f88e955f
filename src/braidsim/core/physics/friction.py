"""Regularised friction laws (the paper's Eq. 14 and two variants).

    arctan:   f = mu N (2/pi) arctan(v / v_hat)
    tanh:     f = mu N tanh(v / v_hat)
    stribeck: f = mu (1 + (r_s - 1) exp(-(v/v_s)^2)) N tanh(v / v_hat)
    none:     f = 0

v the sliding speed [m/s], N the normal force [N], v_hat the regularisation speed [m/s],
r_s = mu_s / mu the static-to-kinetic ratio and v_s the Stribeck speed [m/s]. The law is a
run-time code so that one compiled solver serves all four.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from braidsim.core.interfaces import (
    friction_force,
    friction_force_jvp,
    friction_force_series,
    friction_series_reach,
)
from braidsim.core.jets import (
    jet_atan,
    jet_exp,
    jet_mul,
    jet_mul_const,
    jet_sq,
    jet_tanh,
    saturation_reach,
)

FRICTION_CODES = {"arctan": 0, "tanh": 1, "stribeck": 2, "none": 3}


class RegularizedFriction(NamedTuple):
    """A regularised sign function (see the module docstring)."""

    law: int  # FRICTION_CODES
    regularization_velocity: float  # v_hat [m/s]
    static_ratio: float = 1.0  # r_s (stribeck)
    stribeck_velocity: float = 1.0  # v_s [m/s] (stribeck)


@friction_force.register(RegularizedFriction)
def _friction(law, v, normal, mu):
    kind = law.law
    vhat = law.regularization_velocity
    if kind == 0:
        return mu * normal * (2.0 / math.pi) * math.atan(v / vhat)
    if kind == 1:
        return mu * normal * math.tanh(v / vhat)
    if kind == 2:
        vs = law.stribeck_velocity
        mu_eff = mu * (1.0 + (law.static_ratio - 1.0) * math.exp(-((v / vs) ** 2)))
        return mu_eff * normal * math.tanh(v / vhat)
    return 0.0


@friction_force_series.register(RegularizedFriction)
def _friction_series(law, k, V, NS, mu, S):
    # f_k = mu (N phi)_k, phi the sign function of u = v / v_hat (rows of S: 0 u, then
    # arctan: 1 the series of 1 + u^2, 2 atan(u); tanh and stribeck: 1 tanh(u),
    # 2 1 - tanh(u)^2; stribeck: 3 x = v / v_s, 4 -x^2, 5 e = exp(-x^2),
    # 6 phi = (1 + (r_s - 1) e) tanh(u))
    kind = law.law
    if kind == 3:
        return 0.0
    U = S[0]
    U[k] = V[k] / law.regularization_velocity
    if kind == 0:
        Z = S[2]
        Z[k] = jet_atan(U, S[1], Z, k)
        return mu * (2.0 / math.pi) * jet_mul_const(NS, Z, k)
    T = S[1]
    jet_tanh(U, T, S[2], k)
    if kind == 1:
        return mu * jet_mul_const(NS, T, k)
    X = S[3]
    G = S[4]
    E = S[5]
    phi = S[6]
    X[k] = V[k] / law.stribeck_velocity
    G[k] = -jet_sq(X, k)
    E[k] = jet_exp(G, E, k)
    phi[k] = T[k] + (law.static_ratio - 1.0) * jet_mul(E, T, k)
    return mu * jet_mul_const(NS, phi, k)


@friction_series_reach.register(RegularizedFriction)
def _friction_reach(law, V, h):
    # arctan's series carries its branch points at v = +-i v_hat; tanh saturates as
    # exp(-2 |v| / v_hat) and the Stribeck term as exp(-(v / v_s)^2): their turn-overs hide
    # in coefficients that underflow (core.jets.saturation_reach)
    kind = law.law
    if kind == 1 or kind == 2:
        h = saturation_reach(V, 0.5 * law.regularization_velocity, 1, h)
        if kind == 2:
            h = saturation_reach(V, law.stribeck_velocity, 2, h)
    return h


@friction_force_jvp.register(RegularizedFriction)
def _friction_jvp(law, dlaw, v, dv, normal, dnormal, mu, dmu):
    kind = law.law
    if kind == 3:
        return 0.0
    vhat = law.regularization_velocity
    u = v / vhat
    du = dv / vhat - v * dlaw.regularization_velocity / (vhat * vhat)
    if kind == 0:
        g = (2.0 / math.pi) * math.atan(u)
        dg = (2.0 / math.pi) / (1.0 + u * u) * du
        return (dmu * normal + mu * dnormal) * g + mu * normal * dg
    g = math.tanh(u)
    dg = (1.0 - g * g) * du
    if kind == 1:
        return (dmu * normal + mu * dnormal) * g + mu * normal * dg
    # stribeck: mu_eff = mu (1 + (r_s - 1) e), e = exp(-(v / v_s)^2)
    vs = law.stribeck_velocity
    w = v / vs
    dw = dv / vs - v * dlaw.stribeck_velocity / (vs * vs)
    e = math.exp(-(w * w))
    de = -2.0 * w * e * dw
    mu_eff = mu * (1.0 + (law.static_ratio - 1.0) * e)
    dmu_eff = dmu * (1.0 + (law.static_ratio - 1.0) * e) + mu * (
        dlaw.static_ratio * e + (law.static_ratio - 1.0) * de
    )
    return (dmu_eff * normal + mu_eff * dnormal) * g + mu_eff * normal * dg
