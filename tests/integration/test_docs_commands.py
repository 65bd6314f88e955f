"""Every ``braidsim ...`` command and every Python block of the docs pages runs.

The pages are read as a user reads them (tests/helpers_commands.py finds the blocks). Each
command runs in a fresh folder that sees the repository's ``examples/``; a few run at a
reduced size (``REDUCED``: the same command with smaller grids or durations), the longest as
written only under ``-m slow`` (``SLOW``). Syntax summaries with placeholders (``TEMPLATES``)
are checked by asking their command for ``--help``. A command the tables below do not know
runs as written, so a new command in the docs is tested without editing this file. A
command that the README test runs as written is left to it.
"""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import pytest

from helpers_commands import (
    REPO,
    Block,
    braidsim_commands,
    fenced_blocks,
    run_braidsim,
    run_python,
)

from .test_readme_commands import COMMANDS as README_COMMANDS
from .test_readme_commands import REDUCTIONS as README_REDUCTIONS

DOCS = REPO / "docs"
PAGES = sorted(DOCS.glob("*.md"))

# command as written -> the same command at a size that runs in seconds
REDUCED = {
    'braidsim analyze paper-3.3 --duration "3 s" --transient "2 s" --out a33': (
        'braidsim analyze paper-3.3 --duration "0.3 s" --transient "0.2 s" --out a33'
    ),
    'braidsim bifurcation paper-3.3 --param track.vibration_amplitude --from "0.02 mm" '
    '--to "0.5 mm" --points 121 --workers 0 --out bif': (
        'braidsim bifurcation paper-3.3 --param track.vibration_amplitude --from "0.02 mm" '
        '--to "0.5 mm" --points 2 --transient-cycles 5 --cycles 5 --workers 1 --out bif'
    ),
    'braidsim basins paper-3.3 --x initial.x --x-from "0 mm" --x-to "3 mm" --nx 24 '
    '--y initial.vx --y-from "-0.6 m/s" --y-to "0.6 m/s" --ny 24 --workers 0 --out basins': (
        'braidsim basins paper-3.3 --x initial.x --x-from "0 mm" --x-to "3 mm" --nx 2 '
        '--y initial.vx --y-from "-0.6 m/s" --y-to "0.6 m/s" --ny 2 --transient-cycles 5 '
        "--cycles 5 --workers 1 --out basins"
    ),
    'braidsim lyapunov paper-3.3 --set "track.vibration_amplitude=0.18 mm" --cycles 300 '
    "--out lyap": (
        'braidsim lyapunov paper-3.3 --set "track.vibration_amplitude=0.18 mm" '
        "--transient-cycles 5 --cycles 5 --out lyap"
    ),
}

# commands that a command before them must have prepared (run first, in the same folder)
SETUP = {
    "braidsim analyze results/run-folder": [
        'braidsim run paper-3.1 --duration "0.05 s" --out results/run-folder'
    ],
    "braidsim machine design16/optimised_machine.toml --out m16opt": [
        "braidsim design examples/design16.toml --out design16"
    ],
}

# full-size runs of a minute or more: run as written only with -m slow
SLOW = {
    "braidsim analyze results/run-folder",  # with its set-up run --out: about 12 s
    "braidsim design examples/design16.toml --out design16 --json",
    "braidsim machine design16/optimised_machine.toml --out m16opt",
    "braidsim machine examples/machine16.toml --out machine16",
}

# pages whose Python blocks run a full study (slow)
SLOW_PYTHON = {"design.md"}

# Python blocks that are sketches with elided bodies (running them would register a dummy law
# in the process): only compiled, so a syntax error still fails
SKETCHES = {
    ("core.md", "# my_law.py in src/braidsim/core/physics"),
    ("core.md", "# a run of the paper-3.3 carrier with the new law on the track"),
}


def _sketch(b: Block) -> bool:
    return (b.path.name, b.text.split("\n", 1)[0]) in SKETCHES


def _normal(cmd: str) -> str:
    return shlex.join(shlex.split(cmd))


REDUCED_N = {_normal(k): v for k, v in REDUCED.items()}
SETUP_N = {_normal(k): v for k, v in SETUP.items()}
SLOW_N = {_normal(c) for c in SLOW}


def _is_template(cmd: str) -> bool:
    # a syntax summary: optional parts in brackets or upper-case placeholders
    return "[" in cmd or any(w.isupper() and len(w) > 1 for w in shlex.split(cmd)[1:])


# commands that the README test runs as written (its verb not reduced there): not run twice
IN_README = {
    shlex.join(["braidsim", *c.argv]) for c in README_COMMANDS if c.verb not in README_REDUCTIONS
}


def _command_cases() -> list[object]:
    cases = []
    for page in PAGES:
        for block in fenced_blocks(page):
            for cmd in braidsim_commands(block):
                if cmd in IN_README and cmd not in REDUCED_N and cmd not in SETUP_N:
                    continue
                marks = [pytest.mark.slow] if cmd in SLOW_N else []
                cases.append(pytest.param(cmd, id=f"{block.where}:{cmd[:60]}", marks=marks))
    return cases


def _python_cases() -> list[object]:
    cases = []
    for page in PAGES:
        blocks = [b for b in fenced_blocks(page) if b.lang in ("python", "py") and not _sketch(b)]
        if blocks:
            marks = [pytest.mark.slow] if page.name in SLOW_PYTHON else []
            cases.append(pytest.param(blocks, id=page.name, marks=marks))
    return cases


@pytest.fixture
def workdir(tmp_path: Path) -> Path:
    """A fresh folder in which the repository's examples are where the docs say."""
    (tmp_path / "examples").symlink_to(REPO / "examples", target_is_directory=True)
    return tmp_path


def _check(cmd: str, cwd: Path) -> None:
    proc = run_braidsim(cmd, cwd)
    assert proc.returncode == 0, f"{cmd}\nexit {proc.returncode}\n{proc.stderr[-3000:]}"
    # a documented command writes its units: no "taken as ... (SI)" notice
    assert "braidsim: note:" not in proc.stderr, f"{cmd}\n{proc.stderr[-3000:]}"
    if "--json" in shlex.split(cmd):
        json.loads(proc.stdout)


@pytest.mark.parametrize("cmd", _command_cases())
def test_docs_command_runs(cmd: str, workdir: Path) -> None:
    if _is_template(cmd):
        verb = shlex.split(cmd)[1]
        proc = run_braidsim(f"braidsim {verb} --help", workdir)
        assert proc.returncode == 0, proc.stderr
        return
    for before in SETUP_N.get(cmd, []):
        _check(before, workdir)
    _check(REDUCED_N.get(cmd, cmd), workdir)


@pytest.mark.parametrize("blocks", _python_cases())
def test_docs_python_blocks_run(blocks: list[Block], workdir: Path) -> None:
    run_python(blocks, workdir)


def test_docs_sketches_compile() -> None:
    """Each sketch is still on its page, and is valid Python."""
    found = [b for page in PAGES for b in fenced_blocks(page) if _sketch(b)]
    assert len(found) == len(SKETCHES), SKETCHES
    for b in found:
        compile(b.text, b.where, "exec")


def test_docs_have_commands_and_python() -> None:
    """The search above finds what the pages show (a broken parser would find nothing)."""
    assert len(_command_cases()) >= 10
    assert {c.id for c in _python_cases()} >= {"model.md", "laws.md", "getting-started.md"}  # type: ignore[attr-defined]


def test_reduction_tables_name_commands_of_the_docs() -> None:
    """Every reduced, prepared or slow command is still in the docs (no stale entries)."""
    shown = {c.values[0] for c in _command_cases()}  # type: ignore[attr-defined]
    for table in (REDUCED_N, SETUP_N):
        assert set(table) <= shown, set(table) - shown
    assert SLOW_N <= shown, SLOW_N - shown
