"""Shared test fixtures."""

from __future__ import annotations

import os

import matplotlib

# Figures render off-screen in tests.
matplotlib.use("Agg")
os.environ.setdefault("MPLBACKEND", "Agg")


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """Print the fuzzing suite's count of cases and the share answered clearly."""
    from fuzz.harness import RECORD

    if RECORD.cases:
        terminalreporter.write_line(RECORD.summary())
        for case_id, why in list(RECORD.failures.items())[:20]:
            terminalreporter.write_line(f"  not clear: {case_id}: {why}")
