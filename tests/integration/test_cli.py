"""The command line: JSON output (docs/cli.md), exit codes, one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from braidsim.cli import main


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main(list(argv))
    out, err = capsys.readouterr()
    return int(exc.value.code or 0), out, err


def test_run_json_contract(capsys) -> None:
    code, out, err = run_cli(capsys, "run", "paper-3.2", "--duration", "0.05", "--json")
    assert code == 0, err
    data = json.loads(out)
    assert set(data) >= {"scenario", "parameters", "x", "y", "impacts", "final", "stats"}
    assert set(data["x"]) == {"depth", "stiffness_force", "damping_force", "contact_force"}
    imp = data["impacts"][1]
    assert set(imp) >= {
        "t",
        "pair",
        "wall",
        "velocity",
        "rebound_velocity",
        "peak_force",
        "max_depth",
        "duration",
    }
    assert imp["pair"] == "track" and imp["wall"] == "inner"
    assert data["parameters"]["carrier.mass"] == 1.2
    assert set(data["final"]) == {"t", "x", "vx", "y", "vy"}


def test_run_window_and_set(capsys) -> None:
    code, out, _ = run_cli(
        capsys,
        "run",
        "paper-3.1",
        "--set",
        "track.clearance=2 mm",
        "--window",
        "0.4",
        "0.5",
        "--json",
    )
    assert code == 0
    data = json.loads(out)
    assert data["window"] == [0.4, 0.5]
    assert data["parameters"]["track.clearance"] == pytest.approx(2e-3)
    lo, hi = data["x"]["depth"]
    assert lo == pytest.approx(hi)  # at rest on the inner wall


PARAM = ["--param", "track.vibration_amplitude"]
AXIS = ["--from", "0.05 mm", "--to", "0.3 mm"]


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["run", "paper-3.1", "--set", "carrier.mas=1"], "carrier.mass"),
        (["run", "paper-3.1", "--set", "carrier.mass=3 mm"], "wrong unit"),
        (["run", "paper-3.1", "--set", "carrier.mass=-1"], "allowed > 0 kg"),
        (
            ["run", "paper-3.1", "--set", "contact.track.restitution=1.2"],
            "contact.track.restitution",
        ),
        (["run", "paper-3.1", "--set", "track.clearance=nan"], "not a finite number"),
        (["run", "paper-3.1", "--set", "contact.track.model=hunt"], "contact.track.model"),
        (["run", "no-such-scenario"], "scenario"),
        # an option's value refused by the API is named as the option typed
        (["run", "paper-3.1", "--duration", "-1"], "error: --duration: -1 s is out of range"),
        (
            ["basins", "paper-3.3", "--cycles", "0"],
            "error: --cycles: 0 is out of range; allowed an integer >= 2",
        ),
        (
            ["lyapunov", "paper-3.3", "--transient-cycles", "-1"],
            "error: --transient-cycles: -1.0 is out of range",
        ),
        (["impact", "--restitution", "0"], "--restitution: 0 is out of range"),
        (["impact", "--velocity", "-1"], "velocity"),
        (["impact", "--model", "hertzz"], "--model: 'hertzz' is not allowed (did you mean"),
        (["impact", "--mass", "-1 kg"], "--mass: -1 kg is out of range"),
        (["impact", "--exponent", "-1"], "--exponent: -1 is out of range"),
        (["run", "paper-3.1", "--set", "horn_gear.angular_velocity=150 rmp"], "'rpm'?"),
        # text that is neither a number nor a unit: the key's own unit and range
        (["run", "paper-3.1", "--set", "carrier.mass=abc"], "'abc'; allowed > 0 kg"),
        (["run", "paper-3.1", "--set", "simulation.rtol=abc"], "allowed >= 1e-15 and <= 0.01"),
        # (below the state's rounding: was taken, and the run limited by atol alone)
        (["run", "paper-3.1", "--set", "simulation.rtol=1e-30"], "1e-30 is out of range"),
        # the option as typed, not the API's windows[0] or parameter
        (
            ["run", "paper-3.1", "--window", "0.5 s", "0.1 s"],
            "error: --window: [0.5, 0.1] s is not a time interval",
        ),
        (
            ["bifurcation", "paper-3.3", "--param", "track.vibration_amplitud", *AXIS],
            "error: --param: unknown key 'track.vibration_amplitud' (did you mean",
        ),
        (["basins", "paper-3.3", "--x", "initial.xx"], "error: --x: unknown key 'initial.xx'"),
        (["basins", "paper-3.3", "--y", "carrier.model"], "error: --y: unknown key"),
        (
            ["bifurcation", "paper-3.3", *PARAM, "--from", "-1 mm", "--to", "0.2 mm"],
            "error: --from (track.vibration_amplitude): -0.001 m is out of range",
        ),
        # a range of a bifurcation or basins as a sweep axis's: not reversed, not empty
        (
            ["bifurcation", "paper-3.3", *PARAM, "--from", "0.5 mm", "--to", "0.02 mm"],
            "error: --to: 0.02 mm (2e-05 m) is below --from (0.5 mm; 0.0005 m), a reversed",
        ),
        (
            ["bifurcation", "paper-3.3", *PARAM, "--from", "0.2 mm", "--to", "0.2 mm"],
            "error: --to: 0.2 mm equals --from (0.2 mm; 0.0002 m), an empty range of 41",
        ),
        (
            ["bifurcation", "paper-3.3", *PARAM, *AXIS, "--points", "1"],
            "error: --points: 1 value runs --from only (--to 0.3 mm would not be used)",
        ),
        (
            ["basins", "paper-3.3", "--y-from", "1 m/s", "--y-to", "-1 m/s"],
            "error: --y-to: -1 m/s (-1 m/s) is below --y-from",
        ),
        (["basins", "paper-3.3", "--x-to", "0 mm"], "error: --x-to: 0 mm equals --x-from"),
        # (--ny 1 alone is the row at --y-from: its --y-to is the default, not typed)
        (
            ["basins", "paper-3.3", "--ny", "1", "--y-to", "1 m/s"],
            "error: --ny: 1 value runs --y-from only (--y-to 1 m/s would not be used)",
        ),
    ],
)
def test_bad_input_is_one_line_exit_2(capsys, args: list[str], fragment: str) -> None:
    code, out, err = run_cli(capsys, *args)
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert fragment in lines[0]
    assert "Traceback" not in err


def test_run_table_counts_impacts_not_the_contact_present_at_the_start(capsys) -> None:
    """The printed count is the onsets, as in the metrics of a sweep; the contact present at
    t = 0 (paper-3.3 starts on the inner wall) is listed apart."""
    code, out, err = run_cli(capsys, "run", "paper-3.3", "--duration", "0.01", "--json")
    assert code == 0, err
    imp = json.loads(out)["impacts"]
    n_initial = sum(1 for r in imp if r["initial"])
    assert n_initial == 1 and len(imp) > 2
    code, out, err = run_cli(capsys, "run", "paper-3.3", "--duration", "0.01")
    assert code == 0, err
    assert f"{len(imp) - 1} impacts (+1 contact at the start);" in out
    # its row shows no approach speed (its velocity is the depth rate at t = 0); the next
    # row's is the onset's
    rows = [line for line in out.splitlines() if "│ track │" in line]
    assert rows[0].split("│")[4].strip() == "-"
    assert float(rows[1].split("│")[4]) == pytest.approx(imp[1]["velocity"], rel=1e-3)


@pytest.mark.parametrize("command", ["models", "scenarios"])
def test_listed_names_are_whole_in_80_columns(capsys, monkeypatch, command: str) -> None:
    """The names a user types back (a law for --model, a scenario) are never cut short."""
    monkeypatch.setenv("COLUMNS", "80")
    code, out, err = run_cli(capsys, command, "--json")
    assert code == 0, err
    names = [r["name"] for r in json.loads(out)[command]]
    code, out, err = run_cli(capsys, command)
    assert code == 0, err
    assert max(map(len, out.splitlines())) <= 80
    for name in names:
        assert name in out, name


def test_malformed_toml_file(capsys, tmp_path) -> None:
    f = tmp_path / "bad.toml"
    f.write_text("[track\n")
    code, _, err = run_cli(capsys, "run", str(f))
    assert code == 2 and "malformed TOML" in err and len(err.strip().splitlines()) == 1


def test_numerical_failure_exit_1(capsys) -> None:
    code, _, err = run_cli(capsys, "run", "paper-3.1", "--set", "simulation.max_steps=50")
    assert code == 1
    assert "t = " in err and "simulation.max_steps" in err
    assert len(err.strip().splitlines()) == 1


def test_transfer_period_over_the_limit_is_refused_up_front(capsys, monkeypatch) -> None:
    """A period that makes more transfer times than the limit is refused before they are
    made (1 ns over 0.1 s grew memory until the process was killed); the limit is raisable."""
    monkeypatch.setenv("BRAIDSIM_MAX_TRANSFERS", "50")
    argv = ["run", "paper-3.2", "--duration", "0.1 s", "--set", "transfer.period=1 ms", "--json"]
    code, out, err = run_cli(capsys, *argv)
    assert code == 2 and out == ""
    assert "transfer.period" in err and "BRAIDSIM_MAX_TRANSFERS" in err and "100 transfers" in err
    assert len(err.strip().splitlines()) == 1
    monkeypatch.setenv("BRAIDSIM_MAX_TRANSFERS", "1000")
    code, out, err = run_cli(capsys, *argv)
    assert code == 0, err
    assert json.loads(out)["stats"]["transfers"] == 99


def test_sample_arrays_over_the_memory_limit_are_refused_before_they_are_made(
    monkeypatch,
) -> None:
    """The per-period sample times that are not thinned (analyze's phase-locked grid, a
    streamed series) are checked against the memory limit before they are allocated."""
    import braidsim
    from braidsim.analysis.report import sample_grid
    from braidsim.errors import InputError

    monkeypatch.setenv("BRAIDSIM_MAX_MEMORY", "1e6")
    sc = braidsim.load_scenario("paper-3.1")
    with pytest.raises(InputError, match=r"duration = 1 s at 256 samples.*BRAIDSIM_MAX_MEMORY"):
        sample_grid(sc, 1.0, 256)
    with pytest.raises(InputError, match=r"sample_interval = 1e-08 s.*BRAIDSIM_MAX_MEMORY"):
        braidsim.simulate(sc, 0.01, sample_interval=1e-8, series=lambda chunk: None)
    assert sample_grid(sc, 0.1, 256).size == 1537  # within the limit: unchanged


def test_step_budget_failure_names_max_step_when_it_is_the_cause(capsys) -> None:
    """A tiny simulation.max_step exhausts the step budget: the hint says so instead of
    blaming the damping."""
    code, _, err = run_cli(
        capsys,
        "run",
        "paper-3.1",
        "--duration",
        "0.1 s",
        "--set",
        "simulation.max_step=1e-9 s",
        "--set",
        "simulation.max_steps=1000",
    )
    assert code == 1 and len(err.strip().splitlines()) == 1
    assert "raise simulation.max_step " in err and "1e+08 steps" in err
    assert "min_impact_velocity" not in err


def test_fast_impact_is_measured_not_refused(capsys) -> None:
    """At 1e5 m/s the free mass rebounds across the 1 m gap of the free-mass model within
    the run; the far wall is moved out of reach, and the impact matches the closed form."""
    code, out, err = run_cli(
        capsys, "impact", "--model", "hertz", "--velocity", "1e5 m/s", "--json"
    )
    assert code == 0, err
    data = json.loads(out)
    assert data["effective_restitution"] == pytest.approx(1.0, abs=1e-8)
    for key in ("max_depth", "max_force", "contact_duration"):
        assert data[key] == pytest.approx(data["closed_form"][key], rel=1e-6)


def test_impact_json(capsys) -> None:
    code, out, _ = run_cli(
        capsys,
        "impact",
        "--model",
        "hunt_crossley",
        "--restitution",
        "0.8",
        "--velocity",
        "1",
        "--json",
    )
    assert code == 0
    data = json.loads(out)
    for key in (
        "max_depth",
        "max_force",
        "contact_duration",
        "rebound_velocity",
        "effective_restitution",
        "dissipated_energy",
    ):
        assert key in data
    assert data["effective_restitution"] == pytest.approx(data["exact_restitution"], abs=1e-6)


def test_models_and_scenarios(capsys) -> None:
    code, out, _ = run_cli(capsys, "models", "--json")
    names = {m["name"] for m in json.loads(out)["models"]}
    assert code == 0
    assert {
        "hertz",
        "brandlein",
        "hunt_crossley",
        "herbert_mcwhannell",
        "lee_wang",
        "lankarani_nikravesh",
        "gonthier",
        "zhiying_qishao",
        "flores",
        "carvalho_martins",
    } <= names
    code, out, _ = run_cli(capsys, "scenarios", "--json")
    assert code == 0
    assert "paper-3.4b" in {s["name"] for s in json.loads(out)["scenarios"]}
    code, out, _ = run_cli(capsys, "scenarios", "--keys", "--json")
    keys = {k["key"]: k for k in json.loads(out)["keys"]}
    assert "contact.track.restitution" in keys
    # an infinite default reads as the scenario files write it ("inf"), not as null (absent)
    assert keys["materials.horn_gear.radius"]["default"] == "inf"
    assert keys["contact.track.exponent"]["default"] is None


def test_run_out_writes_plots_and_series(capsys, tmp_path) -> None:
    out_dir = tmp_path / "res"
    code, _, err = run_cli(capsys, "run", "paper-3.2", "--duration", "0.05", "--out", str(out_dir))
    assert code == 0, err
    for name in (
        "x.png",
        "stiffness_force.png",
        "damping_force.png",
        "depth.png",
        "impacts.csv",
        "summary.json",
        "series.nc",
    ):
        assert (out_dir / name).stat().st_size > 0, name
    assert not (out_dir / "series.csv").exists()  # CSV only on request (--csv)
    assert not list(out_dir.glob(".*tmp*"))


@pytest.mark.parametrize(
    ("name", "paper"),
    [
        (
            "paper-3.1",
            {
                "stiffness_force": (-4864.4, 4921.4),
                "damping_force": (-1441.2, 1448.8),
                "depth": (-3.37e-5, 3.39e-5),
            },
        ),
        (
            "paper-3.2",
            {
                "stiffness_force": (-3210.6, 1.2),
                "damping_force": (-948.1, 736.3),
                "depth": (-2.55e-5, 1.32e-7),
            },
        ),
    ],
)
def test_paper_ranges_within_3_percent(capsys, name: str, paper: dict) -> None:
    """`braidsim run paper-3.1 --json` and paper-3.2 give the paper's ranges within 3 %."""
    code, out, _ = run_cli(capsys, "run", name, "--json")
    assert code == 0
    x = json.loads(out)["x"]
    for q, (lo, hi) in paper.items():
        assert x[q][0] == pytest.approx(lo, rel=0.03), q
        assert x[q][1] == pytest.approx(hi, rel=0.03), q


def test_entry_point_subprocess() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "braidsim", "run", "paper-3.1", "--set", "carrier.mass=-1"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr.strip().count("\n") == 0 and "carrier.mass" in proc.stderr


@pytest.mark.parametrize(
    "argv", [["run", "paper-3.1", "--duration", "1 ms", "--json"], ["scenarios"], ["--version"]]
)
def test_a_closed_stdout_is_one_line_exit_1(argv: list[str]) -> None:
    """Started with stdout closed (``>&-``), Python sets sys.stdout to None: the first write
    was an internal error (for --version, a traceback)."""
    proc = subprocess.run(
        ["sh", "-c", 'exec "$0" "$@" >&-', sys.executable, "-m", "braidsim", *argv],
        stderr=subprocess.PIPE,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.startswith("braidsim: error: stdout: Bad file descriptor (the command")
    assert proc.stderr.count("\n") == 1


def test_a_closed_stdout_leaves_the_out_folder_whole(tmp_path) -> None:
    """The outputs are written before the result is printed: a closed stdout fails the
    print, not the files (one line, exit 1, the folder there whole)."""
    out = tmp_path / "r"
    argv = ["run", "paper-3.1", "--duration", "1 ms", "--out", str(out)]
    proc = subprocess.run(
        ["sh", "-c", 'exec "$0" "$@" >&-', sys.executable, "-m", "braidsim", *argv],
        stderr=subprocess.PIPE,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 1 and proc.stderr.count("\n") == 1, proc.stderr
    assert "stdout: Bad file descriptor" in proc.stderr
    assert {"impacts.csv", "series.nc", "summary.json"} <= {p.name for p in out.iterdir()}
    assert [p.name for p in tmp_path.iterdir()] == ["r"]  # (no temporary left beside it)


def test_unknown_option_is_one_line_exit_2(capsys) -> None:
    code, out, err = run_cli(capsys, "run", "paper-3.1", "--bogus")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "--bogus" in err


def test_every_verb_names_its_options() -> None:
    """The options an input error is reported under are read from each verb's declarations
    (an unreadable annotation would leave the library's names)."""
    from braidsim.cli import VERBS, _register
    from braidsim.cli.common import app, option_names

    _register()
    verbs = {
        c.name or c.callback.__name__: option_names(c.callback.__wrapped__)
        for c in app.registered_commands
        if c.callback is not None and hasattr(c.callback, "__wrapped__")
    }
    assert set(VERBS) <= set(verbs), sorted(set(VERBS) - set(verbs))
    assert verbs["run"]["duration"] == "--duration" and verbs["run"]["json_"] == "--json"
    assert verbs["bifurcation"]["transient_cycles"] == "--transient-cycles"
    assert verbs["design"]["workers"] == "--workers"


def test_the_package_imports_no_click_of_its_own() -> None:
    """typer vendors click (``typer._click``) and does not install it: a direct ``import
    click`` works where something else installed click (dask, mkdocs) and breaks a plain
    ``pip install .`` (the README's main job)."""
    import re
    from pathlib import Path

    import braidsim

    src = Path(braidsim.__file__).parent
    offenders = [
        str(p.relative_to(src))
        for p in src.rglob("*.py")
        if re.search(r"^\s*(import click\b|from click\b)", p.read_text(), re.MULTILINE)
    ]
    assert offenders == []


@pytest.mark.parametrize(
    ("terminal", "extra", "drawn"),
    [
        (True, [], True),
        (True, ["--json"], False),
        (False, [], False),
        (True, ["--no-progress"], False),
    ],
)
def test_sweep_draws_progress_only_where_someone_watches(
    capsys, tmp_path, monkeypatch, terminal: bool, extra: list[str], drawn: bool
) -> None:
    """docs/cli.md: no progress with --json, nor on a piped or redirected stderr (the final
    bar line of a sweep ended up in ``2>err.txt``), as for every other verb."""
    import braidsim.sweep

    asked: list[bool] = []

    def fake_run_sweep(spec, out, *, progress, **kwargs):
        asked.append(progress)
        return {
            "store": str(out),
            "runs": 1,
            "dims": {"h_a": 1},
            "runs_computed": 1,
            "elapsed_s": 0.1,
            "executor": "local",
            "failed_runs": 0,
        }

    monkeypatch.setattr(braidsim.sweep, "run_sweep", fake_run_sweep)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: terminal)
    spec = tmp_path / "s.toml"
    spec.write_text(
        'scenario = "paper-3.1"\nduration = "0.004 s"\n[[axes]]\n'
        'key = "track.vibration_amplitude"\nvalues = ["0.05 mm"]\n'
    )
    code, _, err = run_cli(capsys, "sweep", str(spec), "--out", str(tmp_path / "s.zarr"), *extra)
    assert code == 0, err
    assert asked == [drawn]


def test_duration_help_example_carries_its_unit(capsys) -> None:
    """The help's example was a bare 0.5, which the command answers with a note asking for
    the unit."""
    code, out, _ = run_cli(capsys, "run", "--help")
    assert code == 0
    assert "e.g. '0.5 s'" in " ".join(out.split())
