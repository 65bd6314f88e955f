"""Input handling of the Python API: unit strings wherever a time or a speed is asked for, and
a one-line InputError naming the parameter for bad input (never a raw TypeError, ValueError or
ZeroDivisionError from inside)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import braidsim
from braidsim import InputError
from braidsim.analysis import analyze, energy_balance, impact_statistics, restitution_table
from braidsim.analysis.spectra import run_spectra
from braidsim.batch import simulate_batch
from braidsim.fit import synthetic_record
from braidsim.machine import (
    braid_angle,
    carrier_angular_speed,
    load_machine_spec,
    run_machine,
)
from braidsim.machine.kinematics import revolution_time, take_up_speed

SC = "paper-3.1"
MACHINE = Path(__file__).resolve().parents[2] / "examples" / "machine16.toml"


def one_line(exc: pytest.ExceptionInfo[InputError]) -> str:
    text = str(exc.value)
    assert "\n" not in text
    return text


@pytest.fixture(scope="module")
def res() -> braidsim.Result:
    return braidsim.simulate(SC, 0.02, sample_interval=1e-4)


# ----------------------------------------------------------------------------------------
# 1. unit strings accepted everywhere a time or speed is asked for
# ----------------------------------------------------------------------------------------


def test_batch_duration_and_window_accept_unit_strings() -> None:
    a = simulate_batch(SC, [{}], duration="10 ms", window=("1 ms", "5 ms"))
    b = simulate_batch(SC, [{}], duration=0.01, window=(0.001, 0.005))
    np.testing.assert_array_equal(a.windows, b.windows)
    for name, col in a.metrics.items():
        np.testing.assert_array_equal(col, b.metrics[name], err_msg=name)
    c = simulate_batch(SC, [{}], 0.01, series=["x"], series_times=["1 ms", "2 ms"])
    np.testing.assert_array_equal(c.series_times, [0.001, 0.002])


def test_analyze_accepts_unit_strings() -> None:
    a = analyze("paper-3.3", duration="0.05 s", transient="10 ms", per_cycle=16)
    assert a.result.final["t"] == pytest.approx(0.05)
    assert a.window[0] >= 0.01
    with pytest.raises(InputError, match=r"^duration: -1 s is out of range; allowed > 0 s$"):
        analyze("paper-3.3", duration="-1 s")
    with pytest.raises(InputError, match=r"^transient: .*allowed 0 <= T < 0\.05 s"):
        analyze("paper-3.3", duration=0.05, transient="60 ms")
    with pytest.raises(InputError, match=r"^per_cycle: '256' is not allowed"):
        analyze("paper-3.3", duration=0.05, per_cycle="256")  # type: ignore[arg-type]


def test_analyze_refuses_a_window_too_short_for_the_spectra_before_running() -> None:
    """The bound each message names is the one that works: 4 samples or more in the
    half-open window (dt = T / 256)."""
    from braidsim.analysis.regimes import reference_period

    dt = reference_period(braidsim.load_scenario("paper-3.3")) / 256
    with pytest.raises(InputError, match=r"^duration: 1e-300 s is out of range: .* holds 0 "):
        analyze("paper-3.3", duration="1e-300 s")
    with pytest.raises(InputError, match=rf"^duration: .* holds 3 .*allowed {10 * dt:.6g} s"):
        analyze("paper-3.3", duration=6 * dt)
    assert analyze("paper-3.3", duration=10 * dt).spectra
    bound = 0.02 - 5 * dt
    with pytest.raises(InputError, match=rf"^transient: .* allowed at most {bound:.6g} s$"):
        analyze("paper-3.3", duration=0.02, transient=0.02 - 2 * dt)
    assert analyze("paper-3.3", duration=0.02, transient=bound).spectra
    with pytest.raises(InputError, match=r"^duration: .*or more with this transient$"):
        analyze("paper-3.3", duration=3 * dt, transient=2 * dt)


def test_run_machine_accepts_a_duration_with_a_unit() -> None:
    spec = load_machine_spec(MACHINE)
    run = run_machine(spec, duration="20 ms", workers=1, frames=0)
    assert run.duration == pytest.approx(0.02)
    assert spec.with_duration("20 ms").duration == pytest.approx(0.02)
    with pytest.raises(InputError, match=r"^duration: 0 s is out of range; allowed > 0 s$"):
        run_machine(spec, duration="0 s")
    with pytest.raises(InputError, match=r"^workers: '2' is not allowed"):
        run_machine(spec, duration=0.02, workers="2")  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"^frames: -1 is out of range"):
        run_machine(spec, duration=0.02, frames=-1)


def test_synthetic_record_accepts_unit_strings() -> None:
    a = synthetic_record(SC, "30 ms", rate="2 kHz", noise={"acceleration": "20 m/s^2"}, seed=1)
    b = synthetic_record(SC, 0.03, rate=2000.0, noise={"acceleration": 20.0}, seed=1)
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.columns["acceleration"], b.columns["acceleration"])


def test_restitution_table_accepts_unit_strings() -> None:
    a = restitution_table(["hunt_crossley"], [0.5], velocity="0.5 m/s", mass="1200 g")
    b = restitution_table(["hunt_crossley"], [0.5], velocity=0.5, mass=1.2)
    assert (a.velocity, a.mass) == (0.5, 1.2)
    np.testing.assert_array_equal(a.simulated, b.simulated)
    with pytest.raises(InputError, match=r"^velocity: -0\.5 m/s is out of range; allowed > 0"):
        restitution_table(["hunt_crossley"], [0.5], velocity="-0.5 m/s")
    with pytest.raises(InputError, match=r"^velocity: .*wrong unit"):
        restitution_table(["hunt_crossley"], [0.5], velocity="0.5 kg")
    with pytest.raises(InputError, match=r"^nominal: "):
        restitution_table(["hunt_crossley"], [1.5])


def test_windows_accept_unit_strings(res: braidsim.Result) -> None:
    a = braidsim.simulate(SC, 0.01, windows=[("1 ms", "5 ms")], sample_interval=0.0)
    b = braidsim.simulate(SC, 0.01, windows=[(0.001, 0.005)], sample_interval=0.0)
    np.testing.assert_array_equal(a.windows, b.windows)
    np.testing.assert_array_equal(a.rms_x, b.rms_x)
    e1 = energy_balance(res, window=("5 ms", "15 ms"))
    e2 = energy_balance(res, window=(0.005, 0.015))
    np.testing.assert_array_equal(e1.t, e2.t)
    assert e1.t[0] >= 0.005 and e1.t[-1] <= 0.015
    s1 = impact_statistics(res, window=("0 ms", "20 ms"))
    assert s1.window == (0.0, 0.02)
    sp = run_spectra(res, window=("5 ms", "15 ms"), quantities=("x",))
    assert sp[0].window[0] == pytest.approx(0.005)


@pytest.mark.parametrize("value", ["yes", 1, 0.0])
def test_rms_is_true_false_or_none(value: object) -> None:
    with pytest.raises(InputError, match=r"^rms: .* allowed True, False or None$"):
        braidsim.simulate(SC, 0.001, series=False, rms=value)  # type: ignore[arg-type]


def test_sample_times_accept_unit_strings() -> None:
    a = braidsim.simulate(SC, 0.01, sample_times=["1 ms", "2 ms"], record_events=False)
    np.testing.assert_array_equal(a.series["t"], [0.001, 0.002])


# ----------------------------------------------------------------------------------------
# 2. no raw errors from inside
# ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("budget", [0, -1, 1.5, "1 MB", True])
def test_max_series_bytes_must_be_a_positive_integer(budget: object) -> None:
    with pytest.raises(InputError, match=r"^max_series_bytes: .*allowed an integer > 0"):
        braidsim.simulate(SC, 0.01, max_series_bytes=budget)  # type: ignore[arg-type]


def test_max_series_bytes_still_widens_the_interval() -> None:
    res = braidsim.simulate(SC, 0.01, sample_interval=1e-5, max_series_bytes=10_000)
    assert res.stats["sample_interval"] > 1e-5


def test_flat_window_pair_is_refused() -> None:
    with pytest.raises(InputError, match=r"^windows: .*a list of \(t0, t1\) pairs") as exc:
        braidsim.simulate(SC, 0.01, windows=[0.001, 0.005])  # type: ignore[list-item]
    one_line(exc)
    with pytest.raises(InputError, match=r"^windows: .*a list of \(t0, t1\) pairs"):
        braidsim.simulate(SC, 0.01, windows=(0.001, 0.005))  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"^windows\[0\]: .* has 3 entries"):
        braidsim.simulate(SC, 0.01, windows=[(0.001, 0.002, 0.003)])  # type: ignore[list-item]
    with pytest.raises(InputError, match=r"^windows\[0\]: t1 = 0\.02 s is after the end"):
        braidsim.simulate(SC, 0.01, windows=[(0.001, 0.02)])
    with pytest.raises(InputError, match=r"^windows\[0\]: .*wrong unit"):
        braidsim.simulate(SC, 0.01, windows=[("1 mm", "5 ms")])


def test_nested_sample_times_are_refused() -> None:
    with pytest.raises(InputError, match=r"^sample_times: .*allowed a flat list of times"):
        braidsim.simulate(SC, 0.01, sample_times=[[0.001]])  # type: ignore[list-item]
    with pytest.raises(InputError, match=r"^sample_times: an array of shape \(1, 1\)"):
        braidsim.simulate(SC, 0.01, sample_times=np.array([[0.001]]))
    with pytest.raises(InputError, match=r"^sample_times: "):
        braidsim.simulate(SC, 0.01, sample_times=0.001)  # type: ignore[arg-type]


def test_batch_parameter_sets_must_be_a_list_of_dicts() -> None:
    with pytest.raises(InputError, match=r"^parameter_sets: got one dict.*\[\{\.\.\.\}\]"):
        simulate_batch(SC, {"track.clearance": 0.002}, duration=0.01)  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"^parameter_sets: entry 1 is a str"):
        simulate_batch(SC, [{}, "track.clearance"], duration=0.01)  # type: ignore[list-item]
    with pytest.raises(InputError, match=r"^parameter_sets: got int"):
        simulate_batch(SC, 3, duration=0.01)  # type: ignore[arg-type]


@pytest.mark.parametrize("workers", ["2", 1.5, None, True])
def test_batch_workers_must_be_an_integer(workers: object) -> None:
    with pytest.raises(InputError, match=r"^workers: .* is not allowed; allowed an integer"):
        simulate_batch(SC, [{}], duration=0.01, workers=workers)  # type: ignore[arg-type]


def test_batch_bad_duration_and_window() -> None:
    with pytest.raises(InputError, match=r"^duration: -1 s is out of range; allowed > 0 s$"):
        simulate_batch(SC, [{}], duration=-1)
    with pytest.raises(InputError, match=r"^duration: .*wrong unit"):
        simulate_batch(SC, [{}], duration="10 mm")
    with pytest.raises(InputError, match=r"^window: .*after the end of the shortest run"):
        simulate_batch(SC, [{}], duration=0.01, window=("1 ms", "50 ms"))
    with pytest.raises(InputError, match=r"^window: .* is not a \(t0, t1\) pair"):
        simulate_batch(SC, [{}], duration=0.01, window=0.005)  # type: ignore[arg-type]


def test_batch_series_must_be_a_list_of_names() -> None:
    with pytest.raises(InputError, match=r"^series: 'x' is one string; allowed a list"):
        simulate_batch(SC, [{}], duration=0.01, series="x", series_times=[0.005])  # type: ignore[arg-type]


def test_a_scenario_file_with_a_byte_order_mark_is_read(tmp_path: Path) -> None:
    """Windows editors write a UTF-8 byte-order mark; it was reported as malformed TOML at
    line 1, column 1, where the user sees nothing."""
    p = tmp_path / "bom.toml"
    p.write_bytes(b"\xef\xbb\xbf" + b'extends = "paper-3.1"\n"track.clearance" = "2 mm"\n')
    assert braidsim.load_scenario(p)["track.clearance"] == pytest.approx(2e-3)


def test_kinematics_refuse_bad_arguments() -> None:
    with pytest.raises(InputError, match=r"^horn_gears: 0 is out of range; allowed an even"):
        carrier_angular_speed(1.0, 0)
    with pytest.raises(InputError, match=r"^mean_speed: 0 rad/s is out of range; allowed > 0"):
        revolution_time(0.0, 8)
    with pytest.raises(InputError, match=r"^carrier_speed: -1 rad/s is out of range"):
        braid_angle(-1, 0.01, 0.01)
    with pytest.raises(InputError, match=r"^mandrel_radius: 0 m is out of range"):
        braid_angle(1.0, 0.0, 0.01)
    with pytest.raises(InputError, match=r"^take_up_speed: -0\.01 m/s is out of range"):
        braid_angle(1.0, 0.01, -0.01)
    with pytest.raises(InputError, match=r"^angle: .*allowed 0 < angle < pi/2"):
        take_up_speed(1.0, 0.01, "90 deg")
    # units: 120 rpm over 8 gears; 45 degrees from omega_c r_m = v
    assert carrier_angular_speed("120 rpm", 8) == pytest.approx(math.pi)
    assert braid_angle("60 rpm", "10 mm", 2 * math.pi * 0.01) == pytest.approx(math.pi / 4)
    assert take_up_speed(1.0, "10 mm", "45 deg") == pytest.approx(0.01)


# ----------------------------------------------------------------------------------------
# 3. no silent acceptance
# ----------------------------------------------------------------------------------------


def test_energy_balance_refuses_reversed_and_outside_windows(res: braidsim.Result) -> None:
    with pytest.raises(InputError, match=r"^window: \[0\.01, 0\.005\] s is not a time interval"):
        energy_balance(res, window=(0.01, 0.005))
    with pytest.raises(
        InputError, match=r"^window: t1 = 5 s is after the end of the run; allowed 0 <= t0 < t1 "
    ) as exc:
        energy_balance(res, window=(0.01, 5))
    assert "0.02 s" in one_line(exc)
    with pytest.raises(InputError, match=r"^window: .*is not a \(t0, t1\) pair"):
        energy_balance(res, window="1 ms")  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"^window: t0 = -1 s is before the start"):
        impact_statistics(res, window=(-1, 0.01))


@pytest.mark.parametrize("bins", [0, -1, 2.5, "20"])
def test_impact_statistics_bins_must_be_a_positive_integer(
    res: braidsim.Result, bins: object
) -> None:
    with pytest.raises(InputError, match=r"^bins: .* is out of range; allowed an integer >= 1$"):
        impact_statistics(res, bins=bins)  # type: ignore[arg-type]


def test_restitution_table_refuses_an_empty_law_list() -> None:
    with pytest.raises(InputError, match=r"^laws: an empty list; allowed one or more of .*hertz"):
        restitution_table(laws=[])
    with pytest.raises(InputError, match=r"^laws: 'hertz' is not a list of law names"):
        restitution_table(laws="hertz")
    with pytest.raises(InputError, match=r"did you mean 'hunt_crossley'"):
        restitution_table(laws=["hunt_crosley"], nominal=[0.5])


def test_synthetic_record_refuses_unknown_noise_keys() -> None:
    with pytest.raises(InputError, match=r"^noise: 'foo' is not a known quantity; allowed keys "):
        synthetic_record(SC, 0.01, noise={"foo": 1})
    with pytest.raises(InputError, match=r"^noise: 'acceleratoin' .*did you mean 'acceleration'"):
        synthetic_record(SC, 0.01, noise={"acceleratoin": 1})
    with pytest.raises(InputError, match=r"^noise: 'x' is not recorded \(add it to quantities\)"):
        synthetic_record(SC, 0.01, noise={"x": 1e-6})
    with pytest.raises(InputError, match=r"^noise\.acceleration: -1 m/s\*\*2 is out of range"):
        synthetic_record(SC, 0.01, noise={"acceleration": -1})


def test_synthetic_record_blames_the_duration() -> None:
    with pytest.raises(InputError, match=r"^duration: -1 s is out of range; allowed > 0 s$"):
        synthetic_record(SC, -1)
    with pytest.raises(InputError, match=r"^rate: 0 Hz is out of range; allowed > 0 Hz$"):
        synthetic_record(SC, 0.01, rate=0)
    with pytest.raises(InputError, match=r"^rate: 100 Hz gives fewer than 3 samples in 0\.01 s"):
        synthetic_record(SC, 0.01, rate=100)


def test_result_objects_have_one_line_reprs() -> None:
    import braidsim
    from braidsim.analysis.restitution import restitution_table

    r = braidsim.simulate("paper-3.3", 0.01, sensitivities=["track.clearance"])
    tab = restitution_table(laws=["flores"])
    for obj in (r.sensitivity, tab):
        text = repr(obj)
        assert text.startswith("<braidsim.") and "\n" not in text and len(text) < 200, text


def test_a_run_too_long_for_its_step_limit_is_refused_up_front() -> None:
    """At most max_step per step: 1e9 s at 1 ms needs 1e12 steps (days of CPU)."""
    import time

    import braidsim

    c0 = time.process_time()
    with pytest.raises(
        InputError,
        match=r"^duration: 1e\+09 s at simulation.max_step = 0.001 s, at least: "
        r"1e\+12 steps exceeds the limit of 1e\+09 steps; .*BRAIDSIM_MAX_STEPS",
    ):
        braidsim.simulate("paper-3.1", 1e9)
    assert time.process_time() - c0 < 5.0


@pytest.mark.parametrize(
    ("cycles", "interval", "limit"),
    [(1e12, None, "BRAIDSIM_MAX_STEPS"), (1e6, 1e-9, "BRAIDSIM_MAX_STEPS"), (1e7, None, None)],
)
def test_a_lyapunov_exponent_too_long_to_measure_is_refused_up_front(
    cycles, interval, limit, monkeypatch
) -> None:
    """Its intervals are short runs, each within the step limit: the whole measurement,
    two trajectories over every interval, is what counts (it ended as "out of memory",
    exit 1, allocating one number per interval, or ran for hours). 1e7 cycles of
    paper-3.1 are 1.6e8 intervals: 3.8 GB of estimates, under the default memory limit of
    4 GB but not under 1 GB."""
    import time

    from braidsim.analysis.lyapunov import carrier_lyapunov

    if limit is None:
        monkeypatch.setenv("BRAIDSIM_MAX_MEMORY", "1e9")
        limit = "BRAIDSIM_MAX_MEMORY"
    c0 = time.process_time()
    with pytest.raises(InputError, match=rf"^cycles: .* exceeds the limit of .*{limit}=N$"):
        carrier_lyapunov("paper-3.1", cycles=cycles, interval=interval)
    assert time.process_time() - c0 < 5.0


def test_the_rows_kept_in_memory_stay_within_the_memory_limit(monkeypatch) -> None:
    """The sample grid is sized beforehand; the peak rows of a long rest are counted as
    they come, and the run stops with what to change instead of growing without bound."""
    import braidsim
    from braidsim.errors import SimulationError

    # 17,857 rows of 28 columns; the rows are counted as the solver hands them over, in
    # chunks of 32,768
    monkeypatch.setenv("BRAIDSIM_MAX_MEMORY", "4e6")
    with pytest.raises(
        SimulationError,
        match=r"outgrew the memory limit .* event rows: onsets, exits, "
        r"force peaks .* record_events=False",
    ) as err:
        braidsim.simulate("paper-3.1", 100.0, sample_interval=0.01)
    assert 0.0 < err.value.time < 100.0
    # the same run without the event rows fits
    res = braidsim.simulate("paper-3.1", 100.0, sample_interval=0.01, record_events=False)
    assert res.stats["series_rows"] == 10001
    # a sink that streams the rows away is not held to it
    streamed: list[int] = []
    braidsim.simulate(
        "paper-3.1", 100.0, sample_interval=0.01, series=lambda c: streamed.append(len(c))
    )
    assert sum(streamed) > 17_857


@pytest.mark.parametrize("given", [0.3, "0.3 s"])
def test_a_duration_in_the_overrides_place_is_named(given):
    # analyze(scenario, 0.3): the second positional argument is the overrides
    with pytest.raises(InputError, match=r"overrides: .*duration is given by keyword"):
        analyze("paper-3.3", given)


def test_a_wrong_overrides_object_gets_no_duration_hint():
    with pytest.raises(InputError, match=r"got list$"):
        braidsim.load_scenario("paper-3.3").with_overrides([("initial.x", 0.0)])  # type: ignore[arg-type]


def test_a_collapse_without_stiffness_does_not_blame_friction_or_damping() -> None:
    """The message's hint names the stiffer of the friction regularisation and the contact
    damping; with no friction and an elastic contact both rates are 0, and it told the user
    to raise the friction regularisation ("rate ~ 0 1/s")."""
    from braidsim.core import layout as L
    from braidsim.model import build_model
    from braidsim.params import load_scenario
    from braidsim.simulate import failure_message

    sc = load_scenario("table1-hertz", overrides={"friction.law": "none"})
    msg = failure_message(L.ST_STEP_COLLAPSE, 0.01, build_model(sc, 0.1), {})
    assert "neither the friction regularisation nor the contact damping is stiff" in msg
    assert "regularization_velocity" not in msg
    taylor = build_model(sc.with_overrides({"simulation.integrator": "taylor"}), 0.1)
    assert 'simulation.integrator = "dormand-prince"' in failure_message(
        L.ST_STEP_COLLAPSE, 0.01, taylor, {}
    )
    # paper-3.3: the contact damping at the floor speed, 9.3e4 1/s, holds the step
    stiff = failure_message(
        L.ST_STEP_COLLAPSE, 0.01, build_model(load_scenario("paper-3.3"), 0.1), {}
    )
    assert "raise contact.min_impact_velocity" in stiff and "neither" not in stiff


@pytest.mark.parametrize(
    ("overrides", "named", "status"),
    [
        # (started off the wall: its overlap at the start would be refused up front)
        (
            {"contact.track.stiffness": 1e300, "initial.x": "0.2 mm"},
            "contact.track.stiffness = 1e+300 N/m^1.5",
            "collapsed",
        ),
        (
            {"contact.track.exponent": 4.0, "initial.vx": 1e100},
            "initial.vx = 1e+100 m/s",
            "collapsed",
        ),
        (
            {"contact.track.exponent": 4.0, "yarn.tension_horizontal": 1e100},
            "yarn.tension_horizontal = 1e+100 N",
            "NaN or infinite",
        ),
        # a value too close to 0 (every rate overflows; the hint had named another key) and
        # a table's entry (the harmonics were not read)
        (
            {"carrier.mass": "1e-300 kg", "initial.x": "0.2 mm"},
            "carrier.mass = 1e-300 kg",
            "collapsed",
        ),
        (
            {"horn_gear.speed_harmonics": [[1e300, 1, 0]]},
            "horn_gear.speed_harmonics holds 1e+300",
            "NaN or infinite",
        ),
    ],
)
def test_a_failure_names_the_values_of_extreme_magnitude(overrides, named, status) -> None:
    """A stiffness of 1e300 N/m^1.5 collapsed the step at the first impact (overflowed the
    state at t = 0 when the start overlapped the wall: refused since) and a speed of 1e100 m/s
    collapsed the step; both messages told the user only to raise
    contact.min_impact_velocity (the hint read from paper-3.3's own contact damping)."""
    with pytest.raises(braidsim.SimulationError) as info:
        braidsim.simulate("paper-3.3", 0.01, overrides=overrides, series=False)
    msg = str(info.value)
    assert status in msg and f"check the values of extreme magnitude ({named})" in msg


def test_a_stiff_contact_of_a_high_exponent_is_not_called_extreme() -> None:
    """K is in N/m^n: exponent 3 with K = 1e20 is 1e11 N at a depth of 1 mm, a stiff but
    real contact; a count (simulation.max_steps) is no magnitude either."""
    from braidsim.core import layout as L
    from braidsim.model import build_model
    from braidsim.params import load_scenario
    from braidsim.simulate import failure_message

    sc = load_scenario(
        "paper-3.1",
        overrides={
            "contact.track.exponent": 3.0,
            "contact.track.stiffness": 1e20,
            "simulation.max_steps": 2**40,
        },
    )
    msg = failure_message(L.ST_STEP_COLLAPSE, 0.01, build_model(sc, 0.1), {})
    assert "extreme" not in msg and "raise contact.min_impact_velocity" in msg


def test_result_ranges_dict_refuses_an_unknown_pair_or_window(res: braidsim.Result) -> None:
    with pytest.raises(InputError, match=r"^pair: 'trak' is not known; allowed track or slot"):
        res.ranges_dict("trak")
    with pytest.raises(InputError, match=r"^window: 5 is out of range; allowed 0 to 0 "):
        res.ranges_dict("track", 5)
    with pytest.raises(InputError, match=r"^window: 0.5 is out of range; allowed 0 to 0 "):
        res.ranges_dict("track", 0.5)  # type: ignore[arg-type]
    assert res.ranges_dict("slot", -1) == res.ranges_dict("slot", 0)  # numpy's last window


def test_result_window_index_of_a_window_not_computed(res: braidsim.Result) -> None:
    with pytest.raises(InputError, match=r"^window: \[0, 0.005\] s was not computed; allowed "):
        res.window_index(0, 0.005)
    assert res.window_index(0, 0.02) == 0


def test_simulate_refuses_series_and_record_events_of_another_type() -> None:
    """A string is truthy: "no" must not silently run with another meaning."""
    with pytest.raises(InputError, match=r"^series: 'no' is not allowed; allowed True, False or "):
        braidsim.simulate(SC, 0.01, series="no")  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"^record_events: 'no' is not allowed; allowed True or "):
        braidsim.simulate(SC, 0.01, record_events="no")  # type: ignore[arg-type]
    a = braidsim.simulate(SC, 0.01, record_events=np.bool_(False), series=np.bool_(True))
    assert a.series["t"].size > 0 and not np.any(a.series["kind"][1:-1])


def test_sample_times_must_be_finite_increasing_times_in_the_run() -> None:
    """As simulate_batch's series_times: times out of order are refused (they were sorted
    silently, repeats kept as repeated rows); a missing or NaN time is named as such."""
    with pytest.raises(InputError, match=r"^sample_times: not strictly increasing at entry 1 "):
        braidsim.simulate(SC, 0.01, sample_times=[0.005, 0.001])
    with pytest.raises(InputError, match=r"^sample_times: not strictly increasing at entry 1 "):
        braidsim.simulate(SC, 0.01, sample_times=[0.001, 0.001])
    for bad in ([0.001, float("nan")], [None]):
        with pytest.raises(InputError, match=r"^sample_times: entry \d+ is not a finite time"):
            braidsim.simulate(SC, 0.01, sample_times=bad)  # type: ignore[arg-type]
    with pytest.raises(
        InputError,
        match=r"^sample_times: 0.5 s is outside \[0, 0.01\] s; allowed increasing times 0 <= t",
    ):
        braidsim.simulate(SC, 0.01, sample_times=[0.001, 0.5])
    assert braidsim.simulate(SC, 0.01, sample_times=[], record_events=False).series["t"].size == 0


def test_overrides_take_nested_tables_as_a_scenario_mapping_does() -> None:
    """{"track": {"clearance": ...}} is read as track.clearance by load_scenario's mapping;
    as overrides it was an unknown key 'track' (did you mean 'track.harmonics'?)."""
    nested = {"track": {"clearance": "2 mm"}, "contact": {"track": {"restitution": 0.7}}}
    a = braidsim.load_scenario(SC, overrides=nested)
    b = braidsim.load_scenario(
        SC, overrides={"track.clearance": "2 mm", "contact.track.restitution": 0.7}
    )
    assert a.values == b.values and a.explicit == b.explicit
    with pytest.raises(InputError, match=r"^track.clearence: unknown parameter \(did you mean "):
        braidsim.load_scenario(SC, overrides={"track": {"clearence": "2 mm"}})
    with pytest.raises(InputError, match=r"^track.clearance: given twice"):
        braidsim.load_scenario(
            SC, overrides={"track.clearance": 1e-3, "track": {"clearance": 2e-3}}
        )


def test_sensitivities_must_be_a_list_of_keys() -> None:
    """A number was a TypeError from iterating it; a dict's keys and a numpy array of two
    keys (its truth value is ambiguous) were taken or failed inside."""
    allowed = r"allowed a list of numeric scenario keys, e.g. \['track.clearance'\]"
    for bad in (5, {"track.clearance": 1.0}, "track.clearance"):
        with pytest.raises(
            InputError, match=rf"^sensitivities: .* is not a list of keys; {allowed}"
        ):
            braidsim.simulate(SC, 0.005, sensitivities=bad)  # type: ignore[arg-type]
    with pytest.raises(
        InputError, match=rf"^sensitivities: entry 1 \(None\) is not a key; {allowed}"
    ):
        braidsim.simulate(SC, 0.005, sensitivities=["track.clearance", None])  # type: ignore[list-item]
    keys = np.array(["track.clearance", "contact.track.restitution"])
    res = braidsim.simulate(SC, 0.005, sensitivities=keys, series=False)  # type: ignore[arg-type]
    assert res.sensitivity.keys == ("track.clearance", "contact.track.restitution")
    assert all(type(k) is str for k in res.sensitivity.keys)


def test_summary_window_takes_times_with_units_as_simulate_does() -> None:
    res = braidsim.simulate(SC, 0.01, windows=[("1 ms", "5 ms")], series=False)
    assert res.summary(window=("1 ms", "5 ms"))["window"] == [0.001, 0.005]
    assert res.summary(window=("1 ms", "5 ms"))["x"] == res.summary(window=(0.001, 0.005))["x"]
    with pytest.raises(InputError, match=r"^window: \('1 ms', '5 kg'\) s is not one this result"):
        res.summary(window=("1 ms", "5 kg"))


def test_batch_series_times_are_checked_as_sample_times_are() -> None:
    """A NaN among a batch's series_times was 'must lie in [0, T]'; the same check as
    simulate's sample_times names it (one function for both)."""
    from braidsim.batch import simulate_batch

    sc = braidsim.load_scenario(SC)
    with pytest.raises(InputError, match=r"^series_times: entry 1 is not a finite time"):
        simulate_batch(sc, [{}], 0.01, series=["x"], series_times=[0.001, float("nan")])
    with pytest.raises(InputError, match=r"^series_times: not strictly increasing at entry 1"):
        simulate_batch(sc, [{}], 0.01, series=["x"], series_times=[0.002, 0.001])
    with pytest.raises(InputError, match=r"^series_times: 0.5 s is outside \[0, 0.01\] s"):
        simulate_batch(sc, [{}], 0.01, series=["x"], series_times=[0.5])


def test_a_start_state_of_another_model_is_named_so() -> None:
    """The final state of an xy run given as an x-only scenario's start was 'the state
    vector needs 7 entries, got (13,)'."""
    xy = braidsim.simulate(SC, 0.002, overrides={"simulation.dof": "xy"}, series=False)
    with pytest.raises(InputError, match=r"^start: a state of 13 entries, where this scenario's"):
        braidsim.simulate(SC, 0.002, start=xy.final_state, series=False)


def test_extends_in_a_scenario_mapping_is_explained() -> None:
    """'extends' works in a TOML file; in a mapping it was 'unknown parameter'."""
    with pytest.raises(InputError, match=r"^scenario: 'extends' is read in a scenario TOML file"):
        braidsim.load_scenario({"extends": "paper-3.1", "track.clearance": "2 mm"})


def test_a_start_overlap_that_would_throw_the_carrier_off_is_refused() -> None:
    """paper-3.3 starts 0.12 mm into its inner wall; with a stiffness of 1e30 N/m^1.5 that
    overlap stores 6.3e19 J and the run sent the carrier off at 1e10 m/s without a word.
    The largest stiffness allowed, K (n + 1) p^(n + 1) / (n + 1) = m v^2 / 2 at 5,000 m/s,
    is checked on both sides; the built-in scenarios release at most 7.3 m/s."""
    from braidsim.model import MAX_RELEASE_SPEED, build_model, start_overlaps
    from braidsim.params import builtin_names, load_scenario

    with pytest.raises(InputError) as info:
        braidsim.simulate("paper-3.3", 0.001, overrides={"contact.track.stiffness": 1e30})
    msg = str(info.value)
    assert msg.startswith("contact.track.stiffness: 1e+30 N/m^1.5 with the start's overlap")
    assert "0.12 mm into the inner track wall" in msg and "1.03e+10 m/s" in msg
    k_max = float(re.search(r"a stiffness below ([0-9.e+]+) N/m\^1.5", msg).group(1))
    m, p, n = 1.2, 0.12e-3, 1.5
    assert k_max == pytest.approx(0.5 * m * MAX_RELEASE_SPEED**2 * (n + 1) / p ** (n + 1), 1e-2)
    for k, refused in ((0.99 * k_max, False), (1.01 * k_max, True)):
        sc = load_scenario("paper-3.3", overrides={"contact.track.stiffness": k})
        if refused:
            with pytest.raises(InputError, match="stiffness below"):
                build_model(sc)
        else:
            build_model(sc)
    # a stiffness from Eq. (4) is named as such; the slot's overlap (xy) is checked too
    with pytest.raises(InputError, match=r"^the track stiffness K \(Eq. 4\): "):
        moduli = {f"materials.{b}.youngs_modulus": "1e30 Pa" for b in ("track", "guide_pad")}
        braidsim.simulate("paper-3.3", 0.001, overrides=moduli)
    with pytest.raises(InputError, match="into the rear slot wall"):
        load = {"simulation.dof": "xy", "initial.y": "-0.1 mm", "contact.slot.stiffness": 1e30}
        build_model(load_scenario("paper-3.3", overrides=load))
    for name in builtin_names():
        assert start_overlaps(load_scenario(name)) is not None
        build_model(load_scenario(name))


@pytest.mark.parametrize(
    ("name", "amount", "text"),
    [
        ("frames", 10_001, "10001 frames exceeds the limit of 10000 frames"),
        ("transfers", 1_000_001, "1000001 transfers exceeds the limit of 1000000 transfers"),
        ("runs", 1e8, "1e+08 runs exceeds the limit of 1e+07 runs"),
    ],
)
def test_a_refusal_just_over_a_limit_gives_two_different_numbers(name, amount, text) -> None:
    """Four digits made 10001 frames read "1e+04 frames exceeds the limit of 1e+04"."""
    from braidsim import limits

    with pytest.raises(InputError, match=rf"^what: {re.escape(text)}; "):
        limits.check(name, amount, "what")


def test_the_default_step_budget_of_a_very_long_run_stays_a_64_bit_integer() -> None:
    """50,000 steps per simulated second of 1e20 s are 5e24, past a 64-bit integer: the
    compiled solver refused its options ("internal error: TypingError"). The default budget
    stops at the largest one simulation.max_steps allows, 2^52."""
    from braidsim.model import build_model

    sc = braidsim.load_scenario("paper-3.1", overrides={"simulation.max_step": "1e16 s"})
    assert build_model(sc, 1e20).options.max_steps == 2**52
    assert build_model(sc, 1.0).options.max_steps == 5_000_000


@pytest.mark.parametrize(
    ("key", "value"), [("carrier.mass", 5e-324), ("horn_gear.angular_velocity", 1e300)]
)
def test_a_failed_run_of_extreme_values_is_a_simulation_error(key, value) -> None:
    """The failure message's stiffness rates divided by a subnormal mass and squared a speed
    of 1e300 rad/s: a ZeroDivisionError or OverflowError (an internal error) instead of
    the run's failure."""
    from braidsim.errors import SimulationError

    with pytest.raises(SimulationError, match=r"at t = "):
        braidsim.simulate("paper-3.1", 0.01, overrides={key: value}, sample_interval=0.0)


@pytest.mark.parametrize(
    ("call", "named"),
    [
        (lambda: braidsim.machine.parse_machine_spec(3), "spec: expected a table, got 3"),
        (lambda: braidsim.design.parse_design_spec(None), "spec: expected a table"),
        (lambda: braidsim.design.run_design(None), "spec: None is not a DesignSpec"),
        (lambda: braidsim.sweep.open_sweep(3), "path: 3 is not a path"),
        (
            lambda: braidsim.continuation.ScenarioSystem("paper-3.3"),
            "scenario: 'paper-3.3' is not a Scenario",
        ),
    ],
)
def test_specs_and_systems_of_the_wrong_kind_are_refused_naming_the_argument(
    call: object, named: str
) -> None:
    """Not a TypeError or AttributeError from deep inside: the argument and what it must be."""
    with pytest.raises(InputError) as exc:
        call()  # type: ignore[operator]
    assert one_line(exc).startswith(named)


def test_an_unknown_orbit_method_is_refused_before_the_transient_is_simulated(
    monkeypatch,
) -> None:
    from braidsim.continuation import ScenarioSystem, orbit, seed_orbit

    def no_simulation(*args: object, **kwargs: object) -> None:
        raise AssertionError("simulated before checking the method")

    monkeypatch.setattr(orbit, "simulate_state", no_simulation)
    system = ScenarioSystem(braidsim.load_scenario("paper-3.3"))
    with pytest.raises(InputError) as exc:
        seed_orbit(system, {"track.vibration_amplitude": 1e-4}, method="magic")
    assert one_line(exc) == "continuation.method: 'magic' is not allowed; allowed auto, exact, fd"
