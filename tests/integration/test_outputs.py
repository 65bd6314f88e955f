"""What a run leaves behind: the xarray/netCDF series, provenance in every output, the
version, compact and tidy output files, and the steady-state windows of the analysis verbs."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import braidsim
from braidsim.cli import main
from braidsim.sweep.spec import parse_spec

ROOT = Path(__file__).resolve().parents[2]


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main(list(argv))
    out, err = capsys.readouterr()
    return int(exc.value.code or 0), out, err


@pytest.fixture(scope="module")
def transfer_run() -> braidsim.Result:
    """paper-3.2 with a transfer at 20 ms: events at sample times and a state jump."""
    sc = braidsim.load_scenario("paper-3.2", overrides={"transfer.times": [0.02]})
    return braidsim.simulate(sc, duration=0.05)


# ------------------------------------------------------------------ to_xarray / series.nc


def test_xarray_time_index_is_unique_and_increasing(transfer_run) -> None:
    res = transfer_run
    t = res.series["t"]
    assert np.any(np.diff(t) == 0)  # the raw series repeats times (start, end, transfer)
    ds = res.to_xarray()
    ti = ds.indexes["t"]
    assert ti.is_unique and ti.is_monotonic_increasing
    assert ds["t"].values[0] == 0.0 and ds["t"].values[-1] == pytest.approx(0.05)
    assert ds.sizes["t"] == np.unique(t).size

    # nothing is lost: every row is on t or on the event dimension, every event on event
    def rows(tt, kk, xx):
        return set(zip(tt.tolist(), kk.astype(int).tolist(), xx.tolist(), strict=True))

    kinds = np.asarray(res.series["kind"])
    everything = rows(t, kinds, res.series["x"])
    on_t = rows(ds["t"].values, ds["kind"].values, ds["x"].values)
    on_event = rows(ds["event_t"].values, ds["event_kind"].values, ds["event_x"].values)
    assert on_t | on_event == everything
    assert {r for r in everything if r[1] != 0} <= on_event
    # the exact peak is on the time axis
    assert float(ds["track_contact_force"].min()) == res.ranges_dict()["contact_force"][0]


def test_xarray_sel_nearest_and_interp(transfer_run) -> None:
    ds = transfer_run.to_xarray()
    t = ds["t"].values
    i = int(np.searchsorted(t, 0.0123))
    near = ds.sel(t=0.0123, method="nearest")
    j = i if abs(t[i] - 0.0123) < abs(t[i - 1] - 0.0123) else i - 1
    assert float(near["x"]) == float(ds["x"].values[j])
    # linear interpolation between the two neighbouring rows, by hand
    w = (0.0123 - t[i - 1]) / (t[i] - t[i - 1])
    expect = (1 - w) * ds["x"].values[i - 1] + w * ds["x"].values[i]
    assert float(ds.interp(t=0.0123)["x"]) == pytest.approx(expect, rel=1e-12)
    sub = ds.sel(t=slice(0.01, 0.02))
    assert sub.sizes["t"] > 100


def test_transfer_keeps_both_states(transfer_run) -> None:
    """At a transfer the state jumps: the state after it is on t, the state before it on
    the event dimension."""
    ds = transfer_run.to_xarray()
    k = int(np.flatnonzero(ds["event_kind"].values == 4)[0])
    tt = float(ds["event_t"].values[k])
    at = ds.sel(t=tt)
    assert int(at["kind"]) == 4 and float(at["x"]) == float(ds["event_x"].values[k])
    before = ds["event_x"].values[(ds["event_t"].values == tt) & (ds["event_kind"].values == 0)]
    assert before.size == 1 and before[0] != float(at["x"])


def test_series_netcdf_is_compressed_and_round_trips(transfer_run, tmp_path) -> None:
    from braidsim.export import write_series_netcdf

    p = write_series_netcdf(transfer_run, tmp_path / "series.nc")
    ds = transfer_run.to_xarray()
    ds.to_netcdf(tmp_path / "plain.nc", engine="scipy")  # netCDF3, uncompressed
    assert p.stat().st_size < 0.5 * (tmp_path / "plain.nc").stat().st_size
    with xr.open_dataset(p) as back:
        xr.testing.assert_identical(back.load(), ds)
        assert back.indexes["t"].is_unique
        assert float(back.sel(t=0.0123, method="nearest")["x"]) == float(
            ds.sel(t=0.0123, method="nearest")["x"]
        )


def test_xarray_carries_the_sensitivities(tmp_path) -> None:
    """With sensitivities the Dataset holds them on a ``key`` dimension, split over ``t``
    and ``event`` as the series' rows are, the final state's beside them; the final
    state's derivative along the restitution is that of two runs by central differences."""
    from braidsim.export import write_series_netcdf

    # (not the clearance: paper-3.2 starts on its wall, where that derivative does not exist)
    keys = ["carrier.mass", "contact.track.restitution", "contact.track.stiffness"]
    sc = braidsim.load_scenario(
        "paper-3.2", overrides={"transfer.times": [0.02], "simulation.rtol": 1e-11}
    )
    res = braidsim.simulate(sc, duration=0.03, sensitivities=keys)
    ds = res.to_xarray()
    assert list(ds["key"].values) == keys
    assert list(ds["key_units"].values) == ["kg", "", "N/m^1.5"]
    sens = res.sensitivity
    assert sens.series.shape[0] == len(res.series["t"])
    assert ds["d_x"].shape == (ds.sizes["t"], 3) and ds["event_d_x"].shape == (ds.sizes["event"], 3)
    # each row's derivatives travel with its values: rows of x on t and on event
    for grid, prefix in (("t", ""), ("event", "event_")):
        times = ds["t" if grid == "t" else "event_t"].values
        xs = ds[f"{prefix}x"].values
        raw = np.flatnonzero(np.isin(res.series["t"], times))
        for i in range(0, times.size, max(1, times.size // 50)):
            j = raw[(res.series["t"][raw] == times[i]) & (res.series["x"][raw] == xs[i])][-1]
            np.testing.assert_array_equal(ds[f"{prefix}d_x"].values[i], sens.series[j, :, 0])
    assert ds["d_track_contact_force"].attrs["quantity_units"] == "N"
    np.testing.assert_array_equal(ds["final_d_vx"].values, sens.final[:, 1])

    key, h = "contact.track.restitution", 1e-5
    c = float(sc[key])
    ends = [
        np.array(
            braidsim.simulate(sc.with_overrides({key: c + s * h}), duration=0.03).final_state.y[:2]
        )
        for s in (1, -1)
    ]
    fd = (ends[0] - ends[1]) / (2 * h)
    got = [float(ds[f"final_d_{q}"].sel(key=key)) for q in ("x", "vx")]
    np.testing.assert_allclose(got, fd, rtol=1e-5)

    p = write_series_netcdf(res, tmp_path / "series.nc")
    with xr.open_dataset(p) as back:
        xr.testing.assert_identical(back.load(), ds)


# ------------------------------------------------------------------ provenance


def test_duration_actually_used_is_recorded(capsys, tmp_path) -> None:
    out = tmp_path / "r"
    code, stdout, err = run_cli(
        capsys, "run", "paper-3.2", "--duration", "0.02", "--out", str(out), "--json"
    )
    assert code == 0, err
    for data in (json.loads(stdout), json.loads((out / "summary.json").read_text())):
        assert data["parameters"]["simulation.duration"] == 0.02
        assert data["simulation"]["duration"] == 0.02
        assert data["braidsim_version"] == braidsim.__version__
        assert re.match(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d", data["created"])
    with xr.open_dataset(out / "series.nc") as ds:
        assert ds.attrs["braidsim_version"] == braidsim.__version__
        assert ds.attrs["duration"] == 0.02 and ds.attrs["scenario"] == "paper-3.2"
        params = json.loads(ds.attrs["parameters_json"])
        assert params["simulation.duration"] == 0.02 and params["initial.x"] == 0.003
    res = braidsim.simulate("paper-3.2", duration=0.01)
    s = res.summary()
    assert s["parameters"]["simulation.duration"] == 0.01
    assert braidsim.load_scenario("paper-3.2")["simulation.duration"] == 0.5


def test_version_option(capsys) -> None:
    code, out, _ = run_cli(capsys, "--version")
    assert code == 0 and out.strip() == f"braidsim {braidsim.__version__}"


SPEC = """
scenario = "paper-3.2"
duration = "0.01 s"
[[axes]]
key = "track.clearance"
start = "2 mm"
stop = "3 mm"
num = 2
"""

#: every verb with --json, at a size that runs in about a second
JSON_VERBS: dict[str, list[str]] = {
    "run": ["run", "paper-3.2", "--duration", "0.01"],
    "impact": ["impact"],
    "models": ["models"],
    "scenarios": ["scenarios"],
    "restitution": ["restitution", "--law", "hertz", "--points", "2"],
    "bifurcation": [
        "bifurcation",
        "paper-3.3",
        "--param",
        "track.vibration_amplitude",
        "--from",
        "0.1 mm",
        "--to",
        "0.12 mm",
        "--points",
        "2",
        "--transient-cycles",
        "2",
        "--cycles",
        "4",
    ],
    "basins": [
        "basins",
        "paper-3.3",
        "--nx",
        "2",
        "--ny",
        "1",
        "--transient-cycles",
        "2",
        "--cycles",
        "4",
    ],
    "lyapunov": ["lyapunov", "paper-3.4b", "--transient-cycles", "2", "--cycles", "4"],
    "analyze": ["analyze", "paper-3.3", "--duration", "0.1"],
    "fit": [
        "fit",
        str(ROOT / "examples" / "fit_spec.toml"),
        "--data",
        str(ROOT / "examples" / "fit_record.csv"),
        "--out",
        "{tmp}/f",
    ],
    "sweep": ["sweep", "{spec}", "--out", "{tmp}/s.zarr", "--workers", "1"],
    "machine": [
        "machine",
        str(ROOT / "examples" / "machine16.toml"),
        "--out",
        "{tmp}/m",
        "--duration",
        "0.05",
        "--frames",
        "0",
        "--workers",
        "1",
    ],
}
SLOW_JSON_VERBS = {
    "paper": ["paper", "--out", "{tmp}/paper"],
}


def _verbs_with_json() -> set[str]:
    from braidsim.cli import _register
    from braidsim.cli.common import app

    _register()
    names = set()
    for cmd in app.registered_commands:
        name = cmd.name or cmd.callback.__name__.replace("_", "-")
        import inspect

        src = inspect.signature(cmd.callback)
        if "json_" in src.parameters:
            names.add(name)
    return names


def test_every_json_verb_is_checked() -> None:
    """A new verb with --json must be added to the version check below."""
    # continue: its version is checked in tests/unit/test_continuation.py
    covered = set(JSON_VERBS) | set(SLOW_JSON_VERBS) | {"sweep-plot", "design", "continue"}
    assert _verbs_with_json() <= covered


def _check_version(capsys, argv: list[str], tmp_path: Path) -> dict:
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC)
    argv = [a.format(spec=spec, tmp=tmp_path) for a in argv]
    code, out, err = run_cli(capsys, *argv, "--json")
    assert code == 0, err
    assert out.count("\n") == 1  # one JSON object, nothing else on stdout
    data = json.loads(out)
    assert data["braidsim_version"] == braidsim.__version__
    return data


@pytest.mark.parametrize("verb", sorted(JSON_VERBS))
def test_every_json_output_carries_the_version(capsys, tmp_path, verb) -> None:
    data = _check_version(capsys, JSON_VERBS[verb], tmp_path)
    if verb == "sweep":
        code, out, err = run_cli(
            capsys,
            "sweep-plot",
            str(tmp_path / "s.zarr"),
            "--metric",
            "regime",
            "--x",
            "track.clearance",
            "--out",
            str(tmp_path / "p.png"),
            "--json",
        )
        assert code == 0, err
        assert json.loads(out)["braidsim_version"] == braidsim.__version__
    if verb in ("bifurcation", "basins", "lyapunov", "analyze"):
        # analysis outputs state the settings and the steady-state window they used
        assert "window_rule" in data["settings"] and data["parameters"]
        assert data["created"]


@pytest.mark.slow
@pytest.mark.parametrize("verb", sorted(SLOW_JSON_VERBS))
def test_slow_json_outputs_carry_the_version(capsys, tmp_path, verb) -> None:
    _check_version(capsys, SLOW_JSON_VERBS[verb], tmp_path)


# ------------------------------------------------------------------ compact outputs


def test_run_out_refuses_an_unrelated_folder(capsys, tmp_path) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    code, _, err = run_cli(capsys, "run", "paper-3.2", "--duration", "0.01", "--out", str(tmp_path))
    assert code == 2 and "--out" in err and "not empty" in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]
    # an earlier run output is replaced; CSV series only with --csv
    d = tmp_path / "r"
    for extra in ([], ["--csv"]):
        code, _, err = run_cli(
            capsys, "run", "paper-3.2", "--duration", "0.01", "--out", str(d), *extra
        )
        assert code == 0, err
    assert (d / "series.csv").is_file() and (d / "series.nc").is_file()


def test_out_refusal_names_the_command_that_writes_the_output(tmp_path) -> None:
    """The refusal of a foreign --out names the command whose earlier output it would
    replace, a command that exists (it said `braidsim machine report`)."""
    from braidsim.cli import _register
    from braidsim.cli.common import app
    from braidsim.continuation.study import REPORT_KIND as CONTINUE
    from braidsim.design.report import REPORT_KIND as DESIGN
    from braidsim.errors import InputError
    from braidsim.fit.report import REPORT_KIND as FIT
    from braidsim.io import check_output_directory
    from braidsim.machine.report import REPORT_KIND as MACHINE
    from braidsim.paper.report import OUTPUT_KIND as PAPER

    _register()
    commands = {cmd.name or cmd.callback.__name__ for cmd in app.registered_commands}
    (tmp_path / "notes.txt").write_text("mine")
    kinds = {
        MACHINE: "machine",
        DESIGN: "design",
        PAPER: "paper",
        CONTINUE: "continue",
        FIT: "fit",
        "run": "run",
        "analysis-basins": "basins",
    }
    for kind, verb in kinds.items():
        assert verb in commands
        with pytest.raises(InputError, match=f"earlier output of `braidsim {verb}`;"):
            check_output_directory(tmp_path, kind)


def test_rerun_refuses_to_delete_the_users_file_in_its_out(capsys, tmp_path) -> None:
    """``echo x > run1/notes.txt; braidsim run ... --out run1`` deleted notes.txt (exit 0,
    no message): it is refused with one line naming it, and replaced once it is moved."""
    d = tmp_path / "run1"
    argv = ["run", "paper-3.2", "--duration", "0.01 s", "--out", str(d)]
    code, _, err = run_cli(capsys, *argv)
    assert code == 0, err
    (d / "notes.txt").write_text("x")
    code, _, err = run_cli(capsys, *argv)
    assert code == 2 and err.count("\n") == 1, err
    assert f"{str(d / 'notes.txt')!r} in it was not written there by braidsim" in err
    assert "choose another --out" in err
    assert (d / "notes.txt").read_text() == "x"
    (d / "notes.txt").unlink()
    code, _, err = run_cli(capsys, *argv)
    assert code == 0, err


def test_impacts_csv_headers_carry_units_as_series_csv(transfer_run, tmp_path) -> None:
    """impacts.csv said ``t,t_end,...`` while series.csv says ``t [s]``; the table's
    ``attrs["units"]`` were empty. The fit still reads a run's impact list in SI."""
    from braidsim.fit.data import read_csv

    imp = transfer_run.impacts
    assert imp.attrs["units"]["t"] == "s" and imp.attrs["units"]["peak_force"] == "N"
    assert imp.attrs["units"]["pair"] == "" and set(imp.attrs["units"]) == set(imp.columns)
    transfer_run.to_csv(tmp_path)
    header = (tmp_path / "impacts.csv").read_text().splitlines()[0].split(",")
    assert header[:5] == ["t [s]", "t_end [s]", "duration [s]", "pair", "wall"]
    assert "peak_force [N]" in header and "velocity [m/s]" in header
    track = imp[(imp["pair"] == "track") & ~imp["initial"]]
    table = tmp_path / "track_impacts.csv"
    table.write_text(
        (tmp_path / "impacts.csv").read_text().splitlines()[0]
        + "\n"
        + track.to_csv(index=False, header=False)
    )
    back = read_csv(table)
    assert np.array_equal(back.t, track["t"].to_numpy())
    assert np.array_equal(back.columns["peak_force"], track["peak_force"].to_numpy())


def test_out_creates_missing_folders_only_when_it_writes(capsys, tmp_path) -> None:
    """docs/guarantees.md: folders missing above --out are made like ``mkdir -p``, and a
    refused command makes none."""
    d = tmp_path / "a" / "b" / "run"
    code, _, err = run_cli(
        capsys,
        "run",
        "paper-3.2",
        "--duration",
        "0.01",
        "--set",
        "track.clearance=-1 mm",
        "--out",
        str(d),
    )
    assert code == 2 and "track.clearance" in err
    assert not (tmp_path / "a").exists()
    code, _, err = run_cli(capsys, "run", "paper-3.2", "--duration", "0.01", "--out", str(d))
    assert code == 0, err
    assert (d / "summary.json").is_file()


def _tiny_sweep(tmp_path: Path, out: Path, amplitudes: list[str]) -> list[str]:
    """The command line of a sweep of paper-3.1 (4 ms runs) over the track's amplitude."""
    spec = tmp_path / "s.toml"
    values = ", ".join(f'"{a}"' for a in amplitudes)
    spec.write_text(
        'scenario = "paper-3.1"\nduration = "0.004 s"\n[[axes]]\n'
        f'key = "track.vibration_amplitude"\nname = "h_a"\nvalues = [{values}]\n'
    )
    return ["sweep", str(spec), "--out", str(out), "--processes", "1", "--no-progress"]


def test_sweep_out_that_is_not_a_store_is_said_so_up_front(capsys, tmp_path) -> None:
    """A run folder as a sweep's --out: it said "pass --resume to finish it", and --resume
    then that it is not a sweep store."""
    d = tmp_path / "run1"
    d.mkdir()
    (d / "summary.json").write_text("{}")
    for extra in ([], ["--resume"]):
        code, _, err = run_cli(capsys, *_tiny_sweep(tmp_path, d, ["0.05 mm"]), *extra)
        assert code == 2 and err.count("\n") == 1, err
        assert f"--out: {d} exists and is not a sweep store; allowed a new or empty" in err


def test_sweep_writes_its_store_into_an_empty_folder(capsys, tmp_path) -> None:
    """As run and paper do: an empty folder holds nothing to lose (it was refused)."""
    d = tmp_path / "s.zarr"
    d.mkdir()
    code, _, err = run_cli(capsys, *_tiny_sweep(tmp_path, d, ["0.05 mm", "0.06 mm"]))
    assert code == 0, err
    assert braidsim.sweep.open_sweep(d).attrs["complete"] == 1


def test_sweep_failing_before_its_store_does_not_offer_resume(capsys, tmp_path, monkeypatch):
    """A sweep whose store could not be created has nothing to resume: the hint says so."""
    import braidsim.sweep.execute as execute

    def no_store(spec, path):
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(execute, "create_store", no_store)
    out = tmp_path / "s.zarr"
    code, _, err = run_cli(capsys, *_tiny_sweep(tmp_path, out, ["0.05 mm"]))
    assert code == 1 and "No space left" in err
    assert "--resume" not in err and "no store was written" in err


def test_sweep_interrupted_after_its_last_chunk_says_every_run_is_written(
    capsys, tmp_path, monkeypatch
):
    """A signal after the last chunk (before the store is marked complete) said "the chunks
    done are kept; finish with --resume" as if runs were missing; it now says that every
    run is written and what --resume still does."""
    import braidsim.sweep.execute as execute

    real = execute.set_complete

    def interrupted_at_the_end(path, complete):
        if complete:
            raise KeyboardInterrupt
        real(path, complete)

    monkeypatch.setattr(execute, "set_complete", interrupted_at_the_end)
    out = tmp_path / "s.zarr"
    argv = _tiny_sweep(tmp_path, out, ["0.05 mm", "0.06 mm"])
    code, _, err = run_cli(capsys, *argv)
    assert code == 130 and "interrupted by SIGINT" in err
    assert f"every run is written in {out}; --resume marks the store complete" in err, err
    monkeypatch.setattr(execute, "set_complete", real)
    code, _, err = run_cli(capsys, *argv, "--resume")
    assert code == 0, err
    assert braidsim.sweep.open_sweep(out).attrs["complete"] == 1


def test_lyapunov_json_is_short_unless_asked(capsys) -> None:
    argv = ["lyapunov", "paper-3.4b", "--transient-cycles", "2", "--cycles", "20", "--json"]
    code, short, err = run_cli(capsys, *argv)
    assert code == 0, err
    code, full, err = run_cli(capsys, *argv, "--curve")
    assert code == 0, err
    s, f = json.loads(short), json.loads(full)
    assert "running" not in s and len(f["running"]) == f["intervals"] > 100
    assert s["exponent"] == f["exponent"]
    assert len(short) < 0.5 * len(full)


def test_result_repr_is_short_and_html(transfer_run) -> None:
    r = repr(transfer_run)
    assert len(r) < 300 and "\n" not in r and "paper-3.2" in r
    h = transfer_run._repr_html_()
    assert h.startswith("<div>") and "<table>" in h and len(h) < 5000


def test_sweep_plot_says_what_it_wrote(capsys, tmp_path) -> None:
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC)
    code, _, err = run_cli(capsys, "sweep", str(spec), "--out", str(tmp_path / "s.zarr"))
    assert code == 0, err
    png = tmp_path / "p.png"
    code, out, err = run_cli(
        capsys, "sweep-plot", str(tmp_path / "s.zarr"), "--metric", "regime", "--x",
        "track.clearance", "--out", str(png),
    )  # fmt: skip
    assert code == 0, err
    assert str(png) in out.replace("\n", "") and png.is_file()


def test_example_does_not_overwrite_the_tracked_figure() -> None:
    import importlib.util

    spec = importlib.util.spec_from_file_location("ex", ROOT / "examples" / "sweep_ha_omega.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    fig = mod.parser().parse_args([]).figure
    assert "docs" not in Path(fig).parts


# ------------------------------------------------------------------ steady-state defaults


def test_sweep_metrics_window_defaults_to_the_second_half() -> None:
    spec = parse_spec(
        {"scenario": "paper-3.2", "duration": "0.4 s", "axes": [
            {"key": "track.clearance", "start": "2 mm", "stop": "3 mm", "num": 2}
        ]}
    )  # fmt: skip
    assert spec.options.window == (0.2, 0.4)


def test_analyze_default_discards_a_transient(capsys) -> None:
    """paper-3.3 settles into a period-6 orbit; over its first 0.5 s it has not yet. The
    default window starts after 100 excitation periods and says so."""
    from braidsim.analysis.report import analyze

    a = analyze("paper-3.3")
    T = 1 / 60
    assert a.result.model.duration == pytest.approx(150 * T)
    assert a.window[0] == pytest.approx(100 * T, abs=1e-9)
    assert a.steady is not None and a.steady.regime.period == 6
    assert "100 T" in a.window_rule
    short = analyze("paper-3.3", duration=0.5)
    assert short.window[0] == pytest.approx(0.25, abs=T)  # half of a short run
    assert short.steady is not None and short.steady.regime.label == "irregular"


# ------------------------------------------------------------------ xy mode


def test_run_shows_both_pairs_in_xy_mode(capsys, tmp_path) -> None:
    xy = tmp_path / "xy"
    code, out, err = run_cli(
        capsys, "run", "paper-3.1", "--set", "simulation.dof=xy", "--duration", "0.03",
        "--out", str(xy),
    )  # fmt: skip
    assert code == 0, err
    assert "slot (y) min" in out and "track (x) min" in out
    for name in ("x.png", "y.png", "slot_stiffness_force.png", "slot_depth.png"):
        assert (xy / name).stat().st_size > 0, name
    x_only = tmp_path / "x"
    code, out, err = run_cli(capsys, "run", "paper-3.1", "--duration", "0.03", "--out", str(x_only))
    assert code == 0, err
    assert "slot (y)" not in out and not (x_only / "y.png").exists()


# ------------------------------------------------------------------ progress and signals


def test_progress_is_off_under_json_and_without_a_terminal(capsys) -> None:
    from braidsim.cli.progress import enabled

    assert not enabled(quiet=True)
    assert not enabled()  # pytest captures stderr: not a terminal
    # a unit given: no notice either (a bare number would add one line, docs/units.md)
    code, out, err = run_cli(capsys, "run", "paper-3.2", "--duration", "0.01 s", "--json")
    assert code == 0 and err == "" and json.loads(out)


def test_first_compile_is_detected() -> None:
    """With an empty numba cache the integrator's first call compiles (and the progress note
    says so); here, after runs, it does not."""
    import tempfile

    from braidsim.cli.progress import kernel_needs_compile

    braidsim.simulate("paper-3.2", duration=0.001)
    assert not kernel_needs_compile()
    with tempfile.TemporaryDirectory() as cache:
        code = "from braidsim.cli.progress import kernel_needs_compile as k; print(k())"
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        out = subprocess.run(
            [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
        )
    assert out.stdout.strip() == "True"


def _session_members(sid: int) -> dict[int, str]:
    """Process id -> state letter of every process in session ``sid`` (Linux /proc).

    A command started with ``start_new_session`` leads a session of its own, and every
    process it starts stays in it, including one orphaned by the command's end (which
    /proc's parent links no longer lead to)."""
    out: dict[int, str] = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[3]) == sid:  # state, ppid, pgrp, session
                out[int(d.name)] = fields[0]
    return out


def _survivors(sid: int, wait: float) -> dict[int, str]:
    """The session's processes other than zombies once ``wait`` seconds have passed (or
    none are left), each with its command line."""
    deadline = time.monotonic() + wait
    while True:
        alive = {k: v for k, v in _session_members(sid).items() if v != "Z"}
        if not alive or time.monotonic() > deadline:
            break
        time.sleep(0.1)
    out = {}
    for pid, state in alive.items():
        try:
            cmdline = Path(f"/proc/{pid}/cmdline").read_text().replace("\0", " ")[:120]
        except OSError:
            continue
        out[pid] = f"{state} {cmdline}"
    return out


def _kill_session(p: subprocess.Popen) -> None:
    """Clean up after a test: the command (reaped) and whatever is left of its session."""
    if p.poll() is None:
        p.kill()
        p.wait()
    for pid in _session_members(p.pid):
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
def test_sigterm_stops_the_worker_processes(tmp_path) -> None:
    """SIGTERM to the command alone (as ``kill PID`` sends it) while its workers compute:
    the command ends with 143 and its one line, and no process it started outlives it.

    The outputs go to files, not pipes: a process that outlives the command and holds them
    is then found by the session scan and named, instead of hanging a read."""
    cmd = [
        sys.executable, "-m", "braidsim", "bifurcation", "paper-3.3", "--param",
        "track.vibration_amplitude", "--from", "0.1 mm", "--to", "0.2 mm", "--points", "4",
        "--transient-cycles", "5000", "--cycles", "50", "--workers", "2", "--json",
    ]  # fmt: skip
    with (tmp_path / "out").open("w") as out, (tmp_path / "err").open("w") as err:
        p = subprocess.Popen(cmd, stdout=out, stderr=err, start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        # the command, the resource tracker and the two workers
        while time.monotonic() < deadline and len(_session_members(p.pid)) < 4:
            time.sleep(0.2)
        assert len(_session_members(p.pid)) >= 4, "the workers did not start"
        p.terminate()
        p.wait(timeout=30)
        survivors = _survivors(p.pid, 5.0)
    finally:
        _kill_session(p)
    text = (tmp_path / "err").read_text()
    # 128 + 15: the exit code of a command stopped by SIGTERM (docs/guarantees.md)
    assert p.returncode == 143 and "interrupted by SIGTERM" in text, text
    assert "Traceback" not in text, text
    assert not survivors, survivors


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
@pytest.mark.parametrize("method", ["fork", "forkserver"])
def test_pool_workers_die_with_a_killed_parent(tmp_path, method: str) -> None:
    """A process killed with SIGKILL runs no handler: its pool's workers, set up by
    ``die_with_parent``, end with it instead of waiting for tasks forever (here a task of
    60 s); with ``forkserver``, so does the fork server."""
    code = f"""
import multiprocessing, os, sys, time
from concurrent.futures import ProcessPoolExecutor
from braidsim.batch import die_with_parent
if __name__ == "__main__":
    ctx = multiprocessing.get_context({method!r})
    pool = ProcessPoolExecutor(2, mp_context=ctx, initializer=die_with_parent)
    futs = [pool.submit(time.sleep, 60) for _ in range(2)]
    time.sleep(0.5)
    print(" ".join(str(pid) for pid in pool._processes), flush=True)
    time.sleep(60)
"""
    script = tmp_path / "pool.py"
    script.write_text(code)
    p = subprocess.Popen(
        [sys.executable, str(script)], stdout=subprocess.PIPE, start_new_session=True, text=True
    )
    try:
        assert p.stdout is not None
        workers = [int(w) for w in p.stdout.readline().split()]
        assert len(workers) == 2 and all(Path(f"/proc/{w}").exists() for w in workers)
        p.kill()
        p.wait(timeout=30)
        survivors = _survivors(p.pid, 10.0)
    finally:
        _kill_session(p)
        if p.stdout is not None:
            p.stdout.close()
    assert not survivors, survivors


_LONG_RUN = """
import braidsim
braidsim.simulate("paper-3.1", 0.01, series=False)  # compiled before the signal arrives
print("ready", flush=True)
braidsim.simulate("paper-3.1", 1e5, series=False)  # a carrier at rest: no buffer fills
print("finished", flush=True)
"""


def test_ctrl_c_stops_a_long_run_of_the_compiled_solver() -> None:
    """The compiled loop hands control back to Python every PAUSE_STEPS steps, so that a
    signal is acted on. Before, it returned only when a buffer filled, which a carrier at
    rest never does: paper-3.1 over 1e5 s (about 200 s of CPU) ran on after SIGINT and
    SIGTERM until it was killed."""
    # (communicate, not wait: a child that writes more than a pipe holds to stderr blocks
    # until it is read; and the pipes are closed whatever happens, or an unclosed file
    # warning fails a later test of the same worker)
    with subprocess.Popen(
        [sys.executable, "-c", _LONG_RUN],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    ) as p:
        try:
            assert p.stdout is not None and p.stdout.readline().strip() == "ready"
            time.sleep(1.0)  # inside the long run's compiled loop by now
            p.send_signal(signal.SIGINT)
            out, err = p.communicate(timeout=60)
        finally:
            if p.poll() is None:
                p.kill()
                p.communicate()
    assert "finished" not in out
    assert p.returncode != 0 and "KeyboardInterrupt" in err, err[-500:]


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
def test_sigterm_stops_a_long_run_command(tmp_path) -> None:
    """`braidsim run` of a long resting run ends on SIGTERM with 143 and its one line."""
    cmd = [sys.executable, "-m", "braidsim", "run", "paper-3.1", "--duration", "1e5 s", "--json"]
    with (tmp_path / "err").open("w") as err:
        p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err)
    try:
        time.sleep(4.0)  # (a warm cache: in the compiled loop; a cold one: compiling)
        p.terminate()
        p.wait(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    text = (tmp_path / "err").read_text()
    assert p.returncode == 143 and "interrupted by SIGTERM" in text, text
