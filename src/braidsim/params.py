"""Parameters: the schema of every scenario key, validation, and the frozen Scenario.

A scenario is a TOML file, a built-in name, or a mapping of dotted keys. Values are numbers
in SI or strings with units. :func:`load_scenario` reads one, applies overrides, checks every
key against :data:`SCHEMA` (unknown key -> the closest known name; wrong unit; out of range;
NaN or inf) and returns a frozen :class:`Scenario` whose values are plain SI floats.

The key names are public: every one can be set in a scenario file, with ``--set KEY=VALUE``
and with ``overrides=`` in Python (``braidsim scenarios --keys`` lists them; the docs page
*Command line and scenario keys* is generated from :data:`SCHEMA`).
"""

from __future__ import annotations

import difflib
import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any

from braidsim.contact import GEOMETRIES, get_law, law_names
from braidsim.errors import InputError
from braidsim.units import UNIT_HINT, force_per_length_power, to_si

PI = math.pi


@dataclass(frozen=True)
class ParamSpec:
    """One scenario key.

    Attributes
    ----------
    key : str
        Dotted name.
    kind : str
        ``float``, ``int``, ``bool``, ``choice``, ``floats`` (a list of quantities),
        ``harmonics`` (a list of [amplitude, frequency, phase]) or ``profile``
        (a table ``{times = [...], speeds = [...]}``).
    unit : str
        SI unit of the value (pint expression; "" for dimensionless).
    default : Any
        Default in SI (None: absent unless set).
    low, high : float
        Allowed range; ``low_open``/``high_open`` make the bound strict.
    choices : tuple of str
        Allowed values of a ``choice``.
    doc : str
        What it is, with the paper's symbol.
    allow_inf : bool
        Whether infinity is allowed (``"inf"``: a flat surface's radius of curvature).
    """

    key: str
    kind: str
    unit: str
    default: Any
    doc: str
    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    high_open: bool = False
    choices: tuple[str, ...] = ()
    allow_inf: bool = False

    def range_text(self) -> str:
        """The allowed range in words, for error messages."""
        u = f" {self.unit}" if self.unit else ""
        if self.kind == "choice":
            return "one of " + ", ".join(self.choices)
        if self.kind == "bool":
            return "true or false"
        parts = []
        if self.low > -math.inf:
            parts.append(f"{'>' if self.low_open else '>='} {self.low:g}{u}")
        if self.high < math.inf:
            parts.append(f"{'<' if self.high_open else '<='} {self.high:g}{u}")
        return " and ".join(parts) if parts else f"any finite value in {self.unit or 'no unit'}"

    def check_number(self, value: float) -> float:
        """Validate one float against the range; return it."""
        if math.isnan(value) or (math.isinf(value) and not self.allow_inf):
            raise InputError(
                f"{self.key}: {value} is not a finite number; allowed {self.range_text()}"
            )
        bad_low = value <= self.low if self.low_open else value < self.low
        bad_high = value >= self.high if self.high_open else value > self.high
        if bad_low or bad_high:
            u = f" {self.unit}" if self.unit else ""
            raise InputError(
                f"{self.key}: {value:g}{u} is out of range; allowed {self.range_text()}"
            )
        return value


def _f(key: str, unit: str, default: Any, doc: str, **kw: Any) -> ParamSpec:
    return ParamSpec(key, "float", unit, default, doc, **kw)


def _positive(key: str, unit: str, default: Any, doc: str, **kw: Any) -> ParamSpec:
    return ParamSpec(key, "float", unit, default, doc, low=0.0, low_open=True, **kw)


def _nonneg(key: str, unit: str, default: Any, doc: str, **kw: Any) -> ParamSpec:
    return ParamSpec(key, "float", unit, default, doc, low=0.0, **kw)


def _material(part: str, radius: float, doc_radius: str) -> list[ParamSpec]:
    return [
        _positive(
            f"materials.{part}.youngs_modulus",
            "Pa",
            200e9,
            f"E of the {part.replace('_', ' ')} [Pa] (Eq. 4; 200 GPa reproduces the paper, "
            "it prints 2 GPa)",
        ),
        ParamSpec(
            f"materials.{part}.poisson_ratio",
            "float",
            "",
            0.3,
            f"nu of the {part.replace('_', ' ')} (Eq. 4)",
            low=-1.0,
            high=0.5,
            low_open=True,
            high_open=True,
        ),
        _positive(f"materials.{part}.radius", "m", radius, doc_radius, allow_inf=True),
    ]


def _contact(pair: str, geometry: str) -> list[ParamSpec]:
    return [
        ParamSpec(
            f"contact.{pair}.model",
            "choice",
            "",
            "hunt_crossley",
            f"contact force law of the {pair} pair (Eqs. 3-13; `braidsim models`)",
            choices=tuple(law_names()),
        ),
        ParamSpec(
            f"contact.{pair}.restitution",
            "float",
            "",
            5.0 / 9.0,
            f"coefficient of restitution c_r of the {pair} pair",
            low=0.0,
            high=1.0,
            low_open=True,
        ),
        _positive(
            f"contact.{pair}.exponent",
            "",
            None,
            f"force exponent n of the {pair} pair (default: the law's, 1.5 or 1.08)",
            high=4.0,
        ),
        _positive(
            f"contact.{pair}.stiffness",
            "",
            None,
            f"contact stiffness K of the {pair} pair [N/m^n]; from Eq. (4) when absent",
        ),
        ParamSpec(
            f"contact.{pair}.geometry",
            "choice",
            "",
            geometry,
            f"curvature of the {pair} contact for Eq. (4): concave, convex or flat",
            choices=GEOMETRIES,
        ),
    ]


SCHEMA_LIST: list[ParamSpec] = [
    _positive("carrier.mass", "kg", 1.2, "carrier mass m [kg]"),
    _positive("carrier.turning_radius", "m", 0.065, "turning radius r_c of the carrier [m]"),
    _nonneg("horn_gear.angular_velocity", "rad/s", 4 * PI, "mean horn-gear speed omega [rad/s]"),
    ParamSpec(
        "horn_gear.speed_harmonics",
        "harmonics",
        "rad/s",
        (),
        "extra terms of omega(t): [[amplitude, angular frequency, phase], ...]",
    ),
    ParamSpec(
        "horn_gear.speed_profile",
        "profile",
        "rad/s",
        None,
        "periodic piecewise-linear omega(t): {times = [...], speeds = [...]}; replaces the "
        "constant speed and the harmonics",
    ),
    _nonneg("yarn.tension_horizontal", "N", 5.0, "yarn tension T1 [N]"),
    _nonneg("yarn.tension_vertical", "N", 3.0, "yarn tension T2 [N]"),
    _f("yarn.angle", "rad", PI / 6, "angle phi of T1 to the x direction [rad]", low=-PI, high=PI),
    _nonneg("friction.carrier_horn_gear", "", 0.1, "mu1, carrier / horn gear (f_x of Eq. 14)"),
    _nonneg("friction.pad_track", "", 0.1, "mu2, guide pad / track (f_y of Eq. 14)"),
    _positive(
        "friction.regularization_velocity",
        "m/s",
        1e-3,
        "x_hat = y_hat of Eq. (14) [m/s] (not given by the paper)",
    ),
    ParamSpec(
        "friction.law",
        "choice",
        "",
        "arctan",
        "friction law: arctan (Eq. 14), tanh, stribeck, none",
        choices=("arctan", "tanh", "stribeck", "none"),
    ),
    ParamSpec(
        "friction.static_ratio",
        "float",
        "",
        1.5,
        "stribeck law: static over kinetic friction coefficient",
        low=1.0,
    ),
    _positive("friction.stribeck_velocity", "m/s", 0.01, "stribeck law: Stribeck velocity [m/s]"),
    *_material("guide_pad", 0.020, "guide pad radius R1 [m]"),
    *_material("track", 0.065, "track radius R2 [m] (concave)"),
    *_material("carrier", 0.010, "carrier contact radius R3 [m]"),
    *_material("horn_gear", math.inf, "horn-gear slot radius R4 [m] (not given; flat)"),
    _positive("track.clearance", "m", 3e-3, "clearance eps_g between guide pads and track [m]"),
    _nonneg("track.vibration_amplitude", "m", 1e-4, "track vibration amplitude h_a [m]"),
    _nonneg("track.vibration_frequency", "rad/s", 120 * PI, "track vibration omega_h [rad/s]"),
    _f("track.vibration_phase", "rad", 0.0, "phase of h(t) = h_a cos(omega_h t + phase) [rad]"),
    ParamSpec(
        "track.harmonics",
        "harmonics",
        "m",
        (),
        "extra terms of h(t): [[amplitude, angular frequency, phase], ...]",
    ),
    _positive(
        "slot.clearance", "m", 1e-4, "clearance eps_h between carrier and horn-gear slot [m]"
    ),
    *_contact("track", "concave"),
    *_contact("slot", "flat"),
    _positive(
        "contact.min_impact_velocity",
        "m/s",
        1e-4,
        "floor on the latched approach speed v0 of Eqs. (5)-(13) [m/s]",
    ),
    _positive(
        "contact.initial_impact_velocity",
        "m/s",
        None,
        "v0 for a contact present at t = 0 [m/s]; default: none, the overlap is released "
        "elastically (no damping until the next onset), as the paper's sections 3.3-3.4 show",
    ),
    ParamSpec(
        "contact.allow_tension",
        "bool",
        "",
        False,
        "let the total normal force turn negative (adhesive) instead of clamping it at 0",
    ),
    _f("initial.x", "m", 0.0, "x0 [m] (the inner track wall is at x = h(t))"),
    _f("initial.vx", "m/s", 0.0, "dx0/dt [m/s]"),
    _f("initial.y", "m", 0.0, "y0 [m] (the rear slot wall is at y = s(t), s(0) = 0)"),
    _f(
        "initial.vy",
        "m/s",
        0.0,
        "dy0/dt relative to the slot [m/s] (0: moving with the slot at r_c omega(0))",
    ),
    _nonneg("gravity", "m/s**2", 9.81, "g [m/s^2]"),
    _positive("simulation.duration", "s", 0.5, "simulated time [s]"),
    ParamSpec(
        "simulation.dof",
        "choice",
        "",
        "x",
        "x: radial DOF only, y frozen (the paper's section 3); xy: both DOFs",
        choices=("x", "xy"),
    ),
    ParamSpec(
        "simulation.rtol",
        "float",
        "",
        1e-8,
        "relative tolerance of the RK step control (>= 1e-15: below it the rounding of the "
        "state, 2.2e-16 relative, decides the error, not the step control)",
        low=1e-15,
        high=1e-2,
    ),
    _positive("simulation.atol_position", "m", 1e-13, "absolute tolerance on x and y [m]"),
    _positive("simulation.atol_velocity", "m/s", 1e-9, "absolute tolerance on velocities [m/s]"),
    _positive(
        "simulation.max_step",
        "s",
        None,
        "largest step [s]; default 1/8 of the shortest excitation period, at most 1 ms",
    ),
    _positive("simulation.sample_interval", "s", 1e-5, "spacing of the sampled time series [s]"),
    ParamSpec(
        "simulation.resting_contacts",
        "choice",
        "",
        "explicit",
        "integrator of a contact at rest (its fast mode holding the explicit step): explicit "
        "(Dormand-Prince throughout) or implicit (L-stable Radau IIA until its next event; "
        "compiled on first use; a run with sensitivities is explicit)",
        choices=("explicit", "implicit"),
    ),
    ParamSpec(
        "simulation.integrator",
        "choice",
        "",
        "dormand-prince",
        "step of the motion: dormand-prince (Runge-Kutta 5(4) throughout) or taylor (Taylor "
        "series of order 12 wherever they step farther than Dormand-Prince, which keeps the "
        "rest: contact onsets, exits, clamped forces; compiled on first use; a run with "
        "sensitivities takes Dormand-Prince steps)",
        choices=("dormand-prince", "taylor"),
    ),
    ParamSpec(
        "simulation.max_steps",
        "int",
        "",
        5_000_000,
        "budget of integration steps before a run is declared stuck (unless set: this or "
        "50,000 per simulated second, whichever is larger)",
        low=1,
        # (the step counter of a run's record is a float: exact to 2^53, and the driver's
        # pauses shift it by the budget)
        high=2**52,
    ),
    ParamSpec("transfer.times", "floats", "s", (), "times of transfers to the next horn gear [s]"),
    _nonneg(
        "transfer.period",
        "s",
        0.0,
        "period of transfers [s] (pi/omega at 4 horn-gear slots); 0: none",
    ),
    _nonneg("transfer.first", "s", 0.0, "time of the first periodic transfer [s]"),
    _f(
        "transfer.contact_speed",
        "m/s",
        2e-3,
        "speed towards the new far wall given by a transfer [m/s] (section 3.2: 2 mm/s)",
    ),
]

SCHEMA: dict[str, ParamSpec] = {s.key: s for s in SCHEMA_LIST}
_TABLE_KEYS = {k for k, s in SCHEMA.items() if s.kind in ("profile",)}
_META_KEYS = ("name", "description", "source", "extends", "notes")


def _closest(key: str) -> str:
    close = difflib.get_close_matches(key, list(SCHEMA), n=1, cutoff=0.4)
    if not close:
        # Try the last component alone (e.g. "mass" -> "carrier.mass").
        tail = key.rsplit(".", 1)[-1]
        close = [k for k in SCHEMA if k.rsplit(".", 1)[-1] == tail][:1]
    return f" (did you mean {close[0]!r}?)" if close else ""


def _unknown(key: str) -> InputError:
    shown = key if key.isprintable() and len(key) <= 80 else repr(key[:80])
    return InputError(
        f"{shown}: unknown parameter{_closest(key)}; `braidsim scenarios --keys` lists all"
    )


#: deepest nesting of tables accepted in a scenario (the deepest key, contact.track.model,
#: needs 3)
MAX_DEPTH = 8


def flatten(table: Mapping[str, Any], prefix: str = "", depth: int = 0) -> dict[str, Any]:
    """Nested TOML tables -> dotted keys (tables that are values, like profiles, stay whole).

    Raises
    ------
    InputError
        Tables nested deeper than :data:`MAX_DEPTH`, or a key that is not a string.
    """
    if depth > MAX_DEPTH:
        raise InputError(
            f"{prefix.rstrip('.')[:60]}: tables nested {depth} deep; allowed at most {MAX_DEPTH}"
        )
    out: dict[str, Any] = {}
    for k, v in table.items():
        if not isinstance(k, str):
            raise InputError(f"{prefix}{k!r}: a parameter key must be a string, got {k!r}")
        key = f"{prefix}{k}"
        sub = (
            flatten(v, key + ".", depth + 1)
            if isinstance(v, Mapping) and key not in _TABLE_KEYS
            else {key: v}
        )
        for dotted in sub:
            if dotted in out:
                # a quoted dotted key and a table both give it ("track.clearance" = ... and
                # [track] clearance = ...): the later one silently won
                raise InputError(
                    f"{dotted}: given twice (as a dotted key and in a table); allowed once"
                )
        out.update(sub)
    return out


def _list(key: str, value: Any, what: str) -> list[Any]:
    """``value`` as a list (a list, tuple or 1-D numpy array), else an :class:`InputError`."""
    if isinstance(value, list | tuple):
        return list(value)
    if hasattr(value, "tolist") and getattr(value, "ndim", 0) == 1:
        return list(value.tolist())
    raise InputError(f"{key}: expected {what}, got {type(value).__name__} {str(value)[:60]}")


def _convert_list(spec: ParamSpec, value: Any) -> tuple[float, ...]:
    if isinstance(value, str):
        value = [v for v in value.replace(";", ",").split(",") if v.strip()]
    items = _list(spec.key, value, f"a list of quantities in {spec.unit}")
    out = tuple(spec.check_number(to_si(spec.key, v, spec.unit)) for v in items)
    return out


def convert(spec: ParamSpec, value: Any) -> Any:
    """Convert one raw value (number, unit string, list, table) to SI and validate it.

    ``None`` means "absent" and is accepted only for keys that are absent by default (such as
    ``contact.track.stiffness``); for every other key it is an :class:`InputError`. Any value
    of the wrong type gives an :class:`InputError` naming the key, never another exception.
    """
    if value is None:
        if spec.default is None:
            return None
        raise InputError(
            f"{spec.key}: None is not a value; allowed {spec.range_text()} "
            "(leave the key out for its default)"
        )
    try:
        return _convert(spec, value)
    except InputError as exc:
        msg = str(exc)
        if msg.endswith(UNIT_HINT):  # (text that is no unit: say what this key takes)
            raise InputError(msg[: -len(UNIT_HINT)] + f"allowed {spec.range_text()}") from None
        raise
    except (TypeError, ValueError, OverflowError, AttributeError, KeyError, IndexError) as exc:
        raise InputError(
            f"{spec.key}: cannot read {str(value)[:60]!r} ({exc.__class__.__name__}); "
            f"allowed {spec.range_text()}"
        ) from None


def _is_stiffness(key: str) -> bool:
    """Whether ``key`` is a contact stiffness, whose unit N/m^n depends on the exponent n."""
    return key.startswith("contact.") and key.endswith(".stiffness")


class _StiffnessIn(float):
    """A contact stiffness read from a string with a unit, in SI (N/m^n), carrying the n of
    that unit until :func:`_resolve_stiffness` checks it against the pair's exponent."""

    exponent: float


def _convert(spec: ParamSpec, value: Any) -> Any:
    key = spec.key
    if spec.kind == "float" and _is_stiffness(key) and isinstance(value, str):
        n = force_per_length_power(key, value)
        if n is not None:  # (None: a number alone, read below)
            out = _StiffnessIn(spec.check_number(to_si(key, value, f"N/m**{n!r}")))
            out.exponent = n
            return out
    if spec.kind == "float":
        return spec.check_number(to_si(key, value, spec.unit))
    if spec.kind == "int":
        v = to_si(key, value, "")
        if not math.isfinite(v) or v != int(v):
            raise InputError(
                f"{key}: {str(value)[:40]} is not a finite integer; allowed {spec.range_text()}"
            )
        return int(spec.check_number(v))
    if spec.kind == "bool":
        # (numpy's bool: ``bool_`` before numpy 2, ``bool`` since)
        if isinstance(value, bool) or (
            type(value).__module__ == "numpy" and type(value).__name__ in ("bool_", "bool")
        ):
            return bool(value)
        if isinstance(value, str) and value.lower() in ("true", "false", "1", "0", "yes", "no"):
            return value.lower() in ("true", "1", "yes")
        raise InputError(f"{key}: {value!r} is not a boolean; allowed true or false")
    if spec.kind == "choice":
        if not isinstance(value, str) or value not in spec.choices:
            close = difflib.get_close_matches(str(value), spec.choices, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise InputError(f"{key}: {value!r} is not allowed{hint}; allowed {spec.range_text()}")
        return value
    if spec.kind == "floats":
        vals = _convert_list(spec, value)
        if any(v < 0 for v in vals):
            raise InputError(f"{key}: times must be >= 0 s, got {vals}")
        return tuple(sorted(vals))
    if spec.kind == "harmonics":
        terms = []
        for term in _list(key, value, "[[amplitude, frequency, phase], ...]"):
            if not isinstance(term, list | tuple) or len(term) not in (2, 3):
                raise InputError(f"{key}: each term is [amplitude, frequency, phase], got {term!r}")
            amp = to_si(key, term[0], spec.unit)
            freq = to_si(key, term[1], "rad/s")
            phase = to_si(key, term[2], "rad") if len(term) == 3 else 0.0
            for v in (amp, freq, phase):
                if not math.isfinite(v):
                    raise InputError(f"{key}: {term!r} has a non-finite entry")
            if freq < 0:
                raise InputError(f"{key}: frequency {freq:g} rad/s is negative; allowed >= 0")
            terms.append((amp, freq, phase))
        return tuple(terms)
    if spec.kind == "profile":
        if value is None:
            return None
        if not isinstance(value, Mapping) or set(value) != {"times", "speeds"}:
            raise InputError(
                f"{key}: expected a table {{times = [...], speeds = [...]}}, got {value!r}"
            )
        times = [to_si(key, v, "s") for v in _list(key, value["times"], "times = [...]")]
        speeds = [to_si(key, v, "rad/s") for v in _list(key, value["speeds"], "speeds = [...]")]
        if len(times) != len(speeds) or len(times) < 2:
            raise InputError(f"{key}: times and speeds need the same length >= 2")
        if any(not math.isfinite(v) for v in times + speeds):
            raise InputError(f"{key}: non-finite entry in the profile")
        if any(b <= a for a, b in itertools.pairwise(times)):
            raise InputError(f"{key}: times must increase strictly")
        if any(s < 0 for s in speeds):
            raise InputError(f"{key}: speeds must be >= 0 rad/s")
        return (tuple(times), tuple(speeds))
    raise AssertionError(spec.kind)  # pragma: no cover - schema is static


def _scenario_from_state(
    name: str, values: dict[str, Any], description: str, source: str, explicit: frozenset[str]
) -> Scenario:
    """A :class:`Scenario` from its pickled state (see ``Scenario.__reduce__``)."""
    return Scenario(name, MappingProxyType(values), description, source, explicit)


@dataclass(frozen=True)
class Scenario:
    """A validated, frozen set of parameters in SI.

    Attributes
    ----------
    name : str
        Built-in name or file stem.
    values : Mapping[str, Any]
        Every key of :data:`SCHEMA` with its SI value (None where absent).
    description, source : str
        What it is and where it comes from (section and figures of the paper).
    explicit : frozenset of str
        The keys set explicitly (by the file, the overrides or the built-in scenario), as
        opposed to those left at their defaults.
    """

    name: str
    values: Mapping[str, Any]
    description: str = ""
    source: str = ""
    explicit: frozenset[str] = field(default_factory=frozenset)

    def __getitem__(self, key: str) -> Any:
        if not isinstance(key, str):
            raise InputError(f"{key!r}: a scenario key is a dotted name, e.g. 'track.clearance'")
        try:
            return self.values[key]
        except KeyError:
            raise _unknown(key) from None

    def __contains__(self, key: object) -> bool:
        """Whether ``key`` is a parameter of the schema (every scenario has them all)."""
        return key in self.values

    def __repr__(self) -> str:
        # the whole parameter set is ~70 entries: name the ones set explicitly, briefly
        def brief(v: Any) -> str:
            return f"{v:.4g}" if isinstance(v, float) else repr(v)

        shown = [f"{k} = {brief(self.values[k])}" for k in sorted(self.explicit)[:4]]
        more = len(self.explicit) - len(shown)
        set_ = ", ".join(shown) + (f", +{more} more" if more > 0 else "")
        return (
            f"<braidsim.Scenario {self.name!r}: {len(self.values)} parameters in SI"
            + (f"; set: {set_}" if shown else "")
            + ">"
        )

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        # the read-only view of the values cannot be pickled: pickle (and deepcopy) a plain
        # copy of them, viewed read-only again on the way back
        return (
            _scenario_from_state,
            (self.name, dict(self.values), self.description, self.source, self.explicit),
        )

    def with_overrides(
        self,
        overrides: Mapping[str, Any] | None = None,
        name: str | None = None,
        *,
        check_start: bool = True,
    ) -> Scenario:
        """A new scenario with ``overrides`` (dotted keys or nested tables, numbers or unit
        strings) applied.

        ``check_start=False`` leaves the start's position unchecked against the walls: for a
        caller that sets the start itself afterwards (a machine's carriers start at rest on
        the inner wall, wherever the scenario they are built from starts, and a smaller
        clearance must not be refused for that scenario's start)."""
        if overrides is not None and not isinstance(overrides, Mapping):
            # analyze(scenario, 0.3) and the like: their second positional argument is the
            # overrides, the duration a keyword
            hint = (
                "; a duration is given by keyword (duration=...)"
                if isinstance(overrides, (int, float, str))
                else ""
            )
            raise InputError(
                f"overrides: expected a mapping {{dotted key: value}}, got "
                f"{type(overrides).__name__}{hint}"
            )
        raw: dict[str, Any] = dict(self.values)
        explicit = set(self.explicit)
        # nested tables ({"track": {"clearance": ...}}) read as dotted keys, as in a scenario
        for key, value in flatten(overrides or {}).items():
            if key not in SCHEMA:
                raise _unknown(key)
            raw[key] = convert(SCHEMA[key], value)
            explicit.add(key)
        _resolve_stiffness(raw)
        _check_consistency(raw, check_start)
        return Scenario(
            name or self.name,
            MappingProxyType(raw),
            self.description,
            self.source,
            frozenset(explicit),
        )

    def to_dict(self) -> dict[str, Any]:
        """Every parameter in SI, JSON-ready (:func:`json_value`)."""
        return {k: json_value(v) for k, v in self.values.items()}


def json_value(v: Any) -> Any:
    """A parameter's value as JSON data: tuples become lists, an infinite value the string
    ``"inf"`` (which the scenario files read back), an absent value None."""
    if isinstance(v, tuple):
        return [json_value(x) for x in v]
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    return v


def _resolve_stiffness(values: dict[str, Any]) -> None:
    """Check a contact stiffness written with a unit against its pair, in place: its unit is
    N/m^n with n the pair's exponent (``contact.PAIR.exponent``, or the law's own), so
    ``"1e9 N/m^1.5"`` is accepted only where n = 1.5; any other power of length is refused
    naming the key and the unit expected. The value becomes a plain float."""
    for pair in ("track", "slot"):
        key = f"contact.{pair}.stiffness"
        value = values[key]
        if not isinstance(value, _StiffnessIn):
            continue
        n = values[f"contact.{pair}.exponent"]
        if n is None:
            n = get_law(values[f"contact.{pair}.model"]).default_exponent
        if abs(value.exponent - float(n)) > 1e-12 * float(n):
            raise InputError(
                f"{key}: a quantity in N/m^{value.exponent:g} has the wrong unit; expected "
                f"N/m^{float(n):g} (n = {float(n):g}, the {pair} pair's exponent)"
            )
        values[key] = float(value)


def inner_wall_at_start(values: Mapping[str, Any]) -> float:
    """x of the track's inner wall at t = 0 [m]: h(0) = h_a cos(phase) plus each harmonic's
    amplitude times the cosine of its phase."""
    h0 = values["track.vibration_amplitude"] * math.cos(values["track.vibration_phase"])
    return float(h0 + sum(a * math.cos(phase) for a, _, phase in values["track.harmonics"]))


def _check_start_between_walls(values: Mapping[str, Any]) -> None:
    """The start may overlap a wall (the paper's sections 3.3-3.4 start 0.12 mm into the
    track), but by no more than the pair's clearance: a deeper overlap is no state of a
    machine, and a value in the wrong unit ("1 m" for "1 mm") gave a run with forces of
    1e9 N rather than an error. The track's inner wall is at x = h(0) at the start, with
    h(t) = h_a cos(omega_h t + phase) plus its harmonics; the slot's rear wall at y = 0."""
    h0 = inner_wall_at_start(values)
    # where the wall is set by the vibration (its amplitude, a harmonic), the range moves
    # with it: name what put it there, or a wrong amplitude reads as a wrong start
    where_x = "the inner track wall at x = h(0)"
    if h0 != 0.0:
        where_x += (
            f" = {h0 * 1e3:g} mm, from track.vibration_amplitude "
            f"({values['track.vibration_amplitude'] * 1e3:g} mm)"
        )
        if values["track.harmonics"]:
            where_x += " and track.harmonics at their phases"
        else:
            where_x += " at its phase"
    checks = [("initial.x", h0, "track.clearance", where_x)]
    if values["simulation.dof"] == "xy":
        checks.append(("initial.y", 0.0, "slot.clearance", "the rear slot wall at y = 0"))
    for key, wall, gap_key, where in checks:
        gap = values[gap_key]
        low, high = wall - gap, wall + 2.0 * gap
        if not low <= values[key] <= high:
            raise InputError(
                f"{key}: {values[key] * 1e3:g} mm is out of range; allowed {low * 1e3:g} to "
                f"{high * 1e3:g} mm (at most {gap_key}, {gap * 1e3:g} mm, into either wall; "
                f"{where})"
            )


def _check_consistency(values: Mapping[str, Any], check_start: bool = True) -> None:
    """Cross-key checks that a single range cannot express."""
    if check_start:
        _check_start_between_walls(values)
    for pair, (body, other) in {
        "track": ("guide_pad", "track"),
        "slot": ("carrier", "horn_gear"),
    }.items():
        if (
            values[f"contact.{pair}.stiffness"] is None
            and values[f"contact.{pair}.geometry"] == "concave"
        ):
            r1, r2 = values[f"materials.{body}.radius"], values[f"materials.{other}.radius"]
            if r2 <= r1:
                raise InputError(
                    f"materials.{other}.radius: {r2:g} m must exceed materials.{body}.radius "
                    f"({r1:g} m) for a concave {pair} contact; allowed > {r1:g} m"
                )


def _builtin_dir() -> Any:
    return resources.files("braidsim") / "scenarios"


def builtin_names() -> list[str]:
    """Names of the built-in scenarios."""
    return sorted(
        p.name[: -len(".toml")] for p in _builtin_dir().iterdir() if p.name.endswith(".toml")
    )


def _raw_scenario(
    name_or_path: str | Path, depth: int = 0, base_dir: Path | None = None
) -> tuple[str, dict[str, Any], dict[str, str]]:
    """Read a scenario (following ``extends``) into dotted raw values and metadata.

    A relative ``extends`` path is read relative to the folder of the file that names it
    (``base_dir``), like an include; a built-in name always means the built-in scenario.
    """
    from braidsim.specfile import parse_toml, read_text

    if depth > 8:
        raise InputError(f"{name_or_path}: `extends` chain is too deep (a cycle?)")
    name = str(name_or_path)
    if name in builtin_names():
        text = (_builtin_dir() / f"{name}.toml").read_text(encoding="utf-8")
        origin = f"scenario {name}"
    else:
        path = Path(name)
        if base_dir is not None and not path.is_absolute():
            path = base_dir / path
        if not path.is_file():
            close = difflib.get_close_matches(name, builtin_names(), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            where = f" (relative to {str(base_dir)!r})" if base_dir is not None else ""
            raise InputError(
                f"scenario: {name!r}{where} is neither a built-in scenario{hint} nor a TOML "
                "file; `braidsim scenarios` lists the built-in ones"
            )
        text = read_text(path, "scenario")
        origin = str(path)
        name = path.stem
        base_dir = path.parent
    table = parse_toml(text, origin)
    for k in _META_KEYS:
        if k in table and not isinstance(table[k], str):
            what = "a scenario name or a TOML path" if k == "extends" else "a string"
            raise InputError(f"{origin}: {k}: {table[k]!r} is not a string; allowed {what}")
    meta = {k: str(table.pop(k)) for k in _META_KEYS if k in table}
    if not table and "extends" not in meta:
        raise InputError(
            f"{origin}: the scenario sets no parameter; allowed at least one key or "
            'extends = "<scenario>" (`braidsim scenarios --keys` lists the keys)'
        )
    raw: dict[str, Any] = {}
    if "extends" in meta:
        _, raw, parent_meta = _raw_scenario(meta["extends"], depth + 1, base_dir)
        for k in ("description", "source"):
            meta.setdefault(k, parent_meta.get(k, ""))
    raw.update(flatten(table))
    return meta.get("name", name), raw, meta


def load_scenario(
    scenario: str | Path | Mapping[str, Any] = "paper-3.1",
    overrides: Mapping[str, Any] | None = None,
) -> Scenario:
    """Load a built-in scenario, a TOML file, or a mapping of dotted keys, with overrides.

    Parameters
    ----------
    scenario : str, Path or mapping
        Built-in name (``braidsim scenarios``), path to a TOML file, or ``{key: value}``.
        A TOML file may say ``extends = "paper-3.1"`` to start from a built-in scenario.
    overrides : mapping, optional
        ``{dotted key: value}`` (or nested tables, ``{"track": {"clearance": ...}}``); values
        are SI numbers or unit strings.

    Returns
    -------
    Scenario
        Frozen, validated, SI.

    Raises
    ------
    InputError
        Unknown key (naming the closest), wrong unit, out-of-range value, malformed TOML.
    """
    if isinstance(scenario, Mapping):
        if "extends" in scenario:
            # (a file's extends names its base by path or name; a mapping has no file)
            raise InputError(
                "scenario: 'extends' is read in a scenario TOML file only; allowed from "
                "Python load_scenario(BASE, overrides={...}) with BASE a built-in name or path"
            )
        meta: dict[str, str] = {}
        name, raw = "custom", flatten(scenario)
    elif not isinstance(scenario, str | Path):
        raise InputError(
            f"scenario: expected a built-in name, a TOML path or a mapping, got "
            f"{type(scenario).__name__}"
        )
    else:
        name, raw, meta = _raw_scenario(scenario)
    values: dict[str, Any] = {k: s.default for k, s in SCHEMA.items()}
    explicit: set[str] = set()
    for key, value in raw.items():
        if key not in SCHEMA:
            raise _unknown(key)
        values[key] = convert(SCHEMA[key], value)
        explicit.add(key)
    _resolve_stiffness(values)
    base = Scenario(
        name,
        MappingProxyType(values),
        meta.get("description", ""),
        meta.get("source", ""),
        frozenset(explicit),
    )
    _check_consistency(values)
    return base.with_overrides(overrides) if overrides else base


def parse_assignment(text: str) -> tuple[str, str]:
    """Split ``KEY=VALUE`` from ``--set``; an :class:`InputError` otherwise."""
    if "=" not in text:
        raise InputError(f"--set: expected KEY=VALUE, got {text!r}")
    key, value = text.split("=", 1)
    key = key.strip()
    if not key:
        raise InputError(f"--set: {text!r} has no KEY before '='; expected KEY=VALUE")
    if key not in SCHEMA:
        raise _unknown(key)
    return key, value.strip()


def parse_set_value(key: str, value: str) -> Any:
    """Interpret the text of ``--set KEY=VALUE`` (TOML literal if it parses, else a string)."""
    import tomllib

    from braidsim.specfile import toml_float

    try:
        return tomllib.loads(f"v = {value}", parse_float=toml_float)["v"]
    except (ValueError, RecursionError):  # TOMLDecodeError, or an integer of 4300+ digits
        return value
