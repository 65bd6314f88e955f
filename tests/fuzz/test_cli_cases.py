"""Table-driven CLI harness: every verb fed bad input, every case answered as promised.

Each case is a command line with placeholders: ``{fx}`` the folder of bad input files
(:mod:`fixtures`), ``{o}`` a fresh output folder that must be unchanged afterwards (it holds
``a_file``, a regular file), ``{store}`` a finished sweep store, ``{ro}`` a read-only folder,
``{nw}`` a folder where no file can be created although its mode bits allow it for root
(``/proc``: ``os.access`` says yes to root there).
The expected exit codes and the names the error line must contain (a parameter or a path)
come with each case. :func:`harness.check_refused` states the promise.
"""

from __future__ import annotations

import math
import os
import stat
from pathlib import Path

import pytest

from fuzz.fixtures import GOOD_SWEEP, write_files
from fuzz.harness import check_refused

BAD = 2
FAIL = 1
EITHER = (1, 2)

S = "paper-3.1"
R = ["run", S]

#: (id, argv, exit codes, names: one of them must appear in the error line)
CASES: list[tuple[str, list[str], tuple[int, ...] | int, tuple[str, ...]]] = [
    # ---------------------------------------------------------------- run: scenario files
    ("run-latin1", ["run", "{fx}/latin1.toml"], BAD, ("latin1.toml", "UTF-8")),
    ("run-csv-without-out", ["run", "paper-3.1", "--csv"], BAD, ("--csv", "--out")),
    ("run-utf16", ["run", "{fx}/utf16.toml"], BAD, ("utf16.toml",)),
    ("run-binary", ["run", "{fx}/binary.toml"], BAD, ("binary.toml",)),
    ("run-deep-array", ["run", "{fx}/deep_array.toml"], BAD, ("deep_array.toml",)),
    ("run-deep-table", ["run", "{fx}/deep_table.toml"], BAD, ("deep_table.toml",)),
    ("run-deep-dotted", ["run", "{fx}/deep_dotted.toml"], BAD, ("a.a",)),
    ("run-empty", ["run", "{fx}/empty.toml"], BAD, ("empty.toml",)),
    ("run-only-meta", ["run", "{fx}/only_meta.toml"], BAD, ("only_meta.toml",)),
    ("run-nan-steps", ["run", "{fx}/nan_steps.toml"], BAD, ("simulation.max_steps",)),
    ("run-inf-steps", ["run", "{fx}/inf_steps.toml"], BAD, ("simulation.max_steps",)),
    ("run-huge-steps", ["run", "{fx}/huge_steps.toml"], BAD, ("simulation.max_steps",)),
    ("run-float-steps", ["run", "{fx}/float_steps.toml"], BAD, ("simulation.max_steps",)),
    ("run-profile-bad", ["run", "{fx}/profile_bad.toml"], BAD, ("horn_gear.speed_profile",)),
    ("run-profile-str", ["run", "{fx}/profile_str.toml"], BAD, ("horn_gear.speed_profile",)),
    ("run-harm-4", ["run", "{fx}/harmonics_bad.toml"], BAD, ("horn_gear.speed_harmonics",)),
    ("run-harm-scalar", ["run", "{fx}/harmonics_scalar.toml"], BAD, ("track.harmonics",)),
    ("run-table-value", ["run", "{fx}/clearance_table.toml"], BAD, ("track.clearance",)),
    ("run-list-value", ["run", "{fx}/clearance_list.toml"], BAD, ("track.clearance",)),
    ("run-bool-value", ["run", "{fx}/clearance_bool.toml"], BAD, ("track.clearance",)),
    ("run-date-value", ["run", "{fx}/clearance_date.toml"], BAD, ("track.clearance",)),
    ("run-file-pow", ["run", "{fx}/clearance_pow.toml"], BAD, ("track.clearance",)),
    ("run-file-eq", ["run", "{fx}/clearance_eq.toml"], BAD, ("track.clearance",)),
    ("run-unknown-key", ["run", "{fx}/unknown_key.toml"], BAD, ("carrier.mas",)),
    ("run-extends-missing", ["run", "{fx}/extends_missing.toml"], BAD, ("nope.toml",)),
    ("run-extends-cycle", ["run", "{fx}/extends_self.toml"], BAD, ("extends",)),
    ("run-extends-list", ["run", "{fx}/extends_list.toml"], BAD, ("extends: ['paper-3.1']",)),
    ("run-malformed", ["run", "{fx}/malformed.toml"], BAD, ("malformed TOML",)),
    ("run-dup-key", ["run", "{fx}/dup_key.toml"], BAD, ("dup_key.toml",)),
    ("run-dir-as-scenario", ["run", "{fx}"], BAD, ("scenario",)),
    ("run-no-scenario", ["run", "nope"], BAD, ("scenario",)),
    # ---------------------------------------------------------------- run: --set values
    ("set-pow", [*R, "--set", "track.clearance=9**9**9 m"], BAD, ("track.clearance",)),
    ("set-pow-nounit", [*R, "--set", "track.clearance=9**9**9"], BAD, ("track.clearance",)),
    ("set-10pow400", [*R, "--set", "track.clearance=10**400 m"], BAD, ("track.clearance",)),
    ("set-1e400", [*R, "--set", "track.clearance=1e400"], BAD, ("track.clearance",)),
    ("set-1e400-m", [*R, "--set", "track.clearance=1e400 m"], BAD, ("track.clearance",)),
    ("set-1e308-km", [*R, "--set", "track.clearance=1e308 km"], BAD, ("track.clearance",)),
    # the start's overlap under it would throw the carrier off at 1e10 m/s (it ran silently)
    (
        "set-absurd-stiffness",
        ["run", "paper-3.3", "--set", "contact.track.stiffness=1e30"],
        BAD,
        ("contact.track.stiffness", "overlap", "m/s"),
    ),
    ("set-eq", [*R, "--set", "track.clearance=1 m == 0.002"], BAD, ("track.clearance",)),
    ("set-code", [*R, "--set", "track.clearance=__import__('os')"], BAD, ("track.clearance",)),
    ("set-unit-exp", [*R, "--set", "track.clearance=1 m^99"], BAD, ("track.clearance",)),
    ("set-nan", [*R, "--set", "track.clearance=nan"], BAD, ("track.clearance",)),
    ("set-inf", [*R, "--set", "track.clearance=inf"], BAD, ("track.clearance",)),
    ("set-wrong-unit", [*R, "--set", "track.clearance=3 kg"], BAD, ("track.clearance",)),
    ("set-unknown-unit", [*R, "--set", "track.clearance=3 furlongz"], BAD, ("track.clearance",)),
    ("set-empty", [*R, "--set", "track.clearance="], BAD, ("track.clearance",)),
    ("set-no-eq", [*R, "--set", "track.clearance"], BAD, ("--set",)),
    ("set-unknown-key", [*R, "--set", "track.clarance=1 mm"], BAD, ("track.clarance",)),
    ("set-empty-key", [*R, "--set", "=1"], BAD, ("--set", "unknown")),
    ("set-steps-nan", [*R, "--set", "simulation.max_steps=nan"], BAD, ("simulation.max_steps",)),
    ("set-steps-inf", [*R, "--set", "simulation.max_steps=inf"], BAD, ("simulation.max_steps",)),
    ("set-steps-big", [*R, "--set", "simulation.max_steps=1e300"], BAD, ("simulation.max_steps",)),
    ("set-steps-float", [*R, "--set", "simulation.max_steps=2.5"], BAD, ("simulation.max_steps",)),
    ("set-steps-str", [*R, "--set", "simulation.max_steps=many"], BAD, ("simulation.max_steps",)),
    (
        "set-transfer-period-tiny",
        [*R, "--duration", "0.1 s", "--set", "transfer.period=1e-9 s"],
        BAD,
        ("transfer.period",),
    ),
    (
        "set-sample-interval-subnormal",
        [*R, "--set", "simulation.sample_interval=5e-324 s"],
        BAD,
        ("sample_interval",),
    ),
    (
        "set-profile-scalars",
        [*R, "--set", "horn_gear.speed_profile={times=1, speeds=2}"],
        BAD,
        ("horn_gear.speed_profile",),
    ),
    (
        "set-profile-keys",
        [*R, "--set", "horn_gear.speed_profile={t=[0,1], speeds=[1,1]}"],
        BAD,
        ("horn_gear.speed_profile",),
    ),
    (
        "set-profile-decreasing",
        [*R, "--set", "horn_gear.speed_profile={times=[1,0], speeds=[1,1]}"],
        BAD,
        ("horn_gear.speed_profile",),
    ),
    ("set-harm-flat", [*R, "--set", "track.harmonics=[1,2,3]"], BAD, ("track.harmonics",)),
    ("set-harm-nan", [*R, "--set", "track.harmonics=[[1,nan,0]]"], BAD, ("track.harmonics",)),
    (
        "set-harm-deep",
        [*R, "--set", "track.harmonics=" + "[" * 3000 + "]" * 3000],
        BAD,
        ("track.harmonics",),
    ),
    ("set-times-neg", [*R, "--set", "transfer.times=[-1]"], BAD, ("transfer.times",)),
    ("set-times-table", [*R, "--set", "transfer.times={a=1}"], BAD, ("transfer.times",)),
    ("set-bool-bad", [*R, "--set", "contact.allow_tension=maybe"], BAD, ("contact.allow_tension",)),
    ("set-choice-bad", [*R, "--set", "friction.law=[1]"], BAD, ("friction.law",)),
    ("set-choice-num", [*R, "--set", "simulation.dof=3"], BAD, ("simulation.dof",)),
    (
        "set-restitution-0",
        [*R, "--set", "contact.track.restitution=0"],
        BAD,
        ("contact.track.restitution",),
    ),
    ("set-poisson", [*R, "--set", "materials.track.poisson_ratio=0.5"], BAD, ("poisson_ratio",)),
    ("set-radius-order", [*R, "--set", "materials.guide_pad.radius=1"], BAD, ("radius",)),
    (
        "set-long-string",
        [*R, "--set", "track.clearance=" + "1" * 5000 + " m"],
        BAD,
        ("track.clearance",),
    ),
    # ---------------------------------------------------------------- run: options and --out
    ("run-duration-neg", [*R, "--duration", "-1"], BAD, ("duration",)),
    ("run-duration-unit", [*R, "--duration", "3 kg"], BAD, ("--duration",)),
    ("run-duration-pow", [*R, "--duration", "9**9**9 s"], BAD, ("--duration",)),
    ("run-duration-nan", [*R, "--duration", "nan"], BAD, ("duration",)),
    (
        "run-window-after",
        [*R, "--duration", "0.01 s", "--window", "0.5", "1"],
        BAD,
        ("T1", "window"),
    ),
    ("run-window-unit", [*R, "--window", "0 kg", "1 s"], BAD, ("--window",)),
    ("run-out-file", [*R, "--out", "{o}/a_file"], BAD, ("a_file",)),
    ("run-out-under-file", [*R, "--out", "{o}/a_file/sub"], BAD, ("a_file",)),
    ("run-out-nonempty", [*R, "--out", "{fx}"], BAD, ("--out",)),
    ("run-out-ro", [*R, "--out", "{ro}/out"], BAD, ("{ro}",)),
    ("run-out-nw", [*R, "--out", "{nw}/out"], BAD, ("--out", "{nw}/out")),
    # a name longer than any file system takes (255 bytes): the path refused, not an OSError
    ("run-out-long-name", [*R, "--out", "{o}/" + "a" * 300], BAD, ("--out", "255 bytes")),
    ("run-long-scenario-name", ["run", "a" * 300 + ".toml"], BAD, ("SCENARIO", "255 bytes")),
    (
        "sweep-out-long-name",
        ["sweep", "{fx}/good_sweep.toml", "--out", "{o}/" + "a" * 300],
        BAD,
        ("--out",),
    ),
    ("run-unknown-option", [*R, "--nope"], BAD, ("--nope", "No such option")),
    ("run-missing-arg", ["run"], BAD, ("SCENARIO", "scenario", "Missing")),
    # ---------------------------------------------------------------- impact
    ("impact-restitution-0", ["impact", "--restitution", "0"], BAD, ("restitution",)),
    ("impact-restitution-str", ["impact", "--restitution", "high"], BAD, ("restitution",)),
    ("impact-velocity-neg", ["impact", "--velocity", "-1"], BAD, ("velocity",)),
    ("impact-velocity-1e300", ["impact", "--velocity", "1e300 m/s"], BAD, ("velocity",)),
    ("impact-velocity-1e-300", ["impact", "--velocity", "1e-300 m/s"], BAD, ("velocity",)),
    ("impact-stiffness-1e-320", ["impact", "--stiffness", "1e-320 N/m^1.5"], BAD, ("stiffness",)),
    ("impact-velocity-unit", ["impact", "--velocity", "1 kg"], BAD, ("velocity",)),
    (
        "impact-velocity-inf",
        ["impact", "--velocity", "inf m/s"],
        BAD,
        ("--velocity: inf m/s is out of range; allowed > 0 m/s",),
    ),
    ("impact-velocity-pow", ["impact", "--velocity", "9**9**9 m/s"], BAD, ("velocity",)),
    ("impact-mass-0", ["impact", "--mass", "0"], BAD, ("mass",)),
    ("impact-mass-nan", ["impact", "--mass", "nan"], BAD, ("mass",)),
    ("impact-model", ["impact", "--model", "nope"], BAD, ("contact.track.model", "nope")),
    ("impact-stiffness-unit", ["impact", "--stiffness", "1e9 N/m"], BAD, ("--stiffness",)),
    ("impact-stiffness-neg", ["impact", "--stiffness", "-1e9 N/m^1.5"], BAD, ("stiffness",)),
    ("impact-stiffness-str", ["impact", "--stiffness", "stiff"], BAD, ("--stiffness",)),
    ("impact-exponent-0", ["impact", "--exponent", "0"], BAD, ("exponent",)),
    # ---------------------------------------------------------------- models, scenarios
    ("models-extra", ["models", "extra"], BAD, ("extra", "Got unexpected")),
    ("scenarios-extra", ["scenarios", "--nope"], BAD, ("--nope", "No such option")),
    # ---------------------------------------------------------------- restitution
    ("rest-cmin-0", ["restitution", "--c-min", "0"], BAD, ("--c-min",)),
    ("rest-cmax-2", ["restitution", "--c-max", "2"], BAD, ("--c-max",)),
    ("rest-reversed", ["restitution", "--c-min", "0.9", "--c-max", "0.2"], BAD, ("--c-min",)),
    ("rest-points-0", ["restitution", "--points", "0"], BAD, ("--points",)),
    ("rest-points-huge", ["restitution", "--points", "100000000"], BAD, ("--points",)),
    ("rest-velocity-unit", ["restitution", "--velocity", "1 kg"], BAD, ("--velocity",)),
    ("rest-velocity-0", ["restitution", "--velocity", "0 m/s"], BAD, ("--velocity",)),
    ("rest-mass-neg", ["restitution", "--mass", "-1 kg"], BAD, ("--mass",)),
    ("rest-law", ["restitution", "--law", "nope"], BAD, ("nope",)),
    ("rest-out-file", ["restitution", "--out", "{o}/a_file"], BAD, ("a_file",)),
    ("rest-out-under-file", ["restitution", "--out", "{o}/a_file/x"], BAD, ("a_file",)),
    ("rest-out-ro", ["restitution", "--out", "{ro}/x"], BAD, ("{ro}",)),
    ("rest-out-nw", ["restitution", "--out", "{nw}/x"], BAD, ("--out", "{nw}/x")),
    # ---------------------------------------------------------------- bifurcation
    *[
        (f"bif-{i}", ["bifurcation", "paper-3.3", *args], BAD, names)
        for i, (args, names) in enumerate(
            [
                (["--param", "track.nope", "--from", "1", "--to", "2"], ("track.nope",)),
                (["--param", "friction.law", "--from", "1", "--to", "2"], ("friction.law",)),
                (
                    ["--param", "track.clearance", "--from", "9**9**9 m", "--to", "2 mm"],
                    ("--from", "track.clearance"),
                ),
                (
                    ["--param", "track.clearance", "--from", "1 kg", "--to", "2 mm"],
                    ("--from", "track.clearance"),
                ),
                (
                    ["--param", "track.clearance", "--from", "-1 mm", "--to", "2 mm"],
                    ("track.clearance",),
                ),
                (
                    [
                        "--param",
                        "track.clearance",
                        "--from",
                        "1 mm",
                        "--to",
                        "2 mm",
                        "--points",
                        "0",
                    ],
                    ("--points",),
                ),
                (
                    [
                        "--param",
                        "track.clearance",
                        "--from",
                        "1 mm",
                        "--to",
                        "2 mm",
                        "--points",
                        "100000000",
                    ],
                    ("--points",),
                ),
                (
                    [
                        "--param",
                        "track.clearance",
                        "--from",
                        "1 mm",
                        "--to",
                        "2 mm",
                        "--workers",
                        "-1",
                    ],
                    ("--workers",),
                ),
                (
                    [
                        "--param",
                        "track.clearance",
                        "--from",
                        "1 mm",
                        "--to",
                        "2 mm",
                        "--out",
                        "{o}/a_file",
                    ],
                    ("a_file",),
                ),
                (
                    [
                        "--param",
                        "track.clearance",
                        "--from",
                        "1 mm",
                        "--to",
                        "2 mm",
                        "--out",
                        "{ro}/x",
                    ],
                    ("{ro}",),
                ),
                (["--param", "track.clearance", "--from", "1 mm"], ("--to", "Missing")),
            ]
        )
    ],
    # ---------------------------------------------------------------- basins
    ("basins-same", ["basins", "paper-3.3", "--x", "initial.x", "--y", "initial.x"], BAD, ("--x",)),
    ("basins-workers", ["basins", "paper-3.3", "--workers", "-2"], BAD, ("--workers",)),
    ("basins-huge", ["basins", "paper-3.3", "--nx", "10000", "--ny", "10000"], BAD, ("--nx",)),
    ("basins-nx-0", ["basins", "paper-3.3", "--nx", "0"], BAD, ("--nx", "points")),
    ("basins-xfrom", ["basins", "paper-3.3", "--x-from", "1 kg"], BAD, ("--x-from", "initial.x")),
    ("basins-ykey", ["basins", "paper-3.3", "--y", "nope"], BAD, ("nope",)),
    ("basins-out-file", ["basins", "paper-3.3", "--out", "{o}/a_file"], BAD, ("a_file",)),
    # ---------------------------------------------------------------- lyapunov
    ("lyap-cycles-huge", ["lyapunov", S, "--cycles", "1e12"], BAD, ("--cycles",)),
    ("lyap-d0-1", ["lyapunov", "paper-3.3", "--d0", "1"], BAD, ("--d0",)),
    ("lyap-d0-unit", ["lyapunov", "paper-3.3", "--d0", "1 kg"], BAD, ("--d0",)),
    ("lyap-d0-0", ["lyapunov", "paper-3.3", "--d0", "0 nm"], BAD, ("--d0",)),
    ("lyap-d0-pow", ["lyapunov", "paper-3.3", "--d0", "9**9**9 nm"], BAD, ("--d0",)),
    ("lyap-interval-unit", ["lyapunov", "paper-3.3", "--interval", "1 m"], BAD, ("--interval",)),
    ("lyap-out-under-file", ["lyapunov", "paper-3.3", "--out", "{o}/a_file/x"], BAD, ("a_file",)),
    (
        "lyap-set",
        ["lyapunov", "paper-3.3", "--set", "track.clearance=nan"],
        BAD,
        ("track.clearance",),
    ),
    # ---------------------------------------------------------------- analyze
    ("analyze-garbage", ["analyze", "{fx}/run_garbage"], BAD, ("summary.json",)),
    ("analyze-nokeys", ["analyze", "{fx}/run_nokeys"], BAD, ("summary.json",)),
    ("analyze-badparams", ["analyze", "{fx}/run_badparams"], BAD, ("track.clearance",)),
    ("analyze-latin1", ["analyze", "{fx}/run_latin1"], BAD, ("summary.json",)),
    ("analyze-empty-dir", ["analyze", "{fx}/run_empty"], BAD, ("summary.json",)),
    ("analyze-duration-unit", ["analyze", S, "--duration", "1 m"], BAD, ("--duration",)),
    ("analyze-transient-unit", ["analyze", S, "--transient", "1 kg"], BAD, ("--transient",)),
    (
        "analyze-samples-huge",
        ["analyze", S, "--duration", "1 s", "--set", "track.vibration_frequency=1e9 rad/s"],
        BAD,
        ("duration",),
    ),
    ("analyze-out-file", ["analyze", S, "--out", "{o}/a_file"], BAD, ("a_file",)),
    ("analyze-out-ro", ["analyze", S, "--out", "{ro}/x"], BAD, ("{ro}",)),
    # ---------------------------------------------------------------- sweep
    (
        "sweep-latin1",
        ["sweep", "{fx}/sweep_latin1.toml", "--out", "{o}/s"],
        BAD,
        ("sweep_latin1.toml",),
    ),
    (
        "sweep-empty",
        ["sweep", "{fx}/sweep_empty.toml", "--out", "{o}/s"],
        BAD,
        ("sweep_empty.toml",),
    ),
    ("sweep-no-axes", ["sweep", "{fx}/sweep_no_axes.toml", "--out", "{o}/s"], BAD, ("axes",)),
    (
        "sweep-reversed",
        ["sweep", "{fx}/sweep_reversed.toml", "--out", "{o}/s"],
        BAD,
        ("axes[0].stop",),
    ),
    (
        "sweep-huge-num",
        ["sweep", "{fx}/sweep_huge_num.toml", "--out", "{o}/s"],
        BAD,
        ("axes[0].num",),
    ),
    ("sweep-huge-grid", ["sweep", "{fx}/sweep_huge_grid.toml", "--out", "{o}/s"], BAD, ("sweep",)),
    (
        "sweep-huge-samples",
        ["sweep", "{fx}/sweep_huge_samples.toml", "--out", "{o}/s"],
        BAD,
        ("samples.n",),
    ),
    (
        "sweep-huge-series",
        ["sweep", "{fx}/sweep_huge_series.toml", "--out", "{o}/s"],
        BAD,
        ("series.num",),
    ),
    ("sweep-big-store", ["sweep", "{fx}/sweep_big_store.toml", "--out", "{o}/s"], BAD, ("store",)),
    ("sweep-pow", ["sweep", "{fx}/sweep_pow.toml", "--out", "{o}/s"], BAD, ("axes[0]",)),
    (
        "sweep-nan-num",
        ["sweep", "{fx}/sweep_nan_num.toml", "--out", "{o}/s"],
        BAD,
        ("axes[0].num",),
    ),
    (
        "sweep-bad-metric",
        ["sweep", "{fx}/sweep_bad_metric.toml", "--out", "{o}/s"],
        BAD,
        ("metrics.keep",),
    ),
    ("sweep-deep", ["sweep", "{fx}/sweep_deep.toml", "--out", "{o}/s"], BAD, ("sweep_deep.toml",)),
    (
        "sweep-chunk0",
        ["sweep", "{fx}/sweep_chunk0.toml", "--out", "{o}/s"],
        BAD,
        ("execution.chunk_size",),
    ),
    ("sweep-window", ["sweep", "{fx}/sweep_window.toml", "--out", "{o}/s"], BAD, ("window",)),
    (
        "sweep-scenario-int",
        ["sweep", "{fx}/sweep_scenario_int.toml", "--out", "{o}/s"],
        BAD,
        ("scenario",),
    ),
    ("sweep-axes-str", ["sweep", "{fx}/sweep_axis_str.toml", "--out", "{o}/s"], BAD, ("axes",)),
    ("sweep-missing-spec", ["sweep", "{fx}/nope.toml", "--out", "{o}/s"], BAD, ("nope.toml",)),
    ("sweep-spec-dir", ["sweep", "{fx}", "--out", "{o}/s"], BAD, ("SPEC",)),
    ("sweep-out-file", ["sweep", "{fx}/good_sweep.toml", "--out", "{o}/a_file"], BAD, ("a_file",)),
    (
        "sweep-out-file-resume",
        ["sweep", "{fx}/good_sweep.toml", "--out", "{o}/a_file", "--resume"],
        BAD,
        ("a_file",),
    ),
    (
        "sweep-out-under-file",
        ["sweep", "{fx}/good_sweep.toml", "--out", "{o}/a_file/s"],
        BAD,
        ("a_file",),
    ),
    ("sweep-out-ro", ["sweep", "{fx}/good_sweep.toml", "--out", "{ro}/s"], BAD, ("{ro}",)),
    (
        "sweep-out-nw",
        ["sweep", "{fx}/good_sweep.toml", "--out", "{nw}/s.zarr"],
        BAD,
        ("--out", "{nw}/s.zarr"),
    ),
    ("sweep-out-exists", ["sweep", "{fx}/good_sweep.toml", "--out", "{fx}"], BAD, ("--resume",)),
    (
        "sweep-resume-notstore",
        ["sweep", "{fx}/good_sweep.toml", "--out", "{fx}", "--resume"],
        BAD,
        ("not a sweep store",),
    ),
    (
        "sweep-resume-other",
        ["sweep", "{fx}/sweep_reversed_ok.toml", "--out", "{store}", "--resume"],
        BAD,
        ("different spec",),
    ),
    (
        "sweep-processes-neg",
        ["sweep", "{fx}/good_sweep.toml", "--out", "{o}/s", "--processes", "-3"],
        BAD,
        ("--processes",),
    ),
    (
        "sweep-workers-neg",
        ["sweep", "{fx}/good_sweep.toml", "--out", "{o}/s", "--workers", "-1"],
        BAD,
        ("--workers",),
    ),
    (
        "sweep-workers-and-sched",
        [
            "sweep",
            "{fx}/good_sweep.toml",
            "--out",
            "{o}/s",
            "--workers",
            "1",
            "--scheduler",
            "tcp://x:1",
        ],
        BAD,
        ("--workers",),
    ),
    (
        "sweep-scheduler-bad",
        ["sweep", "{fx}/good_sweep.toml", "--out", "{o}/s", "--scheduler", "not an address"],
        BAD,
        ("--scheduler",),
    ),
    (
        "sweep-netcdf-ext",
        ["sweep", "{fx}/good_sweep.toml", "--out", "{o}/s", "--netcdf", "{o}/x.txt"],
        BAD,
        ("--netcdf",),
    ),
    (
        "sweep-netcdf-nw",
        ["sweep", "{fx}/good_sweep.toml", "--out", "{o}/s", "--netcdf", "{nw}/x.nc"],
        BAD,
        ("--netcdf", "{nw}/x.nc"),
    ),
    (
        "sweep-netcdf-dir",
        ["sweep", "{fx}/good_sweep.toml", "--out", "{o}/s", "--netcdf", "{fx}"],
        BAD,
        ("--netcdf",),
    ),
    # ---------------------------------------------------------------- sweep axis names
    *[
        (
            f"sweep-axis-name-{i}",
            ["sweep", f"{{fx}}/axis_name_{i}.toml", "--out", "{o}/s"],
            BAD,
            ("axes[0].name",),
        )
        for i in range(12)
    ],
    # ---------------------------------------------------------------- sweep-plot
    (
        "plot-ext",
        ["sweep-plot", "{store}", "--metric", "regime", "--x", "h_a", "--out", "{o}/p.xyz"],
        BAD,
        ("p.xyz",),
    ),
    (
        "plot-noext",
        ["sweep-plot", "{store}", "--metric", "regime", "--x", "h_a", "--out", "{o}/p"],
        BAD,
        ("--out",),
    ),
    (
        "plot-failure",
        ["sweep-plot", "{store}", "--metric", "failure", "--x", "h_a", "--out", "{o}/p.png"],
        BAD,
        ("--metric",),
    ),
    (
        "plot-metric",
        ["sweep-plot", "{store}", "--metric", "nope", "--x", "h_a", "--out", "{o}/p.png"],
        BAD,
        ("--metric",),
    ),
    (
        "plot-x",
        ["sweep-plot", "{store}", "--metric", "regime", "--x", "nope", "--out", "{o}/p.png"],
        BAD,
        ("nope",),
    ),
    (
        "plot-unit-zz",
        [
            "sweep-plot",
            "{store}",
            "--metric",
            "regime",
            "--x",
            "h_a",
            "--unit",
            "zz=mm",
            "--out",
            "{o}/p.png",
        ],
        BAD,
        ("--unit",),
    ),
    (
        "plot-unit-bad",
        [
            "sweep-plot",
            "{store}",
            "--metric",
            "regime",
            "--x",
            "h_a",
            "--unit",
            "h_a=kg",
            "--out",
            "{o}/p.png",
        ],
        BAD,
        ("--unit", "not a unit of the same kind; allowed e.g. 'mm', 'um'"),
    ),
    (
        "plot-unit-pow",
        [
            "sweep-plot",
            "{store}",
            "--metric",
            "regime",
            "--x",
            "h_a",
            "--unit",
            "h_a=m**9**9**9",
            "--out",
            "{o}/p.png",
        ],
        BAD,
        ("--unit",),
    ),
    (
        "plot-unit-noeq",
        [
            "sweep-plot",
            "{store}",
            "--metric",
            "regime",
            "--x",
            "h_a",
            "--unit",
            "mm",
            "--out",
            "{o}/p.png",
        ],
        BAD,
        ("--unit",),
    ),
    (
        "plot-sel",
        [
            "sweep-plot",
            "{store}",
            "--metric",
            "regime",
            "--x",
            "h_a",
            "--sel",
            "zz=1",
            "--out",
            "{o}/p.png",
        ],
        BAD,
        ("--sel",),
    ),
    (
        "plot-out-dir",
        ["sweep-plot", "{store}", "--metric", "regime", "--x", "h_a", "--out", "{fx}"],
        BAD,
        ("--out",),
    ),
    (
        "plot-out-under-file",
        ["sweep-plot", "{store}", "--metric", "regime", "--x", "h_a", "--out", "{o}/a_file/p.png"],
        BAD,
        ("a_file",),
    ),
    (
        "plot-out-ro",
        ["sweep-plot", "{store}", "--metric", "regime", "--x", "h_a", "--out", "{ro}/p.png"],
        BAD,
        ("{ro}",),
    ),
    (
        "plot-out-nw",
        ["sweep-plot", "{store}", "--metric", "regime", "--x", "h_a", "--out", "{nw}/p.png"],
        BAD,
        ("--out", "{nw}/p.png"),
    ),
    (
        "plot-not-store",
        ["sweep-plot", "{fx}", "--metric", "regime", "--x", "h_a", "--out", "{o}/p.png"],
        BAD,
        ("STORE",),
    ),
    (
        "plot-missing-store",
        ["sweep-plot", "{o}/nope", "--metric", "regime", "--x", "h_a", "--out", "{o}/p.png"],
        BAD,
        ("STORE", "nope"),
    ),
    (
        "plot-corrupt-store",
        ["sweep-plot", "{corrupt}", "--metric", "regime", "--x", "h_a", "--out", "{o}/p.png"],
        FAIL,
        ("checksum",),
    ),
    # ---------------------------------------------------------------- machine
    (
        "machine-latin1",
        ["machine", "{fx}/machine_latin1.toml", "--out", "{o}/m"],
        BAD,
        ("machine_latin1.toml",),
    ),
    (
        "machine-empty",
        ["machine", "{fx}/machine_empty.toml", "--out", "{o}/m"],
        BAD,
        ("machine_empty.toml",),
    ),
    (
        "machine-unknown",
        ["machine", "{fx}/machine_unknown.toml", "--out", "{o}/m"],
        BAD,
        ("horn_gear",),
    ),
    (
        "machine-deep",
        ["machine", "{fx}/machine_deep.toml", "--out", "{o}/m"],
        BAD,
        ("machine_deep.toml",),
    ),
    (
        "machine-frames-huge",
        ["machine", "{fx}/machine_empty.toml", "--out", "{o}/m", "--frames", "100000"],
        BAD,
        ("--frames",),
    ),
    (
        "machine-frames-neg",
        ["machine", "{fx}/machine_empty.toml", "--out", "{o}/m", "--frames", "-1"],
        BAD,
        ("--frames",),
    ),
    (
        "machine-workers-neg",
        ["machine", "{fx}/machine_empty.toml", "--out", "{o}/m", "--workers", "-1"],
        BAD,
        ("--workers",),
    ),
    (
        "machine-duration-unit",
        ["machine", "examples/machine16.toml", "--out", "{o}/m", "--duration", "1 kg"],
        BAD,
        ("--duration",),
    ),
    (
        "machine-out-file",
        ["machine", "examples/machine16.toml", "--out", "{o}/a_file"],
        BAD,
        ("a_file",),
    ),
    (
        "machine-out-under-file",
        ["machine", "examples/machine16.toml", "--out", "{o}/a_file/m"],
        BAD,
        ("a_file",),
    ),
    ("machine-out-ro", ["machine", "examples/machine16.toml", "--out", "{ro}/m"], BAD, ("{ro}",)),
    (
        "machine-out-nonempty",
        ["machine", "examples/machine16.toml", "--out", "{fx}"],
        BAD,
        ("--out",),
    ),
    # ---------------------------------------------------------------- design
    (
        "design-latin1",
        ["design", "{fx}/design_latin1.toml", "--out", "{o}/d"],
        BAD,
        ("design_latin1.toml",),
    ),
    (
        "design-empty",
        ["design", "{fx}/design_empty.toml", "--out", "{o}/d"],
        BAD,
        ("design_empty.toml",),
    ),
    ("design-unknown", ["design", "{fx}/design_unknown.toml", "--out", "{o}/d"], BAD, ("nam",)),
    (
        "design-deep",
        ["design", "{fx}/design_deep.toml", "--out", "{o}/d"],
        BAD,
        ("design_deep.toml",),
    ),
    (
        "design-workers-negative",
        ["design", "examples/design16.toml", "--out", "{o}/d", "--workers", "-1"],
        BAD,
        ("--workers",),
    ),
    (
        "design-out-file",
        ["design", "examples/design16.toml", "--out", "{o}/a_file"],
        BAD,
        ("a_file",),
    ),
    (
        "design-out-under-file",
        ["design", "examples/design16.toml", "--out", "{o}/a_file/d"],
        BAD,
        ("a_file",),
    ),
    ("design-out-ro", ["design", "examples/design16.toml", "--out", "{ro}/d"], BAD, ("{ro}",)),
    ("design-out-nw", ["design", "examples/design16.toml", "--out", "{nw}/d"], BAD, ("{nw}/d",)),
    # ---------------------------------------------------------------- paper
    ("paper-out-file", ["paper", "--out", "{o}/a_file"], BAD, ("a_file",)),
    ("paper-out-under-file", ["paper", "--out", "{o}/a_file/p"], BAD, ("a_file",)),
    ("paper-out-ro", ["paper", "--out", "{ro}/p"], BAD, ("{ro}",)),
    ("paper-out-nw", ["paper", "--out", "{nw}/p"], BAD, ("{nw}/p",)),
    ("paper-out-nonempty", ["paper", "--out", "{fx}"], BAD, ("--out",)),
    # ---------------------------------------------------------------- top level
    ("top-unknown-verb", ["nope"], BAD, ("nope", "No such command")),
]

#: axis names a store must refuse (each becomes a folder of the store)
BAD_AXIS_NAMES = [
    "failure",
    "_sweep",
    "..",
    ".",
    "a/../b",
    "zarr.json",
    "/abs/path",
    "a/b",
    "regime",
    "t",
    "run",
    "",
]


def _write_axis_specs(fx: Path) -> None:
    import json

    for i, name in enumerate(BAD_AXIS_NAMES):
        (fx / f"axis_name_{i}.toml").write_text(
            'scenario = "paper-3.1"\nduration = "0.004 s"\n[[axes]]\n'
            f'key = "track.vibration_amplitude"\nname = {json.dumps(name)}\n'
            'values = ["0.1 mm"]\n'
        )


@pytest.fixture(scope="session")
def fx(tmp_path_factory) -> Path:
    root = write_files(tmp_path_factory.mktemp("fuzz_inputs"))
    (root / "good_sweep.toml").write_text(GOOD_SWEEP)
    (root / "sweep_reversed_ok.toml").write_text(GOOD_SWEEP.replace("0.004 s", "0.003 s"))
    _write_axis_specs(root)
    return root


@pytest.fixture(scope="session")
def store(fx, tmp_path_factory) -> Path:
    from braidsim.sweep import load_spec, run_sweep

    path = tmp_path_factory.mktemp("fuzz_store") / "good.zarr"
    run_sweep(load_spec(fx / "good_sweep.toml"), path, processes=1, progress=False)
    return path


@pytest.fixture(scope="session")
def corrupt(store, tmp_path_factory) -> Path:
    """A copy of the store with one bit flipped in one chunk file."""
    import shutil

    path = tmp_path_factory.mktemp("fuzz_corrupt") / "corrupt.zarr"
    shutil.copytree(store, path)
    chunk = path / "track_max_contact_force" / "c" / "1"
    data = bytearray(chunk.read_bytes())
    data[len(data) // 2] ^= 0x04
    chunk.write_bytes(bytes(data))
    return path


def _readonly_dir(tmp: Path) -> Path | None:
    """A folder this process cannot write, or None (root writes everywhere chmod allows)."""
    d = tmp / "ro"
    d.mkdir()
    d.chmod(stat.S_IRUSR | stat.S_IXUSR)
    if not os.access(d, os.W_OK):
        return d
    for cand in (Path("/proc/sys"), Path("/sys/fs/cgroup")):
        if cand.is_dir() and not os.access(cand, os.W_OK):
            return cand
    return None


@pytest.mark.parametrize(("case_id", "argv", "codes", "names"), CASES, ids=[c[0] for c in CASES])
def test_cli_case(case_id, argv, codes, names, fx, store, corrupt, tmp_path) -> None:
    out = tmp_path / "o"
    out.mkdir()
    (out / "a_file").write_text("not a directory\n")
    ro = _readonly_dir(tmp_path)
    if any("{ro}" in a for a in argv) and ro is None:
        pytest.skip("no read-only folder available to this user")
    if any("{nw}" in a for a in argv) and not Path("/proc/self").is_dir():
        pytest.skip("needs Linux /proc")
    subs = {
        "{fx}": str(fx),
        "{o}": str(out),
        "{store}": str(store),
        "{corrupt}": str(corrupt),
        "{ro}": str(ro),
        "{nw}": "/proc",
    }

    def sub(text: str) -> str:
        for k, v in subs.items():
            text = text.replace(k, v)
        return text

    codes_t = codes if isinstance(codes, tuple) else (codes,)
    why = check_refused(
        case_id,
        [sub(a) for a in argv],
        codes_t,
        tuple(sub(n) for n in names),
        watch=out,
    )
    assert why is None, why


# -------------------------------------------------------------------- damaged stores


def _damage(store: Path, how: str) -> None:
    import json
    import shutil

    if how == "root-garbage":
        (store / "zarr.json").write_text("{not json")
    elif how == "root-missing":
        (store / "zarr.json").unlink()
    elif how == "root-format":
        meta = json.loads((store / "zarr.json").read_text())
        meta["attributes"]["format"] = "something-else/9"
        (store / "zarr.json").write_text(json.dumps(meta))
    elif how == "array-missing":
        shutil.rmtree(store / "regime")
    elif how == "array-meta-garbage":
        (store / "regime" / "zarr.json").write_text("[]")
    elif how == "chunk-truncated":
        p = store / "regime" / "c" / "0"
        p.write_bytes(p.read_bytes()[:3])
    elif how == "chunk-is-dir":
        p = store / "track_max_contact_force" / "c" / "1"
        p.unlink()
        p.mkdir()
    elif how == "done-missing":
        shutil.rmtree(store / "_sweep" / "done")
    elif how == "done-garbage":
        (store / "_sweep" / "done" / "c" / "0").write_bytes(b"xx")
    else:
        raise AssertionError(how)


DAMAGES = [
    "root-garbage",
    "root-missing",
    "root-format",
    "array-missing",
    "array-meta-garbage",
    "chunk-truncated",
    "chunk-is-dir",
    "done-missing",
    "done-garbage",
]


@pytest.mark.parametrize("how", DAMAGES)
@pytest.mark.parametrize("verb", ["sweep-plot", "resume"])
def test_damaged_store(how, verb, store, fx, tmp_path) -> None:
    """A damaged store: reading it is refused in one line naming it (exit 2 when it is not a
    sweep store, 1 when a sweep store's data is damaged); --resume either repairs it (the
    damaged chunks computed again) or refuses it in one line."""
    import shutil

    from braidsim.sweep import open_sweep

    s = tmp_path / "s.zarr"
    shutil.copytree(store, s)
    _damage(s, how)
    if verb == "sweep-plot":
        argv = ["sweep-plot", str(s), "--metric", "regime", "--x", "h_a", "--out"]
        argv.append(str(tmp_path / "p.png"))
        why = check_refused(f"store-{how}-plot", argv, EITHER, (str(s),))
        assert why is None, why
        assert not (tmp_path / "p.png").exists()
        return
    from fuzz.harness import RECORD, judge, run_cli

    code, out, err = run_cli(
        ["sweep", str(fx / "good_sweep.toml"), "--out", str(s), "--resume", "--no-progress"]
    )
    if code == 0:
        ds = open_sweep(s)  # repaired: reads back whole and equal to the good store
        ref = open_sweep(store)
        ok = all(ds[v].equals(ref[v]) for v in ref.data_vars) and set(ds.data_vars) == set(
            ref.data_vars
        )
        RECORD.add(f"store-{how}-resume", None if ok else "repaired store differs")
        assert ok
        return
    why = judge(code, out, err, EITHER, (str(s),))
    if why is None and "--resume`" in err:
        why = "--resume refused the store and sent the user to --resume again"
    RECORD.add(f"store-{how}-resume", why)
    assert why is None, why


# -------------------------------------------------------------------- --set over every key


def bad_set_values(key: str) -> list[str]:
    """Texts of ``--set KEY=TEXT`` that ``key`` must refuse, by the kind of the key."""
    from braidsim.params import SCHEMA

    spec = SCHEMA[key]
    wrong = "3 s" if spec.unit in ("kg", "m") or not spec.unit else "3 kg"
    common = ["'9**9**9 m'", "'1 m == 0.002'", "{a = 1}", "1e400", "'10**400'"]
    if spec.kind == "float":
        vals = ["nan", wrong, "[1, 2]", "true", *common]
        if not spec.allow_inf:
            vals.append("inf")
        if spec.low > -math.inf:
            vals.append(repr(spec.low - 1.0 if spec.low != 0 else -1.0))
        if spec.high < math.inf:
            vals.append(repr(spec.high + 1.0))
        return vals
    if spec.kind == "int":
        return ["nan", "inf", "2.5", "0", "1e300", "'many'", "true", *common]
    if spec.kind == "bool":
        return ["'maybe'", "2", "[true]", "{a = 1}"]
    if spec.kind == "choice":
        return ["'nope'", "1", "[]", "{a = 1}", "true"]
    if spec.kind == "floats":
        return ["'-1 s'", "[[1]]", "{a = 1}", "[nan]", "['3 kg']", "1e400"]
    if spec.kind == "harmonics":
        return ["1", "[[1]]", "[[1, 2, 3, 4]]", "[[1, nan, 0]]", "[[1, -1, 0]]", "{a = 1}"]
    if spec.kind == "profile":
        return [
            "{times = 1, speeds = 2}",
            "{times = [0, 1], speeds = [1]}",
            "{times = [1, 0], speeds = [1, 1]}",
            "5",
            "{times = [0, 1], speeds = [-1, 1]}",
        ]
    raise AssertionError(spec.kind)


def _set_cases(per_key: int | None) -> list[tuple[str, str]]:
    from braidsim.params import SCHEMA

    out = []
    for key in SCHEMA:
        vals = bad_set_values(key)
        for text in vals if per_key is None else vals[:per_key]:
            out.append((key, text))
    return out


def _check_set_case(key: str, text: str) -> str | None:
    return check_refused(f"set {key}={text}", ["run", S, "--set", f"{key}={text}"], (2,), (key,))


@pytest.mark.parametrize(("key", "text"), _set_cases(3))
def test_set_every_key_bounded(key, text) -> None:
    why = _check_set_case(key, text)
    assert why is None, why


@pytest.mark.slow
def test_set_every_key_full_size() -> None:
    bad = {}
    for key, text in _set_cases(None):
        why = _check_set_case(key, text)
        if why is not None:
            bad[f"{key}={text}"] = why
    assert not bad, bad
