"""The machine run: every carrier through its own arcs and transfers, reduced per transfer.

Each loaded carrier is one run of the single-carrier model (:func:`braidsim.simulate`) with
its own ``transfer.times``: the times at which the horn-gear rotation ``Omega(t)`` reaches the
carrier's crossings (:meth:`MachineGeometry.transfer_events` and
:meth:`SpeedLaw.time_at_angle`). At each of them the kernel applies the transfer map of the
paper's section 3.2 (docs/model.md §5): the carrier's position is mirrored across the
track, so that the wall it leaned on becomes the far wall (on the next gear the arc curves the
other way and the centrifugal load points to the other side of the track), its radial speed
relative to the track is reversed and the contact speed ``transfer.contact_speed`` is added.
In the model's frame the load always pushes towards x < 0; the mirror is the flip of its sense.
Inner and outer arcs differ in length, so the carriers spend alternately
``(pi - 2 pi/N)/omega`` and ``(pi + 2 pi/N)/omega`` between transfers.

Engine
------
The batch engine (:mod:`braidsim.batch`) reduces every run to whole-window metrics; the
machine needs the impacts of each run grouped by transfer interval, so it runs its own small
process pool (:func:`run_carriers`) over the compiled kernel
(:func:`braidsim.simulate.run_model`, the path :func:`braidsim.simulate` takes) with only
the samples it needs (the transfer times for the energy integrals, the animation frames) and
no event rows.
Runs are independent and deterministic: the result does not depend on the number of workers.

Reduction
---------
A carrier's run is cut at its transfer times ``t_1 < t_2 < ...`` into intervals
``[t_k, t_{k+1})`` (interval 0 is the start, before the first transfer). For each interval:

* impacts: track contact onsets in it (a contact present at the start of the run with an
  overlap is not an impact); the 2 mm/s touch of the new far wall at the transfer itself is
  one, as in the paper's Fig. 8 (F_kg up to 1.2 N);
* peak force [N]: the largest peak of the normal contact force of those impacts;
* approach speed [m/s]: the largest approach speed at their onsets; gap crossing speed: the
  approach speed of the first impact on the inner wall (the carrier arriving from the far
  wall; NaN when there is none). They differ when the load grows while the carrier bounces:
  the centrifugal load m r_c omega(t)^2 then does more work on the way back than it took on
  the way out, and a later impact can be harder than the first;
* impact energy [J]: sum of m v^2 / 2 over those onsets (kinetic energy brought into the
  wall: a noise and wear proxy);
* dissipated energy [J]: the kernel's integral of the track contact damping power
  ``int (N - K p^n) pdot dt`` over the interval (exact up to the integrator's tolerance);
  friction energy the same for ``int f v dt``.

The slot contact (two-DOF runs, ``simulation.dof = "xy"``) is reduced per carrier: its
impacts (onsets on a slot wall), their largest peak force, sum of m v^2 / 2 and sum of
squared peak forces; and in the totals' ``slot`` entry.

Machine totals: the track contact's impacts per second and impact energy per second (over
all carriers and the whole run), dissipated power, the worst carrier (largest peak force)
and the worst transfer; the slot contact's impacts, impacts and impact energy per second
and largest peak force under ``slot`` (two-DOF runs).
"""

from __future__ import annotations

import math
import numbers
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim import limits
from braidsim.core import CARRIER_COLUMNS
from braidsim.errors import InputError, SimulationError
from braidsim.machine.geometry import TransferEvent
from braidsim.machine.kinematics import SpeedLaw
from braidsim.machine.spec import MachineSpec
from braidsim.model import build_model

if TYPE_CHECKING:
    import pandas as pd

SAMPLED = ("track_dissipated", "friction_work_x", "friction_work_y", "track_contact_force")
"""Kernel columns sampled per carrier (at transfer times and animation frames)."""


@dataclass(frozen=True)
class CarrierPlan:
    """One carrier's transfers.

    Attributes
    ----------
    carrier : str
        Name ``A<lane>`` / ``B<lane>``.
    group : str
        ``A`` (counter-clockwise round the machine) or ``B``.
    lane : int
        Lane on its path.
    events : tuple of TransferEvent
        Crossings passed, in order.
    times : np.ndarray
        Transfer times [s], increasing, all < the run's duration.
    """

    carrier: str
    group: str
    lane: int
    events: tuple[TransferEvent, ...]
    times: np.ndarray


def plan_transfers(
    spec: MachineSpec, duration: float | str | None = None
) -> tuple[SpeedLaw, list[CarrierPlan]]:
    """The transfer times of every loaded carrier from the horn-gear rotation.

    Transfers happen at whole horn-gear angles (the crossing angles of the geometry); their
    times invert ``Omega(t) = int omega dt`` of the carrier model's speed law."""
    from braidsim.simulate import time_value

    T = spec.duration if duration is None else time_value("duration", duration)
    geom = spec.geometry
    law = SpeedLaw.from_model(build_model(spec.scenario, T))
    _, ang = law.rotation([T])
    end = math.floor(float(ang[0]) / geom.quantum + 1e-9)
    # a carrier passes its N crossings in a path period of N^2 S quanta: counted before
    # they are listed (a duration of 1e9 s listed transfers until memory ran out)
    limits.check(
        "transfers",
        end / (geom.N * geom.S) + 1.0,
        f"duration: {T:g} s of the machine (transfers of each carrier)",
    )
    plans = []
    for g, lane in spec.loading.carriers:
        ev = [e for e in geom.transfer_events(g, lane, end)]
        times = law.time_at_angle(np.array([e.angle for e in ev], dtype=float) * geom.quantum)
        # the inverted rotation can land a transfer at the very end a rounding error early
        keep = times < T * (1.0 - 1e-12)
        plans.append(
            CarrierPlan(
                f"{g}{lane}",
                g,
                lane,
                tuple(e for e, k in zip(ev, keep, strict=True) if k),
                times[keep],
            )
        )
    return law, plans


# ----------------------------------------------------------------------------------------
# running carriers (in this process or a pool)
# ----------------------------------------------------------------------------------------


def _run_one(
    sc: Any, times: np.ndarray, duration: float, samples: np.ndarray
) -> tuple[np.ndarray, np.ndarray, int, int]:
    """One carrier: the solver with its transfer times, samples only (no event rows)."""
    from braidsim.simulate import run_model

    model = build_model(sc.with_overrides({"transfer.times": [float(t) for t in times]}), duration)
    W = np.array([[0.0, duration]])
    # the sampled columns need the dissipations and friction works of the quadratures only
    raw = run_model(model, sample_times=samples, windows=W, record_events=False, energy="friction")
    rows = raw.series
    assert rows is not None
    if rows.shape[0] != samples.size or not np.array_equal(rows[:, 0], samples):
        # without event rows the solver writes exactly the samples asked for, in order
        raise AssertionError("solver returned a series that does not match the sample times")
    cols = np.ascontiguousarray(rows[:, [CARRIER_COLUMNS.index(c) for c in SAMPLED]].T)
    return raw.episodes, cols, int(raw.stats[0]["steps"]), int(raw.stats[0]["transfers"])


def _run_chunk(
    payload: tuple[Any, ...],
    jobs: Sequence[tuple[str, np.ndarray, np.ndarray]],
    duration: float,
) -> list[tuple[np.ndarray, np.ndarray, int, int]]:
    """Worker entry: rebuild the scenario, run each (name, transfer times, samples)."""
    from braidsim.batch import scenario_from_payload

    sc = scenario_from_payload(payload)
    out = []
    for name, times, samples in jobs:
        try:
            out.append(_run_one(sc, times, duration, samples))
        except SimulationError as exc:
            raise SimulationError(f"carrier {name}: {exc}", exc.time) from None
    return out


AUTO_POOL_SECONDS = 5.0
"""With ``workers=None`` the remaining carriers go to a process pool only when running them
here is expected to take longer than this [s]: starting a worker (interpreter, imports, loading
the compiled kernel) costs about a second, which a short run does not win back."""


def _pool(
    payload: tuple[Any, ...],
    jobs: Sequence[tuple[str, np.ndarray, np.ndarray]],
    duration: float,
    nw: int,
) -> list[tuple[np.ndarray, np.ndarray, int, int]]:
    import multiprocessing

    n = len(jobs)
    k = min(n, 2 * nw)  # interleaved slices balance carriers of different cost
    out: list[Any] = [None] * n
    from braidsim.batch import process_pool

    with process_pool(nw, multiprocessing.get_context("forkserver")) as pool:
        futs = [pool.submit(_run_chunk, payload, list(jobs[j::k]), duration) for j in range(k)]
        for j, fut in enumerate(futs):
            for i, r in zip(range(j, n, k), fut.result(), strict=True):
                out[i] = r
    return out


def run_carriers(
    spec: MachineSpec,
    jobs: Sequence[tuple[str, np.ndarray, np.ndarray]],
    duration: float,
    workers: int | None,
) -> tuple[list[tuple[np.ndarray, np.ndarray, int, int]], int]:
    """Run every carrier.

    Parameters
    ----------
    workers : int or None
        Local processes: 1 runs here, 0 uses every core, None decides: the first carrier
        runs here and the others go to a pool of all cores when running them here would take
        longer than :data:`AUTO_POOL_SECONDS`.

    Returns
    -------
    results : list
        Per job: (episodes, sampled columns (len(SAMPLED), n samples), steps, transfers).
    workers : int
        Processes that ran carriers (1: this one only).
    """
    from braidsim.batch import local_processes, scenario_payload

    payload = scenario_payload(spec.scenario)
    n = len(jobs)
    cores = os.cpu_count() or 1
    if workers is None:
        t0 = time.perf_counter()
        first = _run_chunk(payload, jobs[:1], duration)
        rest_estimate = (time.perf_counter() - t0) * (n - 1)
        if n > 1 and cores > 1 and rest_estimate > AUTO_POOL_SECONDS:
            nw = min(cores, n - 1)
            return first + _pool(payload, jobs[1:], duration, nw), nw
        return first + _run_chunk(payload, jobs[1:], duration), 1
    nw = max(1, min(local_processes(workers), n))
    if nw == 1:
        return _run_chunk(payload, jobs, duration), 1
    return _pool(payload, jobs, duration, nw), nw


# ----------------------------------------------------------------------------------------
# the result
# ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MachineRun:
    """What :func:`run_machine` returns.

    Attributes
    ----------
    spec : MachineSpec
        The machine.
    duration : float
        Simulated time [s].
    speed : SpeedLaw
        Horn-gear speed and rotation.
    plans : list of CarrierPlan
        Transfers of each carrier.
    transfers : pd.DataFrame
        One row per transfer (module docstring), SI units.
    carriers : pd.DataFrame
        One row per carrier: track impacts, largest peak force, impact energy and friction
        and dissipated energies, ``peak_force_squares`` (sum of the squared peak forces of its
        track impacts [N^2]), and the same for the slot contact (two-DOF runs; zero otherwise):
        ``slot_impacts``, ``slot_max_peak_force``, ``slot_impact_energy``,
        ``slot_peak_force_squares``.
    impacts : pd.DataFrame
        Every track impact: carrier, interval (transfer index, 0 before the first), t, wall,
        velocity, peak_force, dissipated_energy.
    totals : dict
        Machine totals (module docstring).
    frame_times : np.ndarray
        Animation frame times [s].
    frame_positions : np.ndarray
        (frames, carriers, 2) carrier positions [m].
    frame_forces : np.ndarray
        (frames, carriers) largest |contact force| since the previous frame [N].
    elapsed : float
        Wall time of the carrier runs [s].
    workers : int
        Processes that ran carriers.
    steps : int
        Accepted integration steps of all carriers (cost).
    """

    def __repr__(self) -> str:
        return (
            f"<braidsim.MachineRun: {len(self.plans)} carriers over {self.duration:g} s, "
            f"{len(self.transfers)} transfers, {len(self.impacts)} track impacts, "
            f"{self.steps} steps>"
        )

    spec: MachineSpec
    duration: float
    speed: SpeedLaw
    plans: list[CarrierPlan]
    transfers: pd.DataFrame
    carriers: pd.DataFrame
    impacts: pd.DataFrame
    totals: dict[str, Any]
    frame_times: np.ndarray
    frame_positions: np.ndarray
    frame_forces: np.ndarray
    elapsed: float
    workers: int
    steps: int = 0


def frame_times(spec: MachineSpec, duration: float, frames: int | None = None) -> np.ndarray:
    """Animation frame times: ``frames`` points over [0, T_anim], T_anim the animation's
    duration (default: the run, at most one carrier revolution)."""
    a = spec.animation
    n = a.frames if frames is None else int(frames)
    span = a.duration if a.duration is not None else min(duration, spec.revolution_time)
    span = min(span, duration)
    if not a.enabled or n <= 0:
        return np.zeros(0)
    return np.linspace(0.0, span, n)


def run_machine(
    spec: MachineSpec,
    duration: float | str | None = None,
    workers: int | None = None,
    frames: int | None = None,
) -> MachineRun:
    """Simulate every carrier of the machine and reduce the runs per transfer.

    Parameters
    ----------
    spec : MachineSpec
        From :func:`~braidsim.machine.spec.load_machine_spec`.
    duration : float or str, optional
        Simulated time [s] (or a string with a unit, ``"0.5 s"``); default ``spec.duration``.
    workers : int, optional
        Local processes: 1 runs here, 0 every core; default: decided from the cost of the
        first carrier (:func:`run_carriers`).
    frames : int, optional
        Animation frames (default the spec's; 0: none).

    Raises
    ------
    InputError
        A bad duration, workers or frames.
    SimulationError
        A carrier's run failed (the message names the carrier).
    """
    import pandas as pd

    from braidsim.batch import check_workers

    if not isinstance(spec, MachineSpec):
        raise InputError(
            f"spec: got {type(spec).__name__}; allowed a MachineSpec (load_machine_spec)"
        )
    if duration is not None:
        spec = spec.with_duration(duration)  # a number in s or a string with a unit
    check_workers(workers, none=True)
    if frames is not None and (
        isinstance(frames, bool) or not isinstance(frames, numbers.Integral) or frames < 0
    ):
        raise InputError(
            f"frames: {frames!r} is out of range; allowed an integer >= 0 (0: none), or None "
            "for the spec's"
        )
    T = spec.duration
    geom = spec.geometry
    law, plans = plan_transfers(spec, T)
    ft = frame_times(spec, T, frames)
    jobs = []
    for p in plans:
        samples = np.unique(np.concatenate([[0.0, T], p.times, ft]))
        jobs.append((p.carrier, p.times, samples))
    t0 = time.perf_counter()
    outs, nw = run_carriers(spec, jobs, T, workers)
    elapsed = time.perf_counter() - t0

    mass = float(spec.scenario["carrier.mass"])
    tr_rows: list[dict[str, Any]] = []
    ca_rows: list[dict[str, Any]] = []
    im_parts = []
    frame_forces = np.zeros((ft.size, len(plans)))
    steps = 0
    om_tr = {p.carrier: law.rotation(p.times)[0] for p in plans}
    for j, (p, (_, _, samples), (EP, cols, nsteps, ntr)) in enumerate(
        zip(plans, jobs, outs, strict=True)
    ):
        steps += nsteps
        if ntr != p.times.size:
            raise AssertionError(
                f"carrier {p.carrier}: {ntr} transfers applied, {p.times.size} planned"
            )
        edges = np.concatenate([[0.0], p.times, [T]])
        ie = np.searchsorted(samples, edges)
        diss = cols[0][ie]
        fric = cols[1][ie] + cols[2][ie]
        track = EP["pair"] == 0.0
        onset = track & (EP["initial"] == 0.0)
        t_on = EP["t"][onset]
        vel = EP["velocity"][onset]
        peak = EP["peak_force"][onset]
        k_of = np.searchsorted(edges[1:-1], t_on, side="right")  # interval index 0..n
        im_parts.append(
            pd.DataFrame(
                {
                    "carrier": p.carrier,
                    "interval": k_of,
                    "t": t_on,
                    "wall": np.where(EP["wall"][onset] < 0, "inner", "outer"),
                    "velocity": vel,
                    "peak_force": peak,
                    "dissipated_energy": EP["dissipated_energy"][onset],
                }
            )
        )
        n_int = p.times.size + 1
        cnt = np.bincount(k_of, minlength=n_int)
        pk = np.zeros(n_int)
        vmax = np.zeros(n_int)
        ekin = np.zeros(n_int)
        np.maximum.at(pk, k_of, peak)
        np.maximum.at(vmax, k_of, vel)
        np.add.at(ekin, k_of, 0.5 * mass * vel * vel)
        # the gap crossing: the first impact on the inner wall of each interval
        inner = EP["wall"][onset] < 0
        v_gap = np.full(n_int, np.nan)
        ki, first = np.unique(k_of[inner], return_index=True)
        v_gap[ki] = vel[inner][first]
        for k in range(1, n_int):
            e = p.events[k - 1]
            tr_rows.append(
                {
                    "carrier": p.carrier,
                    "group": p.group,
                    "lane": p.lane,
                    "transfer": k,
                    "t": float(edges[k]),
                    "crossing": e.crossing,
                    "from_gear": e.from_gear,
                    "to_gear": e.to_gear,
                    "arc": e.next_side,
                    "interval": float(edges[k + 1] - edges[k]),
                    "complete": bool(k < n_int - 1),
                    "omega": float(om_tr[p.carrier][k - 1]),
                    "impacts": int(cnt[k]),
                    "peak_force": float(pk[k]),
                    "approach_speed": float(vmax[k]),
                    "gap_crossing_speed": float(v_gap[k]),
                    "impact_energy": float(ekin[k]),
                    "dissipated_energy": float(diss[k + 1] - diss[k]),
                    "friction_energy": float(fric[k + 1] - fric[k]),
                }
            )
        worst_k = int(np.argmax(pk[1:]) + 1) if n_int > 1 else 0
        # the slot contact (two-DOF runs only): onsets of the carrier on a slot wall
        s_on = (EP["pair"] == 1.0) & (EP["initial"] == 0.0)
        s_vel = EP["velocity"][s_on]
        s_peak = EP["peak_force"][s_on]
        ca_rows.append(
            {
                "carrier": p.carrier,
                "group": p.group,
                "lane": p.lane,
                "transfers": int(p.times.size),
                "impacts": int(cnt.sum()),
                "impacts_per_second": float(cnt.sum() / T),
                "max_peak_force": float(pk.max()) if pk.size else 0.0,
                "mean_peak_force": float(pk[1:].mean()) if n_int > 1 else 0.0,
                "max_approach_speed": float(vmax.max()) if vmax.size else 0.0,
                "impact_energy": float(ekin.sum()),
                "dissipated_energy": float(diss[-1] - diss[0]),
                "friction_energy": float(fric[-1] - fric[0]),
                "worst_transfer": worst_k,
                "peak_force_squares": float(np.sum(peak * peak)),
                "slot_impacts": int(s_vel.size),
                "slot_max_peak_force": float(s_peak.max()) if s_peak.size else 0.0,
                "slot_impact_energy": float(np.sum(0.5 * mass * s_vel * s_vel)),
                "slot_peak_force_squares": float(np.sum(s_peak * s_peak)),
            }
        )
        if ft.size:
            ifr = np.searchsorted(samples, ft)
            f_now = np.abs(cols[3][ifr])
            t_pk = EP["t_peak_force"][track]
            v_pk = EP["peak_force"][track]
            fb = np.searchsorted(ft, t_pk, side="left")  # frame f gets peaks in (t_{f-1}, t_f]
            ok = fb < ft.size
            np.maximum.at(f_now, fb[ok], v_pk[ok])
            frame_forces[:, j] = f_now

    transfers = pd.DataFrame(tr_rows)
    carriers = pd.DataFrame(ca_rows)
    impacts = pd.concat(im_parts, ignore_index=True) if im_parts else pd.DataFrame()
    positions = (
        geom.carrier_points(spec.loading.carriers, law.rotation(ft)[1])
        if ft.size
        else np.zeros((0, len(plans), 2))
    )
    totals = _totals(spec, T, transfers, carriers)
    return MachineRun(
        spec,
        T,
        law,
        plans,
        transfers,
        carriers,
        impacts,
        totals,
        ft,
        positions,
        frame_forces,
        elapsed,
        nw,
        steps,
    )


def _totals(
    spec: MachineSpec, T: float, transfers: pd.DataFrame, carriers: pd.DataFrame
) -> dict[str, Any]:
    n_imp = int(carriers["impacts"].sum())
    out: dict[str, Any] = {
        "carriers": len(carriers),
        "duration": T,
        "transfers": int(carriers["transfers"].sum()),
        "transfers_per_second": float(carriers["transfers"].sum() / T),
        "impacts": n_imp,
        "impacts_per_second": n_imp / T,
        "impact_energy_per_second": float(carriers["impact_energy"].sum() / T),
        "dissipated_power": float(carriers["dissipated_energy"].sum() / T),
        "friction_power": float(carriers["friction_energy"].sum() / T),
        "max_peak_force": float(carriers["max_peak_force"].max()),
    }
    if spec.scenario["simulation.dof"] == "xy":
        # the slot contact's totals beside the track's (they were only in the carriers'
        # rows, and the report's table read as if the track's were the machine's)
        n_slot = int(carriers["slot_impacts"].sum())
        out["slot"] = {
            "impacts": n_slot,
            "impacts_per_second": n_slot / T,
            "impact_energy_per_second": float(carriers["slot_impact_energy"].sum() / T),
            "max_peak_force": float(carriers["slot_max_peak_force"].max()),
        }
    w = carriers.loc[carriers["max_peak_force"].idxmax()]
    out["worst_carrier"] = {
        "carrier": str(w["carrier"]),
        "max_peak_force": float(w["max_peak_force"]),
        "impacts_per_second": float(w["impacts_per_second"]),
        "impact_energy": float(w["impact_energy"]),
    }
    if len(transfers):
        r = transfers.loc[transfers["peak_force"].idxmax()]
        out["worst_transfer"] = {
            "carrier": str(r["carrier"]),
            "transfer": int(r["transfer"]),
            "t": float(r["t"]),
            "crossing": int(r["crossing"]),
            "arc": str(r["arc"]),
            "peak_force": float(r["peak_force"]),
            "approach_speed": float(r["approach_speed"]),
            "impacts": int(r["impacts"]),
        }
        done = transfers[transfers["complete"]]
        if len(done):
            out["mean_peak_force_per_transfer"] = float(done["peak_force"].mean())
            out["mean_impacts_per_transfer"] = float(done["impacts"].mean())
    else:
        out["worst_transfer"] = None
    return out
