"""The lean Dormand-Prince loop of ``benchmarks/lean_dp5.py`` integrates braidsim's model.

The benchmarks time braidsim against that loop, written apart from braidsim's kernel (its own
tableau code, event checks at 3 interior points instead of 8 plus a dip search, its own peak
search). The comparison means something only if both integrate the same equations: on
paper-3.3 (x only, 0.5 s, 33 contact episodes, chatter on the vibrating inner wall) every
episode must agree in wall, onset and end time and peak force, to well within the finer
accuracy level the benchmark times (1.2e-7 relative peak force) at tight tolerances, and
to the expected error at a moderate tolerance. The tight comparison is made at rtol 1e-13:
the lean loop trusts its error estimate on the first step of each contact, which the
Hertz onset makes 11 times too small, so at 1e-12 its own error is 1e-8 (braidsim's,
which corrects that step, 6e-10).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from braidsim import load_scenario, simulate

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import lean_dp5


def _both(rtol: float, atol_x: float, atol_v: float) -> tuple[np.ndarray, object]:
    sc = load_scenario("paper-3.3")
    tol = {
        "simulation.rtol": rtol,
        "simulation.atol_position": atol_x,
        "simulation.atol_velocity": atol_v,
    }
    res = simulate(sc, 0.5, overrides=tol, sample_interval=0.0, record_events=False)
    q = lean_dp5.lean_params(sc, res.stats["track_stiffness"], res.stats["track_damping_factor"])
    ep, _ = lean_dp5.run_lean(q, 0.5, sc["initial.x"], sc["initial.vx"], rtol, atol_x, atol_v, 1e-3)
    return ep, res.impacts


@pytest.mark.parametrize(
    ("rtol", "atol_x", "atol_v", "peak_tol", "time_tol"),
    [(1e-13, 1e-17, 1e-14, 1e-8, 1e-9), (1e-10, 1e-15, 1e-11, 1e-5, 1e-7)],
)
def test_lean_loop_matches_simulate_on_paper_3_3(
    rtol: float, atol_x: float, atol_v: float, peak_tol: float, time_tol: float
) -> None:
    ep, imp = _both(rtol, atol_x, atol_v)
    assert len(ep) == len(imp) == 33
    walls = np.where(imp["wall"].to_numpy() == "inner", -1.0, 1.0)
    np.testing.assert_array_equal(ep[:, lean_dp5.EP_WALL], walls)
    np.testing.assert_array_equal(ep[:, lean_dp5.EP_INITIAL] == 1.0, imp["initial"].to_numpy())
    np.testing.assert_allclose(ep[:, lean_dp5.EP_T], imp["t"].to_numpy(), rtol=0, atol=time_tol)
    np.testing.assert_allclose(
        ep[:, lean_dp5.EP_TEND], imp["t_end"].to_numpy(), rtol=0, atol=time_tol
    )
    np.testing.assert_allclose(
        ep[:, lean_dp5.EP_PEAK], imp["peak_force"].to_numpy(), rtol=peak_tol, atol=0
    )
    np.testing.assert_allclose(
        ep[:, lean_dp5.EP_V0], imp["latched_velocity"].to_numpy(), rtol=peak_tol, atol=0
    )


def _tight_reference() -> tuple[object, np.ndarray, object]:
    """(scenario, the lean loops' parameter vector, simulate's impacts) at rtol 1e-12."""
    sc = load_scenario("paper-3.3")
    ref = simulate(
        sc,
        0.5,
        overrides={
            "simulation.rtol": 1e-12,
            "simulation.atol_position": 1e-16,
            "simulation.atol_velocity": 1e-13,
        },
        sample_interval=0.0,
        record_events=False,
    )
    q = lean_dp5.lean_params(sc, ref.stats["track_stiffness"], ref.stats["track_damping_factor"])
    return sc, q, ref.impacts


def test_lean_dop853_loop_matches_simulate_on_paper_3_3() -> None:
    """The DOP853 variant of the loop (an experiment on what a higher-order pair buys)."""
    import lean_dop853

    sc, q, imp = _tight_reference()
    ep, _ = lean_dop853.run(q, 0.5, sc["initial.x"], sc["initial.vx"], 1e-11, 1e-16, 1e-12, 1e-3)
    assert len(ep) == len(imp)
    np.testing.assert_allclose(ep[:, lean_dp5.EP_T], imp["t"].to_numpy(), rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        ep[:, lean_dp5.EP_PEAK], imp["peak_force"].to_numpy(), rtol=1e-7, atol=0
    )


@pytest.mark.slow  # (the benchmark's Taylor prototype, its own compile: ~15 s)
@pytest.mark.parametrize(
    ("switch", "exit_steps", "peak_tol"),
    [("distance", False, 1e-8), ("step", False, 2e-8), ("distance", True, 1e-8)],
)
def test_lean_taylor_loop_matches_simulate_on_paper_3_3(
    switch: str, exit_steps: bool, peak_tol: float
) -> None:
    """The hybrid Taylor / DP5 loop (an experiment on what a Taylor method buys), with the
    DP5 steps chosen from the model's singularities or by the generic rule, and with the
    contacts' exits reached by steps in sigma = sqrt(p)."""
    import lean_taylor

    sc, q, imp = _tight_reference()
    ep, st = lean_taylor.run_taylor(
        q,
        0.5,
        sc["initial.x"],
        sc["initial.vx"],
        1e-12,
        1e-16,
        1e-13,
        1e-3,
        switch=switch,
        exit_steps=exit_steps,
    )
    assert len(ep) == len(imp) == 33
    assert st[lean_taylor.S_TAYLOR] > 0
    if exit_steps:
        # exit steps were taken (measured: 106 for 33 contacts at this tolerance)
        assert st[lean_taylor.S_SIGMA] >= 33
    else:
        assert st[lean_taylor.S_DP_CONTACT] > 0  # both kinds ran
    walls = np.where(imp["wall"].to_numpy() == "inner", -1.0, 1.0)
    np.testing.assert_array_equal(ep[:, lean_dp5.EP_WALL], walls)
    np.testing.assert_array_equal(ep[:, lean_dp5.EP_INITIAL] == 1.0, imp["initial"].to_numpy())
    # measured: onsets and ends 6e-12 s, peak forces and latched speeds 3e-10 relative with
    # the distance switch, 3.7e-9 with the generic one
    np.testing.assert_allclose(ep[:, lean_dp5.EP_T], imp["t"].to_numpy(), rtol=0, atol=1e-9)
    np.testing.assert_allclose(ep[:, lean_dp5.EP_TEND], imp["t_end"].to_numpy(), rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        ep[:, lean_dp5.EP_PEAK], imp["peak_force"].to_numpy(), rtol=peak_tol, atol=0
    )
    np.testing.assert_allclose(
        ep[:, lean_dp5.EP_V0], imp["latched_velocity"].to_numpy(), rtol=peak_tol, atol=0
    )
