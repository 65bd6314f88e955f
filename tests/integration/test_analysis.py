"""Impact and nonlinear-dynamics analysis of the carrier against independent answers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import braidsim
from braidsim import contact
from braidsim.analysis import (
    analyze,
    basins,
    carrier_lyapunov,
    contact_loss_bound,
    energy_balance,
    impact_statistics,
    locate_transition,
    restitution_table,
    run_spectra,
    steady_state,
)
from braidsim.batch import simulate_batch
from braidsim.cli import main


def test_restitution_of_every_law_matches_exact_relation() -> None:
    """Simulated impacts restitute e(D(c_r)) of the family's exact relation within 1e-4."""
    c = np.array([0.02, 0.1, 0.3, 5 / 9, 0.8, 1.0])
    table = restitution_table(nominal=c)
    assert set(table.laws) == set(contact.law_names())
    assert table.max_deviation <= 1e-4
    # the exact relation itself: 1 - D e = (1 + D) exp(-D (1 + e))
    D, e = table.damping, table.exact
    np.testing.assert_allclose(1 - D * e, (1 + D) * np.exp(-D * (1 + e)), atol=1e-12)
    i = table.laws.index("carvalho_martins")
    np.testing.assert_allclose(table.simulated[i], c, atol=1e-4)  # built to restitute c_r
    i = table.laws.index("hertz")
    np.testing.assert_allclose(table.simulated[i], 1.0, atol=1e-6)  # elastic


@pytest.mark.parametrize(
    ("name", "overrides"),
    [
        ("paper-3.3", {}),
        ("paper-3.2", {}),
        ("paper-3.1", {"simulation.dof": "xy", "initial.vy": 0.0}),
    ],
)
def test_energy_balance_closes(name: str, overrides: dict) -> None:
    res = braidsim.simulate(name, duration=0.2, overrides=overrides, sample_interval=1e-4)
    eb = energy_balance(res)
    assert eb.closure <= 1e-6
    assert eb.exchanged > 0.0
    tot = eb.totals()
    assert tot["contact_dissipated"] > 0 and tot["friction_dissipated"] > 0
    # the per-impact dissipation of the episodes adds up to the quadrature
    q = res.impacts["dissipated_energy"].sum()
    assert q == pytest.approx(
        res.series["track_dissipated"][-1] + res.series["slot_dissipated"][-1], rel=1e-9
    )
    if overrides:
        assert abs(tot["slot_work"]) > 0  # the horn-gear slot pushes the carrier


def test_impact_statistics_of_a_run() -> None:
    res = braidsim.simulate("paper-3.2", duration=0.25, sample_interval=0)
    st = impact_statistics(res)
    d = st.to_dict()
    assert d["count"] == len(st.impacts) == sum(st.counts.values()) > 3
    assert int(st.speed_counts.sum()) == d["count"]  # all are track impacts here
    # 3.2 starts on the outer wall moving into it at 2 mm/s (an impact at 2 mm/s), then
    # crosses the 3 mm gap under the load less the saturated friction: the inner-wall impact
    # at v^2 = v0^2 + 2 (a_p - mu1 |m g - T2| / m) eps_g is the fastest
    sc = res.model.scenario
    b = contact_loss_bound(sc)
    v = math.sqrt(0.002**2 + 2 * b["pressing_acceleration_with_friction"] * 3e-3)
    assert st.impacts["velocity"].iloc[0] == pytest.approx(0.002)
    assert d["approach_speed"]["max"] == pytest.approx(v, rel=1e-3)
    assert st.impacts["velocity"].iloc[1] == d["approach_speed"]["max"]
    frac = st.contact_fraction["track"]
    assert 0.5 < frac <= 1.0  # comes to rest on the inner wall early in the run
    assert st.impacts["t"].is_monotonic_increasing


def test_regimes_of_the_paper_runs() -> None:
    rest = steady_state("paper-3.4b")
    assert rest.regime.label == "resting_contact"
    assert rest.contact_fraction == pytest.approx(1.0)
    imp = steady_state("paper-3.3")
    assert imp.regime.label == "periodic_one_sided"
    assert imp.regime.period == 6 and imp.regime.walls == "inner"
    assert imp.inner_impacts >= 50
    two = steady_state("paper-3.4a")
    assert (two.regime.label, two.regime.period) == ("periodic_two_sided", 1)


def test_contact_loss_bound_numbers() -> None:
    """docs/model.md §7: a_p = 13.9 and 44.7 m/s^2 against h_a omega_h^2 = 17.1 m/s^2."""
    b3 = contact_loss_bound("paper-3.3")
    b4 = contact_loss_bound("paper-3.4b")
    assert b3["pressing_acceleration"] == pytest.approx(13.87, abs=0.01)
    assert b4["pressing_acceleration"] == pytest.approx(44.67, abs=0.01)
    assert b3["wall_acceleration"] == pytest.approx(1.2e-4 * (2 * math.pi * 60) ** 2, rel=1e-12)
    assert b3["wall_acceleration"] == pytest.approx(17.05, abs=0.01)
    assert not b3["stays_on_wall"] and b4["stays_on_wall"]
    assert b3["critical_amplitude"] == pytest.approx(13.8728 / (2 * math.pi * 60) ** 2, rel=1e-4)


@pytest.mark.parametrize("friction", ["none", "arctan"])
def test_carrier_leaves_the_wall_at_the_bound(friction: str) -> None:
    """Bisection on h_a for the change resting contact -> impacts of the simulated carrier
    lands within 2 % of the analytic bound (frictionless: docs/model.md §7; with
    friction: the bound with the saturated friction force).

    The carrier starts at rest on the wall at mid-stroke (phase pi/2: h(0) = 0, x0 = 0), the
    situation the bound describes; from the paper's start (released from a 0.12 mm overlap)
    it can also end in a coexisting impacting orbit below the bound."""
    sc = braidsim.load_scenario(
        "paper-3.3",
        overrides={
            "friction.law": friction,
            "track.vibration_phase": math.pi / 2,
            "initial.vx": 0.0,
        },
    )
    b = contact_loss_bound(sc)
    expect = b["critical_amplitude_with_friction"]
    if friction == "none":
        assert expect == b["critical_amplitude"]
    lo, hi = locate_transition(
        sc,
        "track.vibration_amplitude",
        0.8 * expect,
        1.2 * expect,
        0.2e-6,
        transient_cycles=60,
        cycles=20,
    )
    assert hi - lo <= 0.2e-6
    assert steady_state(sc, {"track.vibration_amplitude": lo}).regime.label == "resting_contact"
    assert 0.5 * (lo + hi) == pytest.approx(expect, rel=0.02)


def test_lyapunov_exponent_of_resting_contact() -> None:
    """On the wall (paper-3.4b) perturbations decay with the damping of the linearised
    contact: c = D <F_k> / v0 with <F_k> = m a_p, plus the friction slope averaged over
    the wall's motion, lambda = -(c + <df/dv>) / (2 m)."""
    res = carrier_lyapunov("paper-3.4b", transient_cycles=30, cycles=20)
    assert res.start.track_mode == -1
    sc = braidsim.load_scenario("paper-3.4b")
    m = sc["carrier.mass"]
    D = contact.get_law("hunt_crossley").damping_factor(sc["contact.track.restitution"])
    a_p = contact_loss_bound(sc)["pressing_acceleration"]
    c = D * m * a_p / res.start.track_v0
    # arctan friction: f = mu N (2/pi) atan(v / v_hat); with v = V sin(theta) following the
    # wall, <df/dv> = mu N (2/pi) / v_hat / sqrt(1 + (V / v_hat)^2)
    mu_n = sc["friction.carrier_horn_gear"] * abs(m * sc["gravity"] - sc["yarn.tension_vertical"])
    V = sc["track.vibration_amplitude"] * sc["track.vibration_frequency"]
    v_hat = sc["friction.regularization_velocity"]
    fric = mu_n * 2 / math.pi / v_hat / math.sqrt(1 + (V / v_hat) ** 2)
    expected = -(c + fric) / (2 * m)
    assert res.exponent < 0
    assert res.exponent == pytest.approx(expected, rel=0.03)


def test_cli_lyapunov_prints_the_standard_error(capsys) -> None:
    """The text and the JSON give the exponent's standard error by batch means
    (estimate.standard_error()), as docs/analysis.md quotes it (only the range of the
    running estimate was printed, so a quoted "+-" needed Python)."""
    argv = ("lyapunov", "paper-3.4b", "--transient-cycles", "20", "--cycles", "10")
    est = carrier_lyapunov("paper-3.4b", transient_cycles=20, cycles=10).estimate
    se = est.standard_error()
    assert math.isfinite(se) and se > 0
    code, js, err = run_cli(capsys, *argv, "--json")
    assert code == 0, err
    d = json.loads(js)
    assert d["exponent"] == est.exponent and d["standard_error"] == se
    code, out, err = run_cli(capsys, *argv)
    text = " ".join(out.split())
    assert f"largest Lyapunov exponent {est.exponent:.5g} +- {se:.2g} 1/s" in text, text
    assert "standard error by batch means of 10 blocks" in text
    # fewer intervals (8) than blocks: no standard error (null), and no "+-" printed
    short = ("lyapunov", "paper-3.4b", "--transient-cycles", "20", "--cycles", "0.5")
    code, js, err = run_cli(capsys, *short, "--json")
    assert code == 0, err
    assert json.loads(js)["standard_error"] is None
    code, out, err = run_cli(capsys, *short)
    text = " ".join(out.split())
    assert "+-" not in text and "(no standard error: fewer than 10 intervals; 8 intervals" in text


@pytest.mark.slow
def test_lyapunov_exponent_of_irregular_motion_is_positive_and_robust() -> None:
    """h_a = 0.18 mm (irregular impacts): positive exponent, the same with renormalisation
    every T_h/16 or every T_h and with d0 = 1e-8 m or 1e-10 m (a method artefact would not
    be). Over 1,000 periods the estimate's own statistical error is 1.4-1.8 1/s (3 %), and
    runs that differ in the last bits of their arithmetic gave 52-58 1/s; over 4,000 periods
    it is 0.8-0.9 1/s and the three estimates lie within 3 % (54.5, 53.4, 53.1)."""
    over = {"track.vibration_amplitude": "0.18 mm"}
    T = 1 / 60
    a = carrier_lyapunov("paper-3.3", over, cycles=4000, interval=T / 16).estimate
    b = carrier_lyapunov("paper-3.3", over, cycles=4000, interval=T).estimate
    c = carrier_lyapunov("paper-3.3", over, cycles=4000, interval=T, d0=1e-10).estimate
    for e in (a, b, c):
        assert e.exponent - 5 * e.standard_error() > 20
    assert a.exponent == pytest.approx(b.exponent, rel=0.1)
    assert c.exponent == pytest.approx(b.exponent, rel=0.1)
    # the differences are within the estimates' statistical errors
    assert abs(a.exponent - b.exponent) < 4 * math.hypot(a.standard_error(), b.standard_error())


def test_basins_at_the_paper_3_3_conditions() -> None:
    """docs/model.md §8: the 3.3 parameters have several steady states."""
    bm = basins("paper-3.3", "initial.x", [0.0, "1.5 mm"], "initial.vx", ["0 m/s", "0.3 m/s"])
    assert bm.ids.shape == (2, 2)
    assert (bm.ids >= 0).all()
    kinds = {(a.label, a.period) for a in bm.attractors}
    # the paper's own start ends in period 6; the others in period-1 bouncing or chattering
    assert bm.attractors[bm.ids[0, 0]].period == 6
    assert kinds == {
        ("periodic_one_sided", 6),
        ("periodic_one_sided", 1),
        ("chattering", 1),
    }
    assert bm.ids[0, 1] == bm.ids[1, 1]  # two starts, one attractor
    assert sum(a.count for a in bm.attractors) == 4


def test_spectrum_of_a_carrier_on_the_wall() -> None:
    """Resting on the wall (paper-3.4b) the carrier follows h(t) = h_a cos(omega_h t): the
    displacement spectrum peaks at 60 Hz with amplitude h_a (less the small contact-depth
    oscillation)."""
    a = analyze("paper-3.4b", duration=1.0)
    sx = a.spectra[0]
    assert sx.quantity == "x"
    assert sx.peaks[0]["frequency"] == pytest.approx(60.0, abs=1e-6)
    assert sx.peaks[0]["amplitude"] == pytest.approx(1.2e-4, rel=0.01)
    assert sx.harmonics[0]["amplitude"] == sx.peaks[0]["amplitude"]
    assert a.steady is not None and a.steady.regime.label == "resting_contact"
    assert a.energy.closure <= 1e-6
    # the contact force oscillates at the excitation too: m h_a omega_h^2 = 20.5 N
    sf = a.spectra[1]
    assert sf.peaks[0]["frequency"] == pytest.approx(60.0, abs=1e-6)
    assert sf.peaks[0]["amplitude"] == pytest.approx(1.2 * 1.2e-4 * (120 * math.pi) ** 2, rel=0.02)


def test_run_spectra_rejects_unsampled_runs() -> None:
    res = braidsim.simulate("paper-3.2", duration=0.02, sample_interval=0)
    with pytest.raises(braidsim.InputError, match="spectrum"):
        run_spectra(res)


# ----------------------------------------------------------------------------------------
# command line
# ----------------------------------------------------------------------------------------


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main(list(argv))
    out, err = capsys.readouterr()
    return int(exc.value.code or 0), out, err


def test_cli_restitution(capsys, tmp_path) -> None:
    code, out, err = run_cli(
        capsys,
        "restitution",
        "--law",
        "flores",
        "--law",
        "lee_wang",
        "--points",
        "3",
        "--json",
        "--out",
        str(tmp_path / "r"),
    )
    assert code == 0, err
    d = json.loads(out)
    assert set(d["laws"]) == {"flores", "lee_wang"}
    assert d["max_deviation"] <= 1e-4
    assert (tmp_path / "r" / "restitution.png").stat().st_size > 1000
    assert json.loads((tmp_path / "r" / "restitution.json").read_text())["nominal"] == d["nominal"]


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (("scenarios", "--keys"), ("12.566370614359172", "horn_gear.angular_velocity")),
        (("models",), ("doi:10.1515/crll.1882.92.156", "lankarani_nikravesh")),
    ],
)
def test_piped_tables_fold_no_word(
    capsys, monkeypatch, args: tuple[str, ...], words: tuple[str, ...]
) -> None:
    """Piped, a table is printed wide enough that no word of a cell is folded over two
    lines: the default omega 12.566370614359172 read 12.56637 / 06143591 / 72 in a file.
    Its text still wraps at spaces (not one line of a thousand columns). (A COLUMNS the
    user sets is kept: test_cli.test_listed_names_are_whole_in_80_columns.)"""
    monkeypatch.delenv("COLUMNS", raising=False)
    code, out, err = run_cli(capsys, *args)
    assert code == 0, err
    for word in words:
        assert word in out
    assert "…" not in out
    assert max(len(line) for line in out.splitlines()) <= 160


def test_cli_restitution_table_is_whole_when_piped(capsys) -> None:
    """Piped output counts as 80 columns for rich, which cut every cell of the 11-column
    table to '1.0…'; tables are printed at their own width instead."""
    code, out, err = run_cli(capsys, "restitution", "--points", "10")
    assert code == 0, err
    assert "…" not in out
    assert "lankarani_nikravesh" in out
    rows = [line for line in out.splitlines() if line.startswith("│ hunt_crossley")]
    assert len(rows) == 1 and len(rows[0].split("│")) == 13  # the law and ten values, whole
    assert all(len(cell.strip()) == 6 for cell in rows[0].split("│")[2:-1])  # 0.5158


def test_cli_analyze_scenario_and_run_folder(capsys, tmp_path) -> None:
    code, out, err = run_cli(capsys, "analyze", "paper-3.4b", "--duration", "0.3", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["regime"]["regime"]["label"] == "resting_contact"
    assert d["energy_balance"]["closure"] <= 1e-6
    assert d["contact_loss_bound"]["stays_on_wall"] is True
    # a folder written by `braidsim run --out` is analysed from its parameters
    code, _, err = run_cli(
        capsys, "run", "paper-3.2", "--duration", "0.1", "--out", str(tmp_path / "run")
    )
    assert code == 0, err
    code, out, err = run_cli(
        capsys, "analyze", str(tmp_path / "run"), "--json", "--out", str(tmp_path / "a")
    )
    assert code == 0, err
    d2 = json.loads(out)
    assert d2["duration"] == pytest.approx(0.1)
    ref = braidsim.simulate("paper-3.2", duration=0.1, sample_interval=0)
    assert d2["impacts"]["count"] == int((~ref.impacts["initial"]).sum())
    for name in ("impacts.png", "energy.png", "spectra.png", "analyze.json"):
        assert (tmp_path / "a" / name).is_file()


def test_cli_analyze_text_names_the_span_of_each_count(capsys) -> None:
    """The text gives the steady-state window's impacts apart from the whole run's, whose
    transient (paper-3.3's release and its outer-wall impacts) would read as steady."""
    code, out, err = run_cli(
        capsys, "analyze", "paper-3.3", "--duration", "0.6 s", "--transient", "0.3 s"
    )
    assert code == 0, err
    code, js, err = run_cli(
        capsys, "analyze", "paper-3.3", "--duration", "0.6 s", "--transient", "0.3 s", "--json"
    )
    d = json.loads(js)
    text = " ".join(out.split())  # rich wraps the lines
    n_win, n_all = d["impacts_in_window"]["count"], d["impacts"]["count"]
    assert n_win < n_all
    assert f"impacts, in the window: {n_win} (" in text
    assert f"impacts, whole run: {n_all} (" in text
    assert "energy, whole run:" in text


def test_cli_analyze_says_why_a_short_window_has_no_regime(capsys) -> None:
    """A window shorter than 2 whole periods between stroboscopic samples has no regime:
    the text and the JSON say why and what duration is needed (they left the regime out
    silently, the text claiming "steady state over whole periods" over 0.3 periods)."""
    argv = ("analyze", "paper-3.3", "--duration", "0.01 s")
    code, out, err = run_cli(capsys, *argv)
    assert code == 0, err
    text = " ".join(out.split())  # rich wraps the lines
    assert "steady state over whole periods" not in text
    assert "window 0.005-0.01 s (0.3 periods), too short for whole periods" in text
    reason = (
        "not classified: the steady-state window 0.005-0.01 s holds 0.3 periods of the "
        "excitation (T = 0.0166667 s), fewer than the 2 whole periods between stroboscopic "
        "samples that the regime rules need; a duration of 0.1 s or more (6 T: the default "
        "transient is half of a run this short) always gives them"
    )
    assert f"steady state: {reason}" in text
    code, js, err = run_cli(capsys, *argv, "--json")
    d = json.loads(js)
    assert d["regime"] is None and d["regime_reason"] == reason
    # the duration it names is enough
    code, js, err = run_cli(capsys, "analyze", "paper-3.3", "--duration", "0.1 s", "--json")
    d = json.loads(js)
    assert d["regime"] is not None and d["regime_reason"] is None
    # with a transient given: the duration after it, or an earlier transient
    a = analyze("paper-3.3", duration=0.1, transient=0.08)
    assert a.steady is None and a.regime_reason.endswith(
        "a duration of 0.13 s or more (the transient + 3 T), or a transient of at most 0.05 s,"
        " always gives them"
    )


def test_analyze_json_carries_the_poincare_samples(capsys, tmp_path) -> None:
    """analyze.json holds the stroboscopic samples poincare.png draws, in the form of
    bifurcation's states[i].strobe."""
    out = tmp_path / "a"
    argv = ("analyze", "paper-3.3", "--duration", "0.2 s", "--out", str(out))
    code, _, err = run_cli(capsys, *argv)
    assert code == 0, err
    d = json.loads((out / "analyze.json").read_text())
    assert (out / "poincare.png").is_file()
    strobe = d["regime"]["strobe"]
    a = analyze("paper-3.3", duration=0.2)
    assert a.steady is not None
    assert strobe == a.steady.to_dict()["strobe"]
    assert set(strobe) == {"t", "x", "vx", "u"} and len(strobe["t"]) == a.steady.strobe_t.size
    t0, t1 = d["regime"]["window"]
    assert strobe["t"][0] == t0 and strobe["t"][-1] == t1
    np.testing.assert_allclose(np.diff(strobe["t"]), d["regime"]["sampling_period"], rtol=1e-9)


def test_cli_bifurcation_basins_lyapunov(capsys, tmp_path) -> None:
    code, out, err = run_cli(
        capsys,
        "bifurcation",
        "paper-3.3",
        "--param",
        "track.vibration_amplitude",
        "--from",
        "0.05 mm",
        "--to",
        "0.4 mm",
        "--points",
        "2",
        "--transient-cycles",
        "30",
        "--cycles",
        "10",
        "--json",
        "--out",
        str(tmp_path / "b"),
    )
    assert code == 0, err
    d = json.loads(out)
    assert d["labels"] == ["resting_contact", "periodic_two_sided"]
    assert d["values"] == pytest.approx([5e-5, 4e-4])
    assert (tmp_path / "b" / "bifurcation.png").is_file()
    code, out, err = run_cli(
        capsys,
        "basins",
        "paper-3.4b",
        "--nx",
        "2",
        "--ny",
        "1",
        "--transient-cycles",
        "20",
        "--cycles",
        "6",
        "--json",
    )
    assert code == 0, err
    d = json.loads(out)
    assert d["ids"] == [[0, 0]] and d["attractors"][0]["label"] == "resting_contact"
    code, out, err = run_cli(
        capsys,
        "lyapunov",
        "paper-3.4b",
        "--transient-cycles",
        "20",
        "--cycles",
        "4",
        "--json",
        "--out",
        str(tmp_path / "l"),
    )
    assert code == 0, err
    assert json.loads(out)["exponent"] < 0
    assert (tmp_path / "l" / "lyapunov.png").is_file()


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (("restitution", "--c-min", "0"), "--c-min"),
        (
            ("bifurcation", "paper-3.3", "--param", "track.clearence", "--from", "1", "--to", "2"),
            "track.clearance",
        ),
        (
            (
                "bifurcation",
                "paper-3.3",
                "--param",
                "contact.track.model",
                "--from",
                "1",
                "--to",
                "2",
            ),
            "not a scalar",
        ),
        (
            (
                "bifurcation",
                "paper-3.3",
                "--param",
                "track.clearance",
                "--from",
                "-1 mm",
                "--to",
                "2 mm",
            ),
            "track.clearance",
        ),
        (("basins", "paper-3.3", "--x", "initial.vx"), "two different"),
        # (the product's name "--nx x --ny" named no option the user typed)
        (("basins", "paper-3.3", "--nx", "0", "--ny", "3"), "error: --nx: 0 is out of range"),
        (("basins", "paper-3.3", "--ny", "-2"), "error: --ny: -2 is out of range"),
        (("lyapunov", "paper-3.3", "--d0", "0"), "d0"),
        (("analyze", "no-such-scenario"), "scenario"),
        (("analyze", "results/no-such-run"), "a folder written by `braidsim run --out`"),
        (("restitution", "--law", "hertzz"), "--law: 'hertzz' is not a contact law (did you"),
        (("run", "paper-3.1", "--set", "=3"), "--set: '=3' has no KEY before '='"),
    ],
)
def test_cli_bad_input_is_one_line_exit_2(capsys, argv, needle) -> None:
    code, out, err = run_cli(capsys, *argv)
    assert code == 2
    assert out == ""
    assert len(err.strip().splitlines()) == 1 and needle in err


def test_energy_balance_closes_across_transfers() -> None:
    """A transfer changes the carrier's kinetic and elastic energy at an instant; the
    transfer-work quadrature takes that jump, so the balance closes to 1e-6 with transfers
    (without the term: about 1e-3)."""
    over = {"transfer.times": [0.05, 0.12, 0.19], "simulation.dof": "xy", "initial.vy": 0.0}
    res = braidsim.simulate("paper-3.2", duration=0.25, overrides=over, sample_interval=1e-4)
    assert res.stats["transfers"] == 3
    eb = energy_balance(res)
    assert eb.closure <= 1e-6
    # the term matters: without it the residual is the jumps of the transfers
    without = float(np.max(np.abs(eb.residual + eb.transfer_work))) / eb.exchanged
    assert without > 1e-5 and without > 100 * eb.closure


@pytest.mark.parametrize(
    ("name", "pattern"),
    [
        ("paper-3.4b", "resting_contact"),
        ("paper-3.3", "one_sided_impacts"),
        ("paper-3.4a", "two_sided_impacts"),
    ],
)
def test_batch_regime_is_the_pattern_the_steady_state_refines(name: str, pattern: str) -> None:
    """One vocabulary: over the same window a batch run reports as its regime the contact
    pattern of the steady-state regime the analysis finds."""
    ss = steady_state(name)
    t0, t1 = ss.window
    batch = simulate_batch(name, [{}], duration=t1, window=(t0, t1))
    assert ss.regime.pattern == pattern
    assert batch.regime_labels()[0] == pattern
