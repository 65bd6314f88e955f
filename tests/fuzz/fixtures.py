"""Input files for the fuzzing suite: bad scenario, sweep, machine and design specs, broken
run folders and stores, written into a folder once per session."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

GOOD_SWEEP = """
scenario = "paper-3.1"
duration = "0.004 s"

[[axes]]
key = "track.vibration_amplitude"
name = "h_a"
values = ["0.05 mm", "0.1 mm"]

[metrics]
keep = ["regime", "track_max_contact_force"]

[execution]
chunk_size = 1
"""

AXIS = '[[axes]]\nkey = "track.vibration_amplitude"\n'


def sweep_with(body: str, head: str = 'scenario = "paper-3.1"\nduration = "0.004 s"\n') -> str:
    return head + body


#: name -> text (str) or bytes of the files the cases use
FILES: dict[str, str | bytes] = {
    # scenario files
    "latin1.toml": 'name = "caf\xe9"\n[carrier]\nmass = 1.2\n'.encode("latin-1"),
    "utf16.toml": "[carrier]\nmass = 1.2\n".encode("utf-16"),
    "binary.toml": bytes(range(256)),
    "deep_array.toml": "x = " + "[" * 4000 + "]" * 4000 + "\n",
    "deep_table.toml": "x = " + "{a = " * 3000 + "1" + "}" * 3000 + "\n",
    "deep_dotted.toml": "[" + ".".join(["a"] * 40) + "]\nb = 1\n",
    "empty.toml": "",
    "only_meta.toml": 'name = "nothing"\ndescription = "no keys"\n',
    "nan_steps.toml": "[simulation]\nmax_steps = nan\n",
    "inf_steps.toml": "[simulation]\nmax_steps = inf\n",
    "huge_steps.toml": "[simulation]\nmax_steps = 1e300\n",
    "float_steps.toml": "[simulation]\nmax_steps = 1.5\n",
    "profile_bad.toml": "[horn_gear.speed_profile]\ntimes = 1\nspeeds = 2\n",
    "profile_str.toml": 'horn_gear.speed_profile = "fast"\n',
    "harmonics_bad.toml": "[horn_gear]\nspeed_harmonics = [[1, 2, 3, 4]]\n",
    "harmonics_scalar.toml": "[track]\nharmonics = 5\n",
    "clearance_table.toml": "[track]\nclearance = {value = 3}\n",
    "clearance_list.toml": "[track]\nclearance = [1, 2]\n",
    "clearance_bool.toml": "[track]\nclearance = true\n",
    "clearance_date.toml": "[track]\nclearance = 1979-05-27\n",
    "clearance_pow.toml": '[track]\nclearance = "9**9**9 m"\n',
    "clearance_eq.toml": '[track]\nclearance = "1 m == 0.002"\n',
    "unknown_key.toml": "[carrier]\nmas = 1.2\n",
    "extends_missing.toml": 'extends = "nope.toml"\n',
    "extends_self.toml": 'extends = "extends_self.toml"\n',
    "extends_list.toml": 'extends = ["paper-3.1"]\n',
    "malformed.toml": "[track\n",
    "dup_key.toml": "[carrier]\nmass = 1\nmass = 2\n",
    # sweep specs
    "sweep_latin1.toml": ("scenario = 'paper-3.1'\nname = 'caf\xe9'\n").encode("latin-1"),
    "sweep_empty.toml": "",
    "sweep_no_axes.toml": 'scenario = "paper-3.1"\n',
    "sweep_reversed.toml": sweep_with(AXIS + 'start = "0.2 mm"\nstop = "0.1 mm"\nnum = 3\n'),
    "sweep_huge_num.toml": sweep_with(
        AXIS + 'start = "0.1 mm"\nstop = "0.2 mm"\nnum = 10000000000\n'
    ),
    "sweep_huge_grid.toml": sweep_with(
        AXIS
        + 'start = "0.1 mm"\nstop = "0.2 mm"\nnum = 100000\n'
        + '[[axes]]\nkey = "track.clearance"\nstart = "1 mm"\nstop = "4 mm"\nnum = 100000\n'
    ),
    "sweep_huge_samples.toml": sweep_with(
        "[samples]\nn = 10000000000\n[samples.ranges]\n"
        '"track.clearance" = {low = "1 mm", high = "4 mm"}\n'
    ),
    "sweep_huge_series.toml": sweep_with(
        AXIS + 'values = ["0.1 mm", "0.2 mm"]\n[series]\nvariables = ["x"]\nstart = "0 s"\n'
        'stop = "0.004 s"\nnum = 100000000\n'
    ),
    "sweep_big_store.toml": sweep_with(
        AXIS + 'start = "0.01 mm"\nstop = "0.2 mm"\nnum = 1000000\n'
        '[[axes]]\nkey = "track.clearance"\nvalues = ["1 mm", "2 mm", "3 mm", "4 mm", "5 mm"]\n'
        '[series]\nvariables = ["x"]\nstart = "0 s"\nstop = "0.004 s"\nnum = 2000\n'
    ),
    "sweep_pow.toml": sweep_with(AXIS + 'values = ["9**9**9 m"]\n'),
    "sweep_nan_num.toml": sweep_with(AXIS + 'start = "0.1 mm"\nstop = "0.2 mm"\nnum = nan\n'),
    "sweep_bad_metric.toml": sweep_with(AXIS + 'values = ["0.1 mm"]\n[metrics]\nkeep = ["nope"]\n'),
    "sweep_deep.toml": "x = " + "[" * 4000 + "]" * 4000 + "\n",
    "sweep_chunk0.toml": sweep_with(AXIS + 'values = ["0.1 mm"]\n[execution]\nchunk_size = 0\n'),
    "sweep_window.toml": sweep_with(
        AXIS + 'values = ["0.1 mm"]\n[metrics]\nwindow = ["1 s", "2 s"]\n'
    ),
    "sweep_scenario_int.toml": "scenario = 5\n" + AXIS + 'values = ["0.1 mm"]\n',
    "sweep_axis_str.toml": 'scenario = "paper-3.1"\naxes = "h_a"\n',
    # machine and design specs
    "machine_latin1.toml": ("name = 'caf\xe9'\nscenario = 'paper-3.2'\n").encode("latin-1"),
    "machine_empty.toml": "",
    "machine_unknown.toml": 'scenario = "paper-3.2"\n[machine]\nhorn_gear = 8\n',
    "machine_deep.toml": "x = " + "[" * 4000 + "]" * 4000 + "\n",
    "design_latin1.toml": ("name = 'caf\xe9'\n").encode("latin-1"),
    "design_empty.toml": "",
    "design_unknown.toml": 'nam = "x"\n',
    "design_deep.toml": "x = " + "{a = " * 3000 + "1" + "}" * 3000 + "\n",
    # run folders for analyze
    "run_garbage/summary.json": "{not json",
    "run_nokeys/summary.json": json.dumps({"scenario": "x"}),
    "run_badparams/summary.json": json.dumps(
        {"parameters": {"track.clearance": "9**9**9 m"}, "final": {"t": 0.1}}
    ),
    "run_latin1/summary.json": b'{"scenario": "caf\xe9"}',
    "run_empty/.keep": "",
    # files where directories are expected
    "a_file": "not a directory\n",
}


def write_files(root: Path) -> Path:
    """Write :data:`FILES` under ``root``; return ``root``."""
    for name, content in FILES.items():
        p = root / name
        p.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            p.write_bytes(content)
        else:
            p.write_text(textwrap.dedent(content) if content.startswith("\n") else content)
    return root
