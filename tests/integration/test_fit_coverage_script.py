"""examples/fit_coverage.py runs with a few realisations and prints its table."""

from __future__ import annotations

import importlib.util
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "fit_coverage.py"
KEYS = ["contact.track.restitution", "track.clearance", "initial.vx"]


def test_fit_coverage_script_prints_per_parameter_and_joint_coverage(capsys):
    spec = importlib.util.spec_from_file_location("fit_coverage", EXAMPLE)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    data = mod.main(["--realisations", "4", "--seed", "7"])
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("4 realisations (seed 7, jacobian auto, 0 not converged")
    assert out[1].split() == ["parameter", "coverage", "mean", "z", "std", "z"]
    for line, key in zip(out[2:5], KEYS, strict=True):
        words = line.split()
        assert words[0] == key
        assert words[1].endswith("%") and 0 <= float(words[1][:-1]) <= 100
        assert len(words) == 4
    assert out[5].startswith("all at once (joint)") and out[5].endswith("%")
    assert out[6].startswith("pooled over parameters")
    assert data["keys"] == KEYS
    assert data["unconverged"] == 0
    # the joint share never exceeds the lowest per-parameter share
    assert data["joint"] <= min(data["coverage"].values())
    for k in KEYS:
        assert abs(data["z_mean"][k]) < 5 and 0 < data["z_std"][k] < 5
