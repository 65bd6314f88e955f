"""Geometry of a maypole braiding machine: horn gears on a ring, two serpentine carrier paths,
slots, crossings, loading patterns and the collision check.

The machine (Kyosev, *Braiding Technology for Textiles*, 2015, ch. 3 and 5)
-----------------------------------------------------------------------------
``N`` horn gears (N even, >= 4) sit on a ring of radius ``R`` with their pitch circles of
radius ``r`` touching: the centre distance of neighbours is ``2 r = 2 R sin(pi/N)``, so
``R = r / sin(pi/N)``. Gear ``i`` is centred at polar angle ``theta_i = 2 pi i / N``;
neighbours mesh and so counter-rotate: even gears turn counter-clockwise (sense +1), odd gears
clockwise (-1), all at the same speed ``omega(t)``. The tangency point of gears ``i`` and
``i+1`` (crossing ``i``) lies at polar angle ``theta_i + pi/N`` and radius ``R cos(pi/N)``;
seen from the machine centre it is where the rays touching both pitch circles meet, so each
pitch circle splits into an *inner* arc (towards the machine centre) of angle
``pi - 2 pi/N`` and an *outer* arc of ``pi + 2 pi/N``; the two add up to a full turn.

Each horn gear has ``S`` slots (S even, 4 by default) spaced ``2 pi/S``. A carrier sits in a
slot and is carried round the gear's centre on the pitch circle (its turning radius is the
pitch radius, the paper's r_c). At a crossing the slots of both gears meet and form one
pocket, and the track switch passes the carrier on to the other gear. Group A travels
counter-clockwise round the machine (gear 0, 1, 2, ...), group B clockwise (0, N-1, N-2, ...).
A gear turning in sense ``s`` carries a group-A carrier from its crossing with the previous
gear to the next one along the outer arc when ``s = +1`` and along the inner arc when
``s = -1``; group B takes the complementary arc. So every carrier alternates outer and inner
arcs, and its path is a closed serpentine of ``N`` arcs whose angles add up to ``N pi``.

Exact arithmetic
----------------
Every angle of the machine is an integer multiple of the quantum ``q = pi / (N S)``
(pi/N = S q, pi/2 = N S/2 q, the slot pitch 2 pi/S = 2 N q), so positions, transfer phases
and collisions are computed with integers and compare exactly. In these units a full turn is
``2 N S``, the slot pitch ``2 N``, and one revolution of a carrier round the machine is a
horn-gear rotation of ``N pi = N^2 S`` quanta (the *path period*). The state of the whole
machine is a function of the horn-gear rotation angle ``Omega(t) = int_0^t omega dt`` alone.

Lanes and slots
---------------
With all gears phased so that a slot of gear 0 points at crossing 0 when ``Omega = 0`` and the
slots of neighbouring gears meet at every crossing, the slot positions along a path are
equally spaced by the slot pitch: path ``P`` has ``N S / 2`` *lanes*; lane ``k`` is at path
position ``xi = xi_P + 2 N k + Omega`` (quanta, modulo the path period). A loading puts
carriers into lanes of both paths. Two carriers collide when they reach the same crossing at
the same ``Omega`` (they would share the pocket of the two meeting slots), which can only
happen to one carrier of each group; :func:`check_collisions` finds every such pair exactly.

Braid patterns
--------------
A group-A carrier passes the group-B carriers while both are on the same gear, one on the
outer arc and one on the inner arc; the outer one's yarn lies over the other. Group A is
outer on even gears and inner on odd ones, so it goes over all the B carriers it meets on an
even gear, then under all it meets on the next gear: with ``k`` meetings per gear visit the
braid is ``k/k``: 1/1 diamond, 2/2 regular, 3/3 Hercules (Kyosev 2015, sect. 3.2). Each carrier
passes every crossing once per revolution and each crossing serves one carrier per slot
meeting (``N S / 2`` per revolution), so at most ``N S / 2`` carriers fit, ``N S / 4`` per
group when the groups are equal: full
loading of 4-slot gears is 2/2, a 1/1 braid uses half the carriers, and 3/3 needs 6-slot gears.
:func:`interlacing` counts the meetings of every visit exactly; :func:`loading_pattern` builds
a named pattern and checks both the collisions and the k/k interlacing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from braidsim.errors import InputError

GROUPS = ("A", "B")
PATTERNS: dict[str, int] = {"diamond": 1, "regular": 2, "hercules": 3}
"""Named loading patterns -> k of the k/k braid; ``full`` is k = S/2 (every lane that fits)."""
PATTERN_TITLES = {
    "diamond": "1/1 diamond",
    "regular": "2/2 regular",
    "hercules": "3/3 Hercules",
    "full": "full",
}


@dataclass(frozen=True)
class Arc:
    """One arc of a carrier path (angles in quanta ``pi / (N S)``).

    Attributes
    ----------
    gear : int
        Horn gear the arc runs on.
    sense : int
        Rotation sense of that gear (+1 counter-clockwise, -1 clockwise).
    start_direction : int
        Direction from the gear centre to the arc's start (the entry crossing).
    angle : int
        Arc angle (inner ``N S - 2 S``, outer ``N S + 2 S``).
    side : str
        ``"inner"`` or ``"outer"``.
    path_start : int
        Path position at the arc's start.
    crossing_in, crossing_out : int
        Crossings at the arc's start and end (crossing ``c`` joins gears ``c`` and ``c+1``).
    """

    gear: int
    sense: int
    start_direction: int
    angle: int
    side: str
    path_start: int
    crossing_in: int
    crossing_out: int


@dataclass(frozen=True)
class Loading:
    """Which lanes of each path hold a carrier.

    Attributes
    ----------
    name : str
        Pattern name (``full``, ``diamond``, ``regular``, ``hercules`` or ``custom``).
    lanes_a, lanes_b : tuple of int
        Loaded lanes of path A and path B, increasing.
    """

    name: str
    lanes_a: tuple[int, ...]
    lanes_b: tuple[int, ...]

    @property
    def carriers(self) -> list[tuple[str, int]]:
        """``[(group, lane), ...]``: group A first, then B, each by lane."""
        return [("A", k) for k in self.lanes_a] + [("B", k) for k in self.lanes_b]

    def carrier_ids(self) -> list[str]:
        """Names ``A<lane>``, ``B<lane>`` in the order of :attr:`carriers`."""
        return [f"{g}{k}" for g, k in self.carriers]

    @property
    def title(self) -> str:
        """Human name of the pattern."""
        return PATTERN_TITLES.get(self.name, self.name)


@dataclass(frozen=True)
class TransferEvent:
    """One transfer of one carrier, at horn-gear angle ``angle`` (quanta, > 0).

    Attributes
    ----------
    angle : int
        Horn-gear rotation ``Omega`` at the transfer [quanta].
    crossing : int
        Crossing passed.
    from_gear, to_gear : int
        Gears before and after.
    next_side : str
        Side (``inner``/``outer``) of the arc that starts at the transfer.
    """

    angle: int
    crossing: int
    from_gear: int
    to_gear: int
    next_side: str


class MachineGeometry:
    """Horn gears on a ring, the two carrier paths and their slots.

    Parameters
    ----------
    horn_gears : int
        Number of horn gears N (even, >= 4).
    slots : int
        Slots per horn gear S (even, >= 2; 4 by default).
    pitch_radius : float, optional
        Horn-gear pitch radius r [m] (the carrier's turning radius r_c).
    ring_radius : float, optional
        Radius R of the ring of horn-gear centres [m]; give exactly one of the two radii.

    Raises
    ------
    InputError
        Odd or too small N, odd S, both or neither radius, a radius <= 0.
    """

    def __init__(
        self,
        horn_gears: int,
        slots: int = 4,
        pitch_radius: float | None = None,
        ring_radius: float | None = None,
    ) -> None:
        if isinstance(horn_gears, bool) or int(horn_gears) != horn_gears:
            raise InputError(f"machine.horn_gears: {horn_gears!r} is not an integer")
        if isinstance(slots, bool) or int(slots) != slots:
            raise InputError(f"machine.slots: {slots!r} is not an integer")
        N, S = int(horn_gears), int(slots)
        if N < 4 or N % 2 or N > 1000:
            raise InputError(
                f"machine.horn_gears: {N} is not allowed; allowed an even number from 4 to 1000 "
                "(neighbouring gears counter-rotate round a closed ring)"
            )
        if S < 2 or S % 2 or S > 64:
            raise InputError(
                f"machine.slots: {S} is not allowed; allowed an even number from 2 to 64 "
                "(slots of meshing gears must meet at every crossing)"
            )
        if (pitch_radius is None) == (ring_radius is None):
            raise InputError(
                "machine.pitch_radius: give exactly one of machine.pitch_radius and "
                "machine.ring_radius (in m or with a unit)"
            )
        for key, v in (("pitch_radius", pitch_radius), ("ring_radius", ring_radius)):
            if v is not None and not (math.isfinite(v) and v > 0.0):
                raise InputError(f"machine.{key}: {v!r} m is out of range; allowed > 0 m")
        self.N = N
        self.S = S
        sin = math.sin(math.pi / N)
        self.pitch_radius = float(pitch_radius) if pitch_radius is not None else ring_radius * sin  # type: ignore[operator]
        self.ring_radius = self.pitch_radius / sin

    # ------------------------------------------------------------------ units
    @property
    def quantum(self) -> float:
        """The angle quantum q = pi / (N S) [rad]."""
        return math.pi / (self.N * self.S)

    @property
    def full_turn(self) -> int:
        """2 pi in quanta."""
        return 2 * self.N * self.S

    @property
    def slot_pitch(self) -> int:
        """2 pi / S in quanta."""
        return 2 * self.N

    @property
    def path_period(self) -> int:
        """Horn-gear rotation for one carrier revolution, N pi, in quanta."""
        return self.N * self.N * self.S

    @property
    def lanes(self) -> int:
        """Slot positions (lanes) along each path: N S / 2."""
        return self.N * self.S // 2

    @property
    def max_per_group(self) -> int:
        """Most carriers per group when both groups are equal: N S / 4 (every crossing serves
        one carrier per slot meeting, N S / 2 per revolution, and every carrier passes every
        crossing once per revolution)."""
        return self.N * self.S // 4

    @property
    def inner_arc(self) -> int:
        """Inner arc angle pi - 2 pi/N in quanta."""
        return self.N * self.S - 2 * self.S

    @property
    def outer_arc(self) -> int:
        """Outer arc angle pi + 2 pi/N in quanta."""
        return self.N * self.S + 2 * self.S

    # ------------------------------------------------------------------ gears
    def sense(self, gear: int) -> int:
        """Rotation sense of a gear: +1 (counter-clockwise) for even, -1 for odd."""
        return 1 if gear % 2 == 0 else -1

    def gear_angle(self, gear: int) -> int:
        """Polar angle theta_i of the gear centre [quanta]."""
        return 2 * self.S * gear

    @cached_property
    def gear_centres(self) -> np.ndarray:
        """(N, 2) centres of the horn gears [m]."""
        th = 2.0 * np.pi * np.arange(self.N) / self.N
        return self.ring_radius * np.column_stack([np.cos(th), np.sin(th)])

    def crossing_direction(self, gear: int) -> int:
        """Direction beta_i from the centre of ``gear`` to crossing ``gear`` (towards gear+1)
        [quanta]: theta_i + pi/N + pi/2."""
        return self.gear_angle(gear) + self.S + self.N * self.S // 2

    @cached_property
    def crossings(self) -> np.ndarray:
        """(N, 2) tangency points; crossing c joins gears c and c+1 [m]."""
        c = self.gear_centres
        return 0.5 * (c + np.roll(c, -1, axis=0))

    @cached_property
    def slot_phase(self) -> tuple[int, ...]:
        """Slot phase psi_i of each gear [quanta]: slot k of gear i points at
        ``psi_i + s_i Omega + k 2 pi/S``. psi_0 = beta_0 (a slot at crossing 0 at Omega = 0);
        psi_{i+1} = 2 beta_i - psi_i makes the slots of gears i and i+1 meet at crossing i."""
        mod = self.full_turn
        psi = [self.crossing_direction(0) % mod]
        for i in range(self.N - 1):
            psi.append((2 * self.crossing_direction(i) - psi[-1]) % mod)
        return tuple(psi)

    def slot_angles(self, gear: int, omega_angle: float | np.ndarray) -> np.ndarray:
        """Directions of the S slots of ``gear`` at horn-gear rotation ``omega_angle`` [rad]:
        array (..., S) [rad]."""
        q = self.quantum
        base = self.slot_phase[gear] * q + self.sense(gear) * np.asarray(omega_angle, float)
        return base[..., None] + 2.0 * np.pi / self.S * np.arange(self.S)

    def meshing_phase(self, crossing: int) -> int:
        """Horn-gear rotation (mod the slot pitch) at which slots meet at ``crossing`` [quanta]:
        Omega = s_c (beta_c - psi_c) mod 2 pi/S."""
        c = crossing
        return (self.sense(c) * (self.crossing_direction(c) - self.slot_phase[c])) % self.slot_pitch

    @cached_property
    def transfer_cycle(self) -> int:
        """Horn-gear rotation after which the pattern of slot meetings repeats [quanta].

        The meshing phases of the crossings (:meth:`meshing_phase`) take one or two values
        modulo the slot pitch; when they are equally spaced (N = 8, S = 4: 0 and pi/4) the
        cycle is their spacing and every transfer of every carrier happens at a whole number
        of cycles from Omega = 0; otherwise (N = 6, S = 4) it is the slot pitch and the
        transfers fall at the phases of :attr:`transfer_phases` within it."""
        phases = sorted({self.meshing_phase(c) for c in range(self.N)})
        gaps = {
            b - a for a, b in zip(phases, [*phases[1:], phases[0] + self.slot_pitch], strict=True)
        }
        return gaps.pop() if len(gaps) == 1 else self.slot_pitch

    @property
    def transfer_phases(self) -> tuple[int, ...]:
        """Distinct phases of the slot meetings within a transfer cycle [quanta], from 0."""
        cyc = self.transfer_cycle
        return tuple(sorted({self.meshing_phase(c) % cyc for c in range(self.N)}))

    # ------------------------------------------------------------------ paths
    @cached_property
    def paths(self) -> dict[str, tuple[Arc, ...]]:
        """The arcs of path A (gears 0, 1, ..., N-1) and path B (gears 0, N-1, ..., 1)."""
        N, S = self.N, self.S
        out: dict[str, tuple[Arc, ...]] = {}
        for group in GROUPS:
            order = list(range(N)) if group == "A" else [0, *range(N - 1, 0, -1)]
            arcs = []
            pos = 0
            for g in order:
                s = self.sense(g)
                if group == "A":
                    start = self.gear_angle(g) - S - N * S // 2  # towards gear g-1
                    outer = s > 0
                    c_in, c_out = (g - 1) % N, g
                else:
                    start = self.gear_angle(g) + S + N * S // 2  # towards gear g+1
                    outer = s < 0
                    c_in, c_out = g, (g - 1) % N
                angle = self.outer_arc if outer else self.inner_arc
                arcs.append(
                    Arc(
                        g,
                        s,
                        start % self.full_turn,
                        angle,
                        "outer" if outer else "inner",
                        pos,
                        c_in,
                        c_out,
                    )
                )
                pos += angle
            out[group] = tuple(arcs)
        return out

    def path_boundaries(self, group: str) -> np.ndarray:
        """Path positions of the arc starts, plus the path period at the end (N+1 ints)."""
        arcs = self.paths[group]
        return np.array([a.path_start for a in arcs] + [self.path_period], dtype=np.int64)

    @cached_property
    def lane_offset(self) -> dict[str, int]:
        """Path position xi_P of lane 0 at Omega = 0 (0 <= xi_P < slot pitch) [quanta]: the
        first arc's slot condition start + s u = psi_gear (mod 2 pi/S)."""
        out = {}
        for group in GROUPS:
            a = self.paths[group][0]
            out[group] = (a.sense * (self.slot_phase[a.gear] - a.start_direction)) % self.slot_pitch
        return out

    def lane_position(self, group: str, lane: int) -> int:
        """Path position of a lane at Omega = 0 [quanta]."""
        return (self.lane_offset[group] + self.slot_pitch * lane) % self.path_period

    def slot_misalignment(self, group: str) -> list[int]:
        """For each arc of the path, the mismatch (mod the slot pitch) between the lanes and the
        gear's slots: all zero when every lane rides in a slot on every arc."""
        out = []
        for a in self.paths[group]:
            # lane at path position xi = xi_P + Omega lies at direction start + s (xi - b)
            d = a.start_direction + a.sense * (self.lane_offset[group] - a.path_start)
            out.append((d - self.slot_phase[a.gear]) % self.slot_pitch)
        return out

    # ------------------------------------------------------------------ positions
    def arc_at(self, group: str, xi: np.ndarray) -> np.ndarray:
        """Index of the arc holding path position ``xi`` (quanta or float quanta)."""
        b = self.path_boundaries(group)
        x = np.mod(np.asarray(xi, dtype=float), self.path_period)
        return np.clip(np.searchsorted(b, x, side="right") - 1, 0, self.N - 1)

    def path_point(self, group: str, xi: np.ndarray) -> np.ndarray:
        """Points of path ``group`` at path positions ``xi`` [quanta, float]: (..., 2) [m]."""
        x = np.mod(np.asarray(xi, dtype=float), self.path_period)
        idx = self.arc_at(group, x)
        arcs = self.paths[group]
        start = np.array([a.start_direction for a in arcs], float)[idx]
        sense = np.array([a.sense for a in arcs], float)[idx]
        b0 = np.array([a.path_start for a in arcs], float)[idx]
        gear = np.array([a.gear for a in arcs])[idx]
        ang = (start + sense * (x - b0)) * self.quantum
        c = self.gear_centres[gear]
        r = self.pitch_radius
        return np.stack([c[..., 0] + r * np.cos(ang), c[..., 1] + r * np.sin(ang)], axis=-1)

    def carrier_points(
        self, carriers: list[tuple[str, int]], omega_angle: np.ndarray
    ) -> np.ndarray:
        """Positions of carriers ``[(group, lane), ...]`` at horn-gear rotations ``omega_angle``
        [rad]: array (len(omega_angle), len(carriers), 2) [m]."""
        om = np.asarray(omega_angle, dtype=float).reshape(-1) / self.quantum
        out = np.empty((om.size, len(carriers), 2))
        for j, (g, lane) in enumerate(carriers):
            out[:, j] = self.path_point(g, self.lane_position(g, lane) + om)
        return out

    def carrier_gear(self, group: str, lane: int, omega_angle: float) -> int:
        """Gear holding a carrier at horn-gear rotation ``omega_angle`` [rad] (at a crossing:
        the gear it moves on to)."""
        xi = self.lane_position(group, lane) + omega_angle / self.quantum
        return self.paths[group][int(self.arc_at(group, np.array([xi]))[0])].gear

    # ------------------------------------------------------------------ transfers
    def transfer_events(self, group: str, lane: int, omega_end: int) -> list[TransferEvent]:
        """Every transfer of a carrier with 0 < Omega <= omega_end [quanta], in order.

        A carrier exactly at a crossing at Omega = 0 counts as already on its next arc: it
        next passes that crossing one path period later."""
        arcs = self.paths[group]
        P = self.path_period
        xi0 = self.lane_position(group, lane)
        out = []
        for m, a in enumerate(arcs):
            end = a.path_start + a.angle
            first = (end - xi0) % P
            if first == 0:
                first = P
            nxt = arcs[(m + 1) % self.N]
            k = first
            while k <= omega_end:
                out.append(TransferEvent(k, a.crossing_out, a.gear, nxt.gear, nxt.side))
                k += P
        out.sort(key=lambda e: e.angle)
        return out

    def crossing_visits(self, group: str, lane: int) -> dict[tuple[int, int], str]:
        """``{(crossing, Omega mod path period): group+lane}`` over one revolution."""
        arcs = self.paths[group]
        xi0 = self.lane_position(group, lane)
        return {
            (a.crossing_out, (a.path_start + a.angle - xi0) % self.path_period): f"{group}{lane}"
            for a in arcs
        }

    def gear_visits(self, group: str, lane: int) -> list[tuple[int, int, int]]:
        """``[(gear, Omega_in, Omega_out), ...]`` of one revolution (quanta; 0 <= Omega_in <
        path period), in path order from lane's current arc."""
        P = self.path_period
        xi0 = self.lane_position(group, lane)
        return [
            (a.gear, (a.path_start - xi0) % P, (a.path_start - xi0) % P + a.angle)
            for a in self.paths[group]
        ]


# ----------------------------------------------------------------------------------------
# loading: collisions, interlacing, named patterns
# ----------------------------------------------------------------------------------------


def find_collisions(
    geom: MachineGeometry, loading: Loading, first_only: bool = False
) -> list[tuple[str, str, int, int]]:
    """Pairs of carriers that would occupy the same slot pocket.

    Returns
    -------
    list of (carrier, carrier, crossing, Omega mod path period [quanta])
        Empty for a collision-free loading. Two carriers in the same lane of one path share a
        slot all the time (reported with crossing -1).
    """
    out: list[tuple[str, str, int, int]] = []
    for g, lanes in (("A", loading.lanes_a), ("B", loading.lanes_b)):
        seen: set[int] = set()
        for k in lanes:
            if not 0 <= k < geom.lanes:
                raise InputError(
                    f"machine.loading: lane {k} of group {g} does not exist; allowed 0 to "
                    f"{geom.lanes - 1}"
                )
            if k in seen:
                out.append((f"{g}{k}", f"{g}{k}", -1, 0))
                if first_only:
                    return out
            seen.add(k)
    visits: dict[tuple[int, int], str] = {}
    for g, k in loading.carriers:
        for key, name in geom.crossing_visits(g, k).items():
            other = visits.get(key)
            if other is not None and other != name:
                out.append((other, name, key[0], key[1]))
                if first_only:
                    return out
            visits[key] = name
    return out


def check_collisions(geom: MachineGeometry, loading: Loading) -> None:
    """Raise an :class:`InputError` naming the pattern and the first colliding pair."""
    hits = find_collisions(geom, loading, first_only=True)
    if not hits:
        return
    a, b, c, om = hits[0]
    if c < 0:
        where = "share one slot"
    else:
        deg = om * geom.quantum * 180.0 / math.pi
        where = (
            f"meet at crossing {c} (gears {c}|{(c + 1) % geom.N}) at horn-gear rotation "
            f"{deg:.6g} deg"
        )
    raise InputError(
        f"machine.loading: pattern {loading.name!r} is not collision-free: carriers {a} and {b} "
        f"{where}; allowed: a loading where no two carriers reach a crossing together "
        f"(on {geom.N} gears with {geom.S} slots at most N S/2 = {2 * geom.max_per_group} "
        f"carriers in all, N S/4 = {geom.max_per_group} per group when the groups are equal)"
    )


def interlacing(geom: MachineGeometry, loading: Loading) -> dict[str, list[int]]:
    """Meetings of every group-A carrier with group-B carriers, per gear visit.

    Two carriers on the same gear at overlapping times (open intervals of Omega) pass each
    other exactly once there (their polar angles move monotonically in opposite senses
    across the gear's sector). Group A lies over on even gears and under on odd ones.

    Returns
    -------
    dict
        ``{"A<lane>": [meetings on visit 0, visit 1, ...]}`` over one revolution, visits in
        path order (gear 0, 1, ..., N-1).
    """
    P = geom.path_period
    b_visits: dict[int, list[tuple[int, int]]] = {}
    for k in loading.lanes_b:
        for gear, t0, t1 in geom.gear_visits("B", k):
            b_visits.setdefault(gear, []).append((t0, t1))
    out = {}
    for k in loading.lanes_a:
        counts = []
        for gear, a0, a1 in geom.gear_visits("A", k):
            n = 0
            for b0, b1 in b_visits.get(gear, []):
                for j in (-1, 0, 1):
                    if max(a0, b0 + j * P) < min(a1, b1 + j * P):
                        n += 1
                        break
            counts.append(n)
        out[f"A{k}"] = counts
    return out


def braid_pattern(geom: MachineGeometry, loading: Loading) -> str:
    """The interlacing as ``"k/k"`` when every gear visit of every A carrier has k meetings,
    else ``"irregular"`` (``"none"`` without meetings)."""
    counts = {c for v in interlacing(geom, loading).values() for c in v}
    if not counts or counts == {0}:
        return "none"
    if len(counts) == 1:
        k = counts.pop()
        return f"{k}/{k}"
    return "irregular"


def _spread(n: int, total: int, offset: int = 0) -> tuple[int, ...]:
    """n lanes spread as evenly as possible over ``total`` lanes, starting at ``offset``."""
    return tuple(sorted({(offset + (j * total) // n) % total for j in range(n)}))


def loading_pattern(geom: MachineGeometry, name: str) -> Loading:
    """Build a named loading and check it.

    ``full`` loads ``N S / 4`` carriers per group (braid (S/2)/(S/2), 2/2 on 4-slot gears);
    ``diamond``, ``regular`` and ``hercules`` load ``k N / 2`` carriers per group for a k/k
    braid (k = 1, 2, 3). Group A takes evenly spread lanes from lane 0; group B the same
    spread at the first offset that is collision-free and gives k meetings on every gear
    visit.

    Raises
    ------
    InputError
        Unknown name, or a pattern that collides whatever the placement (the message names
        the pattern and one colliding pair).
    """
    if name == "full":
        k = geom.S // 2
    elif name in PATTERNS:
        k = PATTERNS[name]
    else:
        import difflib

        allowed = ["full", *PATTERNS]
        close = difflib.get_close_matches(name, allowed, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise InputError(
            f"machine.loading: unknown pattern {name!r}{hint}; allowed {', '.join(allowed)} or a "
            "table {A = [lanes], B = [lanes]}"
        )
    if k > geom.S // 2:
        # (more than a full loading: it was refused as a collision of two carriers)
        raise InputError(
            f"machine.loading: pattern {name!r} ({k}/{k}) needs at least {2 * k} slots per "
            f"horn gear, machine.slots is {geom.S}; allowed patterns with k <= S/2 = "
            f"{geom.S // 2} (full: {geom.S // 2}/{geom.S // 2})"
        )
    n = k * geom.N // 2
    L = geom.lanes
    if n > L:
        n = L  # cannot even give every carrier its own lane: the check below reports it
    lanes_a = _spread(n, L)
    first_bad: Loading | None = None
    for off in range(L):
        cand = Loading(name, lanes_a, _spread(n, L, off))
        if find_collisions(geom, cand, first_only=True):
            first_bad = first_bad or cand
            continue
        if braid_pattern(geom, cand) == f"{k}/{k}":
            return cand
    if first_bad is not None:
        check_collisions(geom, first_bad)  # raises, naming the pattern and a colliding pair
    raise InputError(
        f"machine.loading: pattern {name!r} ({k}/{k}) has no placement on {geom.N} gears with "
        f"{geom.S} slots; allowed patterns with k <= S/2 = {geom.S // 2}"
    )


def custom_loading(geom: MachineGeometry, lanes_a: list[int], lanes_b: list[int]) -> Loading:
    """An explicit loading ``{A = [...], B = [...]}`` (lanes 0 to N S/2 - 1), checked."""
    for g, lanes in (("A", lanes_a), ("B", lanes_b)):
        for k in lanes:
            if isinstance(k, bool) or not isinstance(k, int):
                raise InputError(f"machine.loading.{g}: lane {k!r} is not an integer")
    loading = Loading("custom", tuple(sorted(lanes_a)), tuple(sorted(lanes_b)))
    if not loading.carriers:
        raise InputError("machine.loading: no carrier loaded; allowed at least one lane in A or B")
    check_collisions(geom, loading)
    return loading
