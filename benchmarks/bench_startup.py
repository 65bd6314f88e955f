"""Start-up cost of the command line: ``braidsim run paper-3.3 --json``, cold and warm.

Run: ``python benchmarks/bench_startup.py [--scenario paper-3.3] [--repeats 5] [--no-cold]
[--delete-installed-cache]``

* cold: the numba cache is empty, so every compiled function of the core is compiled
  (target < 10 s of CPU);
* warm: the cache written by the cold run is reused (target < 1 s of CPU). The 0.5 s
  simulation itself takes a few milliseconds: the rest is the interpreter, the imports, the
  unit registry and numba's loading of the cached functions.

Every figure is the CPU time (user + system, from ``getrusage(RUSAGE_CHILDREN)``) of a fresh
child process that runs what the ``braidsim`` script runs (``python -c "from braidsim.cli import
main; main()"``); the warm runs are interleaved with a *floor* child that does what any program
using numba's cache must do and nothing else: import numpy and numba and make the first call of
one cached ``@njit`` function, spared what the command line spares: the ``scipy.linalg``
package in numba's search for a BLAS (:func:`braidsim.startup.load_cython_blas_alone`) and
numba's registries at a cache load
(:func:`braidsim.startup.load_cached_functions_without_refresh`). ``warm / floor`` is
printed beside the absolute figures, which drift with the load of the machine. Then one warm
run is taken apart: CPU time of its phases (measured in the child with ``time.process_time``)
and the import time of each top-level package (the self times of its modules under
``python -X importtime``, wall-clock time as Python reports it).

By default the cold run points ``NUMBA_CACHE_DIR`` at a new empty directory, so the cache
next to the installed package (``braidsim/core/**/__pycache__/*.nbi, *.nbc``) is neither
used nor touched; the warm runs reuse that directory. With ``--delete-installed-cache`` the
``*.nbi``/``*.nbc`` files under the installed package's ``__pycache__`` directories are
deleted instead and the default cache location is used, which is what a first run after
``pip install`` sees. With ``--no-cold`` the warm runs use the cache as it is (run the command
once first if it is empty).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import braidsim

CLI = "from braidsim.cli import main; main()"

#: what any program that loads a function from numba's cache pays (the floor)
FLOOR = textwrap.dedent(
    """
    import sys
    sys.path.insert(0, sys.argv[1])
    from braidsim import startup
    startup.load_cython_blas_alone()  # as the command line does: numba's BLAS probe alone
    import numpy, numba
    startup.load_cached_functions_without_refresh()  # as the command line does
    import startup_floor_mod
    startup_floor_mod.f(1.0)
    """
)
FLOOR_MODULE = textwrap.dedent(
    """
    import numba

    @numba.njit(cache=True)
    def f(x):
        return x + 1.0
    """
)

#: the CLI with CPU-time probes around its phases (printed as JSON on stderr at exit)
PHASES = textwrap.dedent(
    """
    import time
    pt = time.process_time
    T = {"interpreter start": pt()}
    import atexit, functools, json, sys

    def mark(name, t0):
        T[name] = T.get(name, 0.0) + pt() - t0

    def wrap(owner, attr, name):
        f = getattr(owner, attr)

        @functools.wraps(f)
        def g(*a, **k):
            t0 = pt()
            try:
                return f(*a, **k)
            finally:
                mark(name, t0)

        setattr(owner, attr, g)

    t0 = pt(); import numpy; mark("import numpy", t0)
    t0 = pt(); import numba; mark("import numba", t0)
    t0 = pt()
    import braidsim, braidsim.cli, braidsim.cli.run, braidsim.startup
    braidsim.startup.LIGHT_CACHE_LOADS = True  # as braidsim.cli.main sets it
    mark("import braidsim.cli and the run verb", t0)
    t0 = pt()
    import braidsim.params, braidsim.result, braidsim.simulate, braidsim.units
    mark("import params, result, simulate (the core)", t0)
    wrap(braidsim.units, "registry", "  pint import + unit registry")
    wrap(braidsim, "load_scenario", "load_scenario (includes the line above)")
    wrap(braidsim, "simulate", "simulate (numba loads the cached functions)")
    wrap(braidsim.result.Result, "summary", "Result.summary (pandas import)")
    T0 = pt()

    def report():
        T["rest: typer parsing, JSON, exit"] = pt() - T0 - sum(
            v for k, v in T.items() if k.startswith(("load_", "simulate", "Result"))
        )
        T["total"] = pt()
        sys.stderr.write("PHASES " + json.dumps(T) + "\\n")

    atexit.register(report)
    sys.argv = ["braidsim", *sys.argv[1:]]
    braidsim.cli.main()
    """
)


def child(cmd: list[str], env: dict[str, str]) -> tuple[float, float, str, str]:
    """CPU time [s] (user + system of the child, the change of ``RUSAGE_CHILDREN`` over
    its run: one child at a time), wall time [s], stdout and stderr of one subprocess;
    fails loudly if the command fails."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return cpu, wall, proc.stdout, proc.stderr


def run_cli(args: list[str], env: dict[str, str]) -> tuple[float, float]:
    """CPU and wall time of one ``braidsim`` command; its output must be one JSON object."""
    cpu, wall, out, _ = child([sys.executable, "-c", CLI, *args], env)
    json.loads(out)
    return cpu, wall


def import_table(args: list[str], env: dict[str, str], top: int = 14) -> list[tuple[str, float]]:
    """Import time [s] of each top-level package in one warm run: the sum of the *self*
    times of its modules (``-X importtime``), so that a package is not charged for what it
    imports from other packages."""
    _, _, _, err = child([sys.executable, "-X", "importtime", "-c", CLI, *args], env)
    per_root: dict[str, float] = {}
    for line in err.splitlines():
        m = re.match(r"import time:\s+(\d+) \|\s+\d+ \|\s*(\S+)", line)
        if m:
            root = m.group(2).split(".")[0]
            per_root[root] = per_root.get(root, 0.0) + int(m.group(1)) * 1e-6
    return sorted(per_root.items(), key=lambda kv: -kv[1])[:top]


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
    ap.add_argument("--scenario", default="paper-3.3", help="built-in scenario to run")
    ap.add_argument("--repeats", type=int, default=5, help="warm runs and floor runs (median)")
    ap.add_argument("--no-cold", action="store_true", help="skip the cold run")
    ap.add_argument(
        "--delete-installed-cache",
        action="store_true",
        help="delete the package's *.nbi/*.nbc files instead of using a private cache dir",
    )
    args = ap.parse_args()
    cli_args = ["run", args.scenario, "--duration", "0.5", "--json"]

    env = dict(os.environ)
    # the children cache their bytecode as an installed package has it (pip writes the .pyc
    # files when it installs): with PYTHONDONTWRITEBYTECODE set, as in this development
    # machine's shells, every run of an editable install compiled braidsim's sources again,
    # 0.1-0.15 s of CPU that no installed copy pays
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    with (
        tempfile.TemporaryDirectory(prefix="braidsim-numba-") as cache,
        tempfile.TemporaryDirectory(prefix="braidsim-floor-") as floor_dir,
    ):
        if args.delete_installed_cache:
            env.pop("NUMBA_CACHE_DIR", None)
            n = delete_installed_cache()
            where = f"installed package cache ({n} files deleted)"
        elif args.no_cold:
            where = f"as it is ({env.get('NUMBA_CACHE_DIR', 'next to the installed package')})"
        else:
            env["NUMBA_CACHE_DIR"] = cache
            where = f"private NUMBA_CACHE_DIR {cache}"
        print(f"command: braidsim {' '.join(cli_args)}   (python {sys.version.split()[0]})")
        print(f"numba cache: {where}")
        if not args.no_cold:
            cpu, wall = run_cli(cli_args, env)
            ok = "ok" if cpu < 10 else "MISSED"
            print(f"cold (compile)  {cpu:7.2f} s CPU  {wall:7.2f} s wall   target < 10 s   {ok}")
        else:
            run_cli(cli_args, env)  # make sure the cache is written

        (Path(floor_dir) / "startup_floor_mod.py").write_text(FLOOR_MODULE)
        floor_env = dict(env, NUMBA_CACHE_DIR=str(Path(floor_dir) / "cache"))
        floor_cmd = [sys.executable, "-c", FLOOR, floor_dir]
        child(floor_cmd, floor_env)  # compile the floor's function once
        warm, floor, ratio = [], [], []
        for _ in range(max(1, args.repeats)):  # interleaved: A B A B ...
            w = run_cli(cli_args, env)[0]
            f = child(floor_cmd, floor_env)[0]
            warm.append(w)
            floor.append(f)
            ratio.append(w / f)
        wm = statistics.median(warm)
        ok = "ok" if wm < 1.0 else "MISSED"
        print(
            f"warm (cached)   {wm:7.2f} s CPU (median of {len(warm)}; "
            f"{min(warm):.2f}-{max(warm):.2f})   target < 1 s   {ok}"
        )
        print(
            f"floor (numpy + numba + one cached call) {statistics.median(floor):.2f} s CPU; "
            f"warm / floor {statistics.median(ratio):.2f} "
            f"({min(ratio):.2f}-{max(ratio):.2f})"
        )
        imp = statistics.median(
            child([sys.executable, "-c", "import braidsim"], env)[0] for _ in range(3)
        )
        print(f"python -c 'import braidsim'  {imp:.3f} s CPU")

        _, _, _, err = child([sys.executable, "-c", PHASES, *cli_args], env)
        phases = json.loads(err.rsplit("PHASES ", 1)[1])
        print("\none warm run, CPU time by phase:")
        for name, sec in phases.items():
            print(f"   {name:48s} {sec * 1e3:7.1f} ms")
        print("\none warm run, import time of each top-level package (self times, -X importtime):")
        for name, sec in import_table(cli_args, env):
            print(f"   {name:24s} {sec * 1e3:7.1f} ms")


if __name__ == "__main__":
    main()
