"""The horn-gear drive: inertia of the gear train and carriers, motor limits, and the torque,
power and yarn-tension swing a speed profile asks of it.

All horn gears of a maypole braider are geared together and turn at the same speed ``omega``
(the speed of :mod:`braidsim.design.profiles`); every quantity here is referred to that speed
(torque on one horn-gear shaft's speed, the same power as at the motor).

Inertia [kg m^2]
----------------
``J = N_g J_g + n m r_c^2 + i^2 J_m``:

``N_g J_g``
    the horn gears. Default ``J_g`` (per gear, with the spur gear under it): a solid steel
    disc, ``J_g = rho pi t R^4 / 2`` with ``rho = 7850 kg/m^3``, ``R = 1.15 r_p`` (the pitch
    radius ``r_p`` = the carrier turning radius plus the depth of the slots' outer rim) and
    ``t = 25 mm`` of steel (the horn-gear plate and the spur gear that drives it). This is an
    engineering estimate, not a measured value: the proportions are those of the drawings of
    horn gears in Kyosev, *Braiding Technology for Textiles* (Woodhead 2015), ch. 3; slots
    and lightening holes make a real gear lighter, its shaft and bearings add a little.
    0.0096 kg m^2 per gear for ``r_p = 65 mm``. Give
    ``gear_inertia`` when it is known (CAD).
``n m r_c^2``
    the carriers: each one turns with its gear at the radius ``r_c`` (exact for a point
    mass; the carrier's own rotational inertia about its centre is neglected).
``i^2 J_m``
    the motor rotor seen through the gearbox of ratio ``i`` (motor speed / horn-gear speed).
    Defaults ``J_m = 2.0e-4 kg m^2`` and ``i = 10`` are those of a 1.5 kW class servo motor
    (rotor inertia 1.5-3 kg cm^2 in the catalogues of the common makes) running at 1200 to
    3000 rpm while the gears turn at 120 to 300 rpm.

Torque and power
----------------
``tau(t) = J omega'(t) + tau_d``, ``P(t) = tau(t) omega(t)``: the inertial torque plus a
constant drag ``tau_d`` [N m], by default the friction and contact losses of the carriers
measured by the constant-speed run (dissipated plus friction power over the mean speed).
Losses of the gear train itself (tooth friction, bearings) are not modelled: unknown for a
generic machine; they add to the mean torque, not to its swing. Peak |tau|, RMS tau over
the cycle, peak (motoring) power and the largest regenerated power (-min P) are reported.

Motor limits (defaults for the same 1.5 kW class servo, engineering estimates): rated torque
about 4.8 N m x ``i`` = 48 N m on the gear shaft (the RMS limit: heating), about 3 times that
briefly (``max_torque`` = 150 N m), and a peak power of twice the rated 1.5 kW
(``max_power`` = 3 kW), what such drives give for a fraction of a second.

Yarn-tension swing
------------------
The yarn runs from the carrier's bobbin through a tensioner (a spring-loaded or weighted
lever that stores yarn length) to the braiding point. The carrier's speed along its path is
``r_c omega``; the rate at which the yarn length changes is at most that speed, and its time
derivative at most ``r_c (|omega'| + omega^2)`` (the second term is the centripetal part,
from the carrier's turning). The tensioner's moving mass ``m_t`` must follow, so the swing
of the yarn tension from its inertia is bounded by ``m_t r_c (max|omega'| + max omega^2)``;
the report gives this bound, beside the constant-speed value ``m_t r_c omega_mean^2`` so
that the part the profile adds can be seen. Default ``m_t = 0.05 kg`` (tensioner lever,
weight and the yarn package's share, an engineering estimate). The contact model itself
holds the yarn tension constant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from braidsim.design.profiles import SpeedProfile
from braidsim.errors import InputError

STEEL_DENSITY = 7850.0
"""kg/m^3."""
GEAR_RADIUS_FACTOR = 1.15
"""Outer radius of a horn gear over its pitch radius (estimate)."""
GEAR_THICKNESS = 0.025
"""Steel thickness of a horn gear with its spur gear [m] (estimate)."""
DRIVE_UNITS = {
    "gear_inertia": "kg m^2",
    "motor_inertia": "kg m^2",
    "gear_ratio": "",
    "max_torque": "N m",
    "max_rms_torque": "N m",
    "max_power": "W",
    "tensioner_mass": "kg",
    "drag_torque": "N m",
}
"""Unit of each drive parameter in messages (SI)."""


def gear_inertia_estimate(pitch_radius: float) -> float:
    """Default inertia of one horn gear with its spur gear [kg m^2] (module docstring):
    ``rho pi t R^4 / 2``, ``R = 1.15 r_p``."""
    R = GEAR_RADIUS_FACTOR * pitch_radius
    return 0.5 * STEEL_DENSITY * math.pi * GEAR_THICKNESS * R**4


@dataclass(frozen=True)
class Drive:
    """The drive's parameters (module docstring); SI units.

    Attributes
    ----------
    gear_inertia : float or None
        Per horn gear [kg m^2]; None: :func:`gear_inertia_estimate`.
    motor_inertia : float
        Motor rotor [kg m^2].
    gear_ratio : float
        Motor speed over horn-gear speed.
    max_torque : float
        Peak torque on the horn-gear speed [N m].
    max_rms_torque : float
        RMS torque over the cycle [N m] (motor heating).
    max_power : float
        Peak motoring power [W].
    tensioner_mass : float
        Moving mass of a carrier's yarn tensioner [kg].
    drag_torque : float or None
        Constant drag [N m]; None: from the constant-speed run.
    """

    gear_inertia: float | None = None
    motor_inertia: float = 2.0e-4
    gear_ratio: float = 10.0
    max_torque: float = 150.0
    max_rms_torque: float = 48.0
    max_power: float = 3000.0
    tensioner_mass: float = 0.05
    drag_torque: float | None = None

    def __post_init__(self) -> None:
        for name, v, positive in (
            ("motor_inertia", self.motor_inertia, False),
            ("tensioner_mass", self.tensioner_mass, False),
            ("gear_ratio", self.gear_ratio, True),
            ("max_torque", self.max_torque, True),
            ("max_rms_torque", self.max_rms_torque, True),
            ("max_power", self.max_power, True),
            ("gear_inertia", self.gear_inertia, False),
            ("drag_torque", self.drag_torque, False),
        ):
            if v is None:  # gear_inertia, drag_torque: estimated, measured
                continue
            if not (math.isfinite(v) and (v > 0.0 if positive else v >= 0.0)):
                unit = DRIVE_UNITS[name]
                u = f" {unit}" if unit else ""
                raise InputError(
                    f"design.drive.{name}: {v:g}{u} is out of range; allowed "
                    f"{'>' if positive else '>='} 0{u}"
                )

    def to_dict(self) -> dict[str, Any]:
        return {
            "gear_inertia": self.gear_inertia,
            "motor_inertia": self.motor_inertia,
            "gear_ratio": self.gear_ratio,
            "max_torque": self.max_torque,
            "max_rms_torque": self.max_rms_torque,
            "max_power": self.max_power,
            "tensioner_mass": self.tensioner_mass,
            "drag_torque": self.drag_torque,
        }


@dataclass(frozen=True)
class DriveModel:
    """A drive on a machine: the numbers the figures need.

    Attributes
    ----------
    drive : Drive
    inertia : dict
        ``gears``, ``carriers``, ``motor`` and ``total`` [kg m^2].
    drag_torque : float
        [N m].
    mean_speed : float
        [rad/s].
    cycle_time : float
        Transfer cycle [s].
    turning_radius : float
        r_c [m].
    """

    drive: Drive
    inertia: dict[str, float]
    drag_torque: float
    mean_speed: float
    cycle_time: float
    turning_radius: float

    @classmethod
    def build(
        cls,
        drive: Drive,
        horn_gears: int,
        pitch_radius: float,
        carriers: int,
        carrier_mass: float,
        turning_radius: float,
        mean_speed: float,
        cycle_time: float,
        drag_torque: float = 0.0,
    ) -> DriveModel:
        """The inertia of module docstring; ``drag_torque`` is used unless the drive gives
        its own."""
        jg = (
            drive.gear_inertia
            if drive.gear_inertia is not None
            else gear_inertia_estimate(pitch_radius)
        )
        parts = {
            "gears": horn_gears * jg,
            "carriers": carriers * carrier_mass * turning_radius**2,
            "motor": drive.gear_ratio**2 * drive.motor_inertia,
        }
        parts["total"] = sum(parts.values())
        tau_d = drive.drag_torque if drive.drag_torque is not None else float(drag_torque)
        return cls(drive, parts, tau_d, mean_speed, cycle_time, turning_radius)

    def figures(self, profile: SpeedProfile | None, points: int = 4096) -> dict[str, float]:
        """Torque, power, speed and acceleration extremes and the yarn-tension bound of one
        transfer cycle of ``profile`` (None: constant speed), on ``points`` phases plus the
        profile's corners.

        Returns
        -------
        dict
            ``peak_torque``, ``rms_torque`` [N m], ``peak_power``, ``peak_regenerated_power``,
            ``mean_power`` [W], ``max_acceleration`` [rad/s^2], ``max_jerk`` [rad/s^3],
            ``min_speed``, ``max_speed`` [rad/s], ``yarn_tension_swing`` [N] (bound, module
            docstring) and ``yarn_tension_swing_constant`` (the same at constant speed).
        """
        w, Tc = self.mean_speed, self.cycle_time
        if profile is None or profile.is_constant:
            f, d1 = np.ones(1), np.zeros(1)
            frac = np.ones(1)
        else:
            grid = np.linspace(0.0, 1.0, points, endpoint=False)
            f, d1, _ = profile.evaluate(grid)
            frac = np.full(points, 1.0 / points)
            # the extremes of the cubic ramps sit at the corners and ramp midpoints
            fc, c1, c2 = profile.evaluate(profile.check_points())
        omega, acc = w * f, w * d1 / Tc
        tau = self.inertia["total"] * acc + self.drag_torque
        power = tau * omega
        out = {
            "rms_torque": float(math.sqrt(np.sum(frac * tau * tau) / np.sum(frac))),
            "mean_power": float(np.sum(frac * power) / np.sum(frac)),
        }
        if profile is not None and not profile.is_constant:
            omega, acc = w * fc, w * c1 / Tc
            jerk = w * c2 / Tc**2
            tau = self.inertia["total"] * acc + self.drag_torque
            power = tau * omega
        else:
            jerk = np.zeros(1)
        mt, rc = self.drive.tensioner_mass, self.turning_radius
        out.update(
            {
                "peak_torque": float(np.max(np.abs(tau))),
                "peak_power": float(max(np.max(power), 0.0)),
                "peak_regenerated_power": float(max(-np.min(power), 0.0)),
                "max_acceleration": float(np.max(np.abs(acc))),
                "max_jerk": float(np.max(np.abs(jerk))),
                "min_speed": float(np.min(omega)),
                "max_speed": float(np.max(omega)),
                "yarn_tension_swing": float(mt * rc * (np.max(np.abs(acc)) + np.max(omega) ** 2)),
                "yarn_tension_swing_constant": float(mt * rc * w * w),
            }
        )
        return out

    def margins(self, profile: SpeedProfile | None) -> dict[str, float]:
        """Normalised margins of the motor limits (>= 0: satisfied): ``torque``,
        ``rms_torque``, ``power`` as ``1 - value / limit``."""
        fig = self.figures(profile)
        d = self.drive
        return {
            "torque": 1.0 - fig["peak_torque"] / d.max_torque,
            "rms_torque": 1.0 - fig["rms_torque"] / d.max_rms_torque,
            "power": 1.0 - fig["peak_power"] / d.max_power,
        }

    def to_dict(self) -> dict[str, Any]:
        return {
            **self.drive.to_dict(),
            "inertia": dict(self.inertia),
            "drag_torque_used": self.drag_torque,
        }


__all__ = ["Drive", "DriveModel", "gear_inertia_estimate"]
