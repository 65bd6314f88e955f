"""Central differences of a shooting residual: the reference its exact Jacobian is checked
against (a derivative no one wrote by hand)."""

from __future__ import annotations

from typing import Any

import numpy as np


def residual_jacobian(shooter: Any, U: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """d r / d U of ``shooter.residual`` by central differences of step ``h`` in each of the
    scaled unknowns (error O(h^2) plus the maps' own error over h)."""
    cols = []
    for e in np.eye(U.size):
        cols.append((shooter.residual(U + h * e)[0] - shooter.residual(U - h * e)[0]) / (2 * h))
    return np.column_stack(cols)
