"""Design studies: speed profiles (mean held, derivatives, limits), the exact reduction to
carrier classes, the optimiser's constraints, Morris elementary effects against a closed form,
speed-limit formulas, the spec parser."""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import braidsim
from braidsim.design.drive import Drive, DriveModel
from braidsim.design.evaluate import (
    carrier_classes,
    evaluate,
    machine_for,
    objective_ratio,
    spearman,
)
from braidsim.design.optimise import (
    CONSTRAINTS,
    OptimizerOptions,
    ProfileConstraints,
    optimise_profile,
)
from braidsim.design.profiles import Limits, ProfileFamily, SpeedProfile, limit_margins
from braidsim.design.report import to_toml
from braidsim.design.robust import (
    DEFAULT_TOLERANCES,
    RobustObjective,
    draw_samples,
    improvement,
)
from braidsim.design.sensitivity import (
    Lever,
    elementary_effects,
    make_levers,
    morris,
    morris_design,
)
from braidsim.design.spec import parse_design_spec
from braidsim.design.speed_limits import chatter_speed, first_impact_speed
from braidsim.errors import InputError
from braidsim.machine.run import plan_transfers

ROOT = Path(__file__).resolve().parents[2]
MACHINE16 = ROOT / "examples" / "machine16.toml"


def base16() -> dict[str, Any]:
    return tomllib.loads(MACHINE16.read_text())


def two_carriers(duration: float = 0.6, h_a: float = 0.0) -> dict[str, Any]:
    """The 8-gear machine with one carrier of each group (two classes)."""
    return {
        "scenario": "paper-3.2",
        "duration": duration,
        "overrides": {"track.vibration_amplitude": h_a},
        "machine": {"horn_gears": 8, "loading": {"A": [0], "B": [1]}, "speed": "120 rpm"},
    }


def random_params(fam: ProfileFamily, rng: np.random.Generator) -> np.ndarray:
    b = np.array(fam.bounds(Limits()))
    while True:
        x = b[:, 0] + rng.random(b.shape[0]) * (b[:, 1] - b[:, 0])
        if fam.profile(x).fit_margin() >= 0.0:
            return x


# ---------------------------------------------------------------------------- profiles


@pytest.mark.parametrize("family,K", [("dip", 0), ("fourier", 3), ("dip+fourier", 2)])
def test_profile_mean_is_one_and_derivatives_match(family: str, K: int) -> None:
    """The smooth profile's mean over a cycle is 1 (Simpson on 2^16 intervals, exact to
    ~1e-12 except at the ramps' kinks in f''), and f', f'' agree with central differences."""
    fam = ProfileFamily(family, K)
    rng = np.random.default_rng(7)
    for _ in range(5):
        pr = fam.profile(random_params(fam, rng))
        n = 2**16
        ph = np.linspace(0.0, 1.0, n + 1)
        f, _, _ = pr.evaluate(ph)
        simpson = (f[0] + f[-1] + 4 * f[1:-1:2].sum() + 2 * f[2:-1:2].sum()) / (3 * n)
        assert simpson == pytest.approx(1.0, abs=1e-9)
        h = 1e-6
        x = rng.random(200)
        fp, _, _ = pr.evaluate(x + h)
        fm, _, _ = pr.evaluate(x - h)
        f0, g1, g2 = pr.evaluate(x)
        np.testing.assert_allclose(g1, (fp - fm) / (2 * h), rtol=1e-5, atol=1e-4)
        # f'' jumps at the ramp ends (cubic ramps): compare away from them
        corners = pr.corners()
        far = np.array(
            [np.min(np.abs(((xi - corners + 0.5) % 1.0) - 0.5), initial=1.0) > 1e-4 for xi in x]
        )
        np.testing.assert_allclose(
            g2[far], (fp - 2 * f0 + fm)[far] / h**2, rtol=1e-3, atol=0.5 + 1e-3 * np.abs(g2).max()
        )


def test_dip_extremes_match_closed_forms() -> None:
    """For a cubic ramp of width w and height H - L: max|f'| = 1.5 (H - L)/w and
    max|f''| = 6 (H - L)/w^2 (per unit phase); limit_margins finds them."""
    pr = ProfileFamily("dip").profile([0.4, -0.05, 0.5, 0.08, 0.12])
    H = pr.fast_level()
    gbar = 0.5 + 0.5 * (0.08 + 0.12)
    assert H == pytest.approx((1 - 0.4 * gbar) / (1 - gbar), rel=1e-15)
    w, Tc = 4 * math.pi, 0.0625
    m = limit_margins(pr, Limits(), w, Tc)
    assert m["acceleration_max"] == pytest.approx(1.5 * (H - 0.4) / 0.08 * w / Tc, rel=1e-6)
    assert m["jerk_max"] == pytest.approx(6 * (H - 0.4) / 0.08**2 * w / Tc**2, rel=1e-6)
    assert m["speed_min"] == pytest.approx(0.4, rel=1e-12)
    assert m["speed_max"] == pytest.approx(H, rel=1e-12)


def test_no_dip_is_the_constant_profile() -> None:
    fam = ProfileFamily("dip")
    for x in (fam.constant(), [1.0, -0.3, 0.2, 0.05, 0.4]):
        pr = fam.profile(x)
        assert pr.is_constant
        assert pr.table() == ([0.0, 1.0], [1.0, 1.0])
        f, d1, d2 = pr.evaluate(np.linspace(0, 1, 101))
        assert np.all(f == 1.0) and np.all(d1 == 0.0) and np.all(d2 == 0.0)


def test_table_is_close_to_the_smooth_profile() -> None:
    """Linear interpolation over n segments of a ramp of width w errs by at most
    h^2/8 max|f''| = 6 (H - L) / (8 n^2); the rescaling to mean 1 adds about as much."""
    for n in (8, 32):
        pr = ProfileFamily("dip", ramp_nodes=n).profile([0.35, -0.1, 0.55, 0.15, 0.2])
        ph, fa = pr.table()
        assert ph[0] == 0.0 and ph[-1] == 1.0 and fa[0] == fa[-1]
        assert np.all(np.diff(ph) > 0)
        bound = 6.0 * (pr.fast_level() - 0.35) / (8.0 * n * n)
        assert 0.25 * bound < pr.table_error() < 2.0 * bound


def test_limits_reject_bad_values() -> None:
    with pytest.raises(InputError, match=r"design\.limits\.min_speed"):
        Limits(min_speed=0.0)
    with pytest.raises(InputError, match=r"design\.limits\.max_speed"):
        Limits(max_speed=1.0)
    with pytest.raises(InputError, match=r"design\.limits\.max_jerk"):
        Limits(max_jerk=-1.0)
    with pytest.raises(InputError, match=r"design\.profile\.family"):
        ProfileFamily("spline")
    with pytest.raises(InputError, match=r"design\.profile\.harmonics"):
        ProfileFamily("fourier", 0)


# ---------------------------------------------------------------------------- the machine


def test_mean_speed_is_held_and_transfers_stay_at_slot_meetings() -> None:
    """With a deep dip the gears still turn through exactly one transfer cycle per cycle time,
    so every transfer happens at a multiple of T_c = Theta_c / omega_mean, as at constant speed."""
    base = base16()
    pr = ProfileFamily("dip").profile([0.3, 0.05, 0.45, 0.2, 0.2])
    const = machine_for(base, MACHINE16)
    spec = machine_for(base, MACHINE16, pr)
    Tc = const.cycle_time
    assert spec.cycle_time == const.cycle_time
    k = np.arange(1, 33)
    law = plan_transfers(spec, 2.0)[0]
    _, ang = law.rotation(k * Tc)
    theta_c = spec.geometry.transfer_cycle * spec.geometry.quantum
    np.testing.assert_allclose(ang, k * theta_c, rtol=1e-12)
    assert law.mean == pytest.approx(const.mean_speed, rel=1e-12)
    # (1.99 s: a transfer falls on 2 s, where the inverted time may land 1e-15 s early)
    _, p0 = plan_transfers(const, 1.99)
    _, p1 = plan_transfers(spec, 1.99)
    for a, b in zip(p0, p1, strict=True):
        np.testing.assert_allclose(b.times, a.times, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.times / Tc, np.round(a.times / Tc), atol=1e-9)


def test_no_dip_returns_the_constant_speed_result() -> None:
    """level = 1 is the constant machine, bit for bit; a flat speed table through the kernel's
    profile path gives the same impacts to 1e-8 s (the two-DOF runs integrate the slot wall's
    position from the table: rounding differences, no more)."""
    base = two_carriers(0.6)
    const = evaluate(base, None, None)
    flat = evaluate(base, None, ProfileFamily("dip").profile([1.0, -0.2, 0.3, 0.1, 0.1]))
    assert flat.metrics == const.metrics
    assert const.metrics["impacts"] > 0
    table = dict(base)
    table["machine"] = {
        **base["machine"],
        "speed_profile": {"phase": [0, 0.3, 1], "factor": [1, 1, 1]},
    }
    from braidsim.machine import parse_machine_spec, run_machine

    run = run_machine(parse_machine_spec(table), workers=1, frames=0)
    a = run.impacts
    b = const.run.impacts if const.run is not None else None
    assert b is not None and len(a) == len(b)
    np.testing.assert_allclose(a["t"], b["t"], rtol=0, atol=1e-8)
    np.testing.assert_allclose(a["peak_force"], b["peak_force"], rtol=1e-7, atol=1e-3)


def test_carrier_classes_reproduce_the_full_machine_exactly() -> None:
    """16 carriers fall into 4 classes with the same crossing angles; one run per class,
    weighted, gives the full machine's totals (vibration on, a dip profile)."""
    base = base16()
    pr = ProfileFamily("dip").profile([0.45, -0.02, 0.58, 0.04, 0.04])
    spec = machine_for(base, MACHINE16, pr)
    classes = carrier_classes(spec, 0.5)
    assert sorted(c.weight for c in classes) == [4, 4, 4, 4]
    part = evaluate(base, MACHINE16, pr, cycles=8)
    full = evaluate(base, MACHINE16, pr, cycles=8, full=True)
    for k in ("peak_force", "impact_energy", "impacts", "mean_peak_force", "dissipated_power"):
        assert part.metrics[k] == pytest.approx(full.metrics[k], rel=1e-12), k


def test_optimiser_respects_limits_and_never_loses_to_constant_speed() -> None:
    """Tight limits, a tiny budget: every simulated candidate satisfies the limits, the result
    too, and it is no worse than constant speed on the proxy."""
    base = two_carriers(1.0)
    limits = Limits(min_speed=0.5, max_speed=1.6, max_acceleration=1500.0, max_jerk=1.0e6)
    res = optimise_profile(
        base,
        None,
        ProfileFamily("dip"),
        limits,
        "peak_force",
        OptimizerOptions(maxiter=2, popsize=3, seed=3, cycles=6),
    )
    spec = machine_for(base, None)
    assert len(res.candidates) == res.evaluations >= 10
    for x, _ in res.candidates:
        m = limit_margins(res.family.profile(x), limits, spec.mean_speed, spec.cycle_time)
        assert min(m[k] for k in ("fit", "min_speed", "max_speed", "acceleration", "jerk")) >= 0
    assert min(res.margins[k] for k in ("min_speed", "max_speed", "acceleration", "jerk")) >= 0
    assert res.value <= res.baseline_value
    assert res.value == min(v for _, v in res.candidates)
    # the mean speed of the kernel's table is the machine's
    law = plan_transfers(machine_for(base, None, res.profile), 1.0)[0]
    assert law.mean == pytest.approx(spec.mean_speed, rel=1e-12)
    # same seed, same result
    again = optimise_profile(
        base,
        None,
        ProfileFamily("dip"),
        limits,
        "peak_force",
        OptimizerOptions(maxiter=2, popsize=3, seed=3, cycles=6),
    )
    np.testing.assert_array_equal(again.x, res.x)
    # the summary says whether the search stopped still improving (its own history)
    d = res.to_dict()
    assert d["generations"] == len(res.history) == 2
    k, gain = res.recent_gain()
    assert d["recent_generations"] == k == 1
    assert gain == pytest.approx(1.0 - res.history[-1]["best"] / res.history[-2]["best"])
    assert d["still_improving"] == (gain > 0.0)


def test_still_improving_reads_the_last_quarter_of_the_generations() -> None:
    """recent_gain compares the best value now with the one k = generations // 4 generations
    before; still_improving needs the cap reached and a fall over those generations."""
    res = optimise_profile(
        two_carriers(1.0),
        None,
        ProfileFamily("dip"),
        Limits(),
        "peak_force",
        OptimizerOptions(maxiter=1, popsize=2, seed=1, cycles=2),
    )
    opts = dataclasses.replace(res.options, maxiter=8)

    def rows(best: list[float]) -> list[dict[str, float]]:
        return [{"generation": float(i), "best": b} for i, b in enumerate(best)]

    falling = dataclasses.replace(res, options=opts, history=rows([1.0] * 5 + [0.9, 0.9, 0.8]))
    assert falling.recent_gain() == (2, pytest.approx(1.0 - 0.8 / 0.9))
    assert falling.still_improving()
    # flat over the last two generations (the fall before them does not count)
    flat = dataclasses.replace(res, options=opts, history=rows([1.0] * 5 + [0.8, 0.8, 0.8]))
    assert flat.recent_gain() == (2, 0.0)
    assert not flat.still_improving()
    # stopped before the cap (SciPy's spread test, tol > 0): not "still improving"
    early = dataclasses.replace(res, options=opts, history=rows([1.0, 0.9, 0.8]))
    assert not early.still_improving()
    assert dataclasses.replace(res, history=rows([1.0])).recent_gain()[0] == 0


# ---------------------------------------------------------------------------- sensitivity


def test_morris_effects_of_a_linear_function_are_its_coefficients() -> None:
    """For Y = sum c_i x_i every elementary effect is c_i: mu* = |c_i|, sigma = 0, and the
    ranking follows |c_i| (Morris 1991)."""
    c = np.array([0.3, -2.0, 1.0, 0.0])
    _, _, ee, mu_star, mu, sigma = elementary_effects(lambda p: p @ c, 4, 6, 4, seed=11)
    np.testing.assert_allclose(ee, np.broadcast_to(c, ee.shape), atol=1e-12)
    np.testing.assert_allclose(mu_star, np.abs(c), atol=1e-12)
    np.testing.assert_allclose(mu, c, atol=1e-12)
    np.testing.assert_allclose(sigma, 0.0, atol=1e-12)
    # an interaction shows in sigma: Y = x0 x1
    *_, s2 = elementary_effects(lambda p: p[:, 0] * p[:, 1], 2, 8, 4, seed=11)
    assert np.all(s2 > 0.05)


def test_morris_design_moves_one_lever_per_step() -> None:
    pts, moved, steps = morris_design(5, 4, 4, seed=3)
    assert pts.shape == (4 * 6, 5)
    assert np.all((pts >= 0) & (pts <= 1))
    for r in range(4):
        assert sorted(moved[r]) == list(range(5))
        for j in range(5):
            d = pts[r * 6 + j + 1] - pts[r * 6 + j]
            assert np.count_nonzero(d) == 1
            assert d[moved[r, j]] == pytest.approx(steps[r, j])
            assert abs(steps[r, j]) == pytest.approx(4 / 6)
    again = morris_design(5, 4, 4, seed=3)[0]
    np.testing.assert_array_equal(again, pts)
    assert not np.array_equal(morris_design(5, 4, 4, seed=4)[0], pts)


def test_sensitivity_ranking_is_reproducible_with_a_seed() -> None:
    """The simulated Morris study: the same seed gives the same runs, effects and ranking."""
    base = two_carriers(0.6, h_a=2e-5)
    sc = machine_for(base, None).scenario
    levers = make_levers(sc, ["track.clearance", "contact.track.restitution", "carrier.mass"])
    a = morris(base, None, levers, "peak_force", trajectories=2, levels=4, seed=5, cycles=6)
    b = morris(base, None, levers, "peak_force", trajectories=2, levels=4, seed=5, cycles=6)
    assert a.ranking == b.ranking
    np.testing.assert_array_equal(a.values, b.values)
    np.testing.assert_array_equal(a.mu_star, b.mu_star)
    # the clearance sets the gap-crossing energy (v^2 ~ eps_g): it leads
    assert a.ranking[0] == "track.clearance"
    c = morris(base, None, levers, "peak_force", trajectories=2, levels=4, seed=6, cycles=6)
    assert not np.array_equal(c.points, a.points)


def test_levers_ranges_and_errors() -> None:
    sc = braidsim.load_scenario("paper-3.2")
    lv = make_levers(sc, ["track.clearance"], 0.5, {})[0]
    assert (lv.low, lv.nominal, lv.high) == pytest.approx((1.5e-3, 3e-3, 4.5e-3))
    lv = make_levers(sc, ["track.clearance"], 0.5, {"track.clearance": ["2 mm", "5 mm"]})[0]
    assert (lv.low, lv.high) == pytest.approx((2e-3, 5e-3))
    assert isinstance(lv, Lever) and lv.label == "clearance eps_g [mm]"
    with pytest.raises(InputError, match=r"design\.sensitivity\.levers"):
        make_levers(sc, ["track.clearence"])
    with pytest.raises(InputError, match=r"design\.sensitivity\.ranges\.track\.clearance"):
        make_levers(sc, ["track.clearance"], 0.5, {"track.clearance": ["4 mm", "5 mm"]})
    with pytest.raises(InputError, match=r"design\.sensitivity\.ranges\.carrier\.mass"):
        make_levers(sc, ["track.clearance"], 0.5, {"carrier.mass": [1, 2]})


def test_spearman() -> None:
    assert spearman(np.array([1.0, 2, 3, 4]), np.array([10.0, 20, 25, 100])) == pytest.approx(1)
    assert spearman(np.array([1.0, 2, 3]), np.array([3.0, 2, 1])) == pytest.approx(-1)


# ---------------------------------------------------------------------------- speed limits


def test_chatter_speed_against_model_notes_section_7() -> None:
    """paper-3.3: a_p = 13.9 m/s^2 < h_a omega_h^2 = 17.1 m/s^2 at 4 pi (it chatters) and
    44.7 m/s^2 at 8 pi (it stays): the chatter speed lies between; without vibration or with
    the yarn load alone above h_a omega_h^2 there is none."""
    sc = braidsim.load_scenario("paper-3.3")
    w = chatter_speed(sc)
    m, rc = sc["carrier.mass"], sc["carrier.turning_radius"]
    a_p = (5.0 * math.cos(math.pi / 6) + m * rc * w**2) / m
    assert a_p == pytest.approx(1.2e-4 * (120 * math.pi) ** 2, rel=1e-12)
    assert 4 * math.pi < w < 8 * math.pi
    assert chatter_speed(sc.with_overrides({"track.vibration_amplitude": 0.0})) == 0.0
    assert chatter_speed(sc.with_overrides({"track.vibration_amplitude": 2e-5})) == 0.0


def test_first_impact_speed_is_the_energy_balance() -> None:
    """At omega = 4 pi: F = T1 cos(phi) + m r_c omega^2 = 16.65 N, friction mu1 (m g - T2),
    v = sqrt(v_c^2 + 2 (F - f) eps_g / m) = 0.2808 m/s."""
    sc = braidsim.load_scenario("paper-3.2")
    F = 5 * math.cos(math.pi / 6) + 1.2 * 0.065 * (4 * math.pi) ** 2
    assert F == pytest.approx(16.65, abs=0.01)
    f = 0.1 * (1.2 * 9.81 - 3.0)
    v = math.sqrt(0.002**2 + 2 * (F - f) * 0.003 / 1.2)
    assert first_impact_speed(sc, 4 * math.pi) == pytest.approx(v, rel=1e-12)
    assert v == pytest.approx(0.2808, abs=1e-4)


# ---------------------------------------------------------------------------- spec


def spec_table(**design: Any) -> dict[str, Any]:
    return {"name": "t", "machine_spec": str(MACHINE16), "design": design}


def test_the_held_out_draw_has_a_seed_of_its_own() -> None:
    """design.robust.check_seed draws the held-out sets anew with the optimiser's unchanged
    (default seed + 1, as before), so that another draw checks the same optimum; the
    optimiser's own seed is refused (its own sets would flatter it)."""
    from braidsim.design.robust import draw_samples, robust_sets

    base = parse_design_spec(spec_table())
    other = parse_design_spec(spec_table(robust={"check_seed": 5}))
    sc = base.machine.scenario
    assert base.robust.held_out_seed == base.robust.seed + 1
    assert other.robust.held_out_seed == 5
    assert other.robust.to_dict()["check_seed"] == 5
    opt0, check0 = robust_sets(sc, base.robust)
    opt5, check5 = robust_sets(sc, other.robust)
    assert opt5 == opt0 and check5 != check0
    assert check5 == draw_samples(sc, other.robust.tolerances, len(check5), 5)
    with pytest.raises(InputError, match=r"^design\.robust\.check_seed: 1 is the optimiser's"):
        parse_design_spec(spec_table(robust={"check_seed": 1}))


def test_an_optimisation_too_large_is_refused_up_front(monkeypatch) -> None:
    """maxiter 10000 and popsize 1000 over 10 parameter sets are at most 4e8 machine runs
    of the default profile (4 parameters): refused against BRAIDSIM_MAX_RUNS, with the
    estimate, before any run (the study started and ran on for hours); the defaults pass."""
    import time

    c0 = time.process_time()
    big = spec_table(optimizer={"maxiter": 10000, "popsize": 1000}, robust={"samples": 10})
    with pytest.raises(
        InputError,
        match=r"^design\.optimizer: \(maxiter 10000 \+ 1\) x popsize 1000 x \d+ profile "
        r"parameters x 10 parameter sets \(design\.robust\.samples\), at most: .* runs "
        r"exceeds the limit of 1e\+07 runs; .*BRAIDSIM_MAX_RUNS=N$",
    ):
        parse_design_spec(big)
    assert time.process_time() - c0 < 10.0
    monkeypatch.setenv("BRAIDSIM_MAX_RUNS", "1e12")
    assert parse_design_spec(big).optimizer.maxiter == 10000


def test_design_spec_defaults_and_errors(tmp_path: Path) -> None:
    s = parse_design_spec(spec_table())
    assert s.objective == "score" and s.pair == "both" and s.family.name == "dip"
    assert s.limits == Limits()
    assert s.sensitivity.levers[0].key == "track.clearance"
    s = parse_design_spec(spec_table(limits={"max_acceleration": "2 krad/s^2"}))
    assert s.limits.max_acceleration == pytest.approx(2000.0)
    # 0 workers: all cores, as for the other commands with local workers
    assert parse_design_spec(spec_table(workers=0)).workers == min(os.cpu_count() or 1, 256)
    cases = [
        (spec_table(workers=-1), "design.workers"),
        (spec_table(objectiv="peak_force"), "design.objectiv: unknown key"),
        (spec_table(objective="loudness"), "design.objective"),
        (spec_table(pair="carrier"), "design.pair"),
        (
            spec_table(drive={"max_torque": "-150 N m"}),
            r"^design\.drive\.max_torque: -150 N m is out of range; allowed > 0 N m$",
        ),
        (
            spec_table(drive={"tensioner_mass": "-5 g"}),
            r"^design\.drive\.tensioner_mass: -0\.005 kg is out of range; allowed >= 0 kg$",
        ),
        (spec_table(drive={"gear_inertia": "3 kg"}), "design.drive.gear_inertia"),
        (spec_table(robust={"statistic": "median"}), "design.robust.statistic"),
        (
            spec_table(robust={"tolerances": {"contact.track.restitution": [0.5, 2.0]}}),
            r"design\.robust\.tolerances\.contact\.track\.restitution: 1\.1",
        ),
        (spec_table(levers={"effort": {"paint": 1}}), "design.levers.effort.paint"),
        (
            spec_table(levers={"effort": {"profile": 0}}),
            r"^design\.levers\.effort\.profile: 0 is out of range; allowed > 0 and <= 100$",
        ),
        (
            spec_table(optimizer={"maxiter": -1}),
            r"^design\.optimizer\.maxiter: -1 is out of range; allowed an integer from 0 to",
        ),
        (
            spec_table(optimizer={"maxiter": "many"}),
            r"^design\.optimizer\.maxiter: 'many' is not an integer; allowed an integer from",
        ),
        (
            spec_table(optimizer={"popsize": 2.5}),
            r"^design\.optimizer\.popsize: 2\.5 is not an integer; allowed an integer from",
        ),
        (spec_table(limits={"max_jerk": "3 m"}), "design.limits.max_jerk"),
        (spec_table(speed_limit={"threshold": "3 W"}), "design.speed_limit.threshold"),
        ({"name": "t", "design": {}}, "machine_spec: missing"),
        ({"machine_spec": str(tmp_path / "no.toml")}, "machine_spec"),
        ({"machine_spec": str(MACHINE16), "scenario": "paper-3.1"}, "scenario: given together"),
    ]
    for table, msg in cases:
        with pytest.raises(InputError, match=msg):
            parse_design_spec(table)
    # a study that would fail half-way stops before it starts
    inline = {"scenario": "paper-3.4b", "machine": {"horn_gears": 8}}
    with pytest.raises(InputError, match=r"design\.speed_limit: the machine cannot run"):
        parse_design_spec(inline)
    assert parse_design_spec({**inline, "design": {"speed_limit": {"enabled": False}}})
    radius = spec_table(sensitivity={"levers": ["carrier.turning_radius"]})
    with pytest.raises(InputError, match=r"carrier\.turning_radius = 0\.0325 is not allowed"):
        parse_design_spec(radius)
    prof = tmp_path / "m.toml"
    prof.write_text(
        MACHINE16.read_text()
        + "\n[machine.speed_profile]\nphase = [0, 0.5, 1]\nfactor = [1, 1.2, 1]\n"
    )
    with pytest.raises(InputError, match=r"machine\.speed_profile: set by the design study"):
        parse_design_spec({"machine_spec": str(prof)})


def test_tolerances_the_machine_refuses_are_refused_before_the_study() -> None:
    """A tolerance on a key the machine sets, a range whose end the machine refuses, or
    drawn sets it refuses stop the spec with one line naming design.robust.tolerances (they
    were accepted and failed half-way, naming machine.speed or the pitch radius)."""

    def tol(**tols: list[float]) -> dict[str, Any]:
        return spec_table(robust={"tolerances": tols})

    cases = [
        (
            tol(**{"horn_gear.angular_velocity": [0.8, 1.2]}),
            r"^design\.robust\.tolerances\.horn_gear\.angular_velocity: set by the machine "
            r"\(machine\.speed\).*; allowed a scenario key the machine does not set",
        ),
        (
            tol(**{"carrier.turning_radius": [0.8, 1.2]}),
            r"^design\.robust\.tolerances\.carrier\.turning_radius: set by the machine "
            r"\(machine\.pitch_radius\)",
        ),
        (
            tol(**{"initial.vx": [0.0, 1.0]}),
            r"^design\.robust\.tolerances\.initial\.vx: set by the machine "
            r'\(machine\.start = "rest"\)',
        ),
        (
            tol(**{"track.clearance": [1e-5, 1e-5]}),
            r"^design\.robust\.tolerances\.track\.clearance: x \[1e-05, 1e-05\] gives "
            r"track\.clearance = 3e-08 m at its low end, which this machine refuses "
            r"\(track\.clearance: .*allowed >= [0-9.]+ mm\); allowed a range",
        ),
        # each end passes alone (a clearance just above the resting deflection; a higher
        # tension on the nominal clearance), not together: a drawn set presses the carrier
        # through the clearance
        (
            tol(**{"track.clearance": [3e-4, 3e-4], "yarn.tension_horizontal": [1.0, 2.0]}),
            r"^design\.robust\.tolerances: parameter set \d+ of design\.robust\.samples "
            r"\(.*yarn\.tension_horizontal = .*\) is refused by this machine",
        ),
    ]
    for table, msg in cases:
        with pytest.raises(InputError, match=msg):
            parse_design_spec(table)
    # the narrow clearance with the default tolerances of the others is allowed
    assert parse_design_spec(tol(**{"track.clearance": [3e-4, 3e-4]}))


def test_spec_docstring_states_the_measured_drag_torque() -> None:
    """The spec format's drag_torque is the default the study measures for
    examples/design16.toml ((dissipated + friction power) / mean speed of the constant-speed
    proxy run, as run_design builds the drive model); it said 1.8 N m."""
    import re

    import braidsim.design.spec as ds

    m = re.search(r'drag_torque = "([0-9.]+) N m" +# default: measured', ds.__doc__ or "")
    assert m is not None
    spec = parse_design_spec(
        tomllib.loads((ROOT / "examples" / "design16.toml").read_text()),
        ROOT / "examples" / "design16.toml",
    )
    assert spec.drive.drag_torque is None  # the default: measured
    b = evaluate(spec.machine_table, spec.machine_path, None, cycles=spec.optimizer.cycles)
    drag = (b.metrics["dissipated_power"] + b.metrics["friction_power"]) / spec.machine.mean_speed
    assert float(m.group(1)) == pytest.approx(drag, rel=0.005)


def test_toml_writer_round_trips() -> None:
    t = {
        "name": 'a "quoted" name',
        "n": 3,
        "x": 0.1,
        "flag": True,
        "overrides": {"track.vibration_amplitude": "0.02 mm"},
        "machine": {
            "speed": "120 rpm",
            "speed_profile": {"phase": [0.0, 1.0], "factor": [1.0, 1.0]},
        },
    }
    assert tomllib.loads(to_toml(t)) == t


# ---------------------------------------------------------------------------- both pairs


def test_objective_includes_the_slot_contact() -> None:
    """The two-DOF runs reduce the slot contact too: the combined figures are the sums (the
    peak the larger) of the pairs', a profile that drives the carriers through the slot walls
    raises the slot figures, and the objective of the slot pair (or both) sees it where the
    track pair alone would not."""
    base = two_carriers(0.5, h_a=2e-5)
    const = evaluate(base, None, None, cycles=8).metrics
    dip = ProfileFamily("dip").profile([0.6, -0.3, 0.1, 0.3, 0.3])
    m = evaluate(base, None, dip, cycles=8).metrics
    for x in (const, m):
        assert x["slot.impacts"] > 0 and x["slot.peak_force"] > 0
        for k in ("impact_energy", "impacts", "noise"):
            assert x[k] == pytest.approx(x[f"track.{k}"] + x[f"slot.{k}"], rel=1e-14)
        assert x["peak_force"] == max(x["track.peak_force"], x["slot.peak_force"])
    # the slot walls push the carrier through the speed changes: m r_c omega' on the slot
    assert m["slot.impact_energy"] > 2.0 * const["slot.impact_energy"]
    slot = objective_ratio(m, const, "impact_energy", "slot")
    assert slot == pytest.approx(m["slot.impact_energy"] / const["slot.impact_energy"])
    both = objective_ratio(m, const, "impact_energy", "both")
    track = objective_ratio(m, const, "impact_energy", "track")
    assert both != track
    e_t, e_s = const["track.impact_energy"], const["slot.impact_energy"]
    assert both == pytest.approx((track * e_t + slot * e_s) / (e_t + e_s), rel=1e-12)
    score = objective_ratio(m, const, "score", "slot")
    figs = ("peak_force", "impact_energy", "impacts", "noise")
    assert score == pytest.approx(
        np.mean([m[f"slot.{k}"] / const[f"slot.{k}"] for k in figs]), rel=1e-14
    )
    assert objective_ratio(const, const, "score", "both") == 1.0


def test_noise_proxy_is_the_sum_of_squared_peak_forces() -> None:
    """The noise figure of a run is sum F_peak^2 / T over its impact episodes, per pair,
    recomputed here from the single-carrier run with the same transfers."""
    import braidsim

    base = two_carriers(0.4)
    ev = evaluate(base, None, None, full=True)
    spec = machine_for(base, None)
    _, plans = plan_transfers(spec, 0.4)
    tot = {"track": 0.0, "slot": 0.0}
    for p in plans:
        sc = spec.scenario.with_overrides({"transfer.times": [float(t) for t in p.times]})
        r = braidsim.simulate(sc, duration=0.4, sample_interval=0.0)
        ep = r.impacts
        for pair in tot:
            sel = ep[(ep["pair"] == pair) & ~ep["initial"].astype(bool)]
            tot[pair] += float((sel["peak_force"] ** 2).sum())
    for pair in tot:
        assert tot[pair] > 0
        assert ev.metrics[f"{pair}.noise"] == pytest.approx(tot[pair] / 0.4, rel=1e-9)


# ---------------------------------------------------------------------------- the drive


def drive_model(**kw: Any) -> DriveModel:
    return DriveModel.build(Drive(**kw), 8, 0.065, 16, 1.2, 0.065, 4 * math.pi, 0.0625, 0.0)


def test_drive_figures_match_closed_forms() -> None:
    """Inertia: N rho pi t R^4 / 2 + n m r_c^2 + i^2 J_m. A harmonic profile f = 1 + a cos
    has tau = -J omega a (2 pi / T_c) sin: peak J omega a 2 pi / T_c, RMS that / sqrt 2; a
    dip's peak acceleration is 1.5 (H - L) / w (cubic ramp)."""
    dm = drive_model()
    R = 1.15 * 0.065
    jg = 0.5 * 7850 * math.pi * 0.025 * R**4
    assert dm.inertia["gears"] == pytest.approx(8 * jg, rel=1e-12)
    assert dm.inertia["carriers"] == pytest.approx(16 * 1.2 * 0.065**2, rel=1e-12)
    assert dm.inertia["motor"] == pytest.approx(100 * 2e-4, rel=1e-12)
    J, w, Tc, a = dm.inertia["total"], 4 * math.pi, 0.0625, 0.1
    fig = dm.figures(SpeedProfile("fourier", {"a1": a, "b1": 0.0}))
    peak = J * w * a * 2 * math.pi / Tc
    assert fig["peak_torque"] == pytest.approx(peak, rel=1e-6)
    assert fig["rms_torque"] == pytest.approx(peak / math.sqrt(2), rel=1e-9)
    assert fig["mean_power"] == pytest.approx(0.0, abs=1e-9 * peak * w)
    assert fig["max_speed"] == pytest.approx(1.1 * w, rel=1e-9)
    pr = SpeedProfile("dip", dict(level=0.7, start=-0.2, length=0.2, ramp_down=0.25, ramp_up=0.3))
    H = pr.fast_level()
    fig = dm.figures(pr)
    acc = w * 1.5 * (H - 0.7) / 0.25 / Tc
    assert fig["max_acceleration"] == pytest.approx(acc, rel=1e-9)
    assert fig["peak_torque"] == pytest.approx(J * acc, rel=1e-9)
    assert fig["yarn_tension_swing"] == pytest.approx(0.05 * 0.065 * (acc + (H * w) ** 2), rel=1e-9)
    const = dm.figures(None)
    assert const["peak_torque"] == 0.0 and const["yarn_tension_swing"] == pytest.approx(
        0.05 * 0.065 * w * w
    )


def test_optimiser_respects_the_drive_limits() -> None:
    """Every simulated candidate and the result lie within the torque, RMS torque, power,
    acceleration and jerk limits; the constraints are active (a share of the population
    breaks each limit and is never simulated)."""
    limits = Limits(max_acceleration=600.0, max_jerk=1.2e5)
    dm = DriveModel.build(
        Drive(max_torque=60.0, max_rms_torque=25.0, max_power=700.0),
        8,
        0.065,
        2,
        1.2,
        0.065,
        4 * math.pi,
        0.0625,
        0.0,
    )
    fam = ProfileFamily("dip")
    cons = ProfileConstraints(fam, limits, 4 * math.pi, 0.0625, dm)
    rng = np.random.default_rng(3)
    broken = np.zeros(len(CONSTRAINTS), dtype=bool)
    for _ in range(400):
        x = random_params(fam, rng)
        broken |= cons(x) < 0.0
    # each of the drive's limits is broken by some random profile (not vacuous)
    for name in ("acceleration", "jerk", "torque", "rms_torque", "power"):
        assert broken[CONSTRAINTS.index(name)], name
    res = optimise_profile(
        two_carriers(0.3),
        None,
        fam,
        limits,
        "impact_energy",
        OptimizerOptions(maxiter=3, popsize=4, seed=2, cycles=3),
        pair="track",
        drive=dm,
    )
    assert res.candidates, "nothing simulated"
    for x, _ in res.candidates:
        pr = fam.profile(x)
        assert np.all(cons(x) >= 0.0)
        f = dm.figures(pr)
        assert f["peak_torque"] <= 60.0 and f["rms_torque"] <= 25.0 and f["peak_power"] <= 700.0
        mg = limit_margins(pr, limits, 4 * math.pi, 0.0625)
        assert mg["acceleration_max"] <= 600.0 and mg["jerk_max"] <= 1.2e5
    assert all(v >= 0.0 for k, v in res.margins.items() if k.startswith("drive_"))


# ---------------------------------------------------------------------------- robust


def test_robust_objective_is_reproducible_with_a_seed() -> None:
    """The same seed draws the same parameter sets and gives the same robust objective, bit
    for bit; another seed other sets. Latin hypercube: one draw in each of n strata of every
    tolerance."""
    base = two_carriers(0.3, h_a=2e-5)
    sc = machine_for(base, None).scenario
    a = draw_samples(sc, DEFAULT_TOLERANCES, 6, 11)
    b = draw_samples(sc, DEFAULT_TOLERANCES, 6, 11)
    c = draw_samples(sc, DEFAULT_TOLERANCES, 6, 12)
    assert a == b and a != c
    for t in DEFAULT_TOLERANCES:
        v = np.array([s[t.key] for s in a])
        nom = float(sc[t.key]) if t.relative else 1.0
        u = (v / nom - t.low) / (t.high - t.low)
        assert sorted(np.floor(u * 6).astype(int).tolist()) == list(range(6))
    pr = ProfileFamily("dip").profile([0.8, -0.2, 0.2, 0.3, 0.3])
    r1 = RobustObjective(base, None, "score", "both", 3, a, "quantile", 0.8)
    r2 = RobustObjective(base, None, "score", "both", 3, b, "quantile", 0.8)
    v1, v2 = r1.ratios(pr), r2.ratios(pr)
    assert v1.tolist() == v2.tolist() and len(set(v1.tolist())) > 1
    assert r1(pr) == r2(pr) == pytest.approx(np.quantile(v1, 0.8), rel=1e-15)
    assert r1(None) == 1.0


def test_flat_profile_is_the_constant_speed_result_everywhere() -> None:
    """A profile with no dip (level 1, or zero harmonics) is constant speed: the same metrics,
    bit for bit, a robust ratio of exactly 1, zero improvement on every set, the drive's
    figures of constant speed; and an optimiser that finds nothing better returns it."""
    base = two_carriers(0.3)
    sets = draw_samples(machine_for(base, None).scenario, DEFAULT_TOLERANCES, 3, 5)
    for pr in (
        ProfileFamily("dip").profile([1.0, -0.3, 0.2, 0.2, 0.2]),
        ProfileFamily("fourier", 2).profile([0.0, 0.0, 0.0, 0.0]),
    ):
        assert pr.is_constant
        for s in sets:
            assert evaluate(base, None, pr, s, cycles=3).metrics == (
                evaluate(base, None, None, s, cycles=3).metrics
            )
        imp, _, _ = improvement(base, None, sets, "score", "both", 3, pr)
        assert imp.values.tolist() == [0.0, 0.0, 0.0]
        assert drive_model().figures(pr) == drive_model().figures(None)
    res = optimise_profile(
        base,
        None,
        ProfileFamily("dip"),
        Limits(max_acceleration=1.0, max_jerk=10.0),  # no dip fits: constant speed only
        "score",
        OptimizerOptions(maxiter=1, popsize=2, seed=1, cycles=2),
    )
    assert res.profile.is_constant and res.value == res.baseline_value == 1.0


def test_improvement_standard_errors_against_the_median_of_a_normal_sample() -> None:
    """The bootstrap standard error of the median of n normal values approaches the closed
    form sqrt(pi / 2) sigma / sqrt(n) (Kendall & Stuart); the estimate itself scatters by
    about n^(-1/4) relative (0.63-1.05 of it over 8 seeds at n = 2000), hence 25 %. That of
    the 5th percentile is larger (fewer values near it). Constant values have none."""
    from braidsim.design.robust import Improvement

    sigma, n = 0.02, 2000
    values = np.random.default_rng(11).normal(0.01, sigma, n)
    st = Improvement(values).stats()
    exact = math.sqrt(math.pi / 2.0) * sigma / math.sqrt(n)
    assert st["median_improvement_se"] == pytest.approx(exact, rel=0.25)
    assert st["p5_improvement_se"] > st["median_improvement_se"]
    assert Improvement(values).stats() == st  # seeded: the same errors again
    flat = Improvement(np.full(8, 0.003)).stats()
    assert flat["median_improvement_se"] == 0.0 and flat["p5_improvement_se"] == 0.0
