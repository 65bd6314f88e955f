"""The design report: summary (JSON), Markdown, tables (CSV), figures, and the optimised
machine as a spec that ``braidsim machine`` runs.

:func:`write_report` builds the whole directory under a temporary name and renames it into
place (:func:`braidsim.io.atomic_directory`): the report is complete or absent.

================================  ===========================================================
``summary.json``                  everything below as numbers (SI units)
``report.md``                     the report
``design_summary.png``            main figure: speed and drive torque over the cycle, a
                                  carrier through a transfer, the change of each figure of
                                  both contact pairs, the improvement distributions of the
                                  profile and the other levers over tolerance samples
``profile.png``                   speed, acceleration and jerk over the cycle with the limits
``peak_force_per_transfer.png``   peak force and impacts of every transfer, before and after
``sensitivity.png``               one-at-a-time swings and Morris mu* of the levers
``speed_limits.png``              transfer speed limit and chatter speed against each lever
``convergence.png``               the optimiser's best value per generation
``optimised_profile.csv``         the kernel's table: phase, relative speed, omega, omega'
``optimised_machine.toml``        the machine spec with the optimised [machine.speed_profile]
``transfers_before.csv``,         one row per transfer of the full machine runs
``transfers_after.csv``
``sensitivity.csv``               every one-at-a-time run
``speed_limits.csv``              every lever setting's speed limits
================================  ===========================================================
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.design.evaluate import (
    FIGURES,
    METRIC_KEYS,
    OBJECTIVES,
    metric_label,
    noise_level,
)
from braidsim.io import atomic_directory, atomic_write_text

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from braidsim.design.study import DesignResult
    from braidsim.result import Result

REPORT_KIND = "design report"


# ----------------------------------------------------------------------------------------
# summary
# ----------------------------------------------------------------------------------------


# alt text of each figure of the report (what it shows, for readers who cannot see it)
FIGURE_ALT = {
    "design_summary.png": "Design summary: horn-gear speed and drive torque over the transfer "
    "cycle, a carrier through its hardest transfer, the change of every figure of the track "
    "and slot contacts, and the improvement distributions of the profile and the other levers",
    "profile.png": "The optimised horn-gear speed, acceleration and jerk over one cycle, with "
    "the drive's limits",
    "peak_force_per_transfer.png": "Peak contact force and impact count of every transfer, "
    "at constant speed and with the optimised profile",
    "sensitivity.png": "One-at-a-time swings and Morris mu* of each lever on the objective",
    "speed_limits.png": "Transfer speed limit and chatter speed against each lever",
    "convergence.png": "Best objective value of the optimiser per generation",
}


def _kinematics(res: DesignResult) -> dict[str, Any]:
    from braidsim.machine.report import kinematics_summary

    return kinematics_summary(res.spec.machine)


def summary(res: DesignResult, files: list[str] | None = None) -> dict[str, Any]:
    """The JSON object of ``braidsim design --json`` (SI units)."""
    spec = res.spec
    opt = res.optimisation
    m = spec.machine
    prof = opt.profile
    ph, fa = prof.table()
    out: dict[str, Any] = {
        "name": spec.name,
        "description": spec.description,
        "spec": spec.to_dict(),
        "machine": {
            "name": m.name,
            "horn_gears": m.geometry.N,
            "slots": m.geometry.S,
            "carriers": len(m.loading.carriers),
            "scenario": m.scenario.name,
            "duration": m.duration,
            "cycle_time": m.cycle_time,
        },
        "braidsim_version": braidsim_version(),
        "objective": spec.objective,
        "pair": spec.pair,
        "objective_title": OBJECTIVES[spec.objective][0],
        "objective_unit": OBJECTIVES[spec.objective][1],
        "baseline": _side(res.before.metrics, res.drive_before, _zero_robust(res)),
        "optimised": _side(res.after.metrics, res.drive_after, _robust(res)),
        "robust": _robust(res),
        "reduction": res.reductions,
        "drive_model": res.drive.to_dict() if res.drive is not None else None,
        "levers": [lv.to_dict() for lv in res.levers],
        "production": {
            **res.production,
            "kinematics": _kinematics(res),
            "note": "the mean speed sets the production rate; measured from the rotation of "
            "each full run",
        },
        "profile": {
            **prof.to_dict(),
            "table": {"phase": ph, "factor": fa},
            "table_error": prof.table_error(),
            "margins": opt.margins,
            "limits": spec.limits.to_dict(),
        },
        "optimisation": opt.to_dict(),
        "proxy": {
            "cycles": spec.optimizer.cycles,
            "baseline": res.baseline_proxy,
            "classes": [{"run": c.representative, "members": list(c.members)} for c in res.classes],
            "fidelity": res.fidelity.to_dict() if res.fidelity else None,
        },
        "timings_s": res.timings,
        "files": files or [],
    }
    if res.morris is not None:
        out["sensitivity"] = {
            "morris": res.morris.to_dict(),
            "one_at_a_time": [o.to_dict() for o in res.oat],
            "optimised_not_better": robustness(res),
        }
    if res.speed_limits:
        out["speed_limits"] = {
            "metric": spec.speed_limit.metric,
            "threshold": res.threshold,
            "nominal": res.nominal_speed_limit.to_dict() if res.nominal_speed_limit else None,
            "levers": [ll.to_dict() for ll in res.speed_limits],
        }
    return out


def _finite(d: dict[str, float]) -> dict[str, float]:
    return {k: float(v) for k, v in d.items()}


def braidsim_version() -> str:
    """``braidsim.__version__``, else the installed package's metadata."""
    import braidsim

    v = getattr(braidsim, "__version__", None)
    if isinstance(v, str):
        return v
    from importlib.metadata import version

    return version("braidsim")


def _pair(m: dict[str, float], pair: str) -> dict[str, float]:
    p = "" if pair == "combined" else f"{pair}."
    noise = float(m[f"{p}noise"])
    return {
        "peak_force": float(m[f"{p}peak_force"]),
        "impact_energy_rate": float(m[f"{p}impact_energy"]),
        "impact_rate": float(m[f"{p}impacts"]),
        "noise": noise,
        "noise_level_db": noise_level(noise) if noise > 0.0 else None,  # type: ignore[dict-item]
    }


def _side(m: dict[str, float], drive: dict[str, float], robust: dict[str, Any]) -> dict[str, Any]:
    """One column of the JSON: both pairs, combined, the drive and the robust figures."""
    return {
        "track": _pair(m, "track"),
        "slot": _pair(m, "slot"),
        "combined": _pair(m, "combined"),
        "drive": dict(drive),
        "robust": robust,
        "metrics": _finite(m),
    }


def percent_se(stats: Mapping[str, Any], key: str) -> str:
    """``stats[key]`` in percent with its bootstrap standard error (``key + "_se"``), e.g.
    ``+0.4 +- 0.4 %``; the value alone where there is none."""
    value = 100 * stats[key]
    se = stats.get(f"{key}_se")
    if se is None or not math.isfinite(se):
        return f"{value:+.1f} %"
    return f"{value:+.1f} +- {100 * se:.1f} %"


def _robust(res: DesignResult) -> dict[str, Any]:
    if res.robust is None:
        return {"median_improvement": None, "p5_improvement": None, "samples": 0}
    return {
        **res.robust.stats(),
        "values": res.robust.values.tolist(),
        "check_cycles": res.spec.robust.check_cycles,
        "seed": res.spec.robust.held_out_seed,
    }


def _zero_robust(res: DesignResult) -> dict[str, Any]:
    """Constant speed against itself: improvement 0 on every set (exact)."""
    n = res.robust.samples if res.robust is not None else 0
    return {
        "median_improvement": 0.0,
        "median_improvement_se": 0.0,
        "p5_improvement": 0.0,
        "p5_improvement_se": 0.0,
        "samples": n,
    }


# ----------------------------------------------------------------------------------------
# figures
# ----------------------------------------------------------------------------------------


def carrier_trace(res: DesignResult, optimised: bool) -> tuple[Result, float, float]:
    """The run of the worst carrier of the optimised machine (constant or optimised speed),
    with a dense series over its hardest complete transfer interval: (result, t0, t1)."""
    import braidsim
    from braidsim.design.evaluate import machine_for
    from braidsim.machine.run import plan_transfers

    spec = res.spec
    run_after = res.after.run
    assert run_after is not None
    tr = run_after.transfers
    done = tr[tr["complete"]]
    row = done.loc[done["peak_force"].idxmax()] if len(done) else tr.iloc[0]
    carrier, k = str(row["carrier"]), int(row["transfer"])
    ms = machine_for(
        spec.machine_table, spec.machine_path, res.optimisation.profile if optimised else None
    )
    _, plans = plan_transfers(ms, ms.duration)
    plan = next(p for p in plans if p.carrier == carrier)
    t0 = float(plan.times[k - 1])
    t1 = float(plan.times[k]) if k < plan.times.size else ms.duration
    sc = ms.scenario.with_overrides({"transfer.times": [float(t) for t in plan.times]})
    samples = np.linspace(t0 - 0.002, t1, 4000)
    r = braidsim.simulate(sc, duration=t1, sample_times=samples)
    return r, t0, t1


def main_figure(res: DesignResult) -> Figure:
    """Speed (and drive torque) over two cycles, a carrier through its hardest transfer, the
    change of every figure of both contact pairs, and the improvement distributions of the
    profile and the other levers over the held-out tolerance samples."""
    from braidsim.plotting import new_figure

    spec = res.spec
    m = spec.machine
    prof = res.optimisation.profile
    Tc = m.cycle_time
    w = m.mean_speed
    rpm = 30.0 / math.pi
    fig = new_figure(8.0, 10.8)
    ax1, ax2, ax3, ax4 = fig.subplots(4, 1)
    ph = np.linspace(-0.5, 1.5, 1601)
    f, _, _ = prof.evaluate(ph)
    ax1.plot(ph * Tc * 1e3, np.full_like(ph, w * rpm), color="0.45", lw=1.5, label="constant")
    ax1.plot(ph * Tc * 1e3, f * w * rpm, color="C3", lw=1.5, label="optimised")
    for c in (0.0, 1.0):
        ax1.axvline(c * Tc * 1e3, color="k", lw=0.6, ls=":")
    L = spec.limits
    ax1.axhline(L.min_speed * w * rpm, color="C7", lw=0.6, ls="--")
    ax1.axhline(L.max_speed * w * rpm, color="C7", lw=0.6, ls="--", label="speed limits")
    ax1.set_xlabel("time from a slot meeting (transfers at the dotted lines) / ms")
    ax1.set_ylabel("horn-gear speed / rpm")
    ax1.legend(fontsize=7, frameon=False, ncol=3, loc="upper right")
    ax1.set_title(
        f"{spec.name}\nsame mean speed {w * rpm:.4g} rpm: "
        + ", ".join(
            f"{k.split('.')[0]} peak force {res.before.metrics[k]:.4g} -> "
            f"{res.after.metrics[k]:.4g} N ({-100 * res.reductions[k]:+.0f} %)"
            for k in ("track.peak_force", "slot.peak_force")
        )
        + "\n"
        + ", ".join(
            f"{metric_label(k)[0]} {res.before.metrics[k]:.4g} -> "
            f"{res.after.metrics[k]:.4g} {metric_label(k)[1]} ({-100 * res.reductions[k]:+.0f} %)"
            for k in ("impact_energy", "impacts")
        ),
        fontsize=8,
    )
    for optimised, colour, label in ((False, "0.45", "constant"), (True, "C3", "optimised")):
        r, t0, t1 = carrier_trace(res, optimised)
        s = r.series
        # the crossing and the bounces: at most 2.5 transfer cycles after the transfer
        t_end = min(t1, t0 + 2.5 * m.cycle_time)
        sel = (s["t"] >= t0 - 0.002) & (s["t"] <= t_end)
        ax2.plot((s["t"][sel] - t0) * 1e3, s["x"][sel] * 1e3, color=colour, lw=1.0, label=label)
        imp = r.impacts
        imp = imp[(imp["t"] >= t0) & (imp["t"] <= t_end) & (imp["pair"] == "track")]
        if len(imp):
            j = int(np.argmax(imp["peak_force"].to_numpy()))
            tt = float(imp["t"].iloc[j])
            ax2.annotate(
                f"{float(imp['peak_force'].iloc[j]):.0f} N",
                xy=((tt - t0) * 1e3, 0.0),
                xytext=((tt - t0) * 1e3, -0.45 if optimised else -0.25),
                fontsize=7,
                color=colour,
                ha="center",
                arrowprops={"arrowstyle": "-", "color": colour, "lw": 0.6},
            )
    ax2.axhline(0.0, color="k", lw=0.5)
    ax2.axhline(spec.machine.scenario["track.clearance"] * 1e3, color="k", lw=0.5)
    ax2.set_xlabel("time after the hardest transfer of the worst carrier / ms")
    ax2.set_ylabel("carrier x / mm")
    ax2.set_ylim(-0.6, spec.machine.scenario["track.clearance"] * 1e3 + 0.3)
    ax2.legend(fontsize=7, frameon=False, loc="upper right")
    ax2.set_title(
        "the carrier crosses the clearance and bounces on the inner wall (largest peak marked)",
        fontsize=8,
    )
    _ratio_axes(ax3, res)
    if res.drive is not None:
        tw = ax1.twinx()
        J = res.drive.inertia["total"]
        _, d1, _ = prof.evaluate(ph)
        tau = J * d1 * w / Tc + res.drive.drag_torque
        tw.plot(ph * Tc * 1e3, tau, color="C0", lw=0.9, ls="-.", label="drive torque")
        tw.set_ylabel("drive torque (dash-dot) / N m", color="C0")
        lim = res.spec.drive.max_torque
        tw.set_ylim(-lim, lim)
    _robust_axes(ax4, res)
    for ax in (ax1, ax2, ax3, ax4):
        ax.grid(True, lw=0.3, alpha=0.6)
    return fig


def _ratio_axes(ax: Any, res: DesignResult) -> None:
    """Optimised over constant speed for each figure of each pair (full machine runs)."""
    b, a = res.before.metrics, res.after.metrics
    figs = list(FIGURES)
    x = np.arange(len(figs))
    for j, (pair, colour) in enumerate((("track", "0.45"), ("slot", "C0"), ("both", "C3"))):
        keys = [k if pair == "both" else f"{pair}.{k}" for k in figs]
        r = [100.0 * (a[k] / b[k] - 1.0) if b[k] > 0 else math.nan for k in keys]
        ax.bar(x + (j - 1) * 0.27, r, 0.27, color=colour, label=pair)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xticks(x, ["largest peak force", "impact energy / s", "impacts / s", "noise proxy"])
    ax.set_ylabel("optimised vs constant / %")
    ax.legend(fontsize=7, frameon=False, ncol=3)
    ax.set_title(
        f"the full machine, {res.spec.machine.duration:g} s, both contact pairs (negative = "
        "fewer or softer impacts)",
        fontsize=8,
    )


def _robust_axes(ax: Any, res: DesignResult) -> None:
    """The improvement distributions over the held-out sets: the profile and every lever."""
    if res.robust is None:
        ax.text(0.5, 0.5, "no robustness check", ha="center", transform=ax.transAxes)
        return
    results = res.levers or []
    names = [lv.move.name for lv in results] or ["profile"]
    data = [100.0 * lv.improvement.values for lv in results] or [100.0 * res.robust.values]
    data = [d[np.isfinite(d)] for d in data]
    y = np.arange(len(names))[::-1]
    jitter = np.random.default_rng(0).uniform(-0.15, 0.15, max(len(d) for d in data))
    for yi, d, name in zip(y, data, names, strict=True):
        colour = "C3" if name == "profile" else "C0"
        ax.plot(d, yi + jitter[: d.size], "o", ms=2.5, color=colour, alpha=0.45)
        if d.size:
            p5, med, p95 = np.quantile(d, [0.05, 0.5, 0.95])
            ax.plot([p5, p95], [yi, yi], color="k", lw=1.2)
            ax.plot([med], [yi], "D", ms=6, color=colour, mec="k")
    ax.set_yticks(y, names)
    ax.set_ylim(-0.6, len(names) - 0.4)
    ax.axvline(0.0, color="k", lw=0.8)
    st = res.robust.stats()
    obj = res.spec.objective
    ax.set_xlabel(
        f"improvement of the {obj} ({res.spec.pair}) against constant speed / % (positive = better)"
    )
    ax.set_title(
        f"{st['samples']} held-out tolerance samples, {res.spec.robust.check_cycles:g} cycles "
        f"each (dots; diamond median, bar 5-95 %): profile median "
        f"{percent_se(st, 'median_improvement')}, "
        f"5th percentile {percent_se(st, 'p5_improvement')}",
        fontsize=8,
    )


def _transfer_scatter(ax: Any, res: DesignResult, column: str) -> None:
    for ev, colour, label in ((res.before, "0.45", "constant"), (res.after, "C3", "optimised")):
        if ev.run is None or not len(ev.run.transfers):
            continue
        tr = ev.run.transfers
        # a transfer due at the very end of the run (its time from the inverted rotation can
        # fall 1e-15 s short of it) has no interval: leave it out
        tr = tr[tr["t"] < ev.run.duration * (1.0 - 1e-12)]
        ax.plot(tr["t"], tr[column], "o", ms=3, color=colour, alpha=0.7, label=label)
        ax.axhline(float(tr[column].max()), color=colour, lw=0.6, ls="--")


def profile_figure(res: DesignResult) -> Figure:
    """Speed, acceleration and jerk over one cycle with the limits and the kernel's table."""
    from braidsim.plotting import new_figure

    spec = res.spec
    m = spec.machine
    prof = res.optimisation.profile
    Tc, w = m.cycle_time, m.mean_speed
    L = spec.limits
    ph = np.linspace(0.0, 1.0, 2001)
    f, d1, d2 = prof.evaluate(ph)
    tp, tf = (np.asarray(v) for v in prof.table())
    mean = float(np.sum(0.5 * (tf[1:] + tf[:-1]) * np.diff(tp)))
    fig = new_figure(7.0, 6.4)
    ax1, ax2, ax3 = fig.subplots(3, 1, sharex=True)
    ax1.plot(ph, f * w, color="C3", lw=1.4, label="optimised profile")
    ax1.plot(tp, tf / mean * w, ".", color="k", ms=2.5, label="kernel table nodes")
    ax1.axhline(w, color="0.45", lw=1.0, label="constant (the same mean)")
    ax1.axhline(L.min_speed * w, color="C7", lw=0.6, ls="--")
    ax1.axhline(L.max_speed * w, color="C7", lw=0.6, ls="--", label="limits")
    ax1.set_ylabel("omega / (rad/s)")
    ax1.legend(fontsize=7, frameon=False, ncol=2)
    ax2.plot(ph, d1 * w / Tc, color="C3", lw=1.2)
    for s in (-1, 1):
        ax2.axhline(s * L.max_acceleration, color="C7", lw=0.6, ls="--")
    ax2.set_ylabel("omega' / (rad/s$^2$)")
    ax3.plot(ph, d2 * w / Tc**2, color="C3", lw=1.2)
    for s in (-1, 1):
        ax3.axhline(s * L.max_jerk, color="C7", lw=0.6, ls="--")
    ax3.set_ylabel("omega'' / (rad/s$^3$)")
    ax3.set_xlabel(f"phase of the transfer cycle (T_c = {Tc * 1e3:.4g} ms; 0: slot meeting)")
    for ax in (ax1, ax2, ax3):
        ax.grid(True, lw=0.3, alpha=0.6)
    mg = res.optimisation.margins
    ax1.set_title(
        f"speed {mg['speed_min']:.3g}-{mg['speed_max']:.3g} x mean, "
        f"|omega'| <= {mg['acceleration_max']:.4g} rad/s^2, "
        f"|omega''| <= {mg['jerk_max']:.3g} rad/s^3",
        fontsize=8,
    )
    return fig


def transfers_figure(res: DesignResult) -> Figure:
    """Peak force and impacts of every transfer, before and after."""
    from braidsim.plotting import new_figure

    fig = new_figure(7.0, 5.0)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    _transfer_scatter(ax1, res, "peak_force")
    _transfer_scatter(ax2, res, "impacts")
    ax1.set_ylabel("peak force / N")
    ax2.set_ylabel("impacts per transfer")
    ax2.set_xlabel("transfer time / s")
    ax1.set_ylim(bottom=0.0)
    ax1.legend(fontsize=7, frameon=False, loc="lower right")
    for ax in (ax1, ax2):
        ax.grid(True, lw=0.3, alpha=0.6)
    ax1.set_title("every transfer of every carrier (dashed: the largest)", fontsize=9)
    return fig


def sensitivity_figure(res: DesignResult) -> Figure:
    """One-at-a-time swings (relative change of the objective at each end of each lever's
    range) and Morris mu* with sigma."""
    from braidsim.plotting import new_figure

    obj = res.spec.figure
    fig = new_figure(8.0, 4.6)
    ax1, ax2 = fig.subplots(1, 2)
    mor = res.morris
    if mor is None or not res.oat:
        ax1.text(0.5, 0.5, "no sensitivity study", ha="center", transform=ax1.transAxes)
        return fig
    order = list(reversed(mor.ranking))
    levers = {lv.key: lv for lv in mor.levers}
    y = np.arange(len(order))
    h = 0.38 if len(res.oat) > 1 else 0.6
    for j, (oat, colour) in enumerate(zip(res.oat, ("0.45", "C3"), strict=False)):
        nom = oat.nominal[obj]
        sw = oat.swing(obj)
        off = (j - 0.5 * (len(res.oat) - 1)) * h
        lo = np.array([100.0 * (sw[k][0] / nom - 1.0) for k in order])
        hi = np.array([100.0 * (sw[k][1] / nom - 1.0) for k in order])
        # the longer bar first, so that a shorter one on the same side stays visible on top
        for i in range(len(order)):
            pair = [(lo[i], 0.4, "low end"), (hi[i], 0.95, "high end")]
            pair.sort(key=lambda b: -abs(b[0]))
            for v, alpha, what in pair:
                ax1.barh(
                    y[i] + off,
                    v,
                    height=h,
                    color=colour,
                    alpha=alpha,
                    edgecolor="k",
                    lw=0.3,
                    label=f"{oat.profile}: {what}" if i == 0 else None,
                )
    ax1.axvline(0.0, color="k", lw=0.6)
    ax1.set_yticks(y, [levers[k].label for k in order], fontsize=7)
    ax1.set_xlabel(f"change of the {metric_label(obj)[0]} / %")
    ax1.legend(fontsize=6, frameon=False)
    ax1.set_title("one lever at a time, to each end of its range", fontsize=8)
    idx = [mor.levers.index(levers[k]) for k in order]
    ax2.barh(y, mor.mu_star[idx], color="C0", alpha=0.8, xerr=mor.sigma[idx], capsize=2)
    ax2.set_yticks(y, [""] * len(y))
    ax2.set_xlabel(f"Morris mu* / {metric_label(obj)[1]} (bars: sigma)")
    ax2.set_title(
        f"elementary effects over each range ({mor.trajectories} trajectories, seed {mor.seed})",
        fontsize=8,
    )
    for ax in (ax1, ax2):
        ax.grid(True, axis="x", lw=0.3, alpha=0.6)
    return fig


def speed_limits_figure(res: DesignResult) -> Figure:
    """For each lever: the transfer speed limit (simulated and closed form) and the chatter
    speed against the lever's value; the nominal speed and setting marked."""
    from braidsim.plotting import new_figure

    n = len(res.speed_limits)
    cols = 3
    rows = max(1, math.ceil(n / cols))
    fig = new_figure(9.0, 2.7 * rows + 0.4)
    axes = np.atleast_1d(fig.subplots(rows, cols)).reshape(-1)
    rpm = 30.0 / math.pi
    w = res.spec.machine.mean_speed
    for ax, ll in zip(axes, res.speed_limits, strict=False):
        x = np.array([ll.lever.display(v) for v in ll.values])
        lim = np.array([s.speed for s in ll.limits]) * rpm
        ax.plot(x, lim, "o-", color="C3", ms=3, label="transfer limit (simulated)")
        for xi, s in zip(x, ll.limits, strict=True):
            if s.status == "above_range":
                ax.plot([xi], [s.bracket[0] * rpm], "^", color="C3", ms=5)
            elif s.status == "below_range":
                ax.plot([xi], [s.bracket[1] * rpm], "v", color="C3", ms=5)
        cv = np.array([ll.lever.display(v) for v in ll.curve.get("values", ll.values)])
        est = np.array(ll.curve.get("estimate", ll.estimates))
        chat = np.array(ll.curve.get("chatter", ll.chatter))
        if np.any(np.isfinite(est)):
            ax.plot(cv, est * rpm, "--", color="C1", lw=1.0, label="closed form (first impact)")
        ax.plot(cv, chat * rpm, "-", color="C0", lw=1.2, label="chatter below (closed form)")
        ax.axhline(w * rpm, color="0.45", lw=0.6, ls=":")
        ax.axvline(ll.lever.display(ll.lever.nominal), color="0.45", lw=0.6, ls=":")
        ax.set_xlabel(ll.lever.label, fontsize=8)
        ax.set_ylabel("horn-gear speed / rpm", fontsize=8)
        ax.set_ylim(bottom=0.0)
        ax.grid(True, lw=0.3, alpha=0.6)
        ax.tick_params(labelsize=7)
    for ax in axes[n:]:
        ax.set_visible(False)
    if n:
        axes[0].legend(fontsize=6, frameon=False)
    metric = res.spec.speed_limit.metric
    fig.suptitle(
        f"constant-speed limits: {metric_label(metric)[0]} <= {res.threshold:.4g} "
        f"{metric_label(metric)[1]} (triangles: not reached in the scanned range)",
        fontsize=9,
    )
    return fig


def convergence_figure(res: DesignResult) -> Figure:
    """Best proxy objective per generation."""
    from braidsim.plotting import new_figure

    opt = res.optimisation
    fig = new_figure(6.0, 3.2)
    ax = fig.subplots()
    if opt.history:
        ev = [h["evaluations"] for h in opt.history]
        ax.plot(ev, [h["best"] for h in opt.history], "o-", ms=3, color="C3")
    ax.axhline(opt.baseline_value, color="0.45", lw=0.8, ls="--", label="constant speed")
    ax.set_xlabel("simulated candidates")
    ax.set_ylabel(f"best robust {opt.objective} ({opt.pair}) / constant speed")
    ax.legend(fontsize=7, frameon=False)
    ax.grid(True, lw=0.3, alpha=0.6)
    ax.set_title(
        f"differential evolution, seed {opt.options.seed} ({opt.options.cycles:g}-cycle runs "
        "on the optimiser's parameter sets)",
        fontsize=9,
    )
    return fig


# ----------------------------------------------------------------------------------------
# tables and the optimised machine spec
# ----------------------------------------------------------------------------------------


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(float(v)) if isinstance(v, float) else str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} as TOML")


def to_toml(table: dict[str, Any], prefix: str = "") -> str:
    """A minimal TOML writer for spec tables (scalars, lists, nested tables)."""
    lines = []
    subs = []
    for k, v in table.items():
        key = k if k.replace("_", "").replace("-", "").isalnum() else json.dumps(k)
        if isinstance(v, dict):
            subs.append((key, v))
        else:
            lines.append(f"{key} = {_toml_value(v)}")
    out = "\n".join(lines)
    for key, v in subs:
        name = f"{prefix}.{key}" if prefix else key
        out = out.rstrip("\n") + f"\n\n[{name}]\n" + to_toml(v, name)
    return out.strip("\n") + "\n"


def optimised_machine_toml(res: DesignResult) -> str:
    """The machine spec with the optimised profile, runnable with ``braidsim machine``."""
    import copy

    from braidsim.params import builtin_names

    spec = res.spec
    t = copy.deepcopy(spec.machine_table)
    ref = t.get("scenario")
    if isinstance(ref, str) and ref not in builtin_names() and spec.machine_path is not None:
        p = spec.machine_path.parent / ref
        if p.is_file():
            t["scenario"] = str(p.resolve())
    ph, fa = res.optimisation.profile.table()
    mt = dict(t.get("machine", {}))
    if not res.optimisation.profile.is_constant:
        mt["speed_profile"] = {"phase": ph, "factor": fa}
    t["machine"] = mt
    # the design runs the two-DOF model (track and slot contacts)
    t["overrides"] = {**dict(t.get("overrides", {})), "simulation.dof": "xy"}
    red = res.reductions
    head = (
        f"# {spec.name}: the machine with the optimised horn-gear speed profile\n"
        f"# (braidsim design; objective {spec.objective} of {spec.pair}).\n"
        "# Run: braidsim machine THIS.toml --out DIR\n"
        f"# Full-machine result against constant speed at the same mean speed: track peak "
        f"force {-100 * red['track.peak_force']:+.1f} %, slot peak force "
        f"{-100 * red['slot.peak_force']:+.1f} %, impact energy of both contacts "
        f"{-100 * red['impact_energy']:+.1f} %.\n"
    )
    return head + to_toml(t)


def profile_csv(res: DesignResult) -> str:
    m = res.spec.machine
    prof = res.optimisation.profile
    ph, fa = (np.asarray(v) for v in prof.table())
    mean = float(np.sum(0.5 * (fa[1:] + fa[:-1]) * np.diff(ph)))
    _, d1, d2 = prof.evaluate(ph)
    lines = ["phase,time_s,factor,omega_rad_s,omega_dot_rad_s2,omega_ddot_rad_s3"]
    for i in range(ph.size):
        lines.append(
            f"{ph[i]:.10g},{ph[i] * m.cycle_time:.10g},{fa[i] / mean:.10g},"
            f"{fa[i] / mean * m.mean_speed:.10g},{d1[i] * m.mean_speed / m.cycle_time:.10g},"
            f"{d2[i] * m.mean_speed / m.cycle_time**2:.10g}"
        )
    return "\n".join(lines) + "\n"


def sensitivity_csv(res: DesignResult) -> str:
    lines = ["profile,lever,value," + ",".join(METRIC_KEYS)]
    for oat in res.oat:
        lines.append(
            f"{oat.profile},nominal,," + ",".join(f"{oat.nominal[k]:.10g}" for k in METRIC_KEYS)
        )
        for lv in oat.levers:
            for v, row in zip(oat.values[lv.key], oat.metrics[lv.key], strict=True):
                lines.append(
                    f"{oat.profile},{lv.key},{v:.10g},"
                    + ",".join(f"{row[k]:.10g}" for k in METRIC_KEYS)
                )
    return "\n".join(lines) + "\n"


def speed_limits_csv(res: DesignResult) -> str:
    lines = ["lever,value,transfer_limit_rad_s,status,closed_form_rad_s,chatter_speed_rad_s"]
    for ll in res.speed_limits:
        for v, s, e, c in zip(ll.values, ll.limits, ll.estimates, ll.chatter, strict=True):
            lines.append(f"{ll.lever.key},{v:.10g},{s.speed:.10g},{s.status},{e:.10g},{c:.10g}")
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------
# Markdown
# ----------------------------------------------------------------------------------------


def _f(v: Any, digits: int = 4) -> str:
    if isinstance(v, float | np.floating):
        return f"{float(v):.{digits}g}" if math.isfinite(v) else "n/a"
    return str(v)


def _table(rows: list[list[Any]], head: list[str]) -> str:
    out = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    out += ["| " + " | ".join(_f(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def robustness(res: DesignResult) -> list[dict[str, Any]]:
    """Lever settings of the one-at-a-time study at which the optimised profile does not beat
    constant speed (it is tuned to the nominal parameters)."""
    if len(res.oat) < 2:
        return []
    const, opt = res.oat[0], res.oat[1]
    obj = res.spec.figure
    out = []
    for lv in opt.levers:
        for v, a, b in zip(
            opt.values[lv.key], const.metrics[lv.key], opt.metrics[lv.key], strict=True
        ):
            if not b[obj] < a[obj]:
                out.append({"lever": lv.key, "value": v, "constant": a[obj], "optimised": b[obj]})
    return out


def _robustness(res: DesignResult) -> list[str]:
    if len(res.oat) < 2:
        return []
    bad = robustness(res)
    unit = metric_label(res.spec.figure)[1]
    if not bad:
        return [
            "At every setting of the one-at-a-time study the optimised profile (tuned at the "
            "nominal parameters) stays below constant speed.",
            "",
        ]
    levers = {lv.key: lv for lv in res.oat[1].levers}
    items = [
        f"{levers[b['lever']].label} = {levers[b['lever']].display(b['value']):.4g} "
        f"({b['optimised']:.4g} against {b['constant']:.4g} {unit})"
        for b in bad
    ]
    return [
        "The optimised profile is tuned to the nominal parameters: it times the speed-up to the "
        "first impact, which moves when the clearance, the mass or the load change. At these "
        "settings it does no better than constant speed: " + "; ".join(items) + ". Re-optimise "
        "for the machine as built.",
        "",
    ]


def _drive_lines(res: DesignResult) -> list[str]:
    dm = res.drive
    if dm is None:
        return []
    d0, d1 = res.drive_before, res.drive_after
    D = dm.drive
    J = dm.inertia
    rows = [
        ["peak torque", "N m", d0["peak_torque"], d1["peak_torque"], D.max_torque],
        ["RMS torque", "N m", d0["rms_torque"], d1["rms_torque"], D.max_rms_torque],
        ["peak power (motoring)", "W", d0["peak_power"], d1["peak_power"], D.max_power],
        [
            "peak regenerated power",
            "W",
            d0["peak_regenerated_power"],
            d1["peak_regenerated_power"],
            "",
        ],
        ["mean power", "W", d0["mean_power"], d1["mean_power"], ""],
        [
            "largest |omega'|",
            "rad/s^2",
            d0["max_acceleration"],
            d1["max_acceleration"],
            res.spec.limits.max_acceleration,
        ],
        ["largest |omega''|", "rad/s^3", d0["max_jerk"], d1["max_jerk"], res.spec.limits.max_jerk],
        [
            "yarn-tension swing (bound)",
            "N",
            d0["yarn_tension_swing"],
            d1["yarn_tension_swing"],
            "",
        ],
    ]
    return [
        "## The drive",
        "",
        f"Inertia on the horn-gear speed {J['total']:.4g} kg m^2: horn gears {J['gears']:.4g}, "
        f"carriers {J['carriers']:.4g}, motor rotor through the gearbox {J['motor']:.4g}; "
        f"drag {dm.drag_torque:.3g} N m (the carriers' friction and contact losses at "
        "constant speed). Torque tau = J omega' + drag, power tau omega, over one transfer "
        "cycle; the limits are constraints of the optimiser.",
        "",
        _table(rows, ["quantity", "unit", "constant speed", "optimised", "limit"]),
        "",
    ]


def _robust_lines(res: DesignResult) -> list[str]:
    R = res.spec.robust
    out = ["## Robustness: the improvement over tolerance samples", ""]
    tol = ", ".join(
        f"{t.key} x [{t.low:g}, {t.high:g}]" if t.relative else f"{t.key} [{t.low:g}, {t.high:g}]"
        for t in R.tolerances
    )
    opt = res.optimisation
    n_opt = R.samples if R.samples > 0 else 1
    stat = "mean" if R.statistic == "mean" else f"{R.quantile:g}-quantile"
    out += [
        f"Uniform tolerances (Latin hypercube): {tol}. The optimiser minimised the {stat} of "
        f"J(profile)/J(constant) over {n_opt} parameter sets (seed {R.seed}, "
        f"{opt.options.cycles:g}-cycle runs): {opt.value:.4g}.",
        "",
    ]
    if res.robust is not None:
        st = res.robust.stats()
        out += [
            f"Improvement 1 - J(profile)/J(constant) measured on {st['samples']} *other* "
            f"parameter sets (seed {R.held_out_seed}, {R.check_cycles:g}-cycle runs, every set "
            f"against constant speed on the same machine): median "
            f"{percent_se(st, 'median_improvement')}, 5th percentile "
            f"{percent_se(st, 'p5_improvement')} (+- a bootstrap standard error: what "
            f"another draw of {st['samples']} sets would move it by), 95th percentile "
            f"{100 * st.get('p95_improvement', math.nan):+.1f} %, better than constant speed "
            f"on {100 * st.get('fraction_better', math.nan):.0f} % of the sets.",
            "",
        ]
    if res.levers:
        rows = []
        for i, lv in enumerate(res.levers, 1):
            d = lv.to_dict()
            rows.append(
                [
                    i,
                    d["name"],
                    d["description"],
                    percent_se(d, "median_improvement"),
                    percent_se(d, "p5_improvement"),
                    d["effort"],
                    d["improvement_per_effort"],
                ]
            )
        out += [
            "### The levers on the same footing",
            "",
            "Each change of the machine on the same held-out sets, against the unchanged "
            "machine at constant speed (improvement of the same objective). The effort "
            "(1 = a setting, 5 = a redesign) is an assumption of the study, not a model "
            "result; the reasons are in `summary.json` (`levers`).",
            "",
            _table(
                rows,
                ["rank", "lever", "change", "median", "5th pct", "effort", "median / effort"],
            ),
            "",
        ]
    return out


def markdown(res: DesignResult, data: dict[str, Any], figures: list[str]) -> str:
    """The report as Markdown."""
    spec = res.spec
    m = spec.machine
    opt = res.optimisation
    rpm = 30.0 / math.pi
    b, a, red = res.before.metrics, res.after.metrics, res.reductions
    lines = [f"# {spec.name}", ""]
    if spec.description:
        lines += [spec.description, ""]
    lines += [
        f"Machine: {m.name}; {m.geometry.N} horn gears, {m.geometry.S} slots, "
        f"{len(m.loading.carriers)} carriers, scenario `{m.scenario.name}`, mean horn-gear "
        f"speed {m.mean_speed * rpm:.4g} rpm, transfer cycle {m.cycle_time * 1e3:.4g} ms. "
        f"Objective: **{OBJECTIVES[spec.objective][0]}**, contact pairs: **{spec.pair}**, "
        "as a ratio to constant speed on the same machine.",
        "",
        "## Result: constant speed against the optimised profile (full machine)",
        "",
        f"Every carrier simulated for {m.duration:.4g} s with each speed law; the mean speed, "
        "hence the production rate, is the same.",
        "",
    ]
    rows = []
    for pair in ("track", "slot", "both"):
        for k in FIGURES:
            key = k if pair == "both" else f"{pair}.{k}"
            name = FIGURES[k][0] if k != "noise" else "noise proxy (sum F_peak^2 per s)"
            rows.append(
                [
                    "both pairs" if pair == "both" else pair,
                    name,
                    FIGURES[k][1],
                    b[key],
                    a[key],
                    f"{-100 * red[key]:+.1f} %",
                ]
            )
    rows.append(
        [
            "both pairs",
            "noise proxy level",
            "dB re 1 N^2/s",
            noise_level(b["noise"]),
            noise_level(a["noise"]),
            f"{noise_level(a['noise']) - noise_level(b['noise']):+.2f} dB",
        ]
    )
    rows.append(
        [
            "track",
            "power dissipated in the contacts",
            "W",
            b["dissipated_power"],
            a["dissipated_power"],
            f"{-100 * (1 - a['dissipated_power'] / b['dissipated_power']):+.1f} %",
        ]
    )
    lines += [
        _table(rows, ["pair", "quantity", "unit", "constant speed", "optimised", "change"]),
        "",
    ]
    lines += _drive_lines(res)
    lines += _robust_lines(res)
    p = res.production
    lines += [
        "Production rate: mean horn-gear speed measured from the gear rotation of each run "
        f"{p['before_mean_speed_rpm']:.6g} rpm (constant) and {p['after_mean_speed_rpm']:.6g} "
        f"rpm (optimised); transfers per second {p['before_transfers_per_second']:.6g} and "
        f"{p['after_transfers_per_second']:.6g}.",
        "",
    ]
    kin = data["production"]["kinematics"]
    if "braid" in kin:
        br = kin["braid"]
        lines += [
            f"With the spec's mandrel ({br['mandrel_radius'] * 1e3:.4g} mm) and braid angle "
            f"({br['braid_angle_deg']:.4g} deg) the take-up speed is "
            f"{br['take_up_speed'] * 1e3:.4g} mm/s ({br['production_rate_m_per_h']:.4g} m/h), "
            "unchanged by the profile.",
            "",
        ]
    prof = opt.profile
    mg = opt.margins
    L = spec.limits
    lines += ["## The optimised profile", ""]
    pr = prof.params
    if prof.is_constant:
        # the optimiser keeps constant speed exactly when no feasible candidate beat it; a
        # plateau "at 1 x the mean" with ramps would describe a dip that is not there
        lines += [
            f"Family `{prof.family}`: the result is **constant speed** (the mean speed over "
            "the whole cycle, no dip): no candidate within the limits did better than "
            "constant speed on the proxy objective, so constant speed is kept exactly.",
            "",
        ]
    elif prof.has_dip and pr["level"] == 1.0:
        lines += [
            f"Family `{prof.family}`: no dip (its plateau is at the mean speed); the "
            "harmonics below shape the speed.",
            "",
        ]
    elif prof.has_dip:
        lines += [
            f"Family `{prof.family}`. Slow plateau at {pr['level']:.4g} x the mean speed "
            f"({pr['level'] * m.mean_speed * rpm:.4g} rpm) from phase {pr['start']:+.4g} of the "
            f"cycle ({pr['start'] * m.cycle_time * 1e3:+.3g} ms from the slot meeting) for "
            f"{pr['length']:.4g} of the cycle ({pr['length'] * m.cycle_time * 1e3:.3g} ms); ramp "
            f"down over {pr['ramp_down'] * m.cycle_time * 1e3:.3g} ms, up over "
            f"{pr['ramp_up'] * m.cycle_time * 1e3:.3g} ms; fast level {prof.fast_level():.4g} x "
            f"the mean ({prof.fast_level() * m.mean_speed * rpm:.4g} rpm).",
            "",
        ]
    harm = {k: v for k, v in pr.items() if k[0] in "ab" and k[1:].isdigit()}
    if harm:
        lines += ["Harmonics: " + ", ".join(f"{k} = {v:.4g}" for k, v in harm.items()), ""]
    lines += [
        _table(
            [
                ["lowest speed", "fraction of mean", mg["speed_min"], L.min_speed, mg["min_speed"]],
                [
                    "highest speed",
                    "fraction of mean",
                    mg["speed_max"],
                    L.max_speed,
                    mg["max_speed"],
                ],
                [
                    "largest angular acceleration",
                    "rad/s^2",
                    mg["acceleration_max"],
                    L.max_acceleration,
                    mg["acceleration"],
                ],
                ["largest angular jerk", "rad/s^3", mg["jerk_max"], L.max_jerk, mg["jerk"]],
                ["dip fits in the cycle", "cycles", 1.0 - mg["fit"], 1.0, mg["fit"]],
            ],
            ["constraint", "unit", "profile", "limit", "margin"],
        ),
        "",
        f"The kernel follows a piecewise-linear table of {len(prof.table()[0])} nodes "
        "(`optimised_profile.csv`, and `[machine.speed_profile]` in `optimised_machine.toml`, "
        "which `braidsim machine` runs); it is rescaled to an exact mean of 1 and differs from "
        f"the smooth profile by at most {100 * prof.table_error():.3g} % of the mean speed.",
        "",
        "## Optimisation",
        "",
        f"`scipy.optimize.differential_evolution`, {opt.evaluations} simulated candidates in "
        f"{opt.elapsed:.4g} s (seed {opt.options.seed}, maxiter {opt.options.maxiter}, popsize "
        f"{opt.options.popsize}; {opt.message}). Each candidate: the machine over "
        f"{opt.options.cycles:g} transfer cycles, one carrier per class of identical carriers "
        f"(exact: the {len(m.loading.carriers)} carriers run as {len(res.classes)}, "
        "weighted by class size). Proxy objective: constant "
        f"{opt.baseline_value:.5g}, optimised {opt.value:.5g} "
        f"({-100 * (1 - opt.value / opt.baseline_value):+.1f} %).",
        "",
    ]
    recent, gain = opt.recent_gain()
    if opt.still_improving():
        lines += [
            f"The search stopped at its iteration cap still improving: its best proxy value "
            f"fell by {100 * gain:.2g} % over the last {recent} of its {len(opt.history)} "
            "generations, so a larger `design.optimizer.maxiter` (or other seeds) may find a "
            "better profile; this one is the best found within the budget, not an optimum.",
            "",
        ]
    elif recent > 0:
        lines += [
            f"The best proxy value did not change over the last {recent} of the "
            f"{len(opt.history)} generations.",
            "",
        ]
    if res.fidelity is not None:
        fd = res.fidelity
        lines += [
            f"Proxy check ({fd.proxy.shape[0]} random profiles within the limits, proxy "
            f"against the full run):",
            "",
            _table(
                [
                    [metric_label(k)[0], fd.rank_correlation[k], fd.median_relative_error[k]]
                    for k in METRIC_KEYS
                ],
                ["objective", "Spearman rank correlation", "median relative difference"],
            ),
            "",
        ]
    if res.morris is not None:
        mor = res.morris
        # a sensitivity study of the machine's parameters, not the levers compared above
        lines += ["## Sensitivity to the machine's parameters", ""]
        nominal = {o.profile: o.nominal[spec.figure] for o in res.oat}
        lines += [
            f"Ranked by Morris mu* (mean |elementary effect| over each lever's range, "
            f"{mor.trajectories} trajectories, {mor.levels} levels, seed {mor.seed}, "
            f"{mor.values.size} runs at constant speed), with the one-at-a-time change of the "
            f"{metric_label(spec.figure)[0]} at each end of the range "
            f"(nominal: {', '.join(f'{k} {v:.5g}' for k, v in nominal.items())} "
            f"{metric_label(spec.figure)[1]}).",
            "",
        ]
        rows = []
        levers = {lv.key: lv for lv in mor.levers}
        for rank, key in enumerate(mor.ranking, 1):
            i = mor.levers.index(levers[key])
            lv = levers[key]
            row: list[Any] = [
                rank,
                lv.label,
                f"{lv.display(lv.low):.4g} .. {lv.display(lv.high):.4g}",
                mor.mu_star[i],
                mor.sigma[i],
            ]
            for o in res.oat:
                lo, hi = o.swing(spec.figure)[key]
                nom = o.nominal[spec.figure]
                row.append(f"{100 * (lo / nom - 1):+.1f} % / {100 * (hi / nom - 1):+.1f} %")
            rows.append(row)
        lines += [
            _table(
                rows,
                ["rank", "lever", "range", "mu*", "sigma"]
                + [f"low / high end ({o.profile})" for o in res.oat],
            ),
            "",
        ]
        lines += _robustness(res)
    if res.speed_limits:
        metric = spec.speed_limit.metric
        nl = res.nominal_speed_limit
        lines += [
            "## Speed limits",
            "",
            f"Transfer limit: the largest constant horn-gear speed at which the "
            f"{metric_label(metric)[0]} stays <= {res.threshold:.5g} {metric_label(metric)[1]} "
            f"(scan of {spec.speed_limit.options.points} speeds from "
            f"{spec.speed_limit.options.low:g} to {spec.speed_limit.options.high:g} x the mean, "
            f"then {spec.speed_limit.options.refine} bisections). Chatter speed: below it the "
            "track vibration lifts the resting carrier off the wall between transfers, "
            "sqrt(max(0, h_a omega_h^2 - T1 cos(phi)/m) / r_c) (docs/model.md §7). "
            + (
                f"Nominal setting: {nl.speed * rpm:.4g} rpm ({nl.status})."
                if nl is not None and nl.status == "found"
                else ""
            ),
            "",
        ]
        rows = []
        for ll in res.speed_limits:
            for v, s, e, c in zip(ll.values, ll.limits, ll.estimates, ll.chatter, strict=True):
                rows.append(
                    [
                        ll.lever.label,
                        ll.lever.display(v),
                        s.speed * rpm if s.status == "found" else s.status,
                        e * rpm,
                        c * rpm,
                    ]
                )
        lines += [
            _table(
                rows,
                ["lever", "value", "transfer limit / rpm", "closed form / rpm", "chatter / rpm"],
            ),
            "",
        ]
    lines += ["## Figures", ""]
    lines += [f"![{FIGURE_ALT.get(f, f)}]({f})" for f in figures]
    lines += [
        "",
        "## What the study assumes",
        "",
        "- The horn-gear speed repeats every transfer cycle (all gears turn together and every "
        "slot meeting is a transfer of some carrier); its mean is held exactly, so transfers "
        "stay at the slot meetings and the production rate is unchanged.",
        "- Every carrier runs the two-DOF model: it moves radially in the track (the track "
        "contact) and along its path in the horn-gear slot (the slot contact), so the "
        "tangential inertia m r_c omega' of a profile acts on the slot walls and is in the "
        "objective.",
        "- The drive's inertia, torque and power are those of the drive model (defaults are "
        "engineering estimates stated in `braidsim.design.drive`); gear-train losses are not "
        "modelled. The yarn-tension swing is a bound from the tensioner's inertia; the contact "
        "model holds the yarn tension constant.",
        "- The search is global (differential evolution) only; a local refinement by exact "
        "sensitivities of the runs is not available yet.",
        "- Every carrier is the paper's carrier model with the section 3.2 transfer map; see the "
        "machine report for its other assumptions.",
        "",
    ]
    return "\n".join(lines)


def write_report(res: DesignResult, out: str | Path) -> dict[str, Any]:
    """Write the report directory ``out`` (whole or not at all); return the summary."""
    from braidsim.io import json_safe
    from braidsim.plotting import save

    figures: list[str] = []
    files: list[str] = []
    with atomic_directory(out, REPORT_KIND) as tmp:
        for name, make in (
            ("design_summary.png", main_figure),
            ("profile.png", profile_figure),
            ("peak_force_per_transfer.png", transfers_figure),
            ("sensitivity.png", sensitivity_figure),
            ("speed_limits.png", speed_limits_figure),
            ("convergence.png", convergence_figure),
        ):
            if name == "sensitivity.png" and res.morris is None:
                continue
            if name == "speed_limits.png" and not res.speed_limits:
                continue
            save(make(res), tmp / name)
            figures.append(name)
        atomic_write_text(tmp / "optimised_profile.csv", profile_csv(res))
        atomic_write_text(tmp / "optimised_machine.toml", optimised_machine_toml(res))
        files += ["optimised_profile.csv", "optimised_machine.toml"]
        for name, ev in (("transfers_before.csv", res.before), ("transfers_after.csv", res.after)):
            if ev.run is not None:
                atomic_write_text(tmp / name, ev.run.transfers.to_csv(index=False))
                files.append(name)
        if res.oat:
            atomic_write_text(tmp / "sensitivity.csv", sensitivity_csv(res))
            files.append("sensitivity.csv")
        if res.speed_limits:
            atomic_write_text(tmp / "speed_limits.csv", speed_limits_csv(res))
            files.append("speed_limits.csv")
        files = figures + files + ["report.md", "summary.json"]
        data = summary(res, files)
        atomic_write_text(tmp / "report.md", markdown(res, data, figures))
        atomic_write_text(
            tmp / "summary.json", json.dumps(json_safe(data), indent=1, allow_nan=False) + "\n"
        )
    data["out"] = str(out)
    return data
