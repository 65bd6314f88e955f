"""``simulate``: run one scenario through the compiled integrator and wrap the output."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from braidsim.errors import InputError, SimulationError
from braidsim.integrate import kernel as K
from braidsim.model import Model, build_model
from braidsim.params import Scenario, load_scenario
from braidsim.result import Result, State


def _windows(
    t_start: float, t_end: float, windows: Sequence[tuple[float, float]] | None
) -> np.ndarray:
    W = [(t_start, t_end)]
    for w in windows or ():
        t0, t1 = float(w[0]), float(w[1])
        if not (math.isfinite(t0) and math.isfinite(t1)) or t0 < 0 or t1 <= t0:
            raise InputError(f"window: [{t0}, {t1}] is not a time interval; allowed 0 <= T0 < T1")
        if t1 > t_end + 1e-12:
            raise InputError(f"window: T1 = {t1:g} s is after the end of the run ({t_end:g} s)")
        W.append((t0, t1))
    return np.array(W, dtype=float)


def failure_message(status: int, t: float, model: Model, stats: np.ndarray) -> str:
    """What failed, when, and what to change, for a kernel status code."""
    sc = model.scenario
    m = sc["carrier.mass"]
    # The two rates that can make the explicit integrator crawl: the friction regularisation,
    # d f_x / d vx = (2/pi) mu1 N / (m x_hat), and the contact damping at rest under the
    # constant load F with the floor speed, d F_c / d pdot / m = F D / (v_min m).
    fric_rate = 0.0
    if sc["friction.law"] != "none":
        fric_rate = (
            2
            / math.pi
            * model.P[K.P_MU1]
            * model.P[K.P_NX]
            / (m * sc["friction.regularization_velocity"])
        )
    damp_rate = (
        model.constant_load * model.track.damping_factor / (sc["contact.min_impact_velocity"] * m)
    )
    if fric_rate >= damp_rate:
        hint = (
            "increase friction.regularization_velocity (the friction regularisation makes the "
            f"equations stiff: rate ~ {fric_rate:.3g} 1/s)"
        )
    else:
        hint = (
            "raise contact.min_impact_velocity (tiny latched impact speeds make the damping "
            f"stiff: rate ~ {damp_rate:.3g} 1/s)"
        )
    if status == K.ST_STEP_COLLAPSE:
        return f"step size collapsed below 1e-14 s at t = {t:.9g} s; {hint}"
    if status == K.ST_NONFINITE:
        return f"the state became NaN or infinite at t = {t:.9g} s; check the parameters or {hint}"
    if status == K.ST_MAX_STEPS:
        return (
            f"step budget simulation.max_steps = {int(model.P[K.P_MAXSTEPS])} exhausted "
            f"at t = {t:.9g} s "
            f"(smallest step {stats[5]:.3g} s); {hint}, or raise simulation.max_steps"
        )
    if status == K.ST_STIFF:
        return (
            f"the equations became stiff at t = {t:.9g} s (step {stats[5]:.3g} s held by stability "
            f"for {K.STIFF_LIMIT} steps); {hint}"
        )
    if status == K.ST_ZENO:
        return (
            f"more than 50 contact events at the same instant t = {t:.9g} s (grazing contact); "
            "raise contact.min_impact_velocity or change the initial state"
        )
    return f"integrator status {status} at t = {t:.9g} s"


def run_kernel(
    model: Model,
    sample_times: np.ndarray,
    windows: np.ndarray,
    record_events: bool = True,
    start: State | None = None,
    episode_capacity: int = 256,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """Run the compiled kernel, growing the output arrays until they fit.

    ``start`` continues from a :class:`State` (its time, state vector, contact modes and
    latched speeds) instead of t = 0 and the scenario's initial conditions; the run then ends
    at ``start.t + model.duration``. ``episode_capacity`` is the first size of the episode
    table: a run with more contact episodes is repeated with a larger one, so a caller that
    expects many (a long run with many transfers) saves that repetition by asking for enough.

    Returns (rows, episodes, ranges, integrals of x^2 dt over the windows, stats, final state
    vector, status). Raises :class:`SimulationError` on a numerical failure.
    """
    P = model.P.copy()
    P[K.P_RECORD_EVENTS] = 1.0 if record_events else 0.0
    y_init = model.y0
    if start is not None:
        y_init = np.asarray(start.y, dtype=float)
        if y_init.shape != (K.NY,):
            raise InputError(f"start: the state vector needs {K.NY} entries, got {y_init.shape}")
        P[K.P_T_START] = start.t
        P[K.P_T_END] = start.t + model.duration
        P[K.P_INIT_GIVEN] = 1.0
        P[K.P_INIT_MODE_T] = start.track_mode
        P[K.P_INIT_MODE_S] = start.slot_mode
        P[K.P_INIT_V0_T] = start.track_v0
        P[K.P_INIT_V0_S] = start.slot_v0
    row_cap = sample_times.size + 256
    ep_cap = max(16, int(episode_capacity))
    while True:
        rows = np.empty((row_cap, K.NCOL))
        EP = np.empty((ep_cap, K.NEP))
        R = np.empty((windows.shape[0], 2, 4, 2))
        R[..., 0] = np.inf
        R[..., 1] = -np.inf
        xsq = np.empty(windows.shape[0])
        stats = np.zeros(K.N_STATS)
        y = y_init.copy()
        status, nrow, nep = K.integrate(
            y,
            P,
            model.excitation,
            model.transfer_times,
            windows,
            sample_times,
            rows,
            EP,
            R,
            xsq,
            stats,
        )
        if status == K.ST_CAPACITY_ROWS:
            row_cap = max(2 * row_cap, nrow + 16)
            continue
        if status == K.ST_CAPACITY_EPISODES:
            ep_cap = max(2 * ep_cap, nep + 16)
            continue
        if status != K.ST_OK:
            raise SimulationError(
                failure_message(status, float(stats[7]), model, stats), float(stats[7])
            )
        return rows[:nrow], EP[:nep], R, xsq, stats, y, status


def simulate(
    scenario: Scenario | str | Path | Mapping[str, Any],
    duration: float | None = None,
    *,
    overrides: Mapping[str, Any] | None = None,
    windows: Sequence[tuple[float, float]] | None = None,
    sample_interval: float | None = None,
    sample_times: Sequence[float] | np.ndarray | None = None,
    record_events: bool = True,
    start: State | None = None,
) -> Result:
    """Simulate one carrier.

    Parameters
    ----------
    scenario : Scenario, str, Path or mapping
        A loaded scenario, a built-in name, a TOML path, or ``{dotted key: value}``.
    duration : float, optional
        Simulated time [s]; default ``simulation.duration``.
    overrides : mapping, optional
        Extra ``{key: value}`` applied on top of the scenario.
    windows : sequence of (t0, t1), optional
        Extra time windows [s] over which the exact ranges of depth and forces are kept
        (window 0 is always the whole run).
    sample_interval : float, optional
        Spacing of the sampled series [s]; default ``simulation.sample_interval``;
        0 keeps only the event rows.
    sample_times : array, optional
        Explicit sample times [s] (replaces ``sample_interval``).
    record_events : bool
        Add the exact onset/exit/peak/transfer states to the series.
    start : State, optional
        Continue from this state (e.g. ``previous.final_state``) for ``duration`` more
        seconds; windows and sample times are then absolute times within the new span.

    Returns
    -------
    Result
    """
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if overrides:
        sc = sc.with_overrides(overrides)
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise InputError(f"duration: {duration!r} s is out of range; allowed > 0 s")
    t_start = 0.0 if start is None else float(start.t)
    model = build_model(sc, duration, t_start=t_start)
    T = t_start + model.duration
    if sample_times is not None:
        st = np.sort(np.asarray(sample_times, dtype=float))
        if st.size and (st[0] < t_start or st[-1] > T or not np.all(np.isfinite(st))):
            raise InputError(f"sample_times: must lie in [{t_start:g}, {T:g}] s")
    else:
        dt = sc["simulation.sample_interval"] if sample_interval is None else float(sample_interval)
        if dt < 0 or not math.isfinite(dt):
            raise InputError(f"sample_interval: {dt!r} s is out of range; allowed >= 0 s")
        n = math.floor((T - t_start) / dt + 1e-9) + 1 if dt > 0 else 0
        if n > 50_000_000:
            raise InputError(
                f"simulation.sample_interval: {dt:g} s gives {n} samples; "
                f"allowed >= {T / 5e7:.3g} s"
            )
        st = t_start + np.arange(n, dtype=float) * dt if n else np.zeros(0)
    W = _windows(t_start, T, windows)
    rows, EP, R, xsq, stats, y, _ = run_kernel(model, st, W, record_events, start)
    order = np.argsort(rows[:, 0], kind="stable")
    rows = rows[order]
    series = {name: np.ascontiguousarray(rows[:, i]) for i, name in enumerate(K.COLUMNS)}
    st_dict = {
        "steps": int(stats[0]),
        "rejected_steps": int(stats[1]),
        "events": int(stats[2]),
        "rhs_evaluations": int(stats[3]),
        "transfers": int(stats[4]),
        "min_step": float(stats[5]) if math.isfinite(stats[5]) else None,
        "max_step": float(stats[6]),
        "track_stiffness": model.track.stiffness,
        "track_damping_factor": model.track.damping_factor,
        "track_effective_restitution": model.track.effective_restitution,
    }
    final = {
        "t": float(stats[7]),
        "x": float(y[0]),
        "vx": float(y[1]),
        "y": float(y[2]),
        "vy": float(y[3]),
    }
    final_state = State(
        t=float(stats[7]),
        y=tuple(float(v) for v in y),
        track_mode=int(stats[8]),
        slot_mode=int(stats[9]),
        track_v0=float(stats[10]),
        slot_v0=float(stats[11]),
    )
    rms_x = np.sqrt(xsq / (W[:, 1] - W[:, 0]))
    return Result(model, series, EP, W, R, st_dict, final, final_state, rms_x=rms_x)
