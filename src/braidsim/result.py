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

from braidsim.core.layout import EPISODE_COLUMNS, KIND_NAMES
from braidsim.errors import InputError
from braidsim.units import to_si

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
    "transfer_work": "J",
    "kind": "",
}
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
    """The impact table of the solver's episode records (``EPISODE_DTYPE`` rows);
    ``attrs["units"]`` gives the SI unit of each column ("" for none), as a batch's table
    does."""
    import pandas as pd

    c = {name: episodes[name] for name in EPISODE_COLUMNS}
    pairs = [PAIRS[int(p)] for p in c["pair"]]
    walls = [WALLS[(pr, int(w))] for pr, w in zip(pairs, c["wall"], strict=True)]
    df = pd.DataFrame(
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
    df.attrs["units"] = {name: IMPACT_UNITS.get(name, "") for name in df.columns}
    return df


def impacts_csv(impacts: pd.DataFrame) -> str:
    """The impact table as CSV text, each header with its unit in brackets as in
    ``series.csv`` (``t [s]``, ``peak_force [N]``; ``pair`` has none), from
    ``impacts.attrs["units"]``; the readers of measured impact lists
    (:func:`braidsim.fit.data.read_csv`) take such headers."""
    units = impacts.attrs.get("units", {})
    header = [f"{name} [{units[name]}]" if units.get(name) else str(name) for name in impacts]
    return str(impacts.to_csv(index=False, header=header))


def ranges_dict(ranges: np.ndarray, pair: str = "track", window: int = 0) -> dict[str, list[float]]:
    """``{"depth": [min, max], ...}`` of one pair and window of a (window, pair, quantity,
    min/max) range array; a window that saw no point reads [0, 0].

    Raises
    ------
    InputError
        ``pair`` not one of :data:`PAIRS`, or ``window`` not the index of a window.
    """
    if pair not in PAIRS:
        raise InputError(f"pair: {pair!r} is not known; allowed {' or '.join(PAIRS)}")
    n = ranges.shape[0]
    if not (isinstance(window, int | np.integer) and -n <= window < n):
        raise InputError(
            f"window: {window!r} is out of range; allowed 0 to {n - 1} (the index of a window "
            "of the run; window 0 is the whole run)"
        )
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
        The model's state vector: x, vx (and y, vy in the xy mode) [SI], then the energy
        quadratures [J] (see :mod:`braidsim.core.models.carrier`).
    track_mode, slot_mode : int
        -1 inner/rear wall, +1 outer/front wall, 0 free.
    track_v0, slot_v0 : float
        Latched approach speeds of the contacts in progress [m/s].
    step : float
        The next step size of the step control [s] (0: chosen afresh).
    err_old : float
        The step control's memory of the last error norm.
    onset_q : float
        Error exponent of a pending first contact step (0: none).
    onset_pair : int
        The pair whose contact that step starts (0 track, 1 slot; -1: none), for the onset
        series of Taylor-series steps.
    track_clamped, slot_clamped : int
        Whether the contact's force is held at its law's clamp N = max(0, F_k + F_c) (1) or
        not (0), as the solver's last crossing of it left it; -1: not known (read from the
        force's sign when the run starts).
    """

    t: float
    y: tuple[float, ...]
    track_mode: int = 0
    slot_mode: int = 0
    track_v0: float = 1.0
    slot_v0: float = 1.0
    step: float = 0.0
    err_old: float = 1e-4
    onset_q: float = 0.0
    onset_pair: int = -1
    track_clamped: int = -1
    slot_clamped: int = -1


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
        Columns of :data:`braidsim.core.CARRIER_COLUMNS`, sorted by time: the samples
        asked for plus the exact states at contact onset, exit, peaks and transfers.
    episodes : np.ndarray
        Contact episodes, records of :data:`braidsim.core.layout.EPISODE_DTYPE`.
    windows : np.ndarray
        (n, 2) windows of ``ranges``; window 0 is the whole run.
    ranges : np.ndarray
        (n, pair, quantity, min/max) extremes, exact (refined on the interpolant).
    stats : Mapping[str, Any]
        The run's statistics: the steps that ran, ``integrator`` (``"dormand-prince"`` or
        ``"taylor"``) and ``resting_contacts`` (``"explicit"`` or ``"implicit"``; a run with
        sensitivities takes Dormand-Prince steps, explicit, whatever the scenario asks);
        the solver's counts ``steps``, ``rejected_steps``, ``events``, ``rhs_evaluations``,
        ``implicit_steps``, ``taylor_steps``, ``onset_steps``, ``transfers``; ``min_step``
        (None where no step was taken) and ``max_step`` [s]; the track contact's
        ``track_stiffness`` [N/m^n], ``track_damping_factor`` and
        ``track_effective_restitution``; ``sample_interval`` [s] (None with explicit sample
        times) and ``series_rows``.
    final : Mapping[str, float]
        Final state.
    final_state : State
        Final state with the contact modes and latched speeds, to continue the run with
        ``simulate(..., start=result.final_state)``.
    rms_x : np.ndarray or None
        RMS of x over each window [m], sqrt((1 / (t1 - t0)) int_t0^t1 x^2 dt), the integral
        by a 4-point Gauss-Legendre rule on the interpolant of every step (exact up to the
        integrator's own error, whatever the samples). None where the run did not integrate
        it: the lean path (``simulate(..., series=False)``) unless asked with ``rms=True``.
    backend : str
        ``"compiled"`` (braidsim's own solver, what :func:`braidsim.simulate` runs).
    sensitivity : Sensitivities or None
        The forward sensitivities, when ``simulate(..., sensitivities=[...])`` asked for
        them (:class:`braidsim.sensitivity.Sensitivities`).
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
    sensitivity: Any = None
    _cache: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    # ------------------------------------------------------------------ impacts
    @property
    def impacts(self) -> pd.DataFrame:
        """The impact table, one row per contact episode (pandas DataFrame, SI units).

        Columns: t, t_end, duration, pair, wall, velocity (approach speed at onset; in a row
        present at the start, ``initial``, the depth rate at t = 0, which is no approach),
        latched_velocity (v0 used by the law; inf in a row present at the start, released
        elastically, unless contact.initial_impact_velocity sets one), rebound_velocity (NaN
        while still in contact),
        max_depth, t_max_depth, peak_force, t_peak_force, min/max_damping_force,
        dissipated_energy, ongoing (still in contact at the end), cut_by_transfer (ended by
        a transfer), initial (present at the start).
        """
        if "impacts" not in self._cache:
            self._cache["impacts"] = impacts_frame(self.episodes)
        return self._cache["impacts"]

    # ------------------------------------------------------------------ ranges
    def ranges_dict(self, pair: str = "track", window: int = 0) -> dict[str, list[float]]:
        """Exact extremes of one pair in one window, paper signs, SI units.

        ``pair`` is ``"track"`` (x) or ``"slot"`` (y); ``window`` the index of a window of
        :attr:`windows` (0: the whole run; :meth:`window_index` finds one by its times).
        Returns ``{"depth": [min, max] (m), "stiffness_force": [min, max] (N),
        "damping_force": .. (N), "contact_force": .. (N)}``; InputError for an unknown pair
        or window.
        """
        return ranges_dict(self.ranges, pair, window)

    def window_index(self, t0: float, t1: float) -> int:
        """Index of the window from t0 to t1 (in s) in :attr:`windows` (window 0 is the whole run;
        the others must have been asked for with ``simulate(..., windows=[(t0, t1)])``).

        Raises
        ------
        InputError
            No window [t0, t1] was computed (the message lists those that were).
        """
        for i, (a, b) in enumerate(self.windows):
            if math.isclose(a, t0, abs_tol=1e-12) and math.isclose(b, t1, abs_tol=1e-12):
                return i
        have = ", ".join(f"({a:g}, {b:g})" for a, b in self.windows)
        raise InputError(
            f"window: [{t0:g}, {t1:g}] s was not computed; allowed one of {have} (ask for "
            f"others with simulate(..., windows=[({t0:g}, {t1:g})]))"
        )

    # ------------------------------------------------------------------ provenance
    def provenance(self) -> dict[str, Any]:
        """Where this result comes from, as written into every output made of it.

        ``{"braidsim_version", "created", "scenario", "t_start", "duration", "backend",
        "parameters"}``: the package version; ``created``, the UTC time (ISO 8601) of the
        first call (kept, so that every output of one result carries the same one); the
        scenario's name; the start time and the simulated time actually used [s] (the
        ``duration`` argument of :func:`braidsim.simulate` when given, not the scenario's
        default); the backend (``Result.backend``; the steps a run took are in
        ``Result.stats``); and the resolved scenario, every parameter in SI, with
        ``simulation.duration`` set to the duration actually used.
        """
        if "provenance" not in self._cache:
            from datetime import UTC, datetime

            from braidsim import __version__

            params = self.model.scenario.to_dict()
            params["simulation.duration"] = float(self.model.duration)
            self._cache["provenance"] = {
                "braidsim_version": __version__,
                "created": datetime.now(UTC).isoformat(timespec="seconds"),
                "scenario": self.model.scenario.name,
                "t_start": float(self.windows[0, 0]),
                "duration": float(self.model.duration),
                "backend": self.backend,
                "parameters": params,
            }
        prov = dict(self._cache["provenance"])
        prov["parameters"] = dict(prov["parameters"])
        return prov

    # ------------------------------------------------------------------ display
    def __repr__(self) -> str:
        """One line: scenario, time span, sizes, impacts and peak track force."""
        t0, t1 = float(self.windows[0, 0]), float(self.windows[0, 1])
        n = len(self.series["t"]) if "t" in self.series else 0
        lo, hi = self.ranges_dict("track")["contact_force"]
        return (
            f"<braidsim.Result {self.model.scenario.name!r}: t = {t0:g}-{t1:g} s, "
            f"{n} rows, {self.episodes.shape[0]} contacts, "
            f"track contact force {lo:.4g} to {hi:.4g} N, backend {self.backend}>"
        )

    def _repr_html_(self) -> str:
        """A small table for notebooks: the run and the exact ranges of both pairs."""
        import html

        t0, t1 = float(self.windows[0, 0]), float(self.windows[0, 1])
        e = html.escape
        rows = []
        for pair, sym in (("track", "x"), ("slot", "y")):
            r = self.ranges_dict(pair)
            for q in RANGE_QUANTITIES:
                unit = "mm" if q == "depth" else "N"
                f = 1e3 if q == "depth" else 1.0
                rows.append(
                    f"<tr><td>{e(pair)} ({sym})</td><td>{e(q)} [{unit}]</td>"
                    f"<td>{r[q][0] * f:.6g}</td><td>{r[q][1] * f:.6g}</td></tr>"
                )
        imp = self.impacts
        counts = ", ".join(
            f"{e(str(w))} {int(c)}" for w, c in imp["wall"].value_counts().sort_index().items()
        )
        return (
            f"<div><b>braidsim.Result</b> {e(self.model.scenario.name)}: "
            f"t = {t0:g}-{t1:g} s, {len(self.series['t'])} rows, backend {e(self.backend)}; "
            f"{len(imp)} contacts ({counts or 'none'})"
            "<table><thead><tr><th>pair</th><th>quantity</th><th>min</th><th>max</th></tr>"
            f"</thead><tbody>{''.join(rows)}</tbody></table></div>"
        )

    # ------------------------------------------------------------------ summary
    def summary(self, window: tuple[float, float] | None = None) -> dict[str, Any]:
        """The JSON object of ``braidsim run --json``, SI units, as strict JSON data (a value
        that is not finite, such as the latched speed of a contact present at the start, is
        None).

        It starts with the provenance of :meth:`provenance` (``braidsim_version``,
        ``created``, ``scenario``, ``simulation`` with the start time, the duration actually
        simulated and the backend, and ``parameters``, the resolved scenario). With
        ``window``, one of the windows given to :func:`braidsim.simulate` (times in s or
        strings with a unit), the ranges and the impact list cover only [t0, t1]; an
        InputError names the windows there are for another.
        """
        iw = 0
        if window is not None:
            try:
                if isinstance(window, str) or len(window) != 2:
                    raise TypeError
                # each time a number in s or a string with a unit, as simulate's windows
                t0, t1 = (to_si("window", t, "s") for t in window)
                iw = self.window_index(t0, t1)
                window = (t0, t1)
            except (KeyError, TypeError, ValueError):
                have = ", ".join(f"({a:g}, {b:g})" for a, b in self.windows)
                raise InputError(
                    f"window: {window!r} s is not one this result has ranges for; allowed one "
                    f"of {have} (ask for others with simulate(..., windows=[(t0, t1)]))"
                ) from None
        ep = self.episodes  # read directly: the pandas table would cost its import
        rows = np.arange(len(ep))
        if window is not None:
            rows = rows[(ep["t"] >= window[0]) & (ep["t"] <= window[1])]
        sens = self.sensitivity
        impacts = []
        for i in rows:
            r = ep[i]
            pair = PAIRS[int(r["pair"])]
            impacts.append(
                {
                    "t": float(r["t"]),
                    "pair": pair,
                    "wall": WALLS[(pair, int(r["wall"]))],
                    "velocity": _json_float(r["velocity"]),
                    "rebound_velocity": _json_float(r["rebound_velocity"]),
                    "peak_force": float(r["peak_force"]),
                    "max_depth": float(r["max_depth"]),
                    "duration": _json_float(r["t_end"] - r["t"]),
                    "dissipated_energy": _json_float(r["dissipated_energy"]),
                    "latched_velocity": float(r["latched_velocity"]),
                    "ongoing": bool(r["end_reason"] == 1.0),
                    "initial": bool(r["initial"] == 1.0),
                    **({"sensitivity": sens.impact_dict(int(i))} if sens is not None else {}),
                }
            )
        prov = self.provenance()
        from braidsim.io import json_safe

        return json_safe(
            {
                "braidsim_version": prov["braidsim_version"],
                "created": prov["created"],
                "scenario": prov["scenario"],
                "simulation": {
                    "t_start": prov["t_start"],
                    "duration": prov["duration"],
                    "backend": prov["backend"],
                },
                "parameters": prov["parameters"],
                "window": [float(self.windows[iw, 0]), float(self.windows[iw, 1])],
                "x": self.ranges_dict("track", iw),
                "y": self.ranges_dict("slot", iw),
                "impacts": impacts,
                "final": {
                    **{k: float(v) for k, v in self.final.items()},
                    **({"sensitivity": sens.final_dict()} if sens is not None else {}),
                },
                "stats": dict(self.stats),
            }
        )

    # ------------------------------------------------------------------ exports
    def to_xarray(self) -> xr.Dataset:
        """The series as an xarray Dataset with a unique, increasing time index.

        Layout
        ------
        * Dimension ``t`` [s]: every row of :attr:`series` at a distinct time, strictly
          increasing, so that ``ds.sel(t=0.1, method="nearest")`` and ``ds.interp(t=...)``
          work. The exact event states (contact onset, exit, force and depth peaks) stay on
          this axis, so ``ds.track_contact_force.max()`` is the exact extreme. Where two rows
          share one instant (the start and end rows repeat a sample time; a transfer's state
          map gives the state before and after at the same time) the *last* one is kept: the
          state after the jump. ``kind`` says what each kept row is (0 sample, 1 onset,
          2 exit, 3 peak, 4 transfer, 5 start, 6 end).
        * Dimension ``event``: every event row (``kind`` != 0) and every row left out of
          ``t`` by the rule above, in time order, with its own coordinate ``event_t`` [s],
          ``event_kind``, and each quantity as ``event_<name>`` (e.g. ``event_x``,
          ``event_track_contact_force``). Nothing of :attr:`series` is lost between the two.
        * With sensitivities (``simulate(..., sensitivities=[...])``), a dimension ``key``
          (coordinates ``key`` and ``key_units``, the SI unit of each key): ``d_<q>`` on
          ``(t, key)`` and ``event_d_<q>`` on ``(event, key)``, the derivative of each
          series quantity q (x, vx, y, vy, ax, ay, track_contact_force,
          slot_contact_force) at the row's time, in q's unit per the key's; ``final_d_<s>``
          on ``key``, that of the final state (x, vx, y, vy).

        ``attrs`` carry the provenance: ``braidsim_version``, ``created`` (UTC, ISO 8601),
        ``scenario``, ``duration`` [s] (the simulated time actually used), ``t_start`` [s],
        and ``parameters_json``, the resolved scenario (every parameter in SI) as JSON.
        """
        import json

        import xarray as xr

        t = np.asarray(self.series["t"], dtype=float)
        order = np.argsort(t, kind="stable")  # the series is sorted; this is a safeguard
        t = t[order]
        kind = np.asarray(self.series["kind"])[order].astype(np.int8)
        # keep the last row of every run of equal times
        keep = np.ones(t.size, dtype=bool)
        keep[:-1] = t[1:] != t[:-1]
        event = (kind != 0) | ~keep
        kind_doc = "row kind: " + ", ".join(f"{i} {n}" for i, n in enumerate(KIND_NAMES))
        data_vars: dict[str, Any] = {}
        event_vars: dict[str, Any] = {}
        for name, values in self.series.items():
            if name == "t":
                continue
            v = np.asarray(values)[order]
            if name == "kind":
                data_vars["kind"] = ("t", kind[keep], {"description": kind_doc})
                event_vars["event_kind"] = ("event", kind[event], {"description": kind_doc})
            else:
                attrs = {"units": UNITS[name]}
                data_vars[name] = ("t", v[keep], attrs)
                event_vars[f"event_{name}"] = ("event", v[event], attrs)
        ds = xr.Dataset(
            {**data_vars, **event_vars},
            coords={
                "t": ("t", t[keep], {"units": "s", "long_name": "time"}),
                "event_t": ("event", t[event], {"units": "s", "long_name": "time of the event"}),
            },
        )
        if self.sensitivity is not None:
            coords, variables = self._sensitivity_variables(order, keep, event)
            ds = ds.assign_coords(coords).assign(variables)
        ds.attrs.update(
            {
                **{k: v for k, v in self.provenance().items() if k != "parameters"},
                "parameters_json": json.dumps(self.provenance()["parameters"]),
                "track_stiffness_N_per_m_n": self.model.track.stiffness,
                "track_law": self.model.track.law,
                "slot_law": self.model.slot.law,
                "sign_convention": "depth and forces negative on the inner/rear wall",
            }
        )
        return ds

    def _sensitivity_variables(
        self, order: np.ndarray, keep: np.ndarray, event: np.ndarray
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """The forward sensitivities as coordinates and variables of :meth:`to_xarray`'s
        Dataset: along a dimension ``key`` (coordinates ``key``, the scenario keys, and
        ``key_units``, the SI unit of each), ``d_<q>`` on ``(t, key)`` and
        ``event_d_<q>`` on ``(event, key)`` for each series quantity q, the rows split as
        the series' own, and ``final_d_<s>`` on ``key`` for each state s at the end of the
        run."""
        from braidsim.sensitivity import SERIES_QUANTITIES, STATE_NAMES, key_unit

        sens = self.sensitivity
        keys = list(sens.keys)
        coords: dict[str, Any] = {
            "key": ("key", keys, {"long_name": "scenario key of the derivative"}),
            "key_units": (
                "key",
                [key_unit(self.model, k) for k in keys],
                {"description": "SI unit of each key (dimensionless: empty)"},
            ),
        }
        out: dict[str, Any] = {}

        units = {**UNITS, "ax": "m/s^2", "ay": "m/s^2"}  # accelerations: not series columns

        def attrs(q: str) -> dict[str, str]:
            u = units[q] or "1"
            return {
                "description": f"d {q} / d key, in {u} per the key's SI unit (key_units)",
                "quantity_units": u,
            }

        if sens.series is not None:
            d = np.asarray(sens.series)[order]
            for j, q in enumerate(SERIES_QUANTITIES):
                out[f"d_{q}"] = (("t", "key"), d[keep, :, j], attrs(q))
                out[f"event_d_{q}"] = (("event", "key"), d[event, :, j], attrs(q))
        for j, s in enumerate(STATE_NAMES):
            out[f"final_d_{s}"] = ("key", np.asarray(sens.final)[:, j], attrs(s))
        return coords, out

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
        p2 = atomic_write_text(d / "impacts.csv", impacts_csv(self.impacts))
        return [p1, p2]
