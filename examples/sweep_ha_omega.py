"""Where does the carrier stay on a vibrating track, and where does it chatter?

Runs the sweep of ``sweep_ha_omega.toml`` (track vibration amplitude h_a against horn-gear
speed omega, 17 x 25 one-second runs of the paper-3.3 carrier; 4.5-5.8 s wall, 6.0 s of CPU,
with the compiled code cached, on the shared 2-core development machine, 2026-11-30;
resumable: run it again after an interruption) and draws two heat maps over it:

* the regime of the track contact over the last 0.5 s (braidsim.batch: resting contact,
  impacts on one wall, impacts on both walls);
* the largest approach speed of those impacts (how hard the carrier hits).

Over both it draws docs/model.md §7's line h_a omega_h^2 = a_p with
a_p = (T1 cos phi + m r_c omega^2) / m: above it the wall's acceleration exceeds the one
pressing the carrier on, and the carrier cannot stay on the wall. The dashed line
h_a omega_h^2 = a_p pi (1 - e) / (1 + e) is where a carrier that already bounces can keep
one impact per vibration period (the period-1 orbit of the bouncing ball: Holmes, J. Sound
Vib. 84 (1982) 173; Luck & Mehta, Phys. Rev. E 48 (1993) 3988), with e the effective
restitution of the contact law. Between the two lines both states exist, and which one a run
ends in depends on its start. Every run starts as paper-3.3 does: x0 = 0 on a wall at
h(0) = h_a, an overlap released elastically, which launches the carrier the harder the larger
h_a; above about h_a = 0.25 mm it lands on orbits with impacts on both walls (one per
vibration period on each at 90 rpm, still there after 4 s). The paper's two cases are marked:
h_a = 0.12 mm at omega = 4 pi rad/s (paper-3.3, chatters, Fig. 11) and at 8 pi rad/s
(paper-3.4b, stays on the wall, Fig. 19).

Usage::

    python examples/sweep_ha_omega.py [--out ha_omega.zarr] [--figure sweep_ha_omega.png]
                                      [--spec SPEC.toml]

The same sweep from the command line::

    braidsim sweep examples/sweep_ha_omega.toml --out ha_omega.zarr
    braidsim sweep-plot ha_omega.zarr --metric regime --x omega --y h_a \\
        --unit omega=rpm --unit h_a=mm --out regime.png
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from braidsim.model import build_model
from braidsim.params import load_scenario
from braidsim.plotting import new_figure, save
from braidsim.sweep import load_spec, open_sweep, plot_sweep, run_sweep

HERE = Path(__file__).resolve().parent
RPM = 2.0 * math.pi / 60.0  # rad/s per rpm


def parser() -> argparse.ArgumentParser:
    """The example's options."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("ha_omega.zarr"), help="zarr store")
    # the default writes beside the store, never over the figure tracked in docs/img
    # (regenerate that one on purpose: --figure docs/img/sweep_ha_omega.png)
    ap.add_argument("--figure", type=Path, default=Path("sweep_ha_omega.png"))
    ap.add_argument(
        "--spec",
        type=Path,
        default=HERE / "sweep_ha_omega.toml",
        help="another sweep over the axes omega and h_a (e.g. a smaller grid, for a quick look)",
    )
    return ap


def main(argv: list[str] | None = None) -> None:
    args = parser().parse_args(argv)

    spec = load_spec(args.spec)
    summary = run_sweep(spec, args.out, resume=args.out.exists())
    print(json.dumps({k: summary[k] for k in ("store", "runs", "regimes", "failed_runs")}))
    ds = open_sweep(args.out).load()

    p = json.loads(ds.attrs["parameters"])
    m = p["carrier.mass"]
    load = p["yarn.tension_horizontal"] * math.cos(p["yarn.angle"])
    w_h = p["track.vibration_frequency"]
    e = build_model(load_scenario("paper-3.3")).track.effective_restitution
    omega = np.linspace(float(ds["omega"].min()), float(ds["omega"].max()), 200)
    a_p = (load + m * p["carrier.turning_radius"] * omega**2) / m
    h_rest = a_p / w_h**2  # h_a omega_h^2 = a_p
    h_orbit = h_rest * math.pi * (1.0 - e) / (1.0 + e)

    fig = new_figure(12.0, 4.6)
    axes = fig.subplots(1, 2)
    # plot_sweep refuses a unit for a name it does not draw: each plot gets its own
    axes_units = {"omega": "rpm", "h_a": "mm"}
    plot_sweep(
        ds,
        "regime",
        x="omega",
        y="h_a",
        units=axes_units,
        ax=axes[0],
        title="regime of the track contact, t = 0.5-1 s",
    )
    plot_sweep(
        ds,
        "track_max_approach_speed",
        x="omega",
        y="h_a",
        units={**axes_units, "track_max_approach_speed": "mm/s"},
        ax=axes[1],
        title="largest approach speed of an impact, t = 0.5-1 s",
    )
    for ax in axes:
        ax.plot(
            omega / RPM,
            h_rest * 1e3,
            "k-",
            lw=1.6,
            label=r"$h_a\omega_h^2 = a_p$ (docs/model.md §7)",
        )
        ax.plot(
            omega / RPM,
            h_orbit * 1e3,
            "k--",
            lw=1.2,
            label=rf"$h_a\omega_h^2 = a_p\,\pi(1-e)/(1+e)$, $e$ = {e:.3f}",
        )
        ax.plot([120, 240], [0.12, 0.12], "o", mfc="none", mec="k", ms=9, mew=1.5)
        for w, name in ((120, "paper-3.3"), (240, "paper-3.4b")):
            ax.annotate(
                name,
                (w, 0.12),
                (8, -14),
                textcoords="offset points",
                fontsize=8,
                bbox={"boxstyle": "round,pad=0.15", "fc": "white", "alpha": 0.8, "lw": 0},
            )
        ax.set_ylim(float(ds["h_a"].min()) * 1e3 - 0.01, float(ds["h_a"].max()) * 1e3 + 0.01)
        ax.set_xlim(float(ds["omega"].min()) / RPM - 7.5, float(ds["omega"].max()) / RPM + 7.5)
    axes[0].legend(loc="upper left", fontsize=7, framealpha=0.9)
    print(f"figure: {save(fig, args.figure)}")


if __name__ == "__main__":
    main()
