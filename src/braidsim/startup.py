"""What a process that runs braidsim alone may do before it starts numba.

The command line calls :func:`load_cython_blas_alone` and sets :data:`LIGHT_CACHE_LOADS`
(``braidsim.cli.main``); the floor process of ``benchmarks/bench_startup.py`` does the same.
This module imports neither numba nor the ``scipy.linalg`` package.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import sys
from pathlib import Path
from typing import Any


def load_cython_blas_alone() -> None:
    """Load SciPy's ``scipy.linalg.cython_blas`` extension under its name without running the
    ``scipy.linalg`` package.

    numba probes for a BLAS when it loads its first function from the cache
    (``numba.np.arraymath`` imports ``scipy.linalg.cython_blas``), and importing that
    submodule runs the whole ``scipy.linalg`` package first, for a package a run never uses:
    a warm ``braidsim run paper-3.3 --json`` took 1.13 s of CPU with this and 1.42 s without
    (medians of 12 alternated runs, numba 0.68, SciPy 1.17). Found in
    ``sys.modules``, the extension is imported as it is, and numba's BLAS (``np.dot``) and
    LAPACK (which imports ``scipy.linalg`` itself) work as before; code that needs
    ``scipy.linalg`` imports it as usual, the package then lacking only the attribute
    ``cython_blas`` (the submodule itself stays importable). Nothing is done where SciPy's
    files are laid out otherwise, or where the extension is loaded already.
    """
    name = "scipy.linalg.cython_blas"
    if name in sys.modules or "scipy.linalg" in sys.modules:
        return
    try:
        scipy_spec = importlib.util.find_spec("scipy")
        if scipy_spec is None or scipy_spec.origin is None:
            return
        folder = Path(scipy_spec.origin).parent / "linalg"
        suffixes = tuple(importlib.machinery.EXTENSION_SUFFIXES)
        path = next(p for p in sorted(folder.glob("cython_blas.*")) if p.name.endswith(suffixes))
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None:
            return
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    except Exception:  # (StopIteration included: no such file) the ordinary import then
        return
    sys.modules[name] = module


#: Set by a process that runs braidsim alone (the command line) before it imports the core:
#: ``braidsim.core`` then calls :func:`load_cached_functions_without_refresh` once numba is
#: imported.
LIGHT_CACHE_LOADS = False


def load_cached_functions_without_refresh() -> None:
    """Make numba load a function from its disk cache without first loading every one of
    its registries.

    Before it reads a cached function, numba refreshes its target context
    (``numba.core.caching.Cache.load_overload``): it imports and installs all its
    implementation and typing registries (arrays, lists, dicts, sets, random, polynomials,
    linear algebra, datetimes, jitclasses, third-party extensions), which only a *compile*
    needs, and starts its reference-counting runtime, which the loaded machine code calls.
    Here a cache load starts the runtime only; the first compile in the process, if any,
    still refreshes the contexts itself (numba's compiler does so before every compile). In a
    warm ``braidsim run paper-3.3 --json`` the command line's ``main()`` took 0.28-0.37 s of
    CPU instead of 0.48-0.54 s (five alternated pairs, numba 0.68), with the same output.

    This relies on numba's ``Cache._load_overload`` and ``_guard_against_spurious_io_errors``
    and on ``numba.core.runtime.nrt.rtsys`` as numba 0.68 defines them; with a numba that
    lacks them nothing is changed. Calling it twice changes nothing more.
    """
    import inspect

    from numba.core import caching
    from numba.core.runtime import nrt

    cache = caching.Cache
    needed = ("_load_overload", "_guard_against_spurious_io_errors", "load_overload")
    if not all(hasattr(cache, name) for name in needed) or not hasattr(nrt, "rtsys"):
        return
    if getattr(cache.load_overload, "braidsim_light", False):
        return
    if list(inspect.signature(cache.load_overload).parameters) != ["self", "sig", "target_context"]:
        return  # a numba whose cache loads differ from what this replaces

    def load_overload(self: Any, sig: Any, target_context: Any) -> Any:
        nrt.rtsys.initialize(target_context)  # what the loaded code needs of the refresh
        with self._guard_against_spurious_io_errors():
            return self._load_overload(sig, target_context)
        return None  # the guard swallowed an I/O error: compile instead, as numba does

    load_overload.braidsim_light = True  # type: ignore[attr-defined]
    load_overload.__doc__ = cache.load_overload.__doc__
    cache.load_overload = load_overload  # type: ignore[method-assign]
