"""Continuation of periodic orbits: shooting, Floquet multipliers, the command line.

References no one here wrote: the exact variational monodromy against a central
finite-difference one (two independent derivatives of the same map); multipliers that must
not depend on where the period is cut (a similarity invariant of the monodromy); the brute
force stroboscopic diagram and the analytic contact-loss bound a_p = h_a omega_h^2 are in
``test_continuation_slow.py`` and below.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re

import numpy as np
import pytest

import braidsim
from braidsim.continuation import ScenarioSystem, seed_orbit
from braidsim.continuation.branch import continue_orbit, orbit_at
from braidsim.continuation.orbit import ContinuationError, recut, solve_fixed
from braidsim.continuation.results import (
    branch_dataset,
    open_branch,
    orbit_from_dataset,
    write_branch,
)
from braidsim.errors import InputError

HA = "track.vibration_amplitude"


@pytest.fixture(scope="module")
def system() -> ScenarioSystem:
    return ScenarioSystem(braidsim.load_scenario("paper-3.3"))


@pytest.fixture(scope="module")
def bouncing(system: ScenarioSystem):
    """The period-1 orbit with one impact per vibration cycle at h_a = 0.1 mm."""
    return seed_orbit(system, {HA: 0.1e-3}, 1, method="fd")


def test_bouncing_orbit_is_periodic_and_stable(system, bouncing) -> None:
    o = bouncing
    assert o.profile.impacts == 1
    assert o.stable
    # one forcing period from the section returns to the same state
    from braidsim.continuation.fdmap import advance

    prep = system.prepare(o.values)
    t0 = o.phase / prep.omega
    seg = advance(prep, t0, t0 + prep.period, o.z[0], o.cuts[0].modes, (math.nan, math.nan))
    assert np.allclose(seg.y1, o.z[0], rtol=0, atol=1e-12 * 0 + 1e-11)


def test_exact_monodromy_matches_finite_differences(system, bouncing) -> None:
    """Multipliers of the exact variational map against the central-difference map, on the
    one-impact orbit at h_a = 0.12 mm next to its period doubling (continued from 0.1 mm: the
    run at 0.12 mm hovers near a period-3 orbit, not near this one) and on that period-3
    orbit."""
    br = continue_orbit(system, bouncing, HA, 0.125e-3, method="fd", switch=False, max_points=30)
    p1 = orbit_at(system, br, 0.12e-3, method="fd")
    for period in (1, 3):
        o = p1 if period == 1 else seed_orbit(system, {HA: 0.12e-3}, period, method="fd")
        oe = solve_fixed(system, o.values, period, o.phase, o.cuts, o.z, "exact")
        mu_f = o.multipliers
        mu_e = oe.multipliers
        # central differences at 1e-5 of the scales: agreement to 1e-3 of the spectral radius
        scale = float(np.max(np.abs(mu_e)))
        assert scale > 0.5
        assert np.max(np.abs(mu_e - mu_f)) < 1e-3 * scale
        L, V = system.scales(o.values)
        assert abs(oe.z[0][0] - o.z[0][0]) < 1e-6 * L
        assert abs(oe.z[0][1] - o.z[0][1]) < 1e-6 * V


def test_multipliers_do_not_depend_on_the_cut(system, bouncing) -> None:
    """The same orbit cut in free flight at several phases, inside the contact (the latched
    approach speed joins the state) and into 3 shooting segments: same multipliers (the
    exact map; central differences inside a stiff contact are good to about 1e-2 only)."""
    ref = solve_fixed(
        system, bouncing.values, 1, bouncing.phase, bouncing.cuts, bouncing.z, "exact"
    ).multipliers
    prof = bouncing.profile
    w = system.prepare(bouncing.values).omega
    t_on = float(prof.onsets[0])
    t_mid = t_on + 0.5 * (float(prof.exits[0]) - t_on) % prof.period
    inside = recut(bouncing, system, w * t_mid, method="exact")
    assert inside.cuts[0].modes[0] != 0 and inside.cuts[0].v0_state[0]
    assert inside.z[0].size == 3
    cases = [recut(bouncing, system, ph, method="exact") for ph in (0.3, 2.0)]
    cases += [inside, recut(bouncing, system, bouncing.phase, segments=3, method="exact")]
    for o in cases:
        # the latched speed is set again at the next onset from (x, x') alone: the extra
        # multiplier of a cut inside the contact is 0, the others are those of a free cut
        mu = o.multipliers
        assert np.allclose(np.sort_complex(mu[:2]), np.sort_complex(ref), atol=1e-5)
        assert np.all(np.abs(mu[2:]) < 1e-6)


def test_the_residuals_frequency_column_with_a_latched_speed_in_the_state(system, bouncing) -> None:
    """With the forcing frequency free the cut times t_j = theta_j / Omega move with it. Cut
    inside the contact, the latched speed out of the map moves with t_0 as -(dv0/dy0) f0
    (the same trajectory started later); that term was missing (the column's latched-speed
    entry came out 9 times too large). Every column of the residual's Jacobian against
    central differences of the residual itself."""
    from braidsim.continuation.orbit import Shooter, frequency_key
    from reference.central_differences import residual_jacobian

    prof = bouncing.profile
    w = system.prepare(bouncing.values).omega
    t_on = float(prof.onsets[0])
    t_mid = t_on + 0.5 * (float(prof.exits[0]) - t_on) % prof.period
    for o in (recut(bouncing, system, w * t_mid, method="exact"), bouncing):
        key = frequency_key(system)
        sh = Shooter(system, dict(o.values), key, o.period, o.phase, o.cuts, "exact", pscale=w)
        U = sh.pack(o.z, w)
        _, DR, _ = sh.residual(U)
        fd = residual_jacobian(sh, U)
        assert np.all(np.abs(DR - fd) <= 1e-6 * np.abs(fd).max(axis=0)), o.cuts


def test_newton_iterates_on_rough_maps_and_takes_the_multipliers_from_an_accurate_one(
    system, bouncing
) -> None:
    """With the exact map, Newton's iterates take maps whose tangents are not held to the
    tolerance (less than half the time on a resting orbit) and the converged orbit's
    monodromy is that of one map with them held: the same bits as a fresh accurate map at
    the orbit, not the rough one's (its multipliers 9e-4 off here, up to 4e-3 at other
    cuts: the tangents' field is not smooth at the contact's onset and exit)."""
    from braidsim.continuation.orbit import Shooter, monodromy_of, sort_multipliers

    o = solve_fixed(system, bouncing.values, 1, bouncing.phase, bouncing.cuts, bouncing.z, "exact")
    sh = Shooter(system, dict(o.values), None, o.period, o.phase, o.cuts, "exact")
    U = sh.pack(o.z, None)
    R, _, Js = sh.residual(U)
    assert not sh.rough
    np.testing.assert_array_equal(monodromy_of(Js), o.monodromy)
    R_rough, _, J_rough = sh.residual(U, accurate=False)
    assert sh.rough
    mu_rough = sort_multipliers(np.linalg.eigvals(monodromy_of(J_rough)))
    assert np.max(np.abs(mu_rough - o.multipliers)) > 1e-4
    # the orbit is a fixed point of the rough maps (those of Newton's iterates), and of the
    # accurate ones to Newton's tolerance: both integrate the state to the same tolerances
    assert np.max(np.abs(R_rough)) < 1e-8 and np.max(np.abs(R)) < 1e-8
    # central differences have no rough form: the flag stays down
    fd = Shooter(system, dict(o.values), None, o.period, o.phase, o.cuts, "fd")
    fd.residual(U, accurate=False)
    assert not fd.rough


def test_branch_points_carry_the_accurate_multipliers(system, bouncing) -> None:
    """Along a branch (the corrector's maps also carry the parameter's direction, so their
    steps are not those of a map at fixed parameters) each point's multipliers are the
    accurate ones: within 1e-6 of an accurate map's at the point (measured 4.4e-8 and
    1.2e-8), while the rough map's are 1.4e-4 off."""
    from braidsim.continuation.orbit import Shooter, monodromy_of, sort_multipliers

    br = continue_orbit(system, bouncing, HA, 0.105e-3, method="exact", switch=False, max_points=3)
    assert len(br.points) == 3
    for o in br.points[1:]:
        sh = Shooter(system, dict(o.values), None, o.period, o.phase, o.cuts, "exact")
        U = sh.pack(o.z, None)
        mu = [
            sort_multipliers(np.linalg.eigvals(monodromy_of(sh.residual(U, accurate)[2])))
            for accurate in (True, False)
        ]
        assert float(np.max(np.abs(o.multipliers - mu[0]))) < 1e-6
        assert float(np.max(np.abs(o.multipliers - mu[1]))) > 5e-5


def test_continuation_maps_hold_the_state_to_rtol_times_its_scales(system, bouncing) -> None:
    """The continuation's maps integrate with absolute tolerances of at most rtol times the
    state scales (L, L omega_h), not the plain run's 1e-13 m and 1e-9 m/s (2.7e-8 of L
    omega_h, above Newton's 1e-8): a period's map of the bouncing orbit started inside its
    contact (the latched speed in the state) converges with rtol. Against the same map at
    rtol / 100, measured: 1.1e-9 L and 1.1e-7 L omega_h at rtol 1e-10, 7e-12 and 7.4e-10 at
    1e-12; with the plain run's absolute tolerances 6.2e-8 and 6.3e-6 at 1e-10, 1.2e-7 and
    1.3e-5 at 1e-12 (the absolute tolerances, not rtol, bounded the error)."""
    from braidsim.continuation.fdmap import advance

    L, V = system.scales(bouncing.values)
    sc = system.scenario_at(bouncing.values)
    assert sc["simulation.atol_position"] == pytest.approx(system.rtol * L, rel=1e-15)
    assert sc["simulation.atol_velocity"] == pytest.approx(system.rtol * V, rel=1e-15)
    # a scenario's own tighter tolerance is kept
    tight = ScenarioSystem(system.scenario.with_overrides({"simulation.atol_velocity": 1e-15}))
    assert tight.scenario_at(bouncing.values)["simulation.atol_velocity"] == 1e-15
    prof = bouncing.profile
    w = system.prepare(bouncing.values).omega
    t_on = float(prof.onsets[0])
    inside = recut(bouncing, system, w * (t_on + 0.5 * (float(prof.exits[0]) - t_on)), method="fd")
    cut, z = inside.cuts[0], inside.z[0]
    t0 = inside.phase / w

    def end(rtol: float) -> np.ndarray:
        p = ScenarioSystem(system.scenario, rtol=rtol).prepare(bouncing.values)
        seg = advance(p, t0, t0 + p.period, z[:2], cut.modes, tuple(cut.v0s(z[2:])))
        return seg.y1 / np.array([L, V])

    assert system.rtol == 1e-10
    for rtol, bound in ((1e-10, (1e-8, 1e-6)), (1e-12, (1e-10, 1e-8))):
        err = np.abs(end(rtol) - end(rtol / 100))
        assert err[0] < bound[0] and err[1] < bound[1], (rtol, err)


def test_period_doubling_and_switched_branch(system, bouncing) -> None:
    """Continuing the bouncing orbit finds one period doubling in [0.09, 0.13] mm; the
    period-2 branch born there is stable next to it and is no period-1 orbit."""
    br = continue_orbit(
        system, bouncing, HA, 0.13e-3, bounds=(0.09e-3, 0.13e-3), method="fd", max_depth=1
    )
    pds = [s for s in br.special if s.type == "period_doubling"]
    assert len(pds) == 1
    assert 0.118e-3 < pds[0].value < 0.123e-3
    # stable before, unstable after
    v = br.values
    assert br.stable[v < pds[0].value - 1e-7].all()
    assert not br.stable[v > pds[0].value + 1e-7].any()
    (child,) = br.children
    assert child.period == 2 and child.stable[:3].all()
    su = child.points[1].profile.strobe_u
    assert abs(su[0] - su[1]) > 1e-6
    # the branch's orbit at a value between points
    o = orbit_at(system, br, 0.105e-3, method="fd")
    assert o.values[HA] == pytest.approx(0.105e-3)


def test_dataset_round_trip_and_restart(system, bouncing, tmp_path) -> None:
    br = continue_orbit(system, bouncing, HA, 0.11e-3, method="fd", switch=False, max_points=6)
    ds = branch_dataset(br, "paper-3.3")
    assert ds.sizes["point"] == len(br.points)
    p = write_branch(ds, tmp_path / "b.nc")
    back = open_branch(p)
    assert back.attrs["parameter"] == HA
    np.testing.assert_array_equal(back["value"].values, br.values)
    o = orbit_from_dataset(system, back, -1, method="fd")
    assert np.allclose(o.multipliers, br.points[-1].multipliers, atol=1e-6)
    z = write_branch(ds, tmp_path / "b.zarr")
    assert open_branch(z).sizes["point"] == len(br.points)


def test_a_damaged_or_foreign_branch_file_is_refused_naming_the_key(tmp_path) -> None:
    """A restart file that is not a readable branch (text under .nc, a truncated netCDF, an
    empty folder, a dataset without a branch's parameter) is an input error naming the key
    and the path, not an OSError without either."""
    import xarray as xr

    garbage = tmp_path / "garbage.nc"
    garbage.write_text("not netCDF\n")
    folder = tmp_path / "folder.nc"
    folder.mkdir()
    whole = tmp_path / "other.nc"
    xr.Dataset({"regime": ("run", np.zeros(3))}).to_netcdf(whole, engine="h5netcdf")
    truncated = tmp_path / "truncated.nc"
    truncated.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    for path in (garbage, folder, truncated, whole):
        with pytest.raises(InputError) as err:
            open_branch(path, "continuation.restart")
        text = str(err.value)
        assert text.startswith(f"continuation.restart: {str(path)!r} ") and "\n" not in text
        assert "allowed a branch_*.nc or branch_*.zarr" in text


def test_not_continuable_keys(system) -> None:
    for key, word in (
        ("initial.x", "not a parameter"),
        ("simulation.rtol", "not a parameter"),
        ("contact.track.model", "not a number"),
        ("track.vibration_amplitud", "did you mean"),
    ):
        with pytest.raises(InputError, match=word):
            system.check_key(key)


def test_transfers_must_repeat_with_the_vibration() -> None:
    sc = braidsim.load_scenario("paper-3.3", overrides={"transfer.period": "0.251 s"})
    with pytest.raises(InputError, match=r"transfer\.period"):
        ScenarioSystem(sc).prepare({})
    ok = braidsim.load_scenario("paper-3.3", overrides={"transfer.period": "0.25 s"})
    assert ScenarioSystem(ok).prepare({}).transfer_period == pytest.approx(0.25)


def _spec(tmp_path, body: str):
    p = tmp_path / "spec.toml"
    p.write_text('scenario = "paper-3.3"\n' + body, encoding="utf-8")
    return p


def test_cli_json_and_restart(tmp_path) -> None:
    from braidsim.cli import _register
    from braidsim.cli.common import run_app

    _register()
    body = (
        '[continuation]\nparameter = "track.vibration_amplitude"\nfrom = "0.1 mm"\n'
        'to = "0.11 mm"\nmax_points = 5\nmethod = "fd"\nswitch = false\n'
    )
    spec = _spec(tmp_path, body)
    out = tmp_path / "out"
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = run_app(["continue", str(spec), "--out", str(out), "--json"])
    assert rc == 0
    assert buf.getvalue().count("\n") == 1  # one JSON object, nothing else on stdout
    data = json.loads(buf.getvalue())
    assert data["braidsim_version"] == braidsim.__version__
    assert data["cross_branch"] is None  # (no `cross` in the spec)
    summary = json.loads((out / "summary.json").read_text())
    assert data == summary  # (the version included: the folder says what made it)
    (b,) = data["branches"]
    assert b["parameter"] == HA and b["period"] == 1
    pt = b["points"][0]
    assert set(pt) >= {"value", "stable", "multipliers", "max_depth", "min_gap", "peak_force"}
    assert pt["value"] == pytest.approx(1e-4)
    assert (out / "branch_0.nc").is_file() and (out / "points.csv").is_file()
    # restart from the saved branch's last point
    spec2 = _spec(
        tmp_path,
        body.replace('from = "0.1 mm"\n', f'restart = "{out / "branch_0.nc"}"\n'),
    )
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = run_app(["continue", str(spec2), "--out", str(tmp_path / "out2"), "--json"])
    assert rc == 0
    b2 = json.loads(buf.getvalue())["branches"][0]
    assert b2["points"][0]["value"] == pytest.approx(b["points"][-1]["value"])


@pytest.mark.parametrize(
    ("body", "code", "words"),
    [
        (  # the carrier rests (period 1): no period-2 orbit to seed
            '[continuation]\nparameter = "track.vibration_amplitude"\nfrom = "0.05 mm"\n'
            'to = "0.06 mm"\nperiod = 2\nmethod = "fd"\n',
            1,
            "set period = 1",
        ),
        ('[continuation]\nparameter = "initial.x"\nfrom = 0\nto = "1 mm"\n', 2, "initial.x"),
        ('[continuation]\nparameter = "track.vibration_amplitude"\nfrom = "0.1 mm"\n', 2, "to"),
        (
            '[continuation]\nparameter = "track.vibration_amplitude"\nfrom = "0.1 mm"\n'
            'to = "0.2 mm"\nseed = ["2 mm", "0.3 m/s"]\nmethod = "fd"\n',
            2,
            "continuation.seed",
        ),
        (
            '[continuation]\nparameter = "track.vibration_amplitude"\nfrom = "0.1 mm"\n'
            'to = "0.2 mm"\nperiod = 0\n',
            2,
            "continuation.period",
        ),
        (
            '[continuation]\nparameter = "track.vibration_amplitude"\nfrom = "0.1 mm"\n'
            'to = "0.2 mm"\nresting_speed = "-1 m/s"\n',
            2,
            "continuation.resting_speed",
        ),
    ],
)
def test_cli_bad_input(tmp_path, capsys, body: str, code: int, words: str) -> None:
    from braidsim.cli import _register
    from braidsim.cli.common import run_app

    _register()
    rc = run_app(["continue", str(_spec(tmp_path, body)), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == code
    assert words in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_multiple_shooting_branch_matches_single_shooting(system, bouncing) -> None:
    """A branch continued with 2 shooting segments has the orbits and multipliers of the
    single-shooting one at the same parameter values."""
    o2 = seed_orbit(system, {HA: 0.1e-3}, 1, segments=2, method="fd")
    assert o2.segments == 2
    br2 = continue_orbit(system, o2, HA, 0.11e-3, method="fd", switch=False, max_points=4)
    assert len(br2.points) == 4
    single = continue_orbit(system, bouncing, HA, 0.11e-3, method="fd", switch=False, max_points=8)
    for o in br2.points[1:]:
        ref = orbit_at(system, single, o.values[HA], method="fd")
        mu, mu_ref = np.sort_complex(o.multipliers), np.sort_complex(ref.multipliers)
        assert np.allclose(mu, mu_ref, atol=1e-4)
        assert abs(o.profile.strobe_u[0] - ref.profile.strobe_u[0]) < 1e-10


def test_period_doubling_located_on_a_coarse_branch(system, bouncing) -> None:
    """A period doubling is located by a root solve of det(M + I) in the parameter, each
    trial orbit corrected by Newton's method: a branch with coarse steps (up to 5 um of h_a
    between points) places it where a fine one (0.1 um) does, and a multiplier is -1
    there (the brute-force diagram brackets it: ``test_continuation_slow.py``)."""
    coarse = continue_orbit(
        system, bouncing, HA, 0.3e-3, method="fd", switch=False, step=0.01, max_step=0.03
    )
    fine = continue_orbit(
        system, bouncing, HA, 0.13e-3, method="fd", switch=False, step=0.002, max_step=0.004
    )
    assert np.diff(coarse.values).max() > 2e-6 and np.diff(fine.values).max() < 2e-7
    (pc,) = [s for s in coarse.special if s.type == "period_doubling"]
    (pf,) = [s for s in fine.special if s.type == "period_doubling"]
    assert pc.tolerance < 1e-12 and pf.tolerance < 1e-12
    assert abs(pc.value - pf.value) < 1e-12
    for sp in (pc, pf):
        assert sp.orbit is not None
        assert np.min(np.abs(sp.orbit.multipliers + 1.0)) < 1e-6


def test_special_point_markers_are_merged_when_they_overlap() -> None:
    from braidsim.continuation.plots import MERGE_FRACTION, merge_marks

    d = 0.5 * MERGE_FRACTION
    marks = [(0.0, 0.0, "grazing"), (d, d, "grazing"), (d, 0.0, "fold"), (0.5, 0.0, "grazing")]
    assert merge_marks(marks, (1.0, 1.0)) == [
        (0.0, 0.0, "grazing", 2),
        (d, 0.0, "fold", 1),
        (0.5, 0.0, "grazing", 1),
    ]


def test_example_specs_parse() -> None:
    """The shipped specs: the (h_a, omega) lift-off and the (clearance, omega) map."""
    from pathlib import Path

    from braidsim.continuation.study import load_spec

    ex = Path(__file__).resolve().parents[2] / "examples"
    a = load_spec(ex / "continuation_paper.toml")
    assert (a.parameter, a.map_parameter) == (HA, "horn_gear.angular_velocity")
    b = load_spec(ex / "continuation_clearance.toml")
    assert (b.parameter, b.map_parameter) == ("track.clearance", "horn_gear.angular_velocity")
    assert b.scenario[HA] == pytest.approx(0.1e-3) and b.regime_points == (6, 7)
    assert b.map_cross == pytest.approx((6 * math.pi, 3 * math.pi))


def test_resting_orbit_does_not_remember_its_seed(system) -> None:
    """A contact open all along the orbit gets the law's floor as its latched speed, so
    resting orbits seeded from runs that latched different speeds (300 cycles from the
    scenario's start; 40 cycles from a state dropped onto the wall) are one orbit; another
    resting_speed gives another orbit (the speed sets the contact's damping)."""
    vals = {HA: 0.05e-3}
    a = seed_orbit(system, vals, 1, method="fd")
    prep = system.prepare(vals)
    drop = (0.0, np.array([1e-6, -0.05]), (0, 0), np.array([math.nan, math.nan]))
    b = seed_orbit(system, vals, 1, method="fd", transient_cycles=40, start=drop)
    for o in (a, b):
        assert o.profile.impacts == 0 and o.cuts[0].modes[0] == -1
        assert o.cuts[0].v0_fixed[0] == system.value("contact.min_impact_velocity")
    t_a, t_b = a.phase / prep.omega, b.phase / prep.omega
    assert t_a == pytest.approx(t_b)
    # to Newton's tolerance (1e-8 of L and L omega_h)
    L, V = system.scales(vals)
    assert abs(a.z[0][0] - b.z[0][0]) < 1e-8 * L and abs(a.z[0][1] - b.z[0][1]) < 1e-8 * V
    other = ScenarioSystem(system.scenario, resting_speed=2e-3)
    c = seed_orbit(other, vals, 1, method="fd")
    assert c.cuts[0].v0_fixed[0] == 2e-3
    assert abs(c.profile.approach - a.profile.approach) > 1e-3 * a.profile.approach


_BASE_CONT = {"parameter": HA, "from": "0.05 mm", "to": "0.06 mm"}


@pytest.mark.parametrize(
    ("continuation", "operating_map", "message"),
    [
        # each was accepted, or failed later without naming the entry (a sceptical audit)
        ({"restart": "b.nc", "restart_point": "last"}, {}, "continuation.restart_point: 'last'"),
        ({"restart": "spec.toml"}, {}, "continuation.restart: 'spec.toml' is not a saved branch"),
        ({"transient_cycles": 0.5}, {}, "continuation.transient_cycles: 0.5 is out of range"),
        ({"transient_cycles": -0.5}, {}, "allowed an integer 0 <= value <= 1e6"),
        ({"min_step": 1e-3, "max_step": 1e-9}, {}, "min_step 0.001 <= step 0.02 <= max_step"),
        ({}, {"parameter": "foo.bar", "to": 1.0}, "operating_map.parameter: unknown key"),
        (
            {},
            {"parameter": "horn_gear.angular_velocity", "to": "4 pi rad/s"},
            "operating_map.to: equals the scenario's horn_gear.angular_velocity",
        ),
    ],
)
def test_spec_entries_are_refused_where_they_are_given(continuation, operating_map, message):
    from braidsim.continuation.study import parse_spec

    table = {"scenario": "paper-3.3", "continuation": {**_BASE_CONT, **continuation}}
    if operating_map:
        table["operating_map"] = operating_map
    with pytest.raises(InputError, match=re.escape(message)):
        parse_spec(table)


def test_spec_accepts_a_transient_of_whole_periods_and_a_restart_point_from_the_end() -> None:
    from braidsim.continuation.study import parse_spec

    cont = {**_BASE_CONT, "transient_cycles": 0, "restart": "b.zarr", "restart_point": -2}
    spec = parse_spec({"scenario": "paper-3.3", "continuation": cont})
    assert spec.transient_cycles == 0.0 and spec.restart_point == -2
    assert spec.restart is not None and spec.restart.endswith("b.zarr")


def test_a_branch_ending_just_below_a_lift_off_ends_on_its_own_orbit(system) -> None:
    """The resting branch of paper-3.3 continued to 0.0968 mm, 1.5 % below its lift-off at
    0.0983 mm, with long steps: the step past the end landed beyond the lift-off, on the
    bouncing orbit that coexists there, and the end point found from it was that orbit
    (one impact, a grazing reported at the end value). It is found from the branch's own
    prediction now: still resting, no special point."""
    rest = seed_orbit(system, {HA: 0.05e-3}, 1, method="fd")
    assert rest.profile.impacts == 0
    br = continue_orbit(
        system, rest, HA, 0.0968e-3, method="fd", switch=False, step=0.1, max_step=0.3
    )
    assert br.points[-1].values[HA] == pytest.approx(0.0968e-3, rel=1e-12)
    assert br.stop.startswith("reached")
    assert all(o.profile.impacts == 0 for o in br.points)
    assert not br.special


def _reported_points_are_zeros(br) -> None:
    """Every fold and period doubling reported has its multiplier at +1 or -1."""
    for sp in br.special:
        if sp.type == "fold":
            assert np.min(np.abs(sp.orbit.multipliers - 1.0)) < 1e-3, sp
        if sp.type == "period_doubling":
            assert np.min(np.abs(sp.orbit.multipliers + 1.0)) < 1e-3, sp


def test_a_step_onto_another_family_is_halved_and_finds_the_doubling(system) -> None:
    """paper-3.3's resting branch at 4 pi rad/s with the finite-difference map and long
    steps (max_step 0.03): the step from 0.1273 mm landed at 0.1308 mm on another family of
    the same contacts, over a period doubling at 0.12850 mm, and the tangent's parameter
    component changed sign there without a zero (multipliers 0.005 +- 0.047i, then 2.98;
    it was once reported as a fold at 0.12875 mm with multipliers -1.24 and -0.003). The
    step is now tried again halved: the doubling is found where a branch of steps of at
    most 0.01 finds it (there 0.1285027101219 mm), and the family ends at its grazing at
    0.13013 mm as that branch's does."""
    rest = seed_orbit(system, {HA: 0.02e-3}, 1, method="fd")
    assert system.value("horn_gear.angular_velocity") == pytest.approx(4 * math.pi)
    br = continue_orbit(
        system, rest, HA, 0.3e-3, method="fd", switch=False, max_points=80, step=0.01, max_step=0.03
    )
    assert not [s for s in br.special if s.type == "fold" and 0.1272e-3 < s.value < 0.1308e-3]
    (pd,) = [s for s in br.special if s.type == "period_doubling"]
    assert pd.value == pytest.approx(0.1285027101219e-3, rel=1e-9)
    assert not br.notes
    assert br.special[-1].type == "grazing"
    assert br.special[-1].value == pytest.approx(0.13013e-3, rel=1e-4)
    _reported_points_are_zeros(br)


def test_a_sign_change_without_a_zero_is_a_note_not_a_fold(system, monkeypatch) -> None:
    """The same branch with the halved retries turned off: the sign change without a zero
    is a note naming both values and multipliers, not a fold."""
    monkeypatch.setattr("braidsim.continuation.branch.RETRIES_WITHOUT_A_ZERO", 0)
    rest = seed_orbit(system, {HA: 0.02e-3}, 1, method="fd")
    br = continue_orbit(
        system, rest, HA, 0.3e-3, method="fd", switch=False, max_points=72, step=0.01, max_step=0.03
    )
    assert not [s for s in br.special if s.type == "fold" and 0.1272e-3 < s.value < 0.1308e-3]
    assert any("the branch turns back" in n and "without a zero" in n for n in br.notes)
    _reported_points_are_zeros(br)


def test_no_false_period_doubling_next_to_a_grazing_with_the_fd_map() -> None:
    """A harmonically forced oscillator (m = k = 1, c = 0.1, Omega = 0.8) under a stiff
    wall (Kelvin-Voigt, 1e6, restitution 0.8) at d = 0.5: its orbit without impacts has the
    multipliers 0.0066 +- 0.675i for every forcing below the grazing one, F_g = d |k - m
    Omega^2 + i c Omega|, so it cannot double its period. With the finite-difference map
    the runs perturbed next to the grazing touched the wall where the base run did not,
    and a period doubling was reported at F_g (1 - 9.5e-6) with a multiplier of -104; now
    (the map's step cut where its runs do not make the base run's contacts, and a located
    sign change kept only where it is a zero) the grazing is the first special point,
    within 1e-6 of F_g."""
    from braidsim.continuation import ModelSystem
    from braidsim.core import ImpactOscillator, KelvinVoigtContact

    m, k, c, w, d = 1.0, 1.0, 0.1, 0.8, 0.5
    f_g = d * abs(complex(k - m * w * w, c * w))
    law = KelvinVoigtContact.for_restitution(1e6, 0.8, m, allow_tension=True)
    s = ModelSystem(ImpactOscillator(m, k, c, 0.9 * f_g, w, 0.0, math.inf, d, law), length_scale=d)
    o = seed_orbit(s, {}, 1, transient_cycles=200, method="fd")
    br = continue_orbit(
        s,
        o,
        "force_amplitude",
        1.2 * f_g,
        method="fd",
        switch=False,
        max_points=30,
        step=0.02,
        max_step=0.05,
    )
    assert br.special and br.special[0].type == "grazing"
    assert br.special[0].value == pytest.approx(f_g, rel=1e-6)
    assert all(s.type != "period_doubling" for s in br.special)
    # (an orbit closer to the wall than the map's smallest step, 1e-7 of the length scale,
    # straddles it under every perturbation: its fd multipliers are not reliable, and the
    # last one before the grazing here, 7e-8 m from the wall, shows 154)
    below = [p for p in br.points if p.values["force_amplitude"] < f_g and p.profile.min_gap > 1e-6]
    assert len(below) >= 10
    assert all(np.abs(p.multipliers).max() < 0.676 and p.reliable for p in below)
    # ... and says so: the orbits whose multipliers are off are flagged
    for p in br.points:
        if p.values["force_amplitude"] < f_g and np.abs(p.multipliers).max() > 0.676:
            assert not p.reliable
    assert any(not p.reliable for p in br.points)


def test_a_seed_far_from_the_simulated_steady_state_is_refused(system) -> None:
    """docs/continuation.md: a steady state that is not near a period-k orbit is exit code 1
    (ContinuationError). At h_a = 0.12 mm the run from the scenario's start does not repeat
    within 12 cycles; Newton's method still converged from it to an unstable period-1 orbit
    (|mu| = 4.2) 3.2 scales away, which was returned; the period-3 orbit the run hovers near
    (0.04 scales) is found."""
    with pytest.raises(ContinuationError, match=r"not near a period-1 orbit .* unstable one"):
        seed_orbit(system, {HA: 0.12e-3}, 1, method="fd")
    o3 = seed_orbit(system, {HA: 0.12e-3}, 3, method="fd")
    assert o3.period == 3


@pytest.mark.parametrize("max_step", [0.05, 0.1])
def test_grazing_from_the_impacting_side_is_where_the_impact_vanishes(max_step: float) -> None:
    """The forced oscillator's impacting orbit continued down in F towards the grazing of
    its orbit without impacts, F_g = d |k - m Omega^2 + i c Omega| (closed form, any wall):
    the grazing is placed where the impact's depth extrapolates to zero, within 1e-6 of F_g
    with the exact map (it was placed where Newton's method first failed on the stiff
    wall's shallow impacts, 5.8e-4 and 1.3e-2 beyond F_g for these two step sizes)."""
    from braidsim.continuation import ModelSystem
    from braidsim.core import ImpactOscillator, KelvinVoigtContact

    m, k, c, w, d = 1.0, 1.0, 0.1, 0.8, 0.5
    f_g = d * abs(complex(k - m * w * w, c * w))
    law = KelvinVoigtContact.for_restitution(1e6, 0.8, m, allow_tension=True)
    s = ModelSystem(ImpactOscillator(m, k, c, 2 * f_g, w, 0.0, math.inf, d, law), length_scale=d)
    o = seed_orbit(s, {}, 1, transient_cycles=200, method="exact")
    assert o.profile.impacts == 1
    br = continue_orbit(
        s,
        o,
        "force_amplitude",
        0.9 * f_g,
        method="exact",
        switch=False,
        max_points=150,
        step=0.02,
        max_step=max_step,
    )
    (g,) = [sp for sp in br.special if sp.type == "grazing"]
    assert g.value == pytest.approx(f_g, rel=1e-6)


def test_a_periodic_map_run_that_fails_says_why_and_what_to_change(system) -> None:
    """A run of the periodic map out of its step budget (a continuation.period of 100000
    forcing periods spends the map's 1e7 steps at t = 232 s) said only "the integrator
    stopped with status 3"."""
    from braidsim.continuation.fdmap import advance
    from braidsim.errors import SimulationError

    prep = system.prepare({HA: 0.1e-3})
    prep = dataclasses.replace(prep, options=prep.options._replace(max_steps=50))
    with pytest.raises(SimulationError) as info:
        advance(prep, 0.0, 100 * prep.period, [0.0001, 0.0])
    text = str(info.value)
    assert "status" not in text, text
    assert re.search(r"step budget of 50 steps was spent at t = .* s .*continuation\.period", text)


def test_newton_halves_a_step_that_leaves_the_maps_domain() -> None:
    """G(u) = ln(u / 0.01) from u = 1: the full Newton step lands at u = -3.6, where the
    map refuses (as a latched speed pushed through 0 is refused); the step is halved until
    the iterate is back in the domain, and Newton's method converges to u = 0.01."""
    from braidsim.continuation.orbit import DOMAIN_HALVINGS, OutOfDomain, newton

    calls: list[float] = []

    def F(U: np.ndarray):
        calls.append(float(U[0]))
        if U[0] <= 0.0:
            raise OutOfDomain("u must be > 0")
        return np.array([math.log(U[0] / 0.01)]), np.array([[1.0 / U[0]]]), None

    U, res, _, _ = newton(F, np.array([1.0]), tol=1e-12, max_iter=20)
    assert U[0] == pytest.approx(0.01, rel=1e-12) and res < 1e-12
    assert calls[1] == pytest.approx(1.0 - math.log(100.0))  # the full step, refused
    # halved three times to u = 0.42, then twice more from there
    assert sum(c <= 0.0 for c in calls) == 5
    assert DOMAIN_HALVINGS >= 3
    # a map defined at its start only: the refusal itself, after the halvings
    calls.clear()

    def only_at_start(U: np.ndarray):
        return F(U if U[0] == 1.0 else np.zeros(1))

    with pytest.raises(OutOfDomain):
        newton(only_at_start, np.array([1.0]), tol=1e-12)
    assert len(calls) == 2 + DOMAIN_HALVINGS
