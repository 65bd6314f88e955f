"""The first step of a contact: the embedded error estimate misses the tau^n onset of a
power-law force, and the solver scales it by the ratio it computes from the tableau."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit
from scipy.integrate._ivp.rk import RK45

from braidsim.core import ImpactOscillator, PowerLawContact, run
from braidsim.core import layout as L
from braidsim.core.solver.dopri5 import onset_error_ratio as _compiled_ratio


@njit
def onset_error_ratio(q: float) -> float:
    """The solver's helper, called as the solver calls it: from compiled code."""
    return _compiled_ratio(q)


def _ratio_from_scipy_tableau(n: float) -> float:
    """True local error over estimated error of one Dormand-Prince step of x'' = tau^n from
    rest at tau = 0, with SciPy's coefficients of the pair (written apart from braidsim's)."""
    A, B, C, E = RK45.A, RK45.B, RK45.C, RK45.E
    k = np.array([c**n for c in C] + [1.0])  # speed derivatives at the stages, then at tau = 1
    v = np.array([A[s, :s] @ k[:s] for s in range(len(C))] + [B @ k[: len(C)]])
    x1 = B @ v[: len(C)]
    err_v = abs((v[-1] - 1.0 / (n + 1.0)) / (E @ k))
    err_x = abs((x1 - 1.0 / ((n + 1.0) * (n + 2.0))) / (E @ v))
    return max(1.0, err_v, err_x)


@pytest.mark.parametrize("n", [0.5, 1.25, 1.5, 2.2, 2.5])
def test_ratio_matches_an_independent_tableau(n: float) -> None:
    assert onset_error_ratio(n + 1.0) == pytest.approx(_ratio_from_scipy_tableau(n), rel=1e-12)


def test_hertz_ratio_and_integer_exponents() -> None:
    # the Hertz exponent: the speed's error estimate is 11.3 times too small
    assert onset_error_ratio(2.5) == pytest.approx(11.342, abs=1e-3)
    # a linear spring (n = 1) or a force that jumps at onset: polynomial, the estimate holds
    assert onset_error_ratio(2.0) == 1.0
    assert onset_error_ratio(1.0) == 1.0


@pytest.mark.parametrize("v", [0.05, 0.4, 2.0])
@pytest.mark.parametrize("rtol", [1e-6, 1e-8])
def test_an_elastic_hertz_impact_rebounds_at_its_approach_speed(v: float, rtol: float) -> None:
    """Energy is conserved by an undamped Hertz contact: the body leaves at the speed it
    came. With the onset step's estimate corrected the rebound speed is right to 2 rtol
    (measured: 1.2 rtol at most); trusting the estimate left errors of 10 to 90 rtol."""
    m, K, gap = 1.2, 2.5e10, 1e-3
    model = ImpactOscillator(
        m, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, gap, PowerLawContact(K, 1.5, 0.0)
    )
    opts = L.SolverOptions(
        rtol=rtol,
        atol_position=1e-5 * rtol,
        atol_velocity=0.1 * rtol,
        max_step=1e-3,
        max_steps=10**7,
        t_end=gap / v + 0.01,
    )
    raw = run(model, opts, np.array([0.0, v, 0.0, 0.0, 0.0]))
    (ep,) = raw.episodes
    assert abs(ep["rebound_velocity"] / ep["velocity"] - 1.0) <= 2.0 * rtol
