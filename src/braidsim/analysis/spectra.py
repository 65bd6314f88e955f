"""Amplitude spectra of displacement and contact force, dominant frequencies, harmonics.

One-sided amplitude spectrum of N uniform samples y_j (spacing dt), mean removed, with a
Hann window w_j = 0.5 (1 - cos(2 pi j / N)):

    A(f_k) = 2 |sum_j w_j y_j exp(-2 pi i j k / N)| / sum_j w_j,   f_k = k / (N dt)    [unit of y]

so that a sinusoid a cos(2 pi f t + phi) whose frequency falls on a bin reads A = a there
(Harris, Proc. IEEE 66 (1978) 51-83). Over a window of whole excitation cycles the
harmonics k omega_h / (2 pi) fall on bins; a motion of period q cycles adds the lines
k omega_h / (2 pi q) (subharmonics).

Dominant frequencies are the largest local maxima of A, the frequency refined by a
parabola through the log-amplitudes of the peak bin and its neighbours.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.errors import InputError

if TYPE_CHECKING:
    from braidsim.result import Result


def amplitude_spectrum(y: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(f [Hz], A [unit of y]) of uniform samples (module docstring)."""
    y = np.asarray(y, dtype=float)
    n = y.size
    if n < 4:
        raise InputError(f"spectrum: {n} samples; allowed at least 4")
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f"spectrum: sample spacing {dt!r} s; allowed > 0")
    w = 0.5 * (1.0 - np.cos(2.0 * math.pi * np.arange(n) / n))
    X = np.fft.rfft((y - y.mean()) * w)
    A = 2.0 * np.abs(X) / w.sum()
    A[0] = 0.0  # the mean is removed; its bin carries only window leakage
    f = np.fft.rfftfreq(n, dt)
    return f, A


def dominant_peaks(
    f: np.ndarray, A: np.ndarray, n: int = 8, rel: float = 1e-3
) -> list[dict[str, float]]:
    """The ``n`` largest local maxima of A above ``rel`` times the largest.

    Returns ``[{"frequency": Hz, "amplitude": A at the peak bin}]``, largest first.
    """
    if A.size < 3:
        return []
    top = float(A.max())
    if top <= 0:
        return []
    i = np.flatnonzero((A[1:-1] > A[:-2]) & (A[1:-1] >= A[2:]) & (A[1:-1] >= rel * top)) + 1
    i = i[np.argsort(A[i])[::-1]][:n]
    df = float(f[1] - f[0])
    out = []
    for k in i:
        a, b, c = (math.log(max(A[k + j], 1e-300)) for j in (-1, 0, 1))
        den = a - 2.0 * b + c
        shift = 0.5 * (a - c) / den if den < 0 else 0.0
        out.append({"frequency": float(f[k] + shift * df), "amplitude": float(A[k])})
    return out


def harmonic_amplitudes(
    f: np.ndarray, A: np.ndarray, f0: float, count: int = 10
) -> list[dict[str, float]]:
    """Amplitude at k f0, k = 1..count (the largest bin within half a bin of k f0)."""
    if f0 <= 0 or f.size < 2:
        return []
    df = float(f[1] - f[0])
    out = []
    for k in range(1, count + 1):
        fk = k * f0
        if fk > f[-1]:
            break
        sel = np.abs(f - fk) <= 0.5 * df + 1e-12 * fk
        amp = float(A[sel].max()) if sel.any() else 0.0
        out.append({"harmonic": k, "frequency": fk, "amplitude": amp})
    return out


@dataclass(frozen=True)
class Spectrum:
    """Spectrum of one quantity of a run.

    Attributes
    ----------
    quantity : str
        Series column.
    unit : str
        Its unit.
    frequency : np.ndarray
        f [Hz].
    amplitude : np.ndarray
        A [unit].
    window : (float, float)
        Time window [s].
    excitation_frequency : float
        omega_h / (2 pi) [Hz] (0: none).
    peaks : list of dict
        Dominant frequencies, largest first, each with ``ratio`` f / f_h.
    harmonics : list of dict
        Amplitude at the harmonics of the excitation.
    """

    quantity: str
    unit: str
    frequency: np.ndarray
    amplitude: np.ndarray
    window: tuple[float, float]
    excitation_frequency: float
    peaks: list[dict[str, float]]
    harmonics: list[dict[str, float]]

    def to_dict(self, arrays: bool = False) -> dict[str, Any]:
        """JSON-ready form (SI; frequencies in Hz)."""
        out: dict[str, Any] = {
            "quantity": self.quantity,
            "unit": self.unit,
            "window": list(self.window),
            "resolution": float(self.frequency[1] - self.frequency[0]),
            "excitation_frequency": self.excitation_frequency,
            "peaks": self.peaks,
            "harmonics": self.harmonics,
        }
        if arrays:
            out["frequency"] = self.frequency.tolist()
            out["amplitude"] = self.amplitude.tolist()
        return out


def run_spectra(
    result: Result,
    window: tuple[float | str, float | str] | None = None,
    quantities: Sequence[str] = ("x", "track_contact_force"),
    peaks: int = 8,
    harmonics: int = 10,
) -> list[Spectrum]:
    """Spectra of ``quantities`` over ``window`` from the run's uniform samples.

    The run must have been sampled uniformly (``sample_interval`` > 0, or uniform
    ``sample_times``); the event rows are left out. Best over whole excitation cycles.

    Raises
    ------
    InputError
        Too few samples in the window, non-uniform samples, or an unknown quantity.
    """
    from braidsim.core.layout import KIND_SAMPLE
    from braidsim.result import UNITS

    s = result.series
    samp = s["kind"] == KIND_SAMPLE
    t = s["t"][samp]
    if t.size < 4:
        raise InputError("spectrum: fewer than 4 samples; sample the run (sample_interval > 0)")
    # a half-open window [t0, t1): over whole cycles the sample at t1 repeats the phase of t0
    if window is None:
        t0, t1 = float(t[0]), float(t[-1])
    else:
        from braidsim.simulate import time_window

        span = float(result.windows[0, 0]), float(result.windows[0, 1])
        t0, t1 = time_window("window", window, *span)
    sel = (t >= t0 - 1e-12) & (t < t1 - 1e-9 * max(abs(t1), 1e-3))
    t = t[sel]
    if t.size < 4:
        raise InputError(
            "spectrum: fewer than 4 samples in the window; sample the run (sample_interval > 0)"
        )
    dts = np.diff(t)
    dt = float(np.median(dts))
    if np.max(np.abs(dts - dt)) > 1e-6 * dt:
        raise InputError("spectrum: the samples are not uniform in the window; use sample_interval")
    n = t.size
    w_h = float(result.model.scenario["track.vibration_frequency"])
    f_h = w_h / (2.0 * math.pi)
    out = []
    for q in quantities:
        if q not in s or q in ("t", "kind"):
            raise InputError(f"spectrum: unknown quantity {q!r}; allowed a series column, e.g. x")
        y = s[q][samp][sel][:n]
        f, A = amplitude_spectrum(y, dt)
        pk = dominant_peaks(f, A, peaks)
        for p in pk:
            p["ratio"] = p["frequency"] / f_h if f_h > 0 else math.nan
        out.append(
            Spectrum(
                q,
                UNITS.get(q, ""),
                f,
                A,
                (float(t[0]), float(t[n - 1] + dt)),
                f_h,
                pk,
                harmonic_amplitudes(f, A, f_h, harmonics),
            )
        )
    return out
