"""Largest Lyapunov exponent by two nearby trajectories (Benettin et al. 1980).

Method
------
A reference trajectory and a perturbed one, a distance d0 apart, are advanced together
over intervals of length tau. After interval k their distance d_k is measured, and the
perturbed state is pulled back along the separation to distance d0 (renormalisation).
The largest exponent is

    lambda = (1 / (N tau)) sum_{k=1}^{N} ln(d_k / d0)                      [1/s]

(Benettin, Galgani, Giorgilli & Strelcyn, Meccanica 15 (1980) 9-20). The running value of
this mean after each interval is the convergence curve.

Valid for the impacting carrier
--------------------------------
No variational (tangent) equations are needed: each trajectory is integrated by the
event-exact kernel in its own right, carrying its own contact mode and its own latched
approach speed through every contact onset and exit (a restart with
``simulate(..., start=state)``). The compliant contact force K p^n (1 + D pdot / v0) is
continuous in the state at onset and exit (it vanishes with p), so the flow is continuous
and the distance of two nearby trajectories stays of order d0 across contacts; the latched
speeds of the two differ by O(d0) as well. Where a rescaled perturbed state lies on the
other side of a wall than its own contact mode says (it can happen within d0 of onset or
exit), its mode is set from its penetration and, when it enters a contact, its latched speed
is the reference's (same wall) or its own approach speed (floored like the kernel's).
The method thereby covers what the saltation-matrix corrections of the tangent method
handle for rigid impacts (Mueller, Chaos Solitons Fractals 5 (1995) 1671-1681).

The distance is d = sqrt(dx^2 + (dvx / Omega)^2 [+ dy^2 + (dvy / Omega)^2 with two DOFs]) [m]
with Omega = omega_h (the limit does not depend on this choice of norm).

Checks: the Lorenz system (:mod:`braidsim.analysis.reference`) gives 0.906 within 2 %; a
carrier resting on the vibrating wall (paper-3.4b) gives the decay rate of the linearised
contact, -D a_p / (2 v0) less the friction term (tests/integration/test_analysis.py).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from braidsim.analysis.regimes import (
    DEFAULT_TRANSIENT_CYCLES,
    as_scenario,
    reference_period,
)
from braidsim.core import pair_gaps
from braidsim.errors import InputError
from braidsim.params import Scenario
from braidsim.result import State

S = TypeVar("S")


@dataclass(frozen=True)
class LyapunovEstimate:
    """Result of :func:`benettin`.

    Attributes
    ----------
    exponent : float
        Largest Lyapunov exponent [1/time unit of the flow; 1/s for the carrier].
    times : np.ndarray
        Elapsed time at the end of each interval since the measurement began.
    running : np.ndarray
        Running estimate after each interval (the convergence curve).
    log_stretch : np.ndarray
        ln(d_k / d0) of each interval.
    interval : float
        tau.
    d0 : float
        Initial and renormalised distance.
    """

    exponent: float
    times: np.ndarray
    running: np.ndarray
    log_stretch: np.ndarray
    interval: float
    d0: float

    def spread(self, tail: float = 0.5) -> float:
        """Range of the running estimate over the last ``tail`` fraction of the intervals
        (a measure of how far it has converged)."""
        n = self.running.size
        if n == 0:
            return math.nan
        r = self.running[int(n * (1.0 - tail)) :]
        return float(np.ptp(r)) if r.size else math.nan

    def standard_error(self, blocks: int = 10) -> float:
        """Standard error of :attr:`exponent` by batch means: the intervals cut into
        ``blocks`` consecutive blocks of equal length, the exponent of each block, their
        standard deviation over sqrt(blocks) (Flyvbjerg & Petersen, J. Chem. Phys. 91, 461
        (1989), doi:10.1063/1.457480). Irregular impact motion needs thousands of forcing
        periods for a few per cent: on paper-3.3 at h_a = 0.18 mm, 1,000 periods give
        52-58 1/s with a standard error of 1.4-1.8 1/s."""
        n = self.log_stretch.size // blocks
        if blocks < 2 or n == 0:
            return math.nan
        per_block = self.log_stretch[: n * blocks].reshape(blocks, n).sum(axis=1)
        rates = per_block / (n * self.interval)
        return float(np.std(rates, ddof=1) / math.sqrt(blocks))

    def to_dict(self, curve: bool = True) -> dict[str, Any]:
        """JSON-ready form: ``exponent`` and its ``standard_error`` (:meth:`standard_error`,
        10 blocks) [1/time unit], ``spread_last_half`` (:meth:`spread`), and with ``curve``
        the convergence curve ``times``, ``running``."""
        out: dict[str, Any] = {
            "exponent": self.exponent,
            "interval": self.interval,
            "intervals": int(self.times.size),
            "d0": self.d0,
            "spread_last_half": self.spread(),
            # batch means over 10 blocks (NaN, null in JSON, with fewer than 10 intervals)
            "standard_error": self.standard_error(),
        }
        if curve:
            out["times"] = self.times.tolist()
            out["running"] = self.running.tolist()
        return out


def benettin(
    advance: Callable[[S, float], S],
    separation: Callable[[S, S], float],
    rescale: Callable[[S, S, float], S],
    reference: S,
    perturbed: S,
    interval: float,
    n_intervals: int,
) -> LyapunovEstimate:
    """Largest Lyapunov exponent of a flow by the two-trajectory method (module docstring).

    Parameters
    ----------
    advance : callable
        ``advance(state, tau) -> state`` integrates the flow over tau.
    separation : callable
        ``separation(reference, perturbed) -> d`` (> 0).
    rescale : callable
        ``rescale(reference, perturbed, f)`` -> the state reference + f (perturbed - reference).
    reference, perturbed : state
        Starting states; their separation is d0.
    interval : float
        tau > 0.
    n_intervals : int
        N >= 1.
    """
    if not (math.isfinite(interval) and interval > 0):
        raise InputError(f"interval: {interval!r} is out of range; allowed > 0")
    if int(n_intervals) != n_intervals or n_intervals < 1:
        raise InputError(f"intervals: {n_intervals!r} is out of range; allowed an integer >= 1")
    d0 = float(separation(reference, perturbed))
    if not (math.isfinite(d0) and d0 > 0):
        raise InputError(f"d0: the initial separation {d0!r} is not positive")
    logs = np.empty(int(n_intervals))
    a, b = reference, perturbed
    for k in range(int(n_intervals)):
        a = advance(a, interval)
        b = advance(b, interval)
        d = float(separation(a, b))
        if not (math.isfinite(d) and d > 0):
            raise InputError(
                f"separation: the trajectories became {'identical' if d == 0 else 'undefined'} "
                f"after interval {k}; allowed a larger d0"
            )
        logs[k] = math.log(d / d0)
        b = rescale(a, b, d0 / d)
    times = interval * np.arange(1, logs.size + 1)
    running = np.cumsum(logs) / times
    return LyapunovEstimate(float(running[-1]), times, running, logs, float(interval), d0)


# ----------------------------------------------------------------------------------------
# the carrier
# ----------------------------------------------------------------------------------------


class CarrierFlow:
    """``advance``/``separation``/``rescale`` of the carrier's hybrid state (a :class:`State`).

    ``advance`` is exactly ``simulate(scenario, duration=tau, start=state).final_state``,
    calling the kernel directly with a model built once (no samples, no event rows).
    """

    def __init__(self, sc: Scenario, span: float) -> None:
        from braidsim.model import build_model

        # the model is built for the whole span so that transfer times after the first
        # interval are kept; each call integrates tau of it
        self.full = build_model(sc, span)
        self.omega = float(sc["track.vibration_frequency"]) or 2.0 * math.pi / reference_period(sc)
        self.two_dof = sc["simulation.dof"] == "xy"
        self.vmin = float(sc["contact.min_impact_velocity"])

    def advance(self, state: State, tau: float) -> State:
        """The state ``tau`` seconds later."""
        from braidsim.simulate import final_state, run_model

        model = dataclasses.replace(self.full, duration=float(tau))
        W = np.array([[state.t, state.t + tau]])
        raw = run_model(model, windows=W, series=False, record_events=False, start=state, xsq=False)
        return final_state(raw)

    def _components(self) -> tuple[int, ...]:
        return (0, 1, 2, 3) if self.two_dof else (0, 1)

    def separation(self, a: State, b: State) -> float:
        """d = sqrt(dx^2 + (dvx/Omega)^2 [+ dy^2 + (dvy/Omega)^2]) [m]."""
        s = 0.0
        for i in self._components():
            d = b.y[i] - a.y[i]
            if i % 2 == 1:
                d /= self.omega
            s += d * d
        return math.sqrt(s)

    def rescale(self, ref: State, pert: State, f: float) -> State:
        """ref + f (pert - ref) in the mechanical components, with consistent contact modes."""
        y = list(pert.y)
        for i in self._components():
            y[i] = ref.y[i] + f * (pert.y[i] - ref.y[i])
        # the latched speed of a contact in progress is part of the hybrid state: pulled back
        # with the rest when both are in the same contact, so no unscaled part is left over
        v0t, v0s = pert.track_v0, pert.slot_v0
        if pert.track_mode != 0 and pert.track_mode == ref.track_mode:
            v0t = ref.track_v0 + f * (pert.track_v0 - ref.track_v0)
        if pert.slot_mode != 0 and pert.slot_mode == ref.slot_mode:
            v0s = ref.slot_v0 + f * (pert.slot_v0 - ref.slot_v0)
        st = dataclasses.replace(pert, y=tuple(y), track_v0=v0t, slot_v0=v0s)
        return self.consistent(ref, st)

    def perturb(self, ref: State, d0: float) -> State:
        """A state at distance d0 from ``ref``, displaced equally in every component."""
        comps = self._components()
        y = list(ref.y)
        for i in comps:
            scale = self.omega if i % 2 == 1 else 1.0
            y[i] += d0 / math.sqrt(len(comps)) * scale
        return self.consistent(ref, dataclasses.replace(ref, y=tuple(y)))

    def consistent(self, ref: State, st: State) -> State:
        """``st`` with each pair's contact mode set from its penetration (module docstring)."""
        Y = np.asarray(st.y, dtype=float)
        modes = [st.track_mode, st.slot_mode]
        v0s = [st.track_v0, st.slot_v0]
        ref_modes = [ref.track_mode, ref.slot_mode]
        ref_v0s = [ref.track_v0, ref.slot_v0]
        for pair in range(2 if self.two_dof else 1):
            g_in, g_out, rate = pair_gaps.py(self.full.record, pair, st.t, Y)
            want = -1 if g_in < 0.0 else (1 if g_out < 0.0 else 0)
            if want == modes[pair]:
                continue
            if want != 0:
                if ref_modes[pair] == want:
                    v0s[pair] = ref_v0s[pair]
                else:
                    approach = -rate if want < 0 else rate
                    v0s[pair] = max(approach, self.vmin)
            modes[pair] = want
        return dataclasses.replace(
            st, track_mode=modes[0], slot_mode=modes[1], track_v0=v0s[0], slot_v0=v0s[1]
        )


@dataclass(frozen=True)
class CarrierLyapunov:
    """Largest Lyapunov exponent of one carrier run.

    Attributes
    ----------
    scenario : str
        Scenario name.
    estimate : LyapunovEstimate
        Exponent [1/s] and convergence curve (times since the end of the transient).
    transient : float
        Discarded start [s].
    start : State
        Reference state at the end of the transient.
    """

    scenario: str
    estimate: LyapunovEstimate
    transient: float
    start: State

    @property
    def exponent(self) -> float:
        """lambda [1/s]."""
        return self.estimate.exponent

    def to_dict(self, curve: bool = True) -> dict[str, Any]:
        """JSON-ready form (SI)."""
        out = {"scenario": self.scenario, "transient": self.transient}
        out.update(self.estimate.to_dict(curve))
        out["start"] = {
            "t": self.start.t,
            "x": self.start.y[0],
            "vx": self.start.y[1],
            "track_mode": self.start.track_mode,
            "track_v0": self.start.track_v0,
        }
        return out


def carrier_lyapunov(
    scenario: Scenario | str | Any,
    overrides: Mapping[str, Any] | None = None,
    *,
    transient_cycles: float = DEFAULT_TRANSIENT_CYCLES,
    cycles: float = 30.0,
    interval: float | None = None,
    d0: float = 1e-9,
    rtol: float | None = 1e-10,
) -> CarrierLyapunov:
    """Largest Lyapunov exponent of the carrier's settled motion [1/s].

    Parameters
    ----------
    scenario : Scenario, str, Path or mapping
        The scenario.
    overrides : mapping, optional
        ``{key: value}`` on top of it.
    transient_cycles : float
        Discarded start [excitation cycles].
    cycles : float
        Measurement length [excitation cycles].
    interval : float, optional
        Renormalisation interval tau [s]; default T_h / 16 (short enough that a resting
        contact, whose perturbations decay at some 10^2-10^3 1/s, stays well above the
        integrator's error between renormalisations).
    d0 : float
        Separation [m] (1e-9 m: far below the 1e-6 m static contact depth, far above the
        integration error at ``rtol``).
    rtol : float or None
        ``simulation.rtol`` of both trajectories (None: the scenario's); 1e-10 by default so
        that the two runs' truncation errors stay far below d0.
    """
    sc = as_scenario(scenario, overrides)
    if sc["transfer.times"] or sc["transfer.period"] > 0:
        # a transfer resets x and dx/dt to fixed values: it erases any perturbation
        raise InputError(
            "lyapunov: transfers reset the carrier's state and erase the perturbation; "
            "allowed a scenario without transfer.times and with transfer.period = 0"
        )
    if rtol is not None:
        sc = sc.with_overrides({"simulation.rtol": rtol})
    if not (math.isfinite(transient_cycles) and transient_cycles >= 0):
        raise InputError(
            f"transient_cycles: {transient_cycles!r} is out of range; allowed >= 0 (cycles)"
        )
    if not (math.isfinite(cycles) and cycles > 0):
        raise InputError(f"cycles: {cycles!r} is out of range; allowed > 0")
    if not (math.isfinite(d0) and d0 > 0):
        raise InputError(f"d0: {d0!r} m is out of range; allowed > 0 m")
    T = reference_period(sc)
    tau = T / 16.0 if interval is None else float(interval)
    if not (math.isfinite(tau) and tau > 0):
        raise InputError(f"interval: {tau!r} s is out of range; allowed > 0 s")
    n = max(1, round(cycles * T / tau))
    t_tr = transient_cycles * T
    flow = CarrierFlow(sc, max(t_tr, 1e-9 * T) + (n + 1) * tau)
    # each interval is a run of its own, within the step limit; the whole measurement is
    # two trajectories over n intervals, each at least one step, and three numbers an
    # interval (the logs, their times and the running estimate) kept
    from braidsim import limits

    def measured() -> str:
        return (
            f"cycles: {cycles:g} excitation cycles in {n:.4g} intervals of {tau:.3g} s, "
            "two trajectories"
        )

    max_step = float(flow.full.options.max_step)
    limits.check("steps", 2.0 * n * max(1.0, tau / max_step), lambda: measured() + ", at least")
    limits.check("memory", 3.0 * 8.0 * n, measured)
    from braidsim.simulate import simulate

    # the transient run applies the kernel's t = 0 contact policy (docs/model.md §4)
    res = simulate(sc, duration=max(t_tr, 1e-9 * T), sample_interval=0.0, record_events=False)
    start = res.final_state
    if start is None:  # pragma: no cover - simulate always sets it
        raise AssertionError("simulate returned no final state")
    pert = flow.perturb(start, d0)
    est = benettin(flow.advance, flow.separation, flow.rescale, start, pert, tau, n)
    return CarrierLyapunov(sc.name, est, t_tr, start)
