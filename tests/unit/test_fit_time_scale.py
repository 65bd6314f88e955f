"""A record whose time column is in ms but read as s (``t [s]`` or a bare ``t``) is refused
before any simulation, in one line naming the column, the numbers and the fix; records
sampled finely enough (the shipped example, synthetic records, a long record) pass. The
command line's refusal of the shipped example read so is in tests/unit/test_fit.py."""

from __future__ import annotations

import importlib
import math
from pathlib import Path

import numpy as np
import pytest

import braidsim
from braidsim.errors import InputError
from braidsim.fit import fit, load_fit_spec, make_record, parse_fit_spec, read_record
from braidsim.fit.estimate import _check_time_scale, build_problem
from braidsim.fit.synthetic import synthetic_record
from braidsim.fit.timescale import longest_flight, pulse_duration

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
SC = "paper-3.1"
FREE2 = {"contact.track.restitution": [0.3, 0.9], "track.clearance": ["2.5 mm", "3.5 mm"]}
#: the module braidsim.simulate (the package's attribute of that name is the function)
SIMULATE = importlib.import_module("braidsim.simulate")


@pytest.fixture
def no_simulation(monkeypatch):
    """Make every simulation fail the test (the refusals come before any)."""

    def refuse(*args, **kwargs):
        raise AssertionError("a simulation ran before the record was refused")

    monkeypatch.setattr(SIMULATE, "simulate", refuse)


def test_a_displacement_record_in_ms_read_as_s_is_refused_by_the_longest_flight(no_simulation):
    t = np.arange(1, 1001) * 0.1  # 0.1 ms steps written as s
    x = 1.5 * (1 - np.cos(t))  # [mm]: any motion, it is not looked at
    with pytest.raises(InputError, match=r"column t \[s\] has a sample interval of 0\.1 s") as e:
        fit(SC, {"t [s]": t, "x [mm]": x}, FREE2, quantity="x")
    assert "longest flight of the carrier between the track walls" in str(e.value)
    assert "head the column t [ms]" in str(e.value)


def test_an_impact_list_in_ms_read_as_s_is_refused_after_the_start_run(monkeypatch):
    # an impact list has no sample interval and may skip impacts: no closed form bounds its
    # times; the run at the start values shows the carrier resting long before the list
    runs = []
    simulate = SIMULATE.simulate

    def counted(*args, **kwargs):
        runs.append(kwargs.get("duration"))
        return simulate(*args, **kwargs)

    monkeypatch.setattr(SIMULATE, "simulate", counted)
    table = {"t": [6.64, 15.85, 54.37], "peak_force [kN]": [5.56, 5.47, 3.28]}
    with pytest.raises(InputError, match=r"starts at t = 6\.64 s, after the last track impact"):
        fit(SC, table, FREE2)
    assert len(runs) == 1


def test_records_sampled_finely_enough_pass():
    """The shipped example and synthetic records of every quantity (at 10 kHz, and a laser
    at 1 kHz) pass, and so does a long record sampled finely: the bound is on the sample
    interval, not the duration."""
    spec = load_fit_spec(EXAMPLES / "fit_spec.toml")
    example = read_record(EXAMPLES / "fit_record.csv")
    _check_time_scale(build_problem(spec, example), spec.laws)
    for quantities, rate in ((("acceleration",), 1e4), (("contact_force",), 1e4), (("x",), 1e3)):
        rec = synthetic_record(SC, 0.05, rate=rate, quantities=quantities, noise=None)
        spec_q = parse_fit_spec({"scenario": SC, "fit": {"free": FREE2, "quantity": quantities[0]}})
        _check_time_scale(build_problem(spec_q, rec))
    # 200 s at 10 kHz: the example's 0.1 s repeated
    n = 2000
    long = make_record(
        np.arange(1, n * example.t.size + 1) * 1e-4,
        {"acceleration": np.tile(example.columns["acceleration"], n)},
    )
    _check_time_scale(build_problem(spec, long))


def test_the_closed_forms_against_the_simulator():
    from braidsim.impact import single_impact
    from braidsim.model import pair_model

    # the elastic contact duration at a given peak force, against a run of hertz
    sc = braidsim.load_scenario(SC)
    hertz = sc.with_overrides({"contact.track.model": "hertz"})
    one = single_impact("hertz", 1.0, 0.3, stiffness=pair_model(sc, "track").stiffness)
    got = pulse_duration(hertz, one["max_force"])
    assert got == pytest.approx(one["contact_duration"], rel=1e-6)
    assert pulse_duration(sc, 0.0) == math.inf
    # far beyond the physical, the bound stays a number (the direct form's p_m^(n+1)
    # raised OverflowError at 1e200 N)
    assert 0.0 <= pulse_duration(sc, 1e300) < pulse_duration(sc, 1e3)
    assert pulse_duration(sc, 1e-300) > pulse_duration(sc, 1.0)
    # every flight of the paper-3.1 carrier between two impacts is shorter than the bound
    res = braidsim.simulate(sc, duration=0.3, record_events=False)
    imp = res.impacts
    tr = imp[(imp["pair"] == "track") & ~imp["initial"]]
    flights = tr["t"].to_numpy()[1:] - tr["t_end"].to_numpy()[:-1]
    bound = longest_flight(sc)
    assert 0 < flights.max() < bound < 3 * flights.max()
    # no bound where the friction can hold the carrier between the walls
    assert longest_flight(sc.with_overrides({"friction.carrier_horn_gear": 10.0})) == math.inf
