"""Faults injected into sweeps and outputs: kills at chosen points (during a chunk write
too), SIGTERM and SIGHUP, a full disk, two writers on one store, a flipped bit, stale
temporaries, a dead Dask worker. After each, the store resumes to the bytes of an
uninterrupted sweep, no worker process outlives its sweep, and every message is one line.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from braidsim.errors import StoreError
from braidsim.sweep import done_chunks, load_spec, open_sweep, run_sweep
from fuzz.harness import RECORD, judge, run_cli

SPEC = """
scenario = "paper-3.3"
duration = "0.03 s"

[[axes]]
key = "horn_gear.angular_velocity"
name = "omega"
values = ["105 rpm", "120 rpm", "135 rpm", "240 rpm"]

[[axes]]
key = "track.vibration_amplitude"
name = "h_a"
start = "0.06 mm"
stop = "0.18 mm"
num = 3

[metrics]
window = ["0.01 s", "0.03 s"]

[series]
variables = ["x", "track_contact_force"]
start = "0.02 s"
stop = "0.03 s"
num = 200

[execution]
chunk_size = 1
"""

#: a sweep process whose zarr chunk writes are counted: it kills itself (SIGKILL, which no
#: handler sees) right after the Nth array write, or sleeps SLOW seconds per chunk computed
WRAPPER = """
import os, signal, sys, time
import zarr
kill_after = int(os.environ.get("KILL_AFTER_WRITES", "0"))
slow = float(os.environ.get("SLOW_CHUNK_S", "0"))
count = [0]
writing = [False]
orig = zarr.Array.__setitem__
def counted(self, key, value):
    orig(self, key, value)
    if writing[0]:
        count[0] += 1
        if kill_after and count[0] >= kill_after:
            os.kill(os.getpid(), signal.SIGKILL)
zarr.Array.__setitem__ = counted
import braidsim.sweep.store as st
init = st.StoreWriter.__init__
def counting_init(self, *a, **k):
    init(self, *a, **k)
    writing[0] = True  # count chunk writes only, not the creation of the store
st.StoreWriter.__init__ = counting_init
if slow:
    import braidsim.sweep.execute as ex
    real = ex.compute_chunk
    def slow_chunk(base, task):
        time.sleep(slow)
        return real(base, task)
    ex.compute_chunk = slow_chunk
if __name__ == "__main__":  # Dask's nannies spawn: the main module is imported again
    from braidsim.cli import main
    main(sys.argv[1:])
"""


def files(store: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(store)): p.read_bytes() for p in sorted(store.rglob("*")) if p.is_file()
    }


@pytest.fixture(scope="module")
def spec_path(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("faults")
    p = d / "spec.toml"
    p.write_text(textwrap.dedent(SPEC))
    (d / "wrapper.py").write_text(WRAPPER)
    return p


@pytest.fixture(scope="module")
def reference(spec_path) -> Path:
    ref = spec_path.parent / "ref.zarr"
    run_sweep(load_spec(spec_path), ref, processes=1, progress=False)
    return ref


def sweep_cmd(spec_path: Path, store: Path, *extra: str) -> list[str]:
    return [
        sys.executable,
        str(spec_path.parent / "wrapper.py"),
        "sweep",
        str(spec_path),
        "--out",
        str(store),
        "--no-progress",
        *extra,
    ]


def _children(pid: int) -> list[int]:
    import psutil

    try:
        return [c.pid for c in psutil.Process(pid).children(recursive=True)]
    except psutil.NoSuchProcess:
        return []


def _gone(pids: list[int], timeout: float = 20.0) -> bool:
    import psutil

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        alive = []
        for p in pids:
            try:
                if psutil.Process(p).status() != psutil.STATUS_ZOMBIE:
                    alive.append(p)
            except psutil.NoSuchProcess:
                pass
        if not alive:
            return True
        time.sleep(0.1)
    return False


# 27 arrays are written per chunk here (x, force, failure, 24 metrics) plus its done flag;
# the counts below land inside the first chunk, inside a later chunk, and on a done flag
@pytest.mark.parametrize("kill_after", [3, 40, 56])
def test_sigkill_during_a_chunk_write_then_resume_is_bit_identical(
    kill_after, spec_path, reference, tmp_path
):
    store = tmp_path / "killed.zarr"
    env = {**os.environ, "KILL_AFTER_WRITES": str(kill_after)}
    proc = subprocess.run(
        sweep_cmd(spec_path, store, "--processes", "1"), env=env, capture_output=True, timeout=300
    )
    assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()[-500:]
    done = done_chunks(store)
    assert not done.all()
    summary = run_sweep(load_spec(spec_path), store, resume=True, processes=1, progress=False)
    assert summary["complete"]
    assert files(store) == files(reference)
    RECORD.add(f"sigkill-after-{kill_after}-writes", None)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_signal_stops_workers_says_one_line_and_the_store_resumes(
    sig, spec_path, reference, tmp_path
):
    store = tmp_path / "sig.zarr"
    env = {**os.environ, "SLOW_CHUNK_S": "0.3"}
    with subprocess.Popen(
        sweep_cmd(spec_path, store, "--processes", "2"),
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    ) as proc:
        flags = store / "_sweep" / "done" / "c"
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if flags.is_dir() and len(list(flags.iterdir())) >= 2:
                break
            time.sleep(0.02)
        workers = _children(proc.pid)
        assert workers, "no worker processes seen"
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    text = err.decode()
    why = judge(proc.returncode, out.decode(), text, (128 + int(sig),), ("--resume",))
    RECORD.add(f"sweep-{signal.Signals(sig).name}", why)
    assert why is None, why
    assert signal.Signals(sig).name in text
    assert _gone(workers), "worker processes outlived the sweep"
    run_sweep(load_spec(spec_path), store, resume=True, processes=1, progress=False)
    assert files(store) == files(reference)


def test_sigkill_of_the_sweep_leaves_no_worker_behind(spec_path, tmp_path):
    store = tmp_path / "orphans.zarr"
    env = {**os.environ, "SLOW_CHUNK_S": "0.3"}
    with subprocess.Popen(
        sweep_cmd(spec_path, store, "--processes", "2"),
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    ) as proc:
        deadline = time.monotonic() + 120
        workers: list[int] = []
        while time.monotonic() < deadline and len(workers) < 2:
            workers = _children(proc.pid)
            time.sleep(0.05)
        assert len(workers) >= 2
        time.sleep(0.5)
        proc.kill()
        proc.wait()
    ok = _gone(workers)
    RECORD.add("sweep-SIGKILL-orphans", None if ok else "workers alive")
    assert ok, "worker processes outlived a SIGKILLed sweep"


def test_second_writer_is_refused_while_the_first_runs(spec_path, reference, tmp_path):
    store = tmp_path / "two.zarr"
    env = {**os.environ, "SLOW_CHUNK_S": "0.2"}
    with subprocess.Popen(
        sweep_cmd(spec_path, store, "--processes", "1"),
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    ) as first:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (store / "zarr.json").exists():
            time.sleep(0.02)
        for argv, needle in (
            (
                ["sweep", str(spec_path), "--out", str(store), "--resume", "--no-progress"],
                "another",
            ),
            (["sweep", str(spec_path), "--out", str(store), "--no-progress"], "--resume"),
        ):
            code, out, err = run_cli(argv)
            why = judge(code, out, err, (2,), (needle,))
            RECORD.add(f"second-writer-{needle}", why)
            assert why is None, why
        _, err1 = first.communicate(timeout=300)
    assert first.returncode == 0, err1.decode()
    assert files(store) == files(reference)


@pytest.mark.parametrize("fsize", [2000, 40000])
def test_full_disk_is_one_line_with_the_path_and_the_store_resumes(fsize, spec_path, tmp_path):
    """A file-size limit (RLIMIT_FSIZE) makes writes fail as on a full disk (EFBIG): at 2 kB
    the store's metadata cannot be written (no store is left, and none is offered to
    resume), at 40 kB the first series chunk (about 68 kB: four runs of 3,000 samples)
    cannot, while the store's files made at its creation (the 22-kB time coordinate the
    largest) can: the store is kept and resumes to the uninterrupted bytes. (At 12 kB, which
    this test used before, the time coordinate itself failed, no store was kept, and the
    message offered a --resume of nothing.)"""
    import resource

    big = spec_path.parent / "big_series.toml"
    big.write_text(
        textwrap.dedent(SPEC)
        .replace("num = 200", "num = 3000")
        .replace("chunk_size = 1", "chunk_size = 4")
    )
    ref = spec_path.parent / "big_ref.zarr"
    if not ref.exists():
        run_sweep(load_spec(big), ref, processes=1, progress=False)
    store = tmp_path / "full.zarr"

    def limit() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of a signal
        resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    proc = subprocess.run(
        sweep_cmd(big, store, "--processes", "1"),
        preexec_fn=limit,
        capture_output=True,
        timeout=300,
    )
    err = proc.stderr.decode()
    why = judge(proc.returncode, proc.stdout.decode(), err, (1,), (str(store),))
    RECORD.add(f"sweep-full-disk-{fsize}", why)
    assert why is None, why
    if fsize < 5000:
        assert not store.exists()
        assert [p.name for p in tmp_path.iterdir()] == []  # no hidden temporary either
        assert "--resume" not in err and "no store was written" in err
        return
    assert store.exists() and "--resume" in err
    run_sweep(load_spec(big), store, resume=True, processes=1, progress=False)
    assert files(store) == files(ref)


def test_flipped_bit_is_detected_on_read_and_recomputed_on_resume(spec_path, reference, tmp_path):
    import shutil

    store = tmp_path / "flip.zarr"
    shutil.copytree(reference, store)
    chunk = store / "x" / "c" / "1" / "2" / "0"
    data = bytearray(chunk.read_bytes())
    data[len(data) // 3] ^= 0x10
    chunk.write_bytes(bytes(data))
    with pytest.raises(StoreError, match="checksum"):
        open_sweep(store)
    summary = run_sweep(load_spec(spec_path), store, resume=True, processes=1, progress=False)
    assert summary["chunks_computed"] == 1
    assert files(store) == files(reference)
    RECORD.add("flipped-bit", None)


@pytest.mark.parametrize("coordinate", ["omega", "h_a", "t"])
@pytest.mark.parametrize("damage", ["flip", "missing"])
def test_a_damaged_coordinate_is_refused_on_read_and_written_again_on_resume(
    coordinate, damage, spec_path, reference, tmp_path
):
    """The coordinates (the grid's axes, the series' times) carry checksums too: a flipped
    bit was read back as another parameter value (0.00277 as 4.97e+305), and a missing file
    as zeros, without error; --resume left them so."""
    import shutil

    store = tmp_path / "coord.zarr"
    shutil.copytree(reference, store)
    chunk = store / coordinate / "c" / "0"
    if damage == "flip":
        data = bytearray(chunk.read_bytes())
        data[len(data) // 2] ^= 0x08
        chunk.write_bytes(bytes(data))
    else:
        chunk.unlink()
    with pytest.raises(StoreError, match=f"coordinate array '{coordinate}'"):
        open_sweep(store)
    summary = run_sweep(load_spec(spec_path), store, resume=True, processes=1, progress=False)
    assert summary["chunks_computed"] == 0
    assert files(store) == files(reference)
    RECORD.add(f"coordinate-{damage}", None)


def test_stale_temporaries_of_dead_processes_are_removed(spec_path, tmp_path):
    from braidsim.io import atomic_write_text

    dead = 2**22 + 12345  # above the default pid_max of 4194304: never a live process
    stale_store = tmp_path / f".s.zarr.creating-{dead}-abcdef01"
    stale_store.mkdir()
    stale_file = tmp_path / f".f.txt.braidsim-{dead}-xyz.tmp"
    stale_file.write_text("x")
    live = tmp_path / f".f.txt.braidsim-{os.getpid()}-live.tmp"
    live.write_text("x")
    spec = load_spec(spec_path)
    run_sweep(spec, tmp_path / "s.zarr", processes=1, progress=False)
    atomic_write_text(tmp_path / "f.txt", "y")
    assert not stale_store.exists() and not stale_file.exists()
    assert live.exists()  # a live process's temporary is left alone
    RECORD.add("stale-temporaries", None)


def test_run_out_is_whole_or_absent(tmp_path, monkeypatch):
    """A failure while `run --out` writes leaves the earlier output untouched, no temporary."""
    out = tmp_path / "r"
    code, _, err = run_cli(["run", "paper-3.1", "--duration", "0.01 s", "--out", str(out)])
    assert code == 0, err
    before = files(out)
    import braidsim.plotting

    def boom(*a, **k):
        raise OSError(28, "No space left on device", str(out))

    monkeypatch.setattr(braidsim.plotting, "run_figures", boom)
    code, o, err = run_cli(["run", "paper-3.1", "--duration", "0.02 s", "--out", str(out)])
    why = judge(code, o, err, (1,), (str(out),))
    RECORD.add("run-out-failure", why)
    assert why is None, why
    assert files(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r"]


@pytest.mark.parametrize("verb", ["run", "continue"])
def test_a_full_disk_while_an_output_folder_is_written_is_one_line_naming_it(verb, tmp_path):
    """A file-size limit under the netCDF4 files (a run's series, 1.6 MB for 0.2 s of
    paper-3.3; a continuation's branch, 14 kB): HDF5 met the failed write inside its own
    file driver, h5py printed hundreds of lines of "Exception ignored" tracebacks and the
    process ended with a segmentation fault (exit 139). Now: exit 1, one line naming the
    file under --out and the cause, the earlier output untouched, no temporary left."""
    import resource

    out = tmp_path / "o"
    if verb == "run":
        argv = ["run", "paper-3.3", "--duration", "0.2 s", "--out", str(out)]
        fsize = 300_000
    else:
        spec = tmp_path / "c.toml"
        spec.write_text(
            textwrap.dedent(
                """
                scenario = "paper-3.3"
                [continuation]
                parameter = "track.vibration_amplitude"
                from = "0.05 mm"
                to = "0.06 mm"
                max_points = 3
                method = "fd"
                """
            )
        )
        argv = ["continue", str(spec), "--out", str(out), "--quiet"]
        fsize = 8_000
    code, _, err = run_cli(argv)
    assert code == 0, err
    before = files(out)

    def limit() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of a signal
        resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    proc = subprocess.run(
        [sys.executable, "-m", "braidsim", *argv],
        preexec_fn=limit,
        capture_output=True,
        timeout=300,
    )
    err = proc.stderr.decode(errors="replace")
    why = judge(proc.returncode, proc.stdout.decode(), err, (1,), (str(out) + os.sep,))
    RECORD.add(f"{verb}-out-full-disk", why)
    assert why is None, why
    assert ".braidsim-" not in err  # the output's own name, not a temporary's
    assert files(out) == before
    assert sorted(p.name for p in tmp_path.iterdir() if p.name != "c.toml") == ["o"]


@pytest.mark.slow
def test_dask_worker_killed_mid_sweep(spec_path, reference, tmp_path):
    """A Dask worker process killed mid-sweep: the scheduler re-runs its tasks and the store
    equals an uninterrupted one."""
    import logging
    import threading

    import psutil
    from distributed import Client, LocalCluster

    from braidsim.sweep import DaskExecutor

    cluster = LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",
        silence_logs=logging.CRITICAL,
    )
    client = Client(cluster)
    try:
        pids = list(client.run(os.getpid).values())  # the worker processes
        store = tmp_path / "dask.zarr"

        def killer() -> None:
            flags = store / "_sweep" / "done" / "c"
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline:
                if flags.is_dir() and len(list(flags.iterdir())) >= 2:
                    break
                time.sleep(0.01)
            os.kill(pids[0], signal.SIGKILL)

        t = threading.Thread(target=killer)
        t.start()
        run_sweep(load_spec(spec_path), store, executor=DaskExecutor(client=client), progress=False)
        t.join()
        assert not psutil.pid_exists(pids[0]) or psutil.Process(pids[0]).status() == "zombie"
        assert files(store) == files(reference)
        np.testing.assert_array_equal(
            open_sweep(store)["regime"].values, open_sweep(reference)["regime"].values
        )
        RECORD.add("dask-worker-killed", None)
    finally:
        client.close()
        cluster.close()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_signal_stops_the_workers_of_an_analysis_verb(sig, tmp_path):
    """`bifurcation --workers 2` (a process pool of the analysis layer): one line, the
    signal's exit code, no worker left, no output written."""
    out = tmp_path / "bif"
    cmd = [
        sys.executable,
        "-m",
        "braidsim",
        "bifurcation",
        "paper-3.3",
        "--param",
        "track.vibration_amplitude",
        "--from",
        "0.05 mm",
        "--to",
        "0.3 mm",
        "--points",
        "40",
        "--workers",
        "2",
        "--out",
        str(out),
    ]
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE) as proc:
        deadline = time.monotonic() + 120
        workers: list[int] = []
        while time.monotonic() < deadline and len(workers) < 2 and proc.poll() is None:
            workers = _children(proc.pid)
            time.sleep(0.05)
        assert len(workers) >= 2, "no worker processes seen"
        time.sleep(0.3)
        proc.send_signal(sig)
        o, e = proc.communicate(timeout=60)
    why = judge(proc.returncode, o.decode(), e.decode(), (128 + int(sig),), ("interrupted",))
    RECORD.add(f"bifurcation-{signal.Signals(sig).name}", why)
    assert why is None, why
    assert _gone(workers), "worker processes outlived the command"
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_two_new_sweeps_racing_to_one_path(spec_path, tmp_path, monkeypatch):
    """The sweep that loses the final rename of a new store is refused with a message."""
    import braidsim.sweep.store as store_mod
    from braidsim.errors import InputError

    target = tmp_path / "race.zarr"
    real = os.rename

    def other_sweep_wins(src, dst):
        Path(dst).mkdir()
        (Path(dst) / "zarr.json").write_text("{}")
        real(src, dst)

    monkeypatch.setattr(store_mod.os, "rename", other_sweep_wins)
    with pytest.raises(InputError, match="another process"):
        run_sweep(load_spec(spec_path), target, processes=1, progress=False)
    assert [p.name for p in tmp_path.iterdir()] == ["race.zarr"]  # no temporary left
    RECORD.add("two-new-sweeps-race", None)


def _crash_on_first_try(marker_dir: str, task_chunk_ids: tuple[int, ...], base, task):
    """compute_chunk, except that the worker running one of the given chunks dies (as the
    out-of-memory killer would leave it) the first time."""
    from braidsim.sweep import compute_chunk

    marker = Path(marker_dir) / f"crashed-{task.chunk}"
    if task.chunk in task_chunk_ids and not marker.exists():
        marker.write_text("x")
        os._exit(1)
    return compute_chunk(base, task)


@pytest.mark.parametrize(
    "attempt", [0, pytest.param(1, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow)]
)
def test_dead_pool_workers_are_replaced_every_time(attempt, spec_path, reference, tmp_path):
    """Workers dying at different moments (also while the next chunk is being submitted to
    the broken pool) never abort the sweep: the chunks are run again on a new pool."""
    import functools

    from braidsim.sweep import LocalProcesses

    crash = ((1, 6), (0, 11), (4, 5))[attempt]
    ex = LocalProcesses(
        2, retries=3, task=functools.partial(_crash_on_first_try, str(tmp_path), crash)
    )
    store = tmp_path / "pool.zarr"
    run_sweep(load_spec(spec_path), store, executor=ex, progress=False)
    assert all((tmp_path / f"crashed-{c}").exists() for c in crash)
    assert files(store) == files(reference)
    RECORD.add(f"dead-pool-workers-{attempt}", None)


@pytest.mark.slow
def test_sigterm_of_a_sweep_on_a_local_dask_cluster(spec_path, reference, tmp_path):
    """SIGTERM to `sweep --workers 2` (a local Dask cluster): one line, exit code 143, no
    nanny or worker process left, and the store resumes to the uninterrupted bytes."""
    store = tmp_path / "dask.zarr"
    env = {**os.environ, "SLOW_CHUNK_S": "0.5"}
    with subprocess.Popen(
        sweep_cmd(spec_path, store, "--workers", "2"),
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    ) as proc:
        flags = store / "_sweep" / "done" / "c"
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if flags.is_dir() and len(list(flags.iterdir())) >= 1:
                break
            time.sleep(0.05)
        workers = _children(proc.pid)
        assert workers
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=120)
    why = judge(proc.returncode, out.decode(), err.decode(), (143,), ("--resume",))
    RECORD.add("dask-sweep-SIGTERM", why)
    assert why is None, why
    assert _gone(workers)
    run_sweep(load_spec(spec_path), store, resume=True, processes=1, progress=False)
    assert files(store) == files(reference)
