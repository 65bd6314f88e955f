"""The immutable result of one simulation: series, impact table, window ranges, summary.

Signs follow the paper (docs/model.md §3): the depth, the stiffness-related force F_kg,
the damping-related force F_cg and the total contact force carry the sign of the wall,
negative on the inner (rear) wall and positive on the outer (front) wall.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.integrate import kernel as K

if TYPE_CHECKING:
    import pandas as pd
    import xarray as xr

    from braidsim.model import Model

UNITS = {
    "t": "s",
    "x": "m",
    "vx": "m/s",
    "y": "m",
    "vy": "m/s",
    "track_depth": "m",
    "track_stiffness_force": "N",
    "track_damping_force": "N",
    "track_contact_force": "N",
    "slot_depth": "m",
    "slot_stiffness_force": "N",
    "slot_damping_force": "N",
    "slot_contact_force": "N",
    "friction_x": "N",
    "friction_y": "N",
    "track_dissipated": "J",
    "slot_dissipated": "J",
    "friction_work_x": "J",
    "friction_work_y": "J",
    "load_work_x": "J",
    "track_work": "J",
    "load_work_y": "J",
    "slot_work": "J",
    "track_position": "m",
    "slot_position": "m",
    "omega": "rad/s",
    "kind": "",
}
KIND_NAMES = ("sample", "onset", "exit", "peak", "transfer", "start", "end")
RANGE_QUANTITIES = ("depth", "stiffness_force", "damping_force", "contact_force")
PAIRS = ("track", "slot")
WALLS = {("track", -1): "inner", ("track", 1): "outer", ("slot", -1): "rear", ("slot", 1): "front"}
IMPACT_UNITS = {
    "t": "s",
    "t_end": "s",
    "velocity": "m/s",
    "latched_velocity": "m/s",
    "rebound_velocity": "m/s",
    "max_depth": "m",
    "t_max_depth": "s",
    "peak_force": "N",
    "t_peak_force": "s",
    "min_damping_force": "N",
    "max_damping_force": "N",
    "dissipated_energy": "J",
    "duration": "s",
}


def impacts_frame(episodes: np.ndarray) -> pd.DataFrame:
    """The impact table of a raw episode array (columns of ``kernel.EPISODE_COLUMNS``)."""
    import pandas as pd

    c = {name: episodes[:, i] for i, name in enumerate(K.EPISODE_COLUMNS)}
    pairs = [PAIRS[int(p)] for p in c["pair"]]
    walls = [WALLS[(pr, int(w))] for pr, w in zip(pairs, c["wall"], strict=True)]
    return pd.DataFrame(
        {
            "t": c["t"],
            "t_end": c["t_end"],
            "duration": c["t_end"] - c["t"],
            "pair": np.array(pairs, dtype=object),
            "wall": np.array(walls, dtype=object),
            "velocity": c["velocity"],
            "latched_velocity": c["latched_velocity"],
            "rebound_velocity": c["rebound_velocity"],
            "max_depth": c["max_depth"],
            "t_max_depth": c["t_max_depth"],
            "peak_force": c["peak_force"],
            "t_peak_force": c["t_peak_force"],
            "min_damping_force": c["min_damping_force"],
            "max_damping_force": c["max_damping_force"],
            "dissipated_energy": c["dissipated_energy"],
            "ongoing": c["end_reason"] == 1.0,
            "cut_by_transfer": c["end_reason"] == 2.0,
            "initial": c["initial"] == 1.0,
        }
    )


def ranges_dict(ranges: np.ndarray, pair: str = "track", window: int = 0) -> dict[str, list[float]]:
    """``{"depth": [min, max], ...}`` of one pair and window of a (window, pair, quantity,
    min/max) range array; a window that saw no point reads [0, 0]."""
    ip = PAIRS.index(pair)
    out = {}
    for q, name in enumerate(RANGE_QUANTITIES):
        lo, hi = ranges[window, ip, q]
        if not math.isfinite(lo):
            lo = hi = 0.0
        out[name] = [float(lo), float(hi)]
    return out


@dataclass(frozen=True)
class State:
    """A full state of the hybrid system: where a run can be continued from.

    Attributes
    ----------
    t : float
        Time [s].
    y : tuple of float
        The kernel's state vector (x, vx, y, vy [SI] and the energy quadratures [J]).
    track_mode, slot_mode : int
        -1 inner/rear wall, +1 outer/front wall, 0 free.
    track_v0, slot_v0 : float
        Latched approach speeds of the contacts in progress [m/s].
    """

    t: float
    y: tuple[float, ...]
    track_mode: int = 0
    slot_mode: int = 0
    track_v0: float = 1.0
    slot_v0: float = 1.0


def _json_float(v: float) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


@dataclass(frozen=True)
class Result:
    """What :func:`braidsim.simulate` returns.

    Attributes
    ----------
    model : Model
        The resolved model (parameters, stiffnesses, damping factors).
    series : Mapping[str, np.ndarray]
        Columns of :data:`braidsim.integrate.kernel.COLUMNS`, sorted by time: the samples
        asked for plus the exact states at contact onset, exit, peaks and transfers.
    episodes : np.ndarray
        Raw contact episodes, columns :data:`braidsim.integrate.kernel.EPISODE_COLUMNS`.
    windows : np.ndarray
        (n, 2) windows of ``ranges``; window 0 is the whole run.
    ranges : np.ndarray
        (n, pair, quantity, min/max) extremes, exact (refined on the interpolant).
    stats : Mapping[str, float]
        Integrator statistics.
    final : Mapping[str, float]
        Final state.
    final_state : State
        Final state with the contact modes and latched speeds, to continue the run with
        ``simulate(..., start=result.final_state)``.
    rms_x : np.ndarray or None
        RMS of x over each window [m], sqrt((1 / (t1 - t0)) int_t0^t1 x^2 dt), the integral
        by a 4-point Gauss-Legendre rule on the interpolant of every step (exact up to the
        integrator's own error, whatever the samples).
    """

    model: Model
    series: Mapping[str, np.ndarray]
    episodes: np.ndarray
    windows: np.ndarray
    ranges: np.ndarray
    stats: Mapping[str, Any]
    final: Mapping[str, float]
    final_state: State | None = None
    rms_x: np.ndarray | None = None
    backend: str = "compiled"
    _cache: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    # ------------------------------------------------------------------ impacts
    @property
    def impacts(self) -> pd.DataFrame:
        """The impact table, one row per contact episode (pandas DataFrame, SI units).

        Columns: t, t_end, duration, pair, wall, velocity (approach speed at onset),
        latched_velocity (v0 used by the law), rebound_velocity (NaN while still in contact),
        max_depth, peak_force, min/max_damping_force, dissipated_energy, ongoing, initial.
        """
        if "impacts" not in self._cache:
            self._cache["impacts"] = impacts_frame(self.episodes)
        return self._cache["impacts"]

    # ------------------------------------------------------------------ ranges
    def ranges_dict(self, pair: str = "track", window: int = 0) -> dict[str, list[float]]:
        """Exact extremes of one pair in one window, paper signs, SI units.

        ``{"depth": [min, max], "stiffness_force": .., "damping_force": .., "contact_force": ..}``
        """
        return ranges_dict(self.ranges, pair, window)

    def window_index(self, t0: float, t1: float) -> int:
        """Index of the window [t0, t1] (it must have been asked for in ``simulate``)."""
        for i, (a, b) in enumerate(self.windows):
            if math.isclose(a, t0, abs_tol=1e-12) and math.isclose(b, t1, abs_tol=1e-12):
                return i
        raise KeyError(
            f"window [{t0}, {t1}] was not computed; pass windows=[({t0}, {t1})] to simulate"
        )

    # ------------------------------------------------------------------ summary
    def summary(self, window: tuple[float, float] | None = None) -> dict[str, Any]:
        """The JSON object of ``braidsim run --json``, SI units (keys in docs/cli.md).

        With ``window`` the ranges and the impact list cover only [t0, t1].
        """
        iw = 0 if window is None else self.window_index(*window)
        imp = self.impacts
        if window is not None:
            imp = imp[(imp["t"] >= window[0]) & (imp["t"] <= window[1])]
        impacts = [
            {
                "t": float(r.t),
                "pair": r.pair,
                "wall": r.wall,
                "velocity": _json_float(r.velocity),
                "rebound_velocity": _json_float(r.rebound_velocity),
                "peak_force": float(r.peak_force),
                "max_depth": float(r.max_depth),
                "duration": _json_float(r.duration),
                "dissipated_energy": _json_float(r.dissipated_energy),
                "latched_velocity": float(r.latched_velocity),
                "ongoing": bool(r.ongoing),
                "initial": bool(r.initial),
            }
            for r in imp.itertuples()
        ]
        return {
            "scenario": self.model.scenario.name,
            "parameters": self.model.scenario.to_dict(),
            "window": [float(self.windows[iw, 0]), float(self.windows[iw, 1])],
            "x": self.ranges_dict("track", iw),
            "y": self.ranges_dict("slot", iw),
            "impacts": impacts,
            "final": {k: float(v) for k, v in self.final.items()},
            "stats": dict(self.stats),
        }

    # ------------------------------------------------------------------ exports
    def to_xarray(self) -> xr.Dataset:
        """The series as an xarray Dataset on a ``t`` dimension, units in ``attrs``."""
        import xarray as xr

        t = self.series["t"]
        data_vars = {}
        for name, values in self.series.items():
            if name == "t":
                continue
            if name == "kind":
                data_vars[name] = (
                    "t",
                    values.astype(np.int8),
                    {
                        "description": "row kind: "
                        + ", ".join(f"{i} {n}" for i, n in enumerate(KIND_NAMES))
                    },
                )
            else:
                data_vars[name] = ("t", values, {"units": UNITS[name]})
        ds = xr.Dataset(data_vars, coords={"t": ("t", t, {"units": "s"})})
        ds.attrs.update(
            {
                "scenario": self.model.scenario.name,
                "track_stiffness_N_per_m_n": self.model.track.stiffness,
                "track_law": self.model.track.law,
                "slot_law": self.model.slot.law,
                "sign_convention": "depth and forces negative on the inner/rear wall",
            }
        )
        return ds

    def to_csv(self, directory: str | Path) -> list[Path]:
        """Write ``series.csv`` and ``impacts.csv`` into ``directory``; return the paths."""
        from braidsim.io import atomic_write_text

        d = Path(directory)
        names = list(self.series)
        header = ",".join(f"{n} [{UNITS[n]}]" if UNITS[n] else n for n in names)
        arr = np.column_stack([self.series[n] for n in names])
        import io

        buf = io.StringIO()
        np.savetxt(buf, arr, delimiter=",", header=header, comments="", fmt="%.10g")
        p1 = atomic_write_text(d / "series.csv", buf.getvalue())
        p2 = atomic_write_text(d / "impacts.csv", self.impacts.to_csv(index=False))
        return [p1, p2]
