"""Forward sensitivities through impacts, against things no one here wrote: central finite
differences of the simulator itself at tight tolerance, the closed-form solution of a
forced linear oscillator (differentiated by the complex step), and the monodromy of a
resting-contact orbit against finite differences of the flow map."""

from __future__ import annotations

import math

import numpy as np
import pytest

import braidsim
from braidsim.core import layout as L
from braidsim.core.driver import Tangents, run
from braidsim.core.models.oscillator import ImpactOscillator
from braidsim.core.physics.contact_laws import PowerLawContact
from braidsim.core.physics.kelvin_voigt import KelvinVoigtContact
from braidsim.errors import InputError
from braidsim.sensitivity import SensitivityError, flow_map, zero_tangent

TIGHT = {
    "simulation.rtol": 1e-11,
    "simulation.atol_position": 1e-14,
    "simulation.atol_velocity": 1e-11,
}


def _quantities(res: braidsim.Result, n_impacts: int) -> np.ndarray:
    imp = res.impacts.iloc[:n_impacts]
    cols = [imp[c].to_numpy() for c in ("t", "velocity", "peak_force", "max_depth", "t_end")]
    fin = [res.final[k] for k in ("x", "vx", "y", "vy")]
    return np.concatenate([np.asarray(fin), np.stack(cols, axis=1).ravel()])


def _tangent_quantities(res: braidsim.Result, i: int, n_impacts: int) -> np.ndarray:
    S = res.sensitivity
    return np.concatenate([S.final[i], S.impacts[:n_impacts, i, :].ravel()])


def _check_against_fd(sc, keys, duration, rel=1e-6, min_checked=0.6):
    """Tangents against central differences at two steps; entries whose two quotients
    agree to 1e-8 (well conditioned) must agree with the tangent to ``rel``."""
    res = braidsim.simulate(sc, duration=duration, sensitivities=keys, series=False)
    n_imp = len(res.impacts)
    assert n_imp >= 2
    checked = total = 0
    for i, key in enumerate(keys):
        p = res.model.scenario[key]
        quotients = []
        for h in (1e-5 * abs(p), 0.5e-5 * abs(p)):
            plus = braidsim.simulate(sc, duration=duration, overrides={key: p + h}, series=False)
            minus = braidsim.simulate(sc, duration=duration, overrides={key: p - h}, series=False)
            assert len(plus.impacts) == len(minus.impacts) == n_imp
            quotients.append((_quantities(plus, n_imp) - _quantities(minus, n_imp)) / (2 * h))
        fd1, fd2 = quotients
        tan = _tangent_quantities(res, i, n_imp)
        scale = np.abs(fd2) + 1e-300
        good = (np.abs(fd1 - fd2) <= 1e-8 * scale) & (np.abs(fd2) > 0) & np.isfinite(fd2)
        total += int(np.sum(np.isfinite(fd2) & (np.abs(fd2) > 0)))
        checked += int(good.sum())
        err = np.abs(tan[good] - fd2[good]) / scale[good]
        assert np.all(err < rel), (key, np.max(err), tan[good], fd2[good])
        # where the quotient is defined but ill conditioned, the tangent still agrees roughly
        loose = np.isfinite(fd2) & (np.abs(fd2) > 0) & ~good
        assert np.all(np.abs(tan[loose] - fd2[loose]) <= 1e-3 * scale[loose] + 1e-12), key
    assert checked >= min_checked * total, (checked, total)


def test_x_carrier_sensitivities_match_finite_differences() -> None:
    """paper-3.3 (track vibration, chatter), x only: final state and every impact's time,
    speed, peak force, depth and exit, along parameters of the law, the geometry, the
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
    ]
    _check_against_fd(sc, keys, 0.02)


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


def _zero_oscillator_tangent(law: object) -> ImpactOscillator:
    return zero_tangent(ImpactOscillator(1.0, 1.0, 1.0, 1.0, 1.0, 0.0, math.inf, 1.0, law))


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


@pytest.mark.parametrize("law_kind", ["hertz", "kelvin_voigt"])
def test_impact_oscillator_event_sensitivities(law_kind: str) -> None:
    """Onset time, approach speed, peak force, depth and exit time of every impact of a
    forced impact oscillator against central differences of the gap and of x0; the
    Kelvin-Voigt dashpot makes the vector field jump at onset (the saltation term)."""
    if law_kind == "hertz":
        law = PowerLawContact(1e9, 1.5, 0.4)
    else:
        law = KelvinVoigtContact.for_restitution(2e7, 0.7, 1.0, allow_tension=False)
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
        cols = ("t", "velocity", "peak_force", "max_depth", "t_end")
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
    eps = 1e-9
    fd = np.zeros((3, 3))
    base = np.r_[y0, fs.track_v0]
    for j in range(3):
        cols = []
        for sgn in (1, -1):
            z = base.copy()
            z[j] += sgn * eps * (1.0 if j < 2 else fs.track_v0 * 1e3)
            f = flow_map(sc, t0, t0 + T, y0=z[:2], modes=(-1, 0), v0s=(z[2], math.nan))
            cols.append(np.r_[f.y1, f.v0s1[0]])
        step = eps * (1.0 if j < 2 else fs.track_v0 * 1e3)
        fd[:, j] = (cols[0] - cols[1]) / (2 * step)
    np.testing.assert_allclose(M, fd, rtol=1e-5, atol=1e-7 * np.max(np.abs(fd)))
    mult = np.sort(np.abs(np.linalg.eigvals(M)))
    mult_fd = np.sort(np.abs(np.linalg.eigvals(fd)))
    np.testing.assert_allclose(mult, mult_fd, rtol=1e-5, atol=1e-8)
    assert mult[-1] == pytest.approx(1.0, abs=1e-12)  # the latched speed is neutral
    assert mult[0] < 1.0


def test_bad_keys_are_one_clear_line() -> None:
    with pytest.raises(InputError, match="contact.track.model is not a differentiable"):
        braidsim.simulate("paper-3.3", duration=0.01, sensitivities=["contact.track.model"])
    with pytest.raises(InputError, match="contact.track.restitutio"):
        braidsim.simulate("paper-3.3", duration=0.01, sensitivities=["contact.track.restitutio"])
    with pytest.raises(InputError, match="simulation.rtol is not a differentiable"):
        braidsim.simulate("paper-3.3", duration=0.01, sensitivities=["simulation.rtol"])


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
