"""Horn-gear speed profiles over the transfer cycle, with the mean speed held exactly.

Every slot meeting of the machine is a transfer of some carrier (a 16-carrier machine with
8 four-slot gears has 4 transfers at each meeting, one meeting every ``Theta_c = pi/4`` of
gear rotation), and all horn gears turn together, so a speed profile that treats every
transfer alike repeats with the transfer cycle ``T_c = Theta_c / omega_mean`` (62.5 ms at
120 rpm). A profile is a relative speed ``f(phase)``, ``0 <= phase < 1`` of the cycle, with
phase 0 at a slot meeting, and

    omega(t) = omega_mean * f(t / T_c),   mean of f over a cycle = 1 exactly,

so the gears turn through exactly ``Theta_c`` per cycle: the transfers stay at the slot
meetings and the production rate (set by the mean speed) is that of the constant-speed
machine. Time derivatives follow from the phase derivatives:
``omega' = omega_mean f'(phase) / T_c`` [rad/s^2], ``omega'' = omega_mean f''(phase) / T_c^2``
[rad/s^3].

Families
--------
``dip`` (5 parameters): a slow plateau at relative speed ``level`` from phase ``start``
(usually just before the transfer at phase 0) for ``length`` of the cycle, entered by a ramp
of width ``ramp_down`` and left by a ramp of width ``ramp_up``; the rest of the cycle runs at
the fast level ``H`` that holds the mean::

    g(phase) = 0 (fast) ... S(.) over ramp_down ... 1 (slow plateau) ... 1 - S(.) over ramp_up
    f = H - (H - level) g,    mean(g) = length + (ramp_down + ramp_up) / 2,
    H = (1 - level mean(g)) / (1 - mean(g)),

with the cubic smoothstep ``S(u) = 3u^2 - 2u^3`` (zero slope at both ends: the acceleration is
continuous, the jerk bounded). Its extremes are closed-form: ``max|f'| = 1.5 (H - level)/w``
and ``max|f''| = 6 (H - level)/w^2`` for a ramp of width ``w``. ``level = 1`` is the constant
speed (no dip).

``fourier`` (2K parameters): ``f = 1 + sum_k a_k cos(2 pi k phase) + b_k sin(2 pi k phase)``,
k = 1..K: mean 1 by construction.

``dip+fourier`` (5 + 2K): the dip plus K harmonics that reshape it.

What the kernel runs
--------------------
The carrier model takes a periodic piecewise-linear ``omega(t)``
(:func:`braidsim.machine.kinematics.cycle_profile`, ``[machine.speed_profile]`` of a machine
spec). :meth:`SpeedProfile.table` samples ``f`` at nodes (every corner of the dip, ``ramp_nodes``
segments per ramp, a uniform grid for harmonics); ``cycle_profile`` rescales the table so that
its exact (trapezoidal) mean is 1, so the simulated mean speed is exact, and the table can be
pasted into a machine spec and run with ``braidsim machine``. The largest difference between the
smooth profile and the table is reported (:meth:`SpeedProfile.table_error`).

Limits
------
:class:`Limits`: ``min_speed <= f <= max_speed`` (fractions of the mean), ``|omega'| <=
max_acceleration``, ``|omega''| <= max_jerk``. :func:`limit_margins` evaluates them on the
smooth profile (dense grid plus every corner and ramp midpoint, where the cubic ramps take
their extremes) and returns each margin (>= 0: satisfied).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from braidsim.errors import InputError

FAMILIES = ("dip", "fourier", "dip+fourier")
DIP_NAMES = ("level", "start", "length", "ramp_down", "ramp_up")
DENSE = 4096
"""Points of the dense phase grid on which limits of harmonic profiles are evaluated."""


@dataclass(frozen=True)
class Limits:
    """Motion limits of the horn-gear drive.

    Attributes
    ----------
    min_speed : float
        Lowest speed as a fraction of the mean (> 0: the gears keep turning forward).
    max_speed : float
        Highest speed as a fraction of the mean (the drive's top speed).
    max_acceleration : float
        Largest |omega'| [rad/s^2].
    max_jerk : float
        Largest |omega''| [rad/s^3].

    Defaults (engineering estimates for the horn-gear drive of a braider, not catalogue
    values): the gears never drop below a quarter of the mean speed nor exceed twice it
    (240 rpm for a machine rated 120 rpm: gear trains of this kind are built for about
    that); ``max_acceleration = 1000 rad/s^2`` puts a tangential acceleration
    ``r_c omega'`` of 65 m/s^2 (6.6 g) on a carrier of the paper's 65 mm turning radius, the
    order of what a servo drive reaches on the machine's inertia within its peak torque
    (:mod:`braidsim.design.drive`); ``max_jerk = 2e5 rad/s^3`` takes 5 ms to reach that
    acceleration, gentle enough for a gear train with backlash.
    """

    min_speed: float = 0.25
    max_speed: float = 2.0
    max_acceleration: float = 1000.0
    max_jerk: float = 2.0e5

    def __post_init__(self) -> None:
        if not (0.0 < self.min_speed < 1.0):
            raise InputError(
                f"design.limits.min_speed: {self.min_speed:g} is out of range; allowed "
                "0 < min_speed < 1 (a fraction of the mean speed)"
            )
        if not (1.0 < self.max_speed <= 100.0):
            raise InputError(
                f"design.limits.max_speed: {self.max_speed:g} is out of range; allowed "
                "1 < max_speed <= 100 (a fraction of the mean speed)"
            )
        for name in ("max_acceleration", "max_jerk"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise InputError(f"design.limits.{name}: {v:g} is out of range; allowed > 0")

    def to_dict(self) -> dict[str, float]:
        """SI values (speeds as fractions of the mean)."""
        return {
            "min_speed": self.min_speed,
            "max_speed": self.max_speed,
            "max_acceleration": self.max_acceleration,
            "max_jerk": self.max_jerk,
        }


def _smoothstep(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """S(u) = 3u^2 - 2u^3 on [0, 1] and its first two derivatives."""
    return u * u * (3.0 - 2.0 * u), 6.0 * u * (1.0 - u), 6.0 - 12.0 * u


@dataclass(frozen=True)
class SpeedProfile:
    """One relative speed profile f(phase) over the transfer cycle (module docstring).

    Attributes
    ----------
    family : str
        ``dip``, ``fourier`` or ``dip+fourier``.
    params : dict
        Named parameters (dip: level, start, length, ramp_down, ramp_up; harmonics: a1, b1,
        ...); phases and widths in cycles.
    ramp_nodes : int
        Linear segments per ramp in :meth:`table`.
    """

    family: str
    params: dict[str, float] = field(default_factory=dict)
    ramp_nodes: int = 32

    # ------------------------------------------------------------------ parts
    @property
    def has_dip(self) -> bool:
        return self.family in ("dip", "dip+fourier")

    @property
    def harmonics(self) -> int:
        return sum(1 for k in self.params if k.startswith("a"))

    def dip_geometry(self) -> tuple[float, float, float, float, float]:
        """(level, start, length, ramp_down, ramp_up) of the dip."""
        p = self.params
        return (p["level"], p["start"], p["length"], p["ramp_down"], p["ramp_up"])

    def fit_margin(self) -> float:
        """1 - (length + ramp_down + ramp_up) [cycles]: >= 0 when the dip fits in a cycle."""
        if not self.has_dip:
            return 1.0
        _, _, ln, wd, wu = self.dip_geometry()
        return 1.0 - (ln + wd + wu)

    def fast_level(self) -> float:
        """H, the relative speed outside the dip that holds the mean (1 without a dip)."""
        if not self.has_dip:
            return 1.0
        L, _, ln, wd, wu = self.dip_geometry()
        gbar = ln + 0.5 * (wd + wu)
        if gbar >= 1.0:
            return math.inf
        return (1.0 - L * gbar) / (1.0 - gbar)

    @property
    def is_constant(self) -> bool:
        """True when f = 1 everywhere (no dip depth and no harmonic)."""
        flat_dip = (not self.has_dip) or self.params["level"] == 1.0
        return flat_dip and all(v == 0.0 for k, v in self.params.items() if k[0] in "ab")

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, phase: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """f, df/dphase, d2f/dphase2 at ``phase`` (any real; the profile has period 1)."""
        ph = np.asarray(phase, dtype=float)
        f = np.ones_like(ph)
        d1 = np.zeros_like(ph)
        d2 = np.zeros_like(ph)
        if self.has_dip and self.fit_margin() >= 0.0:
            L, a, ln, wd, wu = self.dip_geometry()
            H = self.fast_level()
            y = np.mod(ph - (a - wd), 1.0)  # 0 at the start of the ramp down
            g = np.zeros_like(ph)
            g1 = np.zeros_like(ph)
            g2 = np.zeros_like(ph)
            if wd > 0.0:
                m = y < wd
                s, s1, s2 = _smoothstep(y[m] / wd)
                g[m], g1[m], g2[m] = s, s1 / wd, s2 / (wd * wd)
            m = (y >= wd) & (y < wd + ln)
            g[m] = 1.0
            if wu > 0.0:
                m = (y >= wd + ln) & (y < wd + ln + wu)
                s, s1, s2 = _smoothstep((y[m] - wd - ln) / wu)
                g[m], g1[m], g2[m] = 1.0 - s, -s1 / wu, -s2 / (wu * wu)
            f = H - (H - L) * g
            d1 = -(H - L) * g1
            d2 = -(H - L) * g2
        for k in range(1, self.harmonics + 1):
            a_k = self.params[f"a{k}"]
            b_k = self.params[f"b{k}"]
            w = 2.0 * math.pi * k
            c, s = np.cos(w * ph), np.sin(w * ph)
            f = f + a_k * c + b_k * s
            d1 = d1 + w * (-a_k * s + b_k * c)
            d2 = d2 - w * w * (a_k * c + b_k * s)
        return f, d1, d2

    def corners(self) -> np.ndarray:
        """Phases in [0, 1) of the dip's corners and ramp midpoints (where |f'| and |f''| of
        the cubic ramps peak)."""
        if not self.has_dip:
            return np.zeros(0)
        _, a, ln, wd, wu = self.dip_geometry()
        c = [a - wd, a - 0.5 * wd, a, a + ln, a + ln + 0.5 * wu, a + ln + wu]
        return np.unique(np.mod(np.array(c), 1.0))

    def check_points(self) -> np.ndarray:
        """Dense grid plus corners (and points just inside each corner, where a cubic ramp's
        second derivative is largest)."""
        grid = np.linspace(0.0, 1.0, DENSE, endpoint=False)
        c = self.corners()
        eps = 1e-9
        return np.unique(np.concatenate([grid, c, np.mod(c + eps, 1.0), np.mod(c - eps, 1.0)]))

    # ------------------------------------------------------------------ the kernel's table
    def table(self) -> tuple[list[float], list[float]]:
        """(phases, factors) of the piecewise-linear table the kernel follows (module
        docstring); phases from 0 to 1, ``factors[0] == factors[-1]``."""
        if self.is_constant:
            return [0.0, 1.0], [1.0, 1.0]
        pts = [np.array([0.0, 1.0])]
        if self.has_dip and self.fit_margin() >= 0.0:
            _, a, ln, wd, wu = self.dip_geometry()
            n = max(1, int(self.ramp_nodes))
            for s0, w in ((a - wd, wd), (a + ln, wu)):
                pts.append(np.mod(s0 + w * np.linspace(0.0, 1.0, n + 1), 1.0))
        K = self.harmonics
        if K:
            pts.append(np.linspace(0.0, 1.0, max(64, 32 * K) + 1))
        ph = np.unique(np.concatenate(pts))
        # merge nodes closer than 1e-9 of a cycle (a ramp end that falls on phase 0)
        keep = np.concatenate([[True], np.diff(ph) > 1e-9])
        ph = ph[keep]
        if ph[-1] != 1.0:
            ph[-1] = 1.0
        f, _, _ = self.evaluate(ph)
        f[-1] = f[0]
        return ph.tolist(), f.tolist()

    def table_error(self) -> float:
        """Largest |f - table| over the dense grid, the table rescaled to mean 1 as the
        kernel uses it [fraction of the mean speed]."""
        ph, fa = (np.asarray(v) for v in self.table())
        mean = float(np.sum(0.5 * (fa[1:] + fa[:-1]) * np.diff(ph)))
        x = self.check_points()
        f, _, _ = self.evaluate(x)
        return float(np.max(np.abs(np.interp(x, ph, fa / mean) - f)))

    def to_dict(self) -> dict[str, Any]:
        return {"family": self.family, "params": dict(self.params), "fast_level": self.fast_level()}


def limit_margins(
    profile: SpeedProfile, limits: Limits, mean_speed: float, cycle_time: float
) -> dict[str, float]:
    """Margins of every limit (>= 0: satisfied), with the extremes they come from.

    Returns
    -------
    dict
        ``fit`` [cycles], ``min_speed``, ``max_speed`` [fractions of the mean],
        ``acceleration`` [rad/s^2], ``jerk`` [rad/s^3] (each ``limit - value`` so that >= 0 is
        satisfied), and the extremes ``speed_min``, ``speed_max`` (fractions),
        ``acceleration_max``, ``jerk_max``.
    """
    fit = profile.fit_margin()
    if fit < 0.0:
        # the dip does not fit in a cycle: no profile to measure
        big = 1e30
        return {
            "fit": fit,
            "min_speed": -big,
            "max_speed": -big,
            "acceleration": -big,
            "jerk": -big,
            "speed_min": math.nan,
            "speed_max": math.nan,
            "acceleration_max": math.nan,
            "jerk_max": math.nan,
        }
    f, d1, d2 = profile.evaluate(profile.check_points())
    acc = float(np.max(np.abs(d1))) * mean_speed / cycle_time
    jerk = float(np.max(np.abs(d2))) * mean_speed / cycle_time**2
    fmin, fmax = float(f.min()), float(f.max())
    return {
        "fit": fit,
        "min_speed": fmin - limits.min_speed,
        "max_speed": limits.max_speed - fmax,
        "acceleration": limits.max_acceleration - acc,
        "jerk": limits.max_jerk - jerk,
        "speed_min": fmin,
        "speed_max": fmax,
        "acceleration_max": acc,
        "jerk_max": jerk,
    }


def feasible(margins: dict[str, float]) -> bool:
    """All margins >= 0 (the motion limits, and the drive's ``drive_*`` margins when
    present)."""
    keys = ["fit", "min_speed", "max_speed", "acceleration", "jerk"]
    keys += [k for k in margins if k.startswith("drive_")]
    return all(margins[k] >= 0.0 for k in keys)


@dataclass(frozen=True)
class ProfileFamily:
    """A parametrised family: names, bounds, the constant member, and x -> SpeedProfile.

    Attributes
    ----------
    name : str
        ``dip``, ``fourier`` or ``dip+fourier``.
    harmonics : int
        K (for the harmonic families).
    ramp_nodes : int
        Segments per ramp in the kernel's table.
    amplitude : float
        Bound on each harmonic coefficient, |a_k|, |b_k| <= amplitude / k.
    """

    name: str = "dip"
    harmonics: int = 0
    ramp_nodes: int = 32
    amplitude: float = 0.5

    def __post_init__(self) -> None:
        if self.name not in FAMILIES:
            raise InputError(
                f"design.profile.family: {self.name!r} is not allowed; allowed "
                + ", ".join(FAMILIES)
            )
        if self.name != "dip" and not (1 <= self.harmonics <= 12):
            raise InputError(
                f"design.profile.harmonics: {self.harmonics} is out of range; allowed 1 to 12 "
                f"for the {self.name} family"
            )
        if not (2 <= self.ramp_nodes <= 256):
            raise InputError(
                f"design.profile.ramp_nodes: {self.ramp_nodes} is out of range; allowed 2 to 256"
            )
        if not (0.0 < self.amplitude <= 1.0):
            raise InputError(
                f"design.profile.amplitude: {self.amplitude:g} is out of range; allowed 0 to 1"
            )

    @property
    def names(self) -> list[str]:
        out = list(DIP_NAMES) if self.name != "fourier" else []
        K = self.harmonics if self.name != "dip" else 0
        for k in range(1, K + 1):
            out += [f"a{k}", f"b{k}"]
        return out

    def bounds(self, limits: Limits) -> list[tuple[float, float]]:
        """Box bounds of the parameters (phases and widths in cycles). The plateau level
        spans [min_speed, 1]; the plateau may start up to half a cycle before or a tenth
        after the transfer; widths up to the cycle (the fit is a constraint)."""
        out: list[tuple[float, float]] = []
        if self.name != "fourier":
            out += [
                (limits.min_speed, 1.0),
                (-0.5, 0.1),
                (0.0, 0.95),
                (0.005, 0.5),
                (0.005, 0.5),
            ]
        K = self.harmonics if self.name != "dip" else 0
        for k in range(1, K + 1):
            out += [(-self.amplitude / k, self.amplitude / k)] * 2
        return out

    def constant(self) -> np.ndarray:
        """Parameters of the constant profile (f = 1): level 1, no harmonics; the dip's
        geometry at the middle of its bounds (it has no effect when level = 1)."""
        x = []
        if self.name != "fourier":
            x += [1.0, -0.1, 0.5, 0.1, 0.1]
        K = self.harmonics if self.name != "dip" else 0
        x += [0.0] * (2 * K)
        return np.array(x, dtype=float)

    def profile(self, x: np.ndarray | list[float]) -> SpeedProfile:
        """The profile of parameter vector ``x`` (in the order of :attr:`names`)."""
        v = [float(t) for t in np.asarray(x, dtype=float).reshape(-1)]
        if len(v) != len(self.names):
            raise ValueError(
                f"{len(v)} parameters for the {self.name} family, need {len(self.names)}"
            )
        return SpeedProfile(self.name, dict(zip(self.names, v, strict=True)), self.ramp_nodes)

    def to_dict(self) -> dict[str, Any]:
        return {
            "family": self.name,
            "harmonics": self.harmonics if self.name != "dip" else 0,
            "ramp_nodes": self.ramp_nodes,
            "amplitude": self.amplitude,
            "parameters": self.names,
        }
