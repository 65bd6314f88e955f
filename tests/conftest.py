"""Shared test fixtures."""

from __future__ import annotations

import os

import matplotlib
import pytest

# Figures render off-screen in tests.
matplotlib.use("Agg")
os.environ.setdefault("MPLBACKEND", "Agg")


def pytest_sessionfinish(session, exitstatus):
    """In an xdist worker: hand the fuzzing suite's record to the controller, which prints
    it (each worker checks its own share of the cases)."""
    workeroutput = getattr(session.config, "workeroutput", None)
    if workeroutput is not None:
        from fuzz.harness import RECORD

        workeroutput["fuzz_record"] = {"cases": RECORD.cases, "failures": RECORD.failures}


@pytest.hookimpl(optionalhook=True)  # (an xdist hook: unknown where xdist is not loaded)
def pytest_testnodedown(node, error):
    """In the xdist controller: add a finished worker's fuzzing record to this process's."""
    data = getattr(node, "workeroutput", {}).get("fuzz_record")
    if data:
        from fuzz.harness import RECORD

        RECORD.cases += data["cases"]
        RECORD.failures.update(data["failures"])


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """Print the fuzzing suite's count of cases and the share answered clearly."""
    from fuzz.harness import RECORD

    if RECORD.cases:
        terminalreporter.write_line(RECORD.summary())
        for case_id, why in list(RECORD.failures.items())[:20]:
            terminalreporter.write_line(f"  not clear: {case_id}: {why}")
