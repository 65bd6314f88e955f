"""Units at the edge: parse numbers and unit strings into SI floats with pint.

Inside braidsim every quantity is a plain float in SI units. This module is the only place
where unit strings ("3 mm", "200 GPa", "120 rpm", "60 Hz", "30 deg") are read.

A quantity string is read by a small grammar, never by evaluating it: a decimal number
(``3``, ``-2.5e-3``, ``inf``, or a ratio such as ``5/9``) followed by an optional unit
expression made of unit names (``pi`` included), ``*``, ``/``, parentheses, small constant
exponents (``^1.5`` or ``**2``, at most :data:`MAX_EXPONENT` in size) and small divisors
(``pi/6 rad``). Anything else (``9**9**9 m``, ``1 m == 0.002``, ``10**400 m``) is refused
with a message naming the parameter before pint sees it, so no input can make braidsim
compute a huge number or run code. Only the checked unit expression is handed to pint, which
looks its names up in its registry.

Angular frequencies need care: pint treats ``Hz`` as ``1/s``, so "60 Hz" converted to
``rad/s`` would give 60. For keys whose unit is ``rad/s`` a pure frequency (Hz, 1/s, 1/min)
is read as cycles per unit time and multiplied by 2 pi, so "60 Hz" is 120 pi rad/s, the
paper's omega_h; "120 rpm" is 4 pi rad/s through pint's revolution unit.

Bare numbers
------------
A bare number (``3``, or the string ``"3"``) is taken as already in SI: this is the rule of
the Python API and of scenario files. The command line says so in a one-line notice on
stderr whenever a bare number is given for a dimensional quantity
(:func:`braidsim.cli.common.quantity_option`); ``docs/units.md`` states the policy.
"""

from __future__ import annotations

import difflib
import functools
import importlib
import math
import numbers
import os
import re
import sys
from typing import TYPE_CHECKING, Any

from braidsim.errors import InputError

if TYPE_CHECKING:
    import pint

#: Whether pint may import dask when this module imports pint (see :func:`_import_pint`). The
#: command line sets it to False: its process never holds a dask array with units.
PINT_WITH_DASK = True

#: largest |exponent| accepted in a unit expression (m^3, s^-2, N/m^1.5 need far less)
MAX_EXPONENT = 12.0
#: longest quantity string read (a unit string is a few words)
MAX_LENGTH = 200

_NUMBER = re.compile(
    r"[+-]?(?:(?:\d+(?:_\d+)*)(?:\.\d*(?:_\d+)*)?|\.\d+(?:_\d+)*)(?:[eE][+-]?\d+)?"
    r"|[+-]?(?:infinity|inf|nan)(?![A-Za-z_])",
    re.IGNORECASE,
)
_TOKEN = re.compile(
    r"\s*(?:(?P<name>[^\W\d][\w]*|%)|(?P<pow>\*\*|\^)"
    r"|(?P<num>[+-]?\d+(?:\.\d+)?|\([+-]?\d+(?:\.\d+)?\))|(?P<op>[*/()]))"
)


#: SI factors of the unit expressions that the built-in scenarios and the usual options use,
#: keyed by (unit text as the grammar returns it, target unit): a quantity in one of them is
#: ``magnitude * factor``, which is what pint computes (each factor is pint's, bit for bit,
#: and the tests compare both paths), without importing pint and building its registry
#: (about 0.1 s of CPU at every start of the command line). pint reads every other unit.
_SI_FACTORS: dict[tuple[str, str], float] = {
    ("m", "m"): 1.0,
    ("mm", "m"): 0.001,
    ("s", "s"): 1.0,
    ("ms", "s"): 0.001,
    ("m / s", "m/s"): 1.0,
    ("mm / s", "m/s"): 0.001,
    ("GPa", "Pa"): 1e9,
    ("rpm", "rad/s"): 0.10471975511965977,  # 2 pi / 60, rounded as pint rounds it
}
#: frequencies for a target in rad/s, read as cycles per time: factor to 1/s, times 2 pi
_FREQUENCY_FACTORS: dict[str, float] = {"Hz": 1.0}


#: the units a user of braidsim writes most, offered first when a unit name is not known
COMMON_UNITS = (
    "m", "mm", "um", "cm", "km", "s", "ms", "us", "min", "h", "kg", "g", "N", "kN", "MN",
    "Pa", "kPa", "MPa", "GPa", "rad", "deg", "rpm", "Hz", "kHz", "J", "mJ", "W", "kW",
    "m/s", "mm/s", "m/s^2", "rad/s", "N/m", "N*m", "meter", "millimeter", "micrometer",
    "second", "millisecond", "newton", "kilonewton", "pascal", "gigapascal", "radian",
    "degree", "hertz", "joule", "watt", "kilogram", "gram",
)  # fmt: skip


# the end of an unknown unit's message when no known unit is close (a parameter that knows its
# unit and range says those instead: braidsim.params.convert)
UNIT_HINT = "allowed e.g. 'mm', 'kN', 'rpm'"


def unknown_unit_message(exc: Exception, text: str) -> str:
    """``unknown unit 'rmp'; did you mean 'rpm'?``: the name pint did not know (from its
    error, else ``text``) and the closest common or known unit, if one is close."""
    names = getattr(exc, "unit_names", None) or (text,)
    bad = str(names[0]) if isinstance(names, tuple | list) else str(names)
    near = difflib.get_close_matches(bad, COMMON_UNITS, n=1, cutoff=0.6)
    if not near:
        known = [n for n in dir(registry()) if not n.startswith("_")]
        near = difflib.get_close_matches(bad, known, n=1, cutoff=0.8)
    hint = f"did you mean {near[0]!r}?" if near else UNIT_HINT
    return f"unknown unit {bad!r}; {hint}"


def _is_time_or_hertz(ureg: pint.UnitRegistry, name: str) -> bool:
    """True for a unit of time or of hertz; False for rpm, deg/s and other angular rates."""
    if name.endswith("hertz"):
        return True
    return bool(ureg.Unit(name).dimensionality == ureg.Unit("s").dimensionality)


def _import_pint() -> None:
    """Import pint: done on the first unit string read, not by ``import braidsim``.

    When dask is installed, importing pint imports ``dask.base`` too (for quantities that wrap
    dask arrays), which costs about as much CPU as pint itself. With :data:`PINT_WITH_DASK`
    off, pint is imported while ``sys.modules["dask"]`` is None, which makes
    ``importlib.util.find_spec("dask")`` answer None: pint then leaves out only its dask
    methods (``Quantity.compute``, ``persist``, ``visualize``); dask itself imports normally
    afterwards. Nothing changes if pint or dask is already imported.
    """
    if not PINT_WITH_DASK and "pint" not in sys.modules and "dask" not in sys.modules:
        sys.modules["dask"] = None  # type: ignore[assignment]
        try:
            importlib.import_module("pint")
        finally:
            if "dask" in sys.modules and sys.modules["dask"] is None:
                del sys.modules["dask"]


def _new_registry(cache_folder: str | os.PathLike[str] | None) -> pint.UnitRegistry:
    """A unit registry of pint's default definitions; with ``cache_folder``, pint keeps the
    parsed definition files there (named by a hash of their content, pint's and Python's
    versions) and reads them back instead of parsing them (0.02 s instead of 0.14 s)."""
    _import_pint()
    import pint

    if cache_folder is not None:
        try:
            cached: pint.UnitRegistry = pint.UnitRegistry(cache_folder=cache_folder)
            return cached
        except Exception:  # an unwritable or damaged cache: parse the files instead
            pass
    ureg: pint.UnitRegistry = pint.UnitRegistry()
    return ureg


@functools.cache
def registry() -> pint.UnitRegistry:
    """The package's unit registry (created once, on first use).

    pint's disk cache of parsed definitions is used (pint's ``cache_folder=":auto:"``, the
    user's cache directory); ``BRAIDSIM_UNIT_CACHE=0`` turns it off. A cache that cannot be
    written or read (a read-only home, a file being written by another process) is passed
    over: the definitions are then parsed, with the same registry as the result.
    """
    use_cache = os.environ.get("BRAIDSIM_UNIT_CACHE", "").strip() != "0"
    return _new_registry(":auto:" if use_cache else None)


def is_number(value: object) -> bool:
    """True for a real number (Python or numpy), False for booleans and everything else."""
    if isinstance(value, bool) or type(value).__name__ == "bool_":
        return False
    return isinstance(value, numbers.Real)


def _float(key: str, value: object) -> float:
    """A real number as a float; an :class:`InputError` if it does not fit a 64-bit float."""
    try:
        x = float(value)  # type: ignore[arg-type]
    except (OverflowError, ValueError, TypeError):
        raise InputError(
            f"{key}: {str(value)[:40]} cannot be represented as a 64-bit float; "
            "allowed |value| < 1.8e308"
        ) from None
    return x


def _check_unit_text(key: str, value: str, text: str) -> str:
    """Validate the unit part of a quantity string by the grammar of the module docstring;
    return it in pint's spelling (``^`` becomes ``**``)."""
    pos, out, prev = 0, [], ""
    if re.match(r"1\s*/", text):  # "1/s", "1/min": a reciprocal unit
        text = text[text.index("/") :]
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            raise InputError(
                f"{key}: cannot read {value!r} as a quantity (unexpected "
                f"{text[pos:].strip()[:12]!r}); allowed a number and a unit, e.g. '3 mm'"
            )
        pos = m.end()
        if m.group("name") is not None:
            out.append("percent" if m.group("name") == "%" else m.group("name"))
            prev = "name"
        elif m.group("pow") is not None:
            if prev not in ("name", ")"):
                raise InputError(f"{key}: cannot read {value!r}: a power needs a unit before it")
            out.append("**")
            prev = "pow"
        elif (
            m.group("num") is not None
            and prev == "/"
            and re.fullmatch(r"\d{1,8}(?:\.\d{1,8})?", m.group("num"))
        ):
            out.append(m.group("num"))  # a small divisor, as in "pi/6 rad"
            prev = "name"
        elif m.group("num") is not None:
            if prev != "pow":
                raise InputError(
                    f"{key}: cannot read {value!r}: a number inside the unit is allowed only "
                    "as an exponent (write the value first, e.g. '1e9 N/m^1.5')"
                )
            exp = float(m.group("num").strip("()"))
            if abs(exp) > MAX_EXPONENT:
                raise InputError(
                    f"{key}: exponent {exp:g} in {value!r} is out of range; "
                    f"allowed |exponent| <= {MAX_EXPONENT:g}"
                )
            out.append(f"({exp!r})")
            prev = "num"
        else:
            op = m.group("op")
            if op in "*/" and prev in ("", "pow", "*", "/") and not (op == "/" and prev == ""):
                raise InputError(f"{key}: cannot read {value!r}: misplaced {op!r}")
            out.append(op)
            prev = ")" if op == ")" else op
    if prev in ("pow", "*", "/"):
        raise InputError(f"{key}: cannot read {value!r}: the unit ends with an operator")
    joined = " ".join(out)
    return "1 " + joined if joined.startswith("/") else joined


def parse_unit(key: str, text: str) -> Any:
    """A unit expression alone (``"mm"``, ``"kN"``, ``"m/s^2"``) as a pint unit, read by the
    grammar of the module docstring (never evaluated).

    Raises
    ------
    InputError
        Empty, not a unit expression, or an unknown unit name.
    """
    if not isinstance(text, str) or not text.strip() or len(text) > MAX_LENGTH:
        raise InputError(f"{key}: {str(text)[:40]!r} is not a unit; allowed e.g. 'mm', 'kN'")
    unit_text = _check_unit_text(key, text, text.strip())
    if any(ch.isdigit() for ch in unit_text.replace("**", "").split("(")[0]) and "/" in text:
        raise InputError(f"{key}: {text!r} is not a unit; allowed e.g. 'mm', 'kN'")
    try:
        return registry().parse_units(unit_text)
    except Exception as exc:  # pint raises several exception types for unknown names
        raise InputError(f"{key}: {unknown_unit_message(exc, text)}") from None


def _split(key: str, value: str, unit: str) -> tuple[float, str]:
    """The number of the quantity string ``value`` (a ratio of two numbers included, 1 when
    the string starts with its unit) and the unit text after it ("" for none); ``unit``
    names the unit expected in the messages."""
    if len(value) > MAX_LENGTH:
        raise InputError(
            f"{key}: the quantity string is {len(value)} characters long; "
            f"allowed at most {MAX_LENGTH}"
        )
    text = value.strip()
    m = _NUMBER.match(text)
    if m is None:
        if not re.match(r"[^\W\d]", text):  # not even a unit name ("pi/6 rad", "mm")
            raise InputError(
                f"{key}: cannot read {value!r} as a quantity; allowed a number followed by a "
                f"unit in {unit or 'no unit'}, e.g. '3 mm'"
            )
        mag, rest = 1.0, text
    else:
        mag = _float(key, m.group(0).replace("_", ""))
        if math.isinf(mag) and "inf" not in m.group(0).lower():
            raise InputError(
                f"{key}: {m.group(0)} cannot be represented as a 64-bit float; "
                "allowed |value| < 1.8e308"
            )
        rest = text[m.end() :].strip()
    frac = re.match(r"/\s*(\d+(?:\.\d*)?(?:[eE][+-]?\d+)?)(?![\w.])", rest)
    if frac is not None:  # a ratio of two numbers, like "5/9"
        denom = float(frac.group(1))
        if denom == 0.0:
            raise InputError(f"{key}: {value!r} divides by zero; allowed a finite value")
        mag = mag / denom
        rest = rest[frac.end() :].strip()
    return mag, rest


def _pint_expression(key: str, value: str, rest: str, unit_text: str) -> Any:
    """pint's reading of the unit part ``rest`` of ``value``, as :func:`_check_unit_text`
    wrote it (``unit_text``): a quantity, or a number for a pure ratio."""
    try:
        # the text passed the grammar: unit names, small exponents and divisors only
        return registry().parse_expression(unit_text)
    except Exception as exc:  # pint raises several exception types for unknown names
        raise InputError(
            f"{key}: cannot read {value!r}: {unknown_unit_message(exc, rest)}"
        ) from None


def parse_quantity(key: str, value: object, unit: str) -> tuple[float, bool]:
    """Read ``value`` as a quantity in ``unit``; return ``(SI value, was a bare number)``.

    See :func:`to_si`; the second item tells whether no unit was given (a number, or a string
    holding only a number), which the command line reports for dimensional quantities.
    """
    if is_number(value):
        return _float(key, value), True
    if not isinstance(value, str):
        got = "None" if value is None else f"{type(value).__name__} {str(value)[:40]}"
        raise InputError(
            f"{key}: expected a number or a quantity string in {unit or 'no unit'}, got {got}"
        )
    mag, rest = _split(key, value, unit)
    if not rest:
        return mag, True
    unit_text = _check_unit_text(key, value, rest)
    if (unit_text, unit) in _SI_FACTORS:
        return _checked(key, value, unit, mag, mag * _SI_FACTORS[unit_text, unit]), False
    if unit == "rad/s" and unit_text in _FREQUENCY_FACTORS:  # as the pure frequency below
        out = mag * _FREQUENCY_FACTORS[unit_text] * 2.0 * math.pi
        return _checked(key, value, unit, mag, out), False
    ureg = registry()  # imports pint
    import pint

    u = _pint_expression(key, value, rest, unit_text)
    q = mag * (u if isinstance(u, pint.Quantity) else ureg.Quantity(float(u), ""))
    target = ureg.Unit(unit) if unit else ureg.dimensionless
    try:
        if unit == "rad/s" and q.dimensionality == ureg.Unit("1/s").dimensionality:
            names = [ureg.get_name(n) for n, _ in q.unit_items()]
            if all(_is_time_or_hertz(ureg, n) for n in names):
                # A pure frequency: cycles per unit time.
                out = float(q.to("1/s").magnitude) * 2.0 * math.pi
            else:
                out = float(q.to(target).magnitude)
        else:
            out = float(q.to(target).magnitude)
    except pint.DimensionalityError:
        want = f"a quantity in {unit}" if unit else "a plain number (no unit)"
        raise InputError(f"{key}: {value!r} has the wrong unit; expected {want}") from None
    except (OverflowError, ZeroDivisionError):
        out = math.inf
    return _checked(key, value, unit, mag, out), False


def force_per_length_power(key: str, value: str) -> float | None:
    """The exponent n of the unit of the quantity string ``value``, a force per length to
    the power n (``"1e9 N/m^1.5"``: 1.5; ``"3 kN/mm"``: 1.0), or None when it has no unit:
    the unit of a contact stiffness K [N/m^n] says which n it was written for.

    Raises
    ------
    InputError
        The string does not parse (as :func:`to_si` would say), or its unit is not a force
        per a power of length.
    """
    _, rest = _split(key, value, "N/m^n")
    if not rest:
        return None
    import pint

    q = _pint_expression(key, value, rest, _check_unit_text(key, value, rest))
    dims = dict(q.dimensionality) if isinstance(q, pint.Quantity) else {}
    if (
        set(dims) <= {"[mass]", "[time]", "[length]"}
        and dims.get("[mass]") == 1
        and dims.get("[time]") == -2
    ):
        return 1.0 - float(dims.get("[length]", 0))  # type: ignore[arg-type]
    raise InputError(
        f"{key}: {value!r} has the wrong unit; expected a quantity in N/m^n, n the pair's "
        "force exponent (e.g. '1e9 N/m^1.5')"
    )


def _checked(key: str, value: str, unit: str, mag: float, out: float) -> float:
    """``out``, the quantity ``value`` (magnitude ``mag``) in ``unit``, unless a finite
    magnitude became infinite or NaN in the conversion (an :class:`InputError`)."""
    if math.isfinite(mag) and not math.isfinite(out):
        raise InputError(
            f"{key}: {value!r} is {'not a number' if math.isnan(out) else 'too large'} in "
            f"{unit or 'no unit'}; allowed a value a 64-bit float can hold"
        )
    return out


def to_si(key: str, value: object, unit: str) -> float:
    """Convert ``value`` (a number in SI or a string with units) to a float in ``unit``.

    Parameters
    ----------
    key : str
        Parameter name, used in error messages.
    value : float or str
        A bare number (Python or numpy; taken as already in SI) or a string such as
        ``"3 mm"`` (read by the grammar of the module docstring, never evaluated).
    unit : str
        Target SI unit as a pint expression (``"m"``, ``"N/m**1.5"``, ``"rad/s"``, ``""``).

    Raises
    ------
    InputError
        The string does not parse, its dimension does not match ``unit``, or the number does
        not fit a 64-bit float.
    """
    return parse_quantity(key, value, unit)[0]
