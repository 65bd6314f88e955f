"""examples/analysis_demo.py runs at reduced size and writes its figures and summary."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "analysis_demo.py"


def test_analysis_demo_quick(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    proc = subprocess.run(
        [sys.executable, str(EXAMPLE), "--out", str(out), "--quick", "--workers", "1"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    for name in ("bifurcation.png", "basins.png"):
        assert (out / name).stat().st_size > 5000
    d = json.loads((out / "demo.json").read_text())
    assert d["quick"] is True
    labels = d["bifurcation"]["labels"]
    # h_a = 0.02 mm is far below the contact-loss bound (0.098 mm), 0.5 mm far above
    assert labels[0] == "resting_contact"
    assert labels[-1] == "periodic_two_sided"
    assert len(d["basins"]["attractors"]) >= 2
    assert "attractors" in proc.stdout
