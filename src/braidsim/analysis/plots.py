"""Figures of the analysis results (matplotlib, via :mod:`braidsim.plotting`).

Lengths are drawn in mm, speeds in m/s, forces in N, frequencies in Hz; every function
returns a Figure (save it with :func:`braidsim.plotting.save`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from braidsim.plotting import new_figure

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from braidsim.analysis.basins import BasinMap
    from braidsim.analysis.bifurcation import BifurcationDiagram
    from braidsim.analysis.impacts import EnergyBalance, ImpactStatistics
    from braidsim.analysis.lyapunov import LyapunovEstimate
    from braidsim.analysis.regimes import SteadyState
    from braidsim.analysis.restitution import RestitutionTable
    from braidsim.analysis.spectra import Spectrum

REGIME_COLORS = {
    "no_contact": "#7f7f7f",
    "resting_contact": "#1f77b4",
    "periodic_one_sided": "#2ca02c",
    "periodic_two_sided": "#9467bd",
    "chattering": "#ff7f0e",
    "irregular": "#d62728",
    "failed": "#000000",
}

# axis label and factor to the plotted unit, per parameter unit
_UNIT_SCALE = {"m": (1e3, "mm"), "m/s": (1.0, "m/s"), "rad/s": (1.0, "rad/s"), "rad": (1.0, "rad")}


def parameter_axis(key: str) -> tuple[float, str]:
    """(factor, axis label) for plotting parameter ``key`` in readable units."""
    from braidsim.params import SCHEMA

    unit = SCHEMA[key].unit if key in SCHEMA else ""
    f, u = _UNIT_SCALE.get(unit, (1.0, unit))
    return f, f"{key} / {u}" if u else key


def plot_restitution(table: RestitutionTable) -> Figure:
    """Effective restitution e of each law against its nominal c_r: simulated impacts
    (markers) on the exact relation e(D(c_r)) (lines), with e = c_r dashed."""
    from braidsim import contact

    fig = new_figure(6.4, 4.6)
    ax = fig.add_subplot(1, 1, 1)
    fine = np.linspace(max(1e-3, float(table.nominal.min())), 1.0, 200)
    markers = "osD^v<>px*h+"
    cmap = [f"C{i % 10}" for i in range(len(table.laws))]
    for i, law in enumerate(table.laws):
        obj = contact.get_law(law)
        exact = [contact.effective_restitution(obj.damping_factor(float(c))) for c in fine]
        ax.plot(fine, exact, "-", color=cmap[i], lw=1.0)
        ax.plot(
            table.nominal,
            table.simulated[i],
            markers[i % len(markers)],
            color=cmap[i],
            ms=4,
            mfc="none",
            label=law,
        )
    ax.plot([0, 1], [0, 1], "k--", lw=0.8, label="e = $c_r$")
    ax.set_xlim(0, 1.02)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("nominal coefficient of restitution $c_r$")
    ax.set_ylabel("effective restitution $e = -v_{out}/v_{in}$")
    ax.set_title(
        "simulated impacts (markers) on the exact relation "
        r"$1 - De = (1+D)e^{-D(1+e)}$ (lines)",
        fontsize=9,
    )
    ax.grid(True, lw=0.3, alpha=0.6)
    ax.legend(fontsize=7, frameon=False, ncol=2, loc="upper left")
    return fig


def plot_bifurcation(
    diagram: BifurcationDiagram,
    title: str | None = None,
    marks: Sequence[tuple[float, str]] = (),
) -> Figure:
    """Stroboscopic position relative to the inner wall, u = x - h, against the parameter,
    coloured by regime; ``marks`` are (value [SI], label) drawn as vertical lines."""
    fig = new_figure(6.8, 4.4)
    ax = fig.add_subplot(1, 1, 1)
    f, label = parameter_axis(diagram.key)
    seen: set[str] = set()
    for v, s in zip(diagram.values, diagram.states, strict=True):
        lab = s.regime.label
        if s.strobe_u.size == 0:
            continue
        ax.plot(
            np.full(s.strobe_u.size, v * f),
            s.strobe_u * 1e3,
            marker="o",
            ms=1.2,
            ls="none",
            color=REGIME_COLORS.get(lab, "k"),
            label=None if lab in seen else lab.replace("_", " "),
        )
        seen.add(lab)
    for k, (v, text) in enumerate(marks):
        ax.axvline(v * f, color="0.2", lw=0.8, ls=("--", ":", "-.")[k % 3], label=text)
    ax.set_xlabel(label)
    ax.set_ylabel("stroboscopic $x - h$ / mm")
    ax.grid(True, lw=0.3, alpha=0.6)
    if seen or marks:
        ax.legend(fontsize=7, frameon=False, markerscale=3, loc="best")
    ax.set_title(title or f"{diagram.scenario}: bifurcation diagram", fontsize=10)
    return fig


def plot_basins(bmap: BasinMap, title: str | None = None) -> Figure:
    """Attractor reached from each start of the grid."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    fig = new_figure(6.6, 4.8)
    ax = fig.add_subplot(1, 1, 1)
    fx, lx = parameter_axis(bmap.x_key)
    fy, ly = parameter_axis(bmap.y_key)
    n = max(len(bmap.attractors), 1)
    palette = ["#000000"] + [f"C{i % 10}" for i in range(n)]
    cmap = ListedColormap(palette)

    def edges(v: np.ndarray) -> np.ndarray:
        if v.size == 1:
            return np.array([v[0] - 0.5, v[0] + 0.5])
        mid = 0.5 * (v[1:] + v[:-1])
        return np.concatenate([[2 * v[0] - mid[0]], mid, [2 * v[-1] - mid[-1]]])

    ax.pcolormesh(
        edges(bmap.x_values) * fx,
        edges(bmap.y_values) * fy,
        bmap.ids + 1,
        cmap=cmap,
        vmin=-0.5,
        vmax=n + 0.5,
        shading="flat",
    )
    handles = [
        Patch(
            color=palette[a.id + 1],
            label=f"{a.id}: {a.describe().replace('_', ' ')} ({a.count})",
        )
        for a in bmap.attractors
    ]
    if np.any(bmap.ids < 0):
        handles.append(Patch(color="#000000", label="failed"))
    ax.legend(
        handles=handles,
        fontsize=7,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        frameon=False,
        title="attractor (starts)",
        title_fontsize=7,
    )
    ax.set_xlabel(lx)
    ax.set_ylabel(ly)
    ax.set_title(title or f"{bmap.scenario}: basins of attraction", fontsize=10)
    return fig


def plot_lyapunov(
    est: LyapunovEstimate, title: str | None = None, unit: str = "1/s", time_unit: str = "s"
) -> Figure:
    """Convergence of the running Lyapunov estimate against the measuring time."""
    fig = new_figure(6.0, 3.8)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(est.times, est.running, lw=1.0)
    ax.axhline(est.exponent, color="k", lw=0.8, ls="--", label=f"final {est.exponent:.4g} {unit}")
    ax.axhline(0.0, color="0.5", lw=0.6)
    n = est.running.size
    tail = est.running[n // 10 :] if n >= 10 else est.running
    lo, hi = float(tail.min()), float(tail.max())
    pad = 0.5 * max(hi - lo, 0.1 * abs(est.exponent), 1e-12)
    ax.set_ylim(min(lo, 0.0) - pad, max(hi, 0.0) + pad)
    ax.set_xlabel(f"measuring time / {time_unit}" if time_unit else "measuring time")
    ax.set_ylabel(f"running estimate of $\\lambda_1$ / ({unit})")
    ax.grid(True, lw=0.3, alpha=0.6)
    ax.legend(fontsize=8, frameon=False)
    ax.set_title(title or "largest Lyapunov exponent (two-trajectory method)", fontsize=10)
    return fig


def plot_energy_balance(eb: EnergyBalance, title: str | None = None) -> Figure:
    """The energy terms since the start and the residual of the balance."""
    fig = new_figure(6.4, 5.0)
    ax1, ax2 = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1])
    e = eb.kinetic + eb.elastic
    ax1.plot(eb.t, e - e[0], label="kinetic + elastic (change)", lw=1.0)
    ax1.plot(eb.t, eb.load_work, label="work of the loads", lw=0.8)
    ax1.plot(eb.t, eb.track_work + eb.slot_work, label="work of the moving walls", lw=0.8)
    ax1.plot(eb.t, -eb.contact_dissipated, label="- contact dissipation", lw=0.8)
    ax1.plot(eb.t, -eb.friction_dissipated, label="- friction dissipation", lw=0.8)
    ax1.set_ylabel("energy / J")
    ax1.grid(True, lw=0.3, alpha=0.6)
    ax1.legend(fontsize=7, frameon=False)
    ax2.plot(eb.t, eb.residual, color="k", lw=0.8)
    ax2.set_ylabel("residual / J")
    ax2.set_xlabel("time $t$ / s")
    ax2.grid(True, lw=0.3, alpha=0.6)
    ax1.set_title(
        title or f"energy balance (closes to {eb.closure:.2g} of the energy exchanged)",
        fontsize=10,
    )
    return fig


def plot_impact_statistics(stats: ImpactStatistics, title: str | None = None) -> Figure:
    """Approach-speed histogram and dissipated energy per impact."""
    fig = new_figure(6.4, 5.0)
    ax1, ax2 = fig.subplots(2, 1)
    e = stats.speed_bins
    ax1.bar(
        0.5 * (e[1:] + e[:-1]),
        stats.speed_counts,
        width=np.diff(e),
        color="C0",
        edgecolor="k",
        lw=0.3,
    )
    ax1.set_xlabel("approach speed / (m/s)")
    ax1.set_ylabel("impacts")
    imp = stats.impacts
    if len(imp):
        for wall, m in (("inner", "o"), ("outer", "s"), ("rear", "^"), ("front", "v")):
            sel = imp["wall"] == wall
            if sel.any():
                ax2.semilogy(
                    imp["t"][sel],
                    np.maximum(imp["dissipated_energy"][sel], 1e-300),
                    m,
                    ms=3,
                    ls="none",
                    label=f"{wall} wall",
                )
        ax2.legend(fontsize=7, frameon=False)
    else:
        ax2.text(0.5, 0.5, "no impacts", transform=ax2.transAxes, ha="center")
    ax2.set_xlabel("time $t$ / s")
    ax2.set_ylabel("dissipated energy / J")
    for ax in (ax1, ax2):
        ax.grid(True, lw=0.3, alpha=0.6)
    frac = stats.contact_fraction.get("track", math.nan)
    ax1.set_title(
        title or f"{len(imp)} impacts, in contact {100 * frac:.3g} % of the time", fontsize=10
    )
    return fig


def plot_spectra(spectra: Sequence[Spectrum], title: str | None = None) -> Figure:
    """Amplitude spectra (log scale) with the harmonics of the excitation marked."""
    fig = new_figure(6.4, 2.6 * max(len(spectra), 1) + 0.6)
    axes = fig.subplots(max(len(spectra), 1), 1, squeeze=False)[:, 0]
    for ax, sp in zip(axes, spectra, strict=False):
        scale, unit = (1e3, "mm") if sp.unit == "m" else (1.0, sp.unit)
        A = sp.amplitude * scale
        pos = A > 0
        ax.semilogy(sp.frequency[pos], A[pos], lw=0.7)
        fmax = min(float(sp.frequency[-1]), 20 * sp.excitation_frequency or float(sp.frequency[-1]))
        if sp.excitation_frequency > 0:
            for h in sp.harmonics:
                ax.axvline(h["frequency"], color="0.6", lw=0.5, ls=":")
        ax.set_xlim(0, fmax)
        ax.set_ylabel(f"{sp.quantity} / {unit}")
        ax.grid(True, lw=0.3, alpha=0.5)
    axes[-1].set_xlabel("frequency / Hz (dotted: harmonics of $\\omega_h$)")
    axes[0].set_title(title or "amplitude spectra over the steady-state window", fontsize=10)
    return fig


def plot_poincare(ss: SteadyState, title: str | None = None) -> Figure:
    """Stroboscopic (Poincare) section of a steady state: (x - h, dx/dt)."""
    fig = new_figure(5.0, 4.0)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(
        ss.strobe_u * 1e3, ss.strobe_vx, "o", ms=3, color=REGIME_COLORS.get(ss.regime.label, "k")
    )
    ax.set_xlabel("stroboscopic $x - h$ / mm")
    ax.set_ylabel(r"stroboscopic $\dot{x}$ / (m/s)")
    ax.grid(True, lw=0.3, alpha=0.6)
    per = f", period {ss.regime.period}" if ss.regime.period else ""
    ax.set_title(
        title or f"Poincare section: {ss.regime.label.replace('_', ' ')}{per}", fontsize=10
    )
    return fig
