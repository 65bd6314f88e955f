"""Drawings of the machine: the layout and a GIF of the carriers coloured by contact force.

The machine is drawn from above: horn-gear pitch circles (grey) with their slots (short
ticks, turning with the gears), the two serpentine paths (group A blue, group B green), the
crossings (small dots) and the carriers (discs edged in their group's colour). A carrier's
fill is the largest track contact force it felt since the previous frame (the peaks of the
impacts in that interval, or the resting force at the frame), on a logarithmic scale; grey
means no contact. The GIF is written with matplotlib's ``PillowWriter`` (Pillow comes with
matplotlib) through :func:`braidsim.io.atomic_write_with`, so it appears whole or not at all.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.io import atomic_write_with

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from braidsim.machine.geometry import MachineGeometry
    from braidsim.machine.run import MachineRun

GROUP_COLOURS = {"A": "C0", "B": "C2"}
FORCE_FLOOR = 1.0  # [N] bottom of the colour scale; 0 N (no contact) is drawn grey


def _slot_segments(geom: MachineGeometry, omega_angle: float) -> np.ndarray:
    """(N S, 2, 2) short radial ticks at the slots of every gear."""
    segs = []
    r = geom.pitch_radius
    for i, c in enumerate(geom.gear_centres):
        ang = geom.slot_angles(i, omega_angle)
        u = np.column_stack([np.cos(ang), np.sin(ang)])
        segs.append(np.stack([c + 0.8 * r * u, c + 1.0 * r * u], axis=1))
    return np.concatenate(segs)


def draw_machine(
    ax: Any,
    geom: MachineGeometry,
    carriers: list[tuple[str, int]],
    omega_angle: float,
    labels: bool = False,
) -> dict[str, Any]:
    """Draw gears, paths, crossings, slots and carriers at horn-gear rotation ``omega_angle``
    [rad] into ``ax`` (lengths in mm). Returns the artists that move."""
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Circle

    mm = 1e3
    r = geom.pitch_radius * mm
    for i, c in enumerate(geom.gear_centres * mm):
        ax.add_patch(Circle(tuple(c), r, fill=False, ec="0.75", lw=0.8))
        ax.text(c[0], c[1], str(i), ha="center", va="center", fontsize=7, color="0.45")
    xi = np.linspace(0.0, geom.path_period, 40 * geom.N + 1)
    for g in ("A", "B"):
        pts = geom.path_point(g, xi) * mm
        ax.plot(pts[:, 0], pts[:, 1], color=GROUP_COLOURS[g], lw=0.8, alpha=0.45)
    cr = geom.crossings * mm
    ax.plot(cr[:, 0], cr[:, 1], "k.", ms=3)
    slots = LineCollection(list(_slot_segments(geom, omega_angle) * mm), colors="0.35", lw=1.2)
    ax.add_collection(slots)
    pos = geom.carrier_points(carriers, np.array([omega_angle]))[0] * mm
    edge = [GROUP_COLOURS[g] for g, _ in carriers]
    sc = ax.scatter(pos[:, 0], pos[:, 1], s=70, c="0.85", edgecolors=edge, linewidths=1.6, zorder=3)
    texts = []
    if labels:
        for (g, k), p in zip(carriers, pos, strict=True):
            texts.append(
                ax.annotate(f"{g}{k}", p, xytext=(4, 4), textcoords="offset points", fontsize=6)
            )
    lim = (geom.ring_radius + 1.25 * geom.pitch_radius) * mm
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.set_xlabel("x / mm")
    ax.set_ylabel("y / mm")
    return {"slots": slots, "carriers": sc, "labels": texts}


def _force_norm(vmax: float) -> tuple[Any, Any]:
    from matplotlib import colormaps
    from matplotlib.colors import LogNorm

    cmap = colormaps["plasma"].with_extremes(under="0.85", bad="0.85")
    return LogNorm(vmin=FORCE_FLOOR, vmax=max(vmax, 10.0 * FORCE_FLOOR)), cmap


def layout_figure(run: MachineRun) -> Figure:
    """The machine at t = 0 with every carrier labelled (group A blue, B green)."""
    from braidsim.plotting import new_figure

    spec = run.spec
    fig = new_figure(6.0, 6.0)
    ax = fig.add_subplot(1, 1, 1)
    draw_machine(ax, spec.geometry, spec.loading.carriers, 0.0, labels=True)
    g = spec.geometry
    ax.set_title(
        f"{g.N} horn gears, {g.S} slots, {len(spec.loading.carriers)} carriers "
        f"({spec.loading.title}); A: counter-clockwise, B: clockwise",
        fontsize=9,
    )
    return fig


def _frame_figure(run: MachineRun, dpi: int) -> tuple[Figure, dict[str, Any], Any]:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.0, 6.8), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.13, 0.2, 0.8, 0.7))
    spec = run.spec
    art = draw_machine(ax, spec.geometry, spec.loading.carriers, 0.0)
    norm, cmap = _force_norm(float(run.frame_forces.max()) if run.frame_forces.size else 10.0)
    art["carriers"].set_cmap(cmap)
    art["carriers"].set_norm(norm)
    cax = fig.add_axes((0.13, 0.075, 0.8, 0.022))
    from matplotlib.cm import ScalarMappable

    fig.colorbar(
        ScalarMappable(norm=norm, cmap=cmap),
        cax=cax,
        orientation="horizontal",
        label="largest contact force since the last frame / N (grey: none)",
    )
    art["title"] = ax.set_title("", fontsize=9)
    return fig, art, ax


def _update(run: MachineRun, art: dict[str, Any], f: int) -> None:
    geom = run.spec.geometry
    om = float(run.speed.rotation([run.frame_times[f]])[1][0])
    art["slots"].set_segments(_slot_segments(geom, om) * 1e3)
    art["carriers"].set_offsets(run.frame_positions[f] * 1e3)
    vals = np.where(run.frame_forces[f] > 0.0, run.frame_forces[f], np.nan)
    art["carriers"].set_array(np.ma.masked_invalid(vals))
    art["title"].set_text(
        f"{run.spec.name}\nt = {run.frame_times[f]:.4f} s, horn gears turned "
        f"{np.degrees(om):.1f} deg"
    )


def save_frame(run: MachineRun, frame: int, path: str | Path, dpi: int | None = None) -> Path:
    """One animation frame as a PNG."""
    d = dpi or run.spec.animation.dpi
    fig, art, _ = _frame_figure(run, d)
    _update(run, art, frame)
    return atomic_write_with(path, lambda tmp: fig.savefig(tmp, format="png", dpi=d))


def save_animation(run: MachineRun, path: str | Path) -> Path:
    """The GIF of every frame of ``run`` (its frame times and forces)."""
    from matplotlib.animation import PillowWriter

    a = run.spec.animation
    fig, art, _ = _frame_figure(run, a.dpi)

    def write(tmp: Path) -> None:
        writer = PillowWriter(fps=a.fps)
        with writer.saving(fig, str(tmp), a.dpi):
            for f in range(run.frame_times.size):
                _update(run, art, f)
                writer.grab_frame()

    return atomic_write_with(path, write)
