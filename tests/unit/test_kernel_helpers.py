"""The kernel's small numerical helpers against independent evaluations.

These are the pieces the step loop relies on without re-checking: the phase rotation of the
track at the RK stages (Taylor series for small angles), the time derivative of the
continuous extension (used to locate peaks), the slopes dN/dt, dF_c/dt of ``pair_info``
(whose signs decide whether a step holds a peak), and the phase memo shared by a step's end
and the next step's start.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from braidsim.integrate import kernel as K
from braidsim.model import build_model
from braidsim.params import load_scenario


@pytest.mark.parametrize("d", [0.0, 1e-9, -3e-5, 0.0123, -0.0777, 0.0999999, 0.1, -0.35, 1.2])
def test_small_angle_sin_cos_match_the_library(d: float) -> None:
    sn, cs = K._sin_cos_small.py_func(d)
    assert sn == pytest.approx(math.sin(d), rel=2e-16, abs=1e-300)
    assert cs == pytest.approx(math.cos(d), rel=2e-16)


def _paper_model() -> tuple[np.ndarray, np.ndarray]:
    m = build_model(load_scenario("paper-3.4a"), 0.01)
    return m.P.copy(), m.excitation


def test_stage_track_rotation_equals_direct_evaluation() -> None:
    _, EX = _paper_model()
    amp, w, ph = EX[K.EX_HEAD : K.EX_HEAD + 3]
    for t in (0.0, 0.1234567, 0.4999):
        for h in (1e-7, 3e-5, 1e-3):
            arg = w * t + ph
            for c in K.RK_C[1:]:
                ht, hdt = K._track_at.py_func(
                    c, h, t, True, amp, w, math.cos(arg), math.sin(arg), EX
                )
                hr, hdr = K.track_h(t + c * h, EX)
                assert ht == pytest.approx(hr, rel=1e-12, abs=1e-18)
                assert hdt == pytest.approx(hdr, rel=1e-12, abs=1e-15)


def _one_contact_step() -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float, np.ndarray]:
    """One DOPRI5 step of a carrier 2 um deep in the inner track wall, moving into it."""
    P, EX = _paper_model()
    Y = np.zeros(K.NY)
    h0, hd0 = K.track_h(0.01, EX)
    Y[0] = h0 - 2e-6
    Y[1] = hd0 - 0.05
    t, h = 0.01, 2e-6
    Kst = np.empty((7, K.NY))
    K.rhs(t, Y, -1, 0, 0.3, 1.0, P, EX, Kst[0])
    Yt, Y1, RC = np.empty(K.NY), np.empty(K.NY), np.empty((5, K.NY))
    K._step(t, Y, h, Kst, -1, 0, 0.3, 1.0, P, EX, Yt, Y1, np.full(3, math.nan))
    K._dense_coeffs(Y, Y1, h, Kst, RC)
    return P, EX, Kst, t, h, RC


def test_dense_derivative_matches_the_stages_and_finite_differences() -> None:
    _, _, Kst, _, h, RC = _one_contact_step()
    d = np.empty(K.NY)
    K.dense_deriv(0.0, h, RC, d)
    np.testing.assert_allclose(d[:4], Kst[0, :4], rtol=1e-9, atol=1e-12)
    K.dense_deriv(1.0, h, RC, d)
    np.testing.assert_allclose(d[:4], Kst[6, :4], rtol=1e-9, atol=1e-12)
    yp, ym = np.empty(K.NY), np.empty(K.NY)
    for theta in (0.2, 0.5, 0.9):
        e = 1e-5
        K.dense_eval(theta + e, RC, yp)
        K.dense_eval(theta - e, RC, ym)
        K.dense_deriv(theta, h, RC, d)
        fd = (yp[:2] - ym[:2]) / (2 * e * h)
        np.testing.assert_allclose(d[:2], fd, rtol=1e-6)


def test_pair_info_slopes_are_the_time_derivatives_of_the_forces() -> None:
    P, EX, _, t, h, RC = _one_contact_step()
    v0 = 0.3
    info, ip, im = np.empty(K.NI), np.empty(K.NI), np.empty(K.NI)
    Ys, Yd = np.empty(K.NY), np.empty(K.NY)
    e = 1e-4
    for theta in (0.3, 0.7):
        for th, out in ((theta, info), (theta + e, ip), (theta - e, im)):
            K.dense_eval(th, RC, Ys)
            K.dense_deriv(th, h, RC, Yd)
            K.pair_info(t + th * h, Ys, Yd, 0, -1, v0, P, EX, out, np.full(3, math.nan))
        dt = 2 * e * h
        assert info[K.I_P] > 0.0
        assert info[K.I_N] == pytest.approx(info[K.I_FK] + info[K.I_FC], rel=1e-14)
        assert info[K.I_DN] == pytest.approx((ip[K.I_N] - im[K.I_N]) / dt, rel=1e-5)
        assert info[K.I_DFC] == pytest.approx((ip[K.I_FC] - im[K.I_FC]) / dt, rel=1e-5)
        assert info[K.I_PD] == pytest.approx((ip[K.I_P] - im[K.I_P]) / dt, rel=1e-5)


def test_phase_memo_gives_the_bits_of_direct_evaluation() -> None:
    """The track's motion from the remembered phase equals a fresh evaluation bit for bit
    (a stale memo, for another time, is recomputed) and the closed form a cos(w t + phi);
    a step started from the memo equals one started from a fresh evaluation."""
    P, EX, _, t, h, RC = _one_contact_step()
    amp, w, ph = EX[K.EX_HEAD : K.EX_HEAD + 3]
    tq = t + 0.6 * h
    fresh = K.track_motion(tq, EX, np.full(3, math.nan))
    TC = np.array([t, 0.5, 0.5])  # stale: remembers another time
    assert K.track_motion(tq, EX, TC) == fresh
    assert TC[0] == tq
    assert K.track_motion(tq, EX, TC) == fresh  # from the memo now
    arg = w * tq + ph
    closed = (amp * math.cos(arg), -amp * w * math.sin(arg), -amp * w * w * math.cos(arg))
    assert fresh == pytest.approx(closed, rel=1e-15)
    Y = np.empty(K.NY)
    K.dense_eval(0.6, RC, Y)
    K0 = np.empty((7, K.NY))
    K.rhs(tq, Y, -1, 0, 0.3, 1.0, P, EX, K0[0])
    K1 = K0.copy()
    out = [np.empty(K.NY) for _ in range(4)]
    K._step(tq, Y, h, K0, -1, 0, 0.3, 1.0, P, EX, out[0], out[1], TC)
    K._step(tq, Y, h, K1, -1, 0, 0.3, 1.0, P, EX, out[2], out[3], np.full(3, math.nan))
    np.testing.assert_array_equal(out[1], out[3])
    np.testing.assert_array_equal(K0, K1)
