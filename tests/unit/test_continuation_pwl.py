"""Continuation of braidsim's impact oscillator against the closed-form piecewise-linear
reference (``tests/reference/pwl_oscillator.py``: orbits by matching the exact solutions of
the linear phases, multipliers from phase exponentials and saltation matrices).

braidsim's side runs the compiled :class:`~braidsim.core.ImpactOscillator` with a
:class:`~braidsim.core.KelvinVoigtContact` law that may pull, through
:class:`braidsim.continuation.ModelSystem` (Newton shooting on the finite-difference map).
"""

from __future__ import annotations

import numpy as np
import pytest

from braidsim.continuation import seed_orbit
from braidsim.continuation.branch import continue_orbit, orbit_at
from braidsim.continuation.orbit import recut
from reference import pwl_oscillator as pwl
from reference.pwl_braidsim import oscillator_system


@pytest.mark.parametrize("name", ["stable_p1", "stable_p1_stiff"])
def test_periodic_orbit_and_multipliers(name: str) -> None:
    ref = pwl.periodic_orbit(pwl.PARAMETER_SETS[name], 1, pwl.ORBIT_GUESSES[(name, 1)])
    system = oscillator_system(ref.params)
    o = seed_orbit(system, {}, 1, transient_cycles=200, method="fd")
    o0 = recut(o, system, 0.0, method="fd")  # the reference's section, t = 0
    assert o0.cuts[0].modes == (0, 0)
    scale = np.array([ref.params.gap, ref.params.gap * ref.params.force_frequency])
    assert np.all(np.abs(o0.z[0] - ref.z_section) < 1e-7 * scale)
    assert o0.profile.impacts == ref.impacts == 1
    mu_ref = np.sort_complex(pwl.floquet_multipliers(ref))
    assert np.allclose(np.sort_complex(o0.multipliers), mu_ref, atol=1e-5)


def test_period_doubling_in_the_forcing_frequency() -> None:
    """The period-1 orbit continued in Omega from 2.2 rad/s doubles its period where the
    reference's det(M + I) vanishes, and the switched branch at Omega = 2.4 rad/s is the
    reference's period-2 orbit."""
    base = pwl.PARAMETER_SETS["period_doubled"]
    p = base._replace(force_frequency=2.2)
    system = oscillator_system(p)
    o = seed_orbit(system, {}, 1, transient_cycles=200, method="fd")
    br = continue_orbit(system, o, "force_frequency", 2.45, method="fd", max_depth=1, max_points=60)
    (pd,) = [s for s in br.special if s.type == "period_doubling"]
    w_pd, _ = pwl.critical_parameter(base, "force_frequency", 2.2, 2.4, guess=None)
    assert pd.value == pytest.approx(w_pd, rel=1e-5)
    # the unstable period-1 orbit at 2.4 rad/s
    ref1 = pwl.periodic_orbit(base, 1, pwl.ORBIT_GUESSES[("period_doubled", 1)])
    o1 = recut(orbit_at(system, br, 2.4, method="fd"), system, 0.0, method="fd")
    assert np.allclose(
        np.sort_complex(o1.multipliers), np.sort_complex(pwl.floquet_multipliers(ref1)), atol=1e-4
    )
    # the stable period-2 orbit at 2.4 rad/s
    ref2 = pwl.periodic_orbit(base, 2, pwl.ORBIT_GUESSES[("period_doubled", 2)])
    (child,) = br.children
    o2 = recut(orbit_at(system, child, 2.4, method="fd"), system, 0.0, method="fd")
    scale = np.array([base.gap, base.gap * base.force_frequency])
    # the period-2 orbit seen from t = 0 or from t = T: the same orbit, either half first
    z_alt = o2.z[0]
    assert o2.stable
    mu2 = np.sort_complex(pwl.floquet_multipliers(ref2))
    assert np.allclose(np.sort_complex(o2.multipliers), mu2, atol=1e-4)
    diff = np.abs(z_alt - ref2.z_section) / scale
    other = pwl.stroboscopic_map(base, ref2.z_section, 0.0, 1)
    diff2 = np.abs(z_alt - other) / scale
    assert min(diff.max(), diff2.max()) < 1e-6
