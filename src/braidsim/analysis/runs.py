"""Many steady-state runs, in this process or over local worker processes.

Bifurcation diagrams and basins need, per parameter set, the stroboscopic samples of the
settled motion *at that run's own excitation phase* (the sampling times depend on omega_h and
on the vibration phase, both of which can be swept) and the contact episodes (rule 3 of
:mod:`braidsim.analysis.regimes` needs the longest contact). :func:`braidsim.batch.simulate_batch`
takes one list of sample times for all runs and reduces the episodes to counts, so this module
runs :func:`braidsim.analysis.regimes.steady_state` per set instead, reusing the batch
engine's validated-scenario payloads and process start method. Runs are independent and
deterministic: the same set gives the same bits in any process, order or chunk.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from braidsim.analysis.regimes import (
    DEFAULT_CYCLES,
    DEFAULT_MAX_PERIOD,
    DEFAULT_PERIOD_TOL,
    DEFAULT_TRANSIENT_CYCLES,
    SteadyState,
    check_window_options,
    failed_steady_state,
    reference_period,
    steady_state,
    strobe_times,
)
from braidsim.errors import InputError, SimulationError
from braidsim.params import Scenario


def _options(
    transient_cycles: float, cycles: int, strobe_phase: float, period_tol: float, max_period: int
) -> dict[str, Any]:
    return {
        "transient_cycles": transient_cycles,
        "cycles": cycles,
        "strobe_phase": strobe_phase,
        "period_tol": period_tol,
        "max_period": max_period,
    }


def _run_one(sc: Scenario, overrides: Mapping[str, Any], opts: Mapping[str, Any]) -> SteadyState:
    try:
        return steady_state(sc, overrides, **opts)
    except SimulationError as exc:
        T = reference_period(sc.with_overrides(overrides))
        st = strobe_times(
            sc.with_overrides(overrides),
            opts["transient_cycles"] * T,
            opts["cycles"],
            opts["strobe_phase"],
        )
        return failed_steady_state(overrides, str(exc), (float(st[0]), float(st[-1])), T)


def _run_chunk(
    payload: tuple[Any, ...], sets: Sequence[Mapping[str, Any]], opts: Mapping[str, Any]
) -> list[SteadyState]:
    """Worker-process entry: rebuild the base scenario and run its share of the sets."""
    from braidsim.batch import scenario_from_payload

    base = scenario_from_payload(payload)
    return [_run_one(base, ov, opts) for ov in sets]


def run_steady_states(
    base: Scenario,
    parameter_sets: Sequence[Mapping[str, Any]],
    *,
    transient_cycles: float = DEFAULT_TRANSIENT_CYCLES,
    cycles: int = DEFAULT_CYCLES,
    strobe_phase: float = 0.0,
    period_tol: float = DEFAULT_PERIOD_TOL,
    max_period: int = DEFAULT_MAX_PERIOD,
    workers: int = 1,
    on_done: Callable[[int], None] | None = None,
) -> list[SteadyState]:
    """The :class:`~braidsim.analysis.regimes.SteadyState` of every parameter set.

    Every set is validated before any run starts. A run that fails numerically gives a
    record with ``regime.label == "failed"`` and the reason, the others go on.

    Parameters
    ----------
    base : Scenario
        The base scenario.
    parameter_sets : sequence of mappings
        ``{dotted key: value}`` per run, on top of ``base``.
    transient_cycles, cycles, strobe_phase, period_tol, max_period
        As in :func:`braidsim.analysis.regimes.steady_state`.
    workers : int
        Local processes; 1 runs here, 0 or less uses all cores.
    on_done : callable, optional
        Called with the number of runs just finished (progress displays).

    If the caller is interrupted (KeyboardInterrupt, e.g. Ctrl-C or a SIGTERM that the
    command line turns into one), the worker processes are terminated before the exception
    goes on: none is left running.

    Raises
    ------
    InputError
        A bad set (with its index) or option.
    """
    from braidsim.batch import check_parameter_sets, check_workers, local_processes

    check_window_options(transient_cycles, cycles, period_tol, max_period)
    check_workers(workers)
    if not math.isfinite(strobe_phase):
        raise InputError(f"strobe_phase: {strobe_phase!r} rad is out of range; allowed finite")
    sets = check_parameter_sets(parameter_sets)
    for i, ov in enumerate(sets):
        try:
            base.with_overrides(ov)
        except InputError as exc:
            raise InputError(f"parameter set {i}: {exc}") from None
    opts = _options(transient_cycles, cycles, strobe_phase, period_tol, max_period)
    nw = max(1, min(local_processes(workers), len(sets)))
    done = on_done or (lambda n: None)
    if nw == 1:
        res = []
        for ov in sets:
            res.append(_run_one(base, ov, opts))
            done(1)
        return res
    from concurrent.futures import as_completed

    from braidsim.batch import process_pool, scenario_payload

    n = len(sets)
    k = min(n, 4 * nw)  # interleaved slices balance costs that vary along the sets
    payload = scenario_payload(base)
    out: list[SteadyState | None] = [None] * n
    pool = process_pool(nw)
    try:
        futs = {pool.submit(_run_chunk, payload, sets[j::k], opts): j for j in range(k)}
        for fut in as_completed(futs):
            j = futs[fut]
            chunk = fut.result()
            for i, st in zip(range(j, n, k), chunk, strict=True):
                out[i] = st
            done(len(chunk))
    except BaseException:
        _stop(pool)
        raise
    pool.shutdown()
    return [s for s in out if s is not None]


def _stop(pool: Any) -> None:
    """Cancel what has not started and end the worker processes now (not after they
    finish their current chunk, which is what ``shutdown`` alone waits for). SIGKILL: a
    worker holds nothing to save, and a forked worker would turn SIGTERM into a
    KeyboardInterrupt traceback of its own (it inherits the command line's handler).

    Last, the pool's manager thread is joined: it notices the dead workers and closes its
    wake-up pipe, and while it still runs as the interpreter exits, the exit handler of
    :mod:`concurrent.futures` writes to that pipe without the pool's lock: a close between
    its test and its write raises there, a traceback after the command's line ("OSError:
    [Errno 9] Bad file descriptor" in about 1 in 20 signals to ``bifurcation --workers 2``
    under load; with that window widened by a delay, in every run of a pool stopped this
    way, and in none with the join; CPython gh-105829, gh-132969). ``shutdown(wait=False)``
    forgets the thread, so it is taken first."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        if p.is_alive():
            p.kill()
    for p in procs:
        p.join(5.0)
    if manager is not None:
        manager.join(10.0)
