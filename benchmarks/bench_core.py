"""The compiled core against its peers, as ratios of CPU time measured in one process.

Run: ``python benchmarks/bench_core.py [--part lean|numbalsoda|scipy|dop853|taylor|batch|machine|
memory|startup] [--repeats 15] [--set KEY=VALUE]`` (every part by default; ``--part`` may be
given more than once). ``--set`` (repeatable) changes a key of the scenario for the parts run
in this process, to see whether a ratio holds away from paper-3.3 itself (e.g.
``--set track.clearance=0.0024``); the lean peers read the same keys.

Parts (all on paper-3.3, x only, unless said otherwise):

lean
    braidsim's public ``simulate`` call with no sampled series (``braidsim_call`` below)
    against the lean event-exact numba Dormand-Prince 5(4) loop of ``lean_dp5.py``, over
    0.5 s, at two accuracy levels: largest relative peak-force error over the 33 contact
    episodes of about 2.5e-6 and 1.2e-7 against a tight reference (braidsim at rtol 1e-12,
    atol 1e-16 m / 1e-13 m/s; the lean loop at the same tolerances is compared with it, as a
    check of both). Each integrator's tolerance for a level is calibrated separately: rtol runs
    over a grid of 8 points per decade, with atol scaled in proportion from the scenario's
    defaults (1e-13 m and 1e-9 m/s at rtol 1e-8), and the loosest rtol whose error and the
    errors of all tighter grid points are at most the level is taken. Printed: the achieved
    errors, right-hand-side evaluations, accepted and rejected steps, and the CPU times
    (``time.process_time``, the two calls interleaved A B A B, best of ``--repeats``) and their
    ratio. Then, as a check on the calibration's luck (the error is not monotone in rtol),
    the same comparison over the whole grid: both timed at every rtol (interleaved, best of
    5 sweeps), a line of log time against log error fitted to each through the points within
    30x of the level, and the ratio of the two lines at the level (:func:`fitted_time`).
    Last, the fixed cost of a call, a 1-us run of each (:func:`fixed_costs`).
numbalsoda
    the same against numbalsoda's DOP853 (Hairer's DOP853, Fortran) where it is installed.
    Its ``solve_ivp`` is called from numba-compiled code, with the right-hand side and the
    event functions as numba ``cfunc``s: terminal events at contact onset and exit (it checks
    for sign changes at step ends and locates them by Brent's method on the 7th-order dense
    output to 1e-8 s, its fixed tolerance) and a terminal event at dN/dt = 0 for the peak
    force; after each event the event time is refined by one Newton step with a 2nd-order
    Taylor update of the state (so that the switch is not 1e-8 s off) and the integration
    restarts from there. One absolute tolerance serves x and x' (the library takes a scalar).
    braidsim is compared twice: with its default integrator and with Taylor-series steps.
dop853
    the lean DP5 loop against the same loop with the DOP853 pair (``lean_dop853.py``): what a
    higher-order pair buys in steps, evaluations and time at equal accuracy.
taylor
    the lean DP5 loop against the hybrid Taylor / DP5 loop (``lean_taylor.py``: Taylor steps
    of order 12, the first step of a contact in s = sqrt(t - t_onset), DP5 steps near contact
    exits and the friction poles): what a Taylor method buys. 'rhs evaluations' of the Taylor
    loop are its DP5 evaluations plus its Taylor steps, one each (a Taylor step is not an
    evaluation: it computes up to 12 coefficients of the solution by recurrences); the Taylor
    steps in contact and in flight and the DP5 steps in contact are printed as well.
scipy
    the same against ``scipy.integrate.solve_ivp`` (DOP853, terminal events at contact onset,
    exit and the force peak, restart after each), plain Python right-hand side.
batch
    one-second paper-3.3 runs per CPU second in ``simulate_batch`` (one worker, 64 parameter
    sets with h_a spread over 0.11-0.13 mm).
machine
    carrier-transfers per CPU second of the 16-carrier machine of ``examples/machine16.toml``
    over one carrier revolution (``run_machine``, one worker).
memory
    peak RSS and CPU time of 10, 100 and 1000-s paper-3.3 runs in subprocesses, with the
    default outputs and summary-only (no sampled series). Each child runs under a timeout
    and an address-space limit (``--timeout``, ``--mem-limit-gb``); a child past either is
    reported as "did not finish within ...".
startup
    the first run from an empty compile cache (a fresh ``NUMBA_CACHE_DIR``) and a warm run,
    both ``braidsim run paper-3.3 --json`` in a subprocess: CPU time of the child
    (``os.wait4``'s resource usage) and wall time.
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

import braidsim
from braidsim import Scenario, load_scenario

sys.path.insert(0, str(Path(__file__).resolve().parent))
import lean_dp5

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = "paper-3.3"
# the parts that run SCENARIO itself (in subprocesses, or another scenario): no --set there
UNSET_PARTS = ("machine", "memory", "startup")
DURATION = 0.5
LEVELS = (2.5e-6, 1.2e-7)  # peak-force accuracies at which the integrators are compared
TIGHT = {
    "simulation.rtol": 1e-12,
    "simulation.atol_position": 1e-16,
    "simulation.atol_velocity": 1e-13,
}
# atol belongs to rtol as in the scenario's defaults (1e-13 m, 1e-9 m/s at rtol 1e-8)
ATOL_X_PER_RTOL = 1e-13 / 1e-8
ATOL_V_PER_RTOL = 1e-9 / 1e-8
RTOL_GRID = tuple(10.0 ** (-6.0 - k / 8.0) for k in range(0, 49))  # 1e-6 ... 1e-12
FIT_BAND = 30.0  # the grid points whose error is within this factor of a level are fitted
# the fixed cost of a call: a run this long [s], timed in batches of this many calls
FIXED_RUN = 1e-6
FIXED_BATCH = 100
FIT_REPEATS = 5  # sweeps of the grid for the fitted times (best of)
HMAX = 1e-3  # braidsim's default maximum step for a 60-Hz track (1 ms cap)
PARTS = ("lean", "numbalsoda", "scipy", "dop853", "taylor", "batch", "machine", "memory", "startup")


def tolerances(rtol: float) -> dict[str, float]:
    return {
        "simulation.rtol": rtol,
        "simulation.atol_position": ATOL_X_PER_RTOL * rtol,
        "simulation.atol_velocity": ATOL_V_PER_RTOL * rtol,
    }


def braidsim_call(sc: Scenario) -> Any:
    """braidsim's public call with no sampled series (the lean path: impacts, ranges,
    summary and final state)."""
    return braidsim.simulate(sc, DURATION, series=False)


def peak_error(peaks: np.ndarray, walls: np.ndarray, ref: Any) -> float:
    """Largest relative peak-force error over the episodes; inf if the sequences differ."""
    rp = ref["peak_force"].to_numpy(dtype=float)
    rw = np.where(ref["wall"].to_numpy() == "inner", -1.0, 1.0)
    if peaks.shape != rp.shape or not np.array_equal(walls, rw):
        return math.inf
    return float(np.max(np.abs(peaks - rp) / np.abs(rp)))


def timed_pair(fa: Callable[[], Any], fb: Callable[[], Any]) -> tuple[float, float]:
    """CPU times [s] of one call of fa, then one of fb."""
    c0 = time.process_time()
    fa()
    c1 = time.process_time()
    fb()
    c2 = time.process_time()
    return c1 - c0, c2 - c1


def interleaved(fa: Callable[[], Any], fb: Callable[[], Any], repeats: int) -> tuple[float, float]:
    """Best CPU times [s] of fa and fb, called A B A B ... ``repeats`` times each."""
    ta, tb = interleaved_all((fa, fb), repeats)
    return ta, tb


def interleaved_all(calls: tuple[Callable[[], Any], ...], repeats: int) -> list[float]:
    """Best CPU times [s] of each of ``calls``, called in turn ``repeats`` times each."""
    best = [math.inf] * len(calls)
    for _ in range(repeats):
        for i, call in enumerate(calls):
            c0 = time.process_time()
            call()
            best[i] = min(best[i], time.process_time() - c0)
    return best


class Peer:
    """An integrator under calibration: ``run(rtol)`` returns (peaks, walls, stats dict)."""

    name: str

    def run(self, rtol: float) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
        raise NotImplementedError

    def call(self, rtol: float) -> Callable[[], Any]:
        return lambda: self.run(rtol)


class BraidsimPeer(Peer):
    """braidsim's public call with the scenario's ``simulation.integrator``: Dormand-Prince
    throughout, or Taylor-series steps where they are longer."""

    def __init__(self, sc: Scenario, integrator: str = "dormand-prince") -> None:
        self.sc = sc.with_overrides({"simulation.integrator": integrator})
        self.name = "braidsim simulate()" + (" taylor" if integrator == "taylor" else "")
        self.scs: dict[float, Scenario] = {}

    def scenario(self, rtol: float) -> Scenario:
        if rtol not in self.scs:
            self.scs[rtol] = self.sc.with_overrides(tolerances(rtol))
        return self.scs[rtol]

    def run(self, rtol: float) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
        res = braidsim_call(self.scenario(rtol))
        im = res.impacts
        walls = np.where(im["wall"].to_numpy() == "inner", -1.0, 1.0)
        st = {
            "rhs": res.stats["rhs_evaluations"],
            "steps": res.stats["steps"],
            "rejected": res.stats["rejected_steps"],
        }
        return im["peak_force"].to_numpy(dtype=float), walls, st

    def call(self, rtol: float) -> Callable[[], Any]:
        sc = self.scenario(rtol)
        return lambda: braidsim_call(sc)


class LeanPeer(Peer):
    """The lean DP5 loop of ``lean_dp5.py``; its variants override :meth:`runner` (a
    function with ``run_lean``'s arguments and outputs) and :meth:`stats`."""

    name = "lean DP5 loop"

    def __init__(self, q: np.ndarray, x0: float, v0: float) -> None:
        self.q, self.x0, self.v0 = q, x0, v0

    def runner(self) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
        return lean_dp5.run_lean

    def stats(self, st: np.ndarray) -> dict[str, float]:
        return {
            "rhs": st[lean_dp5.S_NFEV],
            "steps": st[lean_dp5.S_ACC],
            "rejected": st[lean_dp5.S_REJ],
        }

    def run(self, rtol: float) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
        ep, st = self.runner()(
            self.q,
            DURATION,
            self.x0,
            self.v0,
            rtol,
            ATOL_X_PER_RTOL * rtol,
            ATOL_V_PER_RTOL * rtol,
            HMAX,
        )
        return ep[:, lean_dp5.EP_PEAK], ep[:, lean_dp5.EP_WALL], self.stats(st)


def calibrate(
    peer: Peer, ref: Any, grid: tuple[float, ...]
) -> list[tuple[float, float, dict[str, float]]]:
    """(rtol, error, stats) over the grid, loosest first."""
    out = []
    for rtol in grid:
        try:
            peaks, walls, st = peer.run(rtol)
            err = peak_error(peaks, walls, ref)
        except Exception as exc:  # a failed run at a loose tolerance is a result, not a crash
            err, st = math.inf, {"failure": str(exc)}  # type: ignore[dict-item]
        out.append((rtol, err, st))
    return out


def pick(
    cal: list[tuple[float, float, dict[str, float]]], level: float
) -> tuple[float, float, dict[str, float]] | None:
    """The loosest grid point whose error, and that of every tighter one, is <= level."""
    chosen = None
    for rtol, err, st in reversed(cal):  # tightest first
        if err <= level:
            chosen = (rtol, err, st)
        else:
            break
    return chosen


def grid_times(
    peer_a: Peer, peer_b: Peer, grid: tuple[float, ...], repeats: int
) -> tuple[dict[float, float], dict[float, float]]:
    """Best CPU time [s] of each peer at every rtol of the grid, the two interleaved at each
    point and the grid swept ``repeats`` times (so that a change of the machine's speed
    falls on both)."""
    calls = [(r, peer_a.call(r), peer_b.call(r)) for r in grid]
    ta = dict.fromkeys(grid, math.inf)
    tb = dict.fromkeys(grid, math.inf)
    for _ in range(repeats):
        for r, fa, fb in calls:
            a, b = timed_pair(fa, fb)
            ta[r] = min(ta[r], a)
            tb[r] = min(tb[r], b)
    return ta, tb


def fitted_time(
    cal: list[tuple[float, float, dict[str, float]]],
    times: dict[float, float],
    level: float,
    band: float = FIT_BAND,
) -> tuple[float, int]:
    """The time [s] at which the grid's points reach ``level``: a least-squares line of
    log(time) against log(error) through the points whose error lies within a factor
    ``band`` of the level, read at the level; and the number of points (NaN below 4).

    The calibrated pick (:func:`pick`) guarantees the level at every tighter grid point, so it
    rides on the luck of the few points near the level: the peak-force error jumps by up to
    20x between neighbouring rtols (the chain of impacts amplifies each local error). The
    line through some twenty points is the typical cost of that accuracy."""
    pts = [
        (math.log(err), math.log(times[rtol]))
        for rtol, err, _ in cal
        if math.isfinite(err) and err > 0.0 and level / band <= err <= level * band
    ]
    if len(pts) < 4:
        return math.nan, len(pts)
    x, y = np.array(pts).T
    slope, intercept = np.polyfit(x, y, 1)
    return math.exp(intercept + slope * math.log(level)), len(pts)


def compare(
    peer_a: Peer,
    peer_b: Peer,
    ref: Any,
    repeats: int,
    grid_b: tuple[float, ...] = RTOL_GRID,
    fitted: bool = False,
) -> None:
    """Calibrate both, then time them at each level (A = braidsim) and print the ratio; with
    ``fitted`` (both on ``RTOL_GRID``) also the ratio of their fitted times over the whole
    grid (:func:`fitted_time`)."""
    cal_a = calibrate(peer_a, ref, RTOL_GRID)
    cal_b = calibrate(peer_b, ref, grid_b)
    grid_t = grid_times(peer_a, peer_b, RTOL_GRID, FIT_REPEATS) if fitted else None
    for level in LEVELS:
        ca = pick(cal_a, level)
        cb = pick(cal_b, level)
        print(f"  level {level:.1e}:")
        if ca is None or cb is None:
            who = peer_a.name if ca is None else peer_b.name
            print(f"    {who} reaches no error <= {level:.1e} on the rtol grid")
            continue
        ta, tb = interleaved(peer_a.call(ca[0]), peer_b.call(cb[0]), repeats)
        for (rtol, err, st), t, nm in ((ca, ta, peer_a.name), (cb, tb, peer_b.name)):
            print(
                f"    {nm:22s} rtol {rtol:8.2e}  error {err:8.2e}  {t * 1e3:8.3f} ms CPU  "
                f"{int(st['rhs']):6d} rhs evaluations, {_count(st['steps']):>5s} steps, "
                f"{_count(st['rejected']):>4s} rejected  "
                f"({t / st['rhs'] * 1e9:.0f} ns per rhs evaluation)"
            )
        print(
            f"    ratio time {peer_b.name} / time {peer_a.name}: {tb / ta:.2f}  "
            f"(>1: {peer_a.name} faster)"
        )
        if grid_t is not None:
            fa, na = fitted_time(cal_a, grid_t[0], level)
            fb, nb = fitted_time(cal_b, grid_t[1], level)
            print(
                f"    fitted over the grid (log time against log error, errors within "
                f"{FIT_BAND:g}x of the level): {peer_a.name} {fa * 1e3:.3f} ms ({na} points), "
                f"{peer_b.name} {fb * 1e3:.3f} ms ({nb} points), ratio {fb / fa:.2f}"
            )


def _count(v: float) -> str:
    return "-" if math.isnan(v) else str(int(v))


def reference(sc: Scenario) -> Any:
    return braidsim.simulate(sc.with_overrides(TIGHT), DURATION, series=False)


def lean_peer(sc: Scenario, ref_result: Any) -> LeanPeer:
    q = lean_dp5.lean_params(
        sc, ref_result.stats["track_stiffness"], ref_result.stats["track_damping_factor"]
    )
    return LeanPeer(q, sc["initial.x"], sc["initial.vx"])


def part_lean(sc: Scenario, args: argparse.Namespace) -> None:
    repeats = args.repeats
    print(
        f"\n== lean: braidsim simulate() vs the lean numba DP5 loop, "
        f"{args.label} x only, {DURATION} s"
    )
    print(
        "   braidsim call: simulate(sc, 0.5, series=False) (the lean path: impacts, ranges, "
        "summary, final state)"
    )
    res = reference(sc)
    ref = res.impacts
    lean = lean_peer(sc, res)
    ep, _ = lean_dp5.run_lean(lean.q, DURATION, lean.x0, lean.v0, 1e-12, 1e-16, 1e-13, HMAX)
    chk = peak_error(ep[:, lean_dp5.EP_PEAK], ep[:, lean_dp5.EP_WALL], ref)
    print(
        f"   reference: braidsim rtol 1e-12 (atol 1e-16 m, 1e-13 m/s), {len(ref)} episodes; "
        f"the lean loop at the same tolerances differs by {chk:.1e} (peak force)"
    )
    compare(BraidsimPeer(sc), lean, ref, repeats, fitted=True)
    print("   with Taylor-series steps (simulation.integrator = taylor):")
    compare(BraidsimPeer(sc, "taylor"), lean, ref, repeats, fitted=True)
    fixed = fixed_costs(sc, lean, repeats)
    print(
        f"   fixed cost of a call (a {FIXED_RUN * 1e6:g}-us run, best of {repeats} batches of "
        f"{FIXED_BATCH}): braidsim simulate() {fixed[0] * 1e6:.1f} us, with Taylor steps "
        f"{fixed[1] * 1e6:.1f} us; the lean DP5 loop {fixed[2] * 1e6:.1f} us"
    )


def fixed_costs(sc: Scenario, lean: LeanPeer, repeats: int) -> tuple[float, float, float]:
    """CPU time [s] of one call that integrates FIXED_RUN seconds, for braidsim's call with
    each integrator and for the lean loop: what a call costs besides its steps (argument
    checks, records, results; for the lean loop its Python wrapper). Each timed as a batch
    of FIXED_BATCH calls, the three batches interleaved, best of ``repeats``."""
    taylor = sc.with_overrides({"simulation.integrator": "taylor"})
    runner = lean.runner()
    rtol = 1e-8

    def batch(call: Callable[[], Any]) -> Callable[[], None]:
        def run() -> None:
            for _ in range(FIXED_BATCH):
                call()

        return run

    calls = (
        batch(lambda: braidsim.simulate(sc, FIXED_RUN, series=False)),
        batch(lambda: braidsim.simulate(taylor, FIXED_RUN, series=False)),
        batch(
            lambda: runner(
                lean.q,
                FIXED_RUN,
                lean.x0,
                lean.v0,
                rtol,
                ATOL_X_PER_RTOL * rtol,
                ATOL_V_PER_RTOL * rtol,
                HMAX,
            )
        ),
    )
    best = interleaved_all(calls, repeats)
    return best[0] / FIXED_BATCH, best[1] / FIXED_BATCH, best[2] / FIXED_BATCH


def part_scipy(sc: Scenario, args: argparse.Namespace) -> None:
    repeats = args.repeats
    from scipy.integrate import solve_ivp

    print(
        f"\n== scipy: braidsim simulate() vs solve_ivp DOP853 with events, "
        f"{args.label} x only, {DURATION} s"
    )
    res = reference(sc)
    q = lean_peer(sc, res).q
    m, load, K, n, D, eps, ha, w, ph, fric, vhat, vmin, vinit = (
        float(v) for v in q[: lean_dp5.Q_SIZE]
    )

    def wall(t: float) -> tuple[float, float, float]:
        c = math.cos(w * t + ph)
        return ha * c, -ha * w * math.sin(w * t + ph), -ha * w * w * c

    def contact(
        t: float, x: float, v: float, mode: int, v0: float
    ) -> tuple[float, float, float, float]:
        h, hd, _ = wall(t)
        p, pd = (h - x, hd - v) if mode < 0 else (x - h - eps, v - hd)
        if p <= 0.0:
            return p, pd, 0.0, 0.0
        fk = K * p**n
        return p, pd, max(fk * (1.0 + D * pd / v0), 0.0), fk

    class Run:
        def __init__(self, rtol: float) -> None:
            self.rtol = rtol
            self.nfev = 0
            self.steps = 0
            self.calls = 0

        def rejected(self) -> float:
            """Rejected steps, derived from the counts: solve_ivp's DOP853 takes 2
            evaluations to start (f(t0) and the initial step guess), 12 per step tried and,
            with events, 3 more per accepted step for the dense output."""
            return (self.nfev - 2 * self.calls - 15 * self.steps) / 12

        def solve(self) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
            t, y = 0.0, np.array([sc["initial.x"], sc["initial.vx"]])
            h0 = wall(0.0)[0]
            mode, v0 = (-1 if y[0] < h0 else 1 if y[0] > h0 + eps else 0), math.inf
            peaks: list[float] = []
            walls: list[float] = []
            if mode:
                v0 = vinit if vinit > 0.0 else math.inf
                peaks.append(contact(0.0, y[0], y[1], mode, v0)[2])
                walls.append(mode)
            armed = True
            while t < DURATION:
                md, vv = mode, v0

                def f(t: float, y: np.ndarray, md: int = md, vv: float = vv) -> list[float]:
                    a = -(fric * math.atan(y[1] / vhat) + load)
                    if md:
                        a -= md * contact(t, y[0], y[1], md, vv)[2]
                    return [y[1], a / m]

                evs: list[Callable[[float, np.ndarray], float]] = []
                if mode == 0:
                    evs = [lambda t, y: y[0] - wall(t)[0], lambda t, y: eps - (y[0] - wall(t)[0])]
                else:
                    evs = [lambda t, y, md=md, vv=vv: contact(t, y[0], y[1], md, vv)[0]]
                    if armed:

                        def slope(t: float, y: np.ndarray, md: int = md, vv: float = vv) -> float:
                            h, hd, hdd = wall(t)
                            a = f(t, y)[1]
                            p, pd, pdd = (
                                (h - y[0], hd - y[1], hdd - a)
                                if md < 0
                                else (y[0] - h - eps, y[1] - hd, a - hdd)
                            )
                            if p <= 0.0:
                                return pd
                            fk = K * p**n
                            return n * fk / p * pd * (1.0 + D * pd / vv) + fk * D * pdd / vv

                        evs.append(slope)
                for e in evs:
                    e.terminal = True  # type: ignore[attr-defined]
                    e.direction = -1  # type: ignore[attr-defined]
                sol = solve_ivp(
                    f,
                    (t, DURATION),
                    y,
                    method="DOP853",
                    rtol=self.rtol,
                    atol=[ATOL_X_PER_RTOL * self.rtol, ATOL_V_PER_RTOL * self.rtol],
                    events=evs,
                    max_step=HMAX,
                )
                self.nfev += sol.nfev
                self.steps += sol.t.size - 1
                self.calls += 1
                if sol.status == -1:
                    raise RuntimeError(sol.message)
                hit = [i for i, te in enumerate(sol.t_events) if te.size]
                if not hit:
                    t, y = DURATION, sol.y[:, -1]
                    if mode:
                        peaks[-1] = max(peaks[-1], contact(t, y[0], y[1], mode, v0)[2])
                    break
                i = hit[0]
                t, y = float(sol.t_events[i][0]), sol.y_events[i][0].copy()
                if mode and i == 1:  # the force peak
                    peaks[-1] = max(peaks[-1], contact(t, y[0], y[1], mode, v0)[2])
                    armed = False
                elif mode:  # exit
                    peaks[-1] = max(peaks[-1], contact(t, y[0], y[1], mode, v0)[2])
                    mode = 0
                else:  # onset: latch the approach speed
                    mode = -1 if i == 0 else 1
                    v0 = max(contact(t, y[0], y[1], mode, 1.0)[1], vmin)
                    peaks.append(0.0)
                    walls.append(mode)
                    armed = True
            return (
                np.array(peaks),
                np.array(walls, dtype=float),
                {"rhs": self.nfev, "steps": self.steps, "rejected": self.rejected()},
            )

    class ScipyPeer(Peer):
        name = "scipy solve_ivp DOP853"

        def run(self, rtol: float) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
            return Run(rtol).solve()

    print(
        "   scipy: plain Python right-hand side; 'rejected' derived from nfev (12 evaluations "
        "per step tried, 3 per accepted step for the dense output the events need, 2 per "
        "restart); DOP853 alone, without dense output and restarts, would take 12 x "
        "(steps + rejected) evaluations"
    )
    compare(
        BraidsimPeer(sc),
        ScipyPeer(),
        res.impacts,
        max(2, repeats // 5),
        tuple(10.0 ** (-6.0 - k / 4.0) for k in range(0, 21)),
    )


class LeanDop853Peer(LeanPeer):
    name = "lean DOP853 loop"

    def runner(self) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
        import lean_dop853

        return lean_dop853.run


def part_dop853(sc: Scenario, args: argparse.Namespace) -> None:
    print(
        f"\n== dop853: what a higher-order pair buys: the lean DP5 loop vs the same loop with "
        f"DOP853 (lean_dop853.py), {args.label} x only, {DURATION} s"
    )
    res = reference(sc)
    lean = lean_peer(sc, res)
    compare(lean, LeanDop853Peer(lean.q, lean.x0, lean.v0), res.impacts, args.repeats)


class LeanTaylorPeer(LeanPeer):
    """The Taylor loop with its DP5 steps chosen by ``switch`` (``lean_taylor.run_taylor``)."""

    name = "hybrid Taylor loop"

    def __init__(
        self,
        q: np.ndarray,
        x0: float,
        v0: float,
        switch: str = "distance",
        exit_steps: bool = False,
    ) -> None:
        super().__init__(q, x0, v0)
        self.switch = switch
        self.exit_steps = exit_steps
        if switch != "distance":
            self.name = f"Taylor, {switch} switch"
        if exit_steps:
            self.name = "Taylor + exit steps"

    def runner(self) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
        import functools

        import lean_taylor

        return functools.partial(
            lean_taylor.run_taylor, switch=self.switch, exit_steps=self.exit_steps
        )

    def stats(self, st: np.ndarray) -> dict[str, float]:
        import lean_taylor

        return {
            # DP5 evaluations plus Taylor steps (one each, though a step is no evaluation)
            "rhs": st[lean_taylor.S_NFEV] + st[lean_taylor.S_TAYLOR],
            "steps": st[lean_taylor.S_ACC],
            "rejected": st[lean_taylor.S_REJ],
            "dp5": st[lean_taylor.S_NFEV],
            "taylor": st[lean_taylor.S_TAYLOR],
            "taylor_contact": st[lean_taylor.S_TAYLOR_CONTACT],
            "taylor_flight": st[lean_taylor.S_TAYLOR_FLIGHT],
            "dp_contact": st[lean_taylor.S_DP_CONTACT],
            "events": st[lean_taylor.S_EV],
            "exit_steps": st[lean_taylor.S_SIGMA],
        }


def part_taylor(sc: Scenario, args: argparse.Namespace) -> None:
    print(
        f"\n== taylor: what a Taylor method buys: the lean DP5 loop vs the hybrid Taylor / DP5 "
        f"loop (lean_taylor.py), {args.label} x only, {DURATION} s"
    )
    print(
        "   hybrid Taylor loop: 'rhs evaluations' = DP5 evaluations + Taylor steps, one each "
        "(a Taylor step is not an evaluation: up to 12 coefficients by recurrences)"
    )
    print(
        "   the DP5 steps where the model's nearest singularity is closer than the DP5 step "
        "('distance'), then where the Taylor step is shorter than it ('step', generic); "
        "then the distance switch against itself with exit steps in sigma = sqrt(p)"
    )
    res = reference(sc)
    lean = lean_peer(sc, res)
    for switch in ("distance", "step"):
        taylor = LeanTaylorPeer(lean.q, lean.x0, lean.v0, switch)
        compare(lean, taylor, res.impacts, args.repeats)
        _taylor_breakdown(taylor, res.impacts)
    # what the exit step buys (lean_taylor.tcoef_sigma), each calibrated on its own
    taylor = LeanTaylorPeer(lean.q, lean.x0, lean.v0)
    exits = LeanTaylorPeer(lean.q, lean.x0, lean.v0, exit_steps=True)
    compare(exits, taylor, res.impacts, args.repeats)
    _taylor_breakdown(exits, res.impacts)


def _taylor_breakdown(taylor: LeanTaylorPeer, ref: Any) -> None:
    """Where the Taylor loop's steps go at each level's calibrated rtol."""
    cal = calibrate(taylor, ref, RTOL_GRID)
    for level in LEVELS:
        c = pick(cal, level)
        if c is None:
            continue
        st = c[2]
        print(
            f"   {taylor.name} at {level:.1e} (rtol {c[0]:.2e}): "
            f"{int(st['taylor'])} Taylor steps ({int(st['taylor_contact'])} in contact, "
            f"{int(st['taylor_flight'])} in flight), {int(st['dp_contact'])} DP5 steps "
            f"(all in contact), {int(st['rejected'])} rejected, {int(st['dp5'])} DP5 "
            f"evaluations, {int(st['events'])} events"
            + (
                f", {int(st['exit_steps'])} of the steps in contact exit steps"
                if taylor.exit_steps
                else ""
            )
        )


class NumbalsodaPeer(Peer):
    name = "numbalsoda DOP853"

    def __init__(self, q: np.ndarray, x0: float, v0: float) -> None:
        import numbalsoda_peer

        self.mod = numbalsoda_peer
        self.q, self.x0, self.v0 = q, x0, v0

    def run(self, rtol: float) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
        ep, st = self.mod.run(
            self.q, DURATION, self.x0, self.v0, rtol, ATOL_X_PER_RTOL * rtol, HMAX
        )
        stats = {"rhs": st[0], "steps": math.nan, "rejected": math.nan}
        return ep[:, lean_dp5.EP_PEAK], ep[:, lean_dp5.EP_WALL], stats


def part_numbalsoda(sc: Scenario, args: argparse.Namespace) -> None:
    repeats = args.repeats
    print(
        f"\n== numbalsoda: braidsim simulate() vs numbalsoda's DOP853 with events, "
        f"{args.label} x only, {DURATION} s"
    )
    try:
        import numbalsoda  # noqa: F401
    except ImportError as exc:
        print(
            f"   numbalsoda is not installed ({exc}); it builds from source with a Fortran "
            "compiler: apt-get install gfortran, then pip install numbalsoda"
        )
        return
    res = reference(sc)
    peer = NumbalsodaPeer(lean_peer(sc, res).q, sc["initial.x"], sc["initial.vx"])
    print(
        "   numbalsoda: solve_ivp (DOP853) called from numba per contact mode, terminal events "
        "at onset, exit and dN/dt = 0 located by its Brent (1e-8 s), onset/exit refined by a "
        "Newton step; one scalar atol; 'steps' not reported by the library"
    )
    compare(BraidsimPeer(sc), peer, res.impacts, repeats)
    print("   with Taylor-series steps (simulation.integrator = taylor):")
    compare(BraidsimPeer(sc, "taylor"), peer, res.impacts, repeats)


def part_batch(sc: Scenario, args: argparse.Namespace) -> None:
    repeats = args.repeats
    from braidsim.batch import simulate_batch

    n = 64
    sets = [{"track.vibration_amplitude": float(h)} for h in np.linspace(0.11e-3, 0.13e-3, n)]
    print(
        f"\n== batch: simulate_batch of {n} one-second {args.label} runs "
        "(h_a 0.11-0.13 mm), one worker"
    )
    for integrator in ("dormand-prince", "taylor"):
        sci = sc.with_overrides({"simulation.integrator": integrator})
        simulate_batch(sci, sets[:1], 0.01)
        best = math.inf
        out = None
        for _ in range(max(1, repeats // 5)):
            c0 = time.process_time()
            out = simulate_batch(sci, sets, 1.0, workers=1)
            best = min(best, time.process_time() - c0)
        assert out is not None
        print(
            f"   {integrator}: {n / best:.1f} one-second runs per CPU second "
            f"({best / n * 1e3:.2f} ms CPU per run; "
            f"median {np.median(out.metrics['steps']):.0f} steps, "
            f"{np.median(out.metrics['rhs_evaluations']):.0f} rhs evaluations per run; "
            f"failed runs: {int(out.failed.sum())})"
        )
    # the yardstick on the same sets at the scenario's tolerances: the lean loop's episodes only
    res = braidsim_call(sc)
    q0 = lean_dp5.lean_params(sc, res.stats["track_stiffness"], res.stats["track_damping_factor"])
    qs = []
    for ov in sets:
        q = q0.copy()
        q[lean_dp5.Q_HA] = ov["track.vibration_amplitude"]
        qs.append(q)
    tol = (sc["simulation.rtol"], sc["simulation.atol_position"], sc["simulation.atol_velocity"])
    # compiled (or loaded from the cache) before the clock starts, as braidsim was above
    lean_dp5.run_lean(qs[0], 0.01, sc["initial.x"], sc["initial.vx"], *tol, HMAX)
    best_l = math.inf
    for _ in range(max(1, repeats // 5)):
        c0 = time.process_time()
        for q in qs:
            lean_dp5.run_lean(q, 1.0, sc["initial.x"], sc["initial.vx"], *tol, HMAX)
        best_l = min(best_l, time.process_time() - c0)
    print(
        f"   the lean DP5 loop on the same sets and tolerances (episodes only, no metrics): "
        f"{n / best_l:.1f} runs per CPU second ({best_l / n * 1e3:.2f} ms per run)"
    )


def part_machine(sc: Scenario, args: argparse.Namespace) -> None:
    repeats = args.repeats
    from braidsim.machine import load_machine_spec, run_machine

    spec = load_machine_spec(ROOT / "examples" / "machine16.toml")
    T = spec.revolution_time
    print(
        f"\n== machine: {spec.name}, {len(spec.loading.carriers)} carriers, one carrier "
        f"revolution ({T:g} s), run_machine(workers=1, frames=0)"
    )
    # the whole run once before the clock starts: a short one does not reach the transfers,
    # and from an empty cache the timed run compiled them (1.1 s against 0.33 s)
    run_machine(spec, duration=T, workers=1, frames=0)
    best = math.inf
    run = None
    for _ in range(max(1, repeats // 5)):
        c0 = time.process_time()
        run = run_machine(spec, duration=T, workers=1, frames=0)
        best = min(best, time.process_time() - c0)
    assert run is not None
    n_tr = run.totals["transfers"]
    print(
        f"   {n_tr} carrier-transfers in {best:.3f} s CPU: "
        f"{n_tr / best:.1f} carrier-transfers per CPU second"
    )


CHILD = """
import resource, sys, time
import braidsim
T, summary = float(sys.argv[1]), sys.argv[2] == "summary"
kw = dict(series=False) if summary else {}
# the default step budget (5e6 steps) ends a 1000-s run at ~950 s: raised for all lengths
sc = braidsim.load_scenario("paper-3.3").with_overrides({"simulation.max_steps": 100_000_000})
# the bare kernel: CPU inside the compiled integrate calls (the driver calls it once per
# chunk of the buffers)
import braidsim.core.driver as driver
kernel = [0.0]
compiled = driver.integrate
def timed(*args):
    c1 = time.process_time()
    status = compiled(*args)
    kernel[0] += time.process_time() - c1
    return status
driver.integrate = timed
braidsim.simulate(sc, 0.01, **kw)
kernel[0] = 0.0
c0 = time.process_time()
r = braidsim.simulate(sc, T, **kw)
c = time.process_time() - c0
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(c, len(r.impacts), r.stats["steps"], rss, kernel[0])
"""


# Prepended to a Python child's code: at exit it writes /proc/self/status, whose VmHWM is the
# peak resident set of the child's own address space. The rusage of a child (os.wait4) is not:
# Linux carries the forking process's peak into the child's ru_maxrss at exec, so a child of
# this process, which has compiled and run the other parts (about 390 MB), reported at least
# that whatever it used itself.
PEAK_HOOK = (
    "import atexit, os\n"
    "def _peak():\n"
    "    if os.path.exists('/proc/self/status'):\n"
    "        with open(os.environ['BENCH_PEAK_FILE'], 'w') as f:\n"
    "            f.write(open('/proc/self/status').read())\n"
    "atexit.register(_peak)\n"
)


def _own_peak_mb(status: str) -> float | None:
    """VmHWM of a /proc/PID/status text [MB]; None where it has none."""
    for line in status.splitlines():
        if line.startswith("VmHWM:"):
            return float(line.split()[1]) / 1024.0
    return None


def child(
    cmd: list[str], env: dict[str, str] | None, timeout: float, mem_gb: float | None
) -> tuple[str, float, float, float, str]:
    """Run ``cmd``; returns (stdout, CPU s of the child, peak RSS MB, wall s, failure or "").

    A Python child (``python -c CODE ...``) reports its own peak RSS (``PEAK_HOOK``); for
    another, or one that did not exit normally, it is the child's ``ru_maxrss``, which
    includes this process's at the fork. The child caches its bytecode as an installed
    package has it (``bench_startup.py``): without PYTHONDONTWRITEBYTECODE."""
    env = dict(os.environ if env is None else env)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    peak_fd, peak_file = tempfile.mkstemp(prefix="braidsim-peak-")
    os.close(peak_fd)
    env["BENCH_PEAK_FILE"] = peak_file
    if len(cmd) >= 3 and cmd[1] == "-c":
        cmd = [cmd[0], "-c", PEAK_HOOK + cmd[2], *cmd[3:]]

    def limit() -> None:
        if mem_gb:
            lim = int(mem_gb * 2**30)
            resource.setrlimit(resource.RLIMIT_AS, (lim, lim))

    try:
        t0 = time.perf_counter()
        with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
            proc = subprocess.Popen(cmd, stdout=out, stderr=err, env=env, preexec_fn=limit)
            deadline = t0 + timeout
            while True:
                pid, status, ru = os.wait4(proc.pid, os.WNOHANG)
                if pid:
                    break
                if time.perf_counter() > deadline:
                    proc.kill()
                    pid, status, ru = os.wait4(proc.pid, 0)
                    break
                time.sleep(0.05)
            wall = time.perf_counter() - t0
            proc.returncode = os.waitstatus_to_exitcode(status)
            out.seek(0)
            err.seek(0)
            text, etext = out.read().decode(), err.read().decode()
        with open(peak_file) as f:
            own_peak = _own_peak_mb(f.read())
    finally:
        os.unlink(peak_file)
    peak = ru.ru_maxrss / 1024.0 if own_peak is None else own_peak
    fail = ""
    if wall > timeout:
        fail = f"did not finish within {timeout:g} s"
    elif proc.returncode != 0:
        last = (etext.strip().splitlines() or ["?"])[-1]
        fail = f"failed (exit {proc.returncode}): {last[:160]}"
        if "MemoryError" in etext or proc.returncode < 0:
            fail = f"did not finish within {mem_gb:g} GB of address space: {last[:120]}"
    return text, ru.ru_utime + ru.ru_stime, peak, wall, fail


def part_memory(sc: Scenario, args: argparse.Namespace) -> None:
    print(
        f"\n== memory: {SCENARIO} runs of 10, 100, 1000 s in subprocesses (limits: "
        f"{args.timeout:g} s, {args.mem_limit_gb:g} GB address space); CPU of the simulate call "
        "(after a 0.01-s warm-up run) and of the compiled kernel inside it, CPU of the whole "
        "child, peak RSS of the child; "
        "simulation.max_steps raised to 1e8 (the default 5e6 ends a 1000-s run at ~950 s)"
    )
    for T in (10.0, 100.0, 1000.0):
        for mode in ("default", "summary"):
            what = (
                "default outputs"
                if mode == "default"
                else "summary only (no samples, no event rows)"
            )
            text, cpu, rss, _, fail = child(
                [sys.executable, "-c", CHILD, str(T), mode], None, args.timeout, args.mem_limit_gb
            )
            if fail:
                print(f"   {T:6g} s, {what:42s}: {fail} (peak RSS {rss:.0f} MB, {cpu:.1f} s CPU)")
                continue
            c, nimp, steps, _, kern = text.split()
            print(
                f"   {T:6g} s, {what:42s}: simulate {float(c):8.2f} s CPU "
                f"({float(c) / float(kern):.2f}x its compiled kernel, {float(kern):.2f} s), "
                f"child {cpu:8.2f} s CPU, peak RSS {rss:8.0f} MB ({nimp} episodes, {steps} steps)"
            )


def part_startup(sc: Scenario, args: argparse.Namespace) -> None:
    cmd = [sys.executable, "-c", "from braidsim.cli import main; main()", "run", SCENARIO, "--json"]
    print(f"\n== startup: `braidsim run {SCENARIO} --json` in a subprocess")
    with tempfile.TemporaryDirectory(prefix="braidsim-numba-") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        _, cpu, rss, wall, fail = child(cmd, env, 600.0, None)
        print(
            f"   cold (empty NUMBA_CACHE_DIR): {cpu:6.2f} s CPU, {wall:6.2f} s wall, "
            f"peak RSS {rss:.0f} MB {fail}"
        )
        warm = [child(cmd, env, 120.0, None) for _ in range(3)]
        cpu_w = min(w[1] for w in warm)
        wall_w = min(w[3] for w in warm)
        print(
            f"   warm (the cache just written), best of 3: {cpu_w:6.2f} s CPU, {wall_w:6.2f} s wall"
        )
        imp = min(
            child([sys.executable, "-c", "import braidsim"], env, 120.0, None)[1] for _ in range(3)
        )
        print(f"   of which `import braidsim` alone: {imp:.2f} s CPU")


PART_FUNCTIONS: dict[str, Callable[[Scenario, argparse.Namespace], None]] = {
    "lean": part_lean,
    "numbalsoda": part_numbalsoda,
    "scipy": part_scipy,
    "dop853": part_dop853,
    "taylor": part_taylor,
    "batch": part_batch,
    "machine": part_machine,
    "memory": part_memory,
    "startup": part_startup,
}


def _refuse(message: str) -> NoReturn:
    print(message, file=sys.stderr)
    sys.exit(2)


def with_settings(sc: Scenario, settings: list[str], parts: list[str]) -> Scenario:
    """``sc`` with the ``--set KEY=VALUE`` overrides (a number where VALUE reads as one);
    one line naming what is wrong and exit code 2 for a malformed or unknown setting."""
    clash = [p for p in parts if p in UNSET_PARTS]
    if clash:
        _refuse(f"--set: not with --part {', '.join(clash)} (they run {SCENARIO} itself)")
    overrides: dict[str, Any] = {}
    for item in settings:
        key, sep, text = item.partition("=")
        if not sep or not key:
            _refuse(f"--set: {item!r}; expected KEY=VALUE, e.g. track.clearance=0.0024")
        try:
            overrides[key] = float(text)
        except ValueError:
            overrides[key] = text
    try:
        return sc.with_overrides(overrides)
    except braidsim.InputError as exc:
        _refuse(f"--set: {exc}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--part", action="append", choices=PARTS, help="run only this part (repeatable)"
    )
    ap.add_argument("--repeats", type=int, default=15, help="timed calls of each (best is kept)")
    ap.add_argument("--timeout", type=float, default=300.0, help="memory part: seconds per child")
    ap.add_argument(
        "--mem-limit-gb",
        type=float,
        default=12.0,
        help="memory part: address-space limit per child [GB]",
    )
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scenario key (repeatable) in the parts run in this process: the "
        "ratios away from paper-3.3 itself (not with machine, memory, startup)",
    )
    args = ap.parse_args()
    parts = args.part or list(PARTS)
    sc = load_scenario(SCENARIO)
    # what the in-process parts run, named in their headers
    args.label = SCENARIO
    if args.set:
        sc = with_settings(sc, args.set, parts)
        args.label = f"{SCENARIO} with {', '.join(args.set)}"
    braidsim_call(sc)  # load the compiled kernel
    print(
        f"braidsim {braidsim.__version__}, numba cache loaded; {os.cpu_count()} cores; "
        "CPU times by time.process_time"
    )
    for p in parts:
        PART_FUNCTIONS[p](sc, args)


if __name__ == "__main__":
    main()
