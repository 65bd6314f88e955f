"""numba's disk cache and the core's sources: a compiled function of the core holds the code
of the implementations it calls, from other files; an edit of one of them must reach the
next run instead of the cached machine code compiled before it."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

# a generic function, a record class and a cached caller, in one module; the record's
# implementation in another, as an extension of the core would be written
CALLER = '''
from typing import NamedTuple

from braidsim.core.generic import generic, {decorator}


class Scaled(NamedTuple):
    k: float


@generic
def scaled(rec, x):
    """rec.k times x, times the implementation's constant."""
    raise NotImplementedError


import impl  # noqa: E402  (registers the implementation of Scaled)


@{decorator}(error_model="numpy")
def caller(rec, x):
    return scaled(rec, x) + 1.0


print(caller(Scaled(1.5), 2.0))
'''
IMPL = """
from caller import Scaled, scaled


@scaled.register(Scaled)
def _scaled(rec, x):
    return rec.k * x * {factor}
"""


def _run(folder: Path, cache: Path) -> str:
    env = dict(
        os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=f"{folder}{os.pathsep}{ROOT / 'src'}"
    )
    out = subprocess.run(
        [sys.executable, "-c", "import runpy; runpy.run_path('caller.py', run_name='caller')"],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    return out.stdout.strip().splitlines()[-1]


def test_an_edit_of_an_implementation_in_another_file_reaches_the_cached_caller(
    tmp_path: Path,
) -> None:
    """The caller compiled and cached with the implementation's factor 2, then the factor
    changed to 3 in its own file: the next process computes with 3 (with numba's own cache,
    ``njit(cache=True)``, it loaded the caller compiled with 2 and printed 4.0 again), and
    with the factor back to 2 it finds the first compile again (the key is the content)."""
    (tmp_path / "caller.py").write_text(textwrap.dedent(CALLER.format(decorator="cached_njit")))
    impl = tmp_path / "impl.py"
    cache = tmp_path / "cache"
    impl.write_text(IMPL.format(factor="2.0"))
    assert _run(tmp_path, cache) == "7.0"
    assert _run(tmp_path, cache) == "7.0"  # loaded from the cache
    impl.write_text(IMPL.format(factor="3.0"))
    assert _run(tmp_path, cache) == "10.0"
    impl.write_text(IMPL.format(factor="2.0"))
    assert _run(tmp_path, cache) == "7.0"


def test_the_digest_covers_the_records_inside_a_model() -> None:
    """The carrier's record holds its laws, friction and excitation as records: their
    classes are found inside its numba type, so their files are in the digest."""
    from numba import typeof

    import braidsim
    from braidsim.core.generic import _record_classes
    from braidsim.model import build_model

    record = build_model(braidsim.load_scenario("paper-3.3")).record
    classes = _record_classes([typeof(record)], set())
    inner = {type(getattr(record, f)) for f in ("track_law", "friction", "track", "horn_gear")}
    assert {type(record)} | inner <= classes
