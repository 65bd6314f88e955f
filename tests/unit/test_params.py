"""Scenario loading, units and validation (bad input is one clear InputError)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import braidsim
from braidsim.errors import InputError
from braidsim.params import SCHEMA, load_scenario
from braidsim.units import to_si


@pytest.mark.parametrize(
    ("text", "unit", "expected"),
    [
        ("3 mm", "m", 3e-3),
        ("200 GPa", "Pa", 200e9),
        ("120 rpm", "rad/s", 4 * math.pi),
        ("60 Hz", "rad/s", 120 * math.pi),
        ("720 deg/s", "rad/s", 4 * math.pi),
        ("30 deg", "rad", math.pi / 6),
        ("2 mm/s", "m/s", 2e-3),
        (0.5, "m/s", 0.5),
    ],
)
def test_units_convert_to_si(text: object, unit: str, expected: float) -> None:
    assert to_si("k", text, unit) == pytest.approx(expected, rel=1e-12)


def test_every_builtin_scenario_loads() -> None:
    names = braidsim.builtin_names()
    for required in ("paper-3.1", "paper-3.2", "paper-3.3", "paper-3.4a", "paper-3.4b"):
        assert required in names
        assert f"{required}-printed" in names
    for name in names:
        sc = load_scenario(name)
        assert sc.name == name
        assert set(sc.values) == set(SCHEMA)


def test_paper_presets() -> None:
    sc = load_scenario("paper-3.4b")
    assert sc["horn_gear.angular_velocity"] == pytest.approx(8 * math.pi)
    assert sc["track.vibration_amplitude"] == pytest.approx(0.12e-3)
    assert sc["track.vibration_frequency"] == pytest.approx(120 * math.pi)
    assert load_scenario("paper-3.1-printed")["materials.track.youngs_modulus"] == pytest.approx(
        2e9
    )
    assert load_scenario("paper-3.1")["materials.track.youngs_modulus"] == pytest.approx(200e9)


def test_overrides_and_extends(tmp_path) -> None:
    f = tmp_path / "mine.toml"
    f.write_text('extends = "paper-3.3"\n[track]\nclearance = "2 mm"\n')
    sc = load_scenario(f, overrides={"carrier.mass": "1500 g"})
    assert sc["track.clearance"] == pytest.approx(2e-3)
    assert sc["carrier.mass"] == pytest.approx(1.5)
    assert sc["track.vibration_amplitude"] == pytest.approx(0.12e-3)
    assert sc.name == "mine"


@pytest.mark.parametrize(
    ("overrides", "fragment"),
    [
        ({"carrier.mas": 1.0}, "did you mean 'carrier.mass'"),
        ({"carrier.mass": "3 mm"}, "wrong unit"),
        ({"horn_gear.angular_velocity": "150 rmp"}, "unknown unit 'rmp'; did you mean 'rpm'?"),
        ({"track.clearance": "3 milimeter"}, "did you mean 'millimeter'?"),
        ({"track.clearance": "3 qqq"}, "unknown unit 'qqq'; allowed > 0 m"),
        ({"contact.track.restitution": "0.7 m"}, "expected a plain number (no unit)"),
        ({"carrier.mass": -1.2}, "allowed > 0 kg"),
        ({"carrier.mass": 0}, "allowed > 0 kg"),
        ({"contact.track.restitution": 1.5}, "allowed > 0 and <= 1"),
        ({"contact.track.restitution": 0.0}, "allowed > 0 and <= 1"),
        ({"track.clearance": float("nan")}, "not a finite number"),
        ({"track.clearance": "inf mm"}, "not a finite number"),
        ({"contact.track.model": "hunt_crosley"}, "did you mean 'hunt_crossley'"),
        ({"friction.law": "coulomb"}, "allowed one of"),
        ({"materials.track.radius": "10 mm"}, "materials.track.radius"),
        (
            {"contact.track.stiffness": "1e9 N/m"},
            "expected N/m^1.5 (n = 1.5, the track pair's exponent)",
        ),
        ({"contact.slot.stiffness": "-1e9 N/m^1.5"}, "allowed > 0"),
    ],
)
def test_bad_values_name_the_parameter(overrides: dict, fragment: str) -> None:
    with pytest.raises(InputError) as err:
        load_scenario("paper-3.1", overrides=overrides)
    msg = str(err.value)
    assert "\n" not in msg
    assert fragment in msg
    key = next(iter(overrides))
    assert key.split(".")[0] in msg


def test_a_stiffness_with_its_unit_takes_the_pairs_exponent(tmp_path) -> None:
    """K in N/m^n, n the pair's exponent: the law's (Hertz-type 1.5) or the key's; read from
    the API, a scenario file and its overrides alike."""
    base = "paper-3.1"
    sc = load_scenario(base, {"contact.track.stiffness": "1e3 N/mm^1.5"})
    assert sc["contact.track.stiffness"] == pytest.approx(1e3 * 1e3**1.5, rel=1e-12)
    sc = load_scenario(
        base, {"contact.slot.exponent": 1.2, "contact.slot.stiffness": "2e8 N/m^1.2"}
    )
    assert sc["contact.slot.stiffness"] == pytest.approx(2e8, rel=1e-12)
    f = tmp_path / "k.toml"
    f.write_text(f'extends = "{base}"\n[contact.track]\nstiffness = "5e9 N/m^1.5"\n')
    assert load_scenario(f)["contact.track.stiffness"] == pytest.approx(5e9, rel=1e-12)
    with pytest.raises(InputError, match=r"expected N/m\^1\.2"):
        load_scenario(
            base, {"contact.track.exponent": 1.2, "contact.track.stiffness": "1e9 N/m^1.5"}
        )


def test_malformed_toml(tmp_path) -> None:
    f = tmp_path / "bad.toml"
    f.write_text("[carrier\nmass = 1\n")
    with pytest.raises(InputError, match="malformed TOML"):
        load_scenario(f)


def test_unknown_scenario_names_closest() -> None:
    with pytest.raises(InputError, match=r"did you mean 'paper-3\.4[ab]'"):
        load_scenario("paper-3.4x")


def test_unknown_key_in_file(tmp_path) -> None:
    f = tmp_path / "typo.toml"
    f.write_text('[track]\nclearence = "3 mm"\n')
    with pytest.raises(InputError, match=r"did you mean 'track\.clearance'"):
        load_scenario(f)


def test_a_key_given_twice_in_a_file_is_refused(tmp_path) -> None:
    """A quoted dotted key and a table both gave track.clearance; the later one silently
    won (the run used 3 mm where the file also said 2 mm)."""
    f = tmp_path / "s.toml"
    f.write_text('extends = "paper-3.3"\n"track.clearance" = "2 mm"\n[track]\nclearance = "3 mm"\n')
    with pytest.raises(InputError, match=r"^track.clearance: given twice"):
        load_scenario(f)


def test_simulate_reads_a_duration_with_its_unit_and_refuses_a_foreign_start() -> None:
    """The API takes unit strings where the scenario does (``duration="0.1 s"``), and a
    wrong type for ``start`` is one InputError naming it."""
    from braidsim import simulate

    sc = load_scenario("paper-3.3")
    a = simulate(sc, "2 ms", series=False)
    b = simulate(sc, 2e-3, series=False)
    assert a.final["t"] == b.final["t"] == pytest.approx(2e-3)
    with pytest.raises(InputError, match=r"^duration: .*wrong unit"):
        simulate(sc, "2 mm", series=False)
    with pytest.raises(InputError, match=r"^start: expected the State"):
        simulate(sc, 1e-3, start="foo", series=False)  # type: ignore[arg-type]


def test_scenarios_and_results_pickle_and_cross_a_process_pool() -> None:
    """A scenario keeps its values behind a read-only view, which pickle cannot take: it
    pickles a copy, so scenarios, results and models go through pickle, deepcopy and a pool."""
    import copy
    import multiprocessing
    import pickle
    from concurrent.futures import ProcessPoolExecutor

    sc = load_scenario("paper-3.1", overrides={"track.clearance": "2 mm"})
    back = pickle.loads(pickle.dumps(sc))
    assert back == sc and back.explicit == sc.explicit
    with pytest.raises(TypeError):  # still read-only
        back.values["track.clearance"] = 1.0  # type: ignore[index]
    res = braidsim.simulate(sc, 0.01, series=False)
    again = pickle.loads(pickle.dumps(res))
    assert again.impacts.equals(res.impacts) and again.model.scenario == sc
    assert copy.deepcopy(res).final_state == res.final_state
    # spawn: a fresh interpreter that receives everything pickled (and no fork warning)
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        far = pool.submit(braidsim.simulate, sc, 0.01, series=False).result()
    assert far.impacts.equals(res.impacts)


def test_summary_is_strict_json_and_refuses_a_window_it_has_no_ranges_for() -> None:
    """The latched speed of a contact present at t = 0 is infinite: the summary gives None,
    as `run --json` does; a window not computed by simulate is an InputError naming those
    that were."""
    import json

    res = braidsim.simulate("paper-3.3", 0.02, windows=[(0.005, 0.01)])
    text = json.dumps(res.summary(), allow_nan=False)
    assert json.loads(text)["impacts"][0]["latched_velocity"] is None
    assert res.summary(window=(0.005, 0.01))["window"] == [0.005, 0.01]
    for bad in ((0.002, 0.004), (0.01, 0.005), "0.01"):
        with pytest.raises(InputError, match=r"^window: .* allowed one of \(0, 0.02\), "):
            res.summary(window=bad)  # type: ignore[arg-type]


def test_a_scenario_derives_its_records_once_and_each_model_its_own_span() -> None:
    """build_model keeps a scenario's records, pair models and initial state on the frozen
    scenario: a second model of it shares the records but has its own initial state, span,
    step budget and transfers; another scenario (an override) derives its own; the kept
    records do not enter the scenario's equality, pickling or repr."""
    import copy
    import pickle

    from braidsim.model import build_model

    sc = load_scenario("paper-3.3")
    a = build_model(sc, 0.5)
    b = build_model(sc, 2.0, t_start=0.1)
    assert b.record is a.record and b.track is a.track
    assert b.y0 is not a.y0 and list(b.y0) == list(a.y0)
    a.y0[0] = 123.0  # (a model's initial state is its own)
    assert build_model(sc, 0.5).y0[0] == sc["initial.x"]
    assert (a.duration, b.duration) == (0.5, 2.0)
    assert b.options.t_end == 2.0 and b.options.max_steps >= a.options.max_steps
    kept = build_model(sc, 0.5, keep_zero_harmonics=True)
    assert kept.record is not a.record  # (derived apart; with h_a != 0 the same values)
    assert np.array_equal(kept.record.track.table, a.record.track.table)
    other = sc.with_overrides({"track.vibration_amplitude": "0.1 mm"})
    c = build_model(other, 0.5)
    assert c.record is not a.record
    assert c.record.track.table[0, 0] == pytest.approx(1e-4)
    assert a.record.track.table[0, 0] == pytest.approx(1.2e-4)
    for back in (pickle.loads(pickle.dumps(sc)), copy.deepcopy(sc)):
        assert back == sc and "_derived" not in vars(back)
    assert "_derived" not in repr(sc)


def test_reprs_are_one_short_line() -> None:
    from braidsim.model import build_model
    from braidsim.sweep import load_spec

    sc = load_scenario("paper-3.3", overrides={"track.clearance": "2 mm"})
    spec = load_spec(Path(__file__).resolve().parents[2] / "examples" / "sweep_ha_omega.toml")
    for obj in (sc, build_model(sc), spec):
        text = repr(obj)
        assert text.startswith("<braidsim.") and "\n" not in text and len(text) < 300, text
    assert "63 parameters" in repr(sc) or "parameters in SI" in repr(sc)
    assert "(425 runs)" in repr(spec)


def test_a_scenario_answers_in_and_refuses_a_non_string_key() -> None:
    sc = load_scenario("paper-3.3")
    assert "track.clearance" in sc
    assert "track.clearence" not in sc
    assert 0 not in sc  # (it fell back to sc[0], and failed on int.isprintable)
    with pytest.raises(InputError, match="dotted name"):
        sc[0]  # type: ignore[index]


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"initial.x": "1 m"}, "initial.x: 1000 mm is out of range; allowed -2.88 to 6.12 mm"),
        ({"initial.x": "-2.9 mm"}, "initial.x: -2.9 mm is out of range"),
        # the wall's start moves with the phase: h(0) = -0.12 mm at a phase of pi
        ({"track.vibration_phase": math.pi, "initial.x": "6.1 mm"}, "allowed -3.12 to 5.88 mm"),
        ({"simulation.dof": "xy", "initial.y": "0.25 mm"}, "allowed -0.1 to 0.2 mm"),
        # an absurd amplitude moves the wall and the range with it: the message names it
        (
            {"track.vibration_amplitude": 1e300},
            "h(0) = 1e+303 mm, from track.vibration_amplitude (1e+303 mm) at its phase)",
        ),
    ],
)
def test_a_start_deeper_in_a_wall_than_its_clearance_is_refused(overrides, message) -> None:
    """A start may overlap a wall (paper-3.3 starts 0.12 mm into it) by at most the pair's
    clearance; "1 m" for "1 mm" ran with forces of 6e8 N instead of an error."""
    with pytest.raises(InputError, match=re.escape(message)):
        load_scenario("paper-3.3", overrides=overrides)


def test_a_start_within_a_clearance_of_the_walls_is_accepted() -> None:
    for x in ("-2.88 mm", "0 mm", "6.12 mm"):
        assert load_scenario("paper-3.3", overrides={"initial.x": x})["initial.x"] == to_si(
            "x", x, "m"
        )
    xy = load_scenario("paper-3.3", overrides={"simulation.dof": "xy", "initial.y": "-0.1 mm"})
    assert xy["initial.y"] == -1e-4
    # the x-only carrier has no y: its initial.y is not checked
    assert load_scenario("paper-3.3", overrides={"initial.y": "1 m"})["initial.y"] == 1.0


@pytest.mark.parametrize("value", [np.bool_(True), np.bool_(False), np.True_, np.False_])
def test_a_numpy_bool_is_a_boolean(value) -> None:
    """numpy 2 names its bool type ``bool``, not ``bool_``: a numpy boolean was refused
    ("np.False_ is not a boolean")."""
    sc = braidsim.load_scenario("paper-3.1", overrides={"contact.allow_tension": value})
    assert sc["contact.allow_tension"] is bool(value)


def test_none_for_a_boolean_says_true_or_false() -> None:
    with pytest.raises(
        InputError, match=r"^contact\.allow_tension: None is not a value; allowed true or false "
    ):
        braidsim.load_scenario("paper-3.1", overrides={"contact.allow_tension": None})
