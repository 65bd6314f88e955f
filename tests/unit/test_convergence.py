"""Event times of the compiled integrator converge at the order of the method.

Set-up: one elastic impact of a free mass (no loads, no friction, no wall motion) that
starts a gap d away from the wall and approaches it at v. Free flight is integrated exactly,
so the onset time is exact; the contact duration t_exit - t_onset is compared with the closed
form T of ``contact.hertz_impact_closed_form`` (Johnson 1985, Sect. 11.4).

The step is forced to a fixed h: ``simulation.max_step = h`` and tolerances so loose that
every step is accepted at h (checked: no rejected step). With h = T / (N + 1/2) the exit
always falls at the same fraction (1/2) of the step that contains it, so the error follows
C h^q with one constant C and the fitted slope of log(error) against log(h) is the order q.

The order seen also depends on the smoothness of the solution at the contact boundary. With
the force K p^n the acceleration behaves as s^n after onset (s the time since onset), so a step
that starts at the onset integrates s^n with a quadrature error O(h^(n+1)) in the velocity,
which shifts the exit time by the same order: q = min(5, n + 1) for non-integer n (for integer
n the onset step is exact and the step across the exit, whose late stages see the clamped
force, limits q to min(5, n + 2)). Hence:

* n = 3 (a smooth enough law): q = 5, the order of Dormand-Prince 5(4) and of its event
  location on the continuous extension;
* n = 3/2 (Hertz): q = 5/2, a property of the Hertz solution, not of the integrator; any
  Runge-Kutta method shows it at a fixed step (adaptive step control handles it by shrinking
  the steps next to the onset, where the error estimate sees it).
"""

from __future__ import annotations

import numpy as np
import pytest

from braidsim import contact
from braidsim.impact import FREE_MASS
from braidsim.params import load_scenario
from braidsim.simulate import simulate

MASS = 1.2  # kg
SPEED = 0.5  # m/s
N_STEPS = (24, 32, 48, 64, 96, 128)  # steps per contact duration (asymptotic range, error >> 1e-15)


def _fixed_step_errors(exponent: float, stiffness: float) -> tuple[np.ndarray, np.ndarray]:
    """Relative contact-duration errors at the fixed steps h = T / (N + 1/2)."""
    sc = load_scenario(
        "paper-3.1",
        overrides={
            "contact.track.model": "hertz",
            "contact.track.exponent": exponent,
            "contact.track.stiffness": stiffness,
            "carrier.mass": MASS,
            **FREE_MASS,
            "initial.vx": -SPEED,
            # every step accepted: the error norm stays far below 1 at these tolerances
            "simulation.rtol": 1e-2,
            "simulation.atol_position": 1.0,
            "simulation.atol_velocity": 1e3,
        },
    )
    T = contact.hertz_impact_closed_form(MASS, stiffness, exponent, SPEED)["contact_duration"]
    hs, errs = [], []
    for n in N_STEPS:
        h = T / (n + 0.5)
        gap = 3.3 * h * SPEED  # onset inside a step, after the first steps have grown to h
        res = simulate(
            sc,
            duration=gap / SPEED + 1.2 * T,
            sample_interval=0.0,
            overrides={"simulation.max_step": h, "initial.x": gap},
        )
        assert res.stats["rejected_steps"] == 0
        imp = res.impacts
        assert len(imp) == 1 and not imp["ongoing"].iloc[0]
        assert imp["t"].iloc[0] == pytest.approx(gap / SPEED, rel=1e-13)  # free flight is exact
        hs.append(h)
        errs.append(abs(imp["duration"].iloc[0] - T) / T)
    return np.array(hs), np.array(errs)


def _order(hs: np.ndarray, errs: np.ndarray) -> float:
    assert np.all(errs > 1e-13), errs  # above round-off: the slope means something
    return float(np.polyfit(np.log(hs), np.log(errs), 1)[0])


def test_event_time_converges_at_fifth_order_for_a_smooth_law() -> None:
    hs, errs = _fixed_step_errors(exponent=3.0, stiffness=2.5e10)
    q = _order(hs, errs)
    assert 4.5 <= q <= 6.0, (q, errs)
    assert errs[-1] < 1e-9


def test_hertz_event_time_order_is_limited_by_the_contact_onset() -> None:
    hs, errs = _fixed_step_errors(exponent=1.5, stiffness=2.5e10)
    q = _order(hs, errs)
    assert 2.2 <= q <= 2.9, (q, errs)
