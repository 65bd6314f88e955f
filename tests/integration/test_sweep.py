"""`braidsim sweep`: values equal single simulate calls, kill/resume, Dask, bad specs, plots."""

from __future__ import annotations

import functools
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import braidsim
from braidsim import InputError
from braidsim.batch import REGIMES
from braidsim.cli import main
from braidsim.sweep import (
    LocalProcesses,
    compute_chunk,
    done_chunks,
    load_spec,
    open_sweep,
    parse_spec,
    plot_sweep,
    run_sweep,
)
from braidsim.sweep.spec import chunk_shape_for, draw_samples

SPEC = """
scenario = "paper-3.3"
duration = "0.06 s"

[[axes]]
key = "horn_gear.angular_velocity"
name = "omega"
values = ["120 rpm", "240 rpm"]

[[axes]]
key = "track.vibration_amplitude"
name = "h_a"
start = "0.06 mm"
stop = "0.18 mm"
num = 3

[metrics]
window = ["0.02 s", "0.06 s"]

[series]
variables = ["x", "track_contact_force"]
start = "0.05 s"
stop = "0.06 s"
num = 5

[execution]
chunk_size = 2
"""


def write(tmp: Path, text: str, name: str = "spec.toml") -> Path:
    p = tmp / name
    p.write_text(textwrap.dedent(text))
    return p


def run_app(argv: list[str]) -> int:
    """The command line in this process; its exit code."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    return int(exc.value.code or 0)


def files(store: Path) -> dict[str, bytes]:
    """Every file of a store (relative path -> bytes)."""
    return {
        str(p.relative_to(store)): p.read_bytes() for p in sorted(store.rglob("*")) if p.is_file()
    }


@pytest.fixture(scope="module")
def local_store(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("sweep")
    spec = load_spec(write(tmp, SPEC))
    run_sweep(spec, tmp / "local.zarr", processes=1, progress=False)
    return tmp / "local.zarr"


def test_sweep_values_equal_single_simulate_calls(local_store):
    ds = open_sweep(local_store)
    assert ds["regime"].dims == ("omega", "h_a")
    assert ds.sizes == {"omega": 2, "h_a": 3, "t": 5}
    assert ds["h_a"].attrs["units"] == "m"
    np.testing.assert_allclose(ds["h_a"].values, [6e-5, 1.2e-4, 1.8e-4])
    params = json.loads(ds.attrs["parameters"])
    assert params["track.clearance"] == 3e-3 and params["carrier.mass"] == 1.2
    for omega in ds["omega"].values:
        for h_a in ds["h_a"].values[[0, 2]]:
            # the coordinates hold the exact SI values the runs used
            sc = braidsim.load_scenario(
                "paper-3.3",
                overrides={
                    "horn_gear.angular_velocity": float(omega),
                    "track.vibration_amplitude": float(h_a),
                },
            )
            cell = ds.sel(omega=omega, h_a=h_a)
            res = braidsim.simulate(
                sc, duration=0.06, windows=[(0.02, 0.06)], sample_times=cell["t"].values
            )
            imp = res.impacts
            onsets = imp[~imp["initial"] & (imp["t"] >= 0.02) & (imp["pair"] == "track")]
            assert int(cell["track_inner_impacts"]) == int((onsets["wall"] == "inner").sum())
            assert int(cell["track_outer_impacts"]) == int((onsets["wall"] == "outer").sum())
            r = res.ranges_dict("track", 1)
            assert float(cell["track_max_contact_force"]) == pytest.approx(
                max(-r["contact_force"][0], r["contact_force"][1]), rel=1e-12
            )
            assert float(cell["track_max_depth"]) == pytest.approx(
                max(-r["depth"][0], r["depth"][1]), rel=1e-12
            )
            assert float(cell["final_x"]) == pytest.approx(res.final["x"], rel=1e-12, abs=0)
            assert float(cell["final_vx"]) == pytest.approx(res.final["vx"], rel=1e-12, abs=0)
            sample = res.series["kind"] == 0
            np.testing.assert_allclose(cell["x"].values, res.series["x"][sample], rtol=1e-12)
            assert str(cell["failure"].values) == ""


def test_kill_and_resume_gives_the_same_store(tmp_path, local_store):
    """SIGKILL a sweep process mid-way; --resume finishes it; the store equals an
    uninterrupted run's, file for file, and no chunk done before the kill is written again."""
    spec_path = write(
        tmp_path,
        SPEC.replace("chunk_size = 2", "chunk_size = 1").replace(
            'values = ["120 rpm", "240 rpm"]',
            'values = ["105 rpm", "120 rpm", "135 rpm", "240 rpm"]',
        ),
    )
    ref = tmp_path / "ref.zarr"
    run_sweep(load_spec(spec_path), ref, processes=1, progress=False)
    store = tmp_path / "killed.zarr"
    cmd = [
        sys.executable,
        "-m",
        "braidsim",
        "sweep",
        str(spec_path),
        "--out",
        str(store),
        "--processes",
        "1",
        "--no-progress",
    ]
    log = tmp_path / "stderr.txt"
    with (
        log.open("wb") as err,
        subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err) as proc,
    ):
        flags = store / "_sweep" / "done" / "c"
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:
            if flags.is_dir() and len(list(flags.iterdir())) >= 2:
                break
            time.sleep(0.005)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert proc.returncode == -signal.SIGKILL, log.read_text()
    done_before = done_chunks(store)
    assert 2 <= done_before.sum() < done_before.size, "the kill came too late to test resume"
    before = {p: p.stat().st_mtime_ns for p in store.rglob("*") if p.is_file() and "/c/" in str(p)}
    # without --resume an existing store is refused
    with pytest.raises(InputError, match="--resume"):
        run_sweep(load_spec(spec_path), store, processes=1, progress=False)
    summary = run_sweep(load_spec(spec_path), store, resume=True, processes=1, progress=False)
    assert summary["chunks_computed"] == done_before.size - done_before.sum()
    assert summary["complete"]
    assert files(store) == files(ref)
    # chunk files of the chunks done before the kill were not written again
    spec = load_spec(spec_path)
    for c in np.flatnonzero(done_before):
        region = spec.chunk_region(int(c))
        key = ".".join(str(r.start // s) for r, s in zip(region, spec.chunk_shape, strict=True))
        p = store / "regime" / "c" / Path(*key.split("."))
        assert p.stat().st_mtime_ns == before[p]


def test_a_whole_float_num_is_a_count(tmp_path):
    """TOML's `num = 3.0` is the count 3 (it was refused as an empty range)."""
    spec = load_spec(write(tmp_path, SPEC.replace("num = 3", "num = 3.0")))
    assert spec.shape == load_spec(write(tmp_path, SPEC)).shape


def test_processes_0_is_all_cores():
    """`--processes 0` is all cores, as `--workers 0` of the other verbs (it was refused)."""
    from braidsim.sweep.execute import LocalProcesses

    assert LocalProcesses(0).processes == (os.cpu_count() or 1)
    with pytest.raises(InputError, match=r"--processes: -3 is out of range; allowed >= 0"):
        LocalProcesses(-3)


def test_resume_refuses_another_spec(tmp_path, local_store):
    other = load_spec(write(tmp_path, SPEC.replace("num = 3", "num = 4")))
    with pytest.raises(InputError, match=r"different spec \(it differs in axes\[1\]\.num\)"):
        run_sweep(other, local_store, resume=True, processes=1, progress=False)


def test_resume_where_there_is_no_store_starts_one_and_says_so(tmp_path, capsys, local_store):
    """A script may pass --resume every time: with no store yet the sweep starts there,
    and one line on stderr says so (it was silent)."""
    spec = write(tmp_path, SPEC)
    store = tmp_path / "new.zarr"
    argv = ["sweep", str(spec), "--out", str(store), "--processes", "1", "--resume", "--json"]
    assert run_app(argv) == 0
    out, err = capsys.readouterr()
    said = f"--resume: there is no store at {store} yet; a new sweep is started there"
    assert err == f"braidsim: note: {said}\n"
    assert json.loads(out)["chunks_done_before"] == 0
    assert files(store) == files(local_store)
    assert run_app(argv) == 0  # now a finished store: nothing to say, nothing to compute
    out, err = capsys.readouterr()
    assert err == "" and json.loads(out)["chunks_computed"] == 0


def test_spec_differences_name_axes_as_the_spec_check_does():
    """A resumed store's spec differences said ``axes.2.num`` (1-based), the spec's own
    checks ``axes[1].num``: one form."""
    from braidsim.sweep.execute import _spec_differences

    assert _spec_differences(SPEC, SPEC.replace("num = 3", "num = 4")) == ["axes[1].num"]


def test_resume_refuses_a_store_of_another_version(tmp_path, local_store, monkeypatch):
    """Chunks of two versions of braidsim would mix two versions' results in one store."""
    import braidsim

    made_by = re.escape(braidsim.__version__)
    monkeypatch.setattr(braidsim, "__version__", "0.0.9")
    spec = load_spec(write(tmp_path, SPEC))
    with pytest.raises(InputError, match=rf"made by braidsim {made_by} and this is 0\.0\.9"):
        run_sweep(spec, local_store, resume=True, processes=1, progress=False)


def test_dask_local_cluster_equals_local_run(tmp_path, local_store):
    """--scheduler ADDRESS: the chunks run as tasks of an existing Dask cluster."""
    distributed = pytest.importorskip("distributed")
    spec = load_spec(write(tmp_path, SPEC))
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=":0"
    ) as cluster:
        summary = run_sweep(
            spec, tmp_path / "dask.zarr", scheduler=cluster.scheduler_address, progress=False
        )
    assert summary["executor"].startswith("dask scheduler")
    assert files(tmp_path / "dask.zarr") == files(local_store)


def _fail_once(marker: str, base, task):
    """compute_chunk, except that chunk 1 raises the first time."""
    if task.chunk == 1 and not Path(marker).exists():
        Path(marker).write_text("x")
        raise OSError("worker lost its scratch disk")
    return compute_chunk(base, task)


def test_dask_retries_a_failing_chunk(tmp_path, local_store):
    distributed = pytest.importorskip("distributed")
    from braidsim.sweep import DaskExecutor

    marker = tmp_path / "failed-once"
    spec = load_spec(write(tmp_path, SPEC))
    with (
        distributed.LocalCluster(
            n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0"
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        ex = DaskExecutor(client=client, retries=1, task=functools.partial(_fail_once, str(marker)))
        run_sweep(spec, tmp_path / "d.zarr", executor=ex, progress=False)
    assert marker.exists()
    assert files(tmp_path / "d.zarr") == files(local_store)


@pytest.mark.slow
def test_cli_workers_starts_a_local_dask_cluster(tmp_path, capsys, local_store):
    """--workers 2: a local cluster of two worker processes; the same store."""
    pytest.importorskip("distributed")
    store = tmp_path / "w.zarr"
    code = run_app(
        ["sweep", str(write(tmp_path, SPEC)), "--out", str(store), "--workers", "2", "--json"]
    )
    assert code == 0
    assert json.loads(capsys.readouterr().out)["executor"] == "local dask cluster (2 workers)"
    assert files(store) == files(local_store)


def _crash_once(marker: str, base, task):
    """compute_chunk, except that the worker running chunk 1 dies the first time."""
    if task.chunk == 1 and not Path(marker).exists():
        Path(marker).write_text("x")
        os._exit(1)
    return compute_chunk(base, task)


def test_process_pool_equals_local_run_and_retries_a_dead_worker(tmp_path, local_store):
    """Two worker processes give the same store; a worker killed mid-chunk (os._exit)
    breaks the pool, and the chunk is run again on a new one."""
    marker = tmp_path / "crashed-once"
    spec = load_spec(write(tmp_path, SPEC))
    ex = LocalProcesses(2, retries=2, task=functools.partial(_crash_once, str(marker)))
    run_sweep(spec, tmp_path / "pool.zarr", executor=ex, progress=False)
    assert marker.exists()
    assert files(tmp_path / "pool.zarr") == files(local_store)


def _broken(base, task):
    if task.chunk == 2:
        raise RuntimeError("disk full")
    return compute_chunk(base, task)


def test_chunk_failing_too_often_stops_the_sweep_and_keeps_done_chunks(tmp_path):
    from braidsim.sweep import SweepError

    spec = load_spec(write(tmp_path, SPEC))
    with pytest.raises(SweepError, match=r"chunk 2 failed 3 times.*disk full"):
        run_sweep(
            spec, tmp_path / "s.zarr", executor=LocalProcesses(1, task=_broken), progress=False
        )
    done = done_chunks(tmp_path / "s.zarr")
    assert done[:2].all() and not done[2]


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            ('key = "track.vibration_amplitude"', 'key = "track.vibration_amplitud"'),
            "did you mean 'track.vibration_amplitude'",
        ),
        (("num = 3", "num = 0"), "empty range"),
        (("num = 3", "num = 1"), "num: 1 value runs start only \\(stop 0.18 mm would not"),
        (('stop = "0.18 mm"', 'stop = "0.06 mm"'), "empty range"),
        (("num = 3", "num = 2.5"), "num: 2.5 is not a whole number"),
        (
            ("[metrics]", '[overrides]\n"track.vibration_amplitude" = "0.1 mm"\n\n[metrics]'),
            "overrides.track.vibration_amplitude: also an axis",
        ),
        (
            (
                'start = "0.06 mm"\nstop = "0.18 mm"\nnum = 3',
                'start = "0.06 mm"\nstop = "0.01 mm"\nnum = 1',
            ),
            "reversed range",
        ),
        # the values as written beside SI's (bare SI numbers read as another size)
        (
            ('start = "0.06 mm"\nstop = "0.18 mm"', 'start = "0.18 mm"\nstop = "0.06 mm"'),
            r"stop: 0.06 mm \(6e-05 m\) is below start \(0.18 mm; 0.00018 m\)",
        ),
        (
            ('start = "0.06 mm"', 'start = "0.06 s"'),
            r"start \(track.vibration_amplitude\).*wrong unit",
        ),
        (('values = ["120 rpm", "240 rpm"]', "values = []"), "empty"),
        (('values = ["120 rpm", "240 rpm"]', 'values = ["120 rpm", "-5 rpm"]'), "out of range"),
        (('window = ["0.02 s", "0.06 s"]', 'window = ["0.02 s", "1 s"]'), "metrics.window"),
        (('window = ["0.02 s", "0.06 s"]', 'window = ["0.02 mm", "0.06 s"]'), "metrics.window"),
        (("[metrics]", '[metrics]\nkeep = ["regime", "max_force"]'), "unknown metric 'max_force'"),
        (('variables = ["x", "track_contact_force"]', 'variables = ["xx"]'), "did you mean 'x'"),
        (("chunk_size = 2", "chunk_sise = 2"), "did you mean 'chunk_size'"),
        (('[[axes]]\nkey = "horn', '[[axis]]\nkey = "horn'), "did you mean 'axes'"),
        (('scenario = "paper-3.3"', 'scenario = "paper-3.33"'), "did you mean 'paper-3.3'"),
    ],
)
def test_bad_spec_is_rejected_before_any_work(tmp_path, capsys, change, message):
    text = SPEC.replace(*change)
    assert text != SPEC
    spec_path = write(tmp_path, text)
    with pytest.raises(InputError, match=message):
        load_spec(spec_path)
    # the command line: exit code 2, one line on stderr, no store created
    code = run_app(["sweep", str(spec_path), "--out", str(tmp_path / "s.zarr"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "s.zarr").exists()


def test_cli_sweep_json_plot_and_netcdf(tmp_path, capsys, local_store):
    spec_path = write(tmp_path, SPEC)
    store = tmp_path / "cli.zarr"
    nc = tmp_path / "cli.nc"
    code = run_app(
        [
            "sweep",
            str(spec_path),
            "--out",
            str(store),
            "--processes",
            "1",
            "--json",
            "--netcdf",
            str(nc),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0
    summary = json.loads(out)
    assert summary["runs"] == 6 and summary["chunks"] == 4 and summary["complete"]  # blocks (1, 2)
    assert summary["dims"] == {"omega": 2, "h_a": 3}
    assert sum(summary["regimes"].values()) == 6 and set(summary["regimes"]) == set(REGIMES)
    assert files(store) == files(local_store)
    import xarray as xr

    with xr.open_dataset(nc, engine="scipy") as back:
        ds = open_sweep(store)
        np.testing.assert_array_equal(
            back["track_max_contact_force"].values, ds["track_max_contact_force"].values
        )
        np.testing.assert_array_equal(back["x"].values, ds["x"].values)
    heat = tmp_path / "heat.png"
    assert (
        run_app(
            [
                "sweep-plot",
                str(store),
                "--metric",
                "regime",
                "--x",
                "omega",
                "--y",
                "h_a",
                "--unit",
                "omega=rpm",
                "--unit",
                "h_a=mm",
                "--out",
                str(heat),
            ]
        )
        == 0
    )
    line = tmp_path / "line.png"
    assert (
        run_app(
            [
                "sweep-plot",
                str(store),
                "--metric",
                "track_max_contact_force",
                "--x",
                "h_a",
                "--sel",
                "omega=240 rpm",
                "--log",
                "--out",
                str(line),
            ]
        )
        == 0
    )
    assert heat.stat().st_size > 1000 and line.stat().st_size > 1000
    capsys.readouterr()
    assert (
        run_app(["sweep-plot", str(store), "--metric", "regime", "--x", "h_a", "--out", str(line)])
        == 2
    )
    assert "--sel: fix the dimensions omega" in capsys.readouterr().err


def _netcdf_engines() -> list[str | None]:
    import xarray as xr

    # None: xarray's default engine (h5netcdf here, a dependency); scipy writes netCDF-3
    return [None, *(["scipy"] if "scipy" in xr.backends.list_engines() else [])]


def _same_values(a, b) -> None:
    for name in a.variables:
        x, y = np.asarray(a[name].values), np.asarray(b[name].values)
        if x.dtype.kind in "OTU":  # strings: netCDF gives them back as object or fixed width
            assert x.astype(object).tolist() == y.astype(object).tolist(), name
        else:
            np.testing.assert_array_equal(x, y, err_msg=name)


def test_the_open_store_is_saved_by_xarrays_to_netcdf(tmp_path, local_store):
    """The Dataset that xarray.open_zarr or open_sweep gives is saved by xarray's own
    to_netcdf, with the default engine and with netCDF-3 (scipy): a boolean root attribute
    (``complete``) and lists of names (``dims``, ``arrays``) were refused."""
    import xarray as xr

    opened = {
        "open_zarr": xr.open_zarr(local_store, consolidated=False),
        "open_sweep": open_sweep(local_store),
    }
    for how, ds in opened.items():
        for engine in _netcdf_engines():
            nc = tmp_path / f"{how}-{engine}.nc"
            ds.to_netcdf(nc, engine=engine)
            with xr.open_dataset(nc, engine=engine) as back:
                _same_values(ds, back)
                assert back.attrs["complete"] == 1 and back.attrs["dims"] == "omega h_a"
                assert back.attrs["spec_sha256"] == ds.attrs["spec_sha256"]


def test_a_store_of_format_2_is_read_saved_and_resumed(tmp_path, local_store):
    """A store written before format 3 (``complete`` a boolean, ``dims`` and ``arrays``
    lists) is read by open_sweep, whose Dataset has the format-3 attributes and goes to
    netCDF; --resume accepts it and sets ``complete`` to 1."""
    import shutil

    import xarray as xr
    import zarr

    old = tmp_path / "old.zarr"
    shutil.copytree(local_store, old)
    meta = json.loads((old / "zarr.json").read_text())
    a = meta["attributes"]
    a.update(
        format="braidsim-sweep/2",
        complete=False,
        dims=a["dims"].split(),
        arrays=a["arrays"].split(),
    )
    (old / "zarr.json").write_text(json.dumps(meta))
    # a failed run's reason, so that a non-empty string goes to netCDF too
    zarr.open_group(str(old), mode="r+")["failure"][0, 1] = "max_steps (5000000) reached"
    ds = open_sweep(old)
    assert ds.attrs["complete"] == 0 and ds.attrs["arrays"].split()[-3:] == [
        "failure",
        "x",
        "track_contact_force",
    ]
    assert str(ds["failure"].values[0, 1]) == "max_steps (5000000) reached"
    for engine in _netcdf_engines():
        nc = tmp_path / f"old-{engine}.nc"
        ds.to_netcdf(nc, engine=engine)
        with xr.open_dataset(nc, engine=engine) as back:
            _same_values(ds, back)
    spec = load_spec(write(tmp_path, SPEC))
    summary = run_sweep(spec, old, resume=True, processes=1, progress=False)
    assert summary["complete"] and summary["chunks_computed"] == 0
    attrs = zarr.open_group(str(old), mode="r").attrs
    assert attrs["complete"] == 1 and not isinstance(attrs["complete"], bool)
    assert attrs["format"] == "braidsim-sweep/2"


def test_latin_hypercube_samples_fill_every_stratum():
    n = 50
    u = draw_samples("latin_hypercube", n, 3, seed=7)
    for j in range(3):
        assert sorted(np.floor(u[:, j] * n).astype(int)) == list(range(n))
    np.testing.assert_array_equal(u, draw_samples("latin_hypercube", n, 3, seed=7))
    assert not np.array_equal(u, draw_samples("latin_hypercube", n, 3, seed=8))


def test_sampled_sweep_has_a_run_dimension(tmp_path):
    spec = parse_spec(
        {
            "scenario": "paper-3.3",
            "duration": "0.02 s",
            "samples": {
                "method": "latin_hypercube",
                "n": 4,
                "seed": 3,
                "ranges": {
                    "track.clearance": {"low": "1 mm", "high": "4 mm", "spacing": "log"},
                    "track": {"vibration_amplitude": {"low": "0.05 mm", "high": "0.2 mm"}},
                },
            },
            "metrics": {"keep": ["regime", "track_max_contact_force"]},
        }
    )
    run_sweep(spec, tmp_path / "s.zarr", processes=1, progress=False)
    ds = open_sweep(tmp_path / "s.zarr")
    assert ds["regime"].dims == ("run",)
    assert set(ds.data_vars) == {"regime", "track_max_contact_force", "failure"}
    c = ds["track.clearance"].values
    assert ds["track.clearance"].attrs["units"] == "m" and np.all((c >= 1e-3) & (c <= 4e-3))
    b = braidsim.batch.simulate_batch(
        "paper-3.3",
        [
            {
                "track.clearance": float(c[i]),
                "track.vibration_amplitude": float(ds["track.vibration_amplitude"][i]),
            }
            for i in range(4)
        ],
        0.02,  # the default metrics window, as a sweep's: the second half of the run
    )
    np.testing.assert_array_equal(b.windows, [[0.01, 0.02]] * 4)
    np.testing.assert_array_equal(
        ds["track_max_contact_force"].values, b.metrics["track_max_contact_force"]
    )
    fig = plot_sweep(
        ds, "track_max_contact_force", x="track.clearance", y="track.vibration_amplitude"
    )
    assert fig.axes


def test_the_chunking_rule_of_docs_sweeps_md():
    """docs/sweeps.md's example: 17 x 25 runs, at most 64 per chunk, blocks of 2 x 25 (50
    runs), 9 chunks (it said chunks hold 64 to 256 runs)."""
    spec = load_spec(Path(__file__).parents[2] / "examples" / "sweep_ha_omega.toml")
    assert spec.shape == (17, 25) and spec.chunk_shape == (2, 25) and spec.n_chunks == 9
    doc = (Path(__file__).parents[2] / "docs" / "sweeps.md").read_text()
    assert "blocks of 2 x 25 = 50 runs, 9 chunks, the last of 25" in " ".join(doc.split())


def test_chunks_are_contiguous_blocks():
    assert chunk_shape_for((17, 25), 64) == (2, 25)
    assert chunk_shape_for((17, 25), 10) == (1, 10)
    assert chunk_shape_for((3, 4, 5), 40) == (2, 4, 5)
    assert chunk_shape_for((7,), 100) == (7,)
