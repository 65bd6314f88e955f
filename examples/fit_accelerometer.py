"""Contact parameters from an accelerometer on a carrier: ``braidsim fit`` on a synthetic record.

The "measurement" is the paper's section 3.1 carrier (released at x0 = 0 with 0.5 m/s
towards the outer wall, bouncing to rest on the inner one) simulated with parameters that
differ from the paper's (the truth below), sampled at 10 kHz as an accelerometer would, with
white noise of 20 m/s^2 (about 0.5 % of the first impact's peak). The fit starts from the
paper's values and recovers four parameters (restitution, contact stiffness, track
clearance and the launch speed) with their standard errors, 95 % intervals and
correlations; it compares three contact laws by AIC and writes the report:

* ``OUT/fit.json``, ``OUT/fitted_scenario.toml`` (runs with ``braidsim run``),
  ``OUT/residuals.png``, ``OUT/profiles.png``, ``OUT/fitted_series.csv``;
* ``OUT-input/record.csv`` and ``OUT-input/spec.toml``: the record and the spec, so that the
  same fit runs from the command line::

      braidsim fit OUT-input/spec.toml --data OUT-input/record.csv --out OUT

Usage::

    python examples/fit_accelerometer.py [--duration 1.0] [--out fit_accelerometer]

(about a minute for the 1-s record on one core with finite-difference Jacobians; CI runs it
at ``--duration 0.12 --laws 1``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from braidsim.fit import fit_record, load_fit_spec, read_record
from braidsim.fit.report import write_report
from braidsim.fit.synthetic import synthetic_record
from braidsim.io import atomic_write_text
from braidsim.params import load_scenario

#: the parameters of the simulated "measurement" (the paper's: 5/9, Eq. (4) ~ 2.49e10,
#: 3 mm, 0.5 m/s)
TRUTH = {
    "contact.track.restitution": 0.62,
    "contact.track.stiffness": 2.0e10,
    "track.clearance": 2.8e-3,
    "initial.vx": 0.45,
}
NOISE = 20.0  # m/s^2, standard deviation of the accelerometer's white noise
RATE = 10_000.0  # Hz

SPEC = """# braidsim fit spec of examples/fit_accelerometer.py
scenario = "paper-3.1"

[fit]
quantity = "acceleration"
starts = {starts}
profile = ["contact.track.restitution"]
profile_points = 7
laws = {laws}

[fit.free]
"contact.track.restitution" = [0.3, 0.9]
"contact.track.stiffness" = [5e9, 1e11]          # N/m^1.5
"track.clearance" = ["2.5 mm", "3.5 mm"]
"initial.vx" = ["0.3 m/s", "0.7 m/s"]
"""


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=1.0, help="record length [s]")
    ap.add_argument("--out", type=Path, default=Path("fit_accelerometer"), help="report folder")
    ap.add_argument("--starts", type=int, default=4, help="starts of the global stage")
    ap.add_argument("--laws", type=int, default=3, help="contact laws compared (1 to 3)")
    ap.add_argument("--seed", type=int, default=7, help="seed of the noise")
    return ap


def main(argv: list[str] | None = None) -> dict:
    args = parser().parse_args(argv)
    truth_sc = load_scenario("paper-3.1", overrides=TRUTH)
    rec = synthetic_record(truth_sc, args.duration, RATE, {"acceleration": NOISE}, seed=args.seed)

    # the record and the spec as a user would have them
    inp = args.out.with_name(args.out.name + "-input")
    inp.mkdir(parents=True, exist_ok=True)
    buf = "t [s],acceleration [m/s^2]\n" + "\n".join(
        f"{t:.6f},{a:.6g}" for t, a in zip(rec.t, rec.columns["acceleration"], strict=True)
    )
    atomic_write_text(inp / "record.csv", buf + "\n")
    laws = ["hunt_crossley", "lankarani_nikravesh", "hertz"][: max(1, min(3, args.laws))]
    atomic_write_text(inp / "spec.toml", SPEC.format(starts=args.starts, laws=json.dumps(laws)))

    # the fit, as `braidsim fit SPEC --data RECORD --out OUT` runs it
    spec = load_fit_spec(inp / "spec.toml")
    res = fit_record(spec, read_record(inp / "record.csv"), progress=print)
    data = write_report(res, spec, args.out)

    print(f"\n{rec.t.size} samples, {res.impacts_in_record} impacts found in the record")
    print(f"{'parameter':28s} {'truth':>11s} {'estimate':>11s} {'95 % interval':>26s}")
    for i, k in enumerate(res.keys):
        lo, hi = res.stats.ci95[i]
        inside = "yes" if lo <= TRUTH[k] <= hi else "NO"
        print(
            f"{k:28s} {TRUTH[k]:11.5g} {res.stats.values[i]:11.5g} "
            f"[{lo:11.5g}, {hi:11.5g}] {inside}"
        )
    corr = res.stats.correlation
    print("largest |correlation|:", f"{np.max(np.abs(corr - np.eye(len(corr)))):.3f}")
    for lr in res.laws:
        print(
            f"law {lr.law:20s} AIC {lr.aic:10.1f}  c_r {lr.restitution:.4f}  "
            f"effective restitution {lr.effective_restitution:.4f}"
        )
    for w in res.warnings:
        print("warning:", w)
    print(f"fit: {res.seconds:.1f} s, {res.evaluations} simulations; report in {args.out}")
    return data


if __name__ == "__main__":
    main()
