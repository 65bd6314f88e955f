"""Branches as xarray datasets, written to netCDF, zarr and CSV, and read back to restart.

Layout of a branch dataset (SI units in ``attrs["units"]``)
-----------------------------------------------------------
Dimensions ``point`` (the orbits in arclength order), ``multiplier`` (the Floquet
multipliers of each, by decreasing modulus, NaN-padded), ``strobe`` (the k stroboscopic
samples of a period-k orbit), ``cut`` and ``entry`` (the shooting state, for restarting) and
``pair``, and ``special`` (the special points).

* ``value`` (point): the continuation parameter;
* ``stable`` (point, 0/1), ``multiplier_re``, ``multiplier_im``, ``multiplier_abs``;
* ``max_depth``, ``min_gap``, ``peak_force``, ``approach``, ``feature``, ``impacts``,
  ``u_min``, ``u_max`` (see :class:`~braidsim.continuation.orbit.Profile`);
* ``strobe_u``, ``strobe_v`` (point, strobe): the orbit at forcing phase 0 (position
  relative to the inner wall, speed), comparable with a brute-force bifurcation diagram;
* ``phase`` (point), ``state`` (point, cut, entry), ``modes``, ``v0_state``, ``v0_fixed``
  (point, cut, pair): enough to restart from any point (:func:`orbit_from_dataset`); the
  xy carrier's y in ``state`` is its position in the horn-gear slot's frame, y - s(t);
* ``special_type`` (special; a CF flag: 0 fold, 1 period_doubling, 2 neimark_sacker,
  3 grazing), ``special_value``, ``special_period``, ``special_index``.

``attrs``: ``parameter``, ``period``, ``system`` (scenario name), ``base_values_json`` (the
other parameters of the orbit, SI), ``stop`` (why the branch ended), ``braidsim_version``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from braidsim.continuation.branch import SPECIAL_TYPES, Branch
from braidsim.continuation.orbit import Cut, Orbit, profile

UNITS = {
    "max_depth": "m",
    "min_gap": "m",
    "peak_force": "N",
    "approach": "m",
    "feature": "m",
    "u_min": "m",
    "u_max": "m",
    "strobe_u": "m",
    "strobe_v": "m/s",
    "phase": "rad",
}


def branch_dataset(br: Branch, system_name: str = "") -> Any:
    """The branch as an :class:`xarray.Dataset` (module docstring)."""
    import xarray as xr

    from braidsim import __version__

    pts = br.points
    n = len(pts)
    nm = max((o.multipliers.size for o in pts), default=0)
    ns = br.period
    nc = max((o.segments for o in pts), default=1)
    ne = max((z.size for o in pts for z in o.z), default=0)
    mu = np.full((n, nm), np.nan + 0j)
    su = np.full((n, ns), np.nan)
    sv = np.full((n, ns), np.nan)
    state = np.full((n, nc, ne), np.nan)
    modes = np.zeros((n, nc, 2), dtype=np.int8)
    v0s = np.zeros((n, nc, 2), dtype=np.int8)
    v0f = np.full((n, nc, 2), np.nan)
    for i, o in enumerate(pts):
        mu[i, : o.multipliers.size] = o.multipliers
        k = min(ns, o.profile.strobe_u.size)
        su[i, :k] = o.profile.strobe_u[:k]
        sv[i, :k] = o.profile.strobe_v[:k]
        for j, (c, z) in enumerate(zip(o.cuts, o.z, strict=True)):
            state[i, j, : z.size] = z
            modes[i, j] = c.modes
            v0s[i, j] = c.v0_state
            v0f[i, j] = c.v0_fixed

    def col(f: Any) -> np.ndarray:
        return np.array([float(f(o)) for o in pts])

    data = {
        "value": ("point", col(lambda o: o.values[br.key])),
        "stable": ("point", np.array([o.stable for o in pts], dtype=np.int8)),
        "reliable": ("point", np.array([o.reliable for o in pts], dtype=np.int8)),
        "multiplier_re": (("point", "multiplier"), mu.real),
        "multiplier_im": (("point", "multiplier"), mu.imag),
        "multiplier_abs": (("point", "multiplier"), np.abs(mu)),
        "max_depth": ("point", col(lambda o: o.profile.max_depth)),
        "min_gap": ("point", col(lambda o: o.profile.min_gap)),
        "peak_force": ("point", col(lambda o: o.profile.peak_force)),
        "approach": ("point", col(lambda o: o.profile.approach)),
        "feature": ("point", col(lambda o: o.profile.feature)),
        "impacts": ("point", np.array([o.profile.impacts for o in pts], dtype=np.int32)),
        "u_min": ("point", col(lambda o: o.profile.u_min)),
        "u_max": ("point", col(lambda o: o.profile.u_max)),
        "strobe_u": (("point", "strobe"), su),
        "strobe_v": (("point", "strobe"), sv),
        "phase": ("point", col(lambda o: o.phase)),
        "state": (("point", "cut", "entry"), state),
        "modes": (("point", "cut", "pair"), modes),
        "v0_state": (("point", "cut", "pair"), v0s),
        "v0_fixed": (("point", "cut", "pair"), v0f),
        "special_type": (
            "special",
            np.array([SPECIAL_TYPES.index(s.type) for s in br.special], dtype=np.int8),
        ),
        "special_value": ("special", np.array([s.value for s in br.special], dtype=float)),
        "special_period": ("special", np.array([s.period for s in br.special], dtype=np.int32)),
        "special_index": ("special", np.array([s.index for s in br.special], dtype=np.int32)),
    }
    ds = xr.Dataset({k: (d, v) for k, (d, v) in data.items()})
    for name, u in UNITS.items():
        ds[name].attrs["units"] = u
    # CF flags: the type as a small integer (strings have no stable zarr v3 encoding)
    ds["special_type"].attrs.update(
        flag_values=np.arange(len(SPECIAL_TYPES), dtype=np.int8),
        flag_meanings=" ".join(SPECIAL_TYPES),
    )
    base = dict(pts[0].values) if pts else {}
    base.pop(br.key, None)
    ds.attrs.update(
        {
            "parameter": br.key,
            "period": int(br.period),
            "system": system_name,
            "base_values_json": json.dumps(base),
            "stop": br.stop,
            "notes_json": json.dumps(br.notes),
            "braidsim_version": __version__,
        }
    )
    return ds


def orbit_from_dataset(system: Any, ds: Any, index: int = -1, method: str = "auto") -> Orbit:
    """The orbit at point ``index`` of a saved branch, re-solved (a restart point)."""
    from braidsim.continuation.orbit import solve_fixed

    key = str(ds.attrs["parameter"])
    k = int(ds.attrs["period"])
    base = json.loads(str(ds.attrs.get("base_values_json", "{}")))
    npts = int(ds.sizes["point"])
    i = index if index >= 0 else npts + index
    if not 0 <= i < npts:
        from braidsim.errors import InputError

        raise InputError(f"restart point: {index} is out of range; allowed -{npts} to {npts - 1}")
    values = {**{k2: float(v) for k2, v in base.items()}, key: float(ds["value"].values[i])}
    st = ds["state"].values[i]
    cuts = []
    zs = []
    for j in range(st.shape[0]):
        if np.all(np.isnan(st[j])):
            continue
        m = tuple(int(x) for x in ds["modes"].values[i, j])
        vs = tuple(bool(x) for x in ds["v0_state"].values[i, j])
        vf = tuple(float(x) for x in ds["v0_fixed"].values[i, j])
        cuts.append(Cut((m[0], m[1]), (vs[0], vs[1]), (vf[0], vf[1])))
        zs.append(st[j][np.isfinite(st[j])])
    return solve_fixed(system, values, k, float(ds["phase"].values[i]), cuts, zs, method)


def branch_points_table(br: Branch) -> Any:
    """One row per point: value, stable, |mu|_max, measures (a pandas DataFrame)."""
    import pandas as pd

    rows = []
    for o in br.points:
        rows.append(
            {
                "parameter": br.key,
                "period": br.period,
                "value": o.values[br.key],
                "stable": o.stable,
                "max_multiplier_abs": float(np.max(np.abs(o.multipliers))),
                "max_depth": o.profile.max_depth,
                "min_gap": o.profile.min_gap,
                "peak_force": o.profile.peak_force,
                "impacts": o.profile.impacts,
                "u_min": o.profile.u_min,
                "u_max": o.profile.u_max,
            }
        )
    return pd.DataFrame(rows)


def write_branch(ds: Any, path: str | Path) -> Path:
    """Write a branch dataset to ``path`` (``.nc``: netCDF4 via h5netcdf; ``.zarr``: zarr);
    whole or absent."""
    p = Path(path)
    if p.suffix == ".zarr":
        import shutil
        import tempfile

        tmp = Path(tempfile.mkdtemp(dir=p.parent, suffix=".tmp"))
        try:
            ds.to_zarr(tmp / "b.zarr", mode="w", consolidated=False)
            if p.exists():
                shutil.rmtree(p)
            (tmp / "b.zarr").rename(p)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return p
    from braidsim.export import write_netcdf4

    return write_netcdf4(ds, p)


def open_branch(path: str | Path, key: str = "restart") -> Any:
    """Read a branch dataset written by :func:`write_branch`.

    Raises
    ------
    InputError
        One line naming ``key`` (the spec's key or the argument) and the path: a path that
        does not exist, or a file that cannot be read as a branch (damaged, truncated, of
        another format, or a dataset without the branch's ``parameter``)."""
    import xarray as xr

    from braidsim.errors import InputError

    p = Path(path)
    allowed = "allowed a branch_*.nc or branch_*.zarr that braidsim continue wrote"
    if not p.exists():
        raise InputError(f"{key}: {str(p)!r} does not exist; {allowed}")
    try:
        if p.suffix == ".zarr" or p.is_dir():
            ds = xr.open_zarr(str(p), consolidated=False, chunks=None).load()
        else:
            with xr.open_dataset(p, engine="h5netcdf") as opened:
                ds = opened.load()
    except Exception as exc:  # (h5py, zarr and xarray each raise their own kinds)
        text = str(exc).splitlines()[0][:120] if str(exc) else ""
        why = getattr(exc, "strerror", None) or text or exc.__class__.__name__
        raise InputError(
            f"{key}: {str(p)!r} cannot be read as a saved branch ({why}); {allowed}"
        ) from None
    if "parameter" not in ds.attrs or "value" not in ds.variables:
        raise InputError(
            f"{key}: {str(p)!r} is a dataset but not a saved branch (no parameter and points); "
            f"{allowed}"
        )
    return ds


def branch_json(br: Branch) -> dict[str, Any]:
    """The branch as the ``braidsim continue --json`` object's entry (SI)."""

    def f(v: float) -> float | None:
        return float(v) if math.isfinite(v) else None

    return {
        "parameter": br.key,
        "period": int(br.period),
        "points": [
            {
                "value": float(o.values[br.key]),
                "stable": bool(o.stable),
                "multipliers_reliable": bool(o.reliable),
                "multipliers": [[float(m.real), float(m.imag)] for m in o.multipliers],
                "max_depth": f(o.profile.max_depth),
                "min_gap": f(o.profile.min_gap),
                "peak_force": f(o.profile.peak_force),
                "impacts": int(o.profile.impacts),
            }
            for o in br.points
        ],
        "special_points": [s.to_dict() for s in br.special],
        "stop": br.stop,
        "notes": list(br.notes),
    }


__all__ = [
    "branch_dataset",
    "branch_json",
    "branch_points_table",
    "open_branch",
    "orbit_from_dataset",
    "profile",
    "write_branch",
]
