"""The ``braidsim`` command line: a thin layer over the public API.

Each verb lives in its own module and registers itself on :data:`app`; this file only wires
them together and maps errors to exit codes (2 bad input, 1 numerical failure). Only the
module of the verb invoked is imported (all of them for ``--help``, ``--version`` or an
unknown verb), so that a command pays for no other verb's imports.
"""

from __future__ import annotations

import gc
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
    "continue": "continue_",
    "design": "design",
    "fit": "fit",
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
    """Entry point of the ``braidsim`` command (``argv``: the arguments after the command's
    name; by default those of the process)."""
    from braidsim import startup, units
    from braidsim.cli.common import ClosedStream, run_app

    if sys.stdout is None:  # started with stdout closed (``>&-``)
        sys.stdout = ClosedStream("stdout")

    own_process = argv is None
    args = sys.argv[1:] if argv is None else argv
    verb = _verb(args)
    if own_process:
        # The process runs the command line alone, so it may tune the process:
        # - pint need not import dask (see braidsim.units): no dask array here carries units;
        # - the cyclic garbage collector runs every 50,000 allocations instead of 700:
        #   starting numba makes about a million long-lived objects, which the default
        #   schedule scans again and again (~0.1 s of a warm run; a compile from an empty
        #   cache peaks ~4 % higher in memory and takes no longer).
        units.PINT_WITH_DASK = False
        gc.set_threshold(50_000, 20, 20)
        # - numba's search for a BLAS need not import scipy.linalg (see braidsim.startup; not
        #   for help or the version, which load no numba and no scipy)
        if verb in VERBS and "--help" not in args and "--version" not in args:
            startup.load_cython_blas_alone()
        # - a function loaded from numba's cache need not wait for numba's registries, which
        #   only a compile uses (see braidsim.startup; applied when the core is imported)
        startup.LIGHT_CACHE_LOADS = True
    _register(verb)
    code = run_app(argv)
    if own_process:
        # the process ends here: spare the interpreter's shutdown the collections over all
        # those objects (~0.2 s); exit handlers still run, and streams are flushed
        gc.freeze()
    sys.exit(code)


__all__ = ["VERBS", "app", "main"]
