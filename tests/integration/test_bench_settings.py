"""bench_core.py --set: the peers' comparison on paper-3.3 with scenario keys changed."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from braidsim import load_scenario

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_core.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_core", BENCH)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_settings_change_the_scenario_and_parse_numbers(bench):
    sc = load_scenario("paper-3.3")
    out = bench.with_settings(
        sc, ["track.clearance=0.0024", "friction.law=tanh"], ["lean", "numbalsoda"]
    )
    assert out["track.clearance"] == 0.0024
    assert out["friction.law"] == "tanh"
    assert sc["track.clearance"] == 0.003  # (the scenario given is not changed)


@pytest.mark.parametrize(
    ("settings", "parts", "says"),
    [
        (["no.such.key=1"], ["lean"], "no.such.key"),
        (["track.clearance=-1"], ["lean"], "track.clearance"),
        (["track.clearance"], ["lean"], "expected KEY=VALUE"),
        (["=1"], ["lean"], "expected KEY=VALUE"),
        (["track.clearance=0.0024"], ["lean", "memory"], "not with --part memory"),
    ],
)
def test_bad_settings_get_one_line_and_exit_code_2(bench, capsys, settings, parts, says):
    with pytest.raises(SystemExit) as stop:
        bench.with_settings(load_scenario("paper-3.3"), settings, parts)
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("--set: ") and says in err
