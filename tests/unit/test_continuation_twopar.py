"""Two-parameter continuation of special points against closed forms.

* A period doubling of the piecewise-linear impact oscillator followed in (Omega, F) on the
  augmented system (shooting equations + det(M + I)): each point against the reference's
  own period doubling in Omega at that F (closed-form phases matched, Brent's method on
  det(M + I); ``tests/reference/pwl_oscillator.py``).
* The grazing of the oscillator's orbit without impacts followed in (Omega, F) through
  resonance, where the curve turns back in F: each point against the closed form
  F = g |k - m Omega^2 + i c Omega| (the steady state's amplitude reaching the wall).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from braidsim.continuation import ModelSystem, seed_orbit
from braidsim.continuation.branch import continue_orbit
from braidsim.continuation.twopar import bifurcation_function, trace_boundary
from braidsim.errors import InputError
from reference import pwl_oscillator as pwl
from reference.pwl_braidsim import braidsim_oscillator, oscillator_system

W, F = "force_frequency", "force_amplitude"


@pytest.fixture(scope="module")
def doubling():
    base = pwl.PARAMETER_SETS["period_doubled"]
    system = oscillator_system(base._replace(force_frequency=2.2))
    o = seed_orbit(system, {}, 1, transient_cycles=200, method="fd")
    br = continue_orbit(system, o, W, 2.45, method="fd", switch=False, max_points=60)
    (pd,) = [s for s in br.special if s.type == "period_doubling"]
    return base, system, br, pd


@pytest.mark.parametrize("to", [1.5, 0.5])
def test_period_doubling_curve_matches_the_closed_form(doubling, to: float) -> None:
    base, system, br, pd = doubling
    c = trace_boundary(
        system, br, pd, F, to, steps=4, method="fd", range1=(1.5, 3.5), range2=(0.5, 1.5)
    )
    assert c.stop.startswith("left the range of force_amplitude")
    assert len(c.p1) >= 4
    assert c.p2[0] == pytest.approx(1.0) and c.p2[-1] == pytest.approx(to)
    for w, f in zip(c.p1, c.p2, strict=True):
        ref, _ = pwl.critical_parameter(
            base._replace(force_amplitude=f), W, w - 0.02, w + 0.02, steps=2
        )
        assert w == pytest.approx(ref, rel=1e-7)
    assert max(abs(r) for r in c.residuals) < 1e-6


def test_grazing_curve_turns_back_through_resonance() -> None:
    """Below resonance the orbit without impacts grazes the wall at a forcing amplitude
    that falls as Omega rises, above resonance at one that rises again: followed from
    F = 0.06 N towards smaller F, the curve passes its lowest F near Omega = 1 rad/s and
    comes back up to F = 0.06 N on the other side."""
    p = pwl.PARAMETER_SETS["stable_p1"]._replace(
        force_amplitude=0.06, force_frequency=0.5, damping=0.3
    )
    system = oscillator_system(p)
    o = seed_orbit(system, {}, 1, transient_cycles=200, method="fd")
    assert o.profile.impacts == 0
    br = continue_orbit(system, o, W, 0.9, method="fd", switch=False, max_points=60)
    (g,) = [s for s in br.special if s.type == "grazing"]

    def f_graze(w: float) -> float:
        return p.gap * abs(complex(p.stiffness - p.mass * w * w, p.damping * w))

    assert f_graze(g.value) == pytest.approx(0.06, rel=1e-6)
    c = trace_boundary(system, br, g, F, 0.02, steps=3, method="fd", range1=(0.5, 1.5))
    w, f = np.array(c.p1), np.array(c.p2)
    for wi, fi in zip(w, f, strict=True):
        assert fi == pytest.approx(f_graze(wi), rel=1e-6)
    # down through the lowest grazing amplitude and up again: F turns back
    i = int(np.argmin(f))
    assert 0 < i < f.size - 1
    assert np.all(np.diff(f[: i + 1]) < 0) and np.all(np.diff(f[i:]) > 0)
    assert np.all(np.diff(w) > 0)
    assert f[i] < 1.1 * min(f_graze(x) for x in np.linspace(0.9, 1.1, 2001))
    assert c.stop == "left the range of force_amplitude at 0.06"
    assert f[-1] == pytest.approx(0.06) and w[-1] > 1.2


def test_test_functions_and_bad_input(doubling) -> None:
    _, system, br, pd = doubling
    M = np.diag([-1.0, 0.5])
    assert bifurcation_function("period_doubling", M) == pytest.approx(0.0)
    assert bifurcation_function("fold", np.diag([1.0, 0.5])) == pytest.approx(0.0)
    r = 1.0 + 1e-3
    rot = r * np.array([[math.cos(1.0), -math.sin(1.0)], [math.sin(1.0), math.cos(1.0)]])
    assert bifurcation_function("neimark_sacker", rot) == pytest.approx(1e-3)
    with pytest.raises(InputError, match="steps"):
        trace_boundary(system, br, pd, F, 1.5, steps=0)
    with pytest.raises(InputError, match="force_amplitud"):
        trace_boundary(system, br, pd, "force_amplitud", 1.5)


def test_neimark_sacker_of_the_linear_oscillator() -> None:
    """Without a wall the forced oscillator m x'' + c x' + k x = F cos(Omega t) is linear:
    its orbit's multipliers are exp(lambda T), lambda = -c / 2m +- i sqrt(k/m - c^2/4m^2), a
    complex pair of modulus exp(-c T / 2m) that crosses the unit circle at c = 0 whatever
    k is. Continued in c from 0.05 to -0.05 N s/m the branch has one Neimark-Sacker point,
    at c = 0; followed in k it stays at c = 0."""
    p = pwl.PARAMETER_SETS["stable_p1"]._replace(gap=math.inf, damping=0.05)
    system = ModelSystem(braidsim_oscillator(p), length_scale=1.0)
    o = seed_orbit(system, {}, 1, transient_cycles=400, method="fd")
    T = 2 * math.pi / p.force_frequency
    lam = complex(-p.damping / 2, math.sqrt(p.stiffness - p.damping**2 / 4))
    mu = np.exp(lam * T)
    assert np.allclose(
        np.sort_complex(o.multipliers), np.sort_complex([mu, mu.conjugate()]), atol=1e-6
    )
    br = continue_orbit(system, o, "damping", -0.05, method="fd", switch=False, max_points=40)
    (ns,) = [s for s in br.special if s.type == "neimark_sacker"]
    assert abs(ns.value) < 1e-8
    assert ns.orbit is not None and np.allclose(np.abs(ns.orbit.multipliers), 1.0, atol=1e-7)
    c = trace_boundary(
        system,
        br,
        ns,
        "stiffness",
        1.5,
        steps=2,
        method="fd",
        range1=(-0.05, 0.05),
        range2=(0.7, 1.5),
    )
    assert len(c.p1) >= 3 and c.p2[-1] == pytest.approx(1.5)
    assert max(abs(x) for x in c.p1) < 1e-8


@dataclass
class _Side:
    """The branch's orbit before the grazing, as the stand-ins below need it."""

    values: dict
    profile: object


class _TwoFamilies:
    """A stand-in for the grazing plane (scaled coordinates = parameters): this family's
    grazing lies on the line q1 = 0.5; a coexisting family's, 0.3 to its right, is what the
    search finds on the long lines of a long step (span > 0.3)."""

    s1 = s2 = 1.0

    def __init__(self, *args) -> None:
        self.calls = 0
        self.known: list = []

    def lam(self, q):
        return float(q[0]), float(q[1])

    def locate(self, q, n, first, span):
        self.calls += 1
        q1 = 0.8 if span > 0.3 else 0.5
        return np.array([q1, q[1]]), 0.0, None


def _trace_stand_in(monkeypatch, plane: type, hmax: float):
    """A grazing curve of the parameters (a, b) in the box [0, 0.7] x [0, 1] traced on a
    stand-in plane, from the branch's grazing at a = 0.5, b = 0.1."""
    from types import SimpleNamespace

    from braidsim.continuation import twopar

    monkeypatch.setattr(twopar, "_GrazingPlane", plane)
    monkeypatch.setattr(twopar, "grazing_name", lambda sp, side=None: "grazing")
    side = _Side({"a": 0.45, "b": 0.1}, SimpleNamespace(approach=math.nan))
    sp = SimpleNamespace(orbit=None, value=0.5, type="grazing", period=1, detail="", other=None)
    return twopar._trace_grazing(
        None, sp, side, "a", "b", (0.0, 0.7, 0.0, 1.0), 1.0,
        hmax=hmax, hmin=1e-3, window=0.01, npts=100, method="fd", tol=1e-9, on_point=None,
    )  # fmt: skip


def test_a_grazing_curve_is_not_ended_by_another_familys_grazing_out_of_range(monkeypatch):
    """The point a long step finds on the other family lies beyond the range of the first
    parameter: it is a jump (far off the prediction), so the step is shortened and this
    family's curve goes on; it must not end the curve as 'left the range'."""
    curve = _trace_stand_in(monkeypatch, _TwoFamilies, hmax=0.2)
    assert curve.stop == "left the range of b at 1"
    assert np.allclose(curve.p1, 0.5)
    assert curve.p2[-1] > 0.85
    assert all(0.0 <= b <= 1.0 for b in curve.p2)


class _EdgeFromAfar(_TwoFamilies):
    """A stand-in whose grazing lies on q1 = 0.5 and whose search along the range's edge
    (q2 = 1, the line along q1) finds nothing from a last point more than 0.1 below the
    edge: carried that far, Newton's method fell onto a coexisting orbit (paper-3.3's
    lift-off curve from 4 pi up to 10 pi rad/s with the exact map)."""

    last = 0.0

    def locate(self, q, n, first, span):
        self.calls += 1
        if abs(n[1]) == 0.0 and q[1] == 1.0:
            return (np.array([0.5, 1.0]), 0.0, None) if 1.0 - self.last <= 0.1 else None
        if q[1] <= 1.0:  # (a point the tracer keeps)
            self.last = float(q[1])
        return np.array([0.5, q[1]]), 0.0, None


def test_a_grazing_curve_whose_edge_search_fails_steps_shorter_to_the_edge(monkeypatch):
    """The edge's grazing not found from the last point: a shorter step inside the range,
    and the edge again from there (before, the curve ended at its last point inside,
    reported as having left the range)."""
    curve = _trace_stand_in(monkeypatch, _EdgeFromAfar, hmax=0.3)
    assert curve.stop == "left the range of b at 1"
    assert curve.p2[-1] == 1.0 and curve.p2[-2] >= 0.9
    assert np.allclose(curve.p1, 0.5)
    assert np.all(np.diff(curve.p2) > 0)


def test_a_corrector_started_on_the_curve_keeps_its_start() -> None:
    """The augmented corrector returns a start whose residuals already meet the tolerances
    (0 iterations) instead of stepping into the test function's noise: with noise larger
    than gtol, the steps from such a start were refused as divergence (the fold curve of
    ``examples/continuation_operating_map.py --small`` was lost that way). A start off the
    curve is still corrected."""
    from braidsim.continuation.twopar import Augmented

    target = np.array([0.3, -0.2, 0.5])
    noise: list[float] = []

    def equations(V: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        # one shooting residual r = V0 - target0 and the test function g = V1 - target1,
        # plus the next of the scripted noise values (0 once they run out)
        g = V[1] - target[1] + (noise.pop(0) if noise else 0.0)
        return np.array([V[0] - target[0], g]), np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), []

    aug = Augmented.__new__(Augmented)
    aug.equations = equations  # type: ignore[method-assign]
    normal = np.array([0.0, 0.0, 1.0])  # the pseudo-arclength row holds V2
    on = target + np.array([1e-10, 0.0, 0.0])
    noise[:] = [5e-7, 1.5e-5, -1.2e-5, 1.4e-5, -1.1e-5] * 2
    V, g, its, _, _ = aug.correct(on, normal, 1e-8, 1e-6)
    assert its == 0 and np.array_equal(V, on) and g == 5e-7
    noise.clear()
    off = target + np.array([0.01, 0.02, 0.0])
    V, g, its, _, _ = aug.correct(off, normal, 1e-8, 1e-6)
    assert its >= 1 and abs(g) < 1e-12
    assert np.allclose(V, target, rtol=0, atol=1e-12)


@pytest.mark.parametrize("takes_over", [True, False])
def test_a_stalled_central_difference_step_hands_over_to_the_exact_map(
    doubling, monkeypatch, takes_over: bool
) -> None:
    """A central-difference curve step that the corrector's stall rule accepts with its
    test function above tolerance (made so here: its g reported as 5e-4) hands the curve
    over to the exact map at once, which follows the same closed-form doubling; where the
    exact map cannot take over (made to fail here, as for a record without tangents) the
    step is accepted as before and the curve goes on with central differences."""
    from braidsim.continuation import twopar
    from braidsim.continuation.orbit import ContinuationError

    base, system, br, pd = doubling
    correct = twopar.Augmented.correct
    fd_calls = []

    def stalled(self, Vp, normal, tol, gtol, max_iter=10):
        V, g, its, DF, Js = correct(self, Vp, normal, tol, gtol, max_iter)
        if self.method == "fd":
            fd_calls.append(g)
            if len(fd_calls) in (2, 3):  # (the first step after the located point, and
                return V, 5e-4, its, DF, Js  # that step taken again: the same stall)
        return V, g, its, DF, Js

    monkeypatch.setattr(twopar.Augmented, "correct", stalled)
    if not takes_over:
        init = twopar.Augmented.__init__

        def no_exact(self, system, orbit, kind, key1, key2, scales, method):
            if method == "exact":
                raise ContinuationError("no tangents (made so by the test)")
            init(self, system, orbit, kind, key1, key2, scales, method)

        monkeypatch.setattr(twopar.Augmented, "__init__", no_exact)
    c = trace_boundary(
        system, br, pd, F, 1.5, steps=4, method="fd", range1=(1.5, 3.5), range2=(0.5, 1.5)
    )
    assert c.stop.startswith("left the range of force_amplitude")
    assert ("exact flow map from" in c.detail) is takes_over
    assert (5e-4 in c.residuals) is not takes_over
    for w, f in zip(c.p1, c.p2, strict=True):
        ref, _ = pwl.critical_parameter(
            base._replace(force_amplitude=f), W, w - 0.02, w + 0.02, steps=2
        )
        assert w == pytest.approx(ref, rel=1e-7)
