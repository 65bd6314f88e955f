"""The unit policy of the command line (a bare number is SI, with a one-line notice on
stderr; unit strings accepted by every dimensional option) and the help texts, whose
bracketed units must survive rich markup."""

from __future__ import annotations

import json
import re

import pytest

from braidsim.cli.common import quantity_option
from braidsim.errors import InputError
from braidsim.params import SCHEMA
from fuzz.harness import run_cli


def test_bare_set_value_is_si_with_a_notice_and_json_stays_clean():
    code, out, err = run_cli(
        ["run", "paper-3.1", "--set", "track.clearance=0.004", "--duration", "0.01 s", "--json"]
    )
    assert code == 0, err
    data = json.loads(out)  # stdout is one JSON object, nothing else
    assert data["parameters"]["track.clearance"] == 0.004
    notes = err.strip().splitlines()
    assert notes == [
        "braidsim: note: --set track.clearance=0.004: a bare number is taken in SI (m); "
        "write the unit, e.g. '0.004 m'"
    ]


def test_unit_strings_give_no_notice():
    code, out, err = run_cli(
        ["run", "paper-3.1", "--set", "track.clearance=4 mm", "--duration", "10 ms", "--json"]
    )
    assert code == 0, err
    assert err == ""
    assert json.loads(out)["parameters"]["track.clearance"] == pytest.approx(0.004)


def test_bare_option_notice_names_the_unit_assumed():
    code, out, err = run_cli(["run", "paper-3.1", "--duration", "0.01", "--json"])
    assert code == 0
    assert "--duration 0.01 taken as 0.01 s (SI)" in err
    json.loads(out)


def test_impact_stiffness_accepts_its_unit_and_matches_the_bare_si_value():
    code, out, err = run_cli(["impact", "--stiffness", "1e9 N/m^1.5", "--json"])
    assert code == 0 and err == ""
    code2, out2, err2 = run_cli(["impact", "--stiffness", "1e9", "--json"])
    assert code2 == 0 and "N/m**1.5" in err2
    assert json.loads(out)["max_force"] == json.loads(out2)["max_force"]
    # the exponent decides the unit: K in N/m^1.08 for an exponent of 1.08
    code3, _, err3 = run_cli(
        ["impact", "--stiffness", "1e9 N/m^1.5", "--exponent", "1.08", "--json"]
    )
    assert code3 == 2 and "--stiffness" in err3


def test_restitution_velocity_and_mass_take_units():
    code, out, err = run_cli(
        [
            "restitution",
            "--law",
            "hunt_crossley",
            "--points",
            "1",
            "--c-min",
            "0.8",
            "--velocity",
            "500 mm/s",
            "--mass",
            "1200 g",
            "--json",
        ]
    )
    assert code == 0, err
    assert err == ""
    json.loads(out)


@pytest.mark.parametrize(
    ("option", "value", "unit", "si", "noted"),
    [
        ("--d0", "1 nm", "m", 1e-9, False),
        ("--d0", "1", "m", 1.0, True),
        ("--d0", 1e-9, "m", 1e-9, True),
        ("--interval", "2 ms", "s", 2e-3, False),
        ("--from", "0.1 mm", "m", 1e-4, False),
        ("--duration", "0", "s", 0.0, False),  # 0 needs no unit
        ("--velocity", "1 km/h", "m/s", 1 / 3.6, False),
    ],
)
def test_quantity_option(option, value, unit, si, noted):
    from braidsim.cli import common

    common._NOTICES.clear()
    assert quantity_option(option, value, unit) == pytest.approx(si)
    assert bool(common._NOTICES) == noted
    if noted:
        assert f"{option} {value} taken as" in common._NOTICES[0]
    common._NOTICES.clear()


def test_bifurcation_bounds_use_the_parameters_unit():
    from braidsim.cli.analysis import _axis_value

    assert _axis_value("--from", "track.vibration_amplitude", "0.05 mm") == pytest.approx(5e-5)
    assert _axis_value("--from", "horn_gear.angular_velocity", "120 rpm") == pytest.approx(
        4 * 3.141592653589793
    )
    with pytest.raises(InputError, match="--from"):
        _axis_value("--from", "track.clearance", "1 kg")


def test_lyapunov_d0_bare_one_metre_is_refused_with_the_unit():
    code, out, err = run_cli(["lyapunov", "paper-3.3", "--d0", "1"])
    assert code == 2 and out == ""
    assert err.strip() == (
        "braidsim: error: --d0: 1 m is out of range; allowed 0 < d0 <= 1 mm "
        "(a small separation, e.g. '1 nm')"
    )


# -------------------------------------------------------------------- help texts


def _verbs() -> list[str]:
    from braidsim.cli import _register
    from braidsim.cli.common import app

    _register()
    return [c.name or c.callback.__name__ for c in app.registered_commands]  # type: ignore[union-attr]


@pytest.mark.parametrize("verb", _verbs())
def test_help_keeps_bracketed_units(verb, monkeypatch):
    """Every bracketed text of an option's help (a unit such as [m/s]) is printed."""
    import typer.main

    from braidsim.cli.common import app

    monkeypatch.setenv("COLUMNS", "250")
    cmd = typer.main.get_command(app).commands[verb]  # type: ignore[attr-defined]
    wanted = [
        b for p in cmd.params for b in re.findall(r"\[[^\]]*\]", getattr(p, "help", "") or "")
    ]
    code, out, err = run_cli([verb, "--help"])
    assert code == 0, err
    flat = " ".join(out.split())
    for b in wanted:
        assert b in flat, f"{verb} --help lost {b}"


def test_help_shows_units_of_the_documented_options(monkeypatch):
    monkeypatch.setenv("COLUMNS", "250")
    for verb, unit in (("run", "[s]"), ("impact", "[m/s]"), ("lyapunov", "[m]")):
        _, out, _ = run_cli([verb, "--help"])
        assert unit in out


def test_scenarios_keys_keep_bracketed_text(monkeypatch):
    monkeypatch.setenv("COLUMNS", "400")
    code, out, err = run_cli(["scenarios", "--keys"])
    assert code == 0, err
    flat = " ".join(out.split())
    with_brackets = [s for s in SCHEMA.values() if "[" in s.doc]
    assert len(with_brackets) > 30
    for s in with_brackets:
        for b in re.findall(r"\[[^\]]*\]", s.doc):
            assert b in flat, f"{s.key}: {b} lost"
    assert "[[amplitude, angular frequency, phase], ...]" in flat
