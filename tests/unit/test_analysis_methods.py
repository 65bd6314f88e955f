"""The analysis methods on systems whose answers are known in closed form or published."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

from braidsim.analysis.bifurcation import refine_transition, transitions
from braidsim.analysis.lyapunov import LyapunovEstimate, benettin
from braidsim.analysis.reference import (
    LOGISTIC_FIRST_DOUBLING,
    LOGISTIC_SECOND_DOUBLING,
    LORENZ_LARGEST_EXPONENT,
    logistic_orbit,
    lorenz_advance,
)
from braidsim.analysis.regimes import classify, detect_period
from braidsim.analysis.spectra import amplitude_spectrum, dominant_peaks, harmonic_amplitudes
from braidsim.errors import InputError


def _logistic_period(r: float) -> int | None:
    # 2e5 discarded iterates: at |r - r_c| >= 1e-4 from a doubling the orbit has settled to
    # 1e-6 (the multiplier is 1 - O(|r - r_c|) there)
    return detect_period(logistic_orbit(r, transient=200_000, keep=64), 1e-6, 16)


def test_detect_period_of_known_sequences() -> None:
    assert detect_period(np.tile([0.1, 0.5, 0.9], 10), 1e-12, 8) == 3
    assert detect_period(np.ones(10), 0.0, 8) == 1
    z = np.column_stack([np.tile([1.0, 2.0], 8), np.tile([0.0, 0.0, 0.0, 1.0], 4)])
    assert detect_period(z, 1e-12, 8) == 4
    rng = np.random.default_rng(1)
    assert detect_period(rng.random(40), 1e-6, 12) is None
    # a period needs at least one full repetition
    assert detect_period(np.tile([0.1, 0.5, 0.9], 1), 1e-12, 8) is None


def test_logistic_map_period_doublings() -> None:
    """The first two period doublings of x -> r x (1 - x): r = 3 and r = 1 + sqrt(6)."""
    r = np.linspace(2.81, 3.555, 16)  # period 8 from 3.5441 to 3.5644
    periods = [_logistic_period(v) for v in r]
    tr = transitions(r, periods)
    assert [(t["from"], t["to"]) for t in tr] == [(1, 2), (2, 4), (4, 8)]
    assert tr[0]["lower"] < LOGISTIC_FIRST_DOUBLING < tr[0]["upper"]
    assert tr[1]["lower"] < LOGISTIC_SECOND_DOUBLING < tr[1]["upper"]
    lo, hi = refine_transition(_logistic_period, tr[0]["lower"], tr[0]["upper"], 1e-4)
    assert 0.5 * (lo + hi) == pytest.approx(LOGISTIC_FIRST_DOUBLING, abs=1e-3)
    lo, hi = refine_transition(_logistic_period, tr[1]["lower"], tr[1]["upper"], 1e-4)
    assert 0.5 * (lo + hi) == pytest.approx(LOGISTIC_SECOND_DOUBLING, abs=1e-3)


def test_refine_transition_needs_a_bracket() -> None:
    with pytest.raises(InputError, match="both ends"):
        refine_transition(lambda v: v > 10.0, 0.0, 1.0, 1e-3)


def test_lorenz_largest_exponent() -> None:
    """Benettin's method on the Lorenz system: 0.9056 (Sprott 2003) within 2 %."""
    adv = lorenz_advance()
    y0 = adv(np.array([1.0, 1.0, 1.0]), 50.0)  # onto the attractor
    d0 = 1e-8
    u = np.array([1.0, 1.0, 1.0]) / math.sqrt(3.0)
    est = benettin(
        adv,
        lambda a, b: float(np.linalg.norm(b - a)),
        lambda a, b, f: a + f * (b - a),
        y0,
        y0 + d0 * u,
        0.5,
        2000,
    )
    assert est.exponent == pytest.approx(LORENZ_LARGEST_EXPONENT, rel=0.02)
    assert est.running.size == 2000 and est.times[-1] == pytest.approx(1000.0)
    # the estimate's statistical error accounts for its distance from the known value
    se = est.standard_error()
    assert 0.0 < se < 0.02 * LORENZ_LARGEST_EXPONENT
    assert abs(est.exponent - LORENZ_LARGEST_EXPONENT) < 4 * se


def test_standard_error_of_independent_stretches_is_sigma_over_root_n() -> None:
    """Batch means on independent log-stretches of standard deviation s per interval tau:
    the standard error of the exponent is s / (tau sqrt(N)); 100 blocks estimate it to
    about 7 % (one standard deviation)."""
    rng = np.random.default_rng(7)
    tau, n, s = 0.1, 200_000, 0.3
    ls = 0.5 * tau + s * rng.standard_normal(n)
    times = tau * np.arange(1, n + 1)
    est = LyapunovEstimate(
        exponent=float(ls.sum() / (n * tau)),
        times=times,
        running=np.cumsum(ls) / times,
        log_stretch=ls,
        interval=tau,
        d0=1e-8,
    )
    assert est.standard_error(blocks=100) == pytest.approx(s / (tau * math.sqrt(n)), rel=0.25)
    assert math.isnan(est.standard_error(blocks=1))


@pytest.mark.parametrize(
    "A",
    [
        np.array([[0.3, 1.0], [0.0, -2.0]]),  # real eigenvalues 0.3, -2
        np.array([[-0.5, 4.0], [-4.0, -0.5]]),  # complex pair, real part -0.5
    ],
)
def test_benettin_on_linear_flow(A: np.ndarray) -> None:
    """x' = A x: the largest exponent is the largest real part of A's eigenvalues."""
    expected = float(np.max(np.linalg.eigvals(A).real))
    est = benettin(
        lambda y, t: expm(A * t) @ y,
        lambda a, b: float(np.linalg.norm(b - a)),
        lambda a, b, f: a + f * (b - a),
        np.zeros(2),
        np.array([1e-6, 1e-6]),
        0.25,
        800,
    )
    assert est.exponent == pytest.approx(expected, abs=0.01)


def test_amplitude_spectrum_reads_sinusoids() -> None:
    dt = 1e-3
    t = dt * np.arange(2000)  # 2 s: 50 Hz and 120 Hz fall on bins of 0.5 Hz
    y = 3.0 * np.sin(2 * np.pi * 50 * t) + 0.5 * np.cos(2 * np.pi * 120 * t + 0.3) + 7.0
    f, A = amplitude_spectrum(y, dt)
    assert f[1] == pytest.approx(0.5)
    pk = dominant_peaks(f, A, 2)
    assert [p["frequency"] for p in pk] == pytest.approx([50.0, 120.0], abs=1e-9)
    assert pk[0]["amplitude"] == pytest.approx(3.0, rel=1e-9)
    assert pk[1]["amplitude"] == pytest.approx(0.5, rel=1e-9)
    h = harmonic_amplitudes(f, A, 10.0, 12)
    assert h[4]["amplitude"] == pytest.approx(3.0, rel=1e-9)
    assert h[0]["amplitude"] < 1e-9


def test_amplitude_spectrum_between_bins() -> None:
    """Off-bin frequency: the parabola on log amplitudes refines the peak to a fraction of
    a bin (the Hann main lobe is close to a Gaussian)."""
    dt = 1e-3
    t = dt * np.arange(1000)  # bins of 1 Hz
    f, A = amplitude_spectrum(np.sin(2 * np.pi * 73.3 * t), dt)
    pk = dominant_peaks(f, A, 1)
    assert pk[0]["frequency"] == pytest.approx(73.3, abs=0.05)


def test_classification_rules() -> None:
    z2 = np.column_stack([np.tile([1e-4, 2e-4], 10), np.zeros(20)])
    common = dict(stick_time=2e-3, length_scale=1e-4, cycles=20.0)
    r = classify(
        contacts=False, inner_impacts=0, outer_impacts=0, longest_contact=0.0, strobe=z2, **common
    )
    assert r.label == "no_contact"
    r = classify(
        contacts=True, inner_impacts=0, outer_impacts=0, longest_contact=1.0, strobe=z2, **common
    )
    assert r.label == "resting_contact"
    r = classify(
        contacts=True, inner_impacts=20, outer_impacts=0, longest_contact=5e-3, strobe=z2, **common
    )
    assert (r.label, r.period) == ("chattering", 2)
    r = classify(
        contacts=True, inner_impacts=20, outer_impacts=20, longest_contact=4e-4, strobe=z2, **common
    )
    assert (r.label, r.period, r.walls, r.impacts_per_cycle) == ("periodic_two_sided", 2, "both", 2)
    noisy = np.column_stack([np.random.default_rng(0).random(20) * 1e-4, np.zeros(20)])
    r = classify(
        contacts=True,
        inner_impacts=20,
        outer_impacts=0,
        longest_contact=4e-4,
        strobe=noisy,
        **common,
    )
    assert (r.label, r.period, r.walls) == ("irregular", None, "inner")


def test_a_regime_class_prints_as_words() -> None:
    """The bifurcation verb and the demo printed the (label, period) tuples themselves."""
    from braidsim.analysis.bifurcation import class_text

    assert class_text(("periodic_one_sided", 2)) == "periodic_one_sided (period 2)"
    assert class_text(("irregular", None)) == "irregular"
