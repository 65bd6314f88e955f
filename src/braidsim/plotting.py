"""Figures (matplotlib, imported lazily, Agg backend). Every function returns a Figure.

The paper's quantities are plotted in its units: displacement and depth in mm, forces in N,
time in s, signed as in the paper (negative on the inner wall).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

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


def plot_quantity(
    result: Result,
    quantity: str,
    title: str | None = None,
    window: tuple[float, float] | None = None,
    ax: Any = None,
) -> Figure:
    """One paper-style time history: x (with the track walls), F_kg, F_cg or depth.

    Parameters
    ----------
    result : Result
    quantity : str
        ``x``, ``stiffness_force``, ``damping_force``, ``depth`` or ``contact_force``.
    title : str, optional
    window : (t0, t1), optional
        Time range shown [s].
    """
    col, scale, label = QUANTITIES[quantity]
    s = result.series
    t = s["t"]
    sel = slice(None) if window is None else (t >= window[0]) & (t <= window[1])
    if ax is None:
        fig = new_figure()
        ax = fig.add_subplot(1, 1, 1)
    else:
        fig = ax.figure
    if quantity == "x":
        eps = result.model.scenario["track.clearance"]
        ax.plot(t[sel], s["track_position"][sel] * scale, color="0.55", lw=0.8, label="inner wall $h(t)$")
        ax.plot(
            t[sel],
            (s["track_position"][sel] + eps) * scale,
            color="0.55",
            lw=0.8,
            ls="--",
            label=r"outer wall $h(t)+\varepsilon_g$",
        )
    ax.plot(t[sel], s[col][sel] * scale, color="C0", lw=0.9, label=label.split(" /")[0])
    ax.set_xlabel("time $t$ / s")
    ax.set_ylabel(label)
    ax.grid(True, lw=0.3, alpha=0.6)
    if quantity == "x":
        ax.legend(loc="best", fontsize=8, frameon=False)
    if title:
        ax.set_title(title, fontsize=10)
    return fig


def plot_impacts(result: Result, title: str | None = None) -> Figure:
    """The impact sequence: approach speed and peak force of every impact against time."""
    imp = result.impacts
    fig = new_figure(6.4, 4.4)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    for wall, marker in (("inner", "v"), ("outer", "^"), ("rear", "<"), ("front", ">")):
        sel = imp["wall"] == wall
        if not sel.any():
            continue
        ax1.plot(imp["t"][sel], imp["velocity"][sel], marker, ms=4, ls="none", label=f"{wall} wall")
        ax2.semilogy(imp["t"][sel], imp["peak_force"][sel].clip(lower=1e-3), marker, ms=4, ls="none")
    ax1.set_ylabel("approach speed / (m/s)")
    ax2.set_ylabel("peak contact force / N")
    ax2.set_xlabel("time $t$ / s")
    for ax in (ax1, ax2):
        ax.grid(True, lw=0.3, alpha=0.6)
    if len(imp):
        ax1.legend(fontsize=8, frameon=False)
    else:
        ax1.text(0.5, 0.5, "no impacts", transform=ax1.transAxes, ha="center")
    if title:
        ax1.set_title(title, fontsize=10)
    return fig


def plot_phase(result: Result, title: str | None = None) -> Figure:
    """Phase portrait: x relative to the inner wall against the carrier's speed."""
    s = result.series
    fig = new_figure(5.0, 4.0)
    ax = fig.add_subplot(1, 1, 1)
    rel = (s["x"] - s["track_position"]) * 1e3
    ax.plot(rel, s["vx"], lw=0.5, color="C0")
    ax.axvline(0.0, color="0.5", lw=0.8)
    ax.axvline(result.model.scenario["track.clearance"] * 1e3, color="0.5", lw=0.8, ls="--")
    ax.set_xlabel(r"$x - h(t)$ / mm")
    ax.set_ylabel(r"$\dot{x}$ / (m/s)")
    ax.grid(True, lw=0.3, alpha=0.6)
    if title:
        ax.set_title(title, fontsize=10)
    return fig


def save(fig: Figure, path: str | Path) -> Path:
    """Save a figure as a whole file (temporary name + rename)."""
    return atomic_write_with(path, lambda p: fig.savefig(p, format=Path(path).suffix.lstrip(".") or "png"))


def run_figures(result: Result, directory: str | Path) -> list[Path]:
    """The paper-style plots of one run (x, F_kg, F_cg, depth, impacts, phase) as PNG files."""
    d = Path(directory)
    name = result.model.scenario.name
    paths = []
    for q in ("x", "stiffness_force", "damping_force", "depth"):
        paths.append(save(plot_quantity(result, q, title=name), d / f"{q}.png"))
    paths.append(save(plot_impacts(result, title=name), d / "impacts.png"))
    paths.append(save(plot_phase(result, title=name), d / "phase.png"))
    return paths

