"""Coulomb friction plus viscous damping: a friction law in one file.

    f = mu N tanh(v / v_hat) + b v

v the sliding speed [m/s], N the normal force [N], mu the coefficient of the pair [-],
v_hat the regularisation speed [m/s] of the Coulomb part, b the viscous coefficient
[N s/m] (a lubricated or polymer guide). Olsson, H., Astrom, K. J., Canudas de Wit, C.,
Gafvert, M. and Lischinsky, P. (1998), Friction models and friction compensation, Eur. J.
Control 4(3), 176-195, doi:10.1016/S0947-3580(98)70113-X.
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
from braidsim.core.jets import jet_mul_const, jet_tanh, saturation_reach


class CoulombViscousFriction(NamedTuple):
    """mu N tanh(v / v_hat) + b v (see the module docstring)."""

    regularization_velocity: float  # v_hat [m/s]
    viscous: float  # b [N s/m]


@friction_force.register(CoulombViscousFriction)
def _friction(law, v, normal, mu):
    return mu * normal * math.tanh(v / law.regularization_velocity) + law.viscous * v


@friction_force_series.register(CoulombViscousFriction)
def _friction_series(law, k, V, NS, mu, S):
    # f_k = mu (N tanh(u))_k + b V[k], u = v / v_hat (rows of S: 0 u, 1 tanh(u),
    # 2 1 - tanh(u)^2)
    U = S[0]
    U[k] = V[k] / law.regularization_velocity
    jet_tanh(U, S[1], S[2], k)
    return mu * jet_mul_const(NS, S[1], k) + law.viscous * V[k]


@friction_series_reach.register(CoulombViscousFriction)
def _friction_reach(law, V, h):
    # tanh(u) saturates as exp(-2 |u|): its turn-over hides in coefficients that underflow
    # (core.jets.saturation_reach); the viscous term is linear
    return saturation_reach(V, 0.5 * law.regularization_velocity, 1, h)


@friction_force_jvp.register(CoulombViscousFriction)
def _friction_jvp(law, dlaw, v, dv, normal, dnormal, mu, dmu):
    vhat = law.regularization_velocity
    g = math.tanh(v / vhat)
    du = dv / vhat - v * dlaw.regularization_velocity / (vhat * vhat)
    return (
        (dmu * normal + mu * dnormal) * g
        + mu * normal * (1.0 - g * g) * du
        + dlaw.viscous * v
        + law.viscous * dv
    )
