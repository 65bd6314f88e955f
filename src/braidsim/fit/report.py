"""The fit's outputs: the JSON summary, the fitted scenario as TOML, residual and profile
plots, and the fitted series as CSV, written into one directory whole or not at all.

Files of ``braidsim fit ... --out DIR``:

* ``fit.json``: the summary (the same object as ``--json``), SI;
* ``fitted_scenario.toml``: the scenario with the fitted values, runnable as is with
  ``braidsim run DIR/fitted_scenario.toml``;
* ``residuals.png``: the record and the fitted model, and the scaled residuals;
* ``profiles.png``: the profile likelihoods (when the spec asks for some);
* ``fitted_series.csv``: t, each fitted quantity measured and modelled, and the residual.

An impact list, or several records fitted together, give ``fitted_residuals.csv`` instead of
``fitted_series.csv`` (one row per datum: record, kind, quantity, t, measured, model and
scaled residual) and a ``residuals.png`` of the scaled residuals of each record.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from braidsim.fit.data import IMPACT_UNITS, QUANTITY_UNITS, Record
from braidsim.fit.estimate import FitResult
from braidsim.fit.spec import FitSpec, is_offset, scenario_values
from braidsim.io import json_safe

REPORT_KIND = "fit"


def _f(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def _single_series(res: FitResult) -> bool:
    """Whether the fit is of one sampled record (the plots and CSV of the samples)."""
    return isinstance(res.record, Record) and len(res.parts) <= 1


def _record_summary(res: FitResult) -> dict[str, Any]:
    rec = res.record
    if isinstance(rec, Record):
        return {
            "source": rec.source,
            "samples": int(rec.t.size),
            "duration": rec.duration,
            "sample_interval": rec.sample_interval,
        }
    return {"source": rec.source, "impacts": int(rec.t.size), "duration": rec.duration}


def _describe(res: FitResult) -> str:
    rec = res.record
    what = (
        f"{rec.t.size} samples over {rec.duration:g} s"
        if isinstance(rec, Record)
        else f"{rec.t.size} impacts up to {rec.duration:g} s"
    )
    more = f" (and {len(res.parts) - 1} more records)" if len(res.parts) > 1 else ""
    return f"record {rec.source}: {what}{more}"


def summary(res: FitResult) -> dict[str, Any]:
    """The JSON summary of a fit (SI): estimates with standard errors and 95 % intervals,
    convergence, cost, number of data, law, correlation, warnings, profiles and the
    comparison of contact laws."""
    st = res.stats
    est = {}
    for i, p in enumerate(res.free):
        est[p.key] = {
            "value": float(st.values[i]),
            "stderr": _f(st.stderr[i]),
            "ci95": [_f(st.ci95[i, 0]), _f(st.ci95[i, 1])],
            "unit": p.unit,
            "bounds": [p.low, p.high],
            "start": p.start,
        }
    out: dict[str, Any] = {
        "estimates": est,
        "converged": res.converged,
        "cost": res.cost,
        "n_data": res.n_data,
        "law": res.law,
        "quantities": list(res.quantities),
        "noise": res.noise,
        "residual_std": st.residual_std,
        "dof": st.dof,
        "correlation": {"keys": list(res.keys), "matrix": st.correlation.tolist()},
        "singular_values": st.singular_values.tolist(),
        "warnings": list(st.warnings),
        "notes": list(res.notes),
        "jacobian": res.jacobian,
        "impacts_in_record": res.impacts_in_record,
        "record": _record_summary(res),
        "global": res.starts,
        "simulations": res.evaluations,
        "seconds": res.seconds,
    }
    if len(res.parts) > 1:
        out["records"] = [
            {
                "source": part["source"],
                "kind": part["kind"],
                "rows": int(np.asarray(part["t"]).size),
                "quantities": list(part["quantities"]),
                "noise": part["noise"],
            }
            for part in res.parts
        ]
    if res.profiles:
        out["profiles"] = {
            p.key: {
                "values": p.values.tolist(),
                "delta_chi2": p.delta.tolist(),
                "ci95": list(p.ci95),
            }
            for p in res.profiles
        }
    if res.laws:
        best = res.laws[0].aic
        out["model_selection"] = [
            {
                "law": lr.law,
                "aic": lr.aic,
                "bic": lr.bic,
                "delta_aic": lr.aic - best,
                "parameters": lr.k,
                "cost": lr.cost,
                "restitution": lr.restitution,
                "effective_restitution": lr.effective_restitution,
                "estimates": lr.values,
                "converged": lr.converged,
            }
            for lr in res.laws
        ]
        out["selected_law"] = res.law
    return out


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {v!r} as TOML")


def _tree(flat: dict[str, Any]) -> dict[str, Any]:
    root: dict[str, Any] = {}
    for key, v in flat.items():
        *parents, leaf = key.split(".")
        node = root
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = v
    return root


def _emit(table: dict[str, Any], prefix: str = "") -> str:
    """TOML text of a nested table: its own values under ``[prefix]``, then its sub-tables,
    separated by blank lines."""
    scalars = [f"{k} = {_toml_value(v)}" for k, v in table.items() if not isinstance(v, dict)]
    parts = []
    if scalars:
        parts.append((f"[{prefix}]\n" if prefix else "") + "\n".join(scalars))
    for k, v in table.items():
        if isinstance(v, dict):
            parts.append(_emit(v, f"{prefix}.{k}" if prefix else k))
    return "\n\n".join(p for p in parts if p)


def _plain(v: Any) -> Any:
    if isinstance(v, tuple):
        return [_plain(x) for x in v]
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    return v


def fitted_scenario_toml(res: FitResult, spec: FitSpec) -> str:
    """The scenario with the fitted values: ``extends`` the spec's scenario, then its
    overrides, the law and the fitted values (SI numbers written with their units)."""
    from braidsim.params import SCHEMA, builtin_names

    ref = spec.scenario_ref or res.scenario.name
    standalone = ref not in builtin_names() and not Path(ref).is_file()
    flat: dict[str, Any] = {}
    # a scenario given as a mapping or object has no file to extend: write all of it
    keys = [k for k, v in res.scenario.values.items() if v is not None] if standalone else []
    for key in [*keys, *spec.overrides]:
        v = res.scenario[key]
        if v is not None:
            flat[key] = _plain(v)
    flat["contact.track.model"] = res.law
    duration = max(float(np.max(np.asarray(part["t"]))) for part in res.parts)
    duration += max([0.0, *(float(v) for k, v in res.values.items() if is_offset(k))])
    if not isinstance(res.record, Record) or len(res.parts) > 1:
        duration = 1.2 * duration + 0.01  # the impact lists' runs (see ImpactProblem)
    flat["simulation.duration"] = f"{duration!r} s"
    for key, value in scenario_values(res.values).items():
        unit = SCHEMA[key].unit
        flat[key] = f"{value!r} {unit}" if unit else value
    for key, v in list(flat.items()):
        unit = SCHEMA[key].unit
        if isinstance(v, float) and unit and SCHEMA[key].kind == "float" and math.isfinite(v):
            flat[key] = f"{v!r} {unit}"
    head = [
        f"# {res.scenario.name}: the fitted scenario (braidsim fit, contact law {res.law})",
        f"# {_describe(res)}; fitted {', '.join(res.quantities)}",
    ]
    for i, k in enumerate(res.keys):
        unit = "s" if is_offset(k) else SCHEMA[k].unit
        head.append(
            f"# {k} = {res.stats.values[i]:.6g} +- {res.stats.stderr[i]:.3g} {unit} (1 se)".rstrip()
        )
    if any(is_offset(k) for k in res.keys):
        head.append(
            "# (the record's t = 0 is the model's t = record.time_offset: the record's "
            "times plus it are this scenario's)"
        )
    head.append("# Run: braidsim run THIS.toml")
    body = f"name = {json.dumps(res.scenario.name + '-fitted')}\n"
    if not standalone:
        body += f"extends = {json.dumps(ref)}\n"
    body += "\n"
    return "\n".join(head) + "\n" + body + _emit(_tree(flat)) + "\n"


def residual_figure(res: FitResult) -> Any:
    """Per fitted quantity: the record with the fitted model over the whole record and
    around its largest impact (top), the residuals scaled by the noise and their histogram
    against the standard normal density (below)."""
    from braidsim.plotting import new_figure

    qs = res.quantities
    assert isinstance(res.record, Record)
    fig = new_figure(8.0, 3.0 * len(qs) + 0.8)
    axes = fig.subplots(
        2 * len(qs), 2, height_ratios=[2, 1] * len(qs), width_ratios=[3, 1], squeeze=False
    )
    t = res.record.t
    scale = {"x": (1e3, "mm"), "acceleration": (1.0, "m/s$^2$"), "contact_force": (1.0, "N")}
    for i, q in enumerate(qs):
        f, unit = scale[q]
        d, m = res.record.columns[q] * f, res.prediction[q] * f
        r = (res.prediction[q] - res.record.columns[q]) / res.noise[q]
        ax, zoom = axes[2 * i]
        axr, hist = axes[2 * i + 1]
        for a in (ax, zoom):
            a.plot(t, d, ".", ms=1.5 if a is ax else 3, color="0.5", label="record")
            a.plot(t, m, "-", lw=0.8, color="C3", label=f"fit ({res.law})")
            a.grid(True, lw=0.3, alpha=0.6)
        for tk in res.onsets:
            ax.axvline(tk, color="C0", lw=0.4, alpha=0.4)
        k = int(np.argmax(np.abs(m - np.median(m))))
        w = max(20 * res.record.sample_interval, 1e-3)
        zoom.set_xlim(t[k] - w, t[k] + w)
        sel = np.abs(t - t[k]) <= w
        lo, hi = min(d[sel].min(), m[sel].min()), max(d[sel].max(), m[sel].max())
        zoom.set_ylim(lo - 0.08 * (hi - lo), hi + 0.08 * (hi - lo))
        zoom.set_title("largest impact", fontsize=8)
        zoom.tick_params(labelsize=7)
        ax.set_ylabel(f"{q} [{unit}]")
        ax.legend(fontsize=7, frameon=False, loc="upper right")
        axr.plot(t, r, ".", ms=1.2, color="C2")
        axr.axhline(0.0, color="0.3", lw=0.6)
        axr.set_ylabel("residual / $\\sigma$")
        axr.grid(True, lw=0.3, alpha=0.6)
        axr.set_xlabel("t [s]")
        edges = np.linspace(-4.5, 4.5, 37)
        hist.hist(np.clip(r, -4.5, 4.5), bins=edges, density=True, color="C2", alpha=0.6)
        z = np.linspace(-4.5, 4.5, 200)
        hist.plot(z, np.exp(-0.5 * z * z) / np.sqrt(2 * np.pi), color="0.2", lw=0.8)
        hist.set_xlabel("residual / $\\sigma$", fontsize=8)
        hist.tick_params(labelsize=7)
    lines = [
        f"{k} = {v:.6g} ± {1.96 * s:.2g}"
        for k, v, s in zip(res.keys, res.stats.values, res.stats.stderr, strict=True)
    ]
    fig.suptitle("\n".join(lines) + "  (95 %)", fontsize=7)
    return fig


def parts_figure(res: FitResult) -> Any:
    """The scaled residuals of every record and quantity against time (impact lists and
    several records)."""
    from braidsim.plotting import new_figure

    n = len(res.parts)
    fig = new_figure(8.0, 2.2 * n + 0.8)
    axes = np.atleast_1d(fig.subplots(n, 1, squeeze=False)[:, 0])
    for ax, part in zip(axes, res.parts, strict=True):
        t = np.asarray(part["t"])
        for j, q in enumerate(part["quantities"]):
            r = (part["model"][q] - part["data"][q]) / part["noise"][q]
            ax.plot(t, r, "o" if part["kind"] == "impacts" else ".", ms=3, color=f"C{j}", label=q)
        ax.axhline(0.0, color="0.3", lw=0.6)
        ax.set_ylabel("residual / $\\sigma$")
        ax.set_title(f"{part['source']} ({part['kind']})", fontsize=8)
        ax.grid(True, lw=0.3, alpha=0.6)
        ax.legend(fontsize=7, frameon=False)
    axes[-1].set_xlabel("t [s]")
    return fig


def parts_csv(res: FitResult) -> str:
    """One row per datum: record, kind, quantity, t, measured, model, scaled residual (SI)."""
    import io

    buf = io.StringIO()
    buf.write("record,kind,quantity,unit,t [s],measured,model,residual\n")
    units = {**QUANTITY_UNITS, **IMPACT_UNITS, "t": "s"}
    for part in res.parts:
        t = np.asarray(part["t"])
        for q in part["quantities"]:
            d, m = np.asarray(part["data"][q]), np.asarray(part["model"][q])
            r = (m - d) / part["noise"][q]
            u = units[q].replace("**", "^")
            src = json.dumps(part["source"])
            for row in zip(t, d, m, r, strict=True):
                buf.write(f"{src},{part['kind']},{q},{u}," + ",".join(f"{v:.10g}" for v in row))
                buf.write("\n")
    return buf.getvalue()


def profile_figure(res: FitResult) -> Any:
    """Delta chi^2 of each profiled key against its value, with the 95 % level 3.84 and
    the linearised interval."""
    from matplotlib.ticker import MaxNLocator

    from braidsim.plotting import new_figure

    n = len(res.profiles)
    fig = new_figure(3.2 * n + 0.4, 3.0)
    axes = np.atleast_1d(fig.subplots(1, n))
    for ax, p in zip(axes, res.profiles, strict=True):
        i = res.keys.index(p.key)
        ax.plot(p.values, p.delta, "o-", ms=3, color="C0", label="profile")
        v, s = res.stats.values[i], res.stats.stderr[i]
        ax.plot(p.values, ((p.values - v) / s) ** 2, "--", lw=0.8, color="0.4", label="quadratic")
        ax.axhline(3.841, color="C3", lw=0.8, label="95 % (3.84)")
        ax.axvspan(*res.stats.ci95[i], color="C3", alpha=0.1)
        ax.set_xlabel(f"{p.key} [{res.free[i].unit or '1'}]", fontsize=8)
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.tick_params(labelsize=7)
        ax.set_ylabel(r"$\Delta\chi^2$")
        ax.grid(True, lw=0.3, alpha=0.6)
        ax.legend(fontsize=6, frameon=False)
    return fig


def series_csv(res: FitResult) -> str:
    assert isinstance(res.record, Record)
    cols = ["t [s]"]
    arrs = [res.record.t]
    for q in res.quantities:
        u = QUANTITY_UNITS[q].replace("**", "^")
        cols += [f"{q} [{u}]", f"{q}_model [{u}]", f"{q}_residual"]
        arrs += [
            res.record.columns[q],
            res.prediction[q],
            (res.prediction[q] - res.record.columns[q]) / res.noise[q],
        ]
    import io

    buf = io.StringIO()
    np.savetxt(
        buf, np.column_stack(arrs), delimiter=",", header=",".join(cols), comments="", fmt="%.10g"
    )
    return buf.getvalue()


def write_report(res: FitResult, spec: FitSpec, out: str | Path) -> dict[str, Any]:
    """Write the fit's files into ``out`` (whole or absent); return the summary with
    ``out`` and ``files``."""
    from braidsim.io import atomic_directory
    from braidsim.plotting import save

    data = summary(res)
    with atomic_directory(out, REPORT_KIND) as tmp:
        single = _single_series(res)
        table = "fitted_series.csv" if single else "fitted_residuals.csv"
        files = ["fit.json", "fitted_scenario.toml", "residuals.png", table]
        (tmp / "fitted_scenario.toml").write_text(fitted_scenario_toml(res, spec), encoding="utf-8")
        save(residual_figure(res) if single else parts_figure(res), tmp / "residuals.png")
        if res.profiles:
            save(profile_figure(res), tmp / "profiles.png")
            files.append("profiles.png")
        (tmp / table).write_text(series_csv(res) if single else parts_csv(res), encoding="utf-8")
        data = {**data, "out": str(Path(out)), "files": files}
        from braidsim.provenance import version

        (tmp / "fit.json").write_text(
            json.dumps(
                json_safe({"braidsim_version": version(), **data}), indent=1, allow_nan=False
            )
            + "\n",
            encoding="utf-8",
        )
    return data
