"""Every ``braidsim ...`` command and Python block of the README runs, at reduced size.

The helpers here are meant for any Markdown page (the documentation pages too):
:func:`code_blocks` reads the fenced blocks of a page, :func:`documented_commands` the
``braidsim`` command lines in its shell blocks, and :func:`run_documented` runs one through
the command line's entry point in a working directory, with the options of
:data:`REDUCTIONS` appended (an option given twice takes its last value) so that each runs
in seconds. Commands listed in :data:`SLOW_VERBS` run only with ``-m slow``.
"""

from __future__ import annotations

import re
import shlex
import shutil
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"

#: options appended to each verb to make it quick; an option given twice keeps its last value
REDUCTIONS: dict[str, list[str]] = {
    "bifurcation": ["--points", "3", "--transient-cycles", "10", "--cycles", "10"],
    "basins": ["--nx", "2", "--ny", "2", "--transient-cycles", "10", "--cycles", "10"],
    "lyapunov": ["--transient-cycles", "10", "--cycles", "10"],
    "machine": ["--duration", "0.3 s", "--frames", "3", "--workers", "1"],
    "sweep": ["--workers", "1"],
}
#: verbs that take minutes even reduced (the whole paper, a design study); `-m slow`
SLOW_VERBS = {"paper", "design"}


@dataclass(frozen=True)
class Block:
    """A fenced code block of a Markdown page."""

    lang: str
    text: str
    line: int  # 1-based line of the opening fence


@dataclass(frozen=True)
class DocCommand:
    """One ``braidsim`` command line of a page."""

    argv: tuple[str, ...]  # without the leading "braidsim"
    source: str  # as written, for test ids and messages
    line: int

    @property
    def verb(self) -> str:
        return self.argv[0] if self.argv else ""


def code_blocks(path: Path) -> list[Block]:
    """The fenced (```) code blocks of a Markdown file, in order."""
    blocks: list[Block] = []
    lang, buf, start = None, [], 0
    for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        m = re.match(r"^\s*```(\S*)", line)
        if m and lang is None:
            lang, buf, start = m.group(1), [], i
        elif m:
            blocks.append(Block(lang, "\n".join(buf) + "\n", start))
            lang = None
        elif lang is not None:
            buf.append(line)
    return blocks


def documented_commands(path: Path) -> list[DocCommand]:
    """Every ``braidsim ...`` command in the shell blocks (no language, ``sh``, ``bash``,
    ``console``) of a page; a line ``a && braidsim ...`` counts from ``braidsim``, a
    trailing ``# comment`` is dropped, ``\\`` continues a line."""
    out = []
    for b in code_blocks(path):
        if b.lang not in ("", "sh", "bash", "shell", "console"):
            continue
        text = b.text.replace("\\\n", " ")
        for k, line in enumerate(text.splitlines()):
            words = shlex.split(line, comments=True)
            parts: list[list[str]] = [[]]
            for w in words:
                if w in ("&&", ";"):
                    parts.append([])
                else:
                    parts[-1].append(w)
            for argv in parts:
                if argv and argv[0] == "braidsim":
                    out.append(DocCommand(tuple(argv[1:]), shlex.join(argv), b.line + 1 + k))
    return out


def python_blocks(path: Path) -> list[Block]:
    """The ``python`` blocks of a page."""
    return [b for b in code_blocks(path) if b.lang == "python"]


def prepare_workdir(page: Path, workdir: Path) -> None:
    """What a reader of ``page`` has around: the repository's ``examples/``, and the page's
    first TOML block saved as ``my.toml`` (the scenario file the commands refer to)."""
    shutil.copytree(ROOT / "examples", workdir / "examples", dirs_exist_ok=True)
    tomls = [b for b in code_blocks(page) if b.lang == "toml"]
    if tomls:
        (workdir / "my.toml").write_text(tomls[0].text, encoding="utf-8")
    _reduce_sweep_specs(workdir / "examples")


def _reduce_sweep_specs(directory: Path) -> None:
    """Two points per axis in the sweep specs (of hundreds): the same verbs and files."""
    from braidsim.sweep.spec import load_spec

    for p in directory.glob("sweep_*.toml"):
        data = tomllib.loads(p.read_text(encoding="utf-8"))
        for ax in data.get("axes", []):
            if "num" in ax:
                ax["num"] = 2
        load_spec(p)  # the original is valid
        p.write_text(_to_toml(data), encoding="utf-8")


def _to_toml(data: dict[str, Any], prefix: str = "") -> str:
    """A small TOML writer for the spec files' shapes (scalars, lists, tables, arrays of
    tables)."""

    def val(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{" + ", ".join(f'"{k}" = {val(x)}' for k, x in v.items()) + "}"
        return repr(v)

    lines, tables = [], []
    for k, v in data.items():
        if isinstance(v, dict):
            tables.append((k, v, False))
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            tables.append((k, v, True))
        else:
            lines.append(f'"{k}" = {val(v)}')
    for k, v, many in tables:
        name = f"{prefix}{k}"
        for item in v if many else [v]:
            lines.append(f"\n[[{name}]]" if many else f"\n[{name}]")
            lines.append(_to_toml(item, prefix=f"{name}."))
    return "\n".join(lines) + "\n"


def run_documented(
    cmd: DocCommand, workdir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: Any
) -> tuple[int, str, str]:
    """Run one documented command in ``workdir`` with its reductions; (code, stdout, stderr)."""
    from braidsim.cli import main

    monkeypatch.chdir(workdir)
    argv = [*cmd.argv, *REDUCTIONS.get(cmd.verb, [])]
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    return int(exc.value.code or 0), out, err


def check_command(
    cmd: DocCommand, workdir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: Any
) -> None:
    """The command exits 0 with no notice (a documented command writes its units); a
    ``--json`` command prints one JSON object with the version."""
    import json

    code, out, err = run_documented(cmd, workdir, capsys, monkeypatch)
    assert code == 0, f"`{cmd.source}` (line {cmd.line}) exited {code}: {err.strip()}"
    assert "braidsim: note:" not in err, f"`{cmd.source}` (line {cmd.line}): {err.strip()}"
    if "--json" in cmd.argv:
        assert json.loads(out)["braidsim_version"]


# ------------------------------------------------------------------ the README

COMMANDS = documented_commands(README)


@pytest.fixture(scope="module")
def readme_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("readme")
    prepare_workdir(README, d)
    return d


def _param(cmd: DocCommand) -> Any:
    # a command that reads what a slow one wrote is slow too (design16/ is written by design)
    slow = cmd.verb in SLOW_VERBS or any(a.startswith("design16/") for a in cmd.argv)
    return pytest.param(cmd, id=cmd.source[:60], marks=[pytest.mark.slow] if slow else [])


def test_readme_has_the_commands_it_should() -> None:
    sources = [c.source for c in COMMANDS]
    assert any("paper-3.3" in s and "--window '0.5 s' '1 s'" in s for s in sources)
    assert {c.verb for c in COMMANDS} >= {"run", "paper", "impact", "models", "sweep"}


@pytest.mark.parametrize("cmd", [_param(c) for c in COMMANDS])
def test_readme_command_runs(cmd: DocCommand, readme_dir: Path, capsys, monkeypatch) -> None:
    """Commands run in the README's order in one directory (``sweep-plot`` reads the store
    that ``sweep`` wrote)."""
    check_command(cmd, readme_dir, capsys, monkeypatch)


@pytest.mark.parametrize("block", python_blocks(README), ids=lambda b: f"line{b.line}")
def test_readme_python_block_runs(block: Block, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    exec(compile(block.text, f"README.md:{block.line}", "exec"), {"__name__": "__readme__"})
