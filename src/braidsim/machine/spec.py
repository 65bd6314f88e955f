"""The machine specification: a TOML file (or a mapping) read and validated whole before any run.

Format (every quantity a number in SI or a string with units)::

    name = "16-carrier maypole braider"     # optional
    description = "..."                     # optional
    scenario = "paper-3.2"                  # carrier model: built-in name or TOML path
                                            # (relative to the spec); default paper-3.2
    duration = "2 s"                        # simulated time, or:
    revolutions = 1                         # carrier revolutions round the machine

    [overrides]                             # optional changes to the carrier model
    "track.vibration_amplitude" = "0.02 mm"

    [machine]
    horn_gears = 8                          # N, even >= 4
    slots = 4                               # S per horn gear, even; default 4
    pitch_radius = "65 mm"                  # horn-gear pitch radius = the carrier's turning
                                            # radius r_c; or ring_radius (gear centres);
                                            # default: the scenario's carrier.turning_radius
    loading = "full"                        # full | diamond | regular | hercules,
                                            # or a table {A = [lanes], B = [lanes]}:
                                            # lane k of a path lies k slot pitches behind
                                            # lane 0 (summary.json lists the lanes used)
    speed = "120 rpm"                       # mean horn-gear speed; default: the scenario's
    start = "rest"                          # rest: every carrier starts at rest on the inner
                                            # wall (static equilibrium); scenario: its initial.*

    [machine.speed_profile]                 # optional: horn-gear speed over the transfer cycle
    phase = [0, 0.25, 0.5, 0.75, 1]         # 0 = a slot meeting (transfers happen there)
    factor = [0.7, 1.0, 1.3, 1.0, 0.7]      # relative speed, scaled to a time mean of 1

    [braid]                                 # optional: designer's kinematics
    mandrel_radius = "10 mm"
    take_up_speed = "5 mm/s"                # or braid_angle = "45 deg"

    [animation]                             # optional
    enabled = true
    duration = "1 s"                        # default: the run, at most one revolution
    frames = 48                             # 0: no animation; at most 10 000 (raised by
                                            # BRAIDSIM_MAX_FRAMES), as for --frames
    fps = 12
    dpi = 80

The machine sets the carrier model's ``carrier.turning_radius`` (the pitch radius; the contact
stiffness keeps the scenario's ``materials.track.radius``),
``horn_gear.angular_velocity`` / ``horn_gear.speed_profile`` and, per carrier,
``transfer.times``; a scenario that sets those keys itself to other values is rejected with a
one-line :class:`~braidsim.errors.InputError`, as is any unknown key (naming the closest).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from braidsim import limits
from braidsim.core import horn_gear_state, wall_motion
from braidsim.errors import InputError
from braidsim.machine.geometry import (
    Loading,
    MachineGeometry,
    custom_loading,
    loading_pattern,
)
from braidsim.machine.kinematics import SpeedLaw, cycle_profile, revolution_time
from braidsim.model import build_model
from braidsim.params import Scenario, builtin_names, flatten, load_scenario
from braidsim.specfile import check_choice, check_keys, expect_table, read_toml_file
from braidsim.units import to_si

TOP_KEYS = (
    "name",
    "description",
    "scenario",
    "duration",
    "revolutions",
    "overrides",
    "machine",
    "braid",
    "animation",
)
MACHINE_KEYS = (
    "horn_gears",
    "slots",
    "pitch_radius",
    "ring_radius",
    "loading",
    "speed",
    "start",
    "speed_profile",
)
PROFILE_KEYS = ("phase", "factor")
BRAID_KEYS = ("mandrel_radius", "take_up_speed", "braid_angle")
ANIMATION_KEYS = ("enabled", "duration", "frames", "fps", "dpi")
STARTS = ("rest", "scenario")
MACHINE_SET_KEYS = ("transfer.times", "transfer.period", "transfer.first")
#: scenario keys that the machine sets for every carrier -> the entry that sets them
SET_BY_MACHINE = {
    "carrier.turning_radius": "machine.pitch_radius",
    "horn_gear.angular_velocity": "machine.speed",
    "horn_gear.speed_profile": "machine.speed_profile",
    "horn_gear.speed_harmonics": "machine.speed_profile",
    **dict.fromkeys(MACHINE_SET_KEYS, "the transfers of each carrier"),
}
#: scenario keys that the rest start (machine.start = "rest") sets for every carrier
REST_START_KEYS = ("initial.x", "initial.vx", "initial.y", "initial.vy")


def machine_entry(key: str, start: str = "rest") -> str | None:
    """The machine spec's entry that sets scenario key ``key`` for every carrier (None when
    the machine leaves it to the scenario); ``start`` is the machine's ``machine.start``."""
    if key in SET_BY_MACHINE:
        return SET_BY_MACHINE[key]
    if start == "rest" and key in REST_START_KEYS:
        return 'machine.start = "rest"'
    return None


def _int(where: str, value: Any, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise InputError(
            f"{where}: {value!r} is not allowed; allowed an integer from {low} to {high}"
        )
    return int(value)


def _positive(where: str, value: Any, unit: str) -> float:
    v = to_si(where, value, unit)
    if not (math.isfinite(v) and v > 0.0):
        raise InputError(f"{where}: {v:g} {unit} is out of range; allowed > 0 {unit}")
    return v


def _numbers(where: str, value: Any) -> list[float]:
    if not isinstance(value, list) or not value:
        raise InputError(f"{where}: expected a list of numbers, got {value!r}")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise InputError(f"{where}: {v!r} is not a number")
        out.append(float(v))
    return out


@dataclass(frozen=True)
class AnimationOptions:
    """What the animation shows.

    Attributes
    ----------
    enabled : bool
        Write the GIF.
    duration : float or None
        Time span animated from t = 0 [s] (None: the run, at most one revolution).
    frames : int
        Number of frames (0: no animation).
    fps : int
        Frames per second of the GIF.
    dpi : int
        Resolution.
    """

    enabled: bool = True
    duration: float | None = None
    frames: int = 48
    fps: int = 12
    dpi: int = 80


@dataclass(frozen=True)
class BraidOptions:
    """Mandrel and take-up for the designer's kinematics.

    Attributes
    ----------
    mandrel_radius : float
        r_m [m].
    take_up_speed : float or None
        v [m/s] (None when the braid angle is given).
    braid_angle : float or None
        alpha [rad] (None when the take-up speed is given).
    """

    mandrel_radius: float
    take_up_speed: float | None
    braid_angle: float | None


@dataclass(frozen=True)
class MachineSpec:
    """A validated machine.

    Attributes
    ----------
    name, description : str
        Title and text.
    path : Path or None
        The spec file.
    scenario : Scenario
        The carrier model with the machine's radius, speed and start applied (no transfers).
    geometry : MachineGeometry
        Gears, paths, slots.
    loading : Loading
        Loaded lanes (collision-free).
    mean_speed : float
        omega_mean [rad/s].
    speed_profile : dict or None
        ``{"phase": [...], "factor": [...]}`` as given (None: the scenario's speed).
    profile_scale : float
        Factor applied to the profile's factors to hold the mean speed (1 without profile).
    duration : float
        Simulated time [s].
    start : str
        ``rest`` or ``scenario``.
    braid : BraidOptions or None
        Mandrel and take-up.
    animation : AnimationOptions
        GIF options.
    """

    name: str
    description: str
    path: Path | None
    scenario: Scenario
    geometry: MachineGeometry
    loading: Loading
    mean_speed: float
    speed_profile: dict[str, list[float]] | None
    profile_scale: float
    duration: float
    start: str
    braid: BraidOptions | None
    animation: AnimationOptions

    @property
    def revolution_time(self) -> float:
        """Time of one carrier revolution, N pi / omega_mean [s]."""
        return revolution_time(self.mean_speed, self.geometry.N)

    @property
    def cycle_time(self) -> float:
        """Time of one transfer cycle, Theta_c / omega_mean [s]."""
        return self.geometry.transfer_cycle * self.geometry.quantum / self.mean_speed

    def with_duration(self, duration: float | str) -> MachineSpec:
        """The same machine simulated for ``duration`` [s] (or a string with a unit)."""
        from dataclasses import replace

        from braidsim.simulate import time_value

        return replace(self, duration=time_value("duration", duration))


def _round_sig(x: float, up: bool, digits: int = 4) -> float:
    """``x`` > 0 rounded to ``digits`` significant digits, upwards or downwards (a limit that a
    message states must itself be allowed)."""
    q = 10.0 ** (math.floor(math.log10(x)) - digits + 1)
    return (math.ceil if up else math.floor)(x / q) * q


def _rest_start(sc: Scenario) -> dict[str, float]:
    """initial.* for a carrier at rest on the inner wall under the load at t = 0.

    Static equilibrium K delta^n = T1 cos(phi) + m r_c omega(0)^2 on the inner wall, which
    moves with the track: x0 = h(0) - delta, dx0/dt = h'(0). With two DOFs the carrier rides
    in the middle of the slot clearance at the slot speed r_c omega(0).

    A deflection delta larger than the track clearance is refused: naming machine.speed and
    the speed below which it fits when the centrifugal part is to blame, else (the yarn
    tension alone presses the carrier deeper than the clearance, so no speed helps) naming
    track.clearance and its least value at this speed."""
    model = build_model(sc, 1.0)
    om0, s0 = horn_gear_state(model.horn_gear, 0.0)
    rec = model.record
    centrifugal = rec.mass_radius * om0 * om0
    load = rec.load_x + centrifugal
    delta = (load / model.track.stiffness) ** (1.0 / model.track.exponent) if load > 0 else 0.0
    clearance = sc["track.clearance"]
    if delta > clearance:
        # (no machine runs so fast: 1e9 rpm was refused naming initial.x, a key the rest
        # start derives, and the speeds in between ran with absurd forces)
        parts = []
        if rec.load_x > 0.0:
            parts.append(f"yarn tension T1 cos(phi) {rec.load_x:.4g} N")
        if centrifugal > 0.0:
            parts.append(f"centrifugal m r_c omega^2 {centrifugal:.4g} N at {om0:g} rad/s")
        what = " plus ".join(parts)
        spare = model.track.stiffness * clearance**model.track.exponent - rec.load_x
        if spare > 0.0 and rec.mass_radius > 0.0:
            top = _round_sig(math.sqrt(spare / rec.mass_radius), up=False)
            raise InputError(
                f"machine.speed: {om0:g} rad/s presses each carrier {delta * 1e3:.3g} mm into "
                f"the inner wall at rest (its load: {what}), more than the track clearance of "
                f"{clearance * 1e3:g} mm; allowed below {top:.4g} rad/s"
            )
        # the yarn tension alone is too much: no speed, not even 0, satisfies the rest start
        least = _round_sig(delta * 1e3, up=True)
        raise InputError(
            f"track.clearance: {clearance * 1e3:g} mm is less than the {least:.4g} mm each "
            f"carrier is pressed into the inner wall at rest (its load: {what}; the yarn "
            f"tension alone presses it deeper than the clearance at any speed); allowed >= "
            f"{least:.4g} mm"
        )
    h0, hd0, _ = wall_motion.py(rec.track, 0.0)
    out = {"initial.x": float(h0 - delta), "initial.vx": float(hd0)}
    if sc["simulation.dof"] == "xy":
        out["initial.y"] = float(s0 + 0.5 * sc["slot.clearance"])
        out["initial.vy"] = 0.0  # moving with the slot (initial.vy is relative to it)
    return out


def _same(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-12, abs_tol=0.0)


def parse_machine_spec(data: Mapping[str, Any], path: Path | None = None) -> MachineSpec:
    """Validate a machine spec table (already read from TOML); see the module docstring.

    Raises
    ------
    InputError
        The first problem found, naming the entry and what is allowed.
    """
    check_keys("", data, TOP_KEYS)
    name = str(data.get("name", path.stem if path else "machine"))
    description = str(data.get("description", ""))
    ref = data.get("scenario", "paper-3.2")
    if not isinstance(ref, str):
        raise InputError(f"scenario: {ref!r} is not a name or a path")
    scen: str | Path = ref
    if ref not in builtin_names() and path is not None and (path.parent / ref).is_file():
        scen = path.parent / ref
    overrides = flatten(expect_table("overrides", data.get("overrides", {})))
    m = expect_table("machine", data.get("machine", {}))
    check_keys("machine.", m, MACHINE_KEYS)
    start = m.get("start", "rest")
    check_choice("machine.start", start, STARTS)
    # (the carriers' start is checked once it is set: at rest, below, it replaces the
    # scenario's own, which a smaller clearance may put inside the outer wall)
    rest = start == "rest"
    base = load_scenario(scen).with_overrides(overrides or None, check_start=not rest)
    for key in MACHINE_SET_KEYS:
        if key in base.explicit and base[key] not in ((), 0.0):
            raise InputError(
                f"{key}: set by the machine for every carrier; allowed: leave it out of the "
                "scenario and its overrides"
            )

    if "horn_gears" not in m:
        raise InputError("machine.horn_gears: missing; allowed an even number from 4 to 1000")
    n_gears = _int("machine.horn_gears", m["horn_gears"], 4, 1000)
    slots = _int("machine.slots", m.get("slots", 4), 2, 64)
    pitch = (
        _positive("machine.pitch_radius", m["pitch_radius"], "m") if "pitch_radius" in m else None
    )
    ring = _positive("machine.ring_radius", m["ring_radius"], "m") if "ring_radius" in m else None
    if pitch is None and ring is None:
        pitch = float(base["carrier.turning_radius"])
    geom = MachineGeometry(n_gears, slots, pitch_radius=pitch, ring_radius=ring)
    if "carrier.turning_radius" in base.explicit and not _same(
        base["carrier.turning_radius"], geom.pitch_radius
    ):
        raise InputError(
            f"carrier.turning_radius: {base['carrier.turning_radius']:g} m differs from the "
            f"machine's pitch radius {geom.pitch_radius:g} m; allowed: set only one of them"
        )

    raw_loading = m.get("loading", "full")
    loading: Loading
    if isinstance(raw_loading, str):
        loading = loading_pattern(geom, raw_loading)
    elif isinstance(raw_loading, Mapping):
        check_keys("machine.loading.", raw_loading, ("A", "B"))
        lanes = {}
        for g in ("A", "B"):
            v = raw_loading.get(g, [])
            if not isinstance(v, list):
                raise InputError(f"machine.loading.{g}: expected a list of lanes, got {v!r}")
            lanes[g] = v
        loading = custom_loading(geom, lanes["A"], lanes["B"])
    else:
        raise InputError(
            f"machine.loading: {raw_loading!r} is not allowed; allowed full, diamond, regular, "
            "hercules or a table {A = [lanes], B = [lanes]}"
        )

    machine_over: dict[str, Any] = {"carrier.turning_radius": geom.pitch_radius}
    speed_set = "speed" in m
    if speed_set:
        w = _positive("machine.speed", m["speed"], "rad/s")
        if "horn_gear.angular_velocity" in base.explicit and not _same(
            base["horn_gear.angular_velocity"], w
        ):
            raise InputError(
                f"horn_gear.angular_velocity: {base['horn_gear.angular_velocity']:g} rad/s "
                f"differs from machine.speed {w:g} rad/s; allowed: set only one of them"
            )
        if base["horn_gear.speed_profile"] is not None:
            raise InputError(
                "machine.speed: the scenario sets horn_gear.speed_profile; allowed: one of them"
            )
        machine_over["horn_gear.angular_velocity"] = w
    sc = base.with_overrides(machine_over, check_start=not rest)
    law = SpeedLaw.from_model(build_model(sc, 1.0))
    mean = law.mean

    profile_in = None
    scale = 1.0
    if "speed_profile" in m:
        prof = expect_table("machine.speed_profile", m["speed_profile"])
        check_keys("machine.speed_profile.", prof, PROFILE_KEYS)
        for k in PROFILE_KEYS:
            if k not in prof:
                raise InputError(f"machine.speed_profile.{k}: missing; allowed a list of numbers")
        if base["horn_gear.speed_profile"] is not None or base["horn_gear.speed_harmonics"]:
            raise InputError(
                "machine.speed_profile: the scenario sets its own horn-gear speed variation "
                "(horn_gear.speed_profile or speed_harmonics); allowed: one of them"
            )
        phases = _numbers("machine.speed_profile.phase", prof["phase"])
        factors = _numbers("machine.speed_profile.factor", prof["factor"])
        table, scale = cycle_profile(phases, factors, mean, geom.transfer_cycle * geom.quantum)
        sc = sc.with_overrides({"horn_gear.speed_profile": table}, check_start=not rest)
        law = SpeedLaw.from_model(build_model(sc, 1.0))
        profile_in = {"phase": phases, "factor": factors}
    if start == "rest":
        sc = sc.with_overrides(_rest_start(sc))

    t_rev = revolution_time(mean, n_gears)
    if "duration" in data and "revolutions" in data:
        raise InputError("duration: given together with revolutions; allowed one of them")
    if "revolutions" in data:
        rev = data["revolutions"]
        if (
            isinstance(rev, bool)
            or not isinstance(rev, int | float)
            or not (math.isfinite(rev) and rev > 0)
        ):
            raise InputError(f"revolutions: {rev!r} is out of range; allowed a number > 0")
        duration = float(rev) * t_rev
    elif "duration" in data:
        duration = _positive("duration", data["duration"], "s")
    else:
        duration = t_rev

    braid = None
    if "braid" in data:
        b = expect_table("braid", data["braid"])
        check_keys("braid.", b, BRAID_KEYS)
        if "mandrel_radius" not in b:
            raise InputError("braid.mandrel_radius: missing; allowed a radius > 0 m")
        rm = _positive("braid.mandrel_radius", b["mandrel_radius"], "m")
        if ("take_up_speed" in b) == ("braid_angle" in b):
            raise InputError(
                "braid.take_up_speed: give exactly one of braid.take_up_speed and braid.braid_angle"
            )
        v = (
            _positive("braid.take_up_speed", b["take_up_speed"], "m/s")
            if "take_up_speed" in b
            else None
        )
        alpha = None
        if "braid_angle" in b:
            alpha = to_si("braid.braid_angle", b["braid_angle"], "rad")
            if not 0.0 < alpha < math.pi / 2:
                raise InputError(
                    f"braid.braid_angle: {math.degrees(alpha):g} deg is out of range; allowed "
                    "between 0 and 90 deg"
                )
        braid = BraidOptions(rm, v, alpha)

    anim = expect_table("animation", data.get("animation", {}))
    check_keys("animation.", anim, ANIMATION_KEYS)
    enabled = anim.get("enabled", True)
    if not isinstance(enabled, bool):
        raise InputError(f"animation.enabled: {enabled!r} is not allowed; allowed true or false")
    a_dur = _positive("animation.duration", anim["duration"], "s") if "duration" in anim else None
    frames = anim.get("frames", 48)
    if isinstance(frames, bool) or not isinstance(frames, int) or frames < 0:
        raise InputError(
            f"animation.frames: {frames!r} is not allowed; allowed an integer >= 0 "
            "(0: no animation)"
        )
    # the same limit as --frames (docs/guarantees.md), raisable by BRAIDSIM_MAX_FRAMES
    limits.check("frames", frames, "animation.frames")
    animation = AnimationOptions(
        enabled,
        a_dur,
        frames,
        _int("animation.fps", anim.get("fps", 12), 1, 60),
        _int("animation.dpi", anim.get("dpi", 80), 20, 300),
    )
    return MachineSpec(
        name,
        description,
        path,
        sc,
        geom,
        loading,
        mean,
        profile_in,
        scale,
        duration,
        str(start),
        braid,
        animation,
    )


def load_machine_spec(path: str | Path) -> MachineSpec:
    """Read and validate a machine spec TOML file.

    Raises
    ------
    InputError
        Missing or malformed file, or any problem listed in the module docstring.
    """
    return parse_machine_spec(read_toml_file(path, "machine spec"), Path(path))
