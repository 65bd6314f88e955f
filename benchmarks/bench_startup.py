"""Start-up time of the command line: ``braidsim run paper-3.1 --json``, cold and warm.

Run: ``python benchmarks/bench_startup.py [--repeats 3] [--delete-installed-cache]``

* cold: the numba cache is empty, so every compiled function of the core is compiled (target
  < 10 s; the core measured 52 s of CPU with ``bench_core --part startup``);
* warm: the cache written by the cold run is reused; target < 2 s.

By default the cold run points ``NUMBA_CACHE_DIR`` at a new empty directory, so the cache
next to the installed package (``braidsim/core/**/__pycache__/*.nbi, *.nbc``) is neither
used nor touched (other processes may be using it); the warm runs reuse that directory. With
``--delete-installed-cache`` the ``*.nbi``/``*.nbc`` files under the installed package's
``__pycache__`` directories are deleted instead and the default cache location is used, which
is what a first run after ``pip install`` sees.

Each run is a fresh ``python -m braidsim.cli`` subprocess (the same as the ``braidsim`` script);
the time includes the interpreter start, the imports, the scenario, the 0.5 s simulation and
the JSON output. ``python -c "import braidsim"`` is timed as well, for reference.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import braidsim

COMMAND = [
    sys.executable,
    "-c",
    "from braidsim.cli import main; main()",
    "run",
    "paper-3.1",
    "--json",
]


def timed(cmd: list[str], env: dict[str, str]) -> float:
    """Wall time [s] of one subprocess; fails loudly if the command fails."""
    t0 = time.perf_counter()
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    dt = time.perf_counter() - t0
    if out.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({out.returncode}):\n{out.stderr}")
    if cmd is COMMAND:
        json.loads(out.stdout)  # the output must be one JSON object
    return dt


def delete_installed_cache() -> int:
    """Delete the numba cache files under the installed package; return how many."""
    root = Path(braidsim.__file__).parent
    n = 0
    for pattern in ("*.nbi", "*.nbc"):
        for f in root.rglob(f"__pycache__/{pattern}"):
            f.unlink()
            n += 1
    return n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3, help="warm runs (best is reported)")
    ap.add_argument(
        "--delete-installed-cache",
        action="store_true",
        help="delete the package's *.nbi/*.nbc files instead of using a private cache dir",
    )
    args = ap.parse_args()

    env = dict(os.environ)
    with tempfile.TemporaryDirectory(prefix="braidsim-numba-") as cache:
        if args.delete_installed_cache:
            env.pop("NUMBA_CACHE_DIR", None)
            n = delete_installed_cache()
            where = f"installed package cache ({n} files deleted)"
        else:
            env["NUMBA_CACHE_DIR"] = cache
            where = f"private NUMBA_CACHE_DIR {cache}"
        print(f"command: braidsim run paper-3.1 --json   (python {sys.version.split()[0]})")
        print(f"cache: {where}")
        cold = timed(COMMAND, env)
        warm = min(timed(COMMAND, env) for _ in range(max(1, args.repeats)))
        imp = min(
            timed([sys.executable, "-c", "import braidsim"], env)
            for _ in range(max(1, args.repeats))
        )
    print(f"cold (compile)  {cold:7.2f} s   target < 20 s   {'ok' if cold < 20 else 'MISSED'}")
    print(f"warm (cached)   {warm:7.2f} s   target <  2 s   {'ok' if warm < 2 else 'MISSED'}")
    print(f"import braidsim {imp:7.2f} s   (part of both)")


if __name__ == "__main__":
    main()
