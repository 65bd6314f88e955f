"""Time of a 4-parameter fit to a 1-s accelerometer record (``braidsim fit``).

Run: ``python benchmarks/bench_fit.py [--duration 1.0] [--repeats 3]``

The record is the one of ``examples/fit_accelerometer.py``: the paper-3.1 carrier with
restitution 0.62, stiffness 2e10 N/m^1.5, clearance 2.8 mm and launch speed 0.45 m/s, sampled
at 10 kHz with 20 m/s^2 of white noise; the fit frees those four from the paper's values.

Printed, as CPU time of this process (``time.process_time``; the machine may be shared):

1. the whole fit (:func:`braidsim.fit.fit_record`: global stage of 4 starts on the impact
   times, local least squares on the record from the best two, statistics), best of
   ``--repeats``;
2. the cost reached without the global stage (local least squares from the paper's values):
   what the global stage is for;
3. the local stage from the global stage's best end point with braidsim's two Jacobians
   (the exact sensitivities, and central differences) against the peer, SciPy's own
   ``least_squares(jac="2-point")`` (forward differences) on the same residuals, the three
   interleaved (A B C A B C ...) and the best of each kept; the ratios are SciPy / each,
   with the cost and number of simulations of each.
"""

from __future__ import annotations

import argparse
import math
import time

from scipy.optimize import least_squares

from braidsim.fit import fit_record, parse_fit_spec
from braidsim.fit.estimate import global_stage, local_fit
from braidsim.fit.problem import Problem
from braidsim.fit.synthetic import synthetic_record
from braidsim.params import load_scenario

TRUTH = {
    "contact.track.restitution": 0.62,
    "contact.track.stiffness": 2.0e10,
    "track.clearance": 2.8e-3,
    "initial.vx": 0.45,
}
FREE = {
    "contact.track.restitution": [0.3, 0.9],
    "contact.track.stiffness": [5e9, 1e11],
    "track.clearance": ["2.5 mm", "3.5 mm"],
    "initial.vx": ["0.3 m/s", "0.7 m/s"],
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=1.0)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()

    sc = load_scenario("paper-3.1")
    rec = synthetic_record(
        load_scenario("paper-3.1", overrides=TRUTH),
        args.duration,
        10_000.0,
        {"acceleration": 20.0},
        seed=7,
    )
    spec = parse_fit_spec(
        {"fit": {"free": FREE, "quantity": "acceleration", "starts": 4}}, scenario=sc
    )
    fit_record(spec, rec)  # warm-up: loads the compiled kernel
    best = math.inf
    for _ in range(args.repeats):
        c0 = time.process_time()
        res = fit_record(spec, rec)
        best = min(best, time.process_time() - c0)
    print(
        f"4-parameter fit to a {args.duration:g}-s record ({rec.t.size} samples, "
        f"{res.impacts_in_record} impacts): {best:.2f} s CPU (best of {args.repeats}), "
        f"{res.evaluations} simulations, Jacobian {res.jacobian}, converged {res.converged}"
    )
    for i, k in enumerate(res.keys):
        print(
            f"  {k}: {res.stats.values[i]:.6g} (truth {TRUTH[k]:.6g}, se {res.stats.stderr[i]:.2g})"
        )

    pr = Problem(sc, rec, spec.free, spec.quantities)
    # without the global stage: the local least squares from the paper's values
    lf0 = local_fit(pr, pr.u_start, "record", max_nfev=100)
    print(
        f"without the global stage (local least squares from the paper's values): cost "
        f"{lf0.cost:.6g} against {res.cost:.6g} with it (a local minimum: impacts misaligned)"
    )
    # the local stage from the global stage's best end point: braidsim's Jacobian against
    # SciPy's 2-point forward differences on the same residuals
    u0 = global_stage(pr, "multistart", 4, 1, 60)[0]["u"]
    prf = Problem(sc, rec, spec.free, spec.quantities, jacobian="fd")
    best_t = {"exact": math.inf, "fd": math.inf, "scipy": math.inf}
    sims: dict[str, int] = {}
    costs: dict[str, float] = {}
    for _ in range(args.repeats):
        for name, p in (("exact", pr), ("fd", prf)):
            if name == "exact" and not pr.exact:
                continue
            p.evaluations = 0
            c0 = time.process_time()
            lf = local_fit(p, u0, "record", max_nfev=100)
            best_t[name] = min(best_t[name], time.process_time() - c0)
            sims[name], costs[name] = p.evaluations, lf.cost
        prf.evaluations = 0
        c0 = time.process_time()
        out = least_squares(
            lambda u: prf.residuals(u).r, u0, jac="2-point", bounds=(0.0, 1.0), max_nfev=100
        )
        best_t["scipy"] = min(best_t["scipy"], time.process_time() - c0)
        sims["scipy"], costs["scipy"] = prf.evaluations, float(out.cost)
    names = {
        "exact": "braidsim, exact sensitivities",
        "fd": "braidsim, central differences",
        "scipy": "SciPy least_squares, 2-point",
    }
    print("local stage from the global stage's end point (CPU, best of repeats):")
    for name in ("exact", "fd", "scipy"):
        if name in sims:
            print(
                f"  {names[name]:32s} {best_t[name]:6.2f} s, cost {costs[name]:.6g}, "
                f"{sims[name]} simulations, "
                f"SciPy 2-point / this {best_t['scipy'] / best_t[name]:.2f}"
            )


if __name__ == "__main__":
    main()
