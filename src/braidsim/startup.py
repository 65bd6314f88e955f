"""What a process that runs braidsim alone may do before it starts numba.

The command line calls :func:`load_cython_blas_alone` (``braidsim.cli.main``), and so does the
floor process of ``benchmarks/bench_startup.py``. This module imports neither numba nor
the ``scipy.linalg`` package.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import sys
from pathlib import Path


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
