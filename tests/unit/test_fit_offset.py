"""The record's time offset (free key ``record.time_offset``): a record whose t = 0 is not
the model's, made by the simulator with a known offset and parameters. Its estimate and the
other parameters' truth within their intervals, for a sampled record and an impact list;
the exact Jacobian's offset column against central differences; its profile; the fitted
scenario that runs; and the refusals."""

from __future__ import annotations

import importlib
import json
import tomllib

import numpy as np
import pytest

import braidsim
from braidsim.errors import InputError
from braidsim.fit import fit, parse_fit_spec
from braidsim.fit.problem import Problem
from braidsim.fit.synthetic import synthetic_record

from .test_fit import _cli, _write_record
from .test_fit_impacts import FREE2, TRUTH, impact_table, noise_of

SC = "paper-3.1"
OFFSET = 43e-6  # s: 0.43 of the 10-kHz sample interval
FREE3 = {**FREE2, "record.time_offset": ["0 us", "100 us"]}


@pytest.fixture(scope="module")
def late_record():
    """0.15 s of the paper-3.1 carrier's acceleration at 10 kHz, noise 20 m/s^2, its sensor
    triggered 43 us after the model's t = 0."""
    return synthetic_record(SC, 0.15, noise={"acceleration": 20.0}, seed=11, time_offset=OFFSET)


def test_a_late_record_gives_the_offset_and_the_truth_within_the_intervals(late_record):
    res = fit(SC, late_record, FREE3, quantity="acceleration", starts=3)
    assert res.converged
    truth = {**TRUTH, "record.time_offset": OFFSET}
    for i, k in enumerate(res.keys):
        lo, hi = res.stats.ci95[i]
        assert lo <= truth[k] <= hi, (k, lo, truth[k], hi)
    i = res.keys.index("record.time_offset")
    assert res.stats.stderr[i] < 3e-6  # s, against the 100-us sample interval
    assert res.stats.residual_std == pytest.approx(1.0, abs=0.1)
    assert not res.warnings
    # the same record with the offset not free: residuals 1.5 times the noise, said so, and
    # a clearance interval off the truth (what the offset is for)
    res0 = fit(SC, late_record, FREE2, quantity="acceleration", starts=3)
    assert res0.stats.residual_std > 1.4
    assert any("record.time_offset" in w for w in res0.warnings)
    lo, hi = res0.stats.ci95[res0.keys.index("track.clearance")]
    assert not lo <= TRUTH["track.clearance"] <= hi


@pytest.mark.parametrize("quantities", [("acceleration",), ("x", "acceleration")])
def test_the_offset_column_of_the_exact_jacobian_matches_central_differences(
    late_record, quantities
):
    rec = late_record
    if "x" in quantities:
        rec = synthetic_record(SC, 0.05, quantities=quantities, time_offset=OFFSET)
    sc = braidsim.load_scenario(SC)
    spec = parse_fit_spec({"fit": {"free": FREE3, "quantity": list(quantities)}}, scenario=sc)
    pr = Problem(sc, rec, spec.free, spec.quantities, jacobian="exact")
    u = pr.u_start + 0.01
    Je = pr.residuals(u, jac=True).J
    Jf = pr.jacobian_fd(u)
    assert Je is not None
    # (the x rows' offset column is the sampled speed, exact; the acceleration's is itself
    # central differences; next to a contact exit a_x has a kink: see test_fit)
    assert np.all(np.linalg.norm(Je - Jf, axis=0) < 1e-2 * np.linalg.norm(Jf, axis=0))
    if "x" in quantities:
        n = rec.t.size
        j = pr.keys.index("record.time_offset")
        assert np.allclose(Je[:n, j], Jf[:n, j], rtol=1e-4, atol=1e-4 * np.abs(Jf[:n, j]).max())
    Ee = pr.event_residuals(u, jac=True).J
    Ef = pr.jacobian_fd(u, "events")
    assert Ee is not None
    assert np.allclose(Ee, Ef, rtol=1e-3, atol=1e-3 * np.abs(Ef).max())
    # with the offset the only free key: no sensitivities asked of the simulator
    only = parse_fit_spec(
        {"fit": {"free": {"record.time_offset": ["0 us", "100 us"]}, "quantity": "acceleration"}},
        scenario=sc,
    )
    p1 = Problem(sc, late_record, only.free, only.quantities, jacobian="exact")
    u1 = p1.u_start + 0.01
    J1 = p1.residuals(u1, jac=True).J
    assert J1 is not None
    assert np.allclose(J1, p1.jacobian_fd(u1), rtol=1e-8, atol=1e-8 * np.abs(J1).max())


def test_the_offset_profile_agrees_with_its_interval(late_record):
    res = fit(
        SC,
        late_record,
        FREE3,
        quantity="acceleration",
        starts=2,
        profile=["record.time_offset"],
        profile_points=7,
    )
    (prof,) = res.profiles
    lo, hi = prof.ci95
    i = res.keys.index("record.time_offset")
    clo, chi = res.stats.ci95[i]
    assert lo == pytest.approx(clo, abs=0.2 * (chi - clo))
    assert hi == pytest.approx(chi, abs=0.2 * (chi - clo))
    assert prof.delta.min() > -1e-3


def test_an_impact_list_two_ms_late():
    tab = impact_table(n=6, seed=3)
    tab["t [ms]"] = tab["t [ms]"] - 2.0
    free = {**FREE2, "record.time_offset": ["0 ms", "5 ms"]}
    res = fit(SC, tab, free, noise=noise_of(tab), starts=3)
    assert res.converged
    truth = {**TRUTH, "record.time_offset": 2e-3}
    for i, k in enumerate(res.keys):
        lo, hi = res.stats.ci95[i]
        assert lo <= truth[k] <= hi, (k, lo, truth[k], hi)
    # the list's onsets against the model's, in the list's time
    t_model = res.parts[0]["model"]["t"]
    assert np.all(np.abs(t_model - res.parts[0]["data"]["t"]) < 5e-4)


def test_cli_fits_the_offset_and_writes_a_scenario_that_runs(tmp_path, capsys, late_record):
    spec = tmp_path / "spec.toml"
    spec.write_text(
        'scenario = "paper-3.1"\n[fit]\nfree = { "contact.track.restitution" = [0.3, 0.9], '
        '"track.clearance" = ["2.5 mm", "3.5 mm"], "record.time_offset" = ["0 us", "100 us"] }\n'
        'quantity = "acceleration"\nstarts = 2\n'
    )
    data = _write_record(tmp_path / "rec.csv", late_record)
    out = tmp_path / "out"
    code, stdout, err = _cli(
        ["fit", str(spec), "--data", str(data), "--out", str(out), "--json"], capsys
    )
    assert code == 0, err
    est = json.loads(stdout)["estimates"]["record.time_offset"]
    assert est["ci95"][0] <= OFFSET <= est["ci95"][1]
    text = (out / "fitted_scenario.toml").read_text()
    assert "# record.time_offset = " in text
    assert "time_offset" not in "".join(ln for ln in text.splitlines() if not ln.startswith("#"))
    tomllib.loads(text)
    code, stdout, err = _cli(["run", str(out / "fitted_scenario.toml"), "--json"], capsys)
    assert code == 0, err


OFF_KEY = "record.time_offset"


def _two_late_records() -> list:
    """Two records of paper-3.1 triggered 27 and 71 us late, the second launched at 0.3 m/s
    (with that override)."""
    r1 = synthetic_record(SC, 0.15, noise={"acceleration": 20.0}, seed=31, time_offset=27e-6)
    r2 = synthetic_record(
        SC,
        0.15,
        noise={"acceleration": 20.0},
        seed=32,
        time_offset=71e-6,
        overrides={"initial.vx": 0.3},
    )
    return [r1, (r2, {"initial.vx": 0.3})]


def test_two_records_have_an_offset_each():
    """Two records triggered apart (27 and 71 us late; the second launched at 0.3 m/s),
    fitted together: one offset each (record[0].time_offset, record[1].time_offset), both
    and the shared parameters' truth within the intervals; each record's residuals depend
    on its own offset only (the other's Jacobian column is exactly 0, exact and central
    differences alike, and the differences do not run for it)."""
    from braidsim.fit.estimate import build_problem

    data = _two_late_records()
    r1 = data[0]
    res = fit(SC, data, FREE3, quantity="acceleration", starts=3)
    assert res.keys[2:] == ("record[0].time_offset", "record[1].time_offset")
    truth = {**TRUTH, "record[0].time_offset": 27e-6, "record[1].time_offset": 71e-6}
    for i, k in enumerate(res.keys):
        lo, hi = res.stats.ci95[i]
        assert lo <= truth[k] <= hi, (k, lo, truth[k], hi)
    assert res.stats.residual_std == pytest.approx(1.0, abs=0.1)
    sc = braidsim.load_scenario(SC)
    spec = parse_fit_spec({"fit": {"free": FREE3, "quantity": "acceleration"}}, scenario=sc)
    pr = build_problem(spec, data)
    u = pr.u_start + 0.01
    Je = pr.residuals(u, jac=True).J
    before = pr.evaluations
    Jf = pr.jacobian_fd(u)
    assert Je is not None
    # per record: 1 base run, 2 x (2 scenario keys + its own offset) perturbed runs
    assert pr.evaluations - before == 2 * (1 + 2 * 3)
    n = r1.t.size
    for J in (Je, Jf):
        assert np.all(J[:n, 3] == 0) and np.all(J[n:, 2] == 0)
    assert np.all(np.linalg.norm(Je - Jf, axis=0) < 1e-2 * np.linalg.norm(Jf, axis=0))


def test_one_records_offset_of_several_has_a_profile():
    """``profile = ["record[1].time_offset"]``: that record's offset fixed on the grid, the
    other record's offset and the shared keys refitted; its interval holds the truth (71
    us) and agrees with the linearised one where the fit is near linear. A profile of the
    offsets as one key, of a record that is not there, or by a record's name with one
    record, is refused in one line."""
    data = _two_late_records()
    r1 = data[0]
    key = "record[1].time_offset"
    res = fit(SC, data, FREE3, quantity="acceleration", starts=3, profile=[key], profile_points=7)
    (prof,) = res.profiles
    assert prof.key == key
    lo, hi = prof.ci95
    assert lo is not None and hi is not None and lo <= 71e-6 <= hi, (lo, hi)
    i = res.keys.index(key)
    llo, lhi = res.stats.ci95[i]
    assert abs(lo - llo) < 0.3 * (lhi - llo) and abs(hi - lhi) < 0.3 * (lhi - llo)
    assert np.min(prof.delta) == pytest.approx(0.0, abs=0.1)  # (the optimum on the grid)
    with pytest.raises(InputError, match=r"allowed record\[0\].time_offset to record\[1\]"):
        fit(SC, data, FREE3, quantity="acceleration", profile=["record[2].time_offset"])
    with pytest.raises(InputError, match=r"not a free parameter with 1 record; allowed record"):
        fit(SC, r1, FREE3, quantity="acceleration", profile=["record[0].time_offset"])
    with pytest.raises(InputError, match=r"'record\[0\].time_offset' is not a free parameter"):
        fit(SC, data, FREE2, quantity="acceleration", profile=["record[0].time_offset"])


def test_bad_offsets_are_refused_in_one_line(late_record):
    sc = braidsim.load_scenario(SC)
    # a lower bound that puts the first sample (t = 0.1 ms) before the model's t = 0
    spec = parse_fit_spec(
        {"fit": {"free": {**FREE2, "record.time_offset": ["-1 ms", "1 ms"]}}}, scenario=sc
    )
    with pytest.raises(InputError, match=r"record.time_offset: .* allowed >= -0.0001 s"):
        Problem(sc, late_record, spec.free, ("acceleration",))
    # two records' offsets are two parameters: no one profile of them
    with pytest.raises(InputError, match=r"fit.profile: record.time_offset stands for 2 offsets"):
        fit(SC, [late_record, late_record], FREE3, quantity="acceleration", profile=[OFF_KEY])
    with pytest.raises(InputError, match=r"fit.free.record.time_offset: .* not an interval"):
        parse_fit_spec({"fit": {"free": {"record.time_offset": ["1 ms", "0 ms"]}}}, scenario=sc)
    with pytest.raises(InputError, match=r"time_offset: -1e-05 s is out of range"):
        synthetic_record(SC, 0.01, time_offset="-10 us")


@pytest.mark.parametrize("high", ["1e6 s", "1e9 s"])
def test_an_offset_beyond_the_step_limit_is_refused_before_any_simulation(
    late_record, monkeypatch, high
):
    # (1e6 s ran for many minutes, each run half an hour; 1e9 s was refused by the first
    # long run, naming only its duration)
    def refuse(*args, **kwargs):
        raise AssertionError("a simulation ran before the offset was refused")

    monkeypatch.setattr(importlib.import_module("braidsim.simulate"), "simulate", refuse)
    free = {**FREE2, OFF_KEY: ["0 s", high]}
    with pytest.raises(InputError, match=r"^fit.free.record.time_offset: an upper bound of") as e:
        fit(SC, late_record, free, quantity="acceleration", starts=1)
    assert "(allowed upper bounds up to 999999." in str(e.value)
    assert "BRAIDSIM_MAX_STEPS" in str(e.value)
    table = {"t [ms]": [6.64, 15.86], "peak_force [kN]": [5.49, 5.55]}
    with pytest.raises(InputError, match=r"allowed upper bounds up to 833333"):
        fit(SC, table, free, starts=1)


def test_a_misspelt_offset_key_is_named():
    sc = braidsim.load_scenario(SC)
    with pytest.raises(InputError, match=r"unknown scenario key 'record.time_ofset'.*time_offset"):
        parse_fit_spec({"fit": {"free": {"record.time_ofset": [0, 1e-4]}}}, scenario=sc)


def test_the_offset_profile_of_one_record_with_overrides(late_record):
    """One record given with scenario overrides is fitted through the several-records path
    with its one offset: its profile fixes that offset (the fixed value reached the record)."""
    res = fit(
        SC,
        [(late_record, {"initial.vy": 0.0})],
        FREE3,
        quantity="acceleration",
        starts=2,
        profile=[OFF_KEY],
        profile_points=5,
    )
    (prof,) = res.profiles
    i = res.keys.index(OFF_KEY)
    clo, chi = res.stats.ci95[i]
    lo, hi = prof.ci95
    assert lo == pytest.approx(clo, abs=0.2 * (chi - clo))
    assert hi == pytest.approx(chi, abs=0.2 * (chi - clo))
