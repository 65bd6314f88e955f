"""The ``braidsim`` command line: a thin layer over the public API.

Each verb lives in its own module and registers itself on :data:`app`; this file only wires
them together and maps errors to exit codes (2 bad input, 1 numerical failure). Only the
module of the verb invoked is imported (all of them for ``--help``, ``--version`` or an
unknown verb), so that a command pays for no other verb's imports.
"""

from __future__ import annotations

import importlib
import sys

from braidsim.cli.common import app

#: verb -> the module that registers it (checked against the registrations by the tests)
VERBS = {
    "run": "run",
    "impact": "run",
    "models": "run",
    "scenarios": "run",
    "restitution": "analysis",
    "bifurcation": "analysis",
    "basins": "analysis",
    "lyapunov": "analysis",
    "analyze": "analysis",
    "design": "design",
    "machine": "machine",
    "paper": "paper",
    "sweep": "sweep",
    "sweep-plot": "sweep",
}


def _register(verb: str | None = None) -> None:
    """Import the module of ``verb`` (which registers its commands on `app`), or every verb
    module when ``verb`` is None or unknown."""
    names = [VERBS[verb]] if verb in VERBS else sorted(set(VERBS.values()))
    for name in names:
        importlib.import_module(f"braidsim.cli.{name}")


def _verb(argv: list[str]) -> str | None:
    """The verb of a command line: its first word that is not an option (the root options,
    ``--version`` and ``--help``, take no value)."""
    return next((a for a in argv if not a.startswith("-")), None)


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``braidsim`` command."""
    from braidsim import units
    from braidsim.cli.common import run_app

    if argv is None:
        # the process runs the command line alone and holds no dask array with units, so
        # pint need not import dask (see braidsim.units); a caller's process is left as is
        units.PINT_WITH_DASK = False
    _register(_verb(sys.argv[1:] if argv is None else argv))
    sys.exit(run_app(argv))


__all__ = ["VERBS", "app", "main"]
