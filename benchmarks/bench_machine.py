"""Carrier-transfers simulated per second for the 16-carrier machine, against plain SciPy.

Run: ``python benchmarks/bench_machine.py [--spec examples/machine16.toml] [--revolutions 1]
[--repeats 3] [--scipy-carriers 2]``

1. braidsim, one process: :func:`braidsim.machine.run_machine` with ``workers=1`` over
   ``--revolutions`` carrier revolutions (every carrier, every transfer, the per-transfer
   reduction; no report). Best of ``--repeats`` after a warm-up run that loads the compiled
   kernel. Printed: the wall time of the carrier runs and of the whole call, and
   carrier-transfers per second (transfers of all carriers / wall time of the call).
2. braidsim, all cores: the same with a process pool of ``os.cpu_count()`` workers (it
   includes starting the workers, about a second).
3. SciPy in this process: :func:`braidsim.integrate.scipy_backend.simulate_scipy`
   (``solve_ivp``, DOP853, rtol 1e-8, the kernel's absolute tolerances, terminal events at
   every contact onset and exit, the same transfer map) on the first ``--scipy-carriers``
   carriers with the same transfer times, against :func:`braidsim.simulate` on the same
   carriers (one process). The ratio is SciPy time / braidsim time per carrier-transfer;
   the largest relative difference of the impacts' peak forces between the two checks that
   they integrate the same thing.

On a shared machine the wall time is noisy; the CPU time of this process is printed beside it
for the one-process runs.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path

import numpy as np

from braidsim.integrate.scipy_backend import simulate_scipy
from braidsim.machine import load_machine_spec, plan_transfers, run_machine
from braidsim.simulate import simulate

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--spec", default=str(ROOT / "examples" / "machine16.toml"))
    ap.add_argument("--revolutions", type=float, default=1.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--scipy-carriers", type=int, default=2)
    args = ap.parse_args()

    spec = load_machine_spec(args.spec)
    T = args.revolutions * spec.revolution_time
    n_car = len(spec.loading.carriers)
    print(f"{spec.name}: {n_car} carriers, {T:g} s simulated ({args.revolutions:g} revolutions)")
    run_machine(spec, duration=0.05, workers=1, frames=0)  # warm-up: load the compiled kernel

    best = best_cpu = best_sim = math.inf
    run = None
    for _ in range(args.repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        run = run_machine(spec, duration=T, workers=1, frames=0)
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
        best_sim = min(best_sim, run.elapsed)
    assert run is not None
    n_tr = run.totals["transfers"]
    print(
        f"braidsim, 1 process: {n_tr} carrier-transfers in {best:.3f} s wall "
        f"({best_cpu:.3f} s CPU, carrier runs {best_sim:.3f} s): "
        f"{n_tr / best:.1f} carrier-transfers/s ({n_tr / best_cpu:.1f}/s per CPU second)"
    )

    cores = os.cpu_count() or 1
    if cores > 1:
        t0 = time.perf_counter()
        prun = run_machine(spec, duration=T, workers=cores, frames=0)
        wall = time.perf_counter() - t0
        same = prun.transfers.equals(run.transfers)
        print(
            f"braidsim, {prun.workers} processes: {wall:.3f} s wall: "
            f"{n_tr / wall:.1f} carrier-transfers/s (same results as 1 process: {same})"
        )

    k = max(1, min(args.scipy_carriers, n_car))
    _, plans = plan_transfers(spec, T)
    sc = spec.scenario
    t_b = t_s = 0.0
    n_k = 0
    worst = 0.0
    for p in plans[:k]:
        over = {"transfer.times": [float(t) for t in p.times]}
        scn = sc.with_overrides(over)
        t0 = time.perf_counter()
        rb = simulate(scn, T, sample_interval=0.0, record_events=False)
        t_b += time.perf_counter() - t0
        t0 = time.perf_counter()
        rs = simulate_scipy(scn, T)
        t_s += time.perf_counter() - t0
        n_k += p.times.size
        a = rb.impacts[rb.impacts["pair"] == "track"]["peak_force"].to_numpy()
        b = rs.impacts[rs.impacts["pair"] == "track"]["peak_force"].to_numpy()
        if a.size != b.size:
            worst = math.inf
        elif a.size:
            worst = max(worst, float(np.max(np.abs(a - b) / np.abs(b))))
    print(
        f"{k} carrier(s), {n_k} transfers: braidsim {t_b:.3f} s ({n_k / t_b:.1f}/s), "
        f"SciPy DOP853 {t_s:.3f} s ({n_k / t_s:.2f}/s): ratio SciPy/braidsim {t_s / t_b:.1f}; "
        f"largest relative peak-force difference {worst:.2e}"
    )


if __name__ == "__main__":
    main()
