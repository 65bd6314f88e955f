"""Find and run the commands and code blocks that documentation shows a user.

Used by the tests that run every ``braidsim ...`` command and every Python block of the docs
pages (tests/integration/test_docs_commands.py). A fenced block is read as a shell block
unless its language is ``python`` or a data format (``toml``, ``json``).
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

_FENCE = re.compile(r"^(?P<indent> *)(?P<fence>```+|~~~+)\s*(?P<lang>[\w+-]*)")


@dataclass(frozen=True)
class Block:
    """One fenced code block of a Markdown file."""

    path: Path
    line: int  # 1-based line of the opening fence
    lang: str
    text: str

    @property
    def where(self) -> str:
        return f"{self.path.name}:{self.line}"


def fenced_blocks(path: Path) -> list[Block]:
    """Every fenced block of ``path``, in order (indented fences included)."""
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, fence, lang = len(m["indent"]), m["fence"], m["lang"].lower()
        body: list[str] = []
        j = i + 1
        while j < len(lines) and not lines[j].strip().startswith(fence):
            body.append(lines[j][indent:] if lines[j][:indent].strip() == "" else lines[j])
            j += 1
        blocks.append(Block(path, i + 1, lang, "\n".join(body) + "\n"))
        i = j + 1
    return blocks


def shell_lines(block: Block, word: str = "braidsim") -> list[str]:
    """The logical lines of a shell block that contain ``word``: continuations joined,
    comments dropped (other lines, such as formulas in an unlabelled block, are skipped)."""
    joined = block.text.replace("\\\n", " ")
    out = []
    for raw in joined.splitlines():
        if word not in raw:
            continue
        words = shlex.split(raw, comments=True)
        if words:
            out.append(shlex.join(words))
    return out


def braidsim_commands(block: Block) -> list[str]:
    """The ``braidsim ...`` commands of a shell block (also after ``&&``)."""
    if block.lang in ("python", "py", "toml", "json", "yaml", "text"):
        return []
    cmds = []
    for line in shell_lines(block):
        for part in line.split(" && "):
            part = part.strip()
            if part.startswith("braidsim ") or part == "braidsim":
                cmds.append(part)
    return cmds


def run_braidsim(command: str, cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    """Run one ``braidsim ...`` command line as a user would, in ``cwd``."""
    words = shlex.split(command)
    assert words[0] == "braidsim", command
    env = {**os.environ, "MPLBACKEND": "Agg", "COLUMNS": "120"}
    return subprocess.run(
        [sys.executable, "-m", "braidsim", *words[1:]],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def run_python(blocks: list[Block], cwd: Path) -> dict[str, object]:
    """Execute Python blocks in order in one namespace with ``cwd`` as working directory."""
    namespace: dict[str, object] = {"__name__": "__docs__"}
    old = Path.cwd()
    os.chdir(cwd)
    try:
        for b in blocks:
            code = compile(b.text, f"{b.path}:{b.line}", "exec")
            exec(code, namespace)
    finally:
        os.chdir(old)
    return namespace
