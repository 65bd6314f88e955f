"""Textbook systems with known answers, used to check the analysis methods.

* The logistic map x -> r x (1 - x): period 1 is stable for 1 < r < 3, doubles to period 2
  at r = 3 and to period 4 at r = 1 + sqrt(6) = 3.449490 (May, Nature 261 (1976) 459-467).
* The Lorenz system x' = sigma (y - x), y' = x (rho - z) - y, z' = x y - beta z with
  sigma = 10, rho = 28, beta = 8/3: largest Lyapunov exponent 0.9056 (Sprott, Chaos and
  Time-Series Analysis, Oxford 2003, Table A.1 and p. 116; Wolf et al., Physica D 16 (1985)
  285-317 give 0.90).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numba import njit

LORENZ_LARGEST_EXPONENT = 0.9056
"""Largest Lyapunov exponent of the Lorenz system at (10, 28, 8/3) [1/time] (Sprott 2003)."""
LOGISTIC_FIRST_DOUBLING = 3.0
LOGISTIC_SECOND_DOUBLING = 1.0 + math.sqrt(6.0)


def logistic_orbit(
    r: float, transient: int = 20_000, keep: int = 256, x0: float = 0.2
) -> np.ndarray:
    """``keep`` iterates of the logistic map after ``transient`` discarded ones."""
    return _logistic(float(r), int(transient), int(keep), float(x0))


@njit(cache=True)
def _logistic(r: float, transient: int, keep: int, x0: float) -> np.ndarray:
    x = x0
    for _ in range(transient):
        x = r * x * (1.0 - x)
    out = np.empty(keep)
    for i in range(keep):
        x = r * x * (1.0 - x)
        out[i] = x
    return out


@njit(cache=True)
def _lorenz_rk4(y: np.ndarray, T: float, dt: float, s: float, r: float, b: float) -> np.ndarray:
    """Classical RK4 over [0, T] with n = ceil(T/dt) equal steps."""
    n = max(1, int(T / dt - 1e-9) + 1)  # ceil(T / dt), tolerant of rounding
    h = T / n
    x0, y0, z0 = y[0], y[1], y[2]
    for _ in range(n):
        k1x, k1y, k1z = s * (y0 - x0), x0 * (r - z0) - y0, x0 * y0 - b * z0
        ax, ay, az = x0 + 0.5 * h * k1x, y0 + 0.5 * h * k1y, z0 + 0.5 * h * k1z
        k2x, k2y, k2z = s * (ay - ax), ax * (r - az) - ay, ax * ay - b * az
        ax, ay, az = x0 + 0.5 * h * k2x, y0 + 0.5 * h * k2y, z0 + 0.5 * h * k2z
        k3x, k3y, k3z = s * (ay - ax), ax * (r - az) - ay, ax * ay - b * az
        ax, ay, az = x0 + h * k3x, y0 + h * k3y, z0 + h * k3z
        k4x, k4y, k4z = s * (ay - ax), ax * (r - az) - ay, ax * ay - b * az
        x0 += h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
        y0 += h / 6.0 * (k1y + 2.0 * k2y + 2.0 * k3y + k4y)
        z0 += h / 6.0 * (k1z + 2.0 * k2z + 2.0 * k3z + k4z)
    out = np.empty(3)
    out[0], out[1], out[2] = x0, y0, z0
    return out


def lorenz_advance(
    sigma: float = 10.0, rho: float = 28.0, beta: float = 8.0 / 3.0, dt: float = 0.005
) -> Callable[[np.ndarray, float], np.ndarray]:
    """``advance(state, T)`` of the Lorenz flow (classical RK4, step <= ``dt``)."""

    def advance(state: np.ndarray, T: float) -> np.ndarray:
        return _lorenz_rk4(np.asarray(state, dtype=float), float(T), dt, sigma, rho, beta)

    return advance
