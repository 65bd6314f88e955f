"""Plots of a finished sweep: a heat map of a metric over two axes, a line over one.

The regime (:data:`braidsim.batch.REGIMES`) is drawn with one colour per label; other
metrics with a continuous colour scale (optionally logarithmic). Dimensions that are not
plotted must be fixed with ``sel`` (the nearest grid value, within the axis's range; an exact
value of the run number or of a text axis). For sampled sweeps (a ``run`` dimension) the same
calls give a scatter plot over the sampled parameters. The runs of an unfinished sweep that
have not run yet (regime -1 without a failure reason) are not drawn, and the title counts them.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.batch import REGIME_FAILED, REGIMES
from braidsim.errors import InputError
from braidsim.sweep.spec import RUN_DIM, TIME_DIM
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
    except Exception:  # pint raises several types for incompatible units
        raise InputError(
            f"--unit: cannot show {name} [{si_unit or 'no unit'}] in {unit!r}, which is not "
            f"a unit of the same kind; allowed e.g. {_same_kind(si_unit)}"
        ) from None
    return f, unit


def _same_kind(si_unit: str) -> str:
    """Display units a quantity in ``si_unit`` can be shown in, for messages."""
    examples = {
        "m": "'mm', 'um'",
        "s": "'ms', 'min'",
        "rad/s": "'rpm', 'Hz'",
        "m/s": "'mm/s'",
        "N": "'kN'",
        "J": "'mJ'",
        "W": "'kW'",
        "Pa": "'MPa', 'GPa'",
    }
    return examples.get(si_unit, f"{si_unit!r}" if si_unit else "'percent'")


def _edges(c: np.ndarray, log: bool) -> np.ndarray:
    """Cell edges around centres c (midpoints; geometric midpoints on a log axis)."""
    if c.size == 1:
        return np.array([c[0] * 0.9, c[0] * 1.1]) if log else np.array([c[0] - 0.5, c[0] + 0.5])
    v = np.log(c) if log else c
    mid = 0.5 * (v[1:] + v[:-1])
    e = np.concatenate([[v[0] - (mid[0] - v[0])], mid, [v[-1] + (v[-1] - mid[-1])]])
    return np.exp(e) if log else e


def _allowed(values: np.ndarray) -> str:
    """The values of a coordinate that is not a float grid, for an error message."""
    v = values.tolist()
    if values.dtype.kind in "iu" and v == list(range(v[0], v[0] + len(v))):
        return f"the integers {v[0]} to {v[-1]}"
    shown = ", ".join(map(str, v[:10]))
    return shown + (f", ... ({len(v)} values)" if len(v) > 10 else "")


def _index(ds: xr.Dataset, dim: str, value: Any) -> int:
    """Position along ``dim`` that ``value`` selects: the nearest grid value of a float axis
    (a value outside the axis's range is refused), else an exact match."""
    from braidsim.units import is_number

    key = f"--sel {dim}"
    values = np.asarray(ds[dim].values)
    if values.dtype.kind == "f":
        unit = ds[dim].attrs.get("units", "")
        v = to_si(key, value, unit)
        lo, hi = float(values.min()), float(values.max())
        # the bounds of the grid, written with a unit, may differ from the stored SI values
        # in the last bits ("0.5 mm" against linspace's end)
        tol = 1e-9 * max(abs(lo), abs(hi))
        if not lo - tol <= v <= hi + tol:
            u = f" {unit}" if unit else ""
            raise InputError(
                f"{key}: {v:g}{u} is outside the sweep's {dim}; allowed {lo:g}{u} to {hi:g}{u}"
            )
        return int(np.argmin(np.abs(values - v)))
    text = str(value).strip()
    if values.dtype.kind in "iu":
        try:
            v_int = int(value) if is_number(value) and float(value).is_integer() else int(text)
        except ValueError:
            v_int = None
        hits = np.flatnonzero(values == v_int) if v_int is not None else np.array([], int)
    else:  # text or boolean axes: the value as written in the spec
        hits = np.flatnonzero([str(c).lower() == text.lower() for c in values.tolist()])
    if hits.size == 0:
        raise InputError(f"{key}: {value!r} is not a value of {dim}; allowed {_allowed(values)}")
    return int(hits[0])


def _select(
    ds: xr.Dataset, dims: tuple[str, ...], plotted: Mapping[str, str], sel: Mapping[str, Any]
) -> dict[str, int]:
    """Positions ``{dimension: index}`` that ``sel`` fixes; ``plotted`` maps each plotted
    dimension to the --x/--y names drawn along it (those cannot be fixed)."""
    free = [d for d in dims if d not in plotted and d != TIME_DIM]
    out = {}
    for dim, value in sel.items():
        if dim not in dims or dim == TIME_DIM:
            raise InputError(
                f"--sel: {dim!r} is not a dimension of the sweep; allowed "
                f"{', '.join(free) or '(none: every dimension is plotted)'}"
            )
        if dim in plotted:
            raise InputError(
                f"--sel: {dim} is plotted (--x/--y {plotted[dim]}), it cannot be fixed; allowed "
                f"{', '.join(free) or '(none: every dimension is plotted)'}"
            )
        out[dim] = _index(ds, dim, value)
    return out


def _shown(ds: xr.Dataset, dim: str, i: int, unit: str | None) -> str:
    """``dim = value unit``: the grid value at position ``i``, in ``unit`` or the store's."""
    c = ds[dim]
    v = c.values[i]
    if c.dtype.kind != "f":
        return f"{dim} = {v}"
    f, u = _factor(dim, c.attrs.get("units", ""), unit)
    return f"{dim} = {float(v) * f:.6g}" + (f" {u}" if u else "")


def _spread(v: xr.DataArray, like: xr.DataArray) -> np.ndarray:
    """The values of coordinate ``v`` repeated over the dimensions of ``like``, flattened."""
    return np.asarray(
        v.variable.set_dims(dict(like.sizes)).transpose(*like.dims).values, dtype=float
    ).ravel()


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
        ``{dimension: value}`` fixing the other dimensions: the nearest grid value (a number
        in the axis's SI unit or a string with a unit, inside the axis's range), or an exact
        run number or text value.
    units : mapping, optional
        Display units ``{name: unit}`` for the axes, the metric and the dimensions fixed by
        ``sel`` (in the title), e.g. ``{"h_a": "mm"}``.
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
        from braidsim.specfile import closest_hint

        names = sorted(str(v) for v in ds.data_vars)  # (a store's own order is arbitrary)
        raise InputError(
            f"--metric: {metric!r} is not in the sweep{closest_hint(metric, names)}; "
            f"allowed {', '.join(names)}"
        )
    if ds[metric].dtype.kind not in "biuf":
        numeric = sorted(str(v) for v in ds.data_vars if ds[v].dtype.kind in "biuf")
        raise InputError(
            f"--metric: {metric!r} holds text, not numbers; allowed {', '.join(numeric)}"
        )
    units = dict(units or {})
    sel = dict(sel or {})
    names = [x] if y is None else [x, y]
    axes = [str(c) for c in ds.coords if c != TIME_DIM and ds[c].ndim == 1]
    for n in names:
        if n not in axes:
            raise InputError(
                f"--x/--y: {n!r} is not an axis of the sweep; allowed {', '.join(axes)}"
            )
    if y == x:
        raise InputError(f"--y: {y} is already --x; allowed another axis: {', '.join(axes)}")
    for n in units:
        if n not in (*names, metric, *sel):
            raise InputError(
                f"--unit: {n!r} is neither an axis plotted (--x/--y), the metric nor a "
                f"dimension fixed by --sel; allowed {', '.join([*names, metric, *sel])}"
            )
    # a sampled parameter lies along the run dimension: plotting it plots over run
    dim_of = {n: str(ds[n].dims[0]) for n in names}
    plotted: dict[str, str] = {}
    for n in names:
        plotted[dim_of[n]] = f"{plotted[dim_of[n]]}, {n}" if dim_of[n] in plotted else n
    full = ds[metric]
    idx = _select(ds, tuple(map(str, full.dims)), plotted, sel)
    da = full.isel(idx)
    if TIME_DIM in da.dims:
        raise InputError(f"--metric: {metric} is a time series; plot a scalar metric")
    unfixed = [str(d) for d in da.dims if d not in plotted]
    if unfixed:
        raise InputError(
            f"--sel: fix the dimensions {', '.join(unfixed)} to plot {metric} over "
            f"{', '.join(names)}, e.g. --sel {unfixed[0]}=VALUE"
        )
    # cells of an unfinished sweep hold the fill values, regime -1 ("failed") included; a
    # run that failed has its reason in `failure`, one that never ran has none
    not_run = np.zeros(da.shape, dtype=bool)
    if "regime" in ds and "failure" in ds:
        not_run = np.asarray(
            (ds["regime"].isel(idx) == REGIME_FAILED) & (ds["failure"].isel(idx) == "")
        ).reshape(da.shape)
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
    vals = np.ma.masked_array(vals, mask=not_run | ~np.isfinite(vals))
    cmap: Any = "viridis"
    norm: Any = None
    if is_regime:
        cmap = ListedColormap(REGIME_COLORS)
        norm = BoundaryNorm(np.arange(-1.5, len(REGIMES)), cmap.N)
    elif log:
        pos = vals.compressed()
        pos = pos[pos > 0]
        if pos.size:
            norm = LogNorm(vmin=float(pos.min()), vmax=float(pos.max()))
    mlabel = f"{metric} [{um}]" if um and not is_regime else metric
    # a grid axis is drawn as a line or cells; a sampled parameter (or the run number) as
    # points, since its values are not ordered
    points = any(n != dim_of[n] or n == RUN_DIM for n in names)
    if y is None:
        xs = np.asarray(ds[x].values, dtype=float) * fx
        ax.plot(xs, vals, "o" if points else "-o", ms=3)
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
        xlog = ds[x].attrs.get("spacing") == "log"
        ylog = ds[y].attrs.get("spacing") == "log"
        if points:
            art = ax.scatter(
                _spread(ds[x], da) * fx,
                _spread(ds[y], da) * fy,
                c=vals.ravel(),
                cmap=cmap,
                norm=norm,
                s=14,
            )
        else:
            xs = np.asarray(ds[x].values, dtype=float) * fx
            ys = np.asarray(ds[y].values, dtype=float) * fy
            grid = vals if da.dims == (y, x) else vals.T
            if not_run.any():
                ax.patch.set_hatch("xx")  # shows through the cells left empty
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
    if title is None:
        where = ", ".join(_shown(ds, d, i, units.get(d)) for d, i in idx.items())
        title = metric + (f" ({where})" if where else "")
        if not_run.any():
            title += f"; {int(not_run.sum())} runs not run yet (not drawn)"
    ax.set_title(title)
    return fig
