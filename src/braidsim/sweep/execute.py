"""Running a sweep: chunk tasks, executors (local processes, Dask), resume and progress.

The work is cut into the store's chunks (:meth:`SweepSpec.chunk_region`), one task per chunk.
A task carries only the chunk number and its parameter values; the base scenario travels
once per task as a small payload (once per cluster with Dask). Workers only compute; the
process that runs :func:`run_sweep` is the single writer of the store, so a chunk is written
once, when its task is done.

Executors
---------
* :class:`LocalProcesses` (default): a pool of local processes (forked), all cores
  unless told otherwise; with one process the chunks run in this process. A worker process
  that dies (a crash, the out-of-memory killer) breaks the pool: a new pool is started and
  the chunks that were in flight are run again, each at most ``1 + retries`` times.
* :class:`DaskExecutor`: tasks on a Dask distributed cluster, an existing one
  (``scheduler="tcp://..."``) or a local one started for the sweep (``dask_workers=N``).
  Dask re-runs a task whose worker died; a task that raises is retried ``retries`` times.

A run that fails numerically is not an error of its chunk: it is stored as failed with its
reason (:mod:`braidsim.batch`).
"""

from __future__ import annotations

import math
import os
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from braidsim.batch import (
    METRIC_INDEX,
    METRICS,
    REGIME_FAILED,
    REGIMES,
    RunOptions,
    run_metrics,
    scenario_from_payload,
    scenario_payload,
    typed_metrics,
)
from braidsim.errors import BraidsimError, InputError
from braidsim.model import build_model
from braidsim.sweep.spec import SweepSpec
from braidsim.sweep.store import (
    StoreLock,
    StoreWriter,
    corrupt_chunks,
    create_store,
    done_chunks,
    mark_undone,
    nothing_at,
    remove_partial_files,
    repair_coordinates,
    set_complete,
    store_attrs,
)


class SweepError(BraidsimError, RuntimeError):
    """A chunk task failed more often than allowed (not a numerical failure of a run)."""


@dataclass(frozen=True)
class ChunkTask:
    """The work of one chunk.

    Attributes
    ----------
    chunk : int
        Chunk number.
    keys : tuple of str
        Varied scenario keys.
    runs : list of tuple
        Their values (SI) for each run of the chunk, in C order of the chunk's block.
    duration : float or None
        Simulated time [s] (None: each run's own).
    options : RunOptions
        Window, RMS grid, series.
    """

    chunk: int
    keys: tuple[str, ...]
    runs: list[tuple[Any, ...]]
    duration: float | None
    options: RunOptions


@dataclass(frozen=True)
class ChunkOutput:
    """What a chunk task returns: (runs, metrics) values, failures and series."""

    chunk: int
    values: np.ndarray
    failures: list[str]
    series: np.ndarray | None


def compute_chunk(base: tuple[Any, ...], task: ChunkTask) -> ChunkOutput:
    """Run every parameter set of a chunk (in a worker). Deterministic.

    A parameter combination the scenario rejects (a cross-key check no single axis value
    shows) is recorded as a failed run with that reason, like a numerical failure.
    """
    sc = scenario_from_payload(base)
    opts = task.options
    n = len(task.runs)
    values = np.full((n, len(METRICS)), math.nan)
    series = (
        np.full((n, len(opts.series), opts.series_times.size), math.nan) if opts.series else None
    )
    failures = []
    for i, vals in enumerate(task.runs):
        try:
            model = build_model(
                sc.with_overrides(dict(zip(task.keys, vals, strict=True))), task.duration
            )
        except InputError as exc:
            values[i, METRIC_INDEX["regime"]] = REGIME_FAILED
            failures.append(f"invalid parameters: {exc}")
            continue
        v, s, f = run_metrics(model, opts)
        values[i] = v
        if series is not None and s is not None:
            series[i] = s
        failures.append(f)
    return ChunkOutput(task.chunk, values, failures, series)


OnResult = Callable[[ChunkOutput], None]


class Executor(Protocol):
    """Runs chunk tasks and hands each output to ``on_result`` (in the calling process)."""

    description: str

    def run(self, base: tuple[Any, ...], tasks: Sequence[ChunkTask], on_result: OnResult) -> None:
        """Run all ``tasks``; raise :class:`SweepError` when one fails too often."""


class LocalProcesses:
    """Chunks on local processes; in this process when ``processes == 1``.

    Parameters
    ----------
    processes : int, optional
        Number of worker processes; default all cores (``os.cpu_count()``).
    retries : int
        Extra attempts of a chunk whose task failed or whose worker died.
    mp_context : str, optional
        Start method of the processes; default :func:`braidsim.batch.process_context`.
    task : callable
        The function run per chunk, ``task(base, ChunkTask) -> ChunkOutput`` (picklable;
        tests put in one that fails).
    """

    def __init__(
        self,
        processes: int | None = None,
        retries: int = 2,
        mp_context: str | None = None,
        task: Callable[[tuple[Any, ...], ChunkTask], ChunkOutput] | None = None,
    ) -> None:
        n = (os.cpu_count() or 1) if processes is None else int(processes)
        if processes is not None and n == 0:
            n = os.cpu_count() or 1  # (0: all cores, as the other verbs' --workers 0)
        if n < 1:
            raise InputError(f"--processes: {n} is out of range; allowed >= 0 (0: all cores)")
        self.processes = n
        self.retries = retries
        self.mp_context = mp_context
        self.task = compute_chunk if task is None else task
        self.description = f"local processes ({n})" if n > 1 else "this process"
        self._pool: Any = None

    def _new_pool(self) -> Any:
        import multiprocessing

        from braidsim.batch import process_pool

        ctx = None if self.mp_context is None else multiprocessing.get_context(self.mp_context)
        return process_pool(self.processes, ctx)

    def start(self) -> None:
        """Start the worker processes now.

        :func:`run_sweep` calls this before it opens the store: zarr runs an event-loop
        thread, and a process is forked safely only while it has a single thread.
        """
        if self.processes > 1 and self._pool is None:
            self._pool = self._new_pool()
            self._pool.submit(os.getpid).result()  # launches the workers

    def close(self, kill: bool = False) -> None:
        """Stop the worker processes; with ``kill`` end them now instead of letting the chunk
        tasks in flight finish (an interrupted sweep)."""
        if self._pool is not None:
            if kill:
                # the pool has no public way to stop a running task: end its processes
                for proc in list(getattr(self._pool, "_processes", {}).values()):
                    proc.kill()
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def run(self, base: tuple[Any, ...], tasks: Sequence[ChunkTask], on_result: OnResult) -> None:
        if self.processes == 1:
            for task in tasks:
                self._serial(base, task, on_result)
            return
        try:
            self._run_pool(base, tasks, on_result)
        except BaseException:
            self.close(kill=True)
            raise
        self.close()

    def _serial(self, base: tuple[Any, ...], task: ChunkTask, on_result: OnResult) -> None:
        for attempt in range(self.retries + 1):
            try:
                out = self.task(base, task)
            except Exception as exc:  # a bug or a resource error: try again, then give up
                if attempt == self.retries:
                    raise SweepError(
                        f"chunk {task.chunk} failed {attempt + 1} times: {exc!r}"
                    ) from exc
                continue
            on_result(out)
            return

    def _run_pool(
        self, base: tuple[Any, ...], tasks: Sequence[ChunkTask], on_result: OnResult
    ) -> None:
        from concurrent.futures import FIRST_COMPLETED, Future, wait
        from concurrent.futures.process import BrokenProcessPool

        pending = deque(tasks)
        attempts: dict[int, int] = {}
        inflight: dict[Future[ChunkOutput], ChunkTask] = {}

        def again(task: ChunkTask, why: str) -> None:
            attempts[task.chunk] = attempts.get(task.chunk, 0) + 1
            if attempts[task.chunk] > self.retries:
                raise SweepError(f"chunk {task.chunk} failed {attempts[task.chunk]} times: {why}")
            pending.appendleft(task)

        self.start()
        while pending or inflight:
            broken = False
            while pending and len(inflight) < 2 * self.processes:
                task = pending.popleft()
                try:
                    inflight[self._pool.submit(self.task, base, task)] = task
                except BrokenProcessPool:  # a worker died since the last wait
                    pending.appendleft(task)
                    broken = True
                    break
            done: set[Future[ChunkOutput]] = set()
            if inflight and not broken:
                done, _ = wait(list(inflight), return_when=FIRST_COMPLETED)
            for fut in done:
                task = inflight.pop(fut)
                try:
                    out = fut.result()
                except BrokenProcessPool:
                    broken = True
                    again(task, "a worker process died")
                except Exception as exc:
                    again(task, repr(exc))
                else:
                    on_result(out)
            if broken:
                # every task still in flight on the broken pool is lost: run it again
                for task in inflight.values():
                    again(task, "a worker process died")
                inflight.clear()
                self.close()
                self.start()


class DaskExecutor:
    """Chunks as tasks of a Dask distributed cluster.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``).
    workers : int, optional
        Start a local cluster of this many single-threaded worker processes instead.
    retries : int
        Retries of a task that raised (a task whose worker died is re-run by the scheduler).
    client : distributed.Client, optional
        Use this client (tests; the caller closes it).
    task : callable
        The function run per chunk (as for :class:`LocalProcesses`).
    """

    def __init__(
        self,
        scheduler: str | None = None,
        workers: int | None = None,
        retries: int = 2,
        client: Any = None,
        task: Callable[[tuple[Any, ...], ChunkTask], ChunkOutput] | None = None,
    ) -> None:
        self.scheduler = scheduler
        self.workers = workers
        self.retries = retries
        self.client = client
        self.task = compute_chunk if task is None else task
        if client is not None:
            self.description = "dask (given client)"
        elif scheduler is not None:
            self.description = f"dask scheduler {scheduler}"
        else:
            if workers is None or workers < 1:
                raise InputError(f"--workers: {workers} is out of range; allowed >= 1")
            self.description = f"local dask cluster ({workers} workers)"

    def _connect(self) -> tuple[Any, list[Any]]:
        try:
            import logging

            from distributed import Client, LocalCluster
        except ImportError:  # pragma: no cover - dask is installed with the test extras
            raise InputError(
                "--workers/--scheduler: need dask.distributed; pip install 'braidsim[dask]'"
            ) from None
        if self.client is not None:
            return self.client, []
        if self.scheduler is not None:
            import dask

            saved = {k: dask.config.get(k, None) for k in ("scheduler", "scheduler-address")}
            try:
                client = Client(self.scheduler, timeout="20s")
            except Exception as exc:  # a bad address raises ValueError, TypeError or OSError
                # leave no trace of the failed client: a half-made one left as the default
                # (or in dask's config) would be picked up by a later dask computation of
                # this process, xarray's netCDF writer included
                dask.config.set(saved)
                import gc

                gc.collect()
                text = str(exc).splitlines()[0][:120] if str(exc) else exc.__class__.__name__
                raise InputError(
                    f"--scheduler: cannot connect to {self.scheduler!r} ({text}); allowed the "
                    "address of a running Dask scheduler, e.g. tcp://host:8786"
                ) from None
            return client, [client]
        from braidsim.batch import start_resource_tracker

        start_resource_tracker()  # before the cluster's processes need it (see there)
        cluster = LocalCluster(
            n_workers=self.workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",  # a free port (None means 8787, maybe taken)
            silence_logs=logging.ERROR,
        )
        client = Client(cluster)
        return client, [client, cluster]

    _conn: tuple[Any, list[Any]] | None = None
    #: seconds to wait for the client and the local cluster to close
    CLOSE_TIMEOUT = 10.0

    def start(self) -> None:
        """Connect to the cluster (or start the local one) now: :func:`run_sweep` calls this
        before it creates the store, so a failed connection leaves no empty store behind."""
        if self._conn is None:
            self._conn = self._connect()

    def close(self) -> None:
        """Close what :meth:`start` opened (a client, a local cluster), waiting at most
        :attr:`CLOSE_TIMEOUT` seconds for each: after a signal killed its workers a local
        cluster could wait for them forever (1 of 10 SIGHUPs sent to the process group)."""
        if self._conn is not None:
            for obj in self._conn[1]:
                try:
                    obj.close(timeout=self.CLOSE_TIMEOUT)
                except Exception:  # the store is written (or resumable) either way
                    pass
            self._conn = None

    def run(self, base: tuple[Any, ...], tasks: Sequence[ChunkTask], on_result: OnResult) -> None:
        from distributed import as_completed

        if self._conn is None:
            self._conn = self._connect()
        client = self._conn[0]
        try:
            # the base scenario (a few kB) goes inside each task, not scattered once: a
            # scattered object has no recipe, and distributed's active memory manager
            # drops a broadcast's extra replicas within seconds (ReduceReplicas), so a
            # killed worker could take the last copy with it and every task on it was
            # cancelled ("already forgotten"); inline, a lost worker only re-runs its tasks
            futs = {
                client.submit(self.task, base, t, retries=self.retries, pure=False): t
                for t in tasks
            }
            for fut in as_completed(list(futs)):
                task = futs[fut]
                try:
                    out = fut.result()
                except Exception as exc:
                    raise SweepError(
                        f"chunk {task.chunk} failed after {self.retries} retries: {exc!r}"
                    ) from exc
                on_result(out)
                fut.release()
        finally:
            self.close()


def _tasks(spec: SweepSpec, chunks: Iterable[int]) -> list[ChunkTask]:
    out = []
    for c in chunks:
        keys, runs = spec.chunk_runs(c)
        out.append(ChunkTask(c, keys, runs, spec.duration, spec.options))
    return out


class _Progress:
    """A rich progress bar on stderr: runs done, throughput, time left."""

    def __init__(self, total: int, done: int, enabled: bool) -> None:
        self.enabled = enabled
        self.t0 = time.perf_counter()
        self.runs_now = 0
        if not enabled:
            return
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self.bar = Progress(
            TextColumn("sweep"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("runs"),
            TextColumn("{task.fields[rate]}"),
            TextColumn("elapsed"),
            TimeElapsedColumn(),
            TextColumn("left"),
            TimeRemainingColumn(),
            console=Console(stderr=True),
            transient=False,
            # no refresh thread: the sweep process stays single-threaded, so its worker
            # processes can be forked (braidsim.batch.process_context)
            auto_refresh=False,
        )
        self.task = self.bar.add_task("sweep", total=total, completed=done, rate="")
        self.bar.start()
        self.bar.refresh()

    def advance(self, n: int) -> None:
        self.runs_now += n
        if self.enabled:
            dt = time.perf_counter() - self.t0
            rate = f"{self.runs_now / dt:.3g} runs/s" if dt > 0 else ""
            self.bar.update(self.task, advance=n, rate=rate)
            self.bar.refresh()

    def stop(self) -> None:
        if self.enabled:
            self.bar.stop()


def run_sweep(
    spec: SweepSpec,
    store: str | Path,
    *,
    resume: bool = False,
    processes: int | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    executor: Executor | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Run a sweep into a zarr store; finish an interrupted one with ``resume=True``.

    Parameters
    ----------
    spec : SweepSpec
        From :func:`braidsim.sweep.load_spec`.
    store : str or Path
        The zarr store (a folder).
    resume : bool
        Finish the chunks a previous run of the same spec left undone. Without it an
        existing store is an error; with it, a path with no store yet starts a new one
        (``braidsim sweep --resume`` says so on stderr).
    processes : int, optional
        Local worker processes (default: all cores).
    workers : int, optional
        Start a local Dask cluster of this many workers.
    scheduler : str, optional
        Run on the Dask cluster at this address.
    executor : Executor, optional
        Any object with ``run(base, tasks, on_result)`` (overrides the three above).
    progress : bool
        Show a progress bar on stderr.

    Returns
    -------
    dict
        Summary (the JSON of ``braidsim sweep --json``): store, dimensions, runs, chunks
        computed now and before, failed runs, regime counts, time and throughput.

    Raises
    ------
    InputError
        Bad executor options, an existing store without ``resume``, or a store made from
        another spec.
    SweepError
        A chunk task failed more than ``retries`` times.
    """
    path = Path(store)
    if executor is None:
        if workers is not None and scheduler is not None:
            raise InputError(
                "--workers/--scheduler: give one of them (a local cluster or an existing one)"
            )
        if (workers is not None or scheduler is not None) and processes is not None:
            raise InputError("--processes: applies to the local executor, not to a Dask cluster")
        if workers is not None or scheduler is not None:
            executor = DaskExecutor(scheduler=scheduler, workers=workers, retries=spec.retries)
        else:
            executor = LocalProcesses(processes, retries=spec.retries)
    from braidsim.io import check_output_target

    check_output_target(path, "--out", directory=True)
    if not nothing_at(path):  # (an empty folder holds nothing to lose: it is written)
        if not (path / "zarr.json").is_file():  # (a run folder, or any other folder)
            raise InputError(
                f"--out: {path} exists and is not a sweep store; allowed a new or empty "
                "folder, or a sweep store to finish with --resume"
            )
        if not resume:
            raise InputError(
                f"--out: {path} exists; pass --resume to finish it, or choose another path"
            )
        store_attrs(path)  # a store, before any worker starts
    start = getattr(executor, "start", None)
    if start is not None:
        start()  # before the first zarr call (see LocalProcesses.start)
    try:
        t0, n_before, runs_before, todo, failed = _execute(spec, path, executor, progress)
    finally:
        close = getattr(executor, "close", None)
        if close is not None:
            close()
    elapsed = time.perf_counter() - t0
    runs_now = spec.n_runs - runs_before
    return {
        "store": str(path),
        "spec": str(spec.path) if spec.path else None,
        "dims": dict(zip(spec.dims, spec.shape, strict=True)),
        "runs": spec.n_runs,
        "chunks": spec.n_chunks,
        "chunks_done_before": n_before,
        "chunks_computed": len(todo),
        "runs_computed": runs_now,
        "failed_runs_computed": failed,
        "executor": executor.description,
        "elapsed_s": elapsed,
        "runs_per_second": runs_now / elapsed if runs_now and elapsed > 0 else None,
        **summarize_store(path),
    }


def _spec_differences(old_text: str, new_text: str) -> list[str]:
    """The entries where two sweep specs' TOML texts differ, named as the spec's validation
    names them (``axes[1].num``: dotted paths, list entries by 0-based index); empty when
    the old text cannot be read."""
    import tomllib

    try:
        old, new = tomllib.loads(old_text), tomllib.loads(new_text)
    except tomllib.TOMLDecodeError:
        return []

    def flat(d: Any, prefix: str = "") -> dict[str, Any]:
        out: dict[str, Any] = {}
        if isinstance(d, dict):
            for k, v in d.items():
                out.update(flat(v, f"{prefix}{k}."))
        elif isinstance(d, list) and d and all(isinstance(e, dict) for e in d):
            for i, e in enumerate(d):
                out.update(flat(e, f"{prefix[:-1]}[{i}]."))
        else:
            out[prefix[:-1]] = d
        return out

    a, b = flat(old), flat(new)
    return sorted(k for k in a.keys() | b.keys() if a.get(k) != b.get(k))


def _execute(
    spec: SweepSpec, path: Path, executor: Executor, progress: bool
) -> tuple[float, int, int, list[int], int]:
    """Open or create the store, run the chunks not done, write each as it finishes.

    Returns (start time, chunks done before, runs done before, chunks run now, failed runs).
    """
    if not nothing_at(path):
        import braidsim

        attrs = store_attrs(path)
        if attrs.get("spec_sha256") != spec.digest():
            differ = _spec_differences(str(attrs.get("spec", "")), spec.text)
            where = f" (it differs in {', '.join(differ)})" if differ else ""
            raise InputError(
                f"--resume: {path} was made from a different spec{where}; allowed the same spec"
            )
        made_by = attrs.get("braidsim_version")
        if made_by is not None and made_by != braidsim.__version__:
            raise InputError(
                f"--resume: {path} was made by braidsim {made_by} and this is "
                f"{braidsim.__version__}: its chunks would mix two versions' results; allowed "
                "the same version (or run the sweep into a new store)"
            )
        lock = StoreLock(path)
    else:
        create_store(spec, path)
        lock = StoreLock(path)
    try:
        return _execute_locked(spec, path, executor, progress)
    finally:
        lock.release()


def _execute_locked(
    spec: SweepSpec, path: Path, executor: Executor, progress: bool
) -> tuple[float, int, int, list[int], int]:
    import sys

    remove_partial_files(path)
    bad = corrupt_chunks(path)
    if bad:
        sys.stderr.write(
            f"braidsim: note: {len(bad)} chunk(s) of {path} fail their checksum "
            f"(first: chunk {next(iter(bad))}); computing them again\n"
        )
        mark_undone(path, sorted(bad))
    fixed = repair_coordinates(path, spec)
    if fixed:
        sys.stderr.write(
            f"braidsim: note: the coordinate array(s) {', '.join(map(repr, fixed))} of {path} "
            "failed their checksum or differed from the spec; written again\n"
        )
    done = done_chunks(path)
    todo = [int(c) for c in np.flatnonzero(~done)]
    n_before = int(done.sum())
    runs_before = sum(_chunk_size(spec, int(c)) for c in np.flatnonzero(done))
    writer = StoreWriter(path, spec)
    bar = _Progress(spec.n_runs, runs_before, progress)
    counts = {"failed": 0}

    def on_result(out: ChunkOutput) -> None:
        block = tuple(r.stop - r.start for r in spec.chunk_region(out.chunk))
        typed = typed_metrics(out.values)
        vals = {k: v.reshape(block) for k, v in typed.items()}
        fail = np.array(out.failures, dtype=object).reshape(block)
        ser = {}
        if out.series is not None:
            for k, name in enumerate(spec.options.series):
                ser[name] = out.series[:, k].reshape(*block, -1)
        writer.write_chunk(out.chunk, vals, fail, ser)
        counts["failed"] += int(np.count_nonzero(typed["regime"] == REGIME_FAILED))
        bar.advance(len(out.failures))

    t0 = time.perf_counter()
    if todo:
        set_complete(path, False)
    try:
        executor.run(scenario_payload(spec.base), _tasks(spec, todo), on_result)
    finally:
        bar.stop()
    if done_chunks(path).all():
        set_complete(path, True)
    return t0, n_before, runs_before, todo, counts["failed"]


def _chunk_size(spec: SweepSpec, chunk: int) -> int:
    return int(np.prod([r.stop - r.start for r in spec.chunk_region(chunk)]))


def summarize_store(path: str | Path) -> dict[str, Any]:
    """Regime counts and failed runs of a store (over the chunks done)."""
    from braidsim.sweep.store import open_sweep

    ds = open_sweep(path)
    out: dict[str, Any] = {}
    if "regime" in ds:
        r = np.asarray(ds["regime"].values).ravel()
        out["regimes"] = {name: int(np.count_nonzero(r == i)) for i, name in enumerate(REGIMES)}
    fail = np.asarray(ds["failure"].values).astype(object).ravel()
    failed = fail[fail != ""]
    out["failed_runs"] = int(failed.size)
    if failed.size:
        # the most common reason, for the summary line (every run's is in `failure`)
        reasons, counts = np.unique(failed.astype(str), return_counts=True)
        out["failure_example"] = str(reasons[int(np.argmax(counts))])
    out["complete"] = bool(done_chunks(path).all())
    return out
