"""Impact statistics and the energy balance of a run.

Impact statistics
-----------------
From the run's contact episodes (exact onset and exit times and approach speeds from the
integrator): the impact sequence (onsets in a window; a contact present at the start has
no approach and is not an impact), counts per pair and wall, the histogram of approach
speeds, the contact-time fraction (time in contact inside the window over its length, per
pair), and the energy dissipated by each impact, int (N - K p^n) pdot dt over the episode.

Energy balance
--------------
With E = m (vx^2 + vy^2) / 2 + K_t p_t^(n_t+1) / (n_t+1) + K_s p_s^(n_s+1) / (n_s+1) the
kinetic plus elastic contact energy [J], the equations of motion give

    E(t) - E(t0) = W_load + W_track + W_slot - Q_contact - Q_friction

with W_load the work of the constant loads (tension and centrifugal, -int (T1 cos phi +
m r_c omega^2) vx dt, and int T1 sin phi vy dt), W_track and W_slot the work of the moving
track and slot walls on the carrier (int -s N hdot dt, the wall velocity times the contact
force), Q_contact = int (N - K p^n) pdot dt >= 0 the contact damping losses and
Q_friction = int f v dt >= 0 the friction losses. The kernel integrates these quadratures
with the state (same Runge-Kutta steps, same tolerance), so the residual of the balance
measures the integration error; :func:`energy_balance` reports it relative to the energy
exchanged, max |W| + max |Q| over the run.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.errors import InputError

if TYPE_CHECKING:
    import pandas as pd

    from braidsim.result import Result


Window = tuple[float | str, float | str]
"""A window (t0, t1) [s]: numbers in s or strings with a unit (``("1 ms", "5 ms")``)."""


def _window(result: Result, window: Window | None) -> tuple[float, float]:
    """The window as floats [s], the whole run when None; an InputError unless it is a
    (t0, t1) pair inside the run's span."""
    from braidsim.simulate import time_window

    start, end = float(result.windows[0, 0]), float(result.windows[0, 1])
    if window is None:
        return start, end
    return time_window("window", window, start, end)


def impact_sequence(result: Result, window: Window | None = None) -> pd.DataFrame:
    """The impacts (contact onsets with an approach) whose onset lies in ``window``."""
    t0, t1 = _window(result, window)
    imp = result.impacts
    sel = (~imp["initial"]) & (imp["t"] >= t0) & (imp["t"] <= t1)
    return imp[sel].reset_index(drop=True)


def contact_fraction(result: Result, pair: str = "track", window: Window | None = None) -> float:
    """Time in contact with a wall of ``pair`` inside ``window`` over its length [-]."""
    t0, t1 = _window(result, window)
    imp = result.impacts
    mine = imp[imp["pair"] == pair]
    t_end = mine["t_end"].to_numpy().copy()
    t_end[np.isnan(t_end)] = result.final["t"]
    inside = np.clip(np.minimum(t_end, t1) - np.maximum(mine["t"].to_numpy(), t0), 0.0, None)
    return float(inside.sum()) / (t1 - t0)


@dataclass(frozen=True)
class ImpactStatistics:
    """Impact statistics of a run over a window (module docstring).

    Attributes
    ----------
    window : (float, float)
        Window (t0, t1) [s].
    impacts : pandas.DataFrame
        The impact sequence (columns of :attr:`braidsim.Result.impacts`).
    counts : dict
        Impacts per ``pair/wall``.
    contact_fraction : dict
        Per pair [-].
    speed_bins, speed_counts : np.ndarray
        Histogram of the approach speeds [m/s] (edges, counts) of the track impacts.
    excitation_cycles : float
        Window length in excitation cycles (NaN without vibration).
    """

    window: tuple[float, float]
    impacts: pd.DataFrame
    counts: dict[str, int]
    contact_fraction: dict[str, float]
    speed_bins: np.ndarray
    speed_counts: np.ndarray
    excitation_cycles: float

    def to_dict(self, sequence: bool = True) -> dict[str, Any]:
        """JSON-ready form (SI)."""
        imp = self.impacts
        track = imp[imp["pair"] == "track"]
        v = track["velocity"].to_numpy()
        q = imp["dissipated_energy"].to_numpy()
        out: dict[str, Any] = {
            "window": list(self.window),
            "count": len(imp),
            "counts": self.counts,
            "per_excitation_cycle": len(track) / self.excitation_cycles
            if self.excitation_cycles > 0
            else None,
            "contact_fraction": self.contact_fraction,
            "approach_speed": {
                "min": float(v.min()) if v.size else None,
                "mean": float(v.mean()) if v.size else None,
                "max": float(v.max()) if v.size else None,
                "histogram": {
                    "edges": self.speed_bins.tolist(),
                    "counts": self.speed_counts.astype(int).tolist(),
                },
            },
            "dissipated_energy": {
                "total": float(np.nansum(q)),
                "mean_per_impact": float(np.nanmean(q)) if q.size else None,
                "max_per_impact": float(np.nanmax(q)) if q.size else None,
            },
        }
        if sequence:
            out["sequence"] = [
                {
                    "t": float(r.t),
                    "pair": r.pair,
                    "wall": r.wall,
                    "velocity": float(r.velocity),
                    "rebound_velocity": None
                    if not math.isfinite(r.rebound_velocity)
                    else float(r.rebound_velocity),
                    "peak_force": float(r.peak_force),
                    "max_depth": float(r.max_depth),
                    "duration": None if not math.isfinite(r.duration) else float(r.duration),
                    "dissipated_energy": float(r.dissipated_energy),
                }
                for r in imp.itertuples()
            ]
        return out


def impact_statistics(
    result: Result, window: Window | None = None, bins: int = 20
) -> ImpactStatistics:
    """Impact statistics of ``result`` over ``window`` (default: the whole run), with a
    histogram of ``bins`` (>= 1) approach-speed bins."""
    t0, t1 = _window(result, window)
    if isinstance(bins, bool) or not isinstance(bins, numbers.Integral) or bins < 1:
        raise InputError(f"bins: {bins!r} is out of range; allowed an integer >= 1")
    imp = impact_sequence(result, (t0, t1))
    counts: dict[str, int] = {}
    for (pair, wall), grp in imp.groupby(["pair", "wall"]):
        counts[f"{pair}/{wall}"] = len(grp)
    v = imp.loc[imp["pair"] == "track", "velocity"].to_numpy()
    hi = float(v.max()) if v.size else 1.0
    edges = np.linspace(0.0, hi * (1.0 + 1e-9), int(bins) + 1)
    hist, _ = np.histogram(v, bins=edges)
    w_h = float(result.model.scenario["track.vibration_frequency"])
    cyc = (t1 - t0) * w_h / (2.0 * math.pi) if w_h > 0 else math.nan
    fractions = {p: contact_fraction(result, p, (t0, t1)) for p in ("track", "slot")}
    return ImpactStatistics((t0, t1), imp, counts, fractions, edges, hist, cyc)


@dataclass(frozen=True)
class EnergyBalance:
    """Energy balance of a run (module docstring); arrays on the run's series rows [J].

    Attributes
    ----------
    t : np.ndarray
        Times [s].
    kinetic, elastic : np.ndarray
        m v^2 / 2 and the elastic contact energy.
    load_work, track_work, slot_work : np.ndarray
        Work done on the carrier since the start by the constant loads and the moving walls.
    transfer_work : np.ndarray
        Energy given to the carrier by the transfers to the next horn gear (the jump of its
        kinetic and elastic energy at each transfer).
    contact_dissipated, friction_dissipated : np.ndarray
        Losses since the start (>= 0).
    residual : np.ndarray
        (E - E(t0)) - (W - Q).
    exchanged : float
        max |W| + max |Q| over the run [J].
    """

    t: np.ndarray
    kinetic: np.ndarray
    elastic: np.ndarray
    load_work: np.ndarray
    track_work: np.ndarray
    slot_work: np.ndarray
    transfer_work: np.ndarray
    contact_dissipated: np.ndarray
    friction_dissipated: np.ndarray
    residual: np.ndarray
    exchanged: float

    @property
    def closure(self) -> float:
        """max |residual| / exchanged [-] (0 when nothing was exchanged)."""
        r = float(np.max(np.abs(self.residual))) if self.residual.size else 0.0
        return r / self.exchanged if self.exchanged > 0 else r

    def totals(self) -> dict[str, float]:
        """Change of each term from the first to the last row [J]."""

        def d(a: np.ndarray) -> float:
            return float(a[-1] - a[0]) if a.size else 0.0

        return {
            "kinetic": d(self.kinetic),
            "elastic": d(self.elastic),
            "load_work": d(self.load_work),
            "track_work": d(self.track_work),
            "slot_work": d(self.slot_work),
            "transfer_work": d(self.transfer_work),
            "contact_dissipated": d(self.contact_dissipated),
            "friction_dissipated": d(self.friction_dissipated),
            "residual": d(self.residual),
        }

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (SI)."""
        return {
            "window": [float(self.t[0]), float(self.t[-1])] if self.t.size else None,
            "totals": self.totals(),
            "exchanged": self.exchanged,
            "max_abs_residual": float(np.max(np.abs(self.residual))) if self.residual.size else 0.0,
            "closure": self.closure,
            "equation": "dE_kinetic + dE_elastic = W_load + W_track + W_slot + W_transfer"
            " - Q_contact - Q_friction",
        }


def energy_balance(result: Result, window: Window | None = None) -> EnergyBalance:
    """The energy balance of ``result`` over ``window`` (default: the whole run; a (t0, t1)
    pair [s] inside the run, numbers in s or strings with a unit).

    Every term is measured from the first series row in the window, so a window that starts
    after a transient gives the balance of the steady state alone.
    """
    s = result.series
    t = s["t"]
    sel = np.ones(t.size, dtype=bool)
    if window is not None:
        t0, t1 = _window(result, window)
        sel = (t >= t0) & (t <= t1)
    m = float(result.model.scenario["carrier.mass"])
    kt, nt = result.model.track.stiffness, result.model.track.exponent
    ks, ns = result.model.slot.stiffness, result.model.slot.exponent
    pt = np.abs(s["track_depth"][sel])
    ps = np.abs(s["slot_depth"][sel])
    kinetic = 0.5 * m * (s["vx"][sel] ** 2 + s["vy"][sel] ** 2)
    elastic = kt * pt ** (nt + 1.0) / (nt + 1.0) + ks * ps ** (ns + 1.0) / (ns + 1.0)

    def rel(a: np.ndarray) -> np.ndarray:
        return a - a[0] if a.size else a

    load = rel(s["load_work_x"][sel] + s["load_work_y"][sel])
    track = rel(s["track_work"][sel])
    slot = rel(s["slot_work"][sel])
    transfer = rel(s["transfer_work"][sel])
    qc = rel(s["track_dissipated"][sel] + s["slot_dissipated"][sel])
    qf = rel(s["friction_work_x"][sel] + s["friction_work_y"][sel])
    energy = kinetic + elastic
    residual = rel(energy) - (load + track + slot + transfer - qc - qf)
    supplied = load + track + slot + transfer
    lost = qc + qf
    exchanged = float(np.max(np.abs(supplied)) + np.max(np.abs(lost))) if supplied.size else 0.0
    return EnergyBalance(
        t[sel], kinetic, elastic, load, track, slot, transfer, qc, qf, residual, exchanged
    )
