"""Nonlinear dynamics of the paper's carrier: a bifurcation diagram over the track vibration
amplitude h_a and the basins of attraction at the section 3.3 conditions.

    python examples/analysis_demo.py --out analysis-demo              # full size, about 6 s
    python examples/analysis_demo.py --out /tmp/demo --quick          # CI size, under 2 s
    BRAIDSIM_DEMO_QUICK=1 python examples/analysis_demo.py --out /tmp/demo

Writes ``bifurcation.png``, ``basins.png`` and ``demo.json`` (regimes, transitions,
attractors, the contact-loss bound) into ``--out`` and prints a short summary.

Run times with the compiled code cached, on the shared 2-core development machine
(2026-11-30, two workers): full size 5.9-6.6 s wall (10.3-10.4 s of CPU), ``--quick`` 1.7 s.
The full-size ``bifurcation.png`` is docs/img/analysis_bifurcation_ha.png and ``basins.png``
docs/img/analysis_basins_3_3.png: to regenerate those, run it at full size and copy the two
files there.

What to look for: below the contact-loss bound h_a = a_p / omega_h^2 (docs/model.md §7,
dashed line) the carrier started as in section 3.3 mostly rests on the wall; above it it
bounces on the inner wall, periodically or irregularly, until h_a is large enough to throw it
across the 3 mm gap and it hits both walls once per cycle. The basins show that the section
3.3 parameters hold several steady states at once (docs/model.md §8): which one a run
reports depends on where it starts.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

from braidsim.analysis import basins, bifurcation, contact_loss_bound
from braidsim.analysis.bifurcation import class_text
from braidsim.analysis.plots import plot_basins, plot_bifurcation
from braidsim.io import atomic_write_text
from braidsim.plotting import save

FULL = {
    "ha_points": 121,
    "nx": 24,
    "ny": 24,
    "transient_cycles": 100.0,
    "cycles": 50,
}
QUICK = {
    "ha_points": 5,
    "nx": 2,
    "ny": 2,
    "transient_cycles": 40.0,
    "cycles": 12,
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--quick", action="store_true", help="CI size (also BRAIDSIM_DEMO_QUICK=1)")
    parser.add_argument("--workers", type=int, default=0, help="processes (0: all cores)")
    args = parser.parse_args(argv)
    quick = args.quick or os.environ.get("BRAIDSIM_DEMO_QUICK", "") not in ("", "0")
    size = QUICK if quick else FULL
    args.out.mkdir(parents=True, exist_ok=True)
    opts = {"transient_cycles": size["transient_cycles"], "cycles": size["cycles"]}

    # bifurcation diagram over h_a, from the section 3.3 start
    ha = np.linspace(0.02e-3, 0.5e-3, size["ha_points"])
    diag = bifurcation("paper-3.3", "track.vibration_amplitude", ha, workers=args.workers, **opts)
    bound = contact_loss_bound("paper-3.3")
    marks = [
        (bound["critical_amplitude"], "contact-loss bound $a_p/\\omega_h^2$"),
        (bound["critical_amplitude_with_friction"], "bound with friction"),
    ]
    save(
        plot_bifurcation(
            diag,
            "paper-3.3 carrier: stroboscopic $x - h$ against $h_a$ (60 Hz)",
            marks,
        ),
        args.out / "bifurcation.png",
    )

    # basins over (x0, dx0/dt) at the section 3.3 parameters
    x0 = np.linspace(0.0, 3e-3, size["nx"])
    v0 = np.linspace(-0.6, 0.6, size["ny"])
    bmap = basins("paper-3.3", "initial.x", x0, "initial.vx", v0, workers=args.workers, **opts)
    save(
        plot_basins(bmap, "paper-3.3: steady state reached from each start $(x_0, \\dot x_0)$"),
        args.out / "basins.png",
    )

    summary = {
        "quick": quick,
        "contact_loss_bound": bound,
        "bifurcation": diag.to_dict(samples=False),
        "basins": bmap.to_dict(),
    }
    atomic_write_text(args.out / "demo.json", json.dumps(summary, indent=1, default=str))
    print(f"bifurcation over h_a: {len(ha)} values, transitions:")
    for tr in diag.transitions():
        change = f"{class_text(tr['from'])} -> {class_text(tr['to'])}"
        print(f"  {tr['lower'] * 1e3:.4f}-{tr['upper'] * 1e3:.4f} mm: {change}")
    print(f"basins: {bmap.ids.size} starts, {len(bmap.attractors)} attractors:")
    for a in bmap.attractors:
        print(f"  {a.id}: {a.describe()} ({a.count} starts)")
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
