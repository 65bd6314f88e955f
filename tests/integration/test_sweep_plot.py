"""`braidsim sweep-plot` and `plot_sweep`: unfinished stores, --sel on grid axes and on run,
the example script's figure."""

from __future__ import annotations

import importlib.util
import textwrap
from pathlib import Path

import numpy as np
import pytest

from braidsim.cli import main
from braidsim.errors import StoreError
from braidsim.sweep import export_netcdf, load_spec, open_sweep, plot_sweep, run_sweep
from braidsim.sweep.store import mark_undone

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "sweep_ha_omega.py"

# the base scenario and the first axis of both stores
OMEGA = """
scenario = "paper-3.3"
duration = "0.02 s"

[[axes]]
key = "horn_gear.angular_velocity"
name = "omega"
values = ["120 rpm", "240 rpm"]
"""

GRID = (
    OMEGA
    + """
[[axes]]
key = "track.vibration_amplitude"
name = "h_a"
start = "0.06 mm"
stop = "0.18 mm"
num = 3

[metrics]
keep = ["regime", "track_max_approach_speed"]

[execution]
chunk_size = 2
"""
)

# a grid axis and a sampled parameter: dimensions (omega, run)
SAMPLED = (
    OMEGA
    + """
[samples]
method = "latin_hypercube"
n = 3
seed = 1
[samples.ranges]
"track.clearance" = { low = "1 mm", high = "4 mm", spacing = "log" }

[metrics]
keep = ["regime"]
"""
)


def make_store(tmp: Path, text: str, name: str) -> Path:
    spec = tmp / f"{name}.toml"
    spec.write_text(textwrap.dedent(text))
    store = tmp / f"{name}.zarr"
    run_sweep(load_spec(spec), store, processes=1, progress=False)
    return store


@pytest.fixture(scope="module")
def stores(tmp_path_factory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("sweep_plot")
    return {"grid": make_store(tmp, GRID, "grid"), "sampled": make_store(tmp, SAMPLED, "sampled")}


def cli(capsys, *argv: str) -> tuple[int, str]:
    """The command line in this process: (exit code, stderr)."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main(list(argv))
    return int(exc.value.code or 0), capsys.readouterr().err


def test_example_script_draws_its_two_plots(tmp_path, capsys):
    """Each of the example's plots gets the display units of what it draws."""
    spec = tmp_path / "small.toml"
    spec.write_text(textwrap.dedent(GRID))  # the example's axes and metrics, 6 short runs
    mod_spec = importlib.util.spec_from_file_location("sweep_ha_omega", EXAMPLE)
    assert mod_spec is not None and mod_spec.loader is not None
    mod = importlib.util.module_from_spec(mod_spec)
    mod_spec.loader.exec_module(mod)
    fig = tmp_path / "fig.png"
    mod.main(["--spec", str(spec), "--out", str(tmp_path / "s.zarr"), "--figure", str(fig)])
    assert fig.stat().st_size > 1000
    assert f"figure: {fig}" in capsys.readouterr().out


def test_unfinished_store_is_refused_and_its_runs_not_drawn_as_failed(stores, tmp_path, capsys):
    import shutil

    store = tmp_path / "cut.zarr"
    shutil.copytree(stores["grid"], store)
    mark_undone(store, [3])  # as a sweep interrupted before its last chunk: 1 run left
    code, err = cli(
        capsys,
        "sweep-plot",
        str(store),
        "--metric",
        "regime",
        "--x",
        "omega",
        "--y",
        "h_a",
        "--out",
        str(tmp_path / "p.png"),
    )
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert "not finished: 1 of 6 runs" in err and f"--out {store} --resume" in err
    assert not (tmp_path / "p.png").exists()

    # in Python the store is drawn: the run not done is left out, a failed run is "failed"
    ds = open_sweep(store).load()
    assert ds.attrs["runs_not_done"] == 1 and open_sweep(stores["grid"]).attrs["runs_not_done"] == 0
    ds["regime"][0, 0] = -1
    ds["failure"][0, 0] = "step size too small at t = 0.01 s"
    fig = plot_sweep(ds, "regime", x="omega", y="h_a")
    cells = fig.axes[0].collections[0].get_array()
    assert np.ma.count_masked(cells) == 1 and bool(cells.mask[2, 1])  # (h_a, omega)
    assert cells[0, 0] == -1 and not cells.mask[0, 0]
    assert "1 runs not run yet" in fig.axes[0].get_title()


def test_unfinished_store_is_exported_only_when_asked(stores, tmp_path):
    """Its fill values would read as failed runs: export_netcdf refuses the store unless
    partial=True, and the partial file counts the runs missing."""
    import shutil

    import xarray as xr

    store = tmp_path / "cut.zarr"
    shutil.copytree(stores["grid"], store)
    mark_undone(store, [0, 3])  # two runs in the first chunk, one in the last
    nc = tmp_path / "cut.nc"
    with pytest.raises(StoreError, match=r"not finished: 3 of 6 runs .* --resume"):
        export_netcdf(store, nc)
    assert not nc.exists()
    export_netcdf(store, nc, partial=True)
    with xr.open_dataset(nc) as back:
        assert int(back.attrs["runs_not_done"]) == 3
        assert int((back["regime"] == -1).sum()) == 3
    export_netcdf(stores["grid"], tmp_path / "whole.nc")


def test_sel_on_the_run_dimension(stores, tmp_path, capsys):
    store, png = str(stores["sampled"]), str(tmp_path / "a.png")
    base = ("sweep-plot", store, "--metric", "regime", "--out", png)
    code, err = cli(capsys, *base, "--x", "omega", "--sel", "run=0")
    assert code == 0, err
    code, err = cli(capsys, *base, "--x", "omega", "--sel", "run=7")
    assert code == 2 and "--sel run: '7' is not a value of run; allowed the integers 0 to 2" in err
    code, err = cli(capsys, *base, "--x", "omega", "--y", "run")
    assert code == 0, err
    code, err = cli(capsys, *base, "--x", "omega")
    assert code == 2 and "fix the dimensions run to plot regime over omega" in err
    code, err = cli(capsys, *base, "--x", "track.clearance")
    assert code == 2 and "fix the dimensions omega to plot regime over track.clearance" in err
    code, err = cli(capsys, *base, "--x", "track.clearance", "--sel", "run=1")
    assert code == 2 and "--sel: run is plotted (--x/--y track.clearance)" in err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_sel_outside_the_axis_is_refused_and_a_bare_number_noticed(stores, tmp_path, capsys):
    store, png = str(stores["grid"]), str(tmp_path / "r.png")
    base = ("sweep-plot", store, "--metric", "regime", "--x", "omega", "--out", png)
    code, err = cli(capsys, *base, "--sel", "h_a=7")
    assert code == 2 and err.count("\n") == 1
    assert "--sel h_a: 7 m is outside the sweep's h_a; allowed 6e-05 m to 0.00018 m" in err
    code, err = cli(capsys, *base, "--sel", "h_a=7 mm")
    assert code == 2 and "0.007 m is outside" in err
    code, err = cli(capsys, *base, "--sel", "h_a=0.00012")
    assert code == 0 and "note: --sel h_a 0.00012 taken as 0.00012 m (SI)" in err
    code, err = cli(capsys, *base, "--sel", "h_a=0.13 mm", "--unit", "h_a=mm")
    assert code == 0 and err == ""

    ds = open_sweep(stores["grid"])
    fig = plot_sweep(ds, "regime", x="omega", sel={"h_a": "0.13 mm"}, units={"h_a": "mm"})
    assert fig.axes[0].get_title() == "regime (h_a = 0.12 mm)"  # the grid value selected
    fig = plot_sweep(ds, "regime", x="h_a", sel={"omega": "240 rpm"})
    assert fig.axes[0].get_title() == "regime (omega = 25.1327 rad/s)"


def test_a_store_being_written_is_said_to_be(tmp_path, capsys):
    """sweep-plot on a store another sweep writes now said "finish it with --resume" (which
    is refused while it runs); a store left unfinished names its command, its SPEC said."""
    from braidsim.sweep.store import StoreLock, create_store

    spec = tmp_path / "grid.toml"
    spec.write_text(textwrap.dedent(GRID))
    store = create_store(load_spec(spec), tmp_path / "grid.zarr")
    png = tmp_path / "p.png"
    argv = ("sweep-plot", str(store), "--metric", "regime", "--x", "omega", "--out", str(png))
    lock = StoreLock(store)  # as the sweep writing it holds it
    try:
        code, err = cli(capsys, *argv)
    finally:
        lock.release()
    assert code == 2 and err.count("\n") == 1, err
    assert f"STORE: {store} is being written by a braidsim sweep now: 6 of 6 runs" in err
    assert "--resume" not in err
    code, err = cli(capsys, *argv)
    assert code == 2 and "not finished: 6 of 6 runs" in err
    assert f"`braidsim sweep SPEC --out {store} --resume`, SPEC being the spec file" in err
    assert not png.exists()
