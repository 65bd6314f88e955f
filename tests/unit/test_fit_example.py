"""examples/fit_accelerometer.py runs at a reduced size and recovers its truth."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "fit_accelerometer.py"


def test_fit_accelerometer_example_runs_small(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("fit_accelerometer", EXAMPLE)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = tmp_path / "fit"
    data = mod.main(["--duration", "0.12", "--out", str(out), "--starts", "2", "--laws", "1"])
    for f in data["files"]:
        assert (out / f).is_file(), f
    assert (tmp_path / "fit-input" / "record.csv").is_file()
    j = json.loads((out / "fit.json").read_text())
    for key, truth in mod.TRUTH.items():
        lo, hi = j["estimates"][key]["ci95"]
        assert lo <= truth <= hi, (key, lo, truth, hi)
    assert "yes" in capsys.readouterr().out
