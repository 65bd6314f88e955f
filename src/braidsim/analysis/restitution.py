"""Effective restitution of each contact law against its nominal coefficient c_r.

Each law F = K p^n (1 + D(c_r) pdot / v0) is given a nominal c_r, but what one impact
actually restitutes is e = -v_rebound / v0, which depends on D alone through the exact
relation of the family (:mod:`braidsim.contact`):

    1 - D e = (1 + D) exp(-D (1 + e))

:func:`restitution_table` simulates one free impact per law and per c_r of a grid
(:func:`braidsim.impact.single_impact`, the event-exact kernel at rtol = 1e-10) and sets
the measured e beside the exact one, e(D(c_r)), and beside c_r. A law whose e equals c_r
restitutes what it is told; the others dissipate more (e < c_r) or less.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from braidsim import contact
from braidsim.errors import InputError


@dataclass(frozen=True)
class RestitutionTable:
    """Simulated and exact restitution per law over a grid of nominal c_r.

    Attributes
    ----------
    laws : tuple of str
        Law names.
    nominal : np.ndarray
        c_r grid [-].
    damping : np.ndarray
        (laws, c_r) damping factors D [-].
    simulated : np.ndarray
        (laws, c_r) e measured on one simulated impact [-].
    exact : np.ndarray
        (laws, c_r) e from the exact relation [-].
    velocity, mass, stiffness, exponent : float
        The impact's approach speed [m/s], mass [kg], K [N/m^n] and n (stiffness None:
        Eq. 4 with the paper's guide pad and track).
    """

    laws: tuple[str, ...]
    nominal: np.ndarray
    damping: np.ndarray
    simulated: np.ndarray
    exact: np.ndarray
    velocity: float
    mass: float
    stiffness: float | None
    exponent: float | None

    def __repr__(self) -> str:
        return (
            f"<braidsim.RestitutionTable: {len(self.laws)} laws x {self.nominal.size} c_r at "
            f"{self.velocity:g} m/s; largest |simulated - exact| {self.max_deviation:.3g}>"
        )

    @property
    def max_deviation(self) -> float:
        """max |simulated - exact| over the table [-]."""
        return float(np.max(np.abs(self.simulated - self.exact)))

    def rows(self) -> list[dict[str, Any]]:
        """One row per (law, c_r)."""
        out = []
        for i, law in enumerate(self.laws):
            for j, c in enumerate(self.nominal):
                out.append(
                    {
                        "law": law,
                        "nominal": float(c),
                        "damping_factor": float(self.damping[i, j]),
                        "simulated": float(self.simulated[i, j]),
                        "exact": float(self.exact[i, j]),
                        "deviation": float(self.simulated[i, j] - self.exact[i, j]),
                    }
                )
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "velocity": self.velocity,
            "mass": self.mass,
            "stiffness": self.stiffness,
            "exponent": self.exponent,
            "nominal": self.nominal.tolist(),
            "laws": {
                law: {
                    "damping_factor": self.damping[i].tolist(),
                    "simulated": self.simulated[i].tolist(),
                    "exact": self.exact[i].tolist(),
                }
                for i, law in enumerate(self.laws)
            },
            "max_deviation": self.max_deviation,
            "relation": "1 - D e = (1 + D) exp(-D (1 + e))",
        }


def restitution_table(
    laws: Sequence[str] | None = None,
    nominal: Sequence[float] | np.ndarray | None = None,
    velocity: float | str = 0.5,
    mass: float | str = 1.2,
    stiffness: float | None = None,
    exponent: float | None = None,
) -> RestitutionTable:
    """Simulate one impact per law and nominal c_r and compare with the exact relation.

    Parameters
    ----------
    laws : sequence of str, optional
        Law names, at least one (default None: all, ``braidsim models``).
    nominal : sequence of float, optional
        c_r values in (0, 1] (default 0.1, 0.2, ..., 1.0).
    velocity : float or str
        Approach speed [m/s] (or a string with a unit, ``"0.5 m/s"``; e does not depend on
        it).
    mass : float or str
        [kg] (or a string with a unit; e does not depend on it).
    stiffness : float, optional
        K [N/m^n]; default Eq. (4) with the paper's guide pad and track.
    exponent : float, optional
        n; default each law's.
    """
    from braidsim.impact import single_impact
    from braidsim.units import to_si

    if laws is None:
        names = tuple(contact.law_names())
    elif isinstance(laws, str | bytes) or not isinstance(laws, Sequence):
        raise InputError(
            f"laws: {laws!r} is not a list of law names; allowed e.g. ['hunt_crossley'], or "
            "None for all"
        )
    elif not laws:
        raise InputError(
            f"laws: an empty list; allowed one or more of {', '.join(contact.law_names())}, "
            "or None for all"
        )
    else:
        names = tuple(laws)
    for name in names:
        if not isinstance(name, str):
            raise InputError(f"laws: {name!r} is not a law name; allowed a list of names")
        contact.get_law(name)  # InputError naming the closest law
    if nominal is None:
        c = np.linspace(0.1, 1.0, 10)
    elif isinstance(nominal, str | bytes) or not isinstance(nominal, Sequence | np.ndarray):
        raise InputError(f"nominal: {nominal!r} is not a list of c_r values; allowed 0 < c_r <= 1")
    else:
        c = np.array([to_si("nominal", v, "") for v in np.ravel(nominal)], dtype=float)
    if c.size == 0 or not np.all((c > 0) & (c <= 1)):
        raise InputError("nominal: c_r values must lie in (0, 1]; allowed 0 < c_r <= 1")
    velocity = to_si("velocity", velocity, "m/s")  # numbers in SI or strings with a unit
    if not (math.isfinite(velocity) and velocity > 0):
        raise InputError(f"velocity: {velocity:g} m/s is out of range; allowed > 0 m/s")
    mass = to_si("mass", mass, "kg")
    if not (math.isfinite(mass) and mass > 0):
        raise InputError(f"mass: {mass:g} kg is out of range; allowed > 0 kg")
    D = np.empty((len(names), c.size))
    sim = np.empty_like(D)
    ex = np.empty_like(D)
    for i, name in enumerate(names):
        law = contact.get_law(name)
        for j, cr in enumerate(c):
            out = single_impact(name, float(cr), velocity, mass, stiffness, exponent)
            D[i, j] = law.damping_factor(float(cr))
            sim[i, j] = out["effective_restitution"]
            ex[i, j] = contact.effective_restitution(D[i, j])
    return RestitutionTable(names, c, D, sim, ex, float(velocity), float(mass), stiffness, exponent)
