"""Kinematics of the machine: horn-gear rotation and its inverse, the speed profile over the
transfer cycle, carrier speed, braid angle and production rate.

Horn-gear rotation
------------------
Every gear turns through ``Omega(t) = int_0^t omega(t') dt'`` [rad], with ``omega(t)`` the
carrier model's horn-gear speed (constant, harmonics or a periodic piecewise-linear profile;
:func:`braidsim.core.horn_gear_state` evaluates it, and this module calls that same
compiled function so that the transfer times agree with the slot motion the solver integrates).
A carrier transfers when ``Omega`` reaches the angle of its next crossing
(:meth:`~braidsim.machine.geometry.MachineGeometry.transfer_events`); the transfer *times*
follow by inverting ``Omega(t)`` (:meth:`SpeedLaw.time_at_angle`), not from ``angle/omega``
unless the speed is constant.

Speed profile over the transfer cycle
-------------------------------------
Slots meet somewhere in the machine every ``Theta_c`` of horn-gear rotation (the transfer
cycle, pi/4 for 8 gears with 4 slots), and ``Omega = 0`` is such a meeting. A profile given as
relative speeds ``f(phase)`` at phases ``0 <= phase <= 1`` of the cycle, piecewise linear and
periodic (``f(0) = f(1)``), is scaled so that its time mean is 1 and becomes the kernel's
``horn_gear.speed_profile`` with times ``phase * T_c``, ``T_c = Theta_c / omega_mean``, and
speeds ``omega_mean * f``. Each cycle then turns the gears through exactly ``Theta_c``, so
phase 0 falls on every slot meeting and the mean speed, hence the production rate, is that of
the constant-speed machine.

Designer's kinematics (Kyosev 2015, ch. 4)
------------------------------------------
A carrier goes round the machine once per horn-gear rotation ``N pi``: its mean angular speed
about the machine axis is ``omega_c = 2 omega_mean / N`` [rad/s] and its speed along the path
``r omega`` [m/s]. With a mandrel of radius ``r_m`` taken up at speed ``v`` the braid angle
(between yarn and braid axis) is ``tan(alpha) = omega_c r_m / v``; the production rate is
``v`` (braid length per unit time) and one carrier revolution lays the lead
``2 pi r_m / tan(alpha)``.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from braidsim.core import horn_gear_state
from braidsim.errors import InputError
from braidsim.model import Model
from braidsim.units import to_si


@njit(cache=True, error_model="numpy")
def _rotation(ts, hg, om_out, ang_out):  # pragma: no cover - compiled
    rc = hg.turning_radius
    for i in range(ts.shape[0]):
        om, s = horn_gear_state(hg, ts[i])
        om_out[i] = om
        ang_out[i] = s / rc


@njit(cache=True, error_model="numpy")
def _invert(targets, hg, omega_min, omega_mean, out):  # pragma: no cover - compiled
    """Times at which Omega(t) reaches the increasing ``targets`` (Omega(0) = 0, omega >=
    omega_min > 0): bracket [lo, lo + (target - Omega(lo)) / omega_min], then Newton steps
    kept inside the bracket (bisection when a step leaves it)."""
    rc = hg.turning_radius
    lo = 0.0
    a_lo = 0.0
    for i in range(targets.shape[0]):
        th = targets[i]
        if th <= a_lo:
            out[i] = lo
            continue
        hi = lo + (th - a_lo) / omega_min
        t = lo + (th - a_lo) / omega_mean
        t = min(max(t, lo), hi)
        l, h = lo, hi
        for _ in range(200):
            om, s = horn_gear_state(hg, t)
            f = s / rc - th
            if abs(f) <= 1e-14 * max(1.0, abs(th)):
                break
            if f < 0.0:
                l = t
            else:
                h = t
            tn = t - f / om if om > 0.0 else 0.5 * (l + h)
            if not (l < tn < h):
                tn = 0.5 * (l + h)
            if h - l <= 4e-16 * max(1.0, h):
                t = tn
                break
            t = tn
        out[i] = t
        lo = t
        a_lo = th


@dataclass(frozen=True)
class SpeedLaw:
    """The horn-gear speed of a carrier model and its rotation angle.

    Attributes
    ----------
    model : Model
        The compiled model whose ``omega(t)`` it evaluates.
    mean : float
        Long-time mean speed omega_mean [rad/s].
    minimum : float
        A positive lower bound of omega(t) [rad/s].
    """

    model: Model
    mean: float
    minimum: float

    @classmethod
    def from_model(cls, model: Model) -> SpeedLaw:
        """Mean and lower bound of omega(t) from the model's speed tables.

        Raises
        ------
        InputError
            omega(t) can reach 0 or below (the gears would stop or reverse).
        """
        hg = model.horn_gear
        if hg.profile_times.size:
            t, w = hg.profile_times, hg.profile_speeds
            mean = float(hg.profile_integral[-1] / (t[-1] - t[0]))
            low = float(w.min())
            what = "horn_gear.speed_profile: the speeds"
        else:
            w0 = float(hg.omega0)
            H = hg.harmonics
            steady = float(sum(a * math.cos(ph) for a, f, ph in H if f == 0.0))
            mean = w0 + steady
            low = w0 + steady - float(sum(abs(a) for a, f, _ in H if f > 0.0))
            what = "horn_gear.angular_velocity minus the harmonic amplitudes"
        if not low > 0.0:
            raise InputError(
                f"{what} reach {low:g} rad/s; allowed > 0 rad/s: the gears of a machine must keep "
                "turning forward"
            )
        return cls(model, mean, low)

    def rotation(self, t: Sequence[float] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(omega(t) [rad/s], Omega(t) [rad])`` at times ``t`` [s]."""
        ts = np.ascontiguousarray(np.asarray(t, dtype=float).reshape(-1))
        om = np.empty_like(ts)
        ang = np.empty_like(ts)
        _rotation(ts, self.model.horn_gear, om, ang)
        return om, ang

    def time_at_angle(self, angles: Sequence[float] | np.ndarray) -> np.ndarray:
        """Times [s] at which the gears have turned through ``angles`` [rad] (>= 0), to
        about 1e-14 relative."""
        a = np.asarray(angles, dtype=float).reshape(-1)
        if a.size == 0:
            return np.zeros(0)
        if np.any(a < 0) or not np.all(np.isfinite(a)):
            raise ValueError("angles must be finite and >= 0")
        order = np.argsort(a, kind="stable")
        out = np.empty(a.size)
        sorted_t = np.empty(a.size)
        _invert(
            np.ascontiguousarray(a[order]),
            self.model.horn_gear,
            self.minimum,
            self.mean,
            sorted_t,
        )
        out[order] = sorted_t
        return out


def cycle_profile(
    phases: Sequence[float], factors: Sequence[float], mean_speed: float, cycle_angle: float
) -> tuple[dict[str, list[float]], float]:
    """A speed profile over the transfer cycle with the mean speed held.

    Parameters
    ----------
    phases : sequence of float
        Phases of the cycle, strictly increasing from 0 to 1 (0: a slot meeting).
    factors : sequence of float
        Relative speeds (> 0) at those phases, piecewise linear, ``factors[0] == factors[-1]``.
    mean_speed : float
        omega_mean [rad/s].
    cycle_angle : float
        Horn-gear rotation of one cycle Theta_c [rad].

    Returns
    -------
    profile : dict
        ``{"times": [...], "speeds": [...]}`` for ``horn_gear.speed_profile`` [s, rad/s].
    scale : float
        The factor applied to ``factors`` so that their time mean (trapezoidal rule, exact for
        a piecewise-linear profile) is 1.
    """
    p = np.asarray(phases, dtype=float)
    f = np.asarray(factors, dtype=float)
    key = "machine.speed_profile"
    if p.ndim != 1 or f.ndim != 1 or p.size != f.size or p.size < 2:
        raise InputError(f"{key}: phase and factor need the same length >= 2")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(f))):
        raise InputError(f"{key}: non-finite entry; allowed finite numbers")
    if p[0] != 0.0 or p[-1] != 1.0 or np.any(np.diff(p) <= 0.0):
        raise InputError(
            f"{key}.phase: {p.tolist()} is not allowed; allowed strictly increasing from 0 to 1"
        )
    if np.any(f <= 0.0):
        raise InputError(f"{key}.factor: {f.tolist()} has a value <= 0; allowed > 0")
    if not math.isclose(f[0], f[-1], rel_tol=1e-12, abs_tol=0.0):
        raise InputError(
            f"{key}.factor: first ({f[0]:g}) and last ({f[-1]:g}) differ; allowed equal "
            "(the profile repeats every cycle without a jump in speed)"
        )
    mean = float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(p)))
    scale = 1.0 / mean
    period = cycle_angle / mean_speed
    return {
        "times": (p * period).tolist(),
        "speeds": (f * scale * mean_speed).tolist(),
    }, scale


def _positive(key: str, value: float | str, unit: str) -> float:
    """``value`` (a number in SI or a string with a unit) in ``unit``; an InputError unless
    it is finite and > 0."""
    v = to_si(key, value, unit)
    if not (math.isfinite(v) and v > 0.0):
        raise InputError(f"{key}: {v:g} {unit} is out of range; allowed > 0 {unit}")
    return v


def _horn_gears(horn_gears: int) -> int:
    """``horn_gears`` as an int; an InputError unless it is an even integer from 4 to 1000,
    as a machine's (:class:`~braidsim.machine.geometry.MachineGeometry`)."""
    if (
        isinstance(horn_gears, bool)
        or not isinstance(horn_gears, numbers.Integral)
        or not 4 <= horn_gears <= 1000
        or horn_gears % 2
    ):
        raise InputError(
            f"horn_gears: {horn_gears!r} is out of range; allowed an even integer from 4 to 1000"
        )
    return int(horn_gears)


def carrier_angular_speed(mean_speed: float | str, horn_gears: int) -> float:
    """Mean angular speed of a carrier about the machine axis, omega_c = 2 omega / N [rad/s],
    from the horn gears' mean speed omega > 0 [rad/s] (or a string with a unit, ``"120 rpm"``)
    and their number N (even, 4 to 1000)."""
    return 2.0 * _positive("mean_speed", mean_speed, "rad/s") / _horn_gears(horn_gears)


def revolution_time(mean_speed: float | str, horn_gears: int) -> float:
    """Time of one carrier revolution round the machine, N pi / omega [s] (arguments as in
    :func:`carrier_angular_speed`)."""
    return _horn_gears(horn_gears) * math.pi / _positive("mean_speed", mean_speed, "rad/s")


def braid_angle(
    carrier_speed: float | str, mandrel_radius: float | str, take_up_speed: float | str
) -> float:
    """Braid angle alpha [rad] from tan(alpha) = omega_c r_m / v: the carrier's angular
    speed omega_c [rad/s], the mandrel radius r_m [m] and the take-up speed v [m/s], each > 0
    (numbers in SI or strings with a unit)."""
    wc = _positive("carrier_speed", carrier_speed, "rad/s")
    rm = _positive("mandrel_radius", mandrel_radius, "m")
    v = _positive("take_up_speed", take_up_speed, "m/s")
    return math.atan2(wc * rm, v)


def take_up_speed(
    carrier_speed: float | str, mandrel_radius: float | str, angle: float | str
) -> float:
    """Take-up speed v = omega_c r_m / tan(alpha) [m/s] for a braid angle 0 < alpha < pi/2
    [rad] (numbers in SI or strings with a unit, ``"30 deg"``)."""
    wc = _positive("carrier_speed", carrier_speed, "rad/s")
    rm = _positive("mandrel_radius", mandrel_radius, "m")
    a = to_si("angle", angle, "rad")
    if not 0.0 < a < 0.5 * math.pi:
        raise InputError(f"angle: {a:g} rad is out of range; allowed 0 < angle < pi/2 rad")
    return wc * rm / math.tan(a)
