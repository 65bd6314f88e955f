"""Plots of a finished sweep: a heat map of a metric over two axes, a line over one.

The regime (:data:`braidsim.batch.REGIMES`) is drawn with one colour per label; other
metrics with a continuous colour scale (optionally logarithmic). Dimensions that are not
plotted must be fixed with ``sel`` (nearest value). For sampled sweeps (a ``run``
dimension) the same calls give a scatter plot over the sampled parameters.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.batch import REGIMES
from braidsim.errors import InputError
from braidsim.units import to_si

if TYPE_CHECKING:
    import xarray as xr
    from matplotlib.figure import Figure

REGIME_COLORS = ("#9e9e9e", "#f7f7f7", "#4daf4a", "#ff7f00", "#e41a1c")  # failed, then REGIMES


def _factor(name: str, si_unit: str, unit: str | None) -> tuple[float, str]:
    """Scale from the SI unit of a coordinate to the display unit, and the unit's label."""
    if not unit:
        return 1.0, si_unit
    from braidsim.units import parse_unit, registry

    ureg = registry()
    target = parse_unit(f"--unit {name}", unit)
    try:
        f = float(ureg.Quantity(1.0, si_unit or "dimensionless").to(target).magnitude)
    except Exception as exc:  # pint raises several types for bad or incompatible units
        raise InputError(
            f"--unit: cannot show {name} [{si_unit}] in {unit!r} ({exc.__class__.__name__})"
        ) from None
    return f, unit


def _edges(c: np.ndarray, log: bool) -> np.ndarray:
    """Cell edges around centres c (midpoints; geometric midpoints on a log axis)."""
    if c.size == 1:
        return np.array([c[0] * 0.9, c[0] * 1.1]) if log else np.array([c[0] - 0.5, c[0] + 0.5])
    v = np.log(c) if log else c
    mid = 0.5 * (v[1:] + v[:-1])
    e = np.concatenate([[v[0] - (mid[0] - v[0])], mid, [v[-1] + (v[-1] - mid[-1])]])
    return np.exp(e) if log else e


def _select(ds: xr.Dataset, da: xr.DataArray, sel: Mapping[str, Any] | None) -> xr.DataArray:
    for dim, value in (sel or {}).items():
        if dim not in da.dims:
            raise InputError(
                f"--sel: {dim!r} is not a dimension of the sweep; "
                f"allowed {', '.join(map(str, da.dims))}"
            )
        coord = ds[dim]
        v = value
        if coord.dtype.kind == "f":
            v = to_si(f"--sel {dim}", value, coord.attrs.get("units", ""))
        da = da.sel({dim: v}, method="nearest" if coord.dtype.kind == "f" else None)
    return da


def plot_sweep(
    ds: xr.Dataset,
    metric: str,
    x: str,
    y: str | None = None,
    *,
    sel: Mapping[str, Any] | None = None,
    units: Mapping[str, str] | None = None,
    log: bool = False,
    title: str | None = None,
    ax: Any = None,
) -> Figure:
    """Heat map of ``metric`` over ``x`` and ``y``, or a line over ``x`` alone.

    Parameters
    ----------
    ds : xarray.Dataset
        A sweep (:func:`braidsim.sweep.open_sweep`).
    metric : str
        Variable to plot (``regime`` gets one colour per label).
    x, y : str
        Dimension (grid) or sampled parameter (``run`` sweeps) names.
    sel : mapping, optional
        ``{dimension: value}`` fixing the other dimensions (nearest value; unit strings
        allowed).
    units : mapping, optional
        Display units ``{name: unit}`` for axes and metric, e.g. ``{"h_a": "mm"}``.
    log : bool
        Logarithmic colour scale (heat map) or y axis (line).
    title : str, optional
    ax : matplotlib Axes, optional
        Draw into these axes.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.colors import BoundaryNorm, ListedColormap, LogNorm

    from braidsim.plotting import new_figure

    if metric not in ds.data_vars:
        import difflib

        close = difflib.get_close_matches(metric, [str(v) for v in ds.data_vars], n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise InputError(
            f"--metric: {metric!r} is not in the sweep{hint}; "
            f"allowed {', '.join(map(str, ds.data_vars))}"
        )
    if ds[metric].dtype.kind not in "biuf":
        numeric = [str(v) for v in ds.data_vars if ds[v].dtype.kind in "biuf"]
        raise InputError(
            f"--metric: {metric!r} holds text, not numbers; allowed {', '.join(numeric)}"
        )
    units = dict(units or {})
    names = [x] if y is None else [x, y]
    for n in units:
        if n not in (*names, metric):
            raise InputError(
                f"--unit: {n!r} is neither an axis plotted (--x/--y) nor the metric; allowed "
                f"{', '.join([*names, metric])}"
            )
    da = _select(ds, ds[metric], sel)
    for n in names:
        if n not in ds.variables:
            raise InputError(
                f"--x/--y: {n!r} is not an axis of the sweep; "
                f"allowed {', '.join(map(str, ds.coords))}"
            )
    sampled = "run" in da.dims
    left = [str(d) for d in da.dims if d != "t"]
    want = ["run"] if sampled else names
    if sorted(left) != sorted(want):
        extra = [d for d in left if d not in want]
        raise InputError(
            f"--sel: fix the dimensions {', '.join(extra) or '(none)'} to plot {metric} over "
            f"{', '.join(names)} (dimensions left: {', '.join(left)})"
        )
    if "t" in da.dims:
        raise InputError(f"--metric: {metric} is a time series; plot a scalar metric")
    if ax is None:
        fig = new_figure(6.4, 4.4)
        ax = fig.add_subplot()
    else:
        fig = ax.figure
    fx, ux = _factor(x, ds[x].attrs.get("units", ""), units.get(x))
    fm, um = _factor(metric, da.attrs.get("units", ""), units.get(metric))
    xlab = f"{x} [{ux}]" if ux else x
    is_regime = metric == "regime"
    vals = np.asarray(da.values, dtype=float)
    if not is_regime:
        vals = vals * fm
    cmap: Any = "viridis"
    norm: Any = None
    if is_regime:
        cmap = ListedColormap(REGIME_COLORS)
        norm = BoundaryNorm(np.arange(-1.5, len(REGIMES)), cmap.N)
    elif log:
        pos = vals[np.isfinite(vals) & (vals > 0)]
        if pos.size:
            norm = LogNorm(vmin=float(pos.min()), vmax=float(pos.max()))
    mlabel = f"{metric} [{um}]" if um and not is_regime else metric
    if y is None:
        xs = np.asarray(ds[x].values, dtype=float) * fx
        if sampled:
            ax.plot(xs, vals, "o", ms=3)
        else:
            ax.plot(xs, vals, "-o", ms=3)
        ax.set_xlabel(xlab)
        ax.set_ylabel(mlabel)
        if is_regime:
            ax.set_yticks(range(-1, len(REGIMES)), ["failed", *REGIMES])
        if log and not is_regime:
            ax.set_yscale("log")
        if ds[x].attrs.get("spacing") == "log":
            ax.set_xscale("log")
    else:
        fy, uy = _factor(y, ds[y].attrs.get("units", ""), units.get(y))
        xs = np.asarray(ds[x].values, dtype=float) * fx
        ys = np.asarray(ds[y].values, dtype=float) * fy
        if sampled:
            art = ax.scatter(xs, ys, c=vals, cmap=cmap, norm=norm, s=14)
        else:
            grid = da.transpose(y, x).values.astype(float)
            if not is_regime:
                grid = grid * fm
            xlog = ds[x].attrs.get("spacing") == "log"
            ylog = ds[y].attrs.get("spacing") == "log"
            art = ax.pcolormesh(
                _edges(xs, xlog), _edges(ys, ylog), grid, cmap=cmap, norm=norm, shading="flat"
            )
            if xlog:
                ax.set_xscale("log")
            if ylog:
                ax.set_yscale("log")
        ax.set_xlabel(xlab)
        ax.set_ylabel(f"{y} [{uy}]" if uy else y)
        cb = fig.colorbar(art, ax=ax, label="" if is_regime else mlabel)
        if is_regime:
            cb.set_ticks(
                range(-1, len(REGIMES)), labels=["failed", *(r.replace("_", " ") for r in REGIMES)]
            )
    where = ", ".join(f"{k} = {v}" for k, v in (sel or {}).items())
    ax.set_title(title if title is not None else (f"{metric}" + (f" ({where})" if where else "")))
    return fig
