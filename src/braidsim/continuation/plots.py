"""Figures of continuation results: bifurcation diagrams and the safe operating map.

* :func:`plot_branches`: the stroboscopic position of each orbit (x - h at forcing phase 0,
  one curve per sample of a period-k orbit) against the parameter, stable solid and unstable
  dashed, special points marked; a brute-force bifurcation diagram of the same range can be
  drawn beneath as grey dots.
* :func:`plot_operating_map`: boundary curves (fold, period doubling, grazing) in the plane
  of two parameters over the brute-force regime map of the same range.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.analysis.plots import REGIME_COLORS, parameter_axis
from braidsim.plotting import new_figure

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from braidsim.continuation.branch import Branch
    from braidsim.continuation.twopar import BoundaryCurve

MARKERS = {"fold": "s", "period_doubling": "D", "neimark_sacker": "*", "grazing": "o"}
CURVE_STYLE = {
    "fold": ("C3", "-"),
    "period_doubling": ("C2", "-."),
    "neimark_sacker": ("C4", ":"),
    "grazing": ("k", "--"),
}

ALT_COLORS = ("C0", "C5", "C1", "C6")
"""Colours of further boundaries of one type (a lift-off and a grazing of another wall)."""

MERGE_FRACTION = 0.025
"""Special points of one type closer than this fraction of both axes' spans are drawn as one."""


def merge_marks(
    marks: Sequence[tuple[float, float, str]], spans: tuple[float, float]
) -> list[tuple[float, float, str, int]]:
    """Thin the special points' markers: of the points of one type within
    ``MERGE_FRACTION`` of the spans of each other (greedily, in order), the first is kept
    with the number it stands for."""
    sx = max(abs(spans[0]), 1e-300)
    sy = max(abs(spans[1]), 1e-300)
    out: list[list[Any]] = []
    for x, y, kind in marks:
        for m in out:
            if (
                m[2] == kind
                and abs(m[0] - x) < MERGE_FRACTION * sx
                and abs(m[1] - y) < MERGE_FRACTION * sy
            ):
                m[3] += 1
                break
        else:
            out.append([x, y, kind, 1])
    return [(float(a), float(b), str(c), int(d)) for a, b, c, d in out]


def _segments(stable: np.ndarray) -> list[tuple[int, int, bool]]:
    """Runs of equal stability as (start, stop inclusive of the next point, stable)."""
    out = []
    i = 0
    n = stable.size
    while i < n - 1:
        j = i
        while j < n - 1 and stable[j + 1] == stable[i]:
            j += 1
        out.append((i, min(j + 1, n - 1), bool(stable[i])))
        i = j + 1 if j > i else i + 1
    return out


def plot_branches(
    branches: Sequence[Branch],
    title: str | None = None,
    brute: Any | None = None,
    ax: Any | None = None,
) -> Figure:
    """Bifurcation diagram of continued branches (module docstring).

    ``brute``: a :class:`braidsim.analysis.BifurcationDiagram` of the same parameter, drawn
    beneath as grey dots."""
    if ax is None:
        fig = new_figure(6.8, 4.4)
        ax = fig.add_subplot(1, 1, 1)
    else:
        fig = ax.figure
    key = branches[0].key
    f, label = parameter_axis(key)
    if brute is not None:
        p, u, _ = brute.points()
        ax.plot(p * f, u * 1e3, ".", color="0.65", ms=2, label="brute force (settled runs)")
    seen: set[str] = set()
    marks: list[tuple[float, float, str]] = []
    for b_i, br in enumerate(branches):
        if len(br.points) < 2:
            continue
        v = br.values * f
        su = np.array([o.profile.strobe_u for o in br.points]) * 1e3
        st = br.stable
        color = f"C{b_i % 10}"
        # one legend entry per branch (its colour); the line styles are explained once
        rests = {o.profile.impacts == 0 for o in br.points}
        kind = (
            {True: "resting", False: "impacting"}[rests.pop()]
            if len(rests) == 1
            else "resting, then impacting"
        )
        ax.plot([], [], color=color, lw=1.3, label=f"branch {b_i + 1}: period {br.period}, {kind}")
        for a, b, stable in _segments(st):
            for s in range(su.shape[1]):
                ax.plot(
                    v[a : b + 1],
                    su[a : b + 1, s],
                    ls="-" if stable else "--",
                    lw=1.3 if stable else 0.9,
                    color=color,
                )
        for sp in br.special:
            o = sp.orbit if sp.orbit is not None else br.points[min(sp.index, len(br.points) - 1)]
            for y in o.profile.strobe_u * 1e3:
                marks.append((sp.value * f, float(y), sp.type))
    ax.plot([], [], color="0.3", ls="-", lw=1.3, label="stable (solid)")
    ax.plot([], [], color="0.3", ls="--", lw=0.9, label="unstable (dashed)")
    # special points closer than MERGE_FRACTION of the axes are drawn once per type, the
    # number merged beside them (branches born at a point, a grazing next to a doubling)
    ax.autoscale_view()
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    for x, y, kind, n in merge_marks(marks, (x1 - x0, y1 - y0)):
        lab = kind.replace("_", " ")
        ax.plot(
            [x],
            [y],
            MARKERS.get(kind, "x"),
            ms=5,
            mfc="none",
            color="k",
            label=None if lab in seen else lab,
        )
        seen.add(lab)
        if n > 1:
            ax.annotate(
                f"{n}", (x, y), textcoords="offset points", xytext=(4, 3), fontsize=6, color="0.3"
            )
    ax.set_xlabel(label)
    ax.set_ylabel("$x - h$ at forcing phase 0 / mm")
    ax.grid(True, lw=0.3, alpha=0.6)
    ax.legend(fontsize=7, frameon=False, loc="best")
    ax.set_title(title or "periodic orbits: stable solid, unstable dashed", fontsize=10)
    return fig


def plot_operating_map(
    curves: Sequence[BoundaryCurve],
    *,
    regimes: tuple[np.ndarray, np.ndarray, Sequence[Sequence[str]]] | None = None,
    marks: Sequence[tuple[float, float, str]] = (),
    bound: tuple[np.ndarray, np.ndarray] | None = None,
    title: str | None = None,
    keys: tuple[str, str] | None = None,
    legend_loc: Any = "upper left",
) -> Figure:
    """The safe operating map: boundary curves in (key2, key1) over a regime map.

    Parameters
    ----------
    curves : BoundaryCurve
        Drawn with key2 on the x axis and key1 (the branch parameter) on the y axis; a
        curve with the two the other way round (followed from a branch over the second
        parameter, :func:`~braidsim.continuation.twopar.crossing_boundaries`) is drawn in
        the same axes.
    regimes : (values1, values2, labels), optional
        A brute-force regime map: labels[i][j] the regime at (values1[i], values2[j]).
    marks : (value1, value2, text)
        Points to mark (e.g. the paper's cases).
    bound : (values2, values1), optional
        An analytic curve (dotted), e.g. the contact-loss bound a_p = h_a omega_h^2.
    keys : (key1, key2), optional
        The parameters of the y and x axes (default those of the first curve).
    legend_loc : str
        Where the legend goes (a matplotlib location).
    """
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    fig = new_figure(6.8, 4.8)
    ax = fig.add_subplot(1, 1, 1)
    if not curves and regimes is None:
        return fig
    key1 = keys[0] if keys else curves[0].key1 if curves else ""
    key2 = keys[1] if keys else curves[0].key2 if curves else ""
    f1, lab1 = parameter_axis(key1) if key1 else (1.0, "")
    f2, lab2 = parameter_axis(key2) if key2 else (1.0, "")
    handles: list[Any] = []
    if regimes is not None:
        v1, v2, labels = regimes
        names = sorted({lab for row in labels for lab in row})
        idx = np.array([[names.index(lab) for lab in row] for row in labels], dtype=float)
        cmap = ListedColormap([REGIME_COLORS.get(n, "#000000") for n in names])
        ax.pcolormesh(
            np.asarray(v2) * f2,
            np.asarray(v1) * f1,
            idx,
            cmap=cmap,
            vmin=-0.5,
            vmax=len(names) - 0.5,
            shading="nearest",
            alpha=0.35,
        )
        handles += [
            Patch(color=REGIME_COLORS.get(n, "#000"), alpha=0.35, label=n.replace("_", " "))
            for n in names
        ]
    seen: set[str] = set()
    distinct: dict[tuple[str, str], int] = {}  # boundaries of one type: own colours
    for c in curves:
        color, ls = CURVE_STYLE.get(c.type, ("k", "-"))
        name = c.name or c.type.replace("_", " ")
        n_of_type = sum(1 for t, _ in distinct if t == c.type)
        i = distinct.setdefault((c.type, name), n_of_type)
        if i:
            color = ALT_COLORS[(i - 1) % len(ALT_COLORS)]
        lab = f"{name} (period {c.period})"
        ys, xs = (c.p2, c.p1) if (c.key1, c.key2) == (key2, key1) != (key1, key2) else (c.p1, c.p2)
        (ln,) = ax.plot(
            np.asarray(xs) * f2,
            np.asarray(ys) * f1,
            ls=ls,
            color=color,
            lw=1.6,
            marker=".",
            ms=3,
            label=None if lab in seen else lab,
        )
        if lab not in seen:
            handles.append(ln)
        seen.add(lab)
        if getattr(c, "end", "") == "grazing" and len(xs):
            # a codimension-two point: the bifurcation's orbit grazes a wall there
            elab = f"{name} meets a grazing"
            (mk,) = ax.plot(
                [xs[-1] * f2], [ys[-1] * f1], "X", color=color, ms=8, mec="k", mew=0.6, label=elab
            )
            if elab not in seen:
                handles.append(mk)
            seen.add(elab)
    if bound is not None:
        (ln,) = ax.plot(
            np.asarray(bound[0]) * f2,
            np.asarray(bound[1]) * f1,
            ":",
            color="0.3",
            lw=1.2,
            label="contact-loss bound $a_p = h_a\\omega_h^2$",
        )
        handles.append(ln)
    for a, b, text in marks:
        ax.plot(b * f2, a * f1, "k*", ms=9)
        ax.annotate(text, (b * f2, a * f1), textcoords="offset points", xytext=(5, 5), fontsize=7)
    ax.set_xlabel(lab2)
    ax.set_ylabel(lab1)
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(handles=handles, fontsize=7, frameon=True, loc=legend_loc)
    ax.set_title(
        title or "safe operating map: boundaries over the brute-force regimes", fontsize=10
    )
    return fig
