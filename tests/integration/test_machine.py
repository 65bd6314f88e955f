"""The machine run: one carrier against paper-3.2 and closed forms, transfer timing against the
horn-gear speed, the 16-carrier example at reduced length, the command line."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import braidsim
from braidsim.cli import main
from braidsim.machine import load_machine_spec, parse_machine_spec, run_machine
from braidsim.machine.kinematics import revolution_time

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "machine16.toml"


def one_carrier(duration: float, **machine: Any) -> dict[str, Any]:
    return {
        "scenario": "paper-3.2",
        "duration": duration,
        "machine": {"horn_gears": 8, "loading": {"A": [0], "B": []}, **machine},
        "animation": {"enabled": False},
    }


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main(list(argv))
    out, err = capsys.readouterr()
    return int(exc.value.code or 0), out, err


def test_one_carrier_at_constant_speed_reproduces_paper_3_2() -> None:
    """One carrier resting on the inner wall meets its first crossing: the impacts after the
    transfer are those of the single-carrier paper-3.2 run shifted by the transfer time, and
    every later transfer repeats them (the carrier settles within each arc)."""
    spec = parse_machine_spec(one_carrier(1.0))
    run = run_machine(spec, workers=1)
    tr = run.transfers
    # A0 on 8 gears at 4 pi rad/s: first crossing after a quarter turn, then inner and outer
    # arcs of (pi -+ 2 pi/8) / omega = 0.1875 s and 0.3125 s
    np.testing.assert_allclose(tr["t"], [0.25, 0.4375, 0.75, 0.9375], rtol=0, atol=1e-14)
    assert list(tr["arc"]) == ["inner", "outer", "inner", "outer"]
    t1, dt1 = float(tr["t"].iloc[0]), float(tr["interval"].iloc[0])
    ref = braidsim.simulate("paper-3.2", duration=dt1, sample_times=[0.0, dt1], record_events=False)
    after = run.impacts[run.impacts["interval"] == 1]
    assert len(after) == len(ref.impacts) == int(tr["impacts"].iloc[0]) >= 3
    np.testing.assert_allclose(
        after["t"].to_numpy() - t1, ref.impacts["t"].to_numpy(), rtol=0, atol=2e-6
    )
    np.testing.assert_allclose(
        after["peak_force"].to_numpy(), ref.impacts["peak_force"].to_numpy(), rtol=2e-3
    )
    assert tr["peak_force"].iloc[0] == pytest.approx(ref.impacts["peak_force"].max(), rel=2e-3)
    assert tr["dissipated_energy"].iloc[0] == pytest.approx(
        ref.series["track_dissipated"][-1], rel=1e-4
    )
    # nothing happens before the first transfer (the carrier starts at rest)
    assert (run.impacts["interval"] == 0).sum() == 0
    done = tr[tr["complete"]]
    assert len(done) == 3
    np.testing.assert_allclose(done["peak_force"], done["peak_force"].iloc[0], rtol=1e-6)


def test_start_from_the_scenario() -> None:
    """start = "scenario" keeps the scenario's initial state: paper-3.2 starts as a transfer."""
    spec = parse_machine_spec(one_carrier(0.3, start="scenario"))
    run = run_machine(spec, workers=1)
    ref = braidsim.simulate("paper-3.2", duration=0.25, sample_interval=0.0)
    before = run.impacts[run.impacts["interval"] == 0]
    np.testing.assert_allclose(before["t"], ref.impacts["t"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(before["peak_force"], ref.impacts["peak_force"], rtol=1e-9)


def test_a_clearance_below_the_scenarios_start_is_taken_with_the_rest_start() -> None:
    """paper-3.2 starts on its outer wall at x0 = 3 mm; a machine spec that narrows the
    clearance to 1.4 mm (the design study's clearance lever goes to 1.5 mm) was refused for
    that start, "initial.x: 3 mm is out of range", though the carriers start at rest on the
    inner wall instead. With start = "scenario" the scenario's own start is the carriers',
    and it is refused, naming it."""
    narrow = {**one_carrier(0.3), "overrides": {"track.clearance": "1.4 mm"}}
    spec = parse_machine_spec(narrow)
    assert spec.scenario["track.clearance"] == pytest.approx(1.4e-3)
    assert spec.scenario["initial.x"] < 0.0  # at rest, pressed into the inner wall
    narrow["machine"] = {**narrow["machine"], "start": "scenario"}
    with pytest.raises(braidsim.InputError, match=r"initial\.x: 3 mm is out of range"):
        parse_machine_spec(narrow)


def test_the_slot_contacts_totals_beside_the_tracks() -> None:
    """A two-DOF machine gives the slot contact's totals (they were in the carriers' rows
    only, and the report's table read as the machine's): sums over the carriers, and none
    in a one-DOF run."""
    two = {**one_carrier(0.3), "overrides": {"simulation.dof": "xy"}}
    run = run_machine(parse_machine_spec(two), workers=1)
    sl = run.totals["slot"]
    ca = run.carriers
    assert sl["impacts"] == int(ca["slot_impacts"].sum()) > 0
    assert sl["impacts_per_second"] == pytest.approx(sl["impacts"] / run.duration)
    assert sl["impact_energy_per_second"] == pytest.approx(
        ca["slot_impact_energy"].sum() / run.duration
    )
    assert sl["max_peak_force"] == ca["slot_max_peak_force"].max() > 0.0
    assert "slot" not in run_machine(parse_machine_spec(one_carrier(0.3)), workers=1).totals


def test_a_speed_that_presses_the_carriers_through_the_clearance_is_refused() -> None:
    """At 1e9 rpm the rest start's static deflection (centrifugal load) is 1e6 mm: refused
    naming machine.speed and the largest speed the clearance allows (it named initial.x)."""
    with pytest.raises(braidsim.InputError, match=r"machine\.speed: .* allowed below 7243 rad/s"):
        parse_machine_spec(one_carrier(0.3, speed="1e9 rpm"))


def test_a_clearance_the_yarn_tension_alone_closes_is_refused_naming_the_clearance() -> None:
    """At 3e-5 mm of clearance the yarn tension alone presses the resting carrier deeper than
    the clearance, so no speed, not even 0, allows the rest start: refused naming
    track.clearance and its least value (it named machine.speed, "allowed below 0 rad/s",
    and called the whole load centrifugal). The least value stated is allowed."""

    def spec(clearance: str, speed: str = "120 rpm") -> dict[str, Any]:
        d = one_carrier(0.3, speed=speed)
        d["overrides"] = {"track.clearance": clearance}
        return d

    with pytest.raises(braidsim.InputError) as exc:
        parse_machine_spec(spec("0.00003 mm"))
    msg = str(exc.value)
    assert msg.startswith("track.clearance: 3e-05 mm is less than the ")
    assert "yarn tension T1 cos(phi)" in msg and "centrifugal m r_c omega^2" in msg
    least = re.fullmatch(r".*; allowed >= ([0-9.e+-]+) mm", msg)
    assert least is not None, msg
    parse_machine_spec(spec(f"{least.group(1)} mm"))  # the value stated is allowed
    # a clearance that the tension alone leaves open: the speed is to blame, and its limit
    # (stated rounded down) is allowed
    with pytest.raises(braidsim.InputError) as exc:
        parse_machine_spec(spec("0.01 mm", speed="2000 rpm"))
    msg = str(exc.value)
    top = re.fullmatch(
        r"machine\.speed: .*yarn tension.*plus centrifugal.*allowed below (\S+) "
        r"rad/s",
        msg,
    )
    assert top is not None, msg
    parse_machine_spec(spec("0.01 mm", speed=f"{top.group(1)} rad/s"))


def test_spec_frames_have_the_limit_of_the_frames_option(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """animation.frames as --frames (docs/guarantees.md): 0 is no animation, up to 10 000,
    raised by BRAIDSIM_MAX_FRAMES (the spec allowed 1 to 2000)."""

    def spec(frames: Any) -> dict[str, Any]:
        return {**one_carrier(0.05), "animation": {"frames": frames}}

    assert parse_machine_spec(spec(3000)).animation.frames == 3000
    none = parse_machine_spec(spec(0))
    assert none.animation.frames == 0
    assert run_machine(none, workers=1).frame_times.size == 0
    with pytest.raises(
        braidsim.InputError,
        match=r"^animation\.frames: 1\.5e\+04 frames "
        r"exceeds the limit of 1e\+04 frames; .*BRAIDSIM_MAX_FRAMES",
    ):
        parse_machine_spec(spec(15000))
    for bad in (-1, 2.5, True):
        with pytest.raises(
            braidsim.InputError,
            match=r"^animation\.frames: .* allowed an "
            r"integer >= 0 \(0: no animation\)",
        ):
            parse_machine_spec(spec(bad))
    monkeypatch.setenv("BRAIDSIM_MAX_FRAMES", "20000")
    assert parse_machine_spec(spec(15000)).animation.frames == 15000


def test_every_transfer_against_closed_forms() -> None:
    """Outside references for each complete transfer of one carrier (no track vibration):

    * first inner-wall approach speed v = sqrt(v_c^2 + 2 (F - f) eps_g / m), the carrier
      crossing the gap from the far wall under the load F = T1 cos(phi) + m r_c omega^2
      against the saturated friction f = mu1 |m g - T2| (Eq. 14);
    * energy balance from rest to rest: track damping + friction dissipate
      F (eps_g + delta) + m v_c^2 / 2 - K delta^(n+1) / (n+1), delta = (F/K)^(1/n) the
      resting depth.
    """
    spec = parse_machine_spec(one_carrier(1.0, horn_gears=6))
    sc = spec.scenario
    run = run_machine(spec, workers=1)
    done = run.transfers[run.transfers["complete"]]
    assert len(done) >= 3
    m = sc["carrier.mass"]
    F = (
        sc["yarn.tension_horizontal"] * math.cos(sc["yarn.angle"])
        + m * sc["carrier.turning_radius"] * sc["horn_gear.angular_velocity"] ** 2
    )
    f = sc["friction.carrier_horn_gear"] * abs(m * sc["gravity"] - sc["yarn.tension_vertical"])
    eps, vc = sc["track.clearance"], sc["transfer.contact_speed"]
    v = math.sqrt(vc**2 + 2 * (F - f) * eps / m)
    np.testing.assert_allclose(done["approach_speed"], v, rtol=1e-3)
    np.testing.assert_allclose(done["gap_crossing_speed"], v, rtol=1e-3)
    model = braidsim.build_model(sc)
    K, n = model.track.stiffness, model.track.exponent
    delta = (F / K) ** (1 / n)
    energy = F * (eps + delta) + 0.5 * m * vc**2 - K * delta ** (n + 1) / (n + 1)
    np.testing.assert_allclose(
        done["dissipated_energy"] + done["friction_energy"], energy, rtol=1e-5
    )


def test_transfer_times_follow_a_speed_profile_with_the_mean_held() -> None:
    """With a speed profile over the transfer cycle the transfers still fall on the slot
    meetings: whole cycles, whose time T_c = Theta_c / omega_mean is that of the constant
    speed; the gears turn N pi per revolution time (production rate held). A profile that
    stays slow while the carrier crosses the gap lowers the centrifugal load and with it the
    approach speed of the first impact to the closed form at the slow speed. (This profile
    speeds up while the carrier still bounces, which pumps energy into the bounces: its later
    impacts are harder; the design studies have to weigh that.)"""
    prof = {"phase": [0.0, 0.6, 0.7, 0.9, 1.0], "factor": [0.6, 0.6, 1.8, 1.8, 0.6]}
    spec = parse_machine_spec(one_carrier(1.0, speed_profile=prof))
    const = parse_machine_spec(one_carrier(1.0))
    assert spec.mean_speed == const.mean_speed
    assert spec.profile_scale == pytest.approx(1 / 0.96)
    Tc = spec.cycle_time
    assert Tc == pytest.approx(1 / 16, rel=1e-14)
    run = run_machine(spec, workers=1)
    base = run_machine(const, workers=1)
    t = run.transfers["t"].to_numpy()
    np.testing.assert_allclose(t / Tc, np.round(t / Tc), rtol=0, atol=1e-9)
    np.testing.assert_allclose(t, base.transfers["t"], rtol=0, atol=1e-12)
    # independent check of the rotation: trapezoidal rule on the profile's own breakpoints
    table = spec.scenario["horn_gear.speed_profile"]
    tp, wp = np.array(table[0]), np.array(table[1])
    assert np.sum(0.5 * (wp[1:] + wp[:-1]) * np.diff(tp)) == pytest.approx(math.pi / 4, rel=1e-14)
    t_rev = revolution_time(spec.mean_speed, 8)
    assert run.speed.rotation([t_rev])[1][0] == pytest.approx(8 * math.pi, rel=1e-13)
    # the speed at the transfer is the profile's phase-0 speed, held for 0.6 T_c = 37.5 ms,
    # longer than the gap crossing (about 30 ms at that speed)
    w_slow = 0.6 * spec.profile_scale * spec.mean_speed
    np.testing.assert_allclose(run.transfers["omega"], w_slow, rtol=1e-14)
    sc = spec.scenario
    m = sc["carrier.mass"]
    F = (
        sc["yarn.tension_horizontal"] * math.cos(sc["yarn.angle"])
        + m * sc["carrier.turning_radius"] * w_slow**2
    )
    f = sc["friction.carrier_horn_gear"] * abs(m * sc["gravity"] - sc["yarn.tension_vertical"])
    v = math.sqrt(sc["transfer.contact_speed"] ** 2 + 2 * (F - f) * sc["track.clearance"] / m)
    first = run.impacts[(run.impacts["wall"] == "inner")].groupby("interval")["t"].min()
    assert (first.to_numpy() - t < 0.6 * Tc).all()
    np.testing.assert_allclose(run.transfers["gap_crossing_speed"], v, rtol=1e-3)
    assert (run.transfers["gap_crossing_speed"] < base.transfers["gap_crossing_speed"]).all()
    np.testing.assert_allclose(
        base.transfers["gap_crossing_speed"], base.transfers["approach_speed"]
    )


def test_example_runs_reduced_and_its_report_is_complete(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The 16-carrier example at reduced length through the command line."""
    out = tmp_path / "m16"
    code, stdout, err = run_cli(
        capsys,
        "machine",
        str(EXAMPLE),
        "--out",
        str(out),
        "--duration",
        "0.3",
        "--frames",
        "3",
        "--workers",
        "1",
        "--json",
    )
    assert code == 0, err
    data = json.loads(stdout)
    assert data["totals"]["carriers"] == 16
    assert data["loading"]["braid_pattern"] == "2/2"
    assert data["geometry"]["ring_radius"] == pytest.approx(0.065 / math.sin(math.pi / 8))
    assert data["kinematics"]["carrier_angular_speed"] == pytest.approx(math.pi)
    b = data["kinematics"]["braid"]
    assert b["take_up_speed"] == pytest.approx(math.pi * 0.01)  # tan 45 deg = omega_c r / v
    tr_csv = (out / "transfers.csv").read_text().splitlines()
    assert len(tr_csv) - 1 == data["totals"]["transfers"] == 16  # 8 + 4 + 4 in 0.3 s
    for name in data["files"]:
        assert (out / name).is_file(), name
    from PIL import Image

    with Image.open(out / "machine.gif") as im:
        assert im.n_frames == 3
    on_disk = json.loads((out / "summary.json").read_text())
    assert on_disk["totals"] == data["totals"]
    md = (out / "report.md").read_text()
    assert "## Machine totals" in md and "| A0 |" in md
    # the per-transfer approach speeds lie near the no-vibration closed form (the 0.02 mm,
    # 60 Hz track vibration moves the wall at up to h_a omega_h = 7.5 mm/s)
    spec = load_machine_spec(EXAMPLE)
    sc = spec.scenario
    m = sc["carrier.mass"]
    F = (
        sc["yarn.tension_horizontal"] * math.cos(sc["yarn.angle"])
        + m * sc["carrier.turning_radius"] * spec.mean_speed**2
    )
    f = sc["friction.carrier_horn_gear"] * abs(m * sc["gravity"] - sc["yarn.tension_vertical"])
    v = math.sqrt(sc["transfer.contact_speed"] ** 2 + 2 * (F - f) * sc["track.clearance"] / m)
    import pandas as pd

    tr = pd.read_csv(out / "transfers.csv")
    hw = sc["track.vibration_amplitude"] * sc["track.vibration_frequency"]
    assert (abs(tr["approach_speed"] - v) <= hw).all()


def test_colliding_loading_exits_2_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec = tmp_path / "bad.toml"
    spec.write_text('[machine]\nhorn_gears = 8\nslots = 4\nloading = "hercules"\n')
    code, out, err = run_cli(capsys, "machine", str(spec), "--out", str(tmp_path / "o"))
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "pattern 'hercules' (3/3) needs at least 6 slots" in err
    assert not (tmp_path / "o").exists()
    spec.write_text("[machine]\nhorn_gears = 8\nloading = { A = [0], B = [2] }\n")
    code, _, err = run_cli(capsys, "machine", str(spec), "--out", str(tmp_path / "o"))
    assert code == 2 and "carriers A0 and B2" in err


def test_a_duration_beyond_the_transfer_limit_is_refused_up_front(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The transfers are counted before they are listed: 1e9 s of the 16-carrier example
    listed them until memory ran out (180 MB/s)."""
    code, out, err = run_cli(
        capsys, "machine", str(EXAMPLE), "--out", str(tmp_path / "o"), "--duration", "1e9 s"
    )
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "transfers of each carrier" in err and "BRAIDSIM_MAX_TRANSFERS" in err
    assert not (tmp_path / "o").exists()


def test_a_bad_duration_in_the_spec_is_named_as_the_files_with_duration_given(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The spec's own ``duration`` is the file's key, not the ``--duration`` option the
    command also has (the line read ``--duration: -1 s ...`` with a valid option)."""
    spec = tmp_path / "s.toml"
    spec.write_text('duration = "-1 s"\n[machine]\nhorn_gears = 8\n')
    for extra in ([], ["--duration", "0.01 s"]):
        code, out, err = run_cli(capsys, "machine", str(spec), "--out", str(tmp_path / "o"), *extra)
        assert code == 2 and out == "" and err.count("\n") == 1
        assert "error: duration: -1 s is out of range; allowed > 0 s" in err, err
    code, _, err = run_cli(
        capsys, "machine", str(EXAMPLE), "--out", str(tmp_path / "o"), "--duration", "-1 s"
    )
    assert code == 2 and "error: --duration: -1 s is out of range" in err


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[machine]\nhorn_gear = 8\n", "did you mean 'horn_gears'"),
        ("[machine]\nhorn_gears = 7\n", "machine.horn_gears: 7 is not allowed"),
        ("[machine]\nhorn_gears = 8\n[overrides]\n'transfer.period' = 0.2\n", "transfer.period"),
        (
            "[machine]\nhorn_gears = 8\npitch_radius = '50 mm'\n"
            "[overrides]\n'carrier.turning_radius' = '65 mm'\n",
            "differs from the machine's pitch radius",
        ),
        ("[machine]\nhorn_gears = 8\n[braid]\nmandrel_radius = '1 cm'\n", "exactly one"),
    ],
)
def test_bad_specs_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, match: str
) -> None:
    spec = tmp_path / "s.toml"
    spec.write_text(text)
    code, _, err = run_cli(capsys, "machine", str(spec), "--out", str(tmp_path / "o"))
    assert code == 2 and match in err and err.count("\n") == 1


@pytest.mark.slow
def test_results_do_not_depend_on_the_workers() -> None:
    """The pool path gives the same bits as the in-process path. (Slow: each worker process
    starts an interpreter and loads the compiled kernel, several seconds on 2 shared cores,
    much more while the kernel's compile cache is cold.)"""
    spec = parse_machine_spec(
        {
            "scenario": "paper-3.3",
            "duration": 0.15,
            "machine": {"horn_gears": 4, "loading": "diamond"},
            "animation": {"enabled": False},
        }
    )
    a = run_machine(spec, workers=1)
    b = run_machine(spec, workers=2)
    assert b.workers == 2 and len(a.plans) == 4
    assert a.transfers.equals(b.transfers) and a.carriers.equals(b.carriers)


@pytest.mark.slow
def test_example_full_length_with_animation(tmp_path: Path) -> None:
    """The example as written: one revolution (2 s), every carrier makes its 8 transfers
    (7 for the four that start on a crossing), the GIF has the spec's 48 frames."""
    spec = load_machine_spec(EXAMPLE)
    run = run_machine(spec)
    assert run.duration == pytest.approx(2.0)
    counts = run.carriers.set_index("carrier")["transfers"]
    assert sorted(set(counts)) == [7, 8] and (counts == 7).sum() == 4
    from braidsim.machine import write_report

    data = write_report(run, tmp_path / "m16")
    from PIL import Image

    with Image.open(tmp_path / "m16" / "machine.gif") as im:
        assert im.n_frames == 48
    assert data["totals"]["transfers"] == 124
