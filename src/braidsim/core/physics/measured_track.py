"""A track vibration from a measured record: displacement samples, interpolated.

The walls follow h(t), the cubic spline through a measured record (t_k, h_k) (from a laser
displacement sensor, or an accelerometer record integrated twice), repeated with the
record's period t_last - t_first outside it (a record of whole vibration cycles). h' and
h'' are the spline's derivatives, so the solver sees a motion with continuous acceleration
(piecewise linear), whose largest |h''| is reached at a knot.

:func:`MeasuredTrack.from_csv` reads a CSV file with a header row and the columns ``t``
[s] and ``h`` [m] (a name may carry its unit in brackets: ``h [mm]``, ``t [ms]``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from braidsim.core.generic import helper, inline_helper
from braidsim.core.interfaces import wall_accel_bound, wall_motion, wall_motion_jvp, wall_series

_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "m": 1.0, "mm": 1e-3, "um": 1e-6}


class MeasuredTrack(NamedTuple):
    """The cubic spline through a displacement record (module docstring).

    ``coeffs[:, i]`` are the coefficients (c3, c2, c1, c0) of the piece on
    [times[i], times[i + 1]]: h = c3 s^3 + c2 s^2 + c1 s + c0 with s = t - times[i].
    """

    times: np.ndarray  # knots [s], increasing
    coeffs: np.ndarray  # (4, n - 1)
    # the largest |h''| [m/s^2], computed once by from_samples (the solver's contact screen
    # asks for it at every step, and a record has thousands of pieces); < 0: not given,
    # computed from the pieces at every call
    accel_bound: float = -1.0

    @classmethod
    def from_samples(cls, times: np.ndarray, h: np.ndarray) -> MeasuredTrack:
        """The periodic cubic spline through (times, h); the record must close (h[-1] =
        h[0]) to be periodic, else it is closed by its first value."""
        from scipy.interpolate import CubicSpline

        t = np.asarray(times, dtype=float)
        y = np.asarray(h, dtype=float).copy()
        if t.ndim != 1 or t.size < 4 or y.shape != t.shape:
            raise ValueError("a track record needs at least 4 samples of t and h")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y)) and np.all(np.diff(t) > 0)):
            raise ValueError("a track record needs finite h and strictly increasing times")
        y[-1] = y[0]
        spline = CubicSpline(t, y, bc_type="periodic")
        c = np.ascontiguousarray(spline.c)
        return cls(t, c, _largest_accel(t, c))

    @classmethod
    def from_csv(cls, path: str | Path) -> MeasuredTrack:
        """Read columns ``t`` and ``h`` (units in brackets allowed) of a CSV file."""
        import pandas as pd

        frame = pd.read_csv(path)
        cols: dict[str, np.ndarray] = {}
        for name in frame.columns:
            base, _, unit = str(name).partition("[")
            unit = unit.rstrip("] ").strip() or ("s" if base.strip() == "t" else "m")
            if unit not in _UNITS:
                raise ValueError(f"{path}: column {name!r}: unknown unit {unit!r}")
            cols[base.strip()] = frame[name].to_numpy(dtype=float) * _UNITS[unit]
        if "t" not in cols or "h" not in cols:
            raise ValueError(f"{path}: a track record needs the columns t and h")
        return cls.from_samples(cols["t"], cols["h"])


@helper
def _piece(tr, t):
    """(index of the piece, local time s) of t, the record repeated with its period."""
    ts = tr.times
    n = ts.shape[0]
    period = ts[n - 1] - ts[0]
    tau = t - ts[0]
    tau -= math.floor(tau / period) * period
    i = np.searchsorted(ts, ts[0] + tau, side="right") - 1
    if i > n - 2:
        i = n - 2
    if i < 0:
        i = 0
    return i, ts[0] + tau - ts[i]


@inline_helper
def _cubic(ex, t):
    """(piece index, local time s, c3, c2, c1, c0): the cubic c3 s^3 + c2 s^2 + c1 s + c0 of
    the piece holding t."""
    i, s = _piece(ex, t)
    c = ex.coeffs
    return i, s, c[0, i], c[1, i], c[2, i], c[3, i]


@wall_motion.register(MeasuredTrack)
def _motion(ex, t):
    _, s, c3, c2, c1, c0 = _cubic(ex, t)
    h = ((c3 * s + c2) * s + c1) * s + c0
    hd = (3.0 * c3 * s + 2.0 * c2) * s + c1
    hdd = 6.0 * c3 * s + 2.0 * c2
    return h, hd, hdd


@wall_series.register(MeasuredTrack)
def _series(ex, t, order, H):
    # the cubic c3 s^3 + c2 s^2 + c1 s + c0 of the piece holding t, about its local time s:
    # h(t + tau) = h + h' tau + (3 c3 s + c2) tau^2 + c3 tau^3, up to the piece's end
    i, s, c3, c2, c1, c0 = _cubic(ex, t)
    H[0] = ((c3 * s + c2) * s + c1) * s + c0
    for k in range(1, order + 1):
        H[k] = 0.0
    if order >= 1:
        H[1] = (3.0 * c3 * s + 2.0 * c2) * s + c1
    if order >= 2:
        H[2] = 3.0 * c3 * s + c2
    if order >= 3:
        H[3] = c3
    return max(ex.times[i + 1] - ex.times[i] - s, 0.0)


@wall_motion_jvp.register(MeasuredTrack)
def _motion_jvp(ex, dex, t):
    # the spline is linear in its coefficients (the knots are fixed)
    i, s = _piece(ex, t)
    c = dex.coeffs
    h = ((c[0, i] * s + c[1, i]) * s + c[2, i]) * s + c[3, i]
    hd = (3.0 * c[0, i] * s + 2.0 * c[1, i]) * s + c[2, i]
    hdd = 6.0 * c[0, i] * s + 2.0 * c[1, i]
    return h, hd, hdd


def _largest_accel(times: np.ndarray, c: np.ndarray) -> float:
    """max |h''| of the spline: h'' is linear on each piece, so the largest magnitude is
    at a knot, an end of a piece."""
    dt = np.diff(times)
    return float(max(np.max(np.abs(2.0 * c[1])), np.max(np.abs(6.0 * c[0] * dt + 2.0 * c[1]))))


@wall_accel_bound.register(MeasuredTrack)
def _bound(ex):
    if ex.accel_bound >= 0.0:
        return ex.accel_bound
    # h'' is linear on each piece: its largest magnitude is at a knot
    c = ex.coeffs
    acc = 0.0
    for i in range(c.shape[1]):
        dt = ex.times[i + 1] - ex.times[i]
        a0 = abs(2.0 * c[1, i])
        a1 = abs(6.0 * c[0, i] * dt + 2.0 * c[1, i])
        acc = max(acc, a0, a1)
    return acc
