"""From a validated Scenario to the records the compiled core integrates.

:func:`build_model` computes every derived quantity once (stiffness from Eq. 4, damping
factors D(c_r), the constant loads, the excitation tables, the default maximum step) and
returns a frozen :class:`Model`. Nothing here integrates; :mod:`braidsim.simulate` does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from braidsim import contact, limits
from braidsim.core import (
    CarrierX,
    CarrierXY,
    HornGear,
    PowerLawContact,
    RegularizedFriction,
    TrackHarmonics,
    horn_gear_state,
    state_size,
)
from braidsim.core.layout import SolverOptions
from braidsim.core.physics.friction import FRICTION_CODES
from braidsim.errors import InputError
from braidsim.params import Scenario, inner_wall_at_start

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
    """A scenario resolved for the compiled core: the model record, the solver options, the
    initial state, the transfer times and the resolved contact laws.

    Attributes
    ----------
    scenario : Scenario
    record : CarrierX or CarrierXY
        The core's model record (physics records inside), SI units.
    options : SolverOptions
        Tolerances, step limits and budget; ``t_end`` is the end of a run from t = 0.
    y0 : np.ndarray
        Initial state in the record's layout (coordinates, speeds, energy quadratures).
    transfer_times : np.ndarray
        Transfers to the next horn gear [s].
    track, slot : PairModel
    duration : float
        [s]
    implicit_rest : bool
        Integrate resting contacts with the implicit step (``simulation.resting_contacts``).
    taylor_order : int
        Order of the Taylor-series steps (``simulation.integrator = "taylor"``); 0: none.
    t_start : float
        Where the run starts [s]: 0, or the time of the state a continued run starts from.
    continued : bool
        The run continues an earlier one (it makes a transfer at ``t_start`` too).
    """

    scenario: Scenario
    record: Any
    options: SolverOptions
    y0: np.ndarray
    transfer_times: np.ndarray
    track: PairModel
    slot: PairModel
    duration: float
    implicit_rest: bool = False
    taylor_order: int = 0
    t_start: float = 0.0
    continued: bool = False

    def __repr__(self) -> str:
        laws = ", ".join(
            f"{p} {m.law} (n = {m.exponent:g})"
            for p, m in (("track", self.track), ("slot", self.slot))
            if p == "track" or self.two_dof
        )
        return (
            f"<braidsim.Model of {self.scenario.name!r}: {type(self.record).__name__}, "
            f"{self.duration:g} s, {laws}, {len(self.transfer_times)} transfers>"
        )

    @property
    def horn_gear(self) -> HornGear:
        """The horn gear's speed record (omega(t), s(t))."""
        return self.record.horn_gear

    @property
    def constant_load(self) -> float:
        """T1 cos(phi) + m r_c omega0^2 [N], pushing the carrier onto the inner wall."""
        r = self.record
        return float(r.load_x + r.mass_radius * r.horn_gear.omega0**2)

    @property
    def two_dof(self) -> bool:
        """Whether the carrier moves tangentially too (``simulation.dof = "xy"``)."""
        return isinstance(self.record, CarrierXY)


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


#: Speed [m/s] above which a start's overlap, released, is refused: about the speed of sound
#: in steel (longitudinal waves, ~5,900 m/s), where a quasi-static contact law (the force a
#: function of the depth and its rate) no longer describes anything; a braiding carrier
#: moves at a few m/s.
MAX_RELEASE_SPEED = 5000.0


def start_overlaps(sc: Scenario) -> list[tuple[str, str, float]]:
    """(pair, wall, depth [m]) of every wall the start overlaps: the track's inner wall at
    x = h(0) and outer one at h(0) + clearance, the slot's rear wall at y = 0 and front one
    at the slot's clearance (xy only)."""
    h0 = inner_wall_at_start(sc.values)
    x0 = sc["initial.x"]
    walls = [
        ("track", "inner", h0 - x0),
        ("track", "outer", x0 - h0 - sc["track.clearance"]),
    ]
    if sc["simulation.dof"] == "xy":
        y0 = sc["initial.y"]
        walls += [("slot", "rear", -y0), ("slot", "front", y0 - sc["slot.clearance"])]
    return [w for w in walls if w[2] > 0.0]


def _check_start_energy(sc: Scenario, pairs: dict[str, PairModel]) -> None:
    """Refuse a start whose overlap stores more elastic energy, K p^(n+1) / (n+1), than
    would throw the carrier off at :data:`MAX_RELEASE_SPEED`: a stiffness in the wrong unit
    or of an absurd size (1e30 N/m^1.5 under paper-3.3's 0.12-mm overlap ran without a word
    and sent the carrier off at 1e10 m/s)."""
    m = sc["carrier.mass"]
    for pair, wall, p in start_overlaps(sc):
        pm = pairs[pair]
        n = pm.exponent
        energy = pm.stiffness * p ** (n + 1.0) / (n + 1.0)
        speed = math.sqrt(2.0 * energy / m)
        if not speed > MAX_RELEASE_SPEED:
            continue
        k_max = 0.5 * m * MAX_RELEASE_SPEED**2 * (n + 1.0) / p ** (n + 1.0)
        given = sc[f"contact.{pair}.stiffness"] is not None
        key = f"contact.{pair}.stiffness" if given else f"the {pair} stiffness K (Eq. 4)"
        raise InputError(
            f"{key}: {pm.stiffness:.3g} N/m^{n:g} with the start's overlap of {p * 1e3:.4g} mm "
            f"into the {wall} {pair} wall stores {energy:.3g} J, which would throw the "
            f"{m:g} kg carrier off at {speed:.3g} m/s, beyond the speed of sound in steel "
            f"({MAX_RELEASE_SPEED:g} m/s); allowed: a stiffness below {k_max:.3g} N/m^{n:g} "
            "at this overlap, or a start that overlaps less (initial position, vibration "
            "amplitude and phase)"
        )


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


def _transfer_times(
    sc: Scenario, t_start: float, dur: float, continued: bool = False
) -> np.ndarray:
    """The transfers in (t_start, t_start + dur) [s], sorted and distinct: those of
    ``transfer.times`` and every ``transfer.first + k transfer.period`` (k = 0, 1, ...).

    A continued run (``continued``) also makes a transfer at its start, t_start: the run it
    continues stopped there before making it (a run makes those strictly inside its span).
    A transfer within rounding after the start (``first + k period`` computed as
    0.15000000000000002 for a cut at 0.15) is made at the start: the step of 3e-17 s that
    would reach it leaves the step control too short a step to grow from.

    Raises
    ------
    InputError
        The period would make more transfers than the ``transfers`` limit allows.
    """
    end = t_start + dur

    def inside(t: Any) -> Any:
        return ((t >= t_start) if continued else (t > t_start)) & (t < end)

    times = [t for t in sc["transfer.times"] if inside(t)]
    period = sc["transfer.period"]
    if not times and not period > 0.0:
        return np.zeros(0)
    first = sc["transfer.first"]
    if period > 0.0 and first < end:
        # counted before any is made: a period of 1 ns over 0.1 s is 1e8 times, which
        # grew memory until the process was killed
        limits.check(
            "transfers",
            (end - max(first, t_start)) / period,
            f"transfer.period = {period:g} s over {dur:g} s of run",
        )
        k0 = max(0, math.floor((t_start - first) / period))
        k1 = math.ceil((end - first) / period) + 1
        periodic = first + np.arange(k0, k1, dtype=float) * period
        times.extend(periodic[inside(periodic)].tolist())
    tr = np.unique(np.asarray(times, dtype=float))
    if continued and tr.size:
        # those within rounding after the start are made at the start (the run before
        # made those before it)
        near = tr - t_start <= TRANSFER_SNAP_ULPS * math.ulp(t_start)
        tr = np.unique(np.where(near, t_start, tr))
    return tr


# a transfer this many units in the last place of a continued run's start time from it is
# made at the start (_transfer_times)
TRANSFER_SNAP_ULPS = 64

STEPS_PER_SECOND = 50_000
# the order of the Taylor-series steps (simulation.integrator = "taylor"): 12 took the fewest
# CPU seconds on paper-3.3 of the orders tried in benchmarks/lean_taylor.py
TAYLOR_ORDER = 12
"""Default step budget per simulated second (measured at the default tolerances, steps and
rejected steps: paper-3.3 about 5,300, paper-3.4a 7,500, paper-3.4b 26,000), so that a long
run is not cut short by a budget made for short ones."""


def _step_budget(sc: Scenario, duration: float) -> int:
    """``simulation.max_steps`` when the scenario sets it, else the larger of its default and
    :data:`STEPS_PER_SECOND` per simulated second, at most the largest budget the key allows
    (2^52: a longer run's count would pass a 64-bit integer, which the solver refuses)."""
    from braidsim.params import SCHEMA

    budget = int(sc["simulation.max_steps"])
    if "simulation.max_steps" in sc.explicit:
        return budget
    most = int(SCHEMA["simulation.max_steps"].high)
    return max(budget, min(math.ceil(STEPS_PER_SECOND * duration), most))


class _Derived(NamedTuple):
    """What :func:`build_model` derives from the scenario alone (not from the run's span)."""

    record: CarrierX | CarrierXY
    track: PairModel
    slot: PairModel
    y0: np.ndarray
    max_step: float
    implicit: bool
    taylor: int


def _derived(sc: Scenario, keep_zero_harmonics: bool) -> _Derived:
    """The records, pair models, initial state and step settings of ``sc``, kept on the
    scenario: a scenario is frozen and its values read-only, so they are derived once however
    often it is run (a run continued in pieces, the calls of a benchmark or of a
    continuation). The initial state is copied by each model; the records hold arrays that
    nothing writes."""
    kept: dict[bool, _Derived] | None = vars(sc).get("_derived")
    if kept is None:
        kept = {}
        object.__setattr__(sc, "_derived", kept)  # (a cache, not a field: the class is frozen)
    if keep_zero_harmonics not in kept:
        kept[keep_zero_harmonics] = _derive(sc, keep_zero_harmonics)
    return kept[keep_zero_harmonics]


def _derive(sc: Scenario, keep_zero_harmonics: bool) -> _Derived:
    m = sc["carrier.mass"]
    phi = sc["yarn.angle"]
    t1 = sc["yarn.tension_horizontal"]
    track = pair_model(sc, "track")
    slot = pair_model(sc, "slot")
    _check_start_energy(sc, {"track": track, "slot": slot})
    prof_t, prof_w, prof_i = _profile_arrays(sc)
    omega0 = 0.0 if prof_t.size else sc["horn_gear.angular_velocity"]
    allow = bool(sc["contact.allow_tension"])
    th = [
        (
            sc["track.vibration_amplitude"],
            sc["track.vibration_frequency"],
            sc["track.vibration_phase"],
        )
    ]
    th += list(sc["track.harmonics"])
    track_harm = np.array(
        [t for i, t in enumerate(th) if t[0] != 0.0 or (keep_zero_harmonics and i == 0)],
        dtype=float,
    ).reshape(-1, 3)
    speed_harm = np.array(
        [] if prof_t.size else list(sc["horn_gear.speed_harmonics"]), dtype=float
    ).reshape(-1, 3)
    vinit = sc["contact.initial_impact_velocity"]
    xy = sc["simulation.dof"] == "xy"
    record = (CarrierXY if xy else CarrierX)(
        mass=m,
        load_x=t1 * math.cos(phi),
        mass_radius=m * sc["carrier.turning_radius"],
        load_y=t1 * math.sin(phi),
        track_clearance=sc["track.clearance"],
        slot_clearance=sc["slot.clearance"],
        track_law=PowerLawContact(track.stiffness, track.exponent, track.damping_factor, allow),
        slot_law=PowerLawContact(slot.stiffness, slot.exponent, slot.damping_factor, allow),
        friction=RegularizedFriction(
            FRICTION_CODES[sc["friction.law"]],
            sc["friction.regularization_velocity"],
            sc["friction.static_ratio"],
            sc["friction.stribeck_velocity"],
        ),
        mu_x=sc["friction.carrier_horn_gear"],
        normal_x=abs(m * sc["gravity"] - sc["yarn.tension_vertical"]),
        mu_y=sc["friction.pad_track"],
        track=TrackHarmonics(track_harm),
        horn_gear=HornGear(
            sc["carrier.turning_radius"], float(omega0), speed_harm, prof_t, prof_w, prof_i
        ),
        transfer_speed=sc["transfer.contact_speed"],
        min_impact_velocity=sc["contact.min_impact_velocity"],
        initial_impact_velocity=-1.0 if vinit is None else vinit,
    )
    hmax = sc["simulation.max_step"]
    y0 = np.zeros(state_size(record, energy=True))
    y0[0] = sc["initial.x"]
    y0[1] = sc["initial.vx"]
    if xy:
        # initial.y is measured from the rear slot wall (at s(0) = 0), initial.vy relative to
        # the slot: 0 starts the carrier moving with it (the ground-frame y' = r_c omega(0))
        y0[2] = sc["initial.y"]
        omega_start, _ = horn_gear_state(record.horn_gear, 0.0)
        y0[3] = sc["initial.vy"] + sc["carrier.turning_radius"] * omega_start
    return _Derived(
        record,
        track,
        slot,
        y0,
        default_max_step(sc) if hmax is None else hmax,
        sc["simulation.resting_contacts"] == "implicit",
        TAYLOR_ORDER if sc["simulation.integrator"] == "taylor" else 0,
    )


def build_model(
    sc: Scenario,
    duration: float | None = None,
    t_start: float = 0.0,
    keep_zero_harmonics: bool = False,
    continued: bool = False,
) -> Model:
    """Derive the core's records from a validated scenario.

    Parameters
    ----------
    sc : Scenario
        Validated parameters (SI).
    duration : float, optional
        Overrides ``simulation.duration`` [s].
    t_start : float
        Start time of a continued run [s]: the transfers kept are those in
        (t_start, t_start + duration).
    keep_zero_harmonics : bool
        Keep the track's main harmonic in the record even at zero amplitude (the record
        then has the same shape whatever the amplitude, as the sensitivities need; a zero
        row adds exactly 0 to the motion).
    continued : bool
        The run continues an earlier one that stopped at ``t_start``: a transfer at
        ``t_start`` is kept too (that run stopped before making it).
    """
    d = _derived(sc, keep_zero_harmonics)
    dur = float(duration if duration is not None else sc["simulation.duration"])
    options = SolverOptions(
        rtol=sc["simulation.rtol"],
        atol_position=sc["simulation.atol_position"],
        atol_velocity=sc["simulation.atol_velocity"],
        max_step=d.max_step,
        max_steps=_step_budget(sc, dur),
        t_end=dur,
    )
    tr = _transfer_times(sc, t_start, dur, continued)
    return Model(
        sc,
        d.record,
        options,
        d.y0.copy(),
        tr,
        d.track,
        d.slot,
        dur,
        d.implicit,
        d.taylor,
        t_start,
        continued,
    )
