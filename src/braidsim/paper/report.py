"""``braidsim paper``: reproduce every result of sections 3.1-3.5 and set it beside the paper's.

:func:`compute_report` runs every run of ``paper_values.toml`` twice (calibrated E = 200 GPa
and as printed, E = 2 GPa), the short evidence runs of :mod:`braidsim.paper.findings`, and
compares each item; :func:`reproduce` also writes into one directory, whole or not at all:

- ``report.md`` and ``report.html`` (self-contained, figures embedded as base64);
- ``items.json`` (as ``--json``) and ``items.csv``: every item, paper value, ours, deviation,
  status, cause, and the as-printed value;
- ``table1.csv`` and ``table1.md``: Table 1, paper against ours;
- ``excerpt.md``: a few rows of the deviation table (for the README);
- ``figures/``: the paper's Figures 3-22 (``fig03_x.png`` ...), per run the added impact
  sequence and phase portrait (``added_3.1_impacts.png`` ...), and ``table1.png``.

Statuses: *reproduced* (within the item's tolerance: 5 %, 1 % for the initial peaks set by
the initial overlap), *deviates* (outside; the cause found is stated), *not reproducible*
(needs something the paper does not give).
"""

from __future__ import annotations

import base64
import csv
import html
import io
import json
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from braidsim.io import atomic_directory, atomic_write_text, check_output_directory, json_safe
from braidsim.paper import findings as F
from braidsim.paper.compute import compare, measure, run_spec
from braidsim.paper.values import PaperItem, PaperValues, load_paper_values

if TYPE_CHECKING:
    from braidsim.result import Result

#: progress callback: (what was just done, how many steps it was)
StepCallback = Callable[[str, int], None]
OUTPUT_KIND = "paper report"
SECTIONS = ("3.1", "3.2", "3.3", "3.4", "3.5")
TABLE1_LABELS = {
    "hertz": "Hertz [10]",
    "brandlein": "Brändlein [11]",
    "hunt_crossley": "Crossley [19]",
    "herbert_mcwhannell": "McWhannell [20]",
    "lee_wang": "Wang [21]",
    "lankarani_nikravesh": "Nikraves [22]",
    "gonthier": "Gonthier [23]",
    "zhiying_qishao": "Zhiying [24]",
    "flores": "Flores [25]",
}
T1_COLUMNS = (
    ("contact_force", "Contact force / N"),
    ("stiffness_force", "F_kg / N"),
    ("damping_force", "F_cg / N"),
    ("depth", "Contact depth / 1e-2 mm"),
)


@dataclass
class PaperReport:
    """Everything ``braidsim paper`` computes."""

    values: PaperValues
    outcomes: list[F.Outcome]
    evidence: F.Evidence
    readings: list[F.Reading]
    runs: dict[str, dict[str, Any]]
    results: dict[tuple[str, str], Result] = field(repr=False)
    elapsed_s: float = 0.0
    figures: dict[str, list[str]] = field(default_factory=dict)

    # ------------------------------------------------------------------ summaries
    def outcome(self, item_id: str) -> F.Outcome:
        """The outcome of one item."""
        for o in self.outcomes:
            if o.item.id == item_id:
                return o
        raise KeyError(item_id)

    def counts(self) -> dict[str, int]:
        """Number of items per status."""
        return {s: sum(1 for o in self.outcomes if o.status == s) for s in F.STATUSES}

    def acceptance(self) -> list[dict[str, Any]]:
        """The acceptance checks of the reproduction: whether each holds, which items fail it.

        The thresholds are the project's: sections 3.1-3.2 and the four Table 1 rows that follow
        from the printed formulas within 5 %, the initial peaks of 3.3-3.4 within 1 %.
        """

        def check(name: str, ids: list[str]) -> dict[str, Any]:
            failing = [i for i in ids if self.outcome(i).status != F.REPRODUCED]
            return {"check": name, "items": len(ids), "ok": not failing, "failing": failing}

        ids = [o.item.id for o in self.outcomes]
        rows = ("hunt_crossley", "lee_wang", "lankarani_nikravesh", "zhiying_qishao")
        return [
            check(
                "sections 3.1 and 3.2 within 5 %",
                [i for i in ids if i.startswith(("3.1.", "3.2."))],
            ),
            check(
                "Table 1 Hunt-Crossley, Lee-Wang, Lankarani-Nikravesh, Zhiying-Qishao rows "
                "within 5 %",
                [i for i in ids if any(i.startswith(f"T1.{r}.") for r in rows)],
            ),
            check(
                "initial peaks of 3.3 and 3.4 (set by the initial overlap) within 1 %",
                [o.item.id for o in self.outcomes if o.item.tolerance <= 0.01 + 1e-12],
            ),
        ]

    def to_json(self) -> dict[str, Any]:
        """The ``--json`` object: every item in SI units, the counts and the checks (strict JSON:
        no NaN; a relative deviation is null for a printed zero)."""
        items = []
        for o in self.outcomes:
            it = o.item
            items.append(
                {
                    "id": it.id,
                    "section": it.section,
                    "where": it.where,
                    "quantity": it.quantity,
                    "symbol": it.symbol,
                    "statistic": it.statistic,
                    "run": it.run,
                    "scenario": self.values.runs[it.run].scenario,
                    "window": [o.window[0], o.window[1]],
                    "window_name": it.window,
                    "unit": it.si_unit,
                    "paper": it.si_value,
                    "ours": o.ours.value,
                    "deviation": o.cmp.deviation,
                    "abs_deviation": o.cmp.abs_deviation * it.scale,
                    "tolerance": it.tolerance if it.value != 0.0 else None,
                    "abs_tolerance": None if it.abs_tol is None else it.abs_tol * it.scale,
                    "status": o.status,
                    "cause": o.cause,
                    "printed_preset": {
                        "scenario": self.runs[it.run]["printed_scenario"],
                        "ours": o.printed.value,
                        "deviation": o.printed_cmp.deviation,
                        "within_tolerance": o.printed_cmp.within,
                    },
                    "text": it.text,
                }
            )
        from braidsim.provenance import utc_now, version

        return json_safe(
            {
                "braidsim_version": version(),
                "created": utc_now(),
                "paper": self.values.meta.get("paper", ""),
                "sections": self.values.meta.get("sections", ""),
                "counts": self.counts(),
                "checks": self.acceptance(),
                "items": items,
                "elapsed_s": self.elapsed_s,
            }
        )


# ------------------------------------------------------------------------------ compute


def total_steps(values: PaperValues, figures: bool = True) -> int:
    """Number of progress steps of :func:`compute_report` (+ figures and files)."""
    n = 2 * len(values.runs) + len(F.evidence_runs(values))  # main runs + evidence runs
    if figures:
        paper_runs = [s for s in values.runs.values() if s.figures]
        n += sum(len(s.figures) + 2 for s in paper_runs) + 1 + 1
    return n


def compute_report(
    values: PaperValues | None = None,
    on_step: StepCallback | None = None,
    series: bool = True,
) -> PaperReport:
    """Run everything and compare every item (no files written).

    Parameters
    ----------
    values : PaperValues, optional
        Default: the package's ``paper_values.toml``.
    on_step : callable, optional
        ``on_step(description, steps)`` after each run.
    series : bool
        Keep the time series of the runs that have figures.
    """
    t_start = time.perf_counter()
    pv = values or load_paper_values()
    step = on_step or (lambda _d, _n: None)
    results: dict[tuple[str, str], Result] = {}
    runs: dict[str, dict[str, Any]] = {}
    for key, spec in pv.runs.items():
        info: dict[str, Any] = {
            "scenario": spec.scenario,
            "duration": spec.duration,
            "windows": spec.windows,
        }
        for variant in ("calibrated", "printed"):
            t0 = time.perf_counter()
            res = run_spec(
                spec, variant, series=series and bool(spec.figures) and variant == "calibrated"
            )
            results[(key, variant)] = res
            info[f"{variant}_elapsed_s"] = time.perf_counter() - t0
            info[f"{variant}_stiffness"] = res.model.track.stiffness
            info[f"{variant}_impacts"] = int((res.impacts["pair"] == "track").sum())
            if variant == "printed":
                info["printed_scenario"] = res.model.scenario.name
                info["printed_builtin"] = bool(spec.printed)
            step(f"run {spec.scenario}" + (" (E = 2 GPa)" if variant == "printed" else ""), 1)
        runs[key] = info

    outcomes: dict[str, F.Outcome] = {}
    for it in pv.items:
        spec = pv.runs[it.run]
        ours = measure(it, results[(it.run, "calibrated")], spec)
        printed = measure(it, results[(it.run, "printed")], spec)
        outcomes[it.id] = F.Outcome(
            item=it,
            window=spec.windows[it.window],
            ours=ours,
            cmp=compare(it, ours.value),
            printed=printed,
            printed_cmp=compare(it, printed.value),
        )

    extra: dict[str, Result] = {}
    for er in F.evidence_runs(pv):
        extra[er.key] = run_spec(
            pv.runs[er.run], "calibrated", overrides=er.overrides, duration=er.duration
        )
        step(f"evidence: {er.run}, {er.purpose}", 1)
    ev = F.gather_evidence(pv, results, extra, outcomes)
    for o in outcomes.values():
        o.status, o.cause = F.explain(o, pv, outcomes, ev)
    reads = F.readings(pv, outcomes, ev)
    return PaperReport(
        values=pv,
        outcomes=list(outcomes.values()),
        evidence=ev,
        readings=reads,
        runs=runs,
        results=results,
        elapsed_s=time.perf_counter() - t_start,
    )


# ------------------------------------------------------------------------------ formats


fmt = F.fmt


def fmt_dev(o: F.Outcome, printed: bool = False) -> str:
    """Relative deviation in %, or the absolute one for a printed zero."""
    c = o.printed_cmp if printed else o.cmp
    if c.deviation is None:
        return f"{fmt(c.abs_deviation, 3)} {o.item.unit} (abs)"
    return f"{c.deviation * 100:+.2f} %"


def ours_text(o: F.Outcome, printed: bool = False) -> str:
    """Our value in the paper's unit."""
    m = o.printed if printed else o.ours
    return fmt(m.value / o.item.scale + 0.0)


def table1_rows(report: PaperReport) -> list[dict[str, Any]]:
    """Table 1 in long form: one row per (law, quantity), paper / ours / printed, paper units."""
    rows = []
    for key, spec in report.values.runs.items():
        if not spec.is_table1:
            continue
        for q, head in T1_COLUMNS:
            its = [o for o in report.outcomes if o.item.run == key and o.item.quantity == q]
            if not its:
                continue
            unit = its[0].item.unit
            scale = its[0].item.scale
            w = its[0].window
            res = report.results[(key, "calibrated")]
            lo, hi = res.ranges_dict("track", res.window_index(*w))[q]
            pres = report.results[(key, "printed")]
            plo, phi = pres.ranges_dict("track", pres.window_index(*w))[q]
            pmin = next(
                (o.item.value for o in its if o.item.statistic in ("min", "absmax")), math.nan
            )
            pmax = next(
                (o.item.value for o in its if o.item.statistic in ("max", "absmax")), math.nan
            )
            statuses = [o.status for o in its]
            rows.append(
                {
                    "law": spec.law,
                    "label": TABLE1_LABELS.get(spec.law, spec.law),
                    "quantity": q,
                    "column": head,
                    "unit": unit,
                    "paper_min": pmin,
                    "paper_max": pmax,
                    "ours_min": lo / scale + 0.0,
                    "ours_max": hi / scale + 0.0,
                    "printed_min": plo / scale + 0.0,
                    "printed_max": phi / scale + 0.0,
                    "status": "; ".join(sorted({st for st in statuses})),
                    "n_items": len(its),
                    "n_reproduced": sum(st == F.REPRODUCED for st in statuses),
                    "n_deviates": sum(st == F.DEVIATES for st in statuses),
                    "n_not_reproducible": sum(st == F.NOT_REPRODUCIBLE for st in statuses),
                }
            )
    return rows


def table1_csv(rows: list[dict[str, Any]]) -> str:
    """Table 1 as CSV (paper units: N, mm)."""
    buf = io.StringIO()
    cols = [
        "law",
        "quantity",
        "unit",
        "paper_min",
        "paper_max",
        "ours_min",
        "ours_max",
        "printed_min",
        "printed_max",
        "status",
    ]
    w = csv.DictWriter(buf, fieldnames=cols, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{r[k]:.8g}" if isinstance(r[k], float) else r[k]) for k in cols})
    return buf.getvalue()


def _row_status(qs: Mapping[str, dict[str, Any]]) -> str:
    """ "5/7 reproduced, 2 deviate" for one Table 1 row."""
    n = sum(r["n_items"] for r in qs.values())
    rep = sum(r["n_reproduced"] for r in qs.values())
    dev = sum(r["n_deviates"] for r in qs.values())
    nr = sum(r["n_not_reproducible"] for r in qs.values())
    text = f"{rep}/{n} reproduced"
    if dev:
        text += f", {dev} deviate"
    if nr:
        text += f", {nr} not reproducible"
    return text


def _pair(lo: float, hi: float, depth: bool) -> str:
    """A range as Table 1 prints it: integers in N, depth in 1e-2 mm to 2 decimals, 0 as 0."""

    def one(v: float) -> str:
        text = f"{v * 100:.2f}" if depth else f"{v:.0f}"
        return "0" if float(text) == 0.0 else text

    return f"({one(lo)}, {one(hi)})"


def _t1_cell(row: Mapping[str, Any]) -> tuple[str, str]:
    """Paper and ours of one Table 1 cell as printed there ((-4864, 4921); depth in 1e-2 mm)."""
    d = row["quantity"] == "depth"
    paper = _pair(row["paper_min"], row["paper_max"], d)
    if row["paper_min"] == row["paper_max"] == 0.0 and row["quantity"] == "damping_force":
        paper = "0"  # printed as a single 0
    return paper, _pair(row["ours_min"], row["ours_max"], d)


def table1_markdown(rows: list[dict[str, Any]]) -> str:
    """Table 1 in the paper's layout: each cell "paper / ours" (depth in 1e-2 mm)."""
    laws: dict[str, dict[str, dict[str, Any]]] = {}
    for r in rows:
        laws.setdefault(r["label"], {})[r["quantity"]] = r
    head = "| Model | " + " | ".join(h for _, h in T1_COLUMNS) + " | status |"
    lines = [
        "Table 1, contact parameters without track vibration: **paper** / ours (E = 200 GPa).",
        "",
        head,
        "|" + "---|" * (len(T1_COLUMNS) + 2),
    ]
    for label, qs in laws.items():
        cells = []
        for q, _ in T1_COLUMNS:
            row = qs.get(q)
            if row is None:
                cells.append("")
                continue
            paper, ours = _t1_cell(row)
            cells.append(f"**{paper}** / {ours}")
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {_row_status(qs)} |")
    return "\n".join(lines) + "\n"


def items_csv(report: PaperReport) -> str:
    """Every item as CSV, paper units."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(
        [
            "id",
            "section",
            "where",
            "quantity",
            "statistic",
            "window",
            "t0_s",
            "t1_s",
            "unit",
            "paper",
            "ours",
            "deviation",
            "tolerance",
            "status",
            "printed_preset",
            "printed_deviation",
            "cause",
        ]
    )
    for o in report.outcomes:
        it = o.item
        w.writerow(
            [
                it.id,
                it.section,
                it.where,
                it.quantity,
                it.statistic,
                it.window,
                o.window[0],
                o.window[1],
                it.unit,
                f"{it.value:g}",
                f"{o.ours.value / it.scale + 0.0:.8g}",
                "" if o.cmp.deviation is None else f"{o.cmp.deviation:.6g}",
                f"{it.tolerance:g}" if it.value != 0.0 else f"abs {it.abs_tol:g}",
                o.status,
                f"{o.printed.value / it.scale + 0.0:.8g}",
                "" if o.printed_cmp.deviation is None else f"{o.printed_cmp.deviation:.6g}",
                o.cause,
            ]
        )
    return buf.getvalue()


def _printed_name(info: Mapping[str, Any]) -> str:
    """The as-printed preset of a run: a built-in name, or the override applied."""
    if info.get("printed_builtin"):
        return str(info["printed_scenario"])
    return f"{info['scenario']} with E_i = 2 GPa"


def _md_escape(s: str) -> str:
    return s.replace("|", "\\|")


def _status_md(s: str) -> str:
    return {
        F.REPRODUCED: "reproduced",
        F.DEVIATES: "**deviates**",
        F.NOT_REPRODUCIBLE: "*not reproducible*",
    }[s]


def item_label(it: PaperItem) -> str:
    """A short human name: "Fig. 4 (3.1): F_kg min, initially", "Table 1, Wang: F_g min"."""
    stat = {"rest": "at rest", "absmax": "max |.|"}.get(it.statistic, it.statistic)
    if it.run.startswith("T1."):
        law = TABLE1_LABELS.get(it.run.split(".", 1)[1], it.run).split(" [")[0]
        return f"Table 1, {law}: {it.symbol} {stat}"
    return f"{it.where} ({it.section}): {it.symbol} {stat}, {it.window}"


EXCERPT_IDS = (
    "3.1.stiffness_force.initially.min",
    "3.1.damping_force.initially.max",
    "3.1.depth.later.rest",
    "3.2.stiffness_force.initially.min",
    "3.3.stiffness_force.initially.max",
    "3.4a.depth.initially.max",
    "T1.lee_wang.contact_force.run.min",
    "T1.gonthier.damping_force.run.max",
    "3.4b.stiffness_force.initially.max",
    "T1.brandlein.contact_force.run.min",
)


def excerpt_markdown(report: PaperReport, ids: tuple[str, ...] = EXCERPT_IDS) -> str:
    """A few rows of the deviation table, for the README."""
    c = report.counts()
    lines = [
        f"`braidsim paper` compares {len(report.outcomes)} numbers of sections 3.1-3.5: "
        f"{c[F.REPRODUCED]} reproduced (within 5 %; 1 % for the initial peaks), {c[F.DEVIATES]} "
        "deviate "
        f"(cause stated), {c[F.NOT_REPRODUCIBLE]} not reproducible. A few rows:",
        "",
        "| item | paper | braidsim | deviation | status |",
        "|---|---|---|---|---|",
    ]
    for i in ids:
        try:
            o = report.outcome(i)
        except KeyError:
            continue
        it = o.item
        lines.append(
            f"| {item_label(it)} | {fmt(it.value, 6)} {it.unit} | "
            f"{ours_text(o)} {it.unit} | {fmt_dev(o)} | {_status_md(o.status)} |"
        )
    lines.append("")
    return "\n".join(lines)


def _section_items(report: PaperReport, section: str) -> list[F.Outcome]:
    return [o for o in report.outcomes if o.item.section == section]


def _causes(outs: list[F.Outcome]) -> list[tuple[list[str], str, str]]:
    """Distinct causes of a list of outcomes: (ids, status, text)."""
    groups: dict[tuple[str, str], list[str]] = {}
    for o in outs:
        if o.status != F.REPRODUCED:
            groups.setdefault((o.status, o.cause), []).append(o.item.id)
    return [(ids, st, text) for (st, text), ids in groups.items()]


def markdown_report(report: PaperReport) -> str:
    """The report as Markdown (figures linked from ``figures/``)."""
    pv = report.values
    c = report.counts()
    L: list[str] = []
    L.append("# Reproduction of Zhang et al., sections 3.1-3.5 (`braidsim paper`)")
    L.append("")
    L.append(
        f"Paper: *{pv.meta.get('paper', '')}*. Generated by `braidsim paper` in "
        f"{report.elapsed_s:.1f} s "
        "(simulations and comparisons; figures and files not included)."
    )
    L.append("")
    L.append(_provenance_line())
    L.append("")
    L.append(
        f"**{len(report.outcomes)} numbers** stated by the paper: **{c[F.REPRODUCED]} "
        "reproduced** (within 5 %, "
        f"1 % for the initial peaks), **{c[F.DEVIATES]} deviate** (cause stated), "
        f"**{c[F.NOT_REPRODUCIBLE]} not reproducible** (the paper does not give what they need). "
        "Ours: the calibrated preset, E = 200 GPa (reading 1 below); the as-printed preset "
        "(E = 2 GPa) is shown beside it."
    )
    L.append("")
    L.append("| acceptance check | items | holds |")
    L.append("|---|---|---|")
    for a in report.acceptance():
        extra = "" if a["ok"] else " (failing: " + ", ".join(a["failing"]) + ")"
        L.append(f"| {a['check']} | {a['items']} | {'yes' if a['ok'] else 'no'}{extra} |")
    L.append("")
    L.append("## How we read the paper, and the evidence we measured")
    L.append("")
    for r in report.readings:
        L.append(f"### {r.title} ({r.note})")
        L.append("")
        L.append(r.reading)
        L.append("")
        for e in r.evidence:
            L.append(f"- {e}")
        L.append("")
    L.append("## Runs and time windows")
    L.append("")
    L.append(
        "The paper states no duration and no time window; ours are below. Ranges are the exact "
        "extremes "
        "over the window, refined on the integrator's interpolant."
    )
    L.append("")
    L.append("| run | scenario | as printed | duration / s | windows / s | K / (N/m^n) | impacts |")
    L.append("|---|---|---|---|---|---|---|")
    for key, info in report.runs.items():
        ws = ", ".join(f"{n} [{a:g}, {b:g}]" for n, (a, b) in info["windows"].items())
        L.append(
            f"| {key} | `{info['scenario']}` | {_printed_name(info)} | {info['duration']:g} | "
            f"{ws} | "
            f"{fmt(info['calibrated_stiffness'])} | {info['calibrated_impacts']} |"
        )
    L.append("")
    for sec in SECTIONS:
        outs = _section_items(report, sec)
        if not outs:
            continue
        L.append(f"## Section {sec}")
        L.append("")
        L.append(
            "| item | where | window / s | paper | ours (E = 200 GPa) | deviation | status | "
            "as printed (E = 2 GPa) | deviation |"
        )
        L.append("|---|---|---|---|---|---|---|---|---|")
        for o in outs:
            it = o.item
            L.append(
                f"| `{it.id}` | {it.where} | {it.window} [{o.window[0]:g}, {o.window[1]:g}] | "
                f"{fmt(it.value, 6)} {it.unit} | {ours_text(o)} {it.unit} | {fmt_dev(o)} | "
                f"{_status_md(o.status)} | "
                f"{ours_text(o, True)} {it.unit} | {fmt_dev(o, True)} |"
            )
        L.append("")
        causes = _causes(outs)
        if causes:
            L.append("Causes:")
            L.append("")
            for ids, st, text in causes:
                L.append(f"- {', '.join(f'`{i}`' for i in ids)} ({st}): {_md_escape(text)}")
            L.append("")
        figs = report.figures.get(sec, [])
        for f in figs:
            L.append(f"![{_alt(f, report)}]({f})")
            L.append("")
        if sec == "3.5":
            L.append(table1_markdown(table1_rows(report)))
    L.append("## Consistency of the paper's own numbers")
    L.append("")
    L.append(
        "Eq. (4) ties each printed F_kg extreme to the printed depth of the same window: "
        f"F_kg = K |delta|^1.5 with K = {fmt(report.evidence['K'])} N/m^1.5."
    )
    L.append("")
    L.append("| item | paper depth / mm | K depth^1.5 / N | paper F_kg / N | mismatch |")
    L.append("|---|---|---|---|---|")
    for ck in report.evidence["eq4_checks"]:
        L.append(
            f"| `{ck['id']}` | {fmt(ck['depth_mm'], 6)} | {fmt(ck['eq4_F'])} | "
            f"{fmt(ck['paper_F'], 6)} | "
            f"{ck['mismatch'] * 100:+.1f} % |"
        )
    L.append("")
    L.append("Damping-to-stiffness ratio max|F_cg| / max|F_kg| of each window, paper and ours:")
    L.append("")
    L.append("| run | window | paper | ours |")
    L.append("|---|---|---|---|")
    for r in report.evidence["ratios"]:
        L.append(f"| {r['run']} | {r['window']} | {r['paper']:.3f} | {r['ours']:.3f} |")
    L.append("")
    L.append("## Added figures")
    L.append("")
    for f in report.figures.get("added", []):
        L.append(f"![{_alt(f, report)}]({f})")
        L.append("")
    return "\n".join(L)


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;
max-width:1200px;margin:2em auto;padding:0 1em;color:#222;line-height:1.45}
table{border-collapse:collapse;margin:0.8em 0;font-size:0.86em}
th,td{border:1px solid #ccc;padding:3px 6px;text-align:left;vertical-align:top}
th{background:#f3f3f3}
code{font-size:0.92em}
.reproduced{color:#1a7f37;font-weight:600}.deviates{color:#b35900;font-weight:600}
.not-reproducible{color:#8250df;font-weight:600}
img{max-width:100%;border:1px solid #eee;margin:0.5em 0}
.small{font-size:0.85em;color:#555}
"""


def html_report(report: PaperReport, root: Path) -> str:
    """The report as one self-contained HTML page: :func:`markdown_report` rendered by
    markdown-it-py (CommonMark with tables), the figures from ``root`` embedded as base64.

    One writer for both formats: the HTML says exactly what the Markdown says, alt text
    included.
    """
    import re

    from markdown_it import MarkdownIt

    body = MarkdownIt("commonmark", {"html": False}).enable("table").render(markdown_report(report))

    def embed(m: re.Match[str]) -> str:
        path = root / html.unescape(m.group(1))
        if not path.is_file():
            return m.group(0)
        data = base64.b64encode(path.read_bytes()).decode("ascii")
        return f'src="data:image/png;base64,{data}"'

    body = re.sub(r'src="([^"]+\.png)"', embed, body)
    return (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        "<title>braidsim paper: reproduction of sections 3.1-3.5</title>"
        f"<style>{_CSS}</style></head><body>\n{body}</body></html>\n"
    )


def _provenance_line() -> str:
    """Which braidsim made the report, and when (UTC); the scenarios and settings of each run
    are in ``items.json`` and the tables above."""
    from braidsim.provenance import utc_now, version

    return f"braidsim {version()}, {utc_now()}."


def _alt(rel: str, report: PaperReport) -> str:
    """Alt text of a report figure (what it shows, in words)."""
    from braidsim.paper.figures import alt_text

    return alt_text(rel, report.values.runs)


# ------------------------------------------------------------------------------ figures


def write_figures(
    report: PaperReport, root: Path, on_step: StepCallback | None = None
) -> dict[str, list[str]]:
    """Write every figure under ``root/figures``; return the relative paths by report section."""
    from braidsim.paper import figures as FG
    from braidsim.plotting import save

    step = on_step or (lambda _d, _n: None)
    out: dict[str, list[str]] = {}
    by_run: dict[str, list[F.Outcome]] = {}
    for o in report.outcomes:
        by_run.setdefault(o.item.run, []).append(o)
    for key, spec in report.values.runs.items():
        if not spec.figures:
            continue
        res = report.results[(key, "calibrated")]
        for q, number in sorted(spec.figures.items(), key=lambda kv: kv[1]):
            rel = f"figures/{FG.figure_filename(number, q)}"
            fig = FG.paper_figure(res, spec, q, number, by_run.get(key, []))
            save(fig, root / rel)
            out.setdefault(spec.section, []).append(rel)
            step(f"Figure {number}", 1)
        for name, maker in (("impacts", FG.impacts_figure), ("phase", FG.phase_figure)):
            rel = f"figures/added_{key}_{name}.png"
            save(maker(res, spec), root / rel)
            out.setdefault("added", []).append(rel)
            step(f"added figure {key} {name}", 1)
    rel = "figures/table1.png"
    save(FG.table1_figure(table1_rows(report)), root / rel)
    out.setdefault("3.5", []).append(rel)
    step("Table 1 figure", 1)
    return out


def write_outputs(
    report: PaperReport, root: Path, on_step: StepCallback | None = None
) -> list[Path]:
    """Write the figures and every report file into ``root`` (each file atomically)."""
    report.figures = write_figures(report, root, on_step)
    rows = table1_rows(report)
    paths = [
        atomic_write_text(root / "report.md", markdown_report(report)),
        atomic_write_text(root / "report.html", html_report(report, root)),
        atomic_write_text(
            root / "items.json", json.dumps(json_safe(report.to_json()), indent=1, allow_nan=False)
        ),
        atomic_write_text(root / "items.csv", items_csv(report)),
        atomic_write_text(root / "table1.csv", table1_csv(rows)),
        atomic_write_text(root / "table1.md", table1_markdown(rows)),
        atomic_write_text(root / "excerpt.md", excerpt_markdown(report)),
    ]
    if on_step:
        on_step("report files", 1)
    return paths


def reproduce(out: str | Path, on_step: StepCallback | None = None) -> PaperReport:
    """Run everything and write the report directory ``out`` (complete or absent).

    The files are built in a temporary sibling directory that is renamed to ``out`` at the
    end; an earlier ``braidsim paper`` output at ``out`` is replaced, anything else there is
    refused before any work is done (:class:`braidsim.errors.InputError`).
    """
    out = Path(out)
    check_output_directory(out, OUTPUT_KIND)
    report = compute_report(on_step=on_step)
    with atomic_directory(out, OUTPUT_KIND) as tmp:
        write_outputs(report, tmp, on_step)
    return report
