"""Cost of continuation: CPU time per continuation point and per two-parameter point.

Run: ``python benchmarks/bench_continuation.py [--repeats 3] [--points 15]``

On the paper's carrier (paper-3.3, omega = 4 pi rad/s), measured in one process with
``time.process_time`` after a warm-up that compiles the kernels, the calls interleaved
(A B A B ...) and the best of ``--repeats`` kept:

* a branch of ``--points`` points of the period-1 orbit with one impact per cycle, from
  h_a = 0.1 mm towards 0.12 mm (no branch switching), with the exact variational flow map and
  with the central finite-difference map: CPU time per point, each point including its
  corrector, tangent, multipliers, orbit profile and the detection of special points;
* the peer: one point of a brute-force stroboscopic bifurcation diagram at the same h_a
  (:func:`braidsim.analysis.regimes.steady_state`: 300 transient cycles and 24 sampled
  ones), the way the same question is answered without continuation;
* two-parameter points (:func:`braidsim.continuation.twopar.trace_boundary`), followed in
  the horn-gear speed from 4 pi to 6 pi rad/s with steps of 1/4 of the ranges: the lift-off
  grazing of the resting orbit (continuation in the parameter plane, the grazing bracketed
  on each normal line) and the period doubling of the bouncing orbit (the augmented system
  with det(M + I)); CPU time per curve point, one run each (not interleaved), the grazing
  with the finite-difference map only.

Printed as times and as ratios to the brute-force point. Speed is never asserted in tests.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from typing import Any

import braidsim
from braidsim.analysis.regimes import steady_state
from braidsim.continuation import ScenarioSystem, exact_available, seed_orbit
from braidsim.continuation.branch import continue_orbit
from braidsim.continuation.twopar import trace_boundary

HA = "track.vibration_amplitude"


def cpu(fn: Callable[[], Any]) -> tuple[float, Any]:
    """CPU time of one call [s] and its result."""
    t = time.process_time()
    out = fn()
    return time.process_time() - t, out


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--points", type=int, default=15)
    args = ap.parse_args(argv)
    sc = braidsim.load_scenario("paper-3.3")
    system = ScenarioSystem(sc)
    methods = ["exact", "fd"] if exact_available() else ["fd"]
    seeds = {m: seed_orbit(system, {HA: 0.1e-3}, 1, method=m) for m in methods}

    def branch(m: str) -> Any:
        return continue_orbit(
            system, seeds[m], HA, 0.12e-3, method=m, switch=False, max_points=args.points
        )

    def brute() -> Any:
        return steady_state(sc, {HA: 0.1e-3}, transient_cycles=300, cycles=24)

    # warm-up: compile everything once
    for m in methods:
        branch(m)
    brute()
    best: dict[str, float] = {}
    npts: dict[str, int] = {}
    for _ in range(args.repeats):
        for m in methods:
            dt, br = cpu(lambda m=m: branch(m))
            npts[m] = len(br.points) - 1  # the seed is not computed by the run
            best[m] = min(best.get(m, math.inf), dt / max(npts[m], 1))
        dt, _ = cpu(brute)
        best["brute"] = min(best.get("brute", math.inf), dt)
    # two-parameter points: the lift-off grazing (continuation in the parameter plane) and
    # the period doubling (the augmented system), each followed in omega up to 6 pi
    rest = seed_orbit(system, {HA: 0.05e-3}, 1, method="fd")
    br = continue_orbit(system, rest, HA, 0.1e-3, method="fd", switch=False, max_points=40)
    graze = next(s for s in br.special if s.type == "grazing")
    bounce = continue_orbit(
        system, seeds[methods[0]], HA, 0.13e-3, method=methods[0], switch=False, max_points=40
    )
    pd = next(s for s in bounce.special if s.type == "period_doubling")
    npts2: dict[str, int] = {}
    for name, b, sp in (("grazing", br, graze), ("period_doubling", bounce, pd)):
        # (the grazing with the finite-difference map only: each trial of its bracketing
        # is a Newton solve, and near the lift-off many fail, which the exact map makes
        # several times dearer)
        for m in methods if name == "period_doubling" else ["fd"]:
            dt, curve = cpu(
                lambda b=b, sp=sp, m=m: trace_boundary(
                    system,
                    b,
                    sp,
                    "horn_gear.angular_velocity",
                    6 * math.pi,
                    steps=4,
                    method=m,
                    range1=(0.02e-3, 0.4e-3),
                )
            )
            npts2[f"{name} {m}"] = len(curve.p1) - 1
            best[f"{name} {m}"] = dt / max(len(curve.p1) - 1, 1)
    print(f"paper-3.3 at omega = 4 pi rad/s; best of {args.repeats}, CPU seconds")
    print(f"{'what':58s} {'time [s]':>10s} {'/ brute':>8s}")
    for m in methods:
        print(
            f"{'continuation point, ' + m + ' map (' + str(npts[m]) + ' points)':58s} "
            f"{best[m]:10.4f} {best[m] / best['brute']:8.3f}"
        )
    print(f"{'brute-force diagram point (300 + 24 cycles)':58s} {best['brute']:10.4f} {1.0:8.3f}")
    for key, n in npts2.items():
        label = f"two-parameter point, {key} ({n} points)"
        print(f"{label:58s} {best[key]:10.4f} {best[key] / best['brute']:8.3f}")


if __name__ == "__main__":
    main()
