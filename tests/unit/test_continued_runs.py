"""A run cut in two and continued (``simulate(..., start=result.final_state)``): transfers at
the cut, sample grids that end on the run's end, sensitivities of a continued run, and flow
maps that start after t = 0."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

import braidsim
from braidsim.core import layout as L
from braidsim.errors import InputError
from braidsim.sensitivity import flow_map

TRANSFERS = {"transfer.period": "0.1 s", "transfer.first": "0.05 s"}


@pytest.mark.parametrize(
    "cut",
    [
        0.25,  # a transfer exactly at the cut: the first part stops before making it
        0.15,  # the transfer is computed as 0.05 + 0.1 = 0.15000000000000002, 3e-17 s after
        0.2500000000000001,  # 1e-17 s after one: the first part ends on a step of 1e-17 s
    ],
)
def test_a_run_cut_at_a_transfer_makes_it_once(cut: float) -> None:
    """Cut at a transfer, the two parts make every transfer of the unbroken run, once.
    (Before: at 0.25 neither part made it, at 0.15 the continuation failed on a step of
    3e-17 s, at 0.2500000000000001 on the steps grown from the first part's last one.)"""
    sc = braidsim.load_scenario("paper-3.3", overrides=TRANSFERS)
    whole = braidsim.simulate(sc, 0.5, series=False)
    first = braidsim.simulate(sc, cut, series=False)
    rest = braidsim.simulate(sc, 0.5 - cut, start=first.final_state, series=False)
    assert whole.stats["transfers"] == 5
    assert first.stats["transfers"] + rest.stats["transfers"] == 5
    # the cut meets no contact here, so the rows add up (measured: final x 2e-14 m apart)
    assert len(first.impacts) + len(rest.impacts) == len(whole.impacts)
    assert rest.final["x"] == pytest.approx(whole.final["x"], abs=1e-9)


def test_a_continued_run_makes_a_transfer_at_its_start() -> None:
    sc = braidsim.load_scenario("paper-3.3", overrides=TRANSFERS)
    first = braidsim.simulate(sc, 0.25, sample_interval=0.05)
    rest = braidsim.simulate(sc, 0.1, start=first.final_state, sample_interval=0.05)
    kinds = rest.series["kind"]
    at_start = rest.series["t"][kinds == L.KIND_TRANSFER]
    assert at_start.tolist() == [0.25]
    assert first.series["t"][first.series["kind"] == L.KIND_TRANSFER].tolist() == [
        0.05,
        pytest.approx(0.15, abs=1e-15),
    ]


def _samples(res: braidsim.Result) -> np.ndarray:
    return res.series["t"][res.series["kind"] == L.KIND_SAMPLE]


def test_the_sample_grid_ends_on_the_end_of_the_run() -> None:
    """0.3 s / 1e-5 s: 30000 * 1e-5 rounds to 0.30000000000000004, past the end, and that
    sample was never written; it is now the end itself."""
    res = braidsim.simulate("paper-3.3", 0.3, record_events=False)
    t = _samples(res)
    assert t.size == 30001
    assert t[-1] == 0.3
    assert t[1] == 1e-5


def test_a_continued_run_samples_to_its_end() -> None:
    first = braidsim.simulate("paper-3.3", 0.1, series=False)
    rest = braidsim.simulate("paper-3.3", 0.2, start=first.final_state, sample_interval=0.01)
    t = _samples(rest)
    assert t.size == 21
    assert t[0] == 0.1
    assert t[-1] == 0.1 + 0.2  # the end of the run, as the solver computes it


def test_a_widened_grid_keeps_the_points_of_the_grid_asked_for() -> None:
    """A series over its memory budget keeps every k-th sample of the asked grid: the same
    times, to the bit, as the full grid's (before: multiples of k dt, a few ulps off)."""
    full = _samples(braidsim.simulate("paper-3.3", 0.05, record_events=False))
    budget = 8 * len(braidsim.core.CARRIER_COLUMNS) * 100
    wide = _samples(
        braidsim.simulate("paper-3.3", 0.05, record_events=False, max_series_bytes=budget)
    )
    k = round((wide[1] - wide[0]) / (full[1] - full[0]))
    assert k > 1 and wide.size <= 100
    np.testing.assert_array_equal(wide, full[::k][: wide.size])


def test_sensitivities_of_a_continued_run() -> None:
    """A continued run's sensitivities are its own, its start state held fixed: zero at its
    start; a key of the initial state, which the start replaces, is refused."""
    first = braidsim.simulate("paper-3.3", 0.01, series=False)
    with pytest.raises(InputError, match=r"initial\.x with start"):
        braidsim.simulate("paper-3.3", 0.01, start=first.final_state, sensitivities=["initial.x"])
    rest = braidsim.simulate(
        "paper-3.3",
        0.01,
        start=first.final_state,
        sensitivities=["contact.track.restitution"],
        series=False,
    )
    assert np.all(np.isfinite(rest.sensitivity.final))


def test_a_flow_map_from_a_later_time_moves_its_own_transfers() -> None:
    """The tangent of a transfer time along transfer.period is its index k (t_k = first +
    k period): a flow map from t0 > 0 takes the k of its own transfers (before, those of a
    run from 0 of the same length: the derivative of the final state came out half the
    central differences' here)."""
    sc = braidsim.load_scenario(
        "paper-3.3",
        overrides={
            "transfer.period": "0.1 s",
            "transfer.first": "0.05 s",
            "simulation.rtol": 1e-12,
            "simulation.atol_position": 1e-16,
            "simulation.atol_velocity": 1e-13,
        },
    )
    t0, t1, y0 = 0.12, 0.3, [2e-5, 0.0]
    fm = flow_map(sc, t0, t1, y0=y0, keys=["transfer.period"])
    # (the quotient's truncation error is 3e-4 at h = 1e-6 here, 4e-6 at 1e-7)
    h = 1e-7
    ends = [
        flow_map(sc, t0, t1, y0=y0, overrides={"transfer.period": 0.1 + s * h}).y1 for s in (1, -1)
    ]
    fd = (ends[0] - ends[1]) / (2 * h)
    assert math.isfinite(fd[1]) and abs(fd[1]) > 1.0
    np.testing.assert_allclose(fm.jac_p[:, 0], fd, rtol=2e-5)


def test_a_taylor_run_cut_at_an_onset_continues_with_its_onset_step() -> None:
    """Cut at an onset, the first contact step is still to be taken: the state carries its
    error exponent and its pair, and the continuation takes it as the onset series (with
    the pair unknown it took a Dormand-Prince step there). The peak force then comes out
    as the uninterrupted run's (measured: the same bits in the first three contacts)."""
    sc = braidsim.load_scenario("paper-3.3", overrides={"simulation.integrator": "taylor"})
    whole = braidsim.simulate(sc, 0.02, series=False)
    onset = float(whole.episodes["t"][1])
    first = braidsim.simulate(sc, onset, series=False)
    state = first.final_state
    assert state.onset_q > 0.0 and state.onset_pair == 0
    rest = braidsim.simulate(sc, 0.02 - onset, start=state, series=False)
    assert rest.episodes["peak_force"][0] == pytest.approx(
        whole.episodes["peak_force"][1], rel=1e-12
    )


def test_a_contact_open_at_a_cut_that_is_a_transfer_joins_to_the_uninterrupted_row() -> None:
    """A transfer at the cut ends the contact open there, in the continuation, at its start:
    its row there is an `initial` row of zero duration marked `cut_by_transfer`, and joined
    to the first part's `ongoing` row it gives the uninterrupted run's row (start, end,
    wall, approach speed, and the cut)."""
    probe = braidsim.simulate("paper-3.3", 0.02, series=False).impacts.iloc[3]
    cut = float(probe.t + 0.4 * probe.duration)
    sc = braidsim.load_scenario(
        "paper-3.3", overrides={"transfer.period": "1 s", "transfer.first": f"{cut!r} s"}
    )
    whole = braidsim.simulate(sc, 0.03, series=False).impacts
    first = braidsim.simulate(sc, cut, series=False)
    rest = braidsim.simulate(sc, 0.03 - cut, start=first.final_state, series=False).impacts
    before, after = first.impacts.iloc[-1], rest.iloc[0]
    assert before.ongoing and not before.cut_by_transfer
    assert after.initial and after.cut_by_transfer and after.duration == 0.0
    assert after.t == cut and after.wall == before.wall
    joined = whole.iloc[3]
    assert joined.cut_by_transfer and joined.t_end == pytest.approx(cut, abs=1e-15)
    assert before.t == pytest.approx(joined.t, abs=1e-12)
    assert before.velocity == pytest.approx(joined.velocity, rel=1e-9)
    assert max(before.peak_force, after.peak_force) == pytest.approx(joined.peak_force, rel=1e-9)
    # the rows after the cut are the uninterrupted run's (the contact made by the transfer
    # included, `initial` in both), to the integration error (measured: 6e-9 s by 0.028 s)
    assert len(first.impacts) + len(rest) == len(whole) + 1
    assert rest.initial.iloc[1] and whole.initial.iloc[4]
    np.testing.assert_allclose(rest["t"].iloc[1:], whole["t"].iloc[4:], rtol=0, atol=1e-7)


def test_the_pause_hook_sees_the_run_advance_and_changes_nothing(monkeypatch) -> None:
    """The command line's bar of simulated time (core.driver.PAUSE_HOOK) is called at each
    pause of the compiled loop with the run's time, increasing and inside the run; the
    results are those of the same run without it, bit for bit."""
    from braidsim.core import driver

    sc = braidsim.load_scenario("paper-3.3")
    plain = braidsim.simulate(sc, 0.05, series=False)
    monkeypatch.setattr(driver.L, "PAUSE_STEPS", 50)
    seen: list[float] = []
    token = driver.PAUSE_HOOK.set(seen.append)
    try:
        hooked = braidsim.simulate(sc, 0.05, series=False)
    finally:
        driver.PAUSE_HOOK.reset(token)
    assert len(seen) >= 5
    assert all(0.0 < a < b < 0.05 for a, b in itertools.pairwise(seen))
    assert hooked.impacts.equals(plain.impacts)
    assert hooked.final == plain.final
