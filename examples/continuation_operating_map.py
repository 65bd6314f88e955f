"""Why the carrier chatters at omega = 4 pi and stays on the wall at 8 pi: a safe operating map.

The paper's carrier (paper-3.3: h_a = 0.12 mm at 60 Hz) chatters at the horn-gear speed
omega = 4 pi rad/s (Fig. 11) and rests on the track at 8 pi rad/s (paper-3.4b, Fig. 19).
This example follows the carrier's periodic orbits instead of sampling settled runs:

1. branches over the vibration amplitude h_a at omega = 4 pi and 8 pi rad/s: the orbit
   resting on the inner wall (period 1, no impact) up to its lift-off grazing, the orbit
   with one impact per vibration cycle from its fold (where it is born) to its period
   doubling, and the period-2 branch switched to there (stable solid, unstable dashed);
2. the operating map over (omega, h_a): the lift-off grazing curve, the fold curve and the
   period-doubling curve, over the brute-force regime map of the same range, with the
   rigid-contact bound h_a omega_h^2 = a_p, a_p = (T1 cos phi + m r_c omega^2) / m;
3. the (clearance, speed) map at h_a = 0.1 mm: the orbit with one impact per cycle on the
   inner wall, followed towards smaller track clearances, grazes the outer wall; that
   grazing followed in omega bounds the clearances at which the carrier strikes both
   walls; the resting orbit, followed down in omega, lifts off, and that lift-off followed
   in the clearance bounds the speeds at which the carrier can rest; over the brute-force
   regime map of the same range.

Below the fold curve the carrier can only rest; between the fold and lift-off curves resting
and bouncing coexist (which one a run ends in depends on its start); above the lift-off
curve the resting orbit no longer exists. At 4 pi the paper's 0.12 mm lies above the
lift-off curve, at 8 pi below it.

Usage::

    python examples/continuation_operating_map.py [--out continuation_example] [--small]

``--small`` runs a reduced version (fewer points, 2 x 2 regime maps, the maps up to
6 pi rad/s) for CI: 196 s of CPU with the default exact map on the development machine,
the compile cache warm (2026-12-01; 433 s earlier that day, before Newton's iterates took
maps without the tangents' error control), 41 s with ``--method fd``; the full run takes
about 4 minutes with ``--method fd``. Each stage is announced on stderr with
the time it starts at.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import braidsim
from braidsim.analysis.regimes import contact_loss_bound
from braidsim.continuation import ScenarioSystem, seed_orbit
from braidsim.continuation.branch import continue_orbit
from braidsim.continuation.plots import plot_branches, plot_operating_map
from braidsim.continuation.twopar import crossing_boundaries, trace_boundary
from braidsim.io import json_safe
from braidsim.plotting import new_figure, save

HA = "track.vibration_amplitude"
OMEGA = "horn_gear.angular_velocity"
CLEARANCE = "track.clearance"
MM = 1e-3


def regime_map(
    scenario: Any, key1: str, v1: np.ndarray, v2: np.ndarray, small: bool
) -> tuple[np.ndarray, np.ndarray, list[list[str]]]:
    """The brute-force regimes of settled runs on the grid ``v1`` (of ``key1``) x ``v2``
    (horn-gear speeds)."""
    from braidsim.analysis.runs import run_steady_states

    sets = [{key1: float(a), OMEGA: float(b)} for a in v1 for b in v2]
    states = run_steady_states(
        scenario,
        sets,
        transient_cycles=60 if small else 300,
        cycles=12 if small else 24,
        workers=1 if small else 0,
    )
    n2 = v2.size
    labels = [[states[i * n2 + j].regime.label for j in range(n2)] for i in range(v1.size)]
    return v1, v2, labels


def parser() -> argparse.ArgumentParser:
    """The example's options."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("continuation_example"))
    ap.add_argument("--small", action="store_true", help="reduced size (for CI)")
    ap.add_argument("--method", default="auto", help="flow map: auto, exact, fd")
    return ap


def branches_at(
    omega: float, hi: float, h_bounce: float, small: bool, method: str
) -> dict[str, Any]:
    """Resting and bouncing branches over h_a at the horn-gear speed ``omega``; the orbit
    with one impact per cycle is seeded by a run at ``h_bounce``."""
    sc = braidsim.load_scenario("paper-3.3", overrides={OMEGA: omega})
    system = ScenarioSystem(sc)
    npts = 30 if small else 120
    rest = seed_orbit(system, {HA: 0.02 * MM}, 1, method=method)
    out: dict[str, Any] = {"system": system}
    steps = {"step": 0.05, "max_step": 0.25} if small else {"step": 0.01, "max_step": 0.03}
    out["resting"] = continue_orbit(
        system, rest, HA, hi, method=method, switch=False, max_points=npts, **steps
    )
    try:  # the orbit with one impact per cycle
        bounce = seed_orbit(system, {HA: h_bounce}, 1, method=method)
        out["bouncing"] = continue_orbit(
            system,
            bounce,
            HA,
            hi,
            both_directions=True,
            bounds=(0.02 * MM, hi),
            method=method,
            max_points=npts,
            max_depth=1,
            **steps,
        )
    except braidsim.SimulationError:
        out["bouncing"] = None
    return out


_START = time.perf_counter()


def stage(what: str) -> None:
    """Announce a stage on stderr (the run is long and otherwise silent)."""
    print(f"[{time.perf_counter() - _START:6.0f} s] {what}", file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Run the example; returns the findings written to ``findings.json``."""
    args = parser().parse_args(argv)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    small = bool(args.small)
    w4, w8 = 4 * math.pi, 8 * math.pi
    stage("branches over h_a at omega = 4 pi rad/s (the first stage compiles the solver)")
    # a run from the paper's start settles on the orbit with one impact per cycle at 0.1 mm
    # (4 pi: the brute-force diagram) and at 0.28 mm (8 pi); just above the lift-off at
    # 8 pi (0.33-0.36 mm) it settles on a chattering orbit or one that strikes both walls
    res4 = branches_at(w4, 0.2 * MM if small else 0.3 * MM, 0.1 * MM, small, args.method)
    stage("branches over h_a at omega = 8 pi rad/s")
    res8 = branches_at(w8, 0.4 * MM, 0.28 * MM, small, args.method)
    findings: dict[str, Any] = {}
    fig = new_figure(11.0, 4.4)
    for i, (w, res) in enumerate(((w4, res4), (w8, res8))):
        ax = fig.add_subplot(1, 2, i + 1)
        brs = [res["resting"]] + (res["bouncing"].all_branches() if res["bouncing"] else [])
        plot_branches(brs, title=f"omega = {w / math.pi:.0f} pi rad/s", ax=ax)
        ax.axvline(0.12, color="0.4", lw=0.8, ls=":")
        tag = f"{w / math.pi:.0f}pi"
        findings[tag] = {
            "lift_off_h_a": [s.value for s in res["resting"].special if s.type == "grazing"][:1],
            "special_points": [
                s.to_dict() for b in brs for s in b.special if s.type != "grazing" or b is brs[0]
            ],
            "bound_h_a": contact_loss_bound(res["system"].scenario)["critical_amplitude"],
            "bound_h_a_with_friction": contact_loss_bound(res["system"].scenario)[
                "critical_amplitude_with_friction"
            ],
        }
    save(fig, out / "continuation_branches.png")
    stage(f"wrote {out / 'continuation_branches.png'}; the special points followed in omega")

    # the operating map: the special points of the 4 pi branches followed in omega
    system = res4["system"]
    curves = []
    to_w = 6 * math.pi if small else 10 * math.pi
    steps = 1 if small else 8
    targets = (to_w,) if small else (to_w, 3 * math.pi)
    sources = [(res4["resting"], "grazing")]
    if res4["bouncing"] is not None:
        sources += [(res4["bouncing"], "fold"), (res4["bouncing"], "period_doubling")]
    for br, kind in sources:
        for sp in [s for s in br.special if s.type == kind][:1]:
            for target in targets:
                curves.append(
                    trace_boundary(
                        system,
                        br,
                        sp,
                        OMEGA,
                        target,
                        steps=steps,
                        method=args.method,
                        range1=(0.02 * MM, 0.6 * MM),
                    )
                )
    n1, n2 = (2, 2) if small else (14, 12)
    stage("the brute-force regime map over (omega, h_a)")
    regimes = regime_map(
        system.scenario,
        HA,
        np.linspace(0.03 * MM, 0.3 * MM if small else 0.55 * MM, n1 if small else 18),
        np.linspace(3 * math.pi, to_w, n2),
        small,
    )
    ww = np.linspace(3 * math.pi, to_w, 60)
    bound = [contact_loss_bound(system.scenario.with_overrides({OMEGA: float(x)})) for x in ww]
    fig = plot_operating_map(
        curves,
        regimes=regimes,
        marks=[(0.12 * MM, w4, "paper-3.3 (Fig. 11)"), (0.12 * MM, w8, "paper-3.4b (Fig. 19)")],
        bound=(ww, np.array([b["critical_amplitude"] for b in bound])),
    )
    save(fig, out / "continuation_operating_map.png")
    stage(f"wrote {out / 'continuation_operating_map.png'}; the (clearance, speed) map")

    # the (clearance, speed) map at h_a = 0.1 mm: the orbit with one impact per cycle on
    # the inner wall, continued towards smaller clearances, grazes the outer wall
    sc_c = braidsim.load_scenario("paper-3.3", overrides={OMEGA: w4, HA: 0.1 * MM})
    sys_c = ScenarioSystem(sc_c)
    o = seed_orbit(sys_c, {CLEARANCE: 3 * MM}, 1, method=args.method)
    br_c = continue_orbit(
        sys_c,
        o,
        CLEARANCE,
        0.3 * MM,
        method=args.method,
        switch=False,
        max_points=40,
        step=0.05,
        max_step=0.25,
    )
    curves_c = []
    for sp in [s for s in br_c.special if s.type == "grazing"][:1]:
        # towards higher speeds, up to where the family ends in a fold (about 17.2 rad/s),
        # in steps of a third of the range: the family's grazing and that of the unstable
        # family it meets there lie close together, and the first step's direction is a
        # guess (steps as long as an eighth of the range landed on the other family)
        curves_c.append(
            trace_boundary(
                sys_c,
                br_c,
                sp,
                OMEGA,
                6 * math.pi,
                steps=1 if small else 3,
                method=args.method,
                range1=(0.2 * MM, 3 * MM),
            )
        )
    # the resting orbit's lift-off does not depend on the clearance: a branch over the
    # clearance never meets it, one over the speed does
    br_x, curves_x = crossing_boundaries(
        sys_c,
        CLEARANCE,
        1.2 * MM,
        OMEGA,
        6 * math.pi,  # above the fold curve: only the resting orbit exists there
        3 * math.pi,
        0.2 * MM,
        steps=steps,
        method=args.method,
        range1=(0.2 * MM, 1.2 * MM),
        range2=(3 * math.pi, to_w),
        branch_options={"max_points": 40, "step": 0.05, "max_step": 0.25},
    )
    curves_c += curves_x
    stage("the brute-force regime map over (omega, clearance)")
    regimes_c = regime_map(
        sc_c,
        CLEARANCE,
        np.linspace(0.2 * MM, 1.2 * MM, n1),
        np.linspace(3 * math.pi, to_w, n2),
        small,
    )
    fig = plot_operating_map(
        curves_c,
        regimes=regimes_c,
        keys=(CLEARANCE, OMEGA),
        title="(clearance, speed) at h_a = 0.1 mm: lift-off and outer-wall grazing",
        legend_loc="upper right",
    )
    save(fig, out / "continuation_clearance_map.png")
    findings["clearance_curves"] = [c.to_dict() for c in curves_c]
    findings["clearance_special_points"] = [s.to_dict() for s in br_c.special]
    findings["clearance_cross_special_points"] = [s.to_dict() for s in br_x.special]
    findings["curves"] = [c.to_dict() for c in curves]
    # strict JSON: a value that does not exist (NaN) is null, as in every braidsim output
    text = json.dumps(json_safe(findings), indent=1, allow_nan=False)
    (out / "findings.json").write_text(text, encoding="utf-8")
    stage(f"wrote {out / 'continuation_clearance_map.png'} and {out / 'findings.json'}")
    return findings


if __name__ == "__main__":
    main()
