"""The fit specification: a TOML file read and validated whole before any run.

::

    scenario = "paper-3.1"               # a built-in name or a scenario TOML (relative to
                                         # this file)
    data = "record.csv"                  # optional: the record (--data replaces it); or
                                         # several fitted together, each a path or a table
                                         # {path = "...", overrides = {...}}:
                                         # data = [{path = "a.csv", overrides =
                                         #   {"initial.vx" = "0.3 m/s"}}, "b.csv"]
    [overrides]                          # optional, unit strings
    "track.vibration_amplitude" = "0 mm"

    [fit]
    free = { "contact.track.restitution" = [0.2, 0.95], "track.clearance" = ["2 mm", "4 mm"] }
                                         # "record.time_offset" = ["0 ms", "0.2 ms"]: the
                                         # model's time of the record's t = 0 (several
                                         # records: one each, record[i].time_offset)
    quantity = "x"                       # a column, or a list: ["x", "acceleration"];
                                         # an impact list fits t and all its columns
                                         # unless some (peak_force, velocity,
                                         # rebound_velocity, dissipated_energy)
                                         # are named
    start = { "track.clearance" = "3 mm" }   # optional; default the scenario's value
    noise = { x = "2 um" }               # optional sensor noise (standard deviation) per
                                         # quantity; default estimated from the record
                                         # (impact lists: t = "0.1 ms", others 5 % of the
                                         # median measured value)
    jacobian = "auto"                    # auto | exact | fd (central differences)
    global = "multistart"                # multistart | differential_evolution | none
    starts = 6                           # start points of the global stage
    events = true                        # impact-time residuals in the global stage
    profile = ["contact.track.restitution"]     # profile likelihoods of these keys
    profile_points = 9
    laws = ["hunt_crossley", "flores"]   # model selection across contact laws (track pair)
    seed = 1
    max_evaluations = 60                 # per local least-squares run (Jacobians count once)

Every bound and start is a number in SI or a string with units. Unknown keys and bad values
stop with one line naming the entry and what is allowed.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from braidsim.errors import InputError
from braidsim.fit.data import IMPACT_UNITS, QUANTITY_UNITS
from braidsim.params import SCHEMA, Scenario, load_scenario
from braidsim.specfile import check_choice, check_keys, closest_hint, expect_table, read_toml_file
from braidsim.units import to_si

#: every quantity a record or an impact list can give, with its SI unit
ALL_UNITS: dict[str, str] = {**QUANTITY_UNITS, "t": "s", **IMPACT_UNITS}

TOP_KEYS = ("scenario", "data", "overrides", "fit", "name", "description")
FIT_KEYS = (
    "free",
    "quantity",
    "start",
    "noise",
    "jacobian",
    "global",
    "starts",
    "events",
    "profile",
    "profile_points",
    "laws",
    "seed",
    "max_evaluations",
)
JACOBIANS = ("auto", "exact", "fd")
#: the free key of the record's time offset: the model's time of the record's t = 0 [s];
#: with several records it stands for one offset each, ``record[i].time_offset``
TIME_OFFSET = "record.time_offset"


def offset_key(record: int | None) -> str:
    """The free key of the time offset of record ``record`` (None: the one record's)."""
    return TIME_OFFSET if record is None else f"record[{record}].time_offset"


def is_offset(key: str) -> bool:
    """Whether ``key`` is a record's time offset (not a scenario key)."""
    return key == TIME_OFFSET or (key.startswith("record[") and key.endswith("].time_offset"))


def per_record_offsets(free: Sequence[FreeParameter], n: int) -> tuple[FreeParameter, ...]:
    """``free`` with :data:`TIME_OFFSET` replaced by one offset per record of ``n``, each
    with its bounds and start, in its place."""
    out: list[FreeParameter] = []
    for p in free:
        if p.key == TIME_OFFSET:
            out += [FreeParameter(offset_key(i), p.low, p.high, p.start, p.unit) for i in range(n)]
        else:
            out.append(p)
    return tuple(out)


def scenario_values(values: Mapping[str, Any]) -> dict[str, Any]:
    """``values`` without the records' time offsets, the free keys that are not a
    scenario's."""
    return {k: v for k, v in values.items() if not is_offset(k)}


GLOBALS = ("multistart", "differential_evolution", "none")
#: key prefixes of the solver's settings, which no fit may free (as the simulator's
#: sensitivities do not differentiate by them)
SOLVER_SETTINGS = ("simulation.",)


@dataclass(frozen=True)
class FreeParameter:
    """A free parameter: its key, bounds [SI] and the map to the unit box.

    Bounds whose ratio exceeds 10 (both positive) map logarithmically,
    ``u = ln(p / lo) / ln(hi / lo)``, others linearly, ``u = (p - lo) / (hi - lo)``: either
    way the fit works on u in [0, 1], which puts every parameter on the same scale (the
    least-squares trust region and the finite differences see comparable steps).
    """

    key: str
    low: float
    high: float
    start: float
    unit: str = ""

    @property
    def log(self) -> bool:
        return self.low > 0 and self.high / self.low > 10.0

    def to_unit(self, p: float) -> float:
        if self.log:
            return math.log(p / self.low) / math.log(self.high / self.low)
        return (p - self.low) / (self.high - self.low)

    def from_unit(self, u: float) -> float:
        u = min(max(float(u), 0.0), 1.0)
        if self.log:
            return self.low * (self.high / self.low) ** u
        return self.low + u * (self.high - self.low)

    def dp_du(self, u: float) -> float:
        """d p / d u at u [SI unit of the key]."""
        if self.log:
            return self.from_unit(u) * math.log(self.high / self.low)
        return self.high - self.low


@dataclass(frozen=True)
class FitSpec:
    """A validated fit spec (see the module docstring)."""

    scenario: Scenario
    free: tuple[FreeParameter, ...]
    quantities: tuple[str, ...]
    noise: Mapping[str, float] = field(default_factory=dict)
    #: whether the spec names the quantities (else ``x`` of a sampled record, every column of
    #: an impact list)
    quantity_given: bool = True
    jacobian: str = "auto"
    global_method: str = "multistart"
    starts: int = 6
    events: bool = True
    profile: tuple[str, ...] = ()
    profile_points: int = 9
    laws: tuple[str, ...] = ()
    seed: int = 1
    max_evaluations: int = 60
    data: Path | None = None
    #: several records: (path, scenario overrides) each; ``data`` is the first path
    datasets: tuple[tuple[Path, Mapping[str, Any]], ...] = ()
    path: Path | None = None
    scenario_ref: str = ""
    overrides: Mapping[str, Any] = field(default_factory=dict)
    name: str = "fit"

    @property
    def keys(self) -> tuple[str, ...]:
        return tuple(p.key for p in self.free)


def _int(where: str, value: Any, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise InputError(
            f"{where}: {value!r} is not allowed; allowed an integer from {low} to {high}"
        )
    return int(value)


def _choice(where: str, value: Any, allowed: tuple[str, ...]) -> str:
    if value not in allowed:
        raise InputError(f"{where}: {value!r} is not allowed; allowed {', '.join(allowed)}")
    return str(value)


def _numeric_key(where: str, key: Any) -> Any:
    if not isinstance(key, str) or key not in SCHEMA:
        hint = closest_hint(str(key), [*SCHEMA, TIME_OFFSET])
        raise InputError(f"{where}: unknown scenario key {key!r}{hint}")
    spec = SCHEMA[key]
    if key.startswith(SOLVER_SETTINGS):
        # (the runs' duration and sample times are the record's, and a tolerance or step
        # changes the model only by its error: the simulator's sensitivities refused them
        # in a line that began "sensitivity:")
        raise InputError(
            f"{where}: {key!r} is a setting of the solver, not a parameter of the model; "
            "allowed a numeric model key, e.g. contact.track.restitution, track.clearance"
        )
    if spec.kind != "float":
        raise InputError(
            f"{where}: {key!r} is not a numeric scenario key ({spec.kind}); allowed a key with "
            "one number, e.g. contact.track.restitution, track.clearance"
        )
    return spec


def free_parameters(
    free: Mapping[str, Any], sc: Scenario, start: Mapping[str, Any] | None = None
) -> tuple[FreeParameter, ...]:
    """Free parameters from ``{key: [low, high]}`` (numbers in SI or unit strings).

    The start is ``start[key]`` when given, else the scenario's value when it lies within the
    bounds, else the middle of the unit box.
    """
    if not free:
        raise InputError("fit.free: no free parameter; allowed a table {key = [low, high]}")
    out = []
    start = dict(start or {})
    for key, bounds in free.items():
        where = f"fit.free.{key}"
        offset = key == TIME_OFFSET
        spec = None if offset else _numeric_key("fit.free", key)
        unit = "s" if spec is None else spec.unit
        if not isinstance(bounds, list | tuple) or len(bounds) != 2:
            raise InputError(f"{where}: {bounds!r} is not allowed; allowed [low, high] with units")
        lo, hi = (to_si(where, b, unit) for b in bounds)
        if spec is not None:
            lo, hi = spec.check_number(lo), spec.check_number(hi)
        if not (math.isfinite(lo) and math.isfinite(hi)) or not lo < hi:
            raise InputError(f"{where}: [{lo:g}, {hi:g}] is not an interval; allowed low < high")
        fp = FreeParameter(key, lo, hi, math.nan, unit)
        if key in start:
            s = to_si(f"fit.start.{key}", start.pop(key), unit)
            if not lo <= s <= hi:
                raise InputError(
                    f"fit.start.{key}: {s:g} {unit} is out of range; allowed within the "
                    f"bounds [{lo:g}, {hi:g}] {unit}"
                )
        else:
            # (the offset starts at 0 where its bounds allow: the record taken as it is)
            v = 0.0 if offset else sc[key]
            s = float(v) if v is not None and lo <= v <= hi else fp.from_unit(0.5)
        out.append(FreeParameter(key, lo, hi, s, unit))
    if start:
        k = next(iter(start))
        raise InputError(f"fit.start.{k}: not a free parameter; allowed one of {', '.join(free)}")
    return tuple(out)


def _quantities(value: Any) -> tuple[str, ...]:
    names = [*QUANTITY_UNITS, *IMPACT_UNITS]
    items = [value] if isinstance(value, str) else value
    if not isinstance(items, list | tuple) or not items:
        raise InputError(
            f"fit.quantity: {value!r} is not allowed; allowed one or a list of {', '.join(names)}"
        )
    out = []
    for q in items:
        check_choice("fit.quantity", q, names)
        if q not in out:
            out.append(q)
    return tuple(out)


def _datasets(data: Any, base: Path | None) -> tuple[tuple[Path, Mapping[str, Any]], ...]:
    """The spec's ``data``: a path, or a list of paths and tables ``{path, overrides}``."""
    if data is None:
        return ()

    def path_of(where: str, v: Any) -> Path:
        if not isinstance(v, str) or not v:
            raise InputError(f"{where}: {v!r} is not allowed; allowed a path")
        return Path(v) if base is None or Path(v).is_absolute() else base / v

    if isinstance(data, str):
        return ((path_of("data", data), {}),)
    if not isinstance(data, list) or not data:
        raise InputError(
            f"data: {data!r} is not allowed; allowed a path or a list of paths and tables "
            "{path, overrides}"
        )
    out = []
    for i, item in enumerate(data):
        where = f"data[{i}]"
        if isinstance(item, Mapping):
            check_keys(f"{where}.", item, ("path", "overrides"))
            ov = dict(expect_table(f"{where}.overrides", item.get("overrides", {})))
            for key in ov:
                if key not in SCHEMA:
                    hint = closest_hint(str(key), list(SCHEMA))
                    raise InputError(f"{where}.overrides: unknown scenario key {key!r}{hint}")
            out.append((path_of(f"{where}.path", item.get("path")), ov))
        else:
            out.append((path_of(where, item), {}))
    return tuple(out)


def parse_fit_spec(
    table: Mapping[str, Any],
    path: Path | None = None,
    origin: str = "fit spec",
    scenario: Scenario | None = None,
) -> FitSpec:
    """Validate a fit spec table (see the module docstring); ``scenario`` (a loaded one)
    replaces the table's ``scenario`` key."""
    from braidsim.contact import law_names
    from braidsim.params import builtin_names

    if not isinstance(table, Mapping):  # (a list raised TypeError in check_keys)
        raise InputError(
            f"{origin}: table is a {type(table).__name__}, which is not allowed; allowed a "
            f"mapping of the keys {', '.join(TOP_KEYS)}"
        )
    check_keys("", table, TOP_KEYS)
    base = path.parent if path is not None else None
    overrides = dict(expect_table("overrides", table.get("overrides", {})))
    if scenario is not None:
        scen_ref = scenario.name
        sc = scenario.with_overrides(overrides) if overrides else scenario
    else:
        ref = table.get("scenario")
        if not isinstance(ref, str) or not ref:
            raise InputError(f"{origin}: scenario: missing; allowed a built-in name or a TOML path")
        scen_ref = ref
        if ref not in builtin_names():
            p = Path(ref)
            if base is not None and not p.is_absolute():
                p = base / p
            scen_ref = str(p.resolve()) if p.is_file() else ref
        sc = load_scenario(scen_ref, overrides=overrides or None)
    fit = expect_table("fit", table.get("fit", {}))
    check_keys("fit.", fit, FIT_KEYS)
    free = free_parameters(
        expect_table("fit.free", fit.get("free", {})),
        sc,
        expect_table("fit.start", fit.get("start", {})),
    )
    quantities = _quantities(fit.get("quantity", "x"))
    noise = {}
    for q, v in expect_table("fit.noise", fit.get("noise", {})).items():
        if q not in ALL_UNITS:
            raise InputError(f"fit.noise.{q}: unknown quantity; allowed {', '.join(ALL_UNITS)}")
        s = to_si(f"fit.noise.{q}", v, ALL_UNITS[q])
        if not (math.isfinite(s) and s > 0):
            raise InputError(f"fit.noise.{q}: {s:g} is out of range; allowed > 0 {ALL_UNITS[q]}")
        noise[q] = s
    profile = fit.get("profile", [])
    if isinstance(profile, str):
        profile = [profile]
    if not isinstance(profile, list):
        raise InputError(f"fit.profile: {profile!r} is not allowed; allowed a list of free keys")
    keys = [p.key for p in free]
    for k in profile:
        # (record[i].time_offset: one record's offset of several, checked against the
        # number of records where they are known, estimate.build_problem)
        per_record = isinstance(k, str) and is_offset(k) and k != TIME_OFFSET
        if k not in keys and not (per_record and TIME_OFFSET in keys):
            one = [f"{offset_key(0)}, ... (one record's of several)"] if TIME_OFFSET in keys else []
            raise InputError(
                f"fit.profile: {k!r} is not a free parameter; allowed one of "
                f"{', '.join(keys + one)}"
            )
    laws = fit.get("laws", [])
    if isinstance(laws, str):
        laws = [laws]
    if not isinstance(laws, list):
        raise InputError(f"fit.laws: {laws!r} is not allowed; allowed a list of contact laws")
    names = law_names()
    for law in laws:
        if law not in names:
            raise InputError(
                f"fit.laws: {law!r} is not a contact law{closest_hint(str(law), names)}; "
                f"allowed {', '.join(names)}"
            )
    events = fit.get("events", True)
    if not isinstance(events, bool):
        raise InputError(f"fit.events: {events!r} is not allowed; allowed true or false")
    datasets = _datasets(table.get("data"), base)
    data_path = datasets[0][0] if datasets else None
    return FitSpec(
        scenario=sc,
        free=free,
        quantities=quantities,
        noise=noise,
        quantity_given="quantity" in fit,
        jacobian=_choice("fit.jacobian", fit.get("jacobian", "auto"), JACOBIANS),
        global_method=_choice("fit.global", fit.get("global", "multistart"), GLOBALS),
        starts=_int("fit.starts", fit.get("starts", 6), 1, 1000),
        events=events,
        profile=tuple(dict.fromkeys(profile)),
        profile_points=_int("fit.profile_points", fit.get("profile_points", 9), 3, 101),
        laws=tuple(dict.fromkeys(laws)),
        seed=_int("fit.seed", fit.get("seed", 1), 0, 2**31 - 1),
        max_evaluations=_int("fit.max_evaluations", fit.get("max_evaluations", 60), 2, 100_000),
        data=data_path,
        datasets=datasets,
        path=path,
        scenario_ref=scen_ref,
        overrides=overrides,
        name=str(table.get("name", path.stem if path is not None else "fit")),
    )


def load_fit_spec(path: str | Path) -> FitSpec:
    """Read and validate a fit spec TOML file."""
    p = Path(path)
    return parse_fit_spec(read_toml_file(p, "fit spec"), p, str(p))
