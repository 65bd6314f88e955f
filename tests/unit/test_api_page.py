"""docs/api.md documents every public name: each name in the ``__all__`` of braidsim and of
its public subpackages is reached by one of the page's ``::: target`` directives.

A directive with a ``members:`` list reaches those members; one without reaches the target
module's ``__all__`` (mkdocstrings renders those as the module's public names). A name that
is also a submodule (``braidsim.analysis.basins``, a function and a module) or is itself a
module (``braidsim.core.layout``) is rendered only by a directive of its own, so the page
must have one.
"""

from __future__ import annotations

import importlib
import importlib.util
import re
import types

from helpers_commands import REPO

PACKAGES = (
    "braidsim",
    "braidsim.analysis",
    "braidsim.continuation",
    "braidsim.core",
    "braidsim.design",
    "braidsim.fit",
    "braidsim.machine",
    "braidsim.sweep",
)


def _directives(text: str) -> dict[str, list[str] | None]:
    """``{target: members or None}`` of the page's ``::: target`` blocks."""
    out: dict[str, list[str] | None] = {}
    for target, options in re.findall(r"^::: (\S+)\n((?:    .*\n|\n)*)", text, re.M):
        members = re.findall(r"^        - (\S+)$", options, re.M)
        out[target] = members or None
    return out


def _reached(directives: dict[str, list[str] | None]) -> set[str]:
    reached: set[str] = set()
    for target, members in directives.items():
        reached.add(target)
        if members is not None:
            reached |= {f"{target}.{m}" for m in members}
            continue
        try:
            module = importlib.import_module(target)
        except ImportError:  # a function or class: reached itself only
            continue
        names = getattr(module, "__all__", None)
        if names is None:
            names = [n for n in vars(module) if not n.startswith("_")]
        reached |= {f"{target}.{n}" for n in names}
    return reached


def _needs_own_directive(package: str, name: str, obj: object) -> bool:
    if isinstance(obj, types.ModuleType):
        return True
    return importlib.util.find_spec(f"{package}.{name}") is not None


def _reached_elsewhere(reached: set[str], name: str, obj: object) -> bool:
    """A value without a ``__module__`` (a dict, a tuple) documented where it is defined."""
    for path in reached:
        parent, _, last = path.rpartition(".")
        if last != name or not parent:
            continue
        try:
            if getattr(importlib.import_module(parent), name, None) is obj:
                return True
        except ImportError:
            continue
    return False


def test_every_public_name_is_on_the_api_page() -> None:
    directives = _directives((REPO / "docs" / "api.md").read_text())
    reached = _reached(directives)
    missing = []
    for package in PACKAGES:
        module = importlib.import_module(package)
        for name in module.__all__:
            if name.startswith("__"):
                continue
            obj = getattr(module, name)
            home = getattr(obj, "__module__", None)
            if isinstance(obj, types.ModuleType):
                home = obj.__name__.rsplit(".", 1)[0]
            paths = {f"{package}.{name}"} | ({f"{home}.{name}"} if home else set())
            if _needs_own_directive(package, name, obj):
                ok = bool(paths & set(directives))
            else:
                ok = bool(paths & reached) or _reached_elsewhere(reached, name, obj)
            if not ok:
                missing.append(f"{package}.{name}")
    assert not missing, f"docs/api.md does not document: {', '.join(missing)}"


def test_the_check_sees_a_missing_name() -> None:
    # the page without its machine directive leaves the machine's names out
    text = (REPO / "docs" / "api.md").read_text().replace("::: braidsim.machine\n", "")
    assert "braidsim.machine.run_machine" not in _reached(_directives(text))
