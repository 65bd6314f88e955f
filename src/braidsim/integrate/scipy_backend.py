"""SciPy reference backend: the model's equations integrated by :func:`scipy.integrate.solve_ivp`.

A second integrator of the same model as the compiled solver (:mod:`braidsim.core`), for two
purposes:

* an independent cross-check of the compiled solver: same physics (the right-hand side, the
  gaps and the contact forces are the core's own compiled functions, one definition for both
  backends), different method, different event location, different peak search; see
  ``tests/integration/test_backends.py``;
* the baseline of the speed benchmarks (``benchmarks/bench_simulate.py``).

The equations are the model record's registered implementations: :func:`simulate_scipy`
integrates a scenario's carrier (:mod:`braidsim.core.models.carrier`: x radial, y tangential;
walls at x = h(t), h(t) + eps_g and y = s(t), s(t) + eps_h; ``docs/model.md`` explains how they
read the paper), :func:`integrate_scipy` any model record the compiled solver runs (the
impact oscillator, a model of one's own), from the same arguments as
:func:`braidsim.core.run`. A pair's events come from its gaps to its two walls
(``pair_gaps``). A contact present at t = 0 (or right after a transfer) with an overlap is
released elastically (v0 = inf) unless the model's ``initial_impact_velocity`` is set; a body
exactly on a wall and moving into it starts in contact with its rate latched (at least
``min_impact_velocity``). A transfer (at ``transfer.times`` for a scenario) is the model's
``apply_transfer`` (the carrier: from the wall it leans on to the far wall,
x - h -> eps_g - (x - h), x' -> 2 h' - x' + v_tr); the contacts of the pairs it names start
anew.

Method: one :func:`~scipy.integrate.solve_ivp` call per contact mode, with terminal events
at contact onset (free pair: gap to each wall crosses zero downwards) and exit (penetration
crosses zero downwards); the integration restarts after each event with the new mode and the
newly latched v0. A law that clamps its force (N = max(0, F_k + F_c)) has a kink where
F_k + F_c crosses zero inside a contact: a terminal event as well, after which the
integration restarts in the same mode (watching the crossing back). Steps are limited to
``max_step / N_SUB`` in free flight so that the event functions, which SciPy checks only
for a change of sign between step ends, are sampled as often as the compiled solver samples
them (at ``N_SUB`` + 1 points of each of its steps): there the carrier's equations do not
involve the walls, so the steps were as long as ``max_step`` allows, and a gap that dipped
below 0 and back within one (a wall vibrating at 441 Hz sweeping past the carrier) was an
impact missed. In contact the steps are ``max_step`` at most. Within
each contact segment the maxima and minima of the penetration, the damping-related force and
the normal force are found on a grid of the dense output (step ends plus ``N_SUB`` interior
points per step) and refined by bounded Brent minimisation
(:func:`scipy.optimize.minimize_scalar`); the dissipated energy int (N - K p^n) pdot dt is
integrated by 8-point Gauss-Legendre quadrature on each step of the dense output.

All model numbers (stiffness, damping factors, loads, excitation tables, transfer times,
tolerances' defaults, maximum step) come from :func:`braidsim.model.build_model`, so both
backends integrate identical parameters.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import minimize_scalar

from braidsim.core import (
    apply_transfer,
    contact_quantities,
    derivatives,
    model_sizes,
    pair_gaps,
    pair_law,
)
from braidsim.core import layout as L
from braidsim.core.layout import EPISODE_DTYPE
from braidsim.errors import InputError, SimulationError
from braidsim.model import Model, build_model
from braidsim.params import Scenario, load_scenario
from braidsim.result import impacts_frame, ranges_dict

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["ScipyResult", "integrate_scipy", "simulate_scipy"]

N_SUB = 8  # interior samples of the dense output per step for the extremes
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_MAX_SAME_TIME_EVENTS = 50


# =======================================================================================
# The model in plain Python
# =======================================================================================


class _Equations:
    """The model's functions from the compiled core's own definitions (one definition of the
    physics serves both backends), called from Python on plain floats and arrays."""

    def __init__(self, record: Any) -> None:
        r = record
        self.record = r
        n_coords, self.n_pairs, _ = model_sizes(r)
        self.vmin = float(r.min_impact_velocity)
        self.vinit = float(r.initial_impact_velocity)
        self.n_state = 2 * n_coords
        self._derivs = derivatives.implementation(type(r))
        self._gaps = pair_gaps.implementation(type(r))
        self._law = pair_law.implementation(type(r))
        self._transfer = apply_transfer.implementation(type(r))

    def gaps(
        self, t: float, y: np.ndarray | Sequence[float], pair: int
    ) -> tuple[float, float, float]:
        """(g_in, g_out, rate) of ``pair``: its gaps to the inner/rear and the outer/front
        wall [m] and the rate of the first [m/s]."""
        g_in, g_out, rate = self._gaps(self.record, pair, t, np.asarray(y, dtype=float))
        return float(g_in), float(g_out), float(rate)

    def transfer(self, t: float, y: np.ndarray) -> int:
        """Apply the model's transfer to ``y`` in place; the number of leading pairs whose
        contacts start anew."""
        return int(self._transfer(self.record, t, y))

    def unclamped_force(self, t: float, y: np.ndarray, pair: int, mode: int, v0: float) -> float:
        """F_k + F_c [N] of ``pair`` in contact mode ``mode``: the force before the law's
        clamp at 0."""
        _, _, fk, fc, _ = self.pair_arrays(np.array([t]), y, pair, mode, v0)
        return float(fk[0] + fc[0])

    def law_clamps(self, pair: int) -> bool:
        """Whether ``pair``'s law holds its force at 0 where the damping term outpulls the
        stiffness term (asked with a body receding fast: an undamped law never pulls, one
        that allows tension returns the negative sum)."""
        fk, fc, nn = self._law(self.record, pair, 1e-6, -1e6, 1e-6)
        return bool(fk + fc < 0.0 and nn == 0.0)

    def stiffness_force(self, pair: int, p: float) -> float:
        """F_k [N] of ``pair``'s contact law at penetration p (it depends on p alone)."""
        law = self._law(self.record, pair, float(p), 0.0, 1.0)
        return float(law[0])

    def make_rhs(
        self, mt: int, ms: int, v0t: float, v0s: float
    ) -> Callable[[float, np.ndarray], np.ndarray]:
        """f(t, y) of the state [x, x'] (one DOF) or [x, x', y, y'] in the modes (mt, ms)."""
        modes = np.array([mt, ms], dtype=np.int64)
        v0 = np.array([v0t, v0s])
        n = self.n_state
        derivs = self._derivs
        record = self.record

        def rhs(t: float, y: np.ndarray) -> np.ndarray:
            out = np.empty(n)
            derivs(record, t, y, modes, v0, n, out)
            return out

        return rhs

    def make_events(self, mt: int, ms: int, v0: Sequence[float], watch: Sequence[int]) -> list[Any]:
        """Terminal events of the modes (mt, ms): onset of a free pair, exit of a pair in
        contact, and the clamp of a contact force (where its law clamps; ``watch[pair]``: -1
        for the unclamped force falling through zero, +1 for it rising).

        Onset and exit return a value that is >= 0 while nothing happens and crosses zero
        downwards at the event; ``event.tag = (pair, side)``, side 0 for the clamp.
        """
        events: list[Any] = []
        for pair in range(self.n_pairs):
            mode = mt if pair == 0 else ms
            sides = (-1, 1) if mode == 0 else (mode,)
            for side in sides:
                ev = _make_event(self, pair, side, mode)
                events.append(ev)
            if mode != 0 and self.law_clamps(pair):
                events.append(_make_clamp_event(self, pair, mode, v0[pair], watch[pair]))
        return events

    def pair_arrays(
        self, t: np.ndarray, Y: np.ndarray, pair: int, mode: int, v0: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(p, pdot, F_k, F_c, N) of ``pair`` in contact mode ``mode`` at the times ``t``."""
        return contact_quantities(self.record, pair, t, Y, mode, v0)


def _make_event(eq: _Equations, pair: int, side: int, mode: int) -> Any:
    # free: the gap to the wall of ``side`` closing; in contact: the penetration into it
    # (minus that gap) closing
    j = 0 if side < 0 else 1
    sign = 1.0 if mode == 0 else -1.0

    def ev(t: float, y: np.ndarray) -> float:
        return sign * eq.gaps(t, y, pair)[j]

    ev.terminal = True  # type: ignore[attr-defined]
    ev.direction = -1.0  # type: ignore[attr-defined]
    ev.tag = (pair, side)  # type: ignore[attr-defined]
    return ev


def _make_clamp_event(eq: _Equations, pair: int, mode: int, v0: float, direction: int) -> Any:
    def ev(t: float, y: np.ndarray) -> float:
        return eq.unclamped_force(t, y, pair, mode, v0)

    ev.terminal = True  # type: ignore[attr-defined]
    # (one direction only: the segment starts at the last crossing, the force about 0 there)
    ev.direction = float(direction)  # type: ignore[attr-defined]
    ev.tag = (pair, 0)  # type: ignore[attr-defined]
    return ev


# =======================================================================================
# Result
# =======================================================================================


@dataclass
class _Episode:
    t: float
    pair: int
    wall: int
    velocity: float
    latched: float
    initial: bool
    t_end: float = math.nan
    rebound: float = math.nan
    max_depth: float = 0.0
    t_max_depth: float = math.nan
    peak_force: float = 0.0
    t_peak_force: float = math.nan
    min_damping: float = 0.0
    max_damping: float = 0.0
    dissipated: float = 0.0
    end_reason: int = 1  # 0 exit, 1 still in contact at the end, 2 cut by a transfer

    def row(self) -> list[float]:
        """The episode in the field order of :data:`braidsim.core.layout.EPISODE_DTYPE`."""
        return [
            self.t,
            self.t_end,
            float(self.pair),
            float(self.wall),
            self.velocity,
            self.latched,
            self.rebound,
            self.max_depth,
            self.t_max_depth,
            self.peak_force,
            self.t_peak_force,
            self.min_damping,
            self.max_damping,
            self.dissipated,
            float(self.end_reason),
            1.0 if self.initial else 0.0,
        ]


@dataclass(frozen=True)
class ScipyResult:
    """What :func:`simulate_scipy` returns (the parts of :class:`braidsim.Result` it can give).

    Attributes
    ----------
    model : Model or model record
        The model integrated: from :func:`braidsim.build_model` (:func:`simulate_scipy`), or
        the record (:func:`integrate_scipy`).
    episodes : np.ndarray
        Contact episodes, records of :data:`braidsim.core.layout.EPISODE_DTYPE`.
    windows : np.ndarray
        (n, 2) windows of ``ranges`` [s]; window 0 is the whole run.
    ranges : np.ndarray
        (n, pair, quantity, min/max): signed depth [m], stiffness-related force, damping-related
        force and contact force [N] (negative on the inner/rear wall), as in ``Result.ranges``.
    stats : Mapping[str, Any]
        ``segments`` (solve_ivp calls), ``steps``, ``rhs_evaluations``, ``events``, ``transfers``,
        ``method``, ``rtol``, ``wall_time`` [s] and ``solve_ivp_time`` [s] (the part of the wall
        time spent integrating, the rest being the peak search, quadrature and bookkeeping).
    final : Mapping[str, float]
        Final state: ``t, x, vx, y, vy`` for a carrier, ``t`` for another model.
    state : np.ndarray
        The final state vector (coordinates and speeds, as :func:`braidsim.core.run`'s).
    """

    model: Any
    episodes: np.ndarray
    windows: np.ndarray
    ranges: np.ndarray
    stats: Mapping[str, Any]
    final: Mapping[str, float]
    state: np.ndarray = field(default_factory=lambda: np.zeros(0))
    backend: str = "scipy"
    _cache: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def impacts(self) -> pd.DataFrame:
        """Impact table with the columns and meaning of :attr:`braidsim.Result.impacts`."""
        if "impacts" not in self._cache:
            self._cache["impacts"] = impacts_frame(self.episodes)
        return self._cache["impacts"]

    def ranges_dict(self, pair: str = "track", window: int = 0) -> dict[str, list[float]]:
        """Extremes of one pair in one window, paper signs, SI units (as ``Result``)."""
        return ranges_dict(self.ranges, pair, window)


# =======================================================================================
# The driver
# =======================================================================================


@dataclass(frozen=True)
class _Setup:
    """What one run integrates: the model record, its start, end and transfers [s], the
    solver's step limits, and the scenario's model (None for a record alone)."""

    record: Any
    y0: np.ndarray
    duration: float
    transfer_times: np.ndarray
    max_step: float
    max_steps: int
    model: Model | None = None


class _Run:
    """State of one SciPy run: modes, latched speeds, open episodes, ranges."""

    def __init__(
        self, setup: _Setup, windows: np.ndarray, method: str, rtol: float, atol: Any
    ) -> None:
        self.setup = setup
        self.eq = _Equations(setup.record)
        self.W = windows
        self.R = np.empty((windows.shape[0], 2, 4, 2))
        self.R[..., 0] = np.inf
        self.R[..., 1] = -np.inf
        self.method = method
        self.rtol = rtol
        self.atol = atol
        self.hmax = float(setup.max_step)
        self.max_steps = int(setup.max_steps)
        self.modes = [0, 0]
        self.v0 = [1.0, 1.0]
        # the clamp crossing each contact waits for: -1 falling, +1 rising, 0 not known yet
        # (read from the force's sign at the next segment's start)
        self.clamp_watch = [0, 0]
        self.open: list[_Episode | None] = [None, None]
        self.episodes: list[_Episode] = []
        self.stats: dict[str, float] = {
            "segments": 0,
            "steps": 0,
            "rhs_evaluations": 0,
            "events": 0,
            "transfers": 0,
            "min_step": math.inf,
        }
        self.solve_time = 0.0  # wall time spent inside solve_ivp [s]

    @property
    def npair(self) -> int:
        return self.eq.n_pairs

    # ---- contacts at t = 0 and after a transfer ---------------------------------------
    def start_contacts(self, t: float, y: np.ndarray, npair: int) -> None:
        """The solver's start policy (see :mod:`braidsim.core.solver.loop`)."""
        eq = self.eq
        for pair in range(npair):
            g_in, g_out, ud = eq.gaps(t, y, pair)
            mode = 0
            p = pd = 0.0
            if g_in < 0.0 or (g_in == 0.0 and ud < 0.0):
                mode, p, pd = -1, -g_in, -ud
            elif g_out < 0.0 or (g_out == 0.0 and ud > 0.0):
                mode, p, pd = 1, -g_out, ud
            self.modes[pair] = mode
            if mode == 0:
                continue
            if p > 0.0:
                # overlap with no approach history: elastic release unless a speed is given
                v0 = eq.vinit if eq.vinit > 0.0 else math.inf
            else:
                v0 = max(pd, eq.vmin)
            self.v0[pair] = v0
            ep = _Episode(
                t, pair, mode, pd, v0, p > 0.0, max_depth=p, t_max_depth=t, t_peak_force=t
            )
            self.open[pair] = ep
            self.episodes.append(ep)

    # ---- post-processing of one segment -------------------------------------------------
    def _fold_ranges(self, pair: int, ta: float, tb: float, lo: np.ndarray, hi: np.ndarray) -> None:
        for w in range(self.W.shape[0]):
            if self.W[w, 0] <= tb and ta <= self.W[w, 1]:
                self.R[w, pair, :, 0] = np.minimum(self.R[w, pair, :, 0], lo)
                self.R[w, pair, :, 1] = np.maximum(self.R[w, pair, :, 1], hi)

    def _extremes(
        self, sol: Any, ts: np.ndarray, pair: int, mode: int, v0: float, ta: float, tb: float
    ) -> dict[str, tuple[float, float, float, float]]:
        """Max and min (value, time) of p, F_c and N over [ta, tb] on the dense output.

        Returns {quantity: (min, t_min, max, t_max)} for quantity in ("p", "fc", "nn").
        """
        eq = self.eq
        steps = ts[(ts > ta) & (ts < tb)]
        knots = np.concatenate([[ta], steps, [tb]])
        frac = np.arange(N_SUB) / N_SUB
        grid = np.concatenate([(knots[:-1, None] + np.diff(knots)[:, None] * frac).ravel(), [tb]])
        Yg = sol(grid)
        p, _, _, fc, nn = eq.pair_arrays(grid, Yg, pair, mode, v0)
        out = {}

        def q_scalar(name: str, t: float) -> float:
            Yt = sol(t)
            p1, _, _, fc1, nn1 = eq.pair_arrays(np.array([t]), Yt.reshape(-1, 1), pair, mode, v0)
            return float({"p": p1, "fc": fc1, "nn": nn1}[name][0])

        for name, vals in (("p", p), ("fc", fc), ("nn", nn)):
            res = []
            for sgn in (-1.0, 1.0):  # -1: minimum, +1: maximum
                i = int(np.argmax(sgn * vals))
                best_v, best_t = float(vals[i]), float(grid[i])
                last = grid.size - 1
                refine = 0 < i < last
                if not refine and last > 0:
                    # extremum of the samples at an end of the segment: the true one may lie
                    # just inside (e.g. the other pair's event put a kink there); look one
                    # hundredth of a sub-interval inside
                    tin = best_t + (0.01 if i == 0 else -0.01) * float(
                        grid[1] - grid[0] if i == 0 else grid[last] - grid[last - 1]
                    )
                    refine = sgn * q_scalar(name, tin) > sgn * best_v
                if refine:
                    a, b = float(grid[max(i - 1, 0)]), float(grid[min(i + 1, last)])
                    r = minimize_scalar(
                        lambda t, name=name, sgn=sgn: -sgn * q_scalar(name, t),
                        bounds=(a, b),
                        method="bounded",
                        options={"xatol": 1e-14},
                    )
                    v = -sgn * float(r.fun)
                    if sgn * v > sgn * best_v:
                        best_v, best_t = v, float(r.x)
                res.extend([best_v, best_t])
            out[name] = (res[0], res[1], res[2], res[3])
        return out

    def _dissipation(
        self, sol: Any, ts: np.ndarray, pair: int, mode: int, v0: float, ta: float, tb: float
    ) -> float:
        """int_ta^tb (N - K p^n) pdot dt by 8-point Gauss-Legendre on each step."""
        if not tb > ta:
            return 0.0
        steps = ts[(ts > ta) & (ts < tb)]
        knots = np.concatenate([[ta], steps, [tb]])
        half = 0.5 * np.diff(knots)
        mid = 0.5 * (knots[1:] + knots[:-1])
        nodes = (mid[:, None] + half[:, None] * _GL_X).ravel()
        weights = (half[:, None] * _GL_W).ravel()
        _, pd, fk, _, nn = self.eq.pair_arrays(nodes, sol(nodes), pair, mode, v0)
        return float(np.sum(weights * (nn - fk) * pd))

    def post_segment(self, sol: Any, ts: np.ndarray, ta: float, tb: float) -> None:
        """Fold the segment [ta, tb] (modes constant) into episodes and window ranges."""
        for pair in range(2):
            mode = self.modes[pair]
            if mode == 0 or pair >= self.npair:
                self._fold_ranges(pair, ta, tb, np.zeros(4), np.zeros(4))
                continue
            if sol is None or not tb > ta:
                continue
            v0 = self.v0[pair]
            ex = self._extremes(sol, ts, pair, mode, v0, ta, tb)
            ep = self.open[pair]
            if ep is not None:
                pmin, _, pmax, tpmax = ex["p"]
                if pmax > ep.max_depth:
                    ep.max_depth, ep.t_max_depth = pmax, tpmax
                nmax, tnmax = ex["nn"][2], ex["nn"][3]
                if nmax > ep.peak_force:
                    ep.peak_force, ep.t_peak_force = nmax, tnmax
                ep.min_damping = min(ep.min_damping, ex["fc"][0])
                ep.max_damping = max(ep.max_damping, ex["fc"][2])
                ep.dissipated += self._dissipation(sol, ts, pair, mode, v0, ta, tb)
            # window ranges: clip the segment to each window (refined separately when clipped)
            for w in range(self.W.shape[0]):
                wa, wb = float(self.W[w, 0]), float(self.W[w, 1])
                a, b = max(ta, wa), min(tb, wb)
                if a > b:
                    continue
                exw = ex if (a == ta and b == tb) else self._extremes(sol, ts, pair, mode, v0, a, b)
                pmin, pmax = exw["p"][0], exw["p"][2]
                fk_lo, fk_hi = (
                    self.eq.stiffness_force(pair, pmin),
                    self.eq.stiffness_force(pair, pmax),
                )
                lo = np.array([pmin, fk_lo, exw["fc"][0], exw["nn"][0]])
                hi = np.array([pmax, fk_hi, exw["fc"][2], exw["nn"][2]])
                if mode < 0:
                    lo, hi = -hi, -lo
                self.R[w, pair, :, 0] = np.minimum(self.R[w, pair, :, 0], lo)
                self.R[w, pair, :, 1] = np.maximum(self.R[w, pair, :, 1], hi)

    # ---- the main loop -------------------------------------------------------------------
    def run(self) -> tuple[float, np.ndarray]:
        eq = self.eq
        setup = self.setup
        y = np.asarray(setup.y0, dtype=float)[: eq.n_state].copy()
        t = 0.0
        t_end = setup.duration
        self.start_contacts(t, y, self.npair)
        transfers = [float(tt) for tt in setup.transfer_times if 0.0 < tt < t_end]
        itr = 0
        last_event_t = -1.0
        same_time = 0
        while t < t_end:
            if itr < len(transfers) and t >= transfers[itr]:
                # an event landed exactly on the transfer time
                itr += 1
                self._transfer(t, y)
                continue
            t_stop = transfers[itr] if itr < len(transfers) else t_end
            mt, ms = self.modes
            in_contact = any(self.modes[p] != 0 for p in range(self.npair))
            for p in range(self.npair):
                if self.modes[p] != 0 and self.clamp_watch[p] == 0:
                    f = eq.unclamped_force(t, y, p, self.modes[p], self.v0[p])
                    self.clamp_watch[p] = -1 if f >= 0.0 else 1
            events = eq.make_events(mt, ms, self.v0, self.clamp_watch)
            c0 = time.perf_counter()
            sol = solve_ivp(
                eq.make_rhs(mt, ms, self.v0[0], self.v0[1]),
                (t, t_stop),
                y,
                method=self.method,
                rtol=self.rtol,
                atol=self.atol,
                # (in contact the steps are short anyway: the force holds them)
                max_step=self.hmax if in_contact else self.hmax / N_SUB,
                events=events,
                dense_output=in_contact,
            )
            self.solve_time += time.perf_counter() - c0
            self.stats["segments"] += 1
            self.stats["steps"] += max(sol.t.size - 1, 0)
            self.stats["rhs_evaluations"] += int(sol.nfev)
            if sol.t.size > 1:
                self.stats["min_step"] = min(self.stats["min_step"], float(np.diff(sol.t).min()))
            if self.stats["steps"] > self.max_steps:
                # the compiled solver's message: the smallest step, and what to change
                from braidsim.simulate import failure_message

                if setup.model is not None:
                    msg = failure_message(L.ST_MAX_STEPS, t, setup.model, self.stats)
                else:
                    msg = (
                        f"the step budget (max_steps = {self.max_steps}) was exhausted at "
                        f"t = {t:.9g} s (smallest step {self.stats['min_step']:.3g} s); raise "
                        "max_steps or the model's min_impact_velocity"
                    )
                raise SimulationError(msg, t)
            if sol.status < 0:
                raise SimulationError(
                    f"solve_ivp ({self.method}) failed at t = {sol.t[-1]:.9g} s: {sol.message}",
                    float(sol.t[-1]),
                )
            fired = [i for i, te in enumerate(sol.t_events) if te.size]
            if sol.status == 1 and fired:
                j = fired[0]
                t_ev = float(sol.t_events[j][0])
                y_ev = np.asarray(sol.y_events[j][0], dtype=float)
            else:
                j = -1
                t_ev = float(sol.t[-1])
                y_ev = sol.y[:, -1].copy()
            if in_contact:
                ts = sol.sol.ts if sol.sol is not None else np.array([t, t_ev])
                self.post_segment(sol.sol, np.asarray(ts), t, t_ev)
            else:
                self.post_segment(None, np.zeros(0), t, t_ev)
            t, y = t_ev, y_ev
            if j >= 0:
                pair, side = events[j].tag
                if side == 0:
                    # the clamp: the same mode on, watching the crossing back
                    self.clamp_watch[pair] = -self.clamp_watch[pair]
                else:
                    self._switch(t, y, pair, side)
                    self.clamp_watch[pair] = 0
                self.stats["events"] += 1
                if t - last_event_t <= 1e-12 * max(1.0, t):
                    same_time += 1
                    if same_time > _MAX_SAME_TIME_EVENTS:
                        raise SimulationError(
                            f"more than {_MAX_SAME_TIME_EVENTS} contact events at the same instant "
                            f"t = {t:.9g} s (grazing contact); raise contact.min_impact_velocity",
                            t,
                        )
                else:
                    same_time = 0
                last_event_t = t
                continue
            if itr < len(transfers) and t >= t_stop:
                t = t_stop
                itr += 1
                self._transfer(t, y)
        for ep in self.open:
            if ep is not None:
                ep.t_end = t
                ep.end_reason = 1
        return t, y

    def _switch(self, t: float, y: np.ndarray, pair: int, side: int) -> None:
        eq = self.eq
        ud = eq.gaps(t, y, pair)[2]
        rate = -ud if side < 0 else ud  # penetration rate into this wall
        if self.modes[pair] == 0:
            vlat = max(rate, eq.vmin)
            self.modes[pair] = side
            self.v0[pair] = vlat
            new = _Episode(t, pair, side, rate, vlat, False, t_max_depth=t, t_peak_force=t)
            self.open[pair] = new
            self.episodes.append(new)
        else:
            ep = self.open[pair]
            if ep is not None:
                ep.t_end = t
                ep.rebound = -rate
                ep.end_reason = 0
            self.open[pair] = None
            self.modes[pair] = 0

    def _transfer(self, t: float, y: np.ndarray) -> None:
        """The model's transfer (the carrier's to the next horn gear: the wall it leans on
        becomes the far wall); the contacts of the pairs it names end and start anew."""
        self.stats["transfers"] += 1
        k = self.eq.transfer(t, y)
        for pair in range(k):
            ep = self.open[pair]
            if ep is not None:
                ep.t_end = t
                ep.end_reason = 2
                self.open[pair] = None
            self.modes[pair] = 0
            self.clamp_watch[pair] = 0
        self.start_contacts(t, y, k)


def simulate_scipy(
    scenario: Scenario | str | Path | Mapping[str, Any],
    duration: float | None = None,
    *,
    overrides: Mapping[str, Any] | None = None,
    method: str = "DOP853",
    rtol: float = 1e-8,
    atol: float | Sequence[float] | None = None,
    windows: Sequence[tuple[float, float]] | None = None,
    record: Any = None,
) -> ScipyResult:
    """Simulate one carrier with :func:`scipy.integrate.solve_ivp` (reference backend).

    Parameters
    ----------
    scenario : Scenario, str, Path or mapping
        As for :func:`braidsim.simulate`.
    duration : float, optional
        Simulated time [s]; default ``simulation.duration``.
    overrides : mapping, optional
        Extra ``{key: value}`` applied on top of the scenario.
    method : str
        Any :func:`~scipy.integrate.solve_ivp` method; default ``"DOP853"``.
    rtol : float
        Relative tolerance of solve_ivp (the scenario's ``simulation.rtol`` is not used here).
    atol : float or sequence, optional
        Absolute tolerance(s); default ``simulation.atol_position`` [m] on positions and
        ``simulation.atol_velocity`` [m/s] on velocities, as in the compiled solver.
    windows : sequence of (t0, t1), optional
        Extra windows [s] for the ranges (window 0 is the whole run).
    record : CarrierX or CarrierXY, optional
        The carrier's record of the compiled core to integrate instead of the scenario's,
        of the same class (the scenario still gives the initial state, the duration, the
        tolerances and the transfers): the scenario's record with a law, friction law or
        excitation of one's own, ``build_model(sc).record._replace(track_law=MyLaw(...))``,
        checked against this independent integration of the same functions (the backend
        calls the record's registered implementations). A model of another class:
        :func:`integrate_scipy`.

    Returns
    -------
    ScipyResult
        Impact table, window ranges, final state and solver statistics.
    """
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if overrides:
        sc = sc.with_overrides(overrides)
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise InputError(f"duration: {duration!r} s is out of range; allowed > 0 s")
    if not (0.0 < rtol < 1.0):
        raise InputError(f"rtol: {rtol!r} is out of range; allowed 0 < rtol < 1")
    model = build_model(sc, duration)
    if record is not None:
        if type(record) is not type(model.record):
            raise InputError(
                f"record: a {type(record).__name__}; allowed a record of the scenario's "
                f"carrier class, {type(model.record).__name__} (another model: "
                "integrate_scipy(record, options, y0))"
            )
        model = dataclasses.replace(model, record=record)
    from braidsim.simulate import run_windows

    W = run_windows(0.0, model.duration, windows)
    setup = _Setup(
        model.record,
        model.y0,
        model.duration,
        np.asarray(model.transfer_times, dtype=float),
        float(model.options.max_step),
        int(model.options.max_steps),
        model,
    )
    res = _integrate(setup, W, method, rtol, atol, model.options)
    y = res.state
    final = {
        "t": res.final["t"],
        "x": float(y[0]),
        "vx": float(y[1]),
        "y": float(y[2]) if y.size > 2 else float(sc["initial.y"]),
        "vy": float(y[3]) if y.size > 2 else float(sc["initial.vy"]),
    }
    return dataclasses.replace(res, model=model, final=final)


def integrate_scipy(
    record: Any,
    options: L.SolverOptions,
    y0: np.ndarray | Sequence[float],
    *,
    transfer_times: Sequence[float] | np.ndarray = (),
    method: str = "DOP853",
    rtol: float | None = None,
    atol: float | Sequence[float] | None = None,
    windows: Sequence[tuple[float, float]] | None = None,
) -> ScipyResult:
    """Integrate any model record of the compiled core with
    :func:`scipy.integrate.solve_ivp`, from the arguments of :func:`braidsim.core.run`: a
    model of one's own (or the impact oscillator) checked against an independent
    integration of its registered functions.

    Parameters
    ----------
    record : model record
        What :func:`braidsim.core.run` takes (its class registers ``model_size``,
        ``derivatives``, ``pair_gaps``, ``pair_law`` and ``apply_transfer``).
    options : SolverOptions
        ``t_end`` [s], ``max_step`` [s] and ``max_steps``; ``rtol``, ``atol_position`` [m]
        and ``atol_velocity`` [m/s] unless given here.
    y0 : array
        The initial state; its first 2 n_coords entries are used (coordinates and speeds).
    transfer_times : sequence of float
        Times [s] of the model's transfers (``apply_transfer``).
    method, rtol, atol, windows
        As for :func:`simulate_scipy` (``rtol`` default: the options').

    Returns
    -------
    ScipyResult
        Its ``model`` the record, ``final`` holds ``t``, ``state`` the final state vector.
    """
    rtol = float(options.rtol) if rtol is None else rtol
    if not (0.0 < rtol < 1.0):
        raise InputError(f"rtol: {rtol!r} is out of range; allowed 0 < rtol < 1")
    if not (math.isfinite(options.t_end) and options.t_end > 0):
        raise InputError(f"options.t_end: {options.t_end!r} s is out of range; allowed > 0 s")
    from braidsim.simulate import run_windows

    W = run_windows(0.0, float(options.t_end), windows)
    setup = _Setup(
        record,
        np.asarray(y0, dtype=float),
        float(options.t_end),
        np.asarray(transfer_times, dtype=float),
        float(options.max_step),
        int(options.max_steps),
    )
    return _integrate(setup, W, method, rtol, atol, options)


def _integrate(
    setup: _Setup,
    W: np.ndarray,
    method: str,
    rtol: float,
    atol: float | Sequence[float] | None,
    options: L.SolverOptions,
) -> ScipyResult:
    """One run of :class:`_Run`, its episodes, ranges and statistics."""
    if atol is None:
        ax, av = float(options.atol_position), float(options.atol_velocity)
        atol = [ax, av] * (model_sizes(setup.record)[0])
    run = _Run(setup, W, method, rtol, atol)
    t0 = time.perf_counter()
    t, y = run.run()
    wall = time.perf_counter() - t0
    EP = np.array([tuple(ep.row()) for ep in run.episodes], dtype=EPISODE_DTYPE)
    stats: dict[str, Any] = dict(run.stats)
    stats.update(
        {"method": method, "rtol": rtol, "wall_time": wall, "solve_ivp_time": run.solve_time}
    )
    return ScipyResult(setup.record, EP, W, run.R, stats, {"t": float(t)}, np.asarray(y))
