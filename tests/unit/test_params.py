"""Scenario loading, units and validation (bad input is one clear InputError)."""

from __future__ import annotations

import math

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
        ({"carrier.mass": -1.2}, "allowed > 0 kg"),
        ({"carrier.mass": 0}, "allowed > 0 kg"),
        ({"contact.track.restitution": 1.5}, "allowed > 0 and <= 1"),
        ({"contact.track.restitution": 0.0}, "allowed > 0 and <= 1"),
        ({"track.clearance": float("nan")}, "not a finite number"),
        ({"track.clearance": "inf mm"}, "not a finite number"),
        ({"contact.track.model": "hunt_crosley"}, "did you mean 'hunt_crossley'"),
        ({"friction.law": "coulomb"}, "allowed one of"),
        ({"materials.track.radius": "10 mm"}, "materials.track.radius"),
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
