"""From a validated Scenario to the plain arrays the compiled kernel integrates.

:func:`build_model` computes every derived quantity once (stiffness from Eq. 4, damping
factors D(c_r), the constant loads, the excitation tables, the default maximum step) and
returns a frozen :class:`Model`. Nothing here integrates; :mod:`braidsim.simulate` does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from braidsim import contact
from braidsim.integrate import kernel as K
from braidsim.params import Scenario

FRICTION_CODES = {"arctan": 0, "tanh": 1, "stribeck": 2, "none": 3}
PAIR_BODIES = {"track": ("guide_pad", "track"), "slot": ("carrier", "horn_gear")}


@dataclass(frozen=True)
class PairModel:
    """The contact law of one pair, resolved to numbers.

    Attributes
    ----------
    law : str
        Registry name.
    stiffness : float
        K [N/m^n].
    exponent : float
        n [-].
    damping_factor : float
        D(c_r) [-].
    restitution : float
        Nominal c_r [-].
    effective_restitution : float
        Exact restitution of one free impact under this law [-].
    stiffness_source : str
        ``"Eq. (4)"`` or ``"override"``.
    """

    law: str
    stiffness: float
    exponent: float
    damping_factor: float
    restitution: float
    effective_restitution: float
    stiffness_source: str


@dataclass(frozen=True)
class Model:
    """Arrays for :func:`braidsim.integrate.kernel.integrate` plus the resolved contact laws."""

    scenario: Scenario
    P: np.ndarray
    track_harmonics: np.ndarray
    speed_harmonics: np.ndarray
    profile_times: np.ndarray
    profile_speeds: np.ndarray
    profile_integral: np.ndarray
    transfer_times: np.ndarray
    y0: np.ndarray
    excitation: np.ndarray
    track: PairModel
    slot: PairModel
    duration: float

    @property
    def constant_load(self) -> float:
        """T1 cos(phi) + m r_c omega0^2 [N], pushing the carrier onto the inner wall."""
        return float(self.P[K.P_LOAD_X] + self.P[K.P_MRC] * self.P[K.P_OMEGA0] ** 2)


def pair_model(sc: Scenario, pair: str) -> PairModel:
    """Resolve the contact law of ``pair`` ("track" or "slot") from the scenario."""
    law = contact.get_law(sc[f"contact.{pair}.model"])
    c_r = float(sc[f"contact.{pair}.restitution"])
    n = sc[f"contact.{pair}.exponent"]
    n = law.default_exponent if n is None else float(n)
    k = sc[f"contact.{pair}.stiffness"]
    source = "override"
    if k is None:
        b1, b2 = PAIR_BODIES[pair]
        k = contact.hertz_stiffness(
            sc[f"materials.{b1}.youngs_modulus"],
            sc[f"materials.{b1}.poisson_ratio"],
            sc[f"materials.{b1}.radius"],
            sc[f"materials.{b2}.youngs_modulus"],
            sc[f"materials.{b2}.poisson_ratio"],
            sc[f"materials.{b2}.radius"],
            sc[f"contact.{pair}.geometry"],
        )
        source = "Eq. (4)"
    d = law.damping_factor(c_r)
    return PairModel(law.name, float(k), n, d, c_r, contact.effective_restitution(d), source)


def _profile_arrays(sc: Scenario) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    prof = sc["horn_gear.speed_profile"]
    if prof is None:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    times = np.asarray(prof[0], dtype=float)
    speeds = np.asarray(prof[1], dtype=float)
    seg = 0.5 * (speeds[1:] + speeds[:-1]) * np.diff(times)
    integral = np.concatenate([[0.0], np.cumsum(seg)])
    return times, speeds, integral


def default_max_step(sc: Scenario) -> float:
    """1/8 of the shortest excitation period (and at most 1 ms).

    In free flight nothing in the equations limits the step, but the walls move: with the
    8 interpolant samples per step that look for contacts, this resolves the wall motion by
    64 points per period, and a dip between samples is searched for as well."""
    freqs = [sc["track.vibration_frequency"]] if sc["track.vibration_amplitude"] > 0 else []
    freqs += [w for a, w, _ in sc["track.harmonics"] if a != 0.0]
    freqs += [w for a, w, _ in sc["horn_gear.speed_harmonics"] if a != 0.0]
    fmax = max([f for f in freqs if f > 0.0], default=0.0)
    hmax = 1e-3
    if fmax > 0.0:
        hmax = min(hmax, 2.0 * math.pi / fmax / 8.0)
    return hmax


def build_model(sc: Scenario, duration: float | None = None, t_start: float = 0.0) -> Model:
    """Derive the kernel's arrays from a validated scenario.

    Parameters
    ----------
    sc : Scenario
        Validated parameters (SI).
    duration : float, optional
        Overrides ``simulation.duration`` [s].
    t_start : float
        Start time of a continued run [s]: the transfers kept are those in
        (t_start, t_start + duration).
    """
    m = sc["carrier.mass"]
    phi = sc["yarn.angle"]
    t1 = sc["yarn.tension_horizontal"]
    track = pair_model(sc, "track")
    slot = pair_model(sc, "slot")
    dur = float(duration if duration is not None else sc["simulation.duration"])
    prof_t, prof_w, prof_i = _profile_arrays(sc)
    omega0 = 0.0 if prof_t.size else sc["horn_gear.angular_velocity"]
    P = np.zeros(K.P_SIZE)
    P[K.P_MASS] = m
    P[K.P_LOAD_X] = t1 * math.cos(phi)
    P[K.P_MRC] = m * sc["carrier.turning_radius"]
    P[K.P_T_Y] = t1 * math.sin(phi)
    P[K.P_EPS_G] = sc["track.clearance"]
    P[K.P_EPS_H] = sc["slot.clearance"]
    P[K.P_K_T], P[K.P_N_T], P[K.P_D_T] = track.stiffness, track.exponent, track.damping_factor
    P[K.P_K_S], P[K.P_N_S], P[K.P_D_S] = slot.stiffness, slot.exponent, slot.damping_factor
    P[K.P_FRIC_LAW] = FRICTION_CODES[sc["friction.law"]]
    P[K.P_MU1] = sc["friction.carrier_horn_gear"]
    P[K.P_MU2] = sc["friction.pad_track"]
    P[K.P_NX] = abs(m * sc["gravity"] - sc["yarn.tension_vertical"])
    P[K.P_VHAT] = sc["friction.regularization_velocity"]
    P[K.P_MUS_RATIO] = sc["friction.static_ratio"]
    P[K.P_VSTRIBECK] = sc["friction.stribeck_velocity"]
    P[K.P_VMIN] = sc["contact.min_impact_velocity"]
    vinit = sc["contact.initial_impact_velocity"]
    P[K.P_VINIT] = -1.0 if vinit is None else vinit
    P[K.P_ALLOW_TENSION] = 1.0 if sc["contact.allow_tension"] else 0.0
    P[K.P_DOF] = 2.0 if sc["simulation.dof"] == "xy" else 1.0
    P[K.P_RC] = sc["carrier.turning_radius"]
    P[K.P_RTOL] = sc["simulation.rtol"]
    P[K.P_ATOL_X] = sc["simulation.atol_position"]
    P[K.P_ATOL_V] = sc["simulation.atol_velocity"]
    hmax = sc["simulation.max_step"]
    P[K.P_HMAX] = default_max_step(sc) if hmax is None else hmax
    P[K.P_MAXSTEPS] = sc["simulation.max_steps"]
    P[K.P_T_END] = dur
    P[K.P_TRANSFER_SPEED] = sc["transfer.contact_speed"]
    P[K.P_OMEGA0] = omega0

    th = [
        (
            sc["track.vibration_amplitude"],
            sc["track.vibration_frequency"],
            sc["track.vibration_phase"],
        )
    ]
    th += list(sc["track.harmonics"])
    track_harm = np.array([t for t in th if t[0] != 0.0], dtype=float).reshape(-1, 3)
    speed_harm = np.array(
        [] if prof_t.size else list(sc["horn_gear.speed_harmonics"]), dtype=float
    ).reshape(-1, 3)

    transfers = set(sc["transfer.times"])
    period = sc["transfer.period"]
    if period > 0.0:
        k = 0
        while sc["transfer.first"] + k * period < t_start + dur:
            transfers.add(sc["transfer.first"] + k * period)
            k += 1
    tr = np.array(sorted(t for t in transfers if t_start < t < t_start + dur), dtype=float)

    y0 = np.zeros(K.NY)
    y0[0] = sc["initial.x"]
    y0[1] = sc["initial.vx"]
    y0[2] = sc["initial.y"]
    y0[3] = sc["initial.vy"]
    ex = K.pack_excitation(track_harm, speed_harm, prof_t, prof_w, prof_i)
    return Model(
        sc, P, track_harm, speed_harm, prof_t, prof_w, prof_i, tr, y0, ex, track, slot, dur
    )
