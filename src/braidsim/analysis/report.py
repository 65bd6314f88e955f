"""Everything :mod:`braidsim.analysis` says about one run (``braidsim analyze RUN``).

:func:`analyze` simulates a scenario once, sampled uniformly at a whole number of points per
excitation cycle and phase-locked to the track vibration (so that every M-th sample is a
stroboscopic one and a window of whole cycles puts the harmonics on spectral bins), and
reports its impact statistics, energy balance, steady-state regime over the window after
the transient, the contact-loss bound and the spectra of displacement and contact force.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim import limits
from braidsim.analysis.impacts import (
    EnergyBalance,
    ImpactStatistics,
    energy_balance,
    impact_statistics,
)
from braidsim.analysis.regimes import (
    DEFAULT_CYCLES,
    DEFAULT_MAX_PERIOD,
    DEFAULT_PERIOD_TOL,
    DEFAULT_TRANSIENT_CYCLES,
    SteadyState,
    as_scenario,
    contact_loss_bound,
    reference_period,
    steady_state_from_result,
    strobe_times,
)
from braidsim.analysis.spectra import Spectrum, run_spectra
from braidsim.core import CARRIER_COLUMNS
from braidsim.errors import InputError
from braidsim.params import Scenario
from braidsim.units import is_number

if TYPE_CHECKING:
    from braidsim.result import Result


@dataclass(frozen=True)
class RunAnalysis:
    """What :func:`analyze` returns.

    Attributes
    ----------
    result : Result
        The run.
    window : (float, float)
        Steady-state window [s] (after the transient).
    impacts : ImpactStatistics
        Over the whole run.
    impacts_window : ImpactStatistics
        Over the steady-state window.
    energy : EnergyBalance
        Over the whole run.
    steady : SteadyState or None
        Classification over the window (None: the window holds fewer than 2 whole periods
        between stroboscopic samples; ``regime_reason`` says why and what duration is needed).
    bound : dict
        :func:`braidsim.analysis.regimes.contact_loss_bound`.
    spectra : list of Spectrum
        Of x and the track contact force over the window.
    window_rule : str
        How the window was chosen, in words.
    regime_reason : str
        Why ``steady`` is None ("" when it is not).
    """

    result: Result
    window: tuple[float, float]
    impacts: ImpactStatistics
    impacts_window: ImpactStatistics
    energy: EnergyBalance
    steady: SteadyState | None
    bound: dict[str, Any]
    spectra: list[Spectrum]
    window_rule: str = ""
    regime_reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (SI).

        ``regime`` is :meth:`SteadyState.to_dict` with its stroboscopic (Poincare) samples
        ``regime.strobe`` = {t [s], x [m], vx [m/s], u = x - h [m]}, the points of
        ``poincare.png`` and the form of ``bifurcation``'s ``states[i].strobe``; it is
        None when the window is too short to classify, and ``regime_reason`` then says why
        (None otherwise)."""
        sc = self.result.model.scenario
        return {
            "scenario": sc.name,
            "duration": float(self.result.final["t"]),
            "window": list(self.window),
            "window_rule": self.window_rule,
            "impacts": self.impacts.to_dict(sequence=True),
            "impacts_in_window": self.impacts_window.to_dict(sequence=False),
            "energy_balance": self.energy.to_dict(),
            "regime": None if self.steady is None else self.steady.to_dict(samples=True),
            "regime_reason": None if self.steady is not None else self.regime_reason,
            "contact_loss_bound": self.bound,
            "spectra": [s.to_dict() for s in self.spectra],
        }


def default_duration(sc: Scenario) -> float:
    """max(simulation.duration, (100 + 50) T) [s]: the transient and the window of the
    steady-state rule of :func:`analyze` (T the reference period)."""
    T = reference_period(sc)
    return max(float(sc["simulation.duration"]), (DEFAULT_TRANSIENT_CYCLES + DEFAULT_CYCLES) * T)


def default_transient(duration: float, period: float) -> float:
    """max(D / 2, min(100 T, D - 50 T)) [s]: the discarded start of a run of D seconds."""
    return max(
        0.5 * duration,
        min(DEFAULT_TRANSIENT_CYCLES * period, duration - DEFAULT_CYCLES * period),
    )


def sample_grid(sc: Scenario, duration: float, per_cycle: int) -> np.ndarray:
    """Times in [0, duration] at ``per_cycle`` points per reference period, phase-locked to
    the track vibration (omega_h t + phase = 2 pi j / per_cycle)."""
    T = reference_period(sc)
    dt = T / per_cycle
    w = float(sc["track.vibration_frequency"])
    offset = 0.0
    if w > 0.0:
        offset = (-float(sc["track.vibration_phase"]) / w) % T
    offset = offset % dt
    count = (duration - offset) / dt + 1
    # every sample becomes a row of the series kept in memory (explicit sample times are
    # never thinned): a long --duration or a fast vibration would fill the memory
    limits.check(
        "memory",
        count * 8 * (len(CARRIER_COLUMNS) + 1),
        f"duration = {duration:g} s at {per_cycle} samples per period of {T:.3g} s "
        f"({count:.3g} samples)",
    )
    n = math.floor((duration - offset) / dt + 1e-9) + 1
    return offset + dt * np.arange(n)


def _check_spectrum_window(
    grid: np.ndarray,
    window: tuple[float, float],
    duration: float,
    transient: float,
    default_transient: bool,
    dt: float,
) -> None:
    """Refuse, before the run, a window too short for the spectra (4 samples or more).

    The window is half-open, as :func:`braidsim.analysis.spectra.run_spectra` reads it. A
    half-open window of 5 sample intervals ``dt`` holds at least 4 samples, so the bounds
    named are: a duration of 10 dt with the default transient (half of a run this short),
    or a transient that ends 5 dt before the run does.
    """
    t0, t1 = window
    n = int(np.count_nonzero((grid >= t0 - 1e-12) & (grid < t1 - 1e-9 * max(abs(t1), 1e-3))))
    if n >= 4:
        return
    held = f"holds {n} of the samples taken every {dt:.6g} s (fewer than the 4 the spectra need)"
    if default_transient:
        raise InputError(
            f"duration: {duration:g} s is out of range: the analysed second half of the run "
            f"{held}; allowed {10 * dt:.6g} s or more"
        )
    if duration - 5 * dt >= 0.0:
        raise InputError(
            f"transient: {transient:g} s is out of range: the window from it to the end of the "
            f"{duration:g} s run {held}; allowed at most {duration - 5 * dt:.6g} s"
        )
    raise InputError(
        f"duration: {duration:g} s is out of range: the window after the transient {held}; "
        f"allowed {transient + 5 * dt:.6g} s or more with this transient"
    )


def analyze(
    scenario: Scenario | str | Any,
    overrides: Mapping[str, Any] | None = None,
    *,
    duration: float | str | None = None,
    transient: float | str | None = None,
    per_cycle: int = 256,
    period_tol: float = DEFAULT_PERIOD_TOL,
    max_period: int = DEFAULT_MAX_PERIOD,
) -> RunAnalysis:
    """Simulate one scenario and analyse it (module docstring).

    Parameters
    ----------
    scenario : Scenario, str, Path or mapping
        The scenario.
    overrides : mapping, optional
        ``{key: value}`` on top of it.
    duration : float or str, optional
        [s] (or a string with a unit, ``"0.3 s"``); default :func:`default_duration`: long
        enough for the transient and the window of the steady-state rule below.
    transient : float or str, optional
        Start of the steady-state window [s] (or a string with a unit), before ``duration``;
        default :func:`default_transient`.
    per_cycle : int
        Samples per excitation period (>= 16).
    period_tol, max_period
        Regime rule 4 (:mod:`braidsim.analysis.regimes`).

    Steady-state rule
    -----------------
    A run starts with a transient (the first impacts), and what it settles to is judged
    after it, as in the other analysis verbs: with T the reference period
    (:func:`braidsim.analysis.regimes.reference_period`, T_h = 2 pi / omega_h),
    ``DEFAULT_TRANSIENT_CYCLES`` = 100 periods are discarded and ``DEFAULT_CYCLES`` = 50
    periods are analysed. The default duration is max(simulation.duration, 150 T) and the
    default transient max(D / 2, min(100 T, D - 50 T)) for a run of D seconds: 100 periods
    when the run holds 150, never less than its first half. The window used is reported
    (``window`` and ``window_rule`` of :meth:`RunAnalysis.to_dict`).
    """
    from braidsim.simulate import simulate, time_value

    sc = as_scenario(scenario, overrides)
    T = reference_period(sc)
    # numbers in s or strings with a unit, as simulate reads them
    T_run = default_duration(sc) if duration is None else time_value("duration", duration)
    if transient is None:
        t_tr = default_transient(T_run, T)
    else:
        t_tr = time_value("transient", transient, allow_zero=True)
    if not t_tr < T_run:
        raise InputError(f"transient: {t_tr:g} s is out of range; allowed 0 <= T < {T_run:g} s")
    if not is_number(per_cycle) or not math.isfinite(per_cycle) or int(per_cycle) != per_cycle:
        raise InputError(f"per_cycle: {per_cycle!r} is not allowed; allowed an integer >= 16")
    if per_cycle < 16:
        raise InputError(f"per_cycle: {per_cycle!r} is out of range; allowed an integer >= 16")
    grid = sample_grid(sc, T_run, int(per_cycle))
    n_cyc = math.floor((T_run - t_tr) / T + 1e-9)
    window = (t_tr, T_run)
    strobes = None
    if n_cyc >= 2:
        st = strobe_times(sc, t_tr, n_cyc)
        if st[-1] > T_run + 1e-12:
            st = st[:-1]
        # the strobe times are grid points: take them from the grid to share bits
        idx = np.clip(np.searchsorted(grid, st - 1e-12), 0, grid.size - 1)
        st = grid[idx]
        if st.size >= 3:
            window = (float(st[0]), float(st[-1]))
            strobes = st
    _check_spectrum_window(grid, window, T_run, t_tr, transient is None, T / per_cycle)
    res = simulate(sc, duration=T_run, sample_times=grid)
    steady = None
    if strobes is not None:
        steady = steady_state_from_result(res, window, strobes, None, period_tol, max_period)
    spectra = run_spectra(res, window)
    how = (
        f"given: transient {t_tr:g} s"
        if transient is not None
        else f"default: max(D/2, min({DEFAULT_TRANSIENT_CYCLES} T, D - {DEFAULT_CYCLES} T)) "
        f"= {t_tr:.6g} s discarded"
    )
    reason = ""
    if steady is not None:
        span = f"steady state over whole periods {window[0]:.6g}-{window[1]:.6g} s"
    else:
        periods = (window[1] - window[0]) / T
        span = (
            f"window {window[0]:.6g}-{window[1]:.6g} s ({periods:.3g} periods), too short "
            "for whole periods"
        )
        # a window of 3 T always holds 3 stroboscopic samples, 2 whole periods (the first
        # sample lies less than T after its start); the default transient of a run shorter
        # than 100 T is half of it, so such a run needs 6 T
        if transient is None:
            need = f"a duration of {6 * T:.6g} s or more (6 T: the default transient is half"
            need += " of a run this short)"
        else:
            need = f"a duration of {t_tr + 3 * T:.6g} s or more (the transient + 3 T)"
            if T_run - 3 * T >= 0.0:
                need += f", or a transient of at most {T_run - 3 * T:.6g} s,"
        reason = (
            f"not classified: the steady-state window {window[0]:.6g}-{window[1]:.6g} s "
            f"holds {periods:.3g} periods of the excitation (T = {T:.6g} s), fewer than the "
            f"2 whole periods between stroboscopic samples that the regime rules need; "
            f"{need} always gives them"
        )
    rule = f"{how} of a {T_run:g} s run (T = {T:.6g} s, {T_run / T:.4g} periods); {span}"
    return RunAnalysis(
        res,
        window,
        impact_statistics(res),
        impact_statistics(res, window),
        energy_balance(res),
        steady,
        contact_loss_bound(sc),
        spectra,
        rule,
        reason,
    )
