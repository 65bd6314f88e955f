"""Units at the edge: parse numbers and unit strings into SI floats with pint.

Inside braidsim every quantity is a plain float in SI units. This module is the only place
where unit strings ("3 mm", "200 GPa", "120 rpm", "60 Hz", "30 deg") are read.

Angular frequencies need care: pint treats ``Hz`` as ``1/s``, so "60 Hz" converted to
``rad/s`` would give 60. For keys whose unit is ``rad/s`` a pure frequency (Hz, 1/s, 1/min)
is read as cycles per unit time and multiplied by 2 pi, so "60 Hz" is 120 pi rad/s, the
paper's omega_h; "120 rpm" is 4 pi rad/s through pint's revolution unit.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import pint

from braidsim.errors import InputError


def _is_time_or_hertz(ureg: pint.UnitRegistry, name: str) -> bool:
    """True for a unit of time or of hertz; False for rpm, deg/s and other angular rates."""
    if name.endswith("hertz"):
        return True
    return bool(ureg.Unit(name).dimensionality == ureg.Unit("s").dimensionality)


@functools.cache
def registry() -> pint.UnitRegistry:
    """The package's unit registry (created once)."""
    ureg: pint.UnitRegistry = pint.UnitRegistry()
    return ureg


def to_si(key: str, value: object, unit: str) -> float:
    """Convert ``value`` (a number in SI or a string with units) to a float in ``unit``.

    Parameters
    ----------
    key : str
        Parameter name, used in error messages.
    value : float or str
        A bare number (taken as already in SI) or a string such as ``"3 mm"``.
    unit : str
        Target SI unit as a pint expression (``"m"``, ``"N/m**1.5"``, ``"rad/s"``, ``""``).

    Raises
    ------
    InputError
        The string does not parse, or its dimension does not match ``unit``.
    """
    if isinstance(value, bool):
        raise InputError(
            f"{key}: expected a number or a quantity in {unit or 'no unit'}, got {value!r}"
        )
    if isinstance(value, int | float):
        return float(value)
    if not isinstance(value, str):
        raise InputError(
            f"{key}: expected a number or a quantity string in {unit or 'no unit'}, got {value!r}"
        )
    ureg = registry()
    try:
        q: Any = ureg.Quantity(value.strip())
    except Exception as exc:  # pint raises several exception types for bad strings
        raise InputError(
            f"{key}: cannot read {value!r} as a quantity ({exc.__class__.__name__})"
        ) from None
    if not isinstance(q, pint.Quantity):  # a bare number inside a string
        return float(q)
    target = ureg.Unit(unit) if unit else ureg.dimensionless
    if unit == "rad/s" and q.dimensionality == ureg.Unit("1/s").dimensionality:
        names = [ureg.get_name(u) for u, _ in q.unit_items()]
        if all(_is_time_or_hertz(ureg, n) for n in names):
            # A pure frequency: cycles per unit time.
            return float(q.to("1/s").magnitude) * 2.0 * math.pi
    try:
        return float(q.to(target).magnitude)
    except pint.DimensionalityError:
        want = unit or "no unit"
        raise InputError(
            f"{key}: {value!r} has the wrong unit; expected a quantity in {want}"
        ) from None
