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

from braidsim.core.interfaces import friction_force, friction_force_jvp

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
