"""Figures (matplotlib, imported lazily, Agg backend). The plotting functions return a Figure;
``envelope`` returns a thinned series to plot, ``save`` and ``run_figures`` the paths written.

The paper's quantities are plotted in its units: displacement and depth in mm, forces in N,
time in s, signed as in the paper (negative on the inner wall).
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.io import atomic_write_with

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from braidsim.result import Result

# quantity -> (series column, scale to plotted unit, axis label)
QUANTITIES: dict[str, tuple[str, float, str]] = {
    "x": ("x", 1e3, "displacement $x$ / mm"),
    "stiffness_force": ("track_stiffness_force", 1.0, "stiffness-related force $F_{kg}$ / N"),
    "damping_force": ("track_damping_force", 1.0, "damping-related force $F_{cg}$ / N"),
    "depth": ("track_depth", 1e3, r"contact depth $\delta_x$ / mm"),
    "contact_force": ("track_contact_force", 1.0, "contact force $F_g$ / N"),
    # the tangential pair (carrier against the horn-gear slot), shown when simulation.dof = xy
    # y is drawn relative to the moving slot (the slot travels r_c omega t, metres in a run)
    "y": ("y", 1e3, "position in the slot $y - s(t)$ / mm"),
    "slot_stiffness_force": ("slot_stiffness_force", 1.0, "slot stiffness-related force / N"),
    "slot_damping_force": ("slot_damping_force", 1.0, "slot damping-related force / N"),
    "slot_depth": ("slot_depth", 1e3, r"slot contact depth $\delta_y$ / mm"),
    "slot_contact_force": ("slot_contact_force", 1.0, "slot contact force / N"),
}
#: the quantities of the run figures per pair: x is the paper's, y the tangential pair's
PAIR_QUANTITIES = {
    "x": ("x", "stiffness_force", "damping_force", "depth"),
    "y": ("y", "slot_stiffness_force", "slot_damping_force", "slot_depth"),
}


def _mpl() -> Any:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def new_figure(width: float = 6.4, height: float = 3.6) -> Figure:
    """A figure with the package's style (no pyplot state kept)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=120, layout="constrained")
    return fig


def envelope(t: np.ndarray, y: np.ndarray, bins: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """Thin a long series for plotting without losing a peak.

    The time axis is cut into ``bins`` equal intervals; in each, the points holding the
    smallest and the largest value are kept (in time order). The drawn line then reaches
    every extreme of the full series, while a 1 s run sampled every 10 us (10^5 points)
    becomes at most ``2 bins`` points. Series shorter than ``4 bins`` are returned unchanged.

    Parameters
    ----------
    t : array
        Times [s], non-decreasing.
    y : array
        Values, same length.
    bins : int
        Number of time intervals (about the pixel width of the axes is enough).
    """
    n = t.size
    if n <= 4 * bins or bins < 1:
        return t, y
    span = float(t[-1] - t[0])
    if not span > 0.0:
        return t, y
    b = np.minimum(((t - t[0]) / span * bins).astype(np.int64), bins - 1)
    order = np.lexsort((y, b))  # by bin, then by value
    sb = b[order]
    starts = np.flatnonzero(np.r_[True, sb[1:] != sb[:-1]])
    ends = np.r_[starts[1:], n] - 1
    keep = np.unique(np.concatenate([order[starts], order[ends], [0, n - 1]]))
    return t[keep], y[keep]


def plot_quantity(
    result: Result,
    quantity: str,
    title: str | None = None,
    window: tuple[float, float] | None = None,
    ax: Any = None,
    bins: int = 2000,
    label: str | None = None,
    color: str = "C0",
) -> Figure:
    """One paper-style time history: x (with the track walls), F_kg, F_cg or depth.

    Displacement and depth are drawn in mm, forces in N, time in s. Long series are thinned
    with :func:`envelope`, which keeps every extreme.

    Parameters
    ----------
    result : Result
    quantity : str
        ``x``, ``stiffness_force``, ``damping_force``, ``depth`` or ``contact_force``.
    title : str, optional
    window : (t0, t1), optional
        Time range shown [s].
    ax : matplotlib Axes, optional
        Draw into these axes instead of a new figure.
    bins : int
        Time intervals of the thinning (0: plot every point).
    label : str, optional
        Legend label of the curve (default: the quantity's symbol).
    color : str
        Colour of the curve.
    """
    col, scale, axis_label = QUANTITIES[quantity]
    s = result.series
    t = s["t"]
    sel = slice(None) if window is None else (t >= window[0]) & (t <= window[1])
    if ax is None:
        fig = new_figure()
        ax = fig.add_subplot(1, 1, 1)
    else:
        fig = ax.figure
    tt = t[sel]
    if quantity in ("x", "y"):
        if quantity == "x":
            eps = result.model.scenario["track.clearance"]
            wall = s["track_position"][sel] * scale
            names = ("inner wall $h(t)$", r"outer wall $h(t)+\varepsilon_g$")
        else:
            eps = result.model.scenario["slot.clearance"]
            wall = np.zeros(tt.size)
            names = ("rear slot wall", r"front slot wall, $\varepsilon_h$")
        tw, hw = envelope(tt, wall, bins) if bins else (tt, wall)
        ax.plot(tw, hw, color="0.45", lw=0.7, label=names[0])
        ax.plot(tw, hw + eps * scale, color="0.45", lw=0.7, ls="--", label=names[1])
    yy = s[col][sel] * scale
    if quantity == "y":
        yy = yy - s["slot_position"][sel] * scale
    tp, yp = envelope(tt, yy, bins) if bins else (tt, yy)
    ax.plot(tp, yp, color=color, lw=0.8, label=label or axis_label.split(" /")[0])
    ax.set_xlabel("time $t$ / s")
    ax.set_ylabel(axis_label)
    ax.grid(True, lw=0.3, alpha=0.6)
    if len(tt):
        ax.set_xlim(float(tt[0]), float(tt[-1]))
    if quantity in ("x", "y"):
        ax.legend(loc="best", fontsize=8, frameon=False)
    if title:
        ax.set_title(title, fontsize=10)
    return fig


_WALL_STYLE = {
    "inner": ("v", "C0"),
    "outer": ("^", "C3"),
    "rear": ("<", "C2"),
    "front": (">", "C4"),
}


def plot_impacts(result: Result, title: str | None = None) -> Figure:
    """The impact sequence: approach speed and peak force of every impact against time.

    One marker per contact episode, by wall. The approach speed is the relative normal
    speed latched at onset [m/s]; a contact that already exists at the start (an initial
    overlap, or the state right after a transfer) has none and is drawn as an open marker in
    the force panel only. Both axes are logarithmic: speeds and forces fall by decades while
    the carrier settles.
    """
    imp = result.impacts
    fig = new_figure(6.4, 4.6)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    any_speed = False
    for wall, (marker, color) in _WALL_STYLE.items():
        sel = (imp["wall"] == wall).to_numpy()
        if not sel.any():
            continue
        ini = imp["initial"].to_numpy() & sel
        hit = sel & ~ini
        n = int(hit.sum())
        tt = imp["t"].to_numpy()
        peak = imp["peak_force"].to_numpy().clip(1e-3, None)
        if n:
            v = imp["velocity"].to_numpy()[hit]
            ok = v > 0
            any_speed = any_speed or bool(ok.any())
            lab = f"{wall} wall ({n})"
            ax1.semilogy(tt[hit][ok], v[ok], marker, color=color, ms=4, ls="none", label=lab)
            ax2.semilogy(tt[hit], peak[hit], marker, color=color, ms=4, ls="none")
        if ini.any():
            lab = f"{wall} wall, contact present at start"
            ax2.semilogy(
                tt[ini], peak[ini], marker, color=color, mfc="none", ms=6, ls="none", label=lab
            )
    # a contact that lasts to the end of the run (the carrier stays on the wall): a bar
    ongoing = imp["ongoing"].to_numpy()
    for t_on, pk in zip(
        imp["t"].to_numpy()[ongoing], imp["peak_force"].to_numpy()[ongoing], strict=True
    ):
        ax2.hlines(
            max(pk, 1e-3),
            t_on,
            result.model.duration,
            color="0.4",
            lw=1.5,
            label="in contact to the end",
        )
    ax1.set_ylabel("approach speed / (m/s)")
    ax2.set_ylabel("peak contact force / N")
    ax2.set_xlabel("time $t$ / s")
    ax2.set_xlim(0.0, result.model.duration)
    from matplotlib import ticker

    for ax in (ax1, ax2):
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
        if ax.get_yscale() != "log":
            # (a panel with nothing drawn, a run without impacts: no log ticks on its
            # empty linear axis, whose range starts at 0)
            ax.set_yticks([])
            continue
        # plain numbers (0.2, 0.5, 1, 2, ...) instead of 2x10^-1 on the log axes
        ax.yaxis.set_major_locator(ticker.LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
        ax.yaxis.set_minor_formatter(ticker.NullFormatter())
    if any_speed:
        ax1.legend(fontsize=8, frameon=False, loc="upper right")
    else:
        ax1.text(0.5, 0.5, "no impacts", transform=ax1.transAxes, ha="center", va="center")
    handles, _ = ax2.get_legend_handles_labels()
    if handles:
        ax2.legend(fontsize=8, frameon=False, loc="upper right")
    if title:
        ax1.set_title(title, fontsize=10)
    return fig


def plot_phase(result: Result, title: str | None = None, chunks: int = 160) -> Figure:
    """Phase portrait: position relative to the inner wall, x - h(t) [mm], against the
    carrier's speed dx/dt [m/s], coloured by time.

    The vertical lines mark the walls (x - h = 0 inner, x - h = eps_g outer); orbits that
    cross them are impacts, and the late, settled motion is the yellow end of the
    colour scale (a power-law scale, so that the crowded first impacts are told apart).
    """
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import PowerNorm

    s = result.series
    t = s["t"]
    fig = new_figure(5.6, 4.2)
    ax = fig.add_subplot(1, 1, 1)
    rel = (s["x"] - s["track_position"]) * 1e3
    v = s["vx"]
    cmap = colormaps["viridis"]
    # the impacts crowd into the start of a run and the settled motion fills the rest: a
    # power-law colour scale gives the early orbits distinct colours too
    norm = PowerNorm(0.4, 0.0, max(float(t[-1]) if t.size else 1.0, 1e-12))
    # draw in time chunks so the colour follows time without a costly per-segment collection
    edges = np.linspace(0, t.size, chunks + 1).astype(int)
    for a, b in itertools.pairwise(edges):
        if b - a < 1:
            continue
        b = min(b + 1, t.size)  # overlap by one point so the chunks join
        ax.plot(rel[a:b], v[a:b], lw=0.6, color=cmap(norm(0.5 * (t[a] + t[b - 1]))))
    eps = result.model.scenario["track.clearance"] * 1e3
    ax.axvline(0.0, color="0.3", lw=0.8)
    ax.axvline(eps, color="0.3", lw=0.8, ls="--")
    tr = ax.get_xaxis_transform()
    ax.text(0.0, 1.01, " inner wall", transform=tr, fontsize=8, ha="left", va="bottom")
    ax.text(eps, 1.01, "outer wall ", transform=tr, fontsize=8, ha="right", va="bottom")
    ax.set_xlabel(r"position relative to the inner wall $x - h(t)$ / mm")
    ax.set_ylabel(r"carrier speed $\dot{x}$ / (m/s)")
    ax.grid(True, lw=0.3, alpha=0.6)
    fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, label="time $t$ / s")
    if title:
        ax.set_title(title, fontsize=10, pad=14)
    return fig


def save(fig: Figure, path: str | Path) -> Path:
    """Save a figure as a whole file (temporary name + rename)."""
    fmt = Path(path).suffix.lstrip(".") or "png"
    return atomic_write_with(path, lambda p: fig.savefig(p, format=fmt))


def run_figures(result: Result, directory: str | Path) -> list[Path]:
    """The paper-style plots of one run (x, F_kg, F_cg, depth, impacts, phase) as PNG files;
    with both degrees of freedom (``simulation.dof = "xy"``) also those of the tangential
    pair (``y.png``, ``slot_stiffness_force.png``, ...)."""
    d = Path(directory)
    name = result.model.scenario.name
    paths = []
    pairs = ("x", "y") if result.model.scenario["simulation.dof"] == "xy" else ("x",)
    for pair in pairs:
        for q in PAIR_QUANTITIES[pair]:
            paths.append(save(plot_quantity(result, q, title=name), d / f"{q}.png"))
    paths.append(save(plot_impacts(result, title=name), d / "impacts.png"))
    paths.append(save(plot_phase(result, title=name), d / "phase.png"))
    return paths
