"""The report's figures: the paper's Figures 3-22 with its stated ranges drawn in, the added
impact-sequence and phase-portrait figures, and a Table 1 comparison.

Units are the paper's: displacement and depth in mm, forces in N, time in s. Each paper
figure has two panels: (a) the whole run with the "initially" and "later" windows shaded
and the paper's ranges as dashed lines over the window they belong to, (b) the "later"
window enlarged, where the settled motion is orders of magnitude smaller than the first
impacts.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.plotting import QUANTITIES, new_figure, plot_impacts, plot_phase, plot_quantity

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from braidsim.paper.findings import Outcome
    from braidsim.paper.values import RunSpec
    from braidsim.result import Result

#: file-name stem of each plotted quantity
SHORT = {"x": "x", "stiffness_force": "F_kg", "damping_force": "F_cg", "depth": "depth"}
#: what each paper figure shows, as in its caption
CAPTION = {
    "x": "displacement x",
    "stiffness_force": "stiffness-related component force F_kg",
    "damping_force": "damping-related component force F_cg",
    "depth": "contact depth",
}
PAPER_COLOR = "C3"
#: line style of the paper's values per window: (colour, dash pattern)
PAPER_STYLE = {
    "initially": ("C3", (0, (5, 2))),
    "later": ("#7b2cbf", (0, (2, 1.5))),
    "run": ("C3", (0, (5, 2))),
}
WINDOW_COLORS = {"initially": "0.85", "later": "#cfe3f5", "run": "0.92"}


def figure_filename(number: int, quantity: str) -> str:
    """``fig03_x.png``, ``fig04_F_kg.png``, ... (the paper's numbering)."""
    return f"fig{number:02d}_{SHORT[quantity]}.png"


def _paper_lines(
    ax: Axes, outcomes: Sequence[Outcome], window: str, t_span: tuple[float, float]
) -> list[str]:
    """Draw the paper's values of one window as dashed lines; return notes for off-scale values."""
    lo, hi = ax.get_ylim()
    span = hi - lo
    notes = []
    first = True
    for o in outcomes:
        if o.item.window != window:
            continue
        v = o.item.value  # paper unit (N or mm) = plotted unit
        if not (lo - 0.25 * span <= v <= hi + 0.25 * span):
            notes.append(f"paper {o.item.statistic} {v:g} {o.item.unit} (off scale)")
            continue
        color, dashes = PAPER_STYLE.get(window, PAPER_STYLE["initially"])
        ax.hlines(
            v,
            t_span[0],
            t_span[1],
            colors=color,
            linestyles=dashes,
            lw=1.2,
            label=f"paper, {window}" if first else "_nolegend_",
            zorder=5,
        )
        first = False
    return notes


def first_impacts_end(result: Result, t_max: float, share: float = 0.05) -> float:
    """End of the first impacts [s]: where the zoom panel of a paper figure stops.

    The last contact that starts before ``t_max`` with a peak force of at least ``share`` of
    the largest one there, times 1.25 (at least 2 ms, at most ``t_max``).
    """
    imp = result.impacts
    imp = imp[imp["t"] <= t_max]
    if imp.empty:
        return t_max
    peak = imp["peak_force"].abs()
    big = imp[peak >= share * float(peak.max())]
    ends = big["t_end"].where(big["t_end"].notna(), big["t"])
    return float(min(t_max, max(1.25 * float(ends.max()), 2e-3)))


def _fit_ylim(ax: Axes, values: Sequence[float], pad: float = 0.06) -> None:
    """Widen the y-limits of ``ax`` so that the paper's ``values`` fit inside, with margin.

    A value more than half the plotted span beyond it (a paper value that deviates by an
    order of magnitude) is left out, so that it does not flatten our trace: it is named as
    "off scale" on the figure instead.
    """
    lo, hi = ax.get_ylim()
    span0 = hi - lo
    near = [v for v in values if lo - 0.5 * span0 <= v <= hi + 0.5 * span0]
    if near:
        lo, hi = min(lo, *near), max(hi, *near)
    span = hi - lo
    if span > 0:
        ax.set_ylim(lo - pad * span, hi + pad * span)


def _left_margin(ax: Axes, t0: float, t1: float, share: float = 0.02) -> None:
    """Start the time axis a little before t0, so that a peak at t0 is not on the spine."""
    ax.set_xlim(t0 - share * (t1 - t0), t1)


def paper_figure(
    result: Result, spec: RunSpec, quantity: str, number: int, outcomes: Sequence[Outcome]
) -> Figure:
    """One of the paper's Figures 3-22, with the paper's stated ranges for comparison.

    Panels: (a) the whole run, the "initially" and "later" windows shaded, the paper's
    "initially" values as dashed lines; (b) the first impacts enlarged (to
    :func:`first_impacts_end`), where the largest peaks are; (c) the "later" window
    enlarged, where the settled motion is orders of magnitude smaller. Every panel has its
    own y label; the y-limits hold both our trace and the paper's values.

    Parameters
    ----------
    result : Result
        The calibrated run (with series).
    spec : RunSpec
        Its windows and figure numbers.
    quantity : str
        ``x``, ``stiffness_force``, ``damping_force`` or ``depth``.
    number : int
        Paper figure number.
    outcomes : sequence of Outcome
        The items of this run (those of ``quantity`` are drawn).
    """
    has_later = "later" in spec.windows
    has_initial = "initially" in spec.windows
    ncols = 1 + int(has_initial) + int(has_later)
    fig = new_figure(4.0 + 3.6 * (ncols - 1) if ncols > 1 else 6.4, 3.9)
    widths = [1.7] + [1.0] * (ncols - 1)
    axes = list(np.atleast_1d(fig.subplots(1, ncols, gridspec_kw={"width_ratios": widths})))
    ax = axes[0]
    axi = axes[1] if has_initial else None
    axz = axes[-1] if has_later else None
    own = [o for o in outcomes if o.item.quantity == quantity]

    def paper_values(window: str) -> list[float]:
        return [o.item.value for o in own if o.item.window == window]

    plot_quantity(result, quantity, ax=ax, label="braidsim")
    ax.ticklabel_format(axis="y", useOffset=False)
    _fit_ylim(ax, paper_values("initially"), pad=0.04)
    _left_margin(ax, 0.0, spec.duration)
    for name, (t0, t1) in spec.windows.items():
        if name == "run":
            continue
        ax.axvspan(t0, t1, color=WINDOW_COLORS.get(name, "0.9"), zorder=0, lw=0)
        ax.text(
            0.5 * (t0 + t1),
            1.0,
            name,
            transform=ax.get_xaxis_transform(),
            ha="center",
            va="bottom",
            fontsize=8,
            color="0.3",
        )
    notes = []
    if has_initial:
        notes += _paper_lines(ax, own, "initially", spec.windows["initially"])
    ax.set_title(f"(a) whole run, {spec.duration:g} s", fontsize=9, loc="left", pad=12)
    if axi is not None:
        w0 = spec.windows["initially"]
        tz = first_impacts_end(result, w0[1])
        plot_quantity(result, quantity, ax=axi, window=(w0[0], tz), label="braidsim")
        axi.ticklabel_format(axis="y", useOffset=False)
        _fit_ylim(axi, paper_values("initially"), pad=0.04)
        _left_margin(axi, w0[0], tz)
        _paper_lines(axi, own, "initially", (w0[0], tz))
        axi.set_title(f"(b) first impacts, {w0[0]:g}-{tz:.3g} s", fontsize=9, loc="left", pad=12)
    if axz is not None:
        w = spec.windows["later"]
        plot_quantity(result, quantity, ax=axz, window=w, label="braidsim")
        # a flat later series (a carrier at rest) needs a visible y-range around its value,
        # wide enough for the paper's value too
        y0, y1 = axz.get_ylim()
        later = paper_values("later")
        lo, hi = min([y0, *later]), max([y1, *later])
        center, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        main_lo, main_hi = ax.get_ylim()
        # never zoom below 0.2 % of the whole-run scale: integrator-level noise (uN on a
        # carrier at rest) is not a feature
        half = max(1.08 * half, 0.05 * abs(center), 2e-3 * (main_hi - main_lo))
        if half > 0.0:
            axz.set_ylim(center - half, center + half)
        axz.ticklabel_format(axis="y", useOffset=False)
        notes += _paper_lines(axz, own, "later", w)
        label = "(c)" if axi is not None else "(b)"
        axz.set_title(f"{label} later window, {w[0]:g}-{w[1]:g} s", fontsize=9, loc="left", pad=12)
    # one legend for all panels, outside the axes so that it never hides data
    for a in axes:
        if a.get_legend() is not None:
            a.get_legend().remove()
    handles, labels = [], []
    for a in axes:
        h, lab = a.get_legend_handles_labels()
        for hh, ll in zip(h, lab, strict=True):
            if ll not in labels:
                handles.append(hh)
                labels.append(ll)
    fig.legend(
        handles, labels, fontsize=8, frameon=False, loc="outside lower center", ncol=len(labels)
    )
    if notes:
        ax.text(
            0.99,
            0.02,
            "; ".join(notes),
            transform=ax.transAxes,
            ha="right",
            va="bottom",
            fontsize=7,
            color=PAPER_COLOR,
        )
    fig.suptitle(
        f"Figure {number}: {CAPTION[quantity]}, section {spec.section} ({spec.title})", fontsize=10
    )
    return fig


def figure_alt_text(number: int, quantity: str, spec: RunSpec) -> str:
    """Alt text of a paper figure: what it shows, for readers who cannot see it."""
    return (
        f"Figure {number} of the paper reproduced: {CAPTION[quantity]} against time for "
        f"section {spec.section} ({spec.title}); panels show the whole {spec.duration:g} s "
        "run, the first impacts enlarged and the later window enlarged, with the paper's "
        "stated ranges as dashed lines"
    )


def impacts_figure(result: Result, spec: RunSpec) -> Figure:
    """The added impact-sequence figure of one paper run."""
    return plot_impacts(result, title=f"Impact sequence, section {spec.section}\n{spec.title}")


def phase_figure(result: Result, spec: RunSpec) -> Figure:
    """The added phase portrait of one paper run."""
    return plot_phase(result, title=f"Phase portrait, section {spec.section}\n{spec.title}")


def table1_figure(rows: Sequence[Mapping[str, Any]]) -> Figure:
    """Table 1: the paper's ranges (open markers) against ours (filled) for every law.

    ``rows`` are the entries of :func:`braidsim.paper.report.table1_rows`.
    """
    fig = new_figure(9.0, 6.2)
    axes = fig.subplots(2, 2, sharex=True).ravel()
    laws = [str(r["label"]) for r in rows if r["quantity"] == "contact_force"]
    xs = np.arange(len(laws))
    for ax, q in zip(
        axes, ("contact_force", "stiffness_force", "damping_force", "depth"), strict=True
    ):
        sel = [r for r in rows if r["quantity"] == q]
        scale = 100.0 if q == "depth" else 1.0  # depth in 1e-2 mm, as Table 1
        for j, (key, style) in enumerate((("paper", "o"), ("ours", "s"))):
            lo = np.array([float(r[f"{key}_min"]) for r in sel]) * scale
            hi = np.array([float(r[f"{key}_max"]) for r in sel]) * scale
            off = -0.12 if j == 0 else 0.12
            color = "k" if key == "paper" else "C0"
            mfc = "none" if key == "paper" else color
            ax.vlines(xs + off, lo, hi, color=color, lw=0.8, alpha=0.6)
            ax.plot(
                xs + off,
                lo,
                style,
                color=color,
                mfc=mfc,
                ms=5,
                ls="none",
                label="paper" if key == "paper" else "braidsim (E = 200 GPa)",
            )
            ax.plot(xs + off, hi, style, color=color, mfc=mfc, ms=5, ls="none")
        ax.axhline(0.0, color="0.5", lw=0.6)
        # symmetric log scale: the elastic laws (Hertz, Braendlein) reach tens of N (and
        # 1e-4 mm), the others thousands; on a linear axis the former vanish into the zero
        # line. Linear below the smallest nonzero magnitude of the panel (rounded down to a
        # power of ten), logarithmic above.
        vals = np.abs([float(r[f"{k}_{e}"]) * scale for r in sel for k in ("paper", "ours")
                       for e in ("min", "max")])  # fmt: skip
        nz = vals[vals > 0]
        if nz.size:
            lin = 10.0 ** np.floor(np.log10(nz.min()))
            ax.set_yscale("symlog", linthresh=lin, linscale=0.5)
            signed = np.array([float(r[f"{k}_{e}"]) * scale for r in sel for k in ("paper", "ours")
                               for e in ("min", "max")])  # fmt: skip
            # a factor 2 of room beyond the extremes so that no marker sits on the frame
            ax.set_ylim(min(2.0 * signed.min(), -lin), max(2.0 * signed.max(), lin))
        unit = "$10^{-2}$ mm" if q == "depth" else "N"
        ax.set_ylabel(f"{QUANTITIES[q][2].split(' /')[0]} / {unit}\n(symmetric log scale)")
        ax.grid(True, axis="y", lw=0.3, alpha=0.6)
        ax.set_xticks(xs, laws, rotation=35, ha="right", fontsize=8)
        ax.tick_params(axis="y", labelsize=8)
    h, lab = axes[0].get_legend_handles_labels()
    fig.legend(h, lab, fontsize=8, frameon=False, loc="outside lower center", ncol=2)
    fig.suptitle(
        "Table 1: range (min to max) of each quantity, paper against braidsim", fontsize=10
    )
    return fig


def alt_text(rel_path: str, runs: Mapping[str, RunSpec]) -> str:
    """Alt text of a report figure from its file name (``figures/fig16_F_kg.png``,
    ``figures/added_3.3_impacts.png``, ``figures/table1.png``) and the paper runs."""
    name = rel_path.rsplit("/", 1)[-1].removesuffix(".png")
    if name == "table1":
        return (
            "Table 1 of the paper against braidsim: the range (minimum to maximum) of the "
            "contact force, its stiffness- and damping-related parts and the contact depth "
            "for each of the nine contact laws, paper as open circles and braidsim as filled "
            "squares, on symmetric logarithmic axes"
        )
    if name.startswith("added_"):
        key, kind = name.removeprefix("added_").rsplit("_", 1)
        spec = runs.get(key)
        where = f"section {spec.section} ({spec.title})" if spec else key
        if kind == "impacts":
            return (
                f"Impact sequence of {where}: approach speed and peak contact force of every "
                "impact against time, by wall, on logarithmic axes"
            )
        return (
            f"Phase portrait of {where}: carrier speed against its position relative to the "
            "inner wall, coloured by time, with both walls marked"
        )
    if name.startswith("fig"):
        number = int(name[3:5])
        for spec in runs.values():
            for q, n in (spec.figures or {}).items():
                if n == number:
                    return figure_alt_text(number, q, spec)
    return name
