"""The CLI harness of the fuzzing suite: run a command in this process and check that it was
answered as the project promises.

Promise for a refused command: exit code 2 (bad input) or 1 (numerical, storage or I/O
failure), exactly one line on stderr that starts ``braidsim: error:`` and names the
parameter or path, no traceback, nothing on stdout, and no file left behind (no output,
half or whole, and no hidden temporary).

Every case checked goes into :data:`RECORD`; ``tests/conftest.py`` prints the count and the
share answered clearly at the end of the test run.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class Record:
    """Cases checked and failures (id -> why) over the test session."""

    cases: int = 0
    failures: dict[str, str] = field(default_factory=dict)

    def add(self, case_id: str, why: str | None) -> None:
        self.cases += 1
        if why is not None:
            self.failures[case_id] = why

    def summary(self) -> str:
        ok = self.cases - len(self.failures)
        share = 100.0 * ok / self.cases if self.cases else 100.0
        return (
            f"fuzz suite: {self.cases} bad-input and fault cases, "
            f"{ok} answered clearly ({share:.1f} %)"
        )


RECORD = Record()


def run_cli(argv: list[str]) -> tuple[int, str, str]:
    """Run ``braidsim ARGV`` in this process; return (exit code, stdout, stderr).

    An exception escaping the command line (a traceback a user would see) is returned as exit
    code -1 with the exception in stderr.
    """
    from braidsim.cli import _register
    from braidsim.cli.common import run_app

    _register()
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = run_app(argv)
        except BaseException as exc:  # what a user would see as a traceback
            import traceback

            sys.stderr.write("Traceback (most recent call last):\n")
            sys.stderr.write("".join(traceback.format_exception_only(type(exc), exc)))
            code = -1
    return code, out.getvalue(), err.getvalue()


def listing(root: Path) -> set[str]:
    """Every path under ``root`` (hidden ones included), relative."""
    if not root.exists():
        return set()
    return {str(p.relative_to(root)) for p in root.rglob("*")}


def judge(
    code: int, out: str, err: str, codes: tuple[int, ...], names: tuple[str, ...]
) -> str | None:
    """None when a refused command was answered as promised, else what was wrong."""
    lines = err.strip().splitlines()
    if "Traceback" in err:
        return f"traceback: {err.strip().splitlines()[-1][:200]}"
    if code not in codes:
        return f"exit code {code}, expected {codes}: {err.strip()[:200]}"
    if len(lines) != 1:
        return f"{len(lines)} lines on stderr: {err.strip()[:300]}"
    line = lines[0]
    if not line.startswith("braidsim: error: "):
        return f"not an error line: {line[:200]}"
    if "internal error" in line:
        return f"internal error: {line[:200]}"
    if names and not any(n in line for n in names):
        return f"names none of {names}: {line[:200]}"
    if out.strip():
        return f"stdout not empty: {out[:100]}"
    return None


def check_refused(
    case_id: str,
    argv: list[str],
    codes: tuple[int, ...],
    names: tuple[str, ...],
    watch: Path | None = None,
) -> str | None:
    """Run one case, judge it, record it; ``watch`` is a folder that must not change."""
    before = listing(watch) if watch is not None else set()
    cwd = os.getcwd()
    code, out, err = run_cli(argv)
    assert os.getcwd() == cwd
    why = judge(code, out, err, codes, names)
    if why is None and watch is not None:
        after = listing(watch)
        if after != before:
            why = f"files changed: {sorted(after ^ before)[:5]}"
    RECORD.add(case_id, why)
    return why
