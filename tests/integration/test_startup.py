"""What the start of the package and of the command line imports.

A warm ``braidsim run`` spends most of its CPU time importing; these tests keep the heavy
modules out of the paths that do not need them (each check runs in a fresh interpreter and
reads its ``sys.modules``). Times are measured by ``benchmarks/bench_startup.py``, not here.
"""

from __future__ import annotations

import json
import math
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from braidsim.cli import VERBS
from braidsim.errors import InputError

#: modules of outputs, plots and parallel runs: never needed to start or to run one simulation
HEAVY = ("matplotlib", "xarray", "zarr", "dask", "netCDF4", "h5netcdf", "rich.progress")


def _modules_after(code: str, *argv: str) -> set[str]:
    """The names in ``sys.modules`` when a fresh interpreter that ran ``code`` exits (read at
    exit, so that a command line ending in ``sys.exit`` is covered)."""
    prelude = (
        "import atexit, json, sys\n"
        "def _report(): sys.stderr.write('\\nMODULES ' + json.dumps(sorted(sys.modules)))\n"
        "atexit.register(_report)\n"
        f"sys.argv = ['braidsim', *{list(argv)!r}]\n"
    )
    line = _python(prelude + code).stderr.rsplit("MODULES ", 1)[-1]
    return set(json.loads(line))


def _python(code: str) -> subprocess.CompletedProcess[str]:
    """Run ``code`` in a fresh interpreter; fail with its error output if it fails."""
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=False
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc


def _loaded(modules: set[str], names: tuple[str, ...]) -> list[str]:
    return sorted(n for n in names if n in modules)


def test_import_braidsim_loads_no_dependency() -> None:
    """``import braidsim`` imports its exceptions only; the public names load on first use."""
    mods = _modules_after("import braidsim")
    heavy = (*HEAVY, "numba", "numpy", "pint", "pandas", "scipy", "typer")
    assert _loaded(mods, heavy) == []
    assert "braidsim.simulate" not in mods


def test_public_api_after_lazy_import() -> None:
    """The public names resolve to the objects of their modules; ``braidsim.simulate`` is the
    function even when its submodule is imported first."""
    code = (
        "import braidsim.simulate, braidsim.params, braidsim.result\n"
        "import braidsim\n"
        "assert callable(braidsim.simulate)\n"
        "assert braidsim.simulate is braidsim.simulate.__globals__['simulate']\n"
        "assert braidsim.load_scenario is braidsim.params.load_scenario\n"
        "assert braidsim.Result is braidsim.result.Result\n"
        "assert set(braidsim.__all__) <= set(dir(braidsim))\n"
        "for name in braidsim.__all__: getattr(braidsim, name)\n"
    )
    _modules_after(code)


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["--version"]])
def test_cli_start_loads_no_heavy_module(argv: list[str]) -> None:
    """Help and version load neither the compiled core nor any output library."""
    mods = _modules_after("from braidsim.cli import main\nmain()", *argv)
    heavy = (*HEAVY, "numba", "pint", "pandas", "scipy")
    assert _loaded(mods, heavy) == []


def test_cli_run_loads_no_output_module() -> None:
    """``braidsim run SCENARIO --json`` loads no plotting, storage or dask module, no other
    verb's module, and no pint: the units of the built-in scenarios are read without it (see
    the next test); nor the ``scipy.linalg`` package (numba's search for a BLAS finds the
    extension it wants loaded alone) or pydantic (which typer 0.29 imports)."""
    mods = _modules_after(
        "from braidsim.cli import main\nmain()", "run", "paper-3.3", "--duration", "0.01", "--json"
    )
    shunned = (*HEAVY, "scipy.integrate", "scipy.linalg", "pint", "pandas", "pydantic")
    assert _loaded(mods, shunned) == []
    assert "scipy.linalg.cython_blas" in mods
    assert "braidsim.cli.run" in mods
    others = {f"braidsim.cli.{m}" for m in VERBS.values()} - {"braidsim.cli.run"}
    assert sorted(others & mods) == []


def test_cython_blas_loaded_alone_serves_numba_and_scipy() -> None:
    """After the command line loads ``scipy.linalg.cython_blas`` on its own, numba's BLAS and
    LAPACK calls compile and give the right numbers, and ``scipy.linalg`` imports and works
    (its package then runs as usual, and the submodule is the one loaded)."""
    code = (
        "import sys\n"
        "import numpy as np\n"
        "from braidsim.startup import load_cython_blas_alone\n"
        "load_cython_blas_alone()\n"
        "blas = sys.modules['scipy.linalg.cython_blas']\n"
        "assert 'scipy.linalg' not in sys.modules\n"
        "assert 'dgemm' in blas.__pyx_capi__\n"
        "from numba import njit\n"
        "@njit(cache=False)\n"
        "def f(a, b):\n"
        "    return np.dot(a, a), np.linalg.solve(a, b)\n"
        "a = np.array([[2.0, 1.0], [1.0, 3.0]])\n"
        "p, x = f(a, np.array([1.0, 2.0]))\n"
        "assert np.array_equal(p, a @ a) and np.allclose(a @ x, [1.0, 2.0], rtol=0, atol=1e-15)\n"
        "import scipy.linalg\n"
        "import scipy.linalg.cython_blas as again\n"
        "assert again is blas\n"
        "w = np.sort(scipy.linalg.eigvalsh(a))\n"
        "assert np.allclose(w, [(5 - 5**0.5) / 2, (5 + 5**0.5) / 2], rtol=0, atol=1e-14)\n"
    )
    _modules_after(code)


_CACHED_MODULE = """
import numpy as np
from numba import njit

@njit(cache=True)
def ramp(n, x):  # allocates: needs numba's runtime
    return np.arange(n) * x + np.zeros(n)

@njit(cache=True)
def checked(x):
    if x < 0.0:
        raise ValueError("x must be >= 0")
    return np.sqrt(x)
"""


def test_cache_loads_without_refresh(tmp_path: Path) -> None:
    """With :func:`braidsim.startup.load_cached_functions_without_refresh`, functions come
    from numba's cache (no compile) without numba's registries, allocate, return arrays and
    raise their exceptions as compiled; a function not in the cache still compiles (numba's
    compiler loads the registries itself), and so does one that uses a registry the loads
    skipped (numpy's polynomials)."""
    folder = str(tmp_path)
    (tmp_path / "cached_mod.py").write_text(_CACHED_MODULE)
    env_code = f"import os, sys\nos.environ['NUMBA_CACHE_DIR'] = {folder + '/cache'!r}\n"
    env_code += f"sys.path.insert(0, {folder!r})\n"
    warm = "import cached_mod\ncached_mod.ramp(4, 0.5)\ncached_mod.checked(4.0)\n"
    _python(env_code + warm)  # fills the cache
    code = env_code + (
        "import numpy as np\n"
        "from braidsim.startup import load_cached_functions_without_refresh\n"
        "load_cached_functions_without_refresh()\n"
        "load_cached_functions_without_refresh()\n"
        "import numba.core.caching as caching\n"
        "assert caching.Cache.load_overload.braidsim_light\n"
        "import cached_mod\n"
        "r = cached_mod.ramp(5, 0.25)\n"
        "assert np.array_equal(r, [0.0, 0.25, 0.5, 0.75, 1.0])\n"
        "assert cached_mod.ramp.stats.cache_hits and not cached_mod.ramp.stats.cache_misses\n"
        "assert 'numba.np.polynomial.polynomial_functions' not in sys.modules\n"
        "assert cached_mod.checked(9.0) == 3.0\n"
        "try:\n"
        "    cached_mod.checked(-1.0)\n"
        "except ValueError as exc:\n"
        "    assert str(exc) == 'x must be >= 0'\n"
        "else:\n"
        "    raise AssertionError('no exception')\n"
        "from numba import njit\n"
        "@njit(cache=False)\n"
        "def roots(c):\n"
        "    return np.roots(c), np.polynomial.polynomial.polyval(2.0, c)\n"
        "z, v = roots(np.array([1.0, -3.0, 2.0]))\n"
        "assert np.allclose(np.sort(z.real), [1.0, 2.0], rtol=0, atol=1e-12) and v == 3.0\n"
    )
    _python(code)


_HELPER_MODULE = """
import numpy as np
from numba import njit
from braidsim.core.generic import helper, inline_helper

@helper
def scaled_sum(a, s):
    acc = 0.0
    for i in range(a.shape[0]):
        acc += s * a[i]
    return acc

@njit(cache=True)
def first(a):
    return scaled_sum(a, 2.0)

@njit(cache=True)
def second(a):
    return scaled_sum(a, 2.0) + 1.0

@helper(always_inline=True)
def scaled_sum_inlined(a, s):
    acc = 0.0
    for i in range(a.shape[0]):
        acc += s * a[i]
    return acc

@njit(cache=True)
def third(a):
    return scaled_sum_inlined(a, 2.0) + scaled_sum_inlined(a, 3.0)

@njit(cache=True)
def fourth(a):
    return scaled_sum_inlined(a, 4.0)

@inline_helper
def twin_sum(a, s):
    acc = 0.0
    for i in range(a.shape[0]):
        acc += s * a[i]
    return acc

@njit(cache=True)
def fifth(a):
    return twin_sum(a, 5.0)

def inlined_everywhere(helper, caller):
    # the helper's IR carries the attribute, and the caller's optimised code (its first
    # function: the caller itself) holds no call of it
    (cres,) = helper.overloads.values()
    ir = cres.library.get_llvm_str()
    assert "alwaysinline" in ir, ir
    (code,) = caller.inspect_llvm().values()
    assert "scaled_sum_inlined" not in code.split("define", 2)[1]
"""


def test_helpers_are_link_only_and_load_from_cache(tmp_path: Path) -> None:
    """A helper (:func:`braidsim.core.generic.helper`) is compiled to IR that its callers
    link, with no machine code of its own, and refuses calls from Python; numba's cache
    keeps that IR, from which a caller compiled in a later process links it (the helper is
    loaded from the cache, not compiled again) and computes the same. A helper marked
    ``always_inline`` carries LLVM's attribute in its IR, from the cache as well, and its
    caller holds no call of it."""
    folder = str(tmp_path)
    (tmp_path / "helper_mod.py").write_text(_HELPER_MODULE)
    env_code = f"import os, sys\nos.environ['NUMBA_CACHE_DIR'] = {folder + '/cache'!r}\n"
    env_code += f"sys.path.insert(0, {folder!r})\n"
    _python(
        env_code + "import numpy as np\n"
        "import helper_mod as m\n"
        "assert m.first(np.arange(4.0)) == 12.0\n"
        "assert m.third(np.arange(4.0)) == 30.0\n"
        "m.inlined_everywhere(m.scaled_sum_inlined, m.third)\n"
        "(cres,) = m.scaled_sum.overloads.values()\n"
        "assert type(cres.library).__name__ == '_LinkOnlyLibrary'\n"
        "assert m.scaled_sum.stats.cache_misses and not m.scaled_sum.stats.cache_hits\n"
        "try:\n"
        "    m.scaled_sum(np.arange(4.0), 2.0)\n"
        "except TypeError as exc:\n"
        "    assert 'compiled code only' in str(exc)\n"
        "else:\n"
        "    raise AssertionError('a helper called from Python')\n"
    )
    _python(
        env_code + "import numpy as np\n"
        "import helper_mod as m\n"
        "assert m.second(np.arange(4.0)) == 13.0\n"
        "assert m.scaled_sum.stats.cache_hits and not m.scaled_sum.stats.cache_misses\n"
        "assert m.fourth(np.arange(4.0)) == 24.0\n"
        "assert m.scaled_sum_inlined.stats.cache_hits\n"
        "assert not m.scaled_sum_inlined.stats.cache_misses\n"
        "m.inlined_everywhere(m.scaled_sum_inlined, m.fourth)\n"
        "(cres,) = m.scaled_sum.overloads.values()\n"
        "assert type(cres.library).__name__ == '_LinkOnlyLibrary'\n"
    )


def test_an_inline_helper_and_its_python_twin_cache_apart(tmp_path: Path) -> None:
    """An :func:`~braidsim.core.generic.inline_helper` is a link-only helper for compiled
    callers and an ordinary compiled function for calls from Python (its twin). numba names
    a function's cache files by the function alone and keys their entries by argument
    types, so the two of one signature would overwrite each other's entry and load the
    wrong kind; the link-only files are named apart. Both load from the cache in a later
    process, in either order, and compute the same."""
    folder = str(tmp_path)
    (tmp_path / "helper_mod.py").write_text(_HELPER_MODULE)
    env_code = f"import os, sys\nos.environ['NUMBA_CACHE_DIR'] = {folder + '/cache'!r}\n"
    env_code += f"sys.path.insert(0, {folder!r})\n"
    _python(
        env_code + "import numpy as np\n"
        "import helper_mod as m\n"
        "assert m.twin_sum(np.arange(4.0), 2.0) == 12.0\n"  # the twin first
        "assert m.fifth(np.arange(4.0)) == 30.0\n"
        "assert not m.twin_sum.stats.cache_hits and not m.fifth.stats.cache_hits\n"
        "m.inlined_everywhere(m.twin_sum, m.fifth)\n"
    )
    names = sorted(p.name for p in (tmp_path / "cache").rglob("*twin_sum*.nbi"))
    assert len(names) == 2 and sum(".link." in n for n in names) == 1, names
    _python(
        env_code + "import numpy as np\n"
        "import helper_mod as m\n"
        "assert m.fifth(np.arange(4.0)) == 30.0\n"  # the compiled caller first
        "assert m.twin_sum(np.arange(4.0), 2.0) == 12.0\n"
        "assert m.fifth.stats.cache_hits and not m.fifth.stats.cache_misses\n"
        "assert m.twin_sum._twin.stats.cache_hits and not m.twin_sum._twin.stats.cache_misses\n"
    )


def test_cli_run_loads_cached_functions_without_refresh(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The command line, a process of its own, loads the core's cached functions without
    numba's registries, and prints what the same command prints in a process that loads
    them (this one: ``main`` given its arguments tunes nothing)."""
    from braidsim.cli import main

    argv = ["run", "paper-3.3", "--duration", "0.05", "--json"]
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 0
    here = json.loads(capsys.readouterr().out)
    code = (
        "import atexit, numba.core.caching as caching\n"
        "atexit.register(lambda: sys.stderr.write('\\nLIGHT %s' % "
        "getattr(caching.Cache.load_overload, 'braidsim_light', False)))\n"
        "from braidsim.cli import main\nmain()\n"
    )
    prelude = f"import sys\nsys.argv = ['braidsim', *{argv!r}]\n"
    proc = _python(prelude + code)
    assert proc.stderr.rsplit("LIGHT ", 1)[-1].strip() == "True"
    there = json.loads(proc.stdout)
    for report in (here, there):
        report.pop("created")
    assert there == here


def test_jit_disabled_is_refused_in_one_line() -> None:
    """With numba's compiler switched off (``NUMBA_DISABLE_JIT=1``) a run says in one line
    that the solver needs it, and exits with 2."""
    proc = subprocess.run(
        [sys.executable, "-m", "braidsim", "run", "paper-3.3", "--duration", "1 ms"],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
        env={**os.environ, "NUMBA_DISABLE_JIT": "1"},
    )
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "NUMBA_DISABLE_JIT" in lines[0] and "allowed" in lines[0]
    assert "Traceback" not in proc.stderr


def test_verb_table_matches_registrations() -> None:
    """``braidsim.cli.VERBS`` names every registered verb with the module that registers it."""
    code = (
        "import json\n"
        "from braidsim.cli import VERBS, _register, app\n"
        "_register()\n"
        "found = {}\n"
        "for c in app.registered_commands:\n"
        "    name = c.name or c.callback.__name__.replace('_', '-')\n"
        "    found[name] = c.callback.__module__.rsplit('.', 1)[-1]\n"
        "assert found == VERBS, (found, VERBS)\n"
    )
    _modules_after(code)


def _bits(x: float) -> bytes:
    return struct.pack("<d", x)


def _read(units: object, text: str, target: str) -> tuple[str, bytes]:
    """The SI value of ``text`` as bits, or the error it raises (type and message)."""
    try:
        return "ok", _bits(units.parse_quantity("key", text, target)[0])  # type: ignore[attr-defined]
    except InputError as exc:
        return "InputError", str(exc).encode()


def test_units_without_pint_match_pint_bit_for_bit(monkeypatch: pytest.MonkeyPatch) -> None:
    """The table of common units in ``braidsim.units`` gives pint's values, bit for bit
    (finite, zero, signed, huge, tiny, infinite and NaN magnitudes; errors alike)."""
    from braidsim import units

    rng = np.random.default_rng(13)
    mags = [0.0, -0.0, 1.0, 0.12, 2.0, 60.0, 200.0, 5e-324, 1e-300, 1e300, math.inf, math.nan]
    mags += list(rng.lognormal(0.0, 8.0, 200)) + list(-rng.lognormal(0.0, 8.0, 50))
    cases = [*units._SI_FACTORS, *((f, "rad/s") for f in units._FREQUENCY_FACTORS)]
    assert len(cases) >= 8
    for unit_text, target in cases:
        texts = [f"{m!r} {unit_text}" for m in mags] + [f"{unit_text}", f"3/4 {unit_text}"]
        fast = [_read(units, t, target) for t in texts]
        with monkeypatch.context() as mp:
            mp.setattr(units, "_SI_FACTORS", {})
            mp.setattr(units, "_FREQUENCY_FACTORS", {})
            slow = [_read(units, t, target) for t in texts]
        assert fast == slow, (unit_text, target)
