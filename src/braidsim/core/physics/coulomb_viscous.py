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

from braidsim.core.interfaces import friction_force, friction_force_jvp


class CoulombViscousFriction(NamedTuple):
    """mu N tanh(v / v_hat) + b v (see the module docstring)."""

    regularization_velocity: float  # v_hat [m/s]
    viscous: float  # b [N s/m]


@friction_force.register(CoulombViscousFriction)
def _friction(law, v, normal, mu):
    return mu * normal * math.tanh(v / law.regularization_velocity) + law.viscous * v


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
