"""The paper's reported numbers (``paper_values.toml``) as validated, frozen objects.

:func:`load_paper_values` reads the package's data file (or another file of the same shape)
and checks it: unique ids, known quantities, statistics and units, every item pointing at an
existing run and window, windows inside the run, printed zeros carrying an absolute
tolerance. Nothing here simulates; :mod:`braidsim.paper.compute` does.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from braidsim.errors import InputError

#: quantities of the paper and the kernel's range names (Result.ranges_dict keys)
QUANTITIES = ("contact_force", "stiffness_force", "damping_force", "depth")
#: symbol of each quantity as the paper writes it
SYMBOLS = {
    "contact_force": "F_g",
    "stiffness_force": "F_kg",
    "damping_force": "F_cg",
    "depth": "delta_x",
}
STATISTICS = ("min", "max", "rest", "absmax")
#: paper unit -> (SI unit, SI value of one paper unit)
UNITS = {"N": ("N", 1.0), "mm": ("m", 1e-3)}
#: SI unit of each quantity
SI_UNIT = {"contact_force": "N", "stiffness_force": "N", "damping_force": "N", "depth": "m"}


@dataclass(frozen=True)
class RunSpec:
    """One simulation behind a group of paper numbers.

    Attributes
    ----------
    key : str
        Name used by the items (``"3.1"``, ``"T1.hunt_crossley"``).
    scenario : str
        Built-in scenario, calibrated preset (E = 200 GPa).
    printed : str
        Built-in scenario with the printed E = 2 GPa, or "" to apply it as an override.
    section, title : str
        Paper section and a short description.
    duration : float
        Simulated time [s].
    windows : dict[str, tuple[float, float]]
        Named windows [s].
    figures : dict[str, int]
        Paper figure number of each plotted quantity (``x``, ``stiffness_force``, ...).
    """

    key: str
    scenario: str
    printed: str
    section: str
    title: str
    duration: float
    windows: dict[str, tuple[float, float]]
    figures: dict[str, int]

    @property
    def is_table1(self) -> bool:
        """True for a Table 1 row."""
        return self.key.startswith("T1.")

    @property
    def law(self) -> str:
        """Contact law of a Table 1 row (registry name)."""
        return self.key.split(".", 1)[1] if self.is_table1 else "hunt_crossley"


@dataclass(frozen=True)
class PaperItem:
    """One number printed in sections 3.1-3.5.

    ``value`` is as printed, in ``unit`` (N or mm); :attr:`si_value` converts it.
    """

    id: str
    section: str
    where: str
    quantity: str
    statistic: str
    value: float
    unit: str
    run: str
    window: str
    text: str
    tolerance: float
    abs_tol: float | None

    @property
    def si_unit(self) -> str:
        """SI unit of the quantity (N or m)."""
        return UNITS[self.unit][0]

    @property
    def scale(self) -> float:
        """SI value of one paper unit (1 for N, 1e-3 for mm)."""
        return UNITS[self.unit][1]

    @property
    def si_value(self) -> float:
        """The printed value in SI."""
        return self.value * self.scale

    @property
    def symbol(self) -> str:
        """The paper's symbol of the quantity."""
        return SYMBOLS[self.quantity]


@dataclass(frozen=True)
class PaperInput:
    """A parameter value the paper states, and the runs it applies to."""

    key: str
    value: str
    runs: tuple[str, ...]
    variant: str
    text: str


@dataclass(frozen=True)
class PaperValues:
    """Everything in ``paper_values.toml``."""

    meta: dict[str, Any]
    runs: dict[str, RunSpec]
    items: tuple[PaperItem, ...]
    inputs: tuple[PaperInput, ...]

    def item(self, item_id: str) -> PaperItem:
        """The item called ``item_id``."""
        for it in self.items:
            if it.id == item_id:
                return it
        raise KeyError(item_id)

    def items_of(self, run: str) -> list[PaperItem]:
        """The items of one run, in file order."""
        return [it for it in self.items if it.run == run]


def default_path() -> Path:
    """Path of the package's ``paper_values.toml``."""
    return Path(str(resources.files("braidsim.paper") / "paper_values.toml"))


def _window(run: str, name: str, w: Any, duration: float) -> tuple[float, float]:
    if not (isinstance(w, list) and len(w) == 2 and all(isinstance(v, (int, float)) for v in w)):
        raise InputError(
            f"paper values: run {run} window {name}: expected [t0, t1] in s, got {w!r}"
        )
    t0, t1 = float(w[0]), float(w[1])
    if not (0.0 <= t0 < t1 <= duration + 1e-12):
        raise InputError(
            f"paper values: run {run} window {name} = [{t0}, {t1}] s; allowed 0 <= t0 < t1 <= "
            f"{duration} s"
        )
    return (t0, t1)


def _require(table: dict[str, Any], key: str, kind: type | tuple[type, ...], where: str) -> Any:
    if key not in table:
        raise InputError(f"paper values: {where}: missing {key!r}")
    v = table[key]
    if not isinstance(v, kind) or isinstance(v, bool):
        raise InputError(f"paper values: {where}: {key} = {v!r} has the wrong type")
    return v


def parse_paper_values(data: dict[str, Any]) -> PaperValues:
    """Validate the parsed TOML and build :class:`PaperValues`.

    Raises
    ------
    InputError
        Naming the entry and what is wrong with it.
    """
    meta = dict(data.get("meta", {}))
    tol_default = float(meta.get("tolerance", 0.05))
    runs: dict[str, RunSpec] = {}
    for key, r in data.get("runs", {}).items():
        where = f"run {key}"
        duration = float(_require(r, "duration", (int, float), where))
        if not (math.isfinite(duration) and duration > 0):
            raise InputError(f"paper values: {where}: duration {duration} s; allowed > 0 s")
        windows = {
            name: _window(key, name, w, duration)
            for name, w in _require(r, "windows", dict, where).items()
        }
        figures = {str(q): int(n) for q, n in r.get("figures", {}).items()}
        for q in figures:
            if q not in ("x", *QUANTITIES):
                raise InputError(f"paper values: {where}: unknown figure quantity {q!r}")
        runs[key] = RunSpec(
            key=key,
            scenario=str(_require(r, "scenario", str, where)),
            printed=str(r.get("printed", "")),
            section=str(_require(r, "section", str, where)),
            title=str(r.get("title", "")),
            duration=duration,
            windows=windows,
            figures=figures,
        )
    items: list[PaperItem] = []
    seen: set[str] = set()
    for raw in data.get("items", []):
        iid = str(_require(raw, "id", str, "item"))
        where = f"item {iid}"
        if iid in seen:
            raise InputError(f"paper values: {where}: duplicate id")
        seen.add(iid)
        quantity = _require(raw, "quantity", str, where)
        statistic = _require(raw, "statistic", str, where)
        unit = _require(raw, "unit", str, where)
        run = _require(raw, "run", str, where)
        window = _require(raw, "window", str, where)
        if quantity not in QUANTITIES:
            raise InputError(
                f"paper values: {where}: quantity {quantity!r}; allowed {', '.join(QUANTITIES)}"
            )
        if statistic not in STATISTICS:
            raise InputError(
                f"paper values: {where}: statistic {statistic!r}; allowed {', '.join(STATISTICS)}"
            )
        if unit not in UNITS or UNITS[unit][0] != SI_UNIT[quantity]:
            raise InputError(f"paper values: {where}: unit {unit!r} does not fit {quantity}")
        if run not in runs:
            raise InputError(f"paper values: {where}: unknown run {run!r}")
        if window not in runs[run].windows:
            raise InputError(f"paper values: {where}: run {run} has no window {window!r}")
        value = float(_require(raw, "value", (int, float), where))
        abs_tol = raw.get("abs_tol")
        if value == 0.0 and abs_tol is None:
            raise InputError(f"paper values: {where}: a printed zero needs abs_tol")
        tol = float(raw.get("tolerance", tol_default))
        if not 0.0 < tol < 1.0:
            raise InputError(f"paper values: {where}: tolerance {tol}; allowed 0 < tolerance < 1")
        items.append(
            PaperItem(
                id=iid,
                section=str(_require(raw, "section", str, where)),
                where=str(_require(raw, "where", str, where)),
                quantity=quantity,
                statistic=statistic,
                value=value,
                unit=unit,
                run=run,
                window=window,
                text=str(_require(raw, "text", str, where)),
                tolerance=tol,
                abs_tol=None if abs_tol is None else float(abs_tol),
            )
        )
    inputs = []
    for raw in data.get("inputs", []):
        where = f"input {raw.get('key', '?')}"
        runs_of = tuple(str(r) for r in _require(raw, "runs", list, where))
        for r in runs_of:
            if r not in runs:
                raise InputError(f"paper values: {where}: unknown run {r!r}")
        inputs.append(
            PaperInput(
                key=str(_require(raw, "key", str, where)),
                value=str(_require(raw, "value", str, where)),
                runs=runs_of,
                variant=str(raw.get("variant", "calibrated")),
                text=str(raw.get("text", "")),
            )
        )
    return PaperValues(meta, runs, tuple(items), tuple(inputs))


def load_paper_values(path: str | Path | None = None) -> PaperValues:
    """Read and validate ``paper_values.toml`` (the package's own by default)."""
    p = default_path() if path is None else Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"paper values: {p}: malformed TOML ({exc})") from None
    except OSError as exc:
        raise InputError(f"paper values: cannot read {p} ({exc.strerror})") from None
    return parse_paper_values(data)
