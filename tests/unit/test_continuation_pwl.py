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


@pytest.mark.parametrize(("method", "atol"), [("fd", 1e-5), ("exact", 1e-9)])
@pytest.mark.parametrize("name", ["stable_p1", "stable_p1_stiff"])
def test_periodic_orbit_and_multipliers(name: str, method: str, atol: float) -> None:
    """The orbit and its multipliers, with the finite-difference map and with the exact
    variational map of the record (``braidsim.sensitivity.record_flow_map``)."""
    ref = pwl.periodic_orbit(pwl.PARAMETER_SETS[name], 1, pwl.ORBIT_GUESSES[(name, 1)])
    system = oscillator_system(ref.params)
    o = seed_orbit(system, {}, 1, transient_cycles=200, method=method)
    o0 = recut(o, system, 0.0, method=method)  # the reference's section, t = 0
    assert o0.cuts[0].modes == (0, 0)
    scale = np.array([ref.params.gap, ref.params.gap * ref.params.force_frequency])
    assert np.all(np.abs(o0.z[0] - ref.z_section) < 1e-7 * scale)
    assert o0.profile.impacts == ref.impacts == 1
    mu_ref = np.sort_complex(pwl.floquet_multipliers(ref))
    assert np.allclose(np.sort_complex(o0.multipliers), mu_ref, atol=atol)
    if method == "exact":
        np.testing.assert_allclose(o0.monodromy, pwl.monodromy(ref), rtol=0, atol=1e-9)


def test_exact_record_map_matches_finite_differences() -> None:
    """The exact flow map of the record against central differences of the same runs, over
    a period with an impact: d/d state, d/d fields (a field of the nested law too)."""
    from braidsim.continuation.fdmap import fd_flow_map
    from braidsim.sensitivity import record_flow_map

    ref = pwl.periodic_orbit(
        pwl.PARAMETER_SETS["stable_p1"], 1, pwl.ORBIT_GUESSES[("stable_p1", 1)]
    )
    system = oscillator_system(ref.params)
    keys = ("force_amplitude", "damping", "law.stiffness", "law.damping")
    prep = system.prepare({})
    T = ref.params.period
    ex = record_flow_map(prep.record, prep.options, 0.0, T, ref.z_section, keys=keys)
    fd = fd_flow_map(system, {}, 0.0, T, ref.z_section, keys=keys)
    assert len(ex.impacts) == 1
    np.testing.assert_allclose(ex.y1, fd.y1, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ex.jac_y, fd.jac_y, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(ex.jac_p, fd.jac_p, rtol=1e-5, atol=1e-7)
    # the impact's derivatives (onset, speed, peak force, depth, exit) along the state and
    # the keys, made when read (no contact is open at the section: the latched speeds'
    # columns are NaN here, zeros in the exact map)
    n = ref.z_section.size
    cols = [*range(n), *range(n + 2, n + 2 + len(keys))]
    assert fd.impact_sens.shape == ex.impact_sens.shape
    assert np.all(np.isnan(fd.impact_sens[:, n : n + 2]))
    a, b = ex.impact_sens[:, cols], fd.impact_sens[:, cols]
    # (a flow map integrates no energy: the dissipated energy's column is NaN in both)
    finite = np.isfinite(a)
    assert np.array_equal(finite, np.isfinite(b))
    assert np.all(finite[..., :-1]) and not np.any(finite[..., -1])
    a, b = a[..., :-1], b[..., :-1]
    scale = np.max(np.abs(a), axis=(0, 1))  # (per quantity)
    # (to 1e-7 of each quantity's largest derivative; the exit's in the law's damping is
    # 2e-4 relative, a derivative 2e4 times below its column's largest)
    assert np.all(np.abs(b - a) <= 1e-7 * scale)


@pytest.mark.parametrize("name", ["stable_p1", "stable_p1_stiff"])
def test_record_map_without_the_tangents_error_control(name: str) -> None:
    """``control_tangents=False`` integrates the same variational equations over the steps
    the state's error control chooses: on the linear wall, whose tangents' field is as
    smooth as the state's within each phase, the period's Jacobian still agrees with the
    closed-form monodromy to 1e-9 (measured 3e-11 and 5e-11, as with the error control);
    the Hertz carrier's, where it is not smooth, is the rough one of
    ``test_newton_iterates_on_rough_maps_and_takes_the_multipliers_from_an_accurate_one``."""
    from braidsim.sensitivity import record_flow_map

    ref = pwl.periodic_orbit(pwl.PARAMETER_SETS[name], 1, pwl.ORBIT_GUESSES[(name, 1)])
    prep = oscillator_system(ref.params).prepare({})
    T = ref.params.period
    for control in (True, False):
        fm = record_flow_map(
            prep.record, prep.options, 0.0, T, ref.z_section, control_tangents=control
        )
        np.testing.assert_allclose(fm.jac_y, pwl.monodromy(ref), rtol=0, atol=1e-9)
        np.testing.assert_allclose(fm.y1, ref.z_section, rtol=0, atol=1e-9)


@pytest.mark.parametrize(("method", "rel"), [("fd", 1e-5), ("exact", 1e-8)])
def test_period_doubling_in_the_forcing_frequency(method: str, rel: float) -> None:
    """The period-1 orbit continued in Omega from 2.2 rad/s doubles its period where the
    reference's det(M + I) vanishes, and the switched branch at Omega = 2.4 rad/s is the
    reference's period-2 orbit."""
    base = pwl.PARAMETER_SETS["period_doubled"]
    p = base._replace(force_frequency=2.2)
    system = oscillator_system(p)
    o = seed_orbit(system, {}, 1, transient_cycles=200, method=method)
    br = continue_orbit(
        system, o, "force_frequency", 2.45, method=method, max_depth=1, max_points=60
    )
    (pd,) = [s for s in br.special if s.type == "period_doubling"]
    w_pd, _ = pwl.critical_parameter(base, "force_frequency", 2.2, 2.4, guess=None)
    assert pd.value == pytest.approx(w_pd, rel=rel)
    # the unstable period-1 orbit at 2.4 rad/s
    ref1 = pwl.periodic_orbit(base, 1, pwl.ORBIT_GUESSES[("period_doubled", 1)])
    o1 = recut(orbit_at(system, br, 2.4, method=method), system, 0.0, method=method)
    assert np.allclose(
        np.sort_complex(o1.multipliers), np.sort_complex(pwl.floquet_multipliers(ref1)), atol=1e-4
    )
    # the stable period-2 orbit at 2.4 rad/s
    ref2 = pwl.periodic_orbit(base, 2, pwl.ORBIT_GUESSES[("period_doubled", 2)])
    (child,) = br.children
    o2 = recut(orbit_at(system, child, 2.4, method=method), system, 0.0, method=method)
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
