"""Forward sensitivities through impacts, against things no one here wrote: central finite
differences of the simulator itself at tight tolerance, the closed-form solution of a
forced linear oscillator (differentiated by the complex step), and the monodromy of a
resting-contact orbit against finite differences of the flow map."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import braidsim
from braidsim.core import layout as L
from braidsim.core.driver import Tangents, run
from braidsim.core.models.oscillator import ImpactOscillator
from braidsim.core.physics.contact_laws import PowerLawContact
from braidsim.core.physics.kelvin_voigt import KelvinVoigtContact
from braidsim.errors import InputError
from braidsim.sensitivity import SensitivityError, flow_map, record_flow_map, zero_tangent

TIGHT = {
    "simulation.rtol": 1e-12,
    "simulation.atol_position": 1e-14,
    "simulation.atol_velocity": 1e-11,
}


def _quantities(res: braidsim.Result, n_impacts: int) -> np.ndarray:
    imp = res.impacts.iloc[:n_impacts]
    cols = [imp[c].to_numpy() for c in L.IMPACT_SENS_FIELDS]  # (rebound_velocity last)
    fin = [res.final[k] for k in ("x", "vx", "y", "vy")]
    return np.concatenate([np.asarray(fin), np.stack(cols, axis=1).ravel()])


def _tangent_quantities(res: braidsim.Result, i: int, n_impacts: int) -> np.ndarray:
    S = res.sensitivity
    return np.concatenate([S.final[i], S.impacts[:n_impacts, i, :].ravel()])


def _check_against_fd(sc, keys, duration, rel=5e-6, min_checked=0.5):
    """Tangents against central differences at three steps; entries whose three quotients
    agree to 1e-6 (well conditioned: more than half of them) must agree with the tangent to
    ``rel`` (measured: 1.2e-6 at most, median 2e-8). Two steps are not enough: a depth
    located on the same step in the runs at p +- h and p +- h/2 gave two equal quotients,
    both 1.4e-3 off (the third, at 2h, and the tangent at two tolerances agreed)."""
    res = braidsim.simulate(sc, duration=duration, sensitivities=keys, series=False)
    n_imp = len(res.impacts)
    assert n_imp >= 2
    checked = total = 0
    for i, key in enumerate(keys):
        p = res.model.scenario[key]
        if p is None:  # the law's own exponent
            p = res.model.track.exponent
        quotients = []
        for h in (1e-5 * abs(p or 0.1), 0.5e-5 * abs(p or 0.1), 2e-5 * abs(p or 0.1)):
            plus = braidsim.simulate(sc, duration=duration, overrides={key: p + h}, series=False)
            minus = braidsim.simulate(sc, duration=duration, overrides={key: p - h}, series=False)
            assert len(plus.impacts) == len(minus.impacts) == n_imp
            quotients.append((_quantities(plus, n_imp) - _quantities(minus, n_imp)) / (2 * h))
        fd1, fd2, fd3 = quotients
        tan = _tangent_quantities(res, i, n_imp)
        scale = np.abs(fd2) + 1e-300
        good = (
            (np.abs(fd1 - fd2) <= 1e-6 * scale)
            & (np.abs(fd3 - fd2) <= 1e-6 * scale)
            & (np.abs(fd2) > 0)
            & np.isfinite(fd2)
        )
        total += int(np.sum(np.isfinite(fd2) & (np.abs(fd2) > 0)))
        checked += int(good.sum())
        err = np.abs(tan[good] - fd2[good]) / scale[good]
        assert np.all(err < rel), (key, np.max(err), tan[good], fd2[good])
    assert checked >= min_checked * total, (checked, total)


def test_x_carrier_sensitivities_match_finite_differences() -> None:
    """paper-3.3 (track vibration, chatter), x only: final state and every impact's time,
    speed, peak force, depth, exit and rebound speed, along parameters of the law, the geometry, the
    loads, the vibration and the horn gear."""
    sc = braidsim.load_scenario("paper-3.3", overrides=TIGHT)
    keys = [
        "contact.track.restitution",
        "track.clearance",
        "track.vibration_amplitude",
        "track.vibration_frequency",
        "carrier.mass",
        "yarn.tension_horizontal",
        "horn_gear.angular_velocity",
        "friction.carrier_horn_gear",
        "materials.track.youngs_modulus",
        "contact.track.exponent",
        "track.vibration_phase",
        "friction.regularization_velocity",
    ]
    _check_against_fd(sc, keys, 0.02)


def test_contacts_that_transfers_cut_and_start_match_finite_differences() -> None:
    """paper-3.4b rests on its inner wall from 0.077 s; each transfer cuts that contact and
    starts one on the outer wall at the transfer time, which moves with transfer.first and
    transfer.period. The started contact's onset time and approach speed took no account of
    that move (d onset / d first was 0 for 1, d speed 27.7 for -0.407), nor did the cut
    contact's end (NaN for 1), and the wrong latched speed moved the final state by 4e-3."""
    sc = braidsim.load_scenario(
        "paper-3.4b",
        overrides={**TIGHT, "transfer.first": "0.1 s", "transfer.period": "0.03 s"},
    )
    keys = ["transfer.first", "transfer.period"]
    res = braidsim.simulate(sc, duration=0.2, series=False, sensitivities=keys)
    imp = res.impacts
    (cut,) = np.flatnonzero(imp.cut_by_transfer.to_numpy()[:-1])  # the one at 0.1 s
    assert imp.t.iloc[cut + 1] == imp.t_end.iloc[cut] == 0.1
    for i, key in enumerate(keys):
        h = 1e-6 * sc[key]
        plus, minus = (
            braidsim.simulate(sc, duration=0.2, series=False, overrides={key: sc[key] + s * h})
            for s in (1, -1)
        )
        rows = [(cut + 1, "t"), (cut + 1, "velocity"), (cut + 1, "peak_force"), (cut, "t_end")]
        # the dissipated energy of the contact cut at the moving transfer, and of the next
        rows += [(cut, "dissipated_energy"), (cut + 1, "dissipated_energy")]
        for row, column in rows:
            fd = (plus.impacts[column].iloc[row] - minus.impacts[column].iloc[row]) / (2 * h)
            q = L.IMPACT_SENS_FIELDS.index(column)
            tangent = res.sensitivity.impacts[row, i, q]
            assert tangent == pytest.approx(fd, rel=1e-5, abs=1e-6), (key, column)
        for j, name in enumerate(("x", "vx")):
            fd = (plus.final[name] - minus.final[name]) / (2 * h)
            assert res.sensitivity.final[i, j] == pytest.approx(fd, rel=1e-3), (key, name)


def test_dissipated_energy_through_clamped_contacts_matches_finite_differences() -> None:
    """A Gonthier wall at e = 0.1 (paper-3.3, x only): contact forces reach their clamp
    N = 0 before the depth returns to 0, and the body then flies free while the law still
    turns its stored energy into dissipation, D' = -F_k p'. The tangent of that integrand
    goes as sqrt(p) towards the exit; the tangents of the motion, smooth there, took long
    steps, and the first impact's dissipated energy had its tangent 1.6e-5 (mass) and
    3.2e-5 (clearance) off its central differences here (8.3e-5 and 1.8e-4 in a run with
    four keys, whose steps differ), converging only slowly with the tolerance; now 1.2e-7
    and 1.2e-6 (tangent.dissipation_tangent_error bounds those steps). A run continued
    from inside such a clamped phase, whose tangents start at 0 there, is held to the same
    bound (a bound relative to the tangent and its change over the step alone collapsed
    the step at the exit of such a continued run on a Flores wall)."""
    sc = braidsim.load_scenario(
        "paper-3.3",
        overrides={**TIGHT, "contact.track.model": "gonthier", "contact.track.restitution": 0.1},
    )
    q = L.IMPACT_SENS_FIELDS.index("dissipated_energy")

    def check(res, keys, start=None):
        for i, key in enumerate(keys):
            p = sc[key]
            fds = []
            for f in (1e-4, 0.5e-4):  # (clamped runs: steps of 1e-5 spread the quotients)
                h = f * p
                a, b = (
                    braidsim.simulate(
                        sc, duration=0.03, series=False, start=start, overrides={key: p + s * h}
                    ).impacts["dissipated_energy"]
                    for s in (1, -1)
                )
                assert len(a) == len(b) == len(res.impacts)
                fds.append((a.to_numpy() - b.to_numpy()) / (2 * h))
            fd, spread = fds[0], np.abs(fds[1] - fds[0])
            tan = res.sensitivity.impacts[:, i, q]
            big = np.abs(fd) > 1e-3 * np.abs(fd).max()
            assert np.any(big)
            err = np.abs(tan - fd)
            bound = 2e-6 * np.abs(fd) + 2 * spread
            assert np.all(err[big] <= bound[big]), (key, err[big] / np.abs(fd[big]))

    keys = ["carrier.mass", "track.clearance"]
    res = braidsim.simulate(sc, duration=0.03, series=False, sensitivities=keys)
    imp = res.impacts
    # (the clamps are events of their own, beside the onsets and exits)
    assert res.stats["events"] > 2 * len(imp) - imp["initial"].sum() - imp["ongoing"].sum()
    check(res, keys)
    # continued from the middle of the first impact's clamped phase (0.00225-0.0024 s)
    start = braidsim.simulate(sc, duration=0.0023, series=False).final_state
    keys = ["track.vibration_amplitude", "track.clearance"]
    res = braidsim.simulate(sc, duration=0.03, series=False, start=start, sensitivities=keys)
    assert res.impacts["initial"].iloc[0] and np.isfinite(res.sensitivity.impacts[0, :, q]).all()
    check(res, keys, start)


def test_a_start_touching_a_wall_refuses_keys_that_move_its_gap() -> None:
    """paper-3.2 starts the carrier touching its outer wall (x0 = the clearance) and moving
    into it at 2 mm/s: a contact latched at that speed from t = 0. A wider clearance starts
    that contact later, at gap / speed (the onset's slope from that side 1 / 2 mm/s = 500
    s/m), a narrower one overlaps from the start (released elastically, no damping): the
    one-sided quotients disagree and the final x jumps, so there is no derivative. The
    tangents said d onset = 0 and gave the final state's slope from one side, silently. A key
    that moves only the approach speed keeps its derivatives."""
    sc = braidsim.load_scenario("paper-3.2", overrides=TIGHT)
    base = braidsim.simulate(sc, duration=0.05, series=False)
    assert base.impacts.t.iloc[0] == 0.0 and not base.impacts.initial.iloc[0]
    eps = sc["track.clearance"]
    h = 1e-10 * eps
    wider, narrower = (
        braidsim.simulate(sc, duration=0.05, series=False, overrides={"track.clearance": v})
        for v in (eps + h, eps - h)
    )
    assert (wider.impacts.t.iloc[0] - base.impacts.t.iloc[0]) / h == pytest.approx(500, rel=1e-3)
    assert narrower.impacts.t.iloc[0] == 0.0 and narrower.impacts.initial.iloc[0]
    right = (wider.final["x"] - base.final["x"]) / h
    left = (base.final["x"] - narrower.final["x"]) / h
    assert abs(left - right) > 10 * abs(right)  # (the final x jumps: not a kink alone)
    for key in ("track.clearance", "initial.x"):
        with pytest.raises(SensitivityError, match="starts on a wall at t = 0 s") as err:
            braidsim.simulate(sc, duration=0.05, series=False, sensitivities=[key])
        assert "\n" not in str(err.value)
    res = braidsim.simulate(
        sc, duration=0.05, series=False, sensitivities=["initial.vx", "contact.track.restitution"]
    )
    # the first contact starts at t = 0 whatever the speed, with the speed as its approach speed
    assert res.sensitivity.impacts[0, 0, 0] == 0.0
    assert res.sensitivity.impacts[0, 0, 1] == pytest.approx(1.0, rel=1e-9)
    for i, key in enumerate(("initial.vx", "contact.track.restitution")):
        p, dp = sc[key], 1e-6 * sc[key]
        plus, minus = (
            braidsim.simulate(sc, duration=0.05, series=False, overrides={key: p + s * dp})
            for s in (1, -1)
        )
        for j, name in enumerate(("x", "vx")):
            fd = (plus.final[name] - minus.final[name]) / (2 * dp)
            assert res.sensitivity.final[i, j] == pytest.approx(fd, rel=1e-5), (key, name)


@pytest.mark.slow  # 100 s, most of it compiling the xy solver with tangents for this test alone
def test_xy_carrier_with_transfers_matches_finite_differences() -> None:
    """The xy carrier hitting both slot walls and the track, with transfers to the next
    horn gear (the state jumps; the transfer times move with the transfer period)."""
    sc = braidsim.load_scenario(
        "paper-3.1",
        overrides={
            **TIGHT,
            "simulation.dof": "xy",
            "initial.vy": "0.05 m/s",
            "initial.y": "0.05 mm",
            "transfer.period": "0.007 s",
            "transfer.first": "0.004 s",
        },
    )
    keys = [
        "slot.clearance",
        "contact.slot.restitution",
        "friction.pad_track",
        "transfer.period",
        "transfer.contact_speed",
        "initial.vy",
    ]
    _check_against_fd(sc, keys, 0.012)


@pytest.mark.slow  # (the xy solver with tangents, compiled for the test above and this one)
def test_xy_carrier_through_clamped_contacts_matches_finite_differences() -> None:
    """Slot contacts so damped (Flores, e = 0.1) that their force reaches its clamp N = 0
    before the pad leaves the wall: the solver cuts its steps at those kinks (the tangents
    do not jump there, the field being continuous). Stepped over, the kinks made the runs
    themselves err: the central differences of the final y and vy were 4e-4 to 3.5e-2 from
    these same tangents; cut, 1.2e-6 to 3.5e-5 where the differences at two steps agree
    (measured at rtol 1e-12, atol 1e-17 m; docs/sensitivities.md)."""
    sc = braidsim.load_scenario(
        "paper-3.1",
        overrides={
            **TIGHT,
            "simulation.dof": "xy",
            "contact.slot.model": "flores",
            "contact.slot.restitution": 0.1,
        },
    )
    res = braidsim.simulate(sc, duration=0.02, series=False)
    # the clamps are events of their own: more than the onsets and exits
    assert res.stats["events"] > 2 * len(res.impacts)
    _check_against_fd(sc, ["contact.slot.restitution", "carrier.mass", "friction.pad_track"], 0.02)


@pytest.mark.slow  # (the xy solver with tangents, compiled for the tests above and this one)
def test_xy_carrier_starting_on_its_slot_wall_has_sensitivities() -> None:
    """The xy paper scenarios start the carrier on the rear slot wall, at rest relative to
    it, pressed into it by the horn gear: the contact is there from the first instant, and
    its onset is found a few 1e-20 s after the start with no normal speed. For a key that
    does not move that wall's gap or its rate at the start, the onset stays at the start
    (derivative 0) and the run's sensitivities exist: checked against central differences
    (slot impacts, track impacts, final state; entries the differences cannot resolve left
    out). Before, every such run stopped as grazing. A key that moves the gap at the start
    (the initial y) does make the contact appear or not: still grazing, said in one line."""
    sc = braidsim.load_scenario("paper-3.3", overrides={**TIGHT, "simulation.dof": "xy"})
    plain = braidsim.simulate(sc, duration=0.01, series=False)
    first_slot = plain.impacts[plain.impacts["pair"] == "slot"].iloc[0]
    assert first_slot["t"] < 1e-15 and first_slot["velocity"] == pytest.approx(0.0, abs=1e-15)
    # (the phase's value is 0: its record tangent is exactly 0 where the stencil's records
    # differ by rounding only; that rounding over h = 1e-8 made it grazing at this atol)
    keys = [
        "contact.slot.restitution",
        "carrier.mass",
        "horn_gear.angular_velocity",
        "track.vibration_phase",
    ]
    res = braidsim.simulate(sc, duration=0.01, series=False, sensitivities=keys)
    n_imp = len(res.impacts)
    i_slot = int(np.flatnonzero(res.impacts["pair"].to_numpy() == "slot")[0])
    assert np.all(res.sensitivity.impacts[i_slot, :, 0] == 0.0)  # the onset stays at t = 0
    # This run chatters: the difference quotients at h, h/2 and 2h differ by up to 1e-2
    # of their value (the horn gear's speed moves the slot wall under every later slot
    # impact), so each tangent is held to the quotients' own spread (plus 1e-5), and their
    # median agreement to 5e-4 (measured 9.2e-6, 6.4e-6, 4.6e-5 and 2.0e-4: the phase's
    # quotients spread most).
    values = _quantities(res, n_imp)
    per_impact = np.abs(values[4:]).reshape(n_imp, len(L.IMPACT_SENS_FIELDS)).max(axis=0)
    magnitude = np.concatenate([np.abs(values[:4]), np.tile(per_impact, n_imp)])
    errs = []
    counted = total = 0
    for i, key in enumerate(keys):
        p = res.model.scenario[key]
        h1 = 1e-5 * abs(p) or 1e-5  # (1e-5 rad for the phase)
        q = {}
        for f in (0.5, 1.0, 2.0):
            h = f * h1
            plus = braidsim.simulate(sc, duration=0.01, overrides={key: p + h}, series=False)
            minus = braidsim.simulate(sc, duration=0.01, overrides={key: p - h}, series=False)
            assert len(plus.impacts) == len(minus.impacts) == n_imp
            q[f] = (_quantities(plus, n_imp) - _quantities(minus, n_imp)) / (2 * h)
        fd = q[0.5]
        spread = np.maximum(np.abs(q[1.0] - fd), np.abs(q[2.0] - fd))
        tan = _tangent_quantities(res, i, n_imp)
        # entries the differences cannot resolve (below the runs' own error over h, 1e-9 of
        # the largest value of their kind) left out
        floor = 1e-9 * magnitude / (0.5 * h1)
        ok = np.isfinite(fd) & (np.abs(fd) > floor)
        counted += int(ok.sum())
        total += tan.size
        err = np.abs(tan[ok] - fd[ok])
        bound = 1e-5 * np.abs(fd[ok]) + 2 * spread[ok]
        assert np.all(err <= bound), (key, np.flatnonzero(ok)[np.argmax(err / bound)])
        errs.append(np.median(err / np.abs(fd[ok])))
    assert max(errs) < 5e-4, errs
    # (the track's impacts hardly depend on the slot's restitution: those are the most of
    # what is left out)
    assert counted > 0.6 * total, (counted, total)
    # the tangents' own steps: the plain run's impacts, at the tolerance
    np.testing.assert_allclose(res.impacts["t"], plain.impacts["t"], rtol=0, atol=1e-9)
    with pytest.raises(SensitivityError, match="grazing"):
        braidsim.simulate(sc, duration=0.01, series=False, sensitivities=["initial.y"])
    # the initial x moves the slot's gap by rounding only (it was refused at this atol)
    braidsim.simulate(sc, duration=0.01, series=False, sensitivities=["initial.x"])
    # nor do the start's tangents, difference quotients good to ~1e-13, at an atol of
    # 1e-12 m/s (a rate of 1e-13 m/s per unit along the horn gear's speed was refused)
    tighter = sc.with_overrides({"simulation.atol_velocity": 1e-12})
    keys = ["horn_gear.angular_velocity", "initial.x"]
    again = braidsim.simulate(tighter, duration=0.01, series=False, sensitivities=keys)
    assert np.all(again.sensitivity.impacts[i_slot, :, 0] == 0.0)


def test_stencil_rounding_is_no_derivative() -> None:
    """Stencil values that differ from the value by rounding only give the derivative 0;
    a slope, even a small one, is kept (the fourth-order stencil is exact on cubics)."""
    from braidsim.sensitivity import _CENTRAL, _stencil_derivative

    eps = np.finfo(float).eps
    offsets = [o for o, _ in _CENTRAL]
    weights = [w for _, w in _CENTRAL]
    h = 1e-8
    noisy = [np.array([0.8 + 2 * o * eps, 5.0]) for o in offsets]  # ulps, and a constant
    assert np.all(_stencil_derivative(noisy, weights, h, np.array([0.8, 5.0])) == 0.0)
    cubic = [0.8 + 1e-3 * (o * h) + (o * h) ** 3 for o in offsets]
    # (kept, to the rounding of 0.8 over 1e-8: 1.3e-6 relative here)
    assert _stencil_derivative(cubic, weights, h, 0.8) == pytest.approx(1e-3, rel=1e-5)
    big_h = 1e-4
    cubic = [2.0 + 3.0 * (o * big_h) - (o * big_h) ** 3 for o in offsets]
    assert _stencil_derivative(cubic, weights, big_h, 2.0) == pytest.approx(3.0, rel=1e-10)


def _zero_oscillator_tangent(law: object) -> ImpactOscillator:
    return zero_tangent(ImpactOscillator(1.0, 1.0, 1.0, 1.0, 1.0, 0.0, math.inf, 1.0, law))


def test_a_float_field_given_as_an_integer_has_a_zero_tangent() -> None:
    """ImpactOscillator(mass=1, ...): the zero tangent kept the integer 1 as d mass, so
    every direction moved the mass and the continuation's monodromy came out -2.18 for
    -0.843. The flow map of the integer record is now that of the float one, bit for bit."""
    law = KelvinVoigtContact.for_restitution(1e8, 0.8, 1.0, allow_tension=True)
    fields = dict(stiffness=1.0, damping=0.05, force_amplitude=1.0, force_frequency=1.1)
    fields.update(force_phase=0.0, gap_inner=math.inf, gap_outer=0.5, law=law)
    assert zero_tangent(ImpactOscillator(mass=1, **fields)).mass == 0.0
    opts = L.SolverOptions(1e-10, 1e-14, 1e-11, 1e-2, 10**6, 3.0)
    maps = [
        record_flow_map(
            ImpactOscillator(mass=m, **fields), opts, 0.0, 3.0, [0.3, 0.0], keys=["law.damping"]
        )
        for m in (1, 1.0)
    ]
    for name in ("y1", "jac_y", "jac_p", "impact_sens"):
        # (equal NaN: a flow map integrates no energy, so no impact's dissipated energy)
        a, b = getattr(maps[0], name), getattr(maps[1], name)
        assert np.array_equal(a, b, equal_nan=True), name


def _free_response(t, m, c, k, F, W, x0, v0):
    """x(t) of m x'' + c x' + k x = F cos(W t), x(0) = x0, x'(0) = v0 (underdamped), in
    closed form; numpy operations only, so that a complex step differentiates it."""
    wn = np.sqrt(k / m)
    z = c / (2 * np.sqrt(k * m))
    wd = wn * np.sqrt(1 - z * z)
    # particular solution A cos + B sin
    den = (k - m * W * W) ** 2 + (c * W) ** 2
    A = F * (k - m * W * W) / den
    B = F * c * W / den
    a0 = x0 - A
    b0 = (v0 - B * W + z * wn * a0) / wd
    return np.exp(-z * wn * t) * (a0 * np.cos(wd * t) + b0 * np.sin(wd * t)) + (
        A * np.cos(W * t) + B * np.sin(W * t)
    )


def test_linear_oscillator_sensitivities_match_the_closed_form() -> None:
    """A forced linear oscillator (no wall): d x(T) / d (k, c, F, Omega, m, x0, v0) against
    the closed-form solution differentiated by the complex step (exact to round-off)."""
    m, c, k, F, W, x0, v0, T = 1.3, 3.0, 2.0e4, 7.0, 90.0, 1e-3, 0.2, 0.25
    law = PowerLawContact(1e9, 1.5, 0.0)
    model = ImpactOscillator(m, k, c, F, W, 0.0, math.inf, math.inf, law)
    z = _zero_oscillator_tangent(law)
    names = ["stiffness", "damping", "force_amplitude", "force_frequency", "mass"]
    records = [z._replace(**{nm: 1.0}) for nm in names] + [z, z]
    S0 = np.zeros((7, 2))
    S0[5, 0] = 1.0
    S0[6, 1] = 1.0
    scale = np.array([k, c, F, W, m, 1.0, 1.0])
    opts = L.SolverOptions(1e-12, 1e-16, 1e-13, 1e-3, 10**7, T)
    raw = run(
        model,
        opts,
        np.array([x0, v0, 0.0, 0.0, 0.0]),
        series=False,
        tangents=Tangents(records, S0, np.zeros((7, 2)), np.zeros((7, 0)), scale, False),
    )
    assert raw.status == L.ST_OK
    args = [m, c, k, F, W, x0, v0]
    order = [2, 1, 3, 4, 0, 5, 6]  # k, c, F, W, m, x0, v0 in the closed form's arguments
    hc = 1e-30
    for d, j in enumerate(order):
        a = [complex(v) for v in args]
        a[j] += 1j * hc
        exact = float(np.imag(_free_response(T, *a)) / hc)
        assert raw.sensitivity.S[d, 0] == pytest.approx(exact, rel=1e-8, abs=1e-12 * abs(exact))
    assert raw.y[0] == pytest.approx(float(_free_response(T, *args).real), rel=1e-10)


@pytest.mark.parametrize(
    # (Kelvin-Voigt compiles the solver with tangents once more: ~25 s)
    "law_kind",
    [
        "hertz",
        pytest.param("kelvin_voigt", marks=pytest.mark.slow),
        pytest.param("kelvin_voigt_clamped", marks=pytest.mark.slow),
    ],
)
def test_impact_oscillator_event_sensitivities(law_kind: str) -> None:
    """Onset time, approach speed, peak force, depth, exit time, rebound speed and
    dissipated energy of every impact of a forced impact oscillator against central
    differences of the gap and of x0; the Kelvin-Voigt dashpot makes the vector field jump
    at onset (the saltation term), and dissipates from the onset's first instant (the
    dissipated energy's tangent takes D' dt_e there); without tension its force reaches the
    clamp N = 0 before the depth returns to 0 (a kink, where the dissipation rate's
    linearisation changes side)."""
    if law_kind == "hertz":
        law = PowerLawContact(1e9, 1.5, 0.4)
    else:
        # with tension the force is linear in the contact, and its dashpot term makes the
        # vector field jump at onset and exit; without, it clamps before the exit
        tension = law_kind == "kelvin_voigt"
        law = KelvinVoigtContact.for_restitution(2e7, 0.7, 1.0, allow_tension=tension)
    opts = L.SolverOptions(1e-11, 1e-15, 1e-12, 1e-3, 10**7, 0.2)

    def model(gap):
        return ImpactOscillator(1.0, 1e4, 2.0, 5.0, 60.0, 0.0, math.inf, gap, law)

    y0 = np.array([0.0, 0.3, 0.0, 0.0, 0.0])
    z = zero_tangent(model(2e-3))
    tg = Tangents(
        [z._replace(gap_outer=1.0), z],
        np.array([[0.0, 0.0], [1.0, 0.0]]),
        np.zeros((2, 2)),
        np.zeros((2, 0)),
        np.array([2e-3, 1.0]),
        False,
    )
    raw = run(model(2e-3), opts, y0, series=False, tangents=tg)
    assert raw.status == L.ST_OK
    n = len(raw.episodes)
    assert n >= 2

    def q(gap, x0):
        r = run(model(gap), opts, y0 + np.array([x0, 0, 0, 0, 0]), series=False)
        e = r.episodes
        assert len(e) == n
        cols = L.IMPACT_SENS_FIELDS
        return np.r_[r.y[:2], np.stack([e[c] for c in cols], axis=1).ravel()]

    h = 2e-8
    fds = [(q(2e-3 + h, 0) - q(2e-3 - h, 0)) / (2 * h), (q(2e-3, h) - q(2e-3, -h)) / (2 * h)]
    for d in range(2):
        tan = np.r_[raw.sensitivity.S[d], raw.sensitivity.impacts[:, d, :].ravel()]
        np.testing.assert_allclose(tan, fds[d], rtol=2e-5, atol=1e-9 * np.max(np.abs(fds[d])))


def test_series_sensitivities_match_finite_differences() -> None:
    """The tangents of the sampled x, vx, acceleration and contact force at fixed times."""
    sc = braidsim.load_scenario("paper-3.3", overrides=TIGHT)
    st = np.linspace(0.0, 0.01, 41)
    res = braidsim.simulate(
        sc, duration=0.01, sample_times=st, sensitivities=["track.clearance"], record_events=False
    )
    R = res.sensitivity.series
    assert R.shape == (len(res.series["t"]), 1, 8)
    p = sc["track.clearance"]
    h = 1e-5 * p

    def ser(v):
        r = braidsim.simulate(
            sc,
            duration=0.01,
            sample_times=st,
            overrides={"track.clearance": v},
            record_events=False,
        )
        return r.series

    a, b = ser(p + h), ser(p - h)
    for j, col in ((0, "x"), (1, "vx"), (6, "track_contact_force")):
        fd = (a[col] - b[col]) / (2 * h)
        np.testing.assert_allclose(R[:, 0, j], fd, rtol=1e-5, atol=1e-6 * np.max(np.abs(fd)))


def test_resting_contact_monodromy_matches_finite_differences() -> None:
    """A carrier pressed on the inner wall by the centrifugal load while the track vibrates
    gently never leaves it: its stroboscopic map over one forcing period, with the latched
    speed as part of the state, against central differences of the map; its Floquet
    multipliers are inside the unit circle, and the latched speed's is exactly 1."""
    sc = braidsim.load_scenario(
        "paper-3.3",
        overrides={**TIGHT, "track.vibration_amplitude": "0.002 mm", "friction.law": "none"},
    )
    T = 2 * math.pi / sc["track.vibration_frequency"]
    # settle on the wall, then take the state there as the section
    settle = braidsim.simulate(sc, duration=40 * T, series=False)
    fs = settle.final_state
    assert fs.track_mode == -1
    t0 = 40 * T
    y0 = np.array(fs.y[:2])
    fm = flow_map(sc, t0, t0 + T, y0=y0, modes=(-1, 0), v0s=(fs.track_v0, math.nan))
    assert fm.modes1 == (-1, 0)
    M = fm.monodromy()
    assert M.shape == (3, 3)
    # the map contracts by ~1e-6 per period, so its difference quotients carry the noise of
    # the adaptive steps: two steps give the quotient's own uncertainty
    base = np.r_[y0, fs.track_v0]
    quotients = []
    for eps in (1e-9, 1e-8):
        fd = np.zeros((3, 3))
        for j in range(3):
            step = eps * (1.0 if j < 2 else fs.track_v0 * 1e3)
            cols = []
            for sgn in (1, -1):
                z = base.copy()
                z[j] += sgn * step
                f = flow_map(sc, t0, t0 + T, y0=z[:2], modes=(-1, 0), v0s=(z[2], math.nan))
                cols.append(np.r_[f.y1, f.v0s1[0]])
            fd[:, j] = (cols[0] - cols[1]) / (2 * step)
        quotients.append(fd)
    fd = 0.5 * (quotients[0] + quotients[1])
    spread = np.abs(quotients[0] - quotients[1])
    row = np.max(np.abs(fd), axis=1, keepdims=True)
    assert np.all(np.abs(M - fd) <= 2 * spread + 1e-4 * row), (M, fd, spread)
    assert abs(M[1, 0] - fd[1, 0]) < 1e-4 * abs(fd[1, 0])  # the dominant entry, closely
    mult = np.sort(np.abs(np.linalg.eigvals(M)))
    mult_fd = np.sort(np.abs(np.linalg.eigvals(fd)))
    np.testing.assert_allclose(mult, mult_fd, rtol=1e-3, atol=1e-7)
    assert mult[-1] == pytest.approx(1.0, abs=1e-12)  # the latched speed is neutral
    assert mult[0] < 1.0


def test_bad_keys_are_one_clear_line() -> None:
    with pytest.raises(InputError, match=r"contact\.track\.model is not a differentiable"):
        braidsim.simulate("paper-3.3", duration=0.01, sensitivities=["contact.track.model"])
    with pytest.raises(InputError, match=r"contact\.track\.restitutio"):
        braidsim.simulate("paper-3.3", duration=0.01, sensitivities=["contact.track.restitutio"])
    with pytest.raises(InputError, match=r"simulation\.rtol is not a differentiable"):
        braidsim.simulate("paper-3.3", duration=0.01, sensitivities=["simulation.rtol"])
    # an unknown key is named as a sensitivity's (an empty one was ": unknown parameter")
    for key, shown in (("", "''"), ("track.clearence", "track.clearence")):
        with pytest.raises(InputError) as err:
            braidsim.simulate("paper-3.3", duration=0.01, sensitivities=[key])
        assert str(err.value).startswith(f"sensitivity: {shown} is not a scenario key")


def test_a_grazing_onset_after_a_pause_is_refused_as_before_it(monkeypatch) -> None:
    """The grazing of the test above along a direction that does not move the gap (the
    law's stiffness): a run that pauses (every 5 steps here; every 50,000 in use) resumed in
    calls whose start time was -inf, where every onset counted as the run's start and was
    taken as pinned on its wall: the run went on past it. It is refused there, as in one
    call."""
    from braidsim.core import driver

    law = PowerLawContact(1e9, 1.5, 0.3)
    g = 1e-3
    model = ImpactOscillator(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, g, law, 1e-2, -1.0)
    opts = L.SolverOptions(1e-10, 1e-15, 1e-12, 1e-3, 10**6, 2.0)
    y0 = np.array([g - 1e-8, 1e-8, 0.0, 0.0, 0.0])
    z = zero_tangent(model)
    stiff = z._replace(law=z.law._replace(stiffness=1.0))
    tg = Tangents([stiff], np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 0)), np.ones(1), False)
    for pause in (L.PAUSE_STEPS, 5):
        monkeypatch.setattr(driver.L, "PAUSE_STEPS", pause)
        raw = run(model, opts, y0, series=False, tangents=tg)
        # (at the onset, t = 1 s: resumed, the run went on to fail at the exit, 1.032 s)
        assert raw.status == L.ST_GRAZING and raw.t == pytest.approx(1.0, rel=1e-6), pause


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        # a string was taken letter by letter ("t: unknown parameter")
        ({"keys": "track.clearance"}, "keys = 'track.clearance'; allowed a list"),
        ({"modes": (1,)}, "modes = (1,); allowed two contact modes"),  # (an IndexError)
        ({"modes": (-1, 0), "v0s": ("a", 1)}, "v0s = ('a', 1); allowed two latched speeds"),
        ({"y0": [math.nan, 0.0]}, "y0 = [nan, 0.0] is not finite"),  # ("got (2,)")
        ({"y0": [0.0, 0.0, 0.0]}, "y0 has the shape (3,); allowed 2 finite numbers"),
        # a contact declared on a free state was taken for one that ends at once
        (
            {"y0": [0.5e-3, 0.0], "modes": (-1, 0), "v0s": (0.1, math.nan)},
            "modes[0] = -1 declares a contact with the inner track wall, but y0 is 0.38 mm",
        ),
        (
            {"y0": [0.5e-3, 0.0], "modes": (1, 0), "v0s": (0.1, math.nan)},
            "modes[0] = +1 declares a contact with the outer track wall, but y0 is 2.62 mm",
        ),
        # the given y0 replaces the initial state: the key's column was silently 0
        (
            {"y0": [1e-3, 0.0], "keys": ["track.clearance", "initial.vx"]},
            "flow_map: initial.vx with y0: the map starts from the given y0",
        ),
    ],
)
def test_flow_map_inputs_are_one_clear_line(kwargs, message) -> None:
    with pytest.raises(InputError, match=re.escape(message)):
        flow_map("paper-3.3", 0.0, 0.01, **kwargs)


def test_grazing_contact_is_refused() -> None:
    """A body that reaches its wall at 1e-8 m/s (far below the floor of the latched speed)
    touches it tangentially: the impact sequence changes under an infinitesimal change, so
    the run stops with ST_GRAZING (and the public error names the time) instead of giving
    a number."""
    law = PowerLawContact(1e9, 1.5, 0.3)
    g, v = 1e-3, 1e-8
    model = ImpactOscillator(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, g, law, 1e-2, -1.0)
    opts = L.SolverOptions(1e-10, 1e-15, 1e-12, 1e-3, 10**6, 2.0)
    y0 = np.array([g - 1e-8, v, 0.0, 0.0, 0.0])  # reaches the wall at t = 1 s
    z = zero_tangent(model)
    tg = Tangents(
        [z], np.array([[1.0, 0.0]]), np.zeros((1, 2)), np.zeros((1, 0)), np.ones(1), False
    )
    assert run(model, opts, y0, series=False).status == L.ST_OK  # fine without tangents
    raw = run(model, opts, y0, series=False, tangents=tg)
    assert raw.status == L.ST_GRAZING
    assert raw.t == pytest.approx(1.0, rel=1e-6)
    err = braidsim.sensitivity.sensitivity_error(raw.t)
    assert isinstance(err, SensitivityError)
    assert "t = 1 s" in str(err) and "grazing" in str(err)


def test_cli_sensitivity_json_and_bad_key(capsys) -> None:
    """``braidsim run --sensitivity KEY --json``: the derivatives in each impact and in
    ``final``, the same numbers as the Python API; a law name is refused in one line."""
    import json

    from braidsim.cli import main

    def cli(*argv: str) -> tuple[int, str, str]:
        with pytest.raises(SystemExit) as exc:
            main(list(argv))
        out, err = capsys.readouterr()
        return int(exc.value.code or 0), out, err

    args = ("run", "paper-3.3", "--duration", "0.02 s", "--sensitivity", "track.clearance")
    code, out, err = cli(*args, "--json")
    assert code == 0, err
    data = json.loads(out)
    res = braidsim.simulate("paper-3.3", duration=0.02, sensitivities=["track.clearance"])
    d = data["final"]["sensitivity"]["track.clearance"]
    assert d["x"] == pytest.approx(res.sensitivity.final[0, 0], rel=1e-12)
    imp = data["impacts"][1]["sensitivity"]["track.clearance"]
    assert set(imp) == set(L.IMPACT_SENS_FIELDS)
    assert imp["peak_force"] == pytest.approx(res.sensitivity.impacts[1, 0, 2], rel=1e-12)
    code, out, err = cli("run", "paper-3.3", "--sensitivity", "contact.track.model", "--json")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "contact.track.model" in err


@pytest.mark.parametrize(
    ("name", "k"), [("stable_p1", 1), ("period_doubled", 1), ("period_doubled", 2)]
)
def test_tangents_give_the_closed_form_monodromy(name: str, k: int) -> None:
    """The tangents of braidsim's run from a periodic orbit of a piecewise-linear impact
    oscillator (a linear spring-dashpot wall: the field jumps at onset and exit) over its
    period are the orbit's monodromy, as the closed form gives it (phase exponentials and
    saltation matrices, ``tests/reference``); its multipliers too."""
    from reference.pwl_braidsim import braidsim_oscillator
    from reference.pwl_oscillator import (
        ORBIT_GUESSES,
        PARAMETER_SETS,
        floquet_multipliers,
        monodromy,
        periodic_orbit,
    )

    orbit = periodic_orbit(PARAMETER_SETS[name], k, ORBIT_GUESSES[(name, k)])
    model = braidsim_oscillator(orbit.params)
    z = zero_tangent(model)
    opts = L.SolverOptions(1e-12, 1e-15, 1e-14, 0.05, 10**6, orbit.period, energy=False)
    tg = Tangents([z, z], np.eye(2), np.zeros((2, 2)), np.zeros((2, 0)), np.ones(2), False)
    raw = run(model, opts, np.array(orbit.z_section), series=False, tangents=tg)
    assert raw.status == L.ST_OK
    M_braidsim = raw.sensitivity.S.T  # column j: d z(kT) / d z_j(0)
    M = monodromy(orbit)
    np.testing.assert_allclose(M_braidsim, M, rtol=0.0, atol=1e-8 * np.abs(M).max())
    np.testing.assert_allclose(
        np.sort_complex(np.linalg.eigvals(M_braidsim)),
        np.sort_complex(floquet_multipliers(orbit)),
        rtol=1e-7,
    )


def test_stroboscopic_map_over_two_periods_is_the_product_of_two_maps() -> None:
    """The chain rule across the section: the map over 2 periods is the product of the maps
    over each (with the contact state handed on), for a chattering carrier."""
    from braidsim.sensitivity import forcing_period, stroboscopic_map

    sc = braidsim.load_scenario("paper-3.3", overrides=TIGHT)
    T = forcing_period(sc)
    t0 = 3 * T
    pre = braidsim.simulate(sc, duration=t0, series=False).final_state
    y0 = np.array(pre.y[:2])
    v0 = (pre.track_v0 if pre.track_mode else math.nan, math.nan)
    modes = (pre.track_mode, 0)
    both = stroboscopic_map(sc, t0, y0, modes, v0, periods=2)
    first = stroboscopic_map(sc, t0, y0, modes, v0, periods=1)
    second = stroboscopic_map(sc, t0 + T, first.y1, first.modes1, first.v0s1, periods=1)
    # d y2 / d y0 = (d y2 / d y1)(d y1 / d y0) + (d y2 / d v0_1)(d v0_1 / d y0)
    chain = second.jac_y @ first.jac_y + second.jac_v0 @ first.dv0_dy
    scale = np.abs(both.jac_y).max()
    np.testing.assert_allclose(both.jac_y, chain, rtol=0.0, atol=1e-5 * scale)
    np.testing.assert_allclose(both.y1, second.y1, rtol=1e-7, atol=1e-12)
    with pytest.raises(InputError, match="periods"):
        stroboscopic_map(sc, t0, y0, modes, v0, periods=0)


def test_tangents_survive_buffer_flushes_bit_for_bit() -> None:
    """Small series and impact buffers make the solver return and resume many times; the
    tangents (of the final state, of every impact and of every series row) come out with
    the same bits as in one pass (paper-3.3, a chattering carrier)."""
    from braidsim.model import build_model
    from braidsim.sensitivity import directions

    sc = braidsim.load_scenario("paper-3.3")
    model = build_model(sc, 0.1, keep_zero_harmonics=True)
    dirs = directions(model, ["track.clearance", "contact.track.restitution", "initial.x"])
    st = np.linspace(0.0, 0.1, 201)

    def go(**kw):
        return run(
            model.record,
            model.options,
            model.y0,
            sample_times=st,
            transfer_times=model.transfer_times,
            tangents=dirs.tangents(series=True),
            **kw,
        )

    one = go()
    many = go(row_chunk=7, episode_chunk=8)
    assert one.status == many.status == L.ST_OK
    assert len(one.episodes) > 8  # more impacts than one buffer holds
    np.testing.assert_array_equal(one.sensitivity.S, many.sensitivity.S)
    np.testing.assert_array_equal(one.sensitivity.impacts, many.sensitivity.impacts)
    np.testing.assert_array_equal(one.series, many.series)
    np.testing.assert_array_equal(one.sensitivity.series, many.sensitivity.series)


def _kelvin_voigt_wall_monodromy(
    allow_tension: bool, rtol: float, fd_step: float
) -> tuple[np.ndarray, np.ndarray]:
    """The exact map's Jacobian and its central differences (step ``fd_step``) over one
    forcing period from the period-1 orbit of an impact oscillator on a 1e10 N/m
    Kelvin-Voigt wall (one impact)."""
    law = KelvinVoigtContact.for_restitution(1e10, 0.8, 1.0, allow_tension=allow_tension)
    rec = ImpactOscillator(1.0, 1.0, 0.05, 1.0, 1.1, 0.0, math.inf, 0.5, law)
    T = 2 * math.pi / 1.1
    opts = L.SolverOptions(
        rtol=rtol,
        atol_position=1e-14,
        atol_velocity=1e-12,
        max_step=T / 64,
        max_steps=10_000_000,
        t_end=1.0,
    )
    t0 = 2.915493182308611
    z = np.array([-0.7211018850519465, -0.22102315537554795])
    fm = record_flow_map(rec, opts, t0, t0 + T, z)
    assert len(fm.episodes) == 1
    fd = np.zeros((2, 2))
    for j in range(2):
        e = np.zeros(2)
        e[j] = fd_step
        a = record_flow_map(rec, opts, t0, t0 + T, z + e).y1
        b = record_flow_map(rec, opts, t0, t0 + T, z - e).y1
        fd[:, j] = (a - b) / (2 * fd_step)
    return fm.jac_y, fd


def test_stiff_kelvin_voigt_wall_monodromy_matches_finite_differences() -> None:
    """An impact oscillator on a Kelvin-Voigt wall of 1e10 N/m over one forcing period from
    its period-1 orbit: the onset is found by a long free step, and the state there lies
    ~2e-12 m short of the wall. The tangents are jumped on the wall itself
    (tangent.surface_event); jumped at that state they were carried by the contact's
    stiffness over the ~1e-12 s before it, and the map was 7e-3 off its central
    differences (these agree with an independent scipy integration to 1e-5)."""
    jac, fd = _kelvin_voigt_wall_monodromy(True, 1e-10, 1e-6)
    assert np.abs(jac - fd).max() < 2e-5, (jac, fd)


@pytest.mark.parametrize("rtol", [1e-10, 1e-12])
def test_stiff_clamped_kelvin_voigt_monodromy_matches_finite_differences(rtol: float) -> None:
    """The orbit of the test above on the same wall without tension: the force clamps at 0
    before the depth does (a kink of the field, located as an event). The stages read at
    the kink itself took the linearisation of the side the location's error put them on
    (F_k + F_c = -1.6e-7 N past the kink at the end of the step to it), and the map was
    3.2e-4 off its central differences at rtol 1e-10 (tangent.clamp_step_end). At rtol
    1e-12 the tangents' error estimate of the steps over the kink rejected them until the
    step collapsed a few 1e-14 s short of it (the estimate of the part before the kink now
    decides). The central differences agree with the tangents to ~1e-6 at steps of 1e-5 (as
    those of the wall with tension)."""
    jac, fd = _kelvin_voigt_wall_monodromy(False, rtol, 1e-5)
    assert np.abs(jac - fd).max() < 1e-5, (jac, fd)
