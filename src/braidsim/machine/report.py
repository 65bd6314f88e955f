"""The machine report: summary (JSON), tables (CSV, Markdown), figures and the animation.

:func:`write_report` builds the whole output directory under a temporary name and renames it
into place (:func:`braidsim.io.atomic_directory`), so a report is complete or absent:

=============================  ==============================================================
``summary.json``               geometry, kinematics, loading, run, totals, per-carrier rows
``report.md``                  the same as tables, with the figures
``carriers.csv``               one row per carrier
``transfers.csv``              one row per transfer
``impacts.csv``                one row per track impact
``peak_force_per_transfer.png`` peak force and impacts of every transfer against time
``carrier_distribution.png``   peak force per transfer and impact rates, carrier by carrier
``machine_layout.png``         the machine at t = 0, carriers labelled
``machine.gif``                the animation (when enabled)
``machine_frame.png``          the frame of the animation with the largest forces
=============================  ==============================================================
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.io import atomic_directory, json_safe
from braidsim.machine.geometry import braid_pattern
from braidsim.machine.kinematics import (
    braid_angle,
    carrier_angular_speed,
    revolution_time,
    take_up_speed,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from braidsim.machine.run import MachineRun
    from braidsim.machine.spec import MachineSpec

REPORT_KIND = "machine report"


def geometry_summary(spec: MachineSpec) -> dict[str, Any]:
    """Gears, arcs, lanes and the transfer cycle (SI units, angles in rad)."""
    g = spec.geometry
    q = g.quantum
    cyc = g.transfer_cycle
    phases = [p / cyc for p in g.transfer_phases]
    return {
        "horn_gears": g.N,
        "slots": g.S,
        "pitch_radius": g.pitch_radius,
        "ring_radius": g.ring_radius,
        "crossing_radius": g.ring_radius * math.cos(math.pi / g.N),
        "inner_arc_angle": g.inner_arc * q,
        "outer_arc_angle": g.outer_arc * q,
        "path_length": g.pitch_radius * g.path_period * q,
        "lanes_per_path": g.lanes,
        "max_carriers_per_group": g.max_per_group,
        "transfer_cycle_angle": cyc * q,
        "transfer_phases": phases,
    }


def kinematics_summary(spec: MachineSpec) -> dict[str, Any]:
    """Speeds, revolution and transfer rates, braid angle and production rate."""
    g = spec.geometry
    w = spec.mean_speed
    wc = carrier_angular_speed(w, g.N)
    out: dict[str, Any] = {
        "mean_speed": w,
        "mean_speed_rpm": w * 60.0 / (2.0 * math.pi),
        "carrier_angular_speed": wc,
        "carrier_revolutions_per_minute": wc * 60.0 / (2.0 * math.pi),
        "revolution_time": revolution_time(w, g.N),
        "carrier_path_speed": g.pitch_radius * w,
        "inner_arc_time": g.inner_arc * g.quantum / w,
        "outer_arc_time": g.outer_arc * g.quantum / w,
        "transfer_cycle_time": spec.cycle_time,
        "transfers_per_carrier_per_second": g.N / revolution_time(w, g.N),
    }
    if spec.speed_profile is not None:
        table = spec.scenario["horn_gear.speed_profile"]
        out["speed_profile"] = {
            **spec.speed_profile,
            "scale": spec.profile_scale,
            "times": list(table[0]),
            "speeds": list(table[1]),
        }
    b = spec.braid
    if b is not None:
        if b.take_up_speed is not None:
            v = b.take_up_speed
            alpha = braid_angle(wc, b.mandrel_radius, v)
        else:
            alpha = float(b.braid_angle)  # type: ignore[arg-type]
            v = take_up_speed(wc, b.mandrel_radius, alpha)
        out["braid"] = {
            "mandrel_radius": b.mandrel_radius,
            "braid_angle": alpha,
            "braid_angle_deg": math.degrees(alpha),
            "take_up_speed": v,
            "production_rate_m_per_h": v * 3600.0,
            "lead_per_revolution": 2.0 * math.pi * b.mandrel_radius / math.tan(alpha),
        }
    return out


def summary(run: MachineRun, files: list[str] | None = None) -> dict[str, Any]:
    """The JSON object of ``braidsim machine --json`` (SI units)."""
    from braidsim.provenance import utc_now, version

    spec = run.spec
    sc = spec.scenario
    return {
        "braidsim_version": version(),
        "created": utc_now(),
        "name": spec.name,
        "description": spec.description,
        "spec": str(spec.path) if spec.path else None,
        "scenario": sc.name,
        "geometry": geometry_summary(spec),
        "kinematics": kinematics_summary(spec),
        "loading": {
            "pattern": spec.loading.name,
            "title": spec.loading.title,
            "braid_pattern": braid_pattern(spec.geometry, spec.loading),
            "carriers_per_group": [len(spec.loading.lanes_a), len(spec.loading.lanes_b)],
            "lanes_a": list(spec.loading.lanes_a),
            "lanes_b": list(spec.loading.lanes_b),
            "collision_free": True,
        },
        "run": {
            "duration": run.duration,
            "start": spec.start,
            "carriers": len(run.plans),
            "transfers": int(sum(p.times.size for p in run.plans)),
            "integration_steps": run.steps,
            "elapsed_s": run.elapsed,
            "workers": run.workers,
            "engine": "compiled core (braidsim.simulate.run_model) per carrier, "
            + ("in one process" if run.workers == 1 else f"over {run.workers} local processes"),
            "track_vibration_amplitude": sc["track.vibration_amplitude"],
            "transfer_contact_speed": sc["transfer.contact_speed"],
        },
        "totals": run.totals,
        "carriers": run.carriers.to_dict(orient="records"),
        "files": files or [],
    }


# ----------------------------------------------------------------------------------------
# figures
# ----------------------------------------------------------------------------------------


#: alt text of the report's figures: what each shows, for readers who cannot see it
FIGURE_ALT = {
    "peak_force_per_transfer.png": "Peak contact force and number of impacts of every transfer "
    "of every carrier against the transfer time, coloured by carrier group",
    "carrier_distribution.png": "Distribution over the carriers: peak force per transfer as a "
    "box per carrier, impacts per second as bars and impact energy per second as black marks",
    "machine_layout.png": "Layout of the machine: horn gears, carrier paths of both groups and "
    "the crossings where carriers transfer",
    "machine.gif": "Animation of the carriers moving round the machine, coloured by their "
    "contact force",
    "machine_frame.png": "One frame of the animation: carrier positions coloured by contact force",
}


def _from_zero(ax: Any) -> None:
    """y axis from 0 to 8 % above the highest point: nothing sits on the frame."""
    top = ax.dataLim.y1 if np.isfinite(ax.dataLim.y1) else 1.0
    ax.set_ylim(0.0, 1.08 * top if top > 0 else 1.0)


def peak_force_figure(run: MachineRun) -> Figure:
    """Peak contact force and number of impacts of every transfer against its time.

    Colour = carrier group, as in every machine figure and the animation (A blue, B green);
    marker = the arc the carrier moves onto (circle inner, triangle outer). The y axes start
    at 0 so that heights compare.
    """
    from braidsim.machine.animation import GROUP_COLOURS
    from braidsim.plotting import new_figure

    tr = run.transfers
    fig = new_figure(7.0, 5.0)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    for g in ("A", "B"):
        colour = GROUP_COLOURS[g]
        for side, marker in (("inner", "o"), ("outer", "^")):
            sel = (tr["group"] == g) & (tr["arc"] == side) if len(tr) else []
            if not len(tr) or not np.any(sel):
                continue
            lab: str | None = f"group {g}, onto an {side} arc"
            for done in (True, False):
                d = tr[sel & (tr["complete"] == done)]
                if not len(d):
                    continue
                # open markers: the run ended before the next transfer (interval cut short)
                kw = {"mfc": colour if done else "none", "label": lab}
                lab = None
                ax1.plot(d["t"], d["peak_force"], marker, color=colour, ms=4, ls="none", **kw)
                ax2.plot(d["t"], d["impacts"], marker, color=colour, ms=4, ls="none", **kw)
    ax1.set_ylabel("peak contact force / N")
    ax2.set_ylabel("impacts per transfer")
    ax2.set_xlabel("transfer time $t$ / s")
    ax2.set_xlim(0.0, run.duration)
    for ax in (ax1, ax2):
        ax.grid(True, lw=0.3, alpha=0.6)
        _from_zero(ax)
    if len(tr):
        ax1.legend(fontsize=7, frameon=False, loc="lower right", ncol=2)
    else:
        ax1.text(0.5, 0.5, "no transfer in the run", transform=ax1.transAxes, ha="center")
    ax1.set_title(
        f"{run.spec.name}\nevery transfer of every carrier (open: cut short by the end of the run)",
        fontsize=9,
    )
    return fig


def distribution_figure(run: MachineRun) -> Figure:
    """Peak force per transfer (box per carrier) and impact rates per carrier."""
    from braidsim.machine.animation import GROUP_COLOURS
    from braidsim.plotting import new_figure

    ca = run.carriers
    tr = run.transfers
    names = list(ca["carrier"])
    fig = new_figure(max(6.4, 0.38 * len(names) + 2.0), 5.0)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    data = [
        tr.loc[tr["carrier"] == n, "peak_force"].to_numpy() if len(tr) else np.zeros(0)
        for n in names
    ]
    pos = np.arange(len(names))
    nonempty = [i for i, d in enumerate(data) if d.size]
    if nonempty:
        bp = ax1.boxplot(
            [data[i] for i in nonempty],
            positions=pos[nonempty],
            widths=0.6,
            patch_artist=True,
            medianprops={"color": "k"},  # colours mean groups only
        )
        for i, box in zip(nonempty, bp["boxes"], strict=True):
            box.set_facecolor(GROUP_COLOURS[str(ca["group"].iloc[i])])
            box.set_alpha(0.5)
    ax1.set_ylabel("peak force per transfer / N")
    colours = [GROUP_COLOURS[g] for g in ca["group"]]
    ax2.bar(pos, ca["impacts_per_second"], color=colours, alpha=0.7)
    ax2.set_ylabel("impacts per second")
    ax3 = ax2.twinx()
    ax3.plot(pos, ca["impact_energy"] / run.duration, "k_", ms=12, mew=2)
    ax3.set_ylabel("impact energy per second / W (black)")
    _from_zero(ax3)
    ax2.set_xticks(pos, names, rotation=90, fontsize=7)
    ax2.set_xlim(-0.6, len(names) - 0.4)
    for ax in (ax1, ax2):
        ax.grid(True, axis="y", lw=0.3, alpha=0.6)
        _from_zero(ax)  # heights compare from zero, as in the other figures
    ax1.set_title("distribution over carriers (group A blue, group B green)", fontsize=9)
    return fig


# ----------------------------------------------------------------------------------------
# tables
# ----------------------------------------------------------------------------------------


def _fmt(v: Any) -> str:
    if isinstance(v, bool | np.bool_):
        return "yes" if v else "no"
    if isinstance(v, int | np.integer):
        return str(int(v))
    if isinstance(v, float | np.floating):
        return f"{float(v):.4g}"
    return str(v)


def markdown_table(rows: list[dict[str, Any]], columns: list[tuple[str, str]]) -> str:
    """A Markdown table of ``rows`` with ``columns`` = [(key, header), ...]."""
    head = "| " + " | ".join(h for _, h in columns) + " |"
    sep = "|" + "|".join("---" for _ in columns) + "|"
    body = ["| " + " | ".join(_fmt(r.get(k, "")) for k, _ in columns) + " |" for r in rows]
    return "\n".join([head, sep, *body])


def markdown(run: MachineRun, data: dict[str, Any], figures: list[str]) -> str:
    """The report as Markdown."""
    g, k, t = data["geometry"], data["kinematics"], data["totals"]
    lines = [f"# {data['name']}", ""]
    if data["description"]:
        lines += [data["description"], ""]
    lines += [
        f"Carrier model: scenario `{data['scenario']}`; every carrier starts "
        f"{'at rest on the inner wall' if data['run']['start'] == 'rest' else 'from the scenario'}"
        f"; simulated {run.duration:.4g} s.",
        "",
        "## Machine",
        "",
        markdown_table(
            [
                {"q": "horn gears N", "v": g["horn_gears"], "u": ""},
                {"q": "slots per horn gear S", "v": g["slots"], "u": ""},
                {"q": "pitch radius r (= r_c)", "v": g["pitch_radius"] * 1e3, "u": "mm"},
                {"q": "ring radius R = r / sin(pi/N)", "v": g["ring_radius"] * 1e3, "u": "mm"},
                {"q": "inner arc pi - 2 pi/N", "v": math.degrees(g["inner_arc_angle"]), "u": "deg"},
                {"q": "outer arc pi + 2 pi/N", "v": math.degrees(g["outer_arc_angle"]), "u": "deg"},
                {"q": "path length of a carrier", "v": g["path_length"] * 1e3, "u": "mm"},
                {"q": "loading", "v": data["loading"]["title"], "u": ""},
                {
                    "q": "carriers per group (A, B)",
                    "v": str(data["loading"]["carriers_per_group"]),
                    "u": "",
                },
                {
                    "q": "braid pattern (interlacing)",
                    "v": data["loading"]["braid_pattern"],
                    "u": "",
                },
                {"q": "transfer cycle", "v": math.degrees(g["transfer_cycle_angle"]), "u": "deg"},
            ],
            [("q", "quantity"), ("v", "value"), ("u", "unit")],
        ),
        "",
        "## Kinematics",
        "",
    ]
    krows = [
        {"q": "mean horn-gear speed", "v": k["mean_speed_rpm"], "u": "rpm"},
        {
            "q": "carrier speed round the machine omega_c = 2 omega / N",
            "v": k["carrier_angular_speed"],
            "u": "rad/s",
        },
        {"q": "carrier revolution time N pi / omega", "v": k["revolution_time"], "u": "s"},
        {"q": "carrier speed along the path r omega", "v": k["carrier_path_speed"], "u": "m/s"},
        {
            "q": "time on an inner / outer arc",
            "v": f"{k['inner_arc_time']:.4g} / {k['outer_arc_time']:.4g}",
            "u": "s",
        },
        {
            "q": "transfers per carrier per second",
            "v": k["transfers_per_carrier_per_second"],
            "u": "1/s",
        },
    ]
    if "braid" in k:
        b = k["braid"]
        krows += [
            {"q": "mandrel radius", "v": b["mandrel_radius"] * 1e3, "u": "mm"},
            {"q": "braid angle (tan alpha = omega_c r / v)", "v": b["braid_angle_deg"], "u": "deg"},
            {"q": "take-up speed = production rate", "v": b["take_up_speed"] * 1e3, "u": "mm/s"},
            {"q": "production rate", "v": b["production_rate_m_per_h"], "u": "m/h"},
        ]
    if "speed_profile" in k:
        p = k["speed_profile"]
        krows.append(
            {
                "q": "speed profile (phase: factor x scale)",
                "v": ", ".join(
                    f"{a:g}: {f * p['scale']:.3g}"
                    for a, f in zip(p["phase"], p["factor"], strict=True)
                ),
                "u": "of the mean",
            }
        )
    lines += [markdown_table(krows, [("q", "quantity"), ("v", "value"), ("u", "unit")]), ""]
    lines += ["## Machine totals", ""]
    trow = [
        {"q": "carriers", "v": t["carriers"], "u": ""},
        {"q": "transfers simulated", "v": t["transfers"], "u": ""},
        {"q": "track impacts", "v": t["impacts"], "u": ""},
        {"q": "track impacts per second", "v": t["impacts_per_second"], "u": "1/s"},
        {
            "q": "track impact energy per second (sum of m v^2/2 at onsets)",
            "v": t["impact_energy_per_second"],
            "u": "W",
        },
        {"q": "power dissipated by the track contacts", "v": t["dissipated_power"], "u": "W"},
        {"q": "largest track peak force", "v": t["max_peak_force"], "u": "N"},
        {"q": "worst carrier (track peak force)", "v": t["worst_carrier"]["carrier"], "u": ""},
    ]
    sl = t.get("slot")
    if sl:
        trow += [
            {"q": "slot impacts", "v": sl["impacts"], "u": ""},
            {"q": "slot impacts per second", "v": sl["impacts_per_second"], "u": "1/s"},
            {
                "q": "slot impact energy per second (sum of m v^2/2 at onsets)",
                "v": sl["impact_energy_per_second"],
                "u": "W",
            },
            {"q": "largest slot peak force", "v": sl["max_peak_force"], "u": "N"},
        ]
    wt = t.get("worst_transfer")
    if wt:
        trow.append(
            {
                "q": "worst transfer",
                "v": (
                    f"{wt['carrier']} #{wt['transfer']} at t = {wt['t']:.4g} s, "
                    f"crossing {wt['crossing']} (onto an {wt['arc']} arc): "
                    f"{wt['peak_force']:.4g} N, {wt['approach_speed']:.4g} m/s"
                ),
                "u": "",
            }
        )
    lines += [markdown_table(trow, [("q", "quantity"), ("v", "value"), ("u", "unit")]), ""]
    lines += [
        "## Per carrier",
        "",
        markdown_table(
            data["carriers"],
            [
                ("carrier", "carrier"),
                ("transfers", "transfers"),
                ("impacts", "impacts"),
                ("impacts_per_second", "impacts/s"),
                ("max_peak_force", "max peak force / N"),
                ("mean_peak_force", "mean peak force per transfer / N"),
                ("max_approach_speed", "max approach speed / (m/s)"),
                ("impact_energy", "impact energy / J"),
                ("dissipated_energy", "dissipated / J"),
            ],
        ),
        "",
        "## The ten hardest transfers",
        "",
    ]
    tr = run.transfers
    if len(tr):
        top = tr.sort_values("peak_force", ascending=False).head(10).to_dict(orient="records")
        lines.append(
            markdown_table(
                top,
                [
                    ("carrier", "carrier"),
                    ("transfer", "#"),
                    ("t", "t / s"),
                    ("crossing", "crossing"),
                    ("arc", "onto arc"),
                    ("impacts", "impacts"),
                    ("peak_force", "peak force / N"),
                    ("approach_speed", "approach speed / (m/s)"),
                    ("dissipated_energy", "dissipated / J"),
                ],
            )
        )
    else:
        lines.append("No transfer in the run.")
    lines += ["", "## Figures", ""]
    lines += [f"![{FIGURE_ALT.get(f, f)}]({f})" for f in figures]
    lines += [
        "",
        "## What the model assumes",
        "",
        "- Every carrier is the paper's single-carrier model (its x: radial to the horn gear in "
        "the track clearance) with the transfer map of section 3.2 at each crossing: mirrored "
        "across the track, radial speed reversed, the contact speed added.",
        "- The load T1 cos(phi) + m r_c omega^2 has the same magnitude on inner and outer arcs; "
        "the yarn's direction relative to the arc is not resolved.",
        "- All carriers see the same track vibration h(t) along their own track normal.",
        "- Carriers do not interact except through the shared horn-gear rotation.",
        "",
    ]
    return "\n".join(lines)


def write_report(run: MachineRun, out: str | Path, animation: bool = True) -> dict[str, Any]:
    """Write the report directory ``out`` (whole or not at all); return the summary."""
    from braidsim.io import atomic_write_text
    from braidsim.machine.animation import layout_figure, save_animation, save_frame
    from braidsim.plotting import save

    files: list[str] = []
    figs = []
    with atomic_directory(out, REPORT_KIND) as tmp:
        atomic_write_text(tmp / "carriers.csv", run.carriers.to_csv(index=False))
        atomic_write_text(tmp / "transfers.csv", run.transfers.to_csv(index=False))
        atomic_write_text(tmp / "impacts.csv", run.impacts.to_csv(index=False))
        files += ["carriers.csv", "transfers.csv", "impacts.csv"]
        for name, make in (
            ("peak_force_per_transfer.png", peak_force_figure),
            ("carrier_distribution.png", distribution_figure),
            ("machine_layout.png", layout_figure),
        ):
            save(make(run), tmp / name)
            figs.append(name)
        if animation and run.spec.animation.enabled and run.frame_times.size:
            save_animation(run, tmp / "machine.gif")
            f = int(np.argmax(run.frame_forces.max(axis=1))) if run.frame_forces.size else 0
            save_frame(run, f, tmp / "machine_frame.png")
            figs += ["machine.gif", "machine_frame.png"]
        files += figs
        files += ["report.md", "summary.json"]
        data = summary(run, files)
        atomic_write_text(tmp / "report.md", markdown(run, data, figs))
        atomic_write_text(
            tmp / "summary.json", json.dumps(json_safe(data), indent=1, allow_nan=False) + "\n"
        )
    data["out"] = str(out)
    return data
