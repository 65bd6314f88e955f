"""The cost of forward sensitivities: a run with k of them against the same run without.

Run: ``python benchmarks/bench_sensitivity.py [--duration 1] [--repeats 5]``

On paper-3.3 (track vibration, chatter; x only) for ``--duration`` seconds, the public call
``braidsim.simulate(sc, duration, series=False)`` is timed without sensitivities and with
k = 1, 4 and 10 keys (the first k of ``KEYS``), interleaved (one call of each per round),
best of ``--repeats`` rounds, CPU time of this process. Printed: the times, the ratio to the
run without sensitivities, and that ratio per direction. The run with sensitivities also
holds the tangents to the state's tolerance, so its steps differ (more near contact onset
and exit, where the Hertz stiffness sqrt(p) is not smooth): the step counts are printed.

Then one monodromy: :func:`braidsim.sensitivity.flow_map` over one track-vibration period
from the state at 0.5 s (2 state directions + 2 latched speeds), against the plain run over
the same period.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from typing import Any

from braidsim.params import load_scenario
from braidsim.sensitivity import flow_map
from braidsim.simulate import simulate

KEYS = (
    "contact.track.restitution",
    "track.clearance",
    "track.vibration_amplitude",
    "carrier.mass",
    "yarn.tension_horizontal",
    "horn_gear.angular_velocity",
    "friction.carrier_horn_gear",
    "materials.track.youngs_modulus",
    "track.vibration_frequency",
    "initial.vx",
)


def cpu(fn: Callable[[], Any]) -> tuple[float, Any]:
    c0 = time.process_time()
    out = fn()
    return time.process_time() - c0, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=1.0)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    sc = load_scenario("paper-3.3")
    cases: dict[str, Callable[[], Any]] = {
        "k=0": lambda: simulate(sc, duration=args.duration, series=False)
    }
    for k in (1, 4, 10):
        keys = list(KEYS[:k])
        cases[f"k={k}"] = lambda keys=keys: simulate(
            sc, duration=args.duration, series=False, sensitivities=keys
        )
    for fn in cases.values():  # warm-up: load (or compile) the solver variants
        fn()
    best = dict.fromkeys(cases, math.inf)
    steps: dict[str, int] = {}
    for _ in range(args.repeats):
        for name, fn in cases.items():
            t, res = cpu(fn)
            best[name] = min(best[name], t)
            steps[name] = int(res.stats["steps"]) + int(res.stats["rejected_steps"])
    base = best["k=0"]
    print(f"paper-3.3, {args.duration:g} s, CPU time, best of {args.repeats} (interleaved)")
    print(f"{'run':>6} {'time [ms]':>10} {'ratio':>7} {'per key':>8} {'steps+rejected':>15}")
    for name, t in best.items():
        k = int(name.split("=")[1])
        per = f"{(t / base - 1) / k:8.2f}" if k else f"{'':>8}"
        print(f"{name:>6} {1e3 * t:10.2f} {t / base:7.2f} {per} {steps[name]:>15}")

    # one monodromy over a forcing period from the state at 0.5 s
    settle = simulate(sc, duration=0.5, series=False)
    fs = settle.final_state
    T = 2 * math.pi / sc["track.vibration_frequency"]
    t0 = fs.t
    y0 = list(fs.y[:2])
    v0s = (fs.track_v0 if fs.track_mode else math.nan, math.nan)
    modes = (fs.track_mode, 0)

    def mono() -> Any:
        return flow_map(sc, t0, t0 + T, y0=y0, modes=modes, v0s=v0s)

    def plain() -> Any:
        return simulate(sc, duration=T, start=fs, series=False)

    mono()
    plain()
    tm = tp = math.inf
    for _ in range(args.repeats):
        tm = min(tm, cpu(mono)[0])
        tp = min(tp, cpu(plain)[0])
    print(
        f"monodromy over one period ({1e3 * T:.2f} ms of motion): {1e3 * tm:.2f} ms CPU, "
        f"the plain run {1e3 * tp:.2f} ms ({tm / tp:.1f}x; the flow map also samples the "
        "gaps 400 times)"
    )


if __name__ == "__main__":
    main()
