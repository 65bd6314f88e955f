"""``braidsim fit`` on impact lists (onset times with peak forces and speeds) and on several
records fitted together: synthetic lists made by the simulator with known parameters and
noise, the matching against brute force, the exact Jacobian against central differences,
the narrowing of the intervals when two records are fitted together, and bad input."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

import braidsim
from braidsim.errors import InputError
from braidsim.fit import fit, parse_fit_spec, read_record
from braidsim.fit.data import ImpactList, make_impact_list
from braidsim.fit.problem import ImpactProblem, exact_available, match_impacts

SC = "paper-3.1"
FREE2 = {"contact.track.restitution": [0.3, 0.9], "track.clearance": ["2.5 mm", "3.5 mm"]}
FREE2_SI = {"contact.track.restitution": 0.6, "track.clearance": 1e-3}  # widths of FREE2
TRUTH = {"contact.track.restitution": 5 / 9, "track.clearance": 3e-3}
NOISE_T = 1e-4  # s
REL = 0.03  # noise of peak forces and speeds, relative to their median


def impact_table(
    vx: float = 0.5, n: int = 5, seed: int = 0, rebound: bool = False, energy: bool = False
) -> dict:
    """The first ``n`` track impacts of the paper-3.1 carrier started at ``vx`` [m/s], with
    white noise: onset times NOISE_T, peak forces, speeds (and dissipated energies) REL of
    their median."""
    sc = braidsim.load_scenario(SC).with_overrides({"initial.vx": vx})
    im = braidsim.simulate(sc, duration=0.15, record_events=False).impacts
    im = im[(im["pair"] == "track") & ~im["initial"] & ~im["ongoing"]].iloc[:n]
    assert len(im) == n
    rng = np.random.default_rng(seed)
    out = {"t [ms]": 1e3 * (im["t"].to_numpy() + rng.normal(0.0, NOISE_T, n))}
    cols = ["peak_force", "velocity"] + (["rebound_velocity"] if rebound else [])
    cols += ["dissipated_energy"] if energy else []
    unit = {"peak_force": ("kN", 1e-3), "dissipated_energy": ("mJ", 1e3)}
    for q in cols:
        v = np.abs(im[q].to_numpy())
        name, f = unit.get(q, ("mm/s", 1e3))
        out[f"{q} [{name}]"] = (v + rng.normal(0.0, REL * np.median(v), n)) * f
    return out


def noise_of(table: dict) -> dict:
    """The noise the table was made with, in the units of the spec."""
    f = np.asarray(table["peak_force [kN]"])
    v = np.asarray(table["velocity [mm/s]"])
    noise = {"t": f"{NOISE_T} s", "peak_force": f"{REL * np.median(f)} kN"}
    noise["velocity"] = f"{REL * np.median(v)} mm/s"
    if "rebound_velocity [mm/s]" in table:
        noise["rebound_velocity"] = f"{REL * np.median(table['rebound_velocity [mm/s]'])} mm/s"
    if "dissipated_energy [mJ]" in table:
        noise["dissipated_energy"] = f"{REL * np.median(table['dissipated_energy [mJ]'])} mJ"
    return noise


def test_matching_keeps_the_order_and_minimises_the_squared_offsets():
    # against every order-keeping assignment (brute force)
    rng = np.random.default_rng(4)
    for _ in range(30):
        m = int(rng.integers(1, 7))
        n = int(rng.integers(1, m + 1))
        tm = np.sort(rng.uniform(0, 1, m))
        td = np.sort(rng.uniform(0, 1, n))
        got = match_impacts(td, tm)
        assert np.all(np.diff(got) > 0)
        best = min(
            itertools.combinations(range(m), n),
            key=lambda c: float(np.sum((tm[list(c)] - td) ** 2)),
        )
        cost = float(np.sum((tm[got] - td) ** 2))
        assert cost == pytest.approx(float(np.sum((tm[list(best)] - td) ** 2)), abs=1e-15)
    # the nearest in time where that keeps the order
    assert match_impacts(np.array([0.11, 0.52]), np.array([0.0, 0.1, 0.3, 0.5, 0.9])).tolist() == [
        1,
        3,
    ]


def test_a_table_with_impact_columns_is_an_impact_list():
    rec = read_record({"t [ms]": [1.0, 2.0], "peak_force [kN]": [1.5, 0.5]})
    assert isinstance(rec, ImpactList)
    assert rec.t.tolist() == pytest.approx([1e-3, 2e-3])
    assert rec.columns["peak_force"].tolist() == pytest.approx([1500.0, 500.0])


@pytest.mark.parametrize(
    ("table", "words"),
    [
        ({"t": [0.01, 0.01, 0.02], "peak_force": [1, 2, 3]}, "not strictly increasing at row 1"),
        ({"t": [0.02, 0.01], "velocity": [0.1, 0.2]}, "not strictly increasing"),
        ({"peak_force": [1.0, 2.0]}, "no column t"),
        ({"t": [0.01, 0.02], "peak_force [m/s]": [1, 2]}, "does not match the quantity"),
        ({"t [kg]": [0.01, 0.02], "velocity": [1, 2]}, "column t"),
        ({"t": [0.01, 0.02], "velocity": [0.1, np.nan]}, "non-finite"),
        ({"t": [0.01, 0.02], "velocity": [0.1, 0.2], "x": [0, 0]}, "mix sampled"),
        ({"t": [0.01, 0.02], "peak_force": [-1.0, 2.0]}, "negative"),
        # (taken for a record of 2 samples: "allowed a record of at least 3 samples")
        ({"t": [0.01, 0.02]}, "no measured column beside t; allowed"),
        ({"t": [0.01, 0.02], "peak_force": [1.0, 0.0]}, "peak_force is 0 at row 1"),
    ],
)
def test_bad_impact_lists_are_one_line(table, words):
    with pytest.raises(InputError) as err:
        read_record(table)
    assert words in str(err.value)
    assert "\n" not in str(err.value)


def test_an_impact_list_csv_is_read_and_bad_csv_refused(tmp_path):
    p = tmp_path / "impacts.csv"
    p.write_text("t [s],rebound_velocity [m/s]\n0.01,0.2\n0.02,0.1\n", encoding="utf-8")
    rec = read_record(p)
    assert isinstance(rec, ImpactList)
    assert rec.columns["rebound_velocity"].tolist() == [0.2, 0.1]
    p.write_text("t [s],rebound_velocity [m/s]\n0.02,0.2\n0.01,0.1\n", encoding="utf-8")
    with pytest.raises(InputError, match="not strictly increasing"):
        read_record(p)


def test_a_fitted_quantity_no_record_has_is_refused():
    # (it was replaced by the record's own columns without a word)
    table = {"t [ms]": [6.64, 15.86], "peak_force [kN]": [5.49, 5.55]}
    with pytest.raises(InputError, match=r"'velocity' is not a column of the impact list dict"):
        fit(SC, table, FREE2, quantity="velocity")
    with pytest.raises(InputError, match=r"'x' is not a column of the impact list dict"):
        fit(SC, table, FREE2, quantity="x")
    rec = read_record({"t": [0.001, 0.002, 0.003], "acceleration": [0.0, 9.0, 0.0]})
    with pytest.raises(InputError, match=r"'velocity' is not a column of any record; allowed"):
        fit(SC, [rec, table], FREE2, quantity=["acceleration", "peak_force", "velocity"])


def test_cli_refuses_an_impact_list_of_zero_peak_forces(tmp_path, capsys):
    # (its fit ended where the model gave fewer impacts: exit 1, "simulation failed")
    spec = tmp_path / "spec.toml"
    spec.write_text(
        f'scenario = "{SC}"\n[fit]\nfree = {{ "track.clearance" = ["2.5 mm", "3.5 mm"] }}\n'
    )
    data = tmp_path / "impacts.csv"
    data.write_text("t [ms],peak_force [N]\n6.64,0\n15.86,0\n")
    code, stdout, err = _cli(["fit", str(spec), "--data", str(data)], capsys)
    assert (code, stdout) == (2, ""), err
    assert err.count("\n") == 1 and "column peak_force is 0 at row 0" in err, err


def test_noise_of_a_quantity_not_fitted_or_of_no_scale_is_refused():
    table = {"t [ms]": [6.64, 15.86], "peak_force [kN]": [5.49, 5.55]}
    with pytest.raises(InputError, match=r"fit.noise.velocity: velocity is not fitted; allowed "):
        fit(SC, table, FREE2, noise={"velocity": "0.01 m/s"})
    # speeds of 0 give no default noise (5 % of their median): the floor of 1e-9 made
    # every residual beyond the one of a failed run
    with pytest.raises(InputError, match=r"fit.noise.velocity: not given, and the default"):
        fit(SC, {"t [ms]": [6.64, 15.86], "velocity": [0.0, 0.0]}, FREE2)


def test_a_fit_that_ends_short_of_the_lists_impacts_is_bad_input(monkeypatch):
    from braidsim.fit import estimate
    from braidsim.fit.problem import TooFewImpacts

    def short(*args, **kwargs):
        raise TooFewImpacts("the model gives 1 track impacts, fewer than the 2 of the list")

    monkeypatch.setattr(estimate, "_fit_checked", short)
    table = {"t [ms]": [6.64, 15.86], "peak_force [kN]": [5.49, 5.55]}
    with pytest.raises(InputError, match=r"^data \(--data\): at the fitted values the model"):
        fit(SC, table, FREE2)


def test_more_measured_impacts_than_the_model_gives_is_refused():
    t = np.linspace(0.005, 0.14, 40)
    lst = make_impact_list(t, {"peak_force": np.full(40, 1000.0)}, source="too many")
    with pytest.raises(InputError, match="fewer than the 40 of the impact list too many"):
        fit(SC, lst, FREE2, global_method="none")


@pytest.mark.skipif(not exact_available(), reason="needs the simulator's sensitivities")
def test_exact_impact_jacobian_matches_central_differences(monkeypatch):
    # a step of 1e-3 of the unit box: at the default 1e-5 the solver's tolerance (1e-8
    # relative) puts ~1e-2 of noise into the differences of the speeds
    import braidsim.fit.problem as problem

    monkeypatch.setattr(problem, "FD_STEP", 1e-3)
    sc = braidsim.load_scenario(SC)
    spec = parse_fit_spec({"fit": {"free": FREE2}}, scenario=sc)
    rec = read_record(impact_table(seed=1, rebound=True, energy=True))
    pr = ImpactProblem(sc, rec, spec.free, (), None, "exact")
    assert "rebound_velocity" in pr.quantities  # (its rows were central differences)
    assert "dissipated_energy" in pr.quantities  # (the impacts' sensitivities since 12-01)
    u = pr.u_start + 0.03
    Je = pr.residuals(u, jac=True).J
    Jf = pr.jacobian_fd(u)
    assert Je is not None
    scale = np.abs(Jf).max(axis=0)
    assert np.max(np.abs(Je - Jf) / scale) < 1e-3


def test_truth_is_recovered_from_a_noisy_impact_list():
    table = impact_table(seed=7, rebound=True)
    res = fit(SC, table, FREE2, noise=noise_of(table), global_method="none")
    assert res.converged
    assert res.quantities == ("t", "peak_force", "velocity", "rebound_velocity")
    assert res.n_data == 4 * 5
    for i, k in enumerate(res.keys):
        lo, hi = res.stats.ci95[i]
        assert lo <= TRUTH[k] <= hi, (k, lo, TRUTH[k], hi)
        assert hi - lo < 0.2 * FREE2_SI[k], (k, hi - lo)
    assert not any("rebound_velocity" in n for n in res.notes)  # exact rows since


def test_truth_is_recovered_from_the_dissipated_energies_of_an_impact_list():
    """Impact times and each impact's dissipated energy (a force-penetration loop's area)
    alone identify the restitution and the clearance."""
    names = ("t", "dissipated_energy")
    table = impact_table(seed=3, energy=True)
    table = {k: v for k, v in table.items() if k.split(" ")[0] in names}
    # (the noise of the columns fitted only: one of a quantity not fitted is refused)
    noise = {k: v for k, v in noise_of(impact_table(seed=3, energy=True)).items() if k in names}
    res = fit(SC, table, FREE2, noise=noise, global_method="none")
    assert res.converged
    assert res.quantities == ("t", "dissipated_energy")
    for i, k in enumerate(res.keys):
        lo, hi = res.stats.ci95[i]
        assert lo <= TRUTH[k] <= hi, (k, lo, TRUTH[k], hi)
        assert hi - lo < 0.2 * FREE2_SI[k], (k, hi - lo)


def _cli(argv, capsys):
    from braidsim.cli import _register
    from braidsim.cli.common import run_app

    _register()
    code = run_app(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_two_records_at_two_speeds_narrow_the_intervals(tmp_path, capsys):
    a, b = impact_table(0.5, seed=2), impact_table(0.3, seed=3)
    kw = {"global_method": "none"}
    fa = fit(SC, a, FREE2, noise=noise_of(a), **kw)
    fb = fit(SC, b, FREE2, noise=noise_of(b), overrides={"initial.vx": "0.3 m/s"}, **kw)
    both = fit(
        SC,
        [(a, {}), (b, {"initial.vx": "0.3 m/s"})],
        FREE2,
        noise=noise_of(a),
        **kw,
    )
    assert both.n_data == fa.n_data + fb.n_data
    assert len(both.parts) == 2
    for i, k in enumerate(both.keys):
        lo, hi = both.stats.ci95[i]
        assert lo <= TRUTH[k] <= hi, (k, lo, TRUTH[k], hi)
        w = hi - lo
        assert w < np.ptp(fa.stats.ci95[i]) and w < np.ptp(fb.stats.ci95[i]), k

    # the same through the command line: a spec with a data list and its own overrides
    import pandas as pd

    pd.DataFrame(a).to_csv(tmp_path / "a.csv", index=False)
    pd.DataFrame(b).to_csv(tmp_path / "b.csv", index=False)
    noise = ", ".join(f'{q} = "{v}"' for q, v in noise_of(a).items())
    (tmp_path / "spec.toml").write_text(
        f'scenario = "{SC}"\n'
        'data = ["a.csv", {path = "b.csv", overrides = {"initial.vx" = "0.3 m/s"}}]\n'
        "[fit]\n"
        'free = { "contact.track.restitution" = [0.3, 0.9], '
        '"track.clearance" = ["2.5 mm", "3.5 mm"] }\n'
        f'global = "none"\nnoise = {{ {noise} }}\n',
        encoding="utf-8",
    )
    out = tmp_path / "out"
    code, stdout, err = _cli(
        ["fit", str(tmp_path / "spec.toml"), "--out", str(out), "--json"], capsys
    )
    assert code == 0, err
    doc = json.loads(stdout)
    assert [r["kind"] for r in doc["records"]] == ["impacts", "impacts"]
    for k in both.keys:
        assert doc["estimates"][k]["value"] == pytest.approx(both.values[k], rel=1e-6)
    assert (out / "fitted_residuals.csv").read_text(encoding="utf-8").count("\n") == 1 + 2 * 15
    assert (out / "residuals.png").stat().st_size > 0

    # --data repeated replaces the spec's list (and its overrides)
    argv = ["fit", str(tmp_path / "spec.toml"), "--json"]
    code, stdout, err = _cli([*argv, "--data", str(tmp_path / "a.csv")], capsys)
    assert code == 0, err
    one = json.loads(stdout)
    assert one["n_data"] == 15 and "records" not in one
    code, stdout, err = _cli(
        [*argv, "--data", str(tmp_path / "a.csv"), "--data", str(tmp_path / "a.csv")], capsys
    )
    assert code == 0, err
    two = json.loads(stdout)
    assert two["n_data"] == 30 and len(two["records"]) == 2
    for k in both.keys:  # the same record twice: the same estimate
        assert two["estimates"][k]["value"] == pytest.approx(one["estimates"][k]["value"], rel=1e-5)

    # a free parameter overridden per record, and a bad data entry: one line, exit 2
    bad = tmp_path / "bad.toml"
    bad.write_text(
        (tmp_path / "spec.toml")
        .read_text(encoding="utf-8")
        .replace('"initial.vx" = "0.3 m/s"', '"track.clearance" = "3 mm"'),
        encoding="utf-8",
    )
    code, _, err = _cli(["fit", str(bad)], capsys)
    assert code == 2
    assert "data[1].overrides.track.clearance: a free parameter" in err
    bad.write_text(
        f'scenario = "{SC}"\ndata = [3]\n'
        '[fit]\nfree = { "track.clearance" = ["2 mm", "4 mm"] }\n',
        encoding="utf-8",
    )
    code, _, err = _cli(["fit", str(bad)], capsys)
    assert code == 2
    assert "data[0]: 3 is not allowed" in err


def test_the_report_says_where_each_noise_level_comes_from() -> None:
    """An impact list's levels are defaults (the onset times' 0.1 ms said "estimated from the
    record", without a unit)."""
    from braidsim.cli.fit import noise_origin

    assert noise_origin("t", {}) == "default, 0.1 ms"
    assert noise_origin("peak_force", {}) == "default, 5 % of the median"
    assert noise_origin("peak_force", {"peak_force": 150.0}) == "given"
    assert noise_origin("acceleration", {}) == "estimated from the record"
