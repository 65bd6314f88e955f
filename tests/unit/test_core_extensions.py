"""Laws and excitations added to the core in one file each, against closed forms: the
Kelvin-Voigt contact (outside the power-law family), Coulomb plus viscous friction, and a
track vibration from a measured record."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

from braidsim.core import (
    CoulombViscousFriction,
    ImpactOscillator,
    KelvinVoigtContact,
    MeasuredTrack,
    TrackHarmonics,
    run,
    state_size,
    wall_motion,
)
from braidsim.core import layout as L
from braidsim.core.interfaces import (
    contact_force_rates,
    contact_forces,
    contact_onset_step,
    contact_potential,
)
from braidsim.model import build_model
from braidsim.params import load_scenario

TIGHT = L.SolverOptions(
    rtol=1e-11, atol_position=1e-15, atol_velocity=1e-13, max_step=1e-4, max_steps=10**7, t_end=0.0
)


@pytest.mark.parametrize("e", [0.3, 0.7, 0.95])
def test_kelvin_voigt_impact_is_half_a_damped_period(e: float) -> None:
    """With tension allowed, a free impact lasts pi / w_d and rebounds at exactly e."""
    m, k, v, gap = 1.2, 5e7, 0.4, 1e-3
    law = KelvinVoigtContact.for_restitution(k, e, m, allow_tension=True)
    model = ImpactOscillator(m, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, gap, law)
    raw = run(model, TIGHT._replace(t_end=gap / v + 0.01), np.array([0.0, v, 0.0, 0.0, 0.0]))
    (ep,) = raw.episodes
    zeta = law.damping / (2.0 * math.sqrt(k * m))
    w_d = math.sqrt(k / m) * math.sqrt(1.0 - zeta**2)
    assert ep["t_end"] - ep["t"] == pytest.approx(math.pi / w_d, rel=1e-9)
    assert ep["rebound_velocity"] / ep["velocity"] == pytest.approx(e, rel=1e-8)
    # the force jumps to c v at onset: the damping-related force peaks at the first instant
    assert ep["max_damping_force"] == pytest.approx(law.damping * v, rel=1e-9)
    assert ep["dissipated_energy"] == pytest.approx(0.5 * m * v * v * (1 - e * e), rel=1e-8)


def test_kelvin_voigt_without_tension_leaves_the_wall_when_the_force_vanishes() -> None:
    """With tension allowed the dashpot pulls the body back at the end of the contact (N < 0
    while p' < -k p / c); clamped at N >= 0 it does not, so the body rebounds faster than
    the nominal restitution, after the same peak force."""
    m, k, v, gap = 1.2, 5e7, 0.4, 1e-3
    kw = dict(stiffness=k, restitution=0.5, mass=m)
    free = KelvinVoigtContact.for_restitution(**kw, allow_tension=True)
    clamped = KelvinVoigtContact.for_restitution(**kw)
    opts = TIGHT._replace(t_end=gap / v + 0.01)
    out = {}
    for name, law in (("free", free), ("clamped", clamped)):
        model = ImpactOscillator(m, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, gap, law)
        out[name] = run(model, opts, np.array([0.0, v, 0.0, 0.0, 0.0])).episodes[0]
    assert out["free"]["rebound_velocity"] == pytest.approx(0.5 * v, rel=1e-8)
    assert out["clamped"]["rebound_velocity"] > out["free"]["rebound_velocity"] * 1.05
    assert out["clamped"]["peak_force"] == pytest.approx(out["free"]["peak_force"], rel=1e-9)


@pytest.mark.parametrize("e", [0.3, 0.6])
@pytest.mark.parametrize("rtol", [1e-8, 1e-10])
def test_clamped_kelvin_voigt_impact_against_its_closed_form(e: float, rtol: float) -> None:
    """Clamped at N >= 0, the damped oscillation m p'' + c p' + k p = 0 from p = 0, p' = v
    ends where k p + c p' = 0 (the dashpot would pull); the body then flies off the wall at
    the speed it has there. The solver cuts its step at that kink of the force: the rebound
    speed is right to a few rtol (measured over e = 0.3, 0.6, 0.9 and rtol 1e-6 to 1e-12:
    1.6 rtol at most; with the kink stepped over, as before, 0.6 to 180 rtol)."""
    from scipy.optimize import brentq

    m, k, v, gap = 1.2, 5e7, 0.4, 1e-3
    law = KelvinVoigtContact.for_restitution(k, e, m)
    model = ImpactOscillator(m, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, gap, law)
    opts = TIGHT._replace(rtol=rtol, atol_position=1e-5 * rtol, atol_velocity=0.1 * rtol)
    opts = opts._replace(max_step=1e-3, t_end=gap / v + 0.01)
    (ep,) = run(model, opts, np.array([0.0, v, 0.0, 0.0, 0.0])).episodes
    c = law.damping
    w_n = math.sqrt(k / m)
    zeta = c / (2.0 * math.sqrt(k * m))
    w_d = w_n * math.sqrt(1.0 - zeta**2)

    def p(t: float) -> float:
        return v / w_d * math.exp(-zeta * w_n * t) * math.sin(w_d * t)

    def p_dot(t: float) -> float:
        return (
            v
            * math.exp(-zeta * w_n * t)
            * (math.cos(w_d * t) - zeta * w_n / w_d * math.sin(w_d * t))
        )

    # the force k p + c p' is > 0 at the deepest point and c p' < 0 at p = 0
    t_peak = math.atan2(w_d, zeta * w_n) / w_d
    t_clamp = brentq(lambda t: k * p(t) + c * p_dot(t), t_peak, math.pi / w_d, xtol=1e-16)
    assert ep["rebound_velocity"] == pytest.approx(-p_dot(t_clamp), rel=4.0 * rtol)


def _free_carrier(friction: object, mu: float, v0: float) -> tuple[object, np.ndarray]:
    """The x-only carrier in the middle of a 1 m gap, no loads, no vibration."""
    model = build_model(load_scenario("paper-3.1"), 1.0)
    rec = model.record._replace(
        friction=friction,
        mu_x=mu,
        load_x=0.0,
        mass_radius=0.0,
        track_clearance=1.0,
        track=TrackHarmonics(np.zeros((0, 3))),
    )
    y0 = np.zeros(state_size(rec, True))
    y0[:2] = (0.5, v0)
    return rec, y0


@pytest.mark.slow  # (the Coulomb-viscous law's own compile of the solver, about 10 s)
def test_viscous_friction_decays_the_speed_exponentially() -> None:
    """mu = 0: m x'' = -b x', so x' = v0 exp(-b t / m), x = x0 + v0 m / b (1 - exp(-b t / m))."""
    b, v0, T = 3.0, 0.2, 0.4
    rec, y0 = _free_carrier(CoulombViscousFriction(1e-3, b), 0.0, v0)
    raw = run(rec, TIGHT._replace(t_end=T, max_step=1e-3), y0)
    m = rec.mass
    decay = math.exp(-b * T / m)
    assert raw.y[1] == pytest.approx(v0 * decay, rel=1e-9)
    assert raw.y[0] == pytest.approx(0.5 + v0 * m / b * (1 - decay), rel=1e-10)
    assert raw.y[3] == pytest.approx(0.5 * m * v0 * v0 * (1 - decay**2), rel=1e-8)  # friction work


@pytest.mark.slow  # (the Coulomb-viscous law's own compile of the solver, about 10 s)
def test_coulomb_friction_decelerates_at_mu_n_over_m() -> None:
    """b = 0, v >> v_hat: m x'' = -mu N, a constant deceleration while sliding."""
    mu, v0, T = 0.1, 0.5, 0.2
    rec, y0 = _free_carrier(CoulombViscousFriction(1e-7, 0.0), mu, v0)
    raw = run(rec, TIGHT._replace(t_end=T, max_step=1e-3), y0)
    a = mu * rec.normal_x / rec.mass
    assert v0 - a * T > 0.05  # still sliding
    assert raw.y[1] == pytest.approx(v0 - a * T, rel=1e-9)
    assert raw.y[0] == pytest.approx(0.5 + v0 * T - 0.5 * a * T * T, rel=1e-9)


def _paper_track_record(n: int = 400) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float]]:
    sc = load_scenario("paper-3.3")
    a, w, ph = (
        sc["track.vibration_amplitude"],
        sc["track.vibration_frequency"],
        sc["track.vibration_phase"],
    )
    t = np.linspace(0.0, 2 * math.pi / w, n + 1)
    return t, a * np.cos(w * t + ph), (a, w, ph)


def test_measured_track_interpolates_the_sampled_vibration() -> None:
    t, h, (a, w, ph) = _paper_track_record()
    tr = MeasuredTrack.from_samples(t, h)
    for tq in (0.0, 0.0012345, 0.017, 0.31415, 2.5):  # inside and beyond the record
        pos, vel, acc = wall_motion.py(tr, tq)
        arg = w * tq + ph
        assert pos == pytest.approx(a * math.cos(arg), abs=1e-8 * a)
        assert vel == pytest.approx(-a * w * math.sin(arg), abs=1e-6 * a * w)
        assert acc == pytest.approx(-a * w * w * math.cos(arg), abs=1e-3 * a * w * w)


def test_measured_track_acceleration_bound_is_computed_once_and_holds() -> None:
    from braidsim.core.interfaces import wall_accel_bound

    t, h, (a, w, _ph) = _paper_track_record()
    tr = MeasuredTrack.from_samples(t, h)
    # stored by from_samples, equal to the bound taken from the pieces at every call
    assert tr.accel_bound == pytest.approx(wall_accel_bound.py(tr._replace(accel_bound=-1.0)))
    assert wall_accel_bound.py(tr) == tr.accel_bound
    # the spline's |h''| never exceeds it, and it is close to the sine's a w^2
    dense = np.linspace(0.0, t[-1], 2001)
    acc = np.array([wall_motion.py(tr, tq)[2] for tq in dense])
    assert np.max(np.abs(acc)) <= tr.accel_bound * (1 + 1e-12)
    assert tr.accel_bound == pytest.approx(a * w * w, rel=1e-2)


@pytest.mark.slow  # (its own compile of the solver for the measured track, about 10 s)
def test_a_run_on_the_measured_record_equals_the_run_on_the_harmonic(tmp_path: Path) -> None:
    """The paper-3.3 carrier on the record of its own track vibration (written to CSV in mm
    and read back): the same impacts as on the harmonic track."""
    t, h, _ = _paper_track_record()
    path = tmp_path / "track.csv"
    rows = "".join(f"{float(a)!r},{float(b) * 1e3!r}\n" for a, b in zip(t, h, strict=True))
    path.write_text("t [s],h [mm]\n" + rows)
    tr = MeasuredTrack.from_csv(path)
    model = build_model(load_scenario("paper-3.3"), 0.2)
    harmonic = run(model.record, model.options, model.y0)
    measured = run(model.record._replace(track=tr), model.options, model.y0)
    assert measured.episodes.size == harmonic.episodes.size > 10
    np.testing.assert_allclose(measured.episodes["t"], harmonic.episodes["t"], rtol=1e-6)
    np.testing.assert_allclose(
        measured.episodes["peak_force"], harmonic.episodes["peak_force"], rtol=1e-4
    )


def test_a_bad_record_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="increasing"):
        MeasuredTrack.from_samples(np.array([0.0, 1.0, 1.0, 2.0]), np.zeros(4))
    path = tmp_path / "bad.csv"
    path.write_text("t,x\n0,0\n1,0\n2,0\n3,0\n")
    with pytest.raises(ValueError, match="columns t and h"):
        MeasuredTrack.from_csv(path)


def test_an_implementation_is_compiled_once_and_inlined_by_llvm() -> None:
    """A generic function's implementation is compiled once per argument types, whatever
    the number of its call sites (numba's inlining of numba IR typed and lowered it again at
    each), and LLVM inlines it into the caller: no call to it is left in the caller's
    machine code. It is called with the declaration's arguments in their order, so its
    parameters may be named otherwise. A typing error inside an implementation still stops
    the caller's compile."""
    from typing import NamedTuple

    import numba
    from numba.core import event

    from braidsim.core.generic import generic

    @generic
    def scaled(rec, x):  # the declaration
        """rec.a * x (a test's generic function)."""

    class Scale(NamedTuple):
        a: float

    class Broken(NamedTuple):
        a: float

    @scaled.register(Scale)
    def _scale(factor, value):
        return factor.a * value

    @scaled.register(Broken)
    def _broken(rec, x):
        return rec.a * x.no_such_attribute

    @numba.njit
    def twice(rec, x):  # two call sites of one signature
        return scaled(rec, x) + scaled(rec, 2.0 * x)

    compiled: list[str] = []

    class Listener(event.Listener):
        def on_start(self, ev: event.Event) -> None:
            disp = ev.data.get("dispatcher")
            if disp is not None:
                compiled.append(disp.py_func.__name__)

        def on_end(self, ev: event.Event) -> None:
            pass

    with event.install_listener("numba:compile", Listener()):
        assert twice(Scale(1.5), 2.0) == 1.5 * 2.0 + 1.5 * 4.0
    assert sorted(compiled) == ["_scale", "twice"]
    assert scaled.py(Scale(1.5), 2.0) == 3.0  # its twin, for calls from Python
    # marked for LLVM to inline wherever it is called (a helper of a generic function
    # declared inline=False is not), and no call to it left in the caller
    ir = next(iter(scaled.implementation(Scale).overloads.values())).library.get_llvm_str()
    assert "alwaysinline" in ir
    caller = next(iter(twice.inspect_llvm().values()))
    calls = [line for line in caller.splitlines() if " call " in line]
    assert not [line for line in calls if "_scale" in line]
    assert [line for line in calls if "twice" in line]  # (calls are found by their names)
    with pytest.raises(numba.core.errors.TypingError, match="no_such_attribute"):
        twice(Broken(1.0), 2.0)


def test_class_constants_from_the_interpreter_equal_the_compiled_ones() -> None:
    """The driver reads a model's sizes and dissipation slots by running their plain Python
    (``plain``): for every model class they equal what the compiled implementations give,
    and every class registered for one is registered for the other."""
    from braidsim.core.interfaces import dissipation_index, model_size

    law = KelvinVoigtContact.for_restitution(5e7, 0.5, 1.2, allow_tension=True)
    models = [
        build_model(load_scenario("paper-3.3")).record,
        build_model(load_scenario("paper-3.3").with_overrides({"simulation.dof": "xy"})).record,
        ImpactOscillator(1.2, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, 1e-3, law),
    ]
    # (a model added elsewhere, a test's or an extension's, registers both as well)
    assert {type(m) for m in models} <= set(model_size.generic.impls)
    assert set(model_size.generic.impls) == set(dissipation_index.generic.impls)
    for model in models:
        size = model_size.plain(model)
        assert size == tuple(model_size.py(model))
        assert all(isinstance(v, int) for v in size)
        for pair in range(size[1]):
            assert dissipation_index.plain(model, pair) == dissipation_index.py(model, pair)


def test_a_helper_called_from_python_says_so() -> None:
    """A helper is compiled without the wrapper that would let Python call it: a call from
    Python raises a TypeError that names it, and the same helper works from compiled code."""
    import numba

    from braidsim.core.generic import helper

    @helper
    def halve(x):
        return 0.5 * x

    @numba.njit
    def caller(x):
        return halve(x)

    assert caller(3.0) == 1.5
    with pytest.raises(TypeError, match="halve is compiled to be called from the solver"):
        halve(3.0)


def test_a_record_passed_by_reference_reads_as_the_record() -> None:
    """A record handed to a called helper by reference (one pointer, not one argument per
    field) gives the same values as the record itself: scalars, a bool, a nested record, 1-D
    and 2-D arrays, and a generic function dispatched on the record type behind the
    reference; reading array fields through it in reference-counted code leaks nothing."""
    from typing import NamedTuple

    import numba

    from braidsim.core.generic import by_ref, generic, helper

    class Inner(NamedTuple):
        k: float
        on: bool

    class Rec(NamedTuple):
        a: float
        n: int
        inner: Inner
        v: np.ndarray
        table: np.ndarray

    @generic
    def weight(rec, x):  # the declaration
        """A test's generic function."""

    @weight.register(Rec)
    def _weight(rec, x):
        return rec.a * x + rec.table[1, 0]

    @helper
    def read(rec, x):
        s = rec.a + rec.n + rec.inner.k + (10.0 if rec.inner.on else 0.0)
        for i in range(rec.v.shape[0]):
            s += rec.v[i] * (i + 1)
        return s + rec.table[1, 2] + rec.table.shape[1] + weight(rec, x)

    @numba.njit
    def through_ref(rec, x):
        ref = by_ref(rec)
        acc = 0.0
        for _ in range(100):
            acc += read(ref, x) + ref.table[0, 1]
        return acc / 100

    @numba.njit
    def direct(rec, x):
        return read(rec, x) + rec.table[0, 1]

    rec = Rec(1.5, 3, Inner(0.25, True), np.array([1.0, 2.0, 4.0]), np.arange(6.0).reshape(2, 3))
    expected = 1.5 + 3 + 0.25 + 10.0 + (1.0 + 4.0 + 12.0) + 5.0 + 3 + (1.5 * 2.0 + 3.0) + 1.0
    assert through_ref(rec, 2.0) == expected
    assert direct(rec, 2.0) == expected
    # an array numba takes from Python is held by its reference count while numba uses it:
    # a count left behind by the 200 reads through the reference would keep it held
    held = sys.getrefcount(rec.table), sys.getrefcount(rec.v)
    assert through_ref(rec, 2.0) == expected
    assert (sys.getrefcount(rec.table), sys.getrefcount(rec.v)) == held
    # the helper's machine code takes a reference as one argument, the record field by field
    # (its arrays as seven or more values each)
    import llvmlite.binding as llvm

    def n_args(sig: tuple) -> int:
        cres = read.overloads[sig]
        module = llvm.parse_assembly(str(cres.library._final_module))
        return len(list(module.get_function(cres.fndesc.mangled_name).arguments))

    (ref_sig,) = [s for s in read.signatures if type(s[0]).__name__ == "RecordRef"]
    (rec_sig,) = [s for s in read.signatures if s is not ref_sig]
    # (two more: the return slot and the exception slot)
    assert n_args(ref_sig) == 2 + 1 + 1
    assert n_args(rec_sig) == 2 + 4 + 7 + 9 + 1  # a, n, inner (2), v (7), table (9), x


class _LawWithoutTangent(NamedTuple):
    stiffness: float


@contact_forces.register(_LawWithoutTangent)
def _law_without_tangent_forces(law, p, p_dot, v0):
    fk = law.stiffness * p
    return fk, 0.0, fk


def test_sensitivities_name_the_part_without_tangents() -> None:
    """The check finds a physics record by the function it implements, in any field."""
    from braidsim import InputError
    from braidsim.sensitivity import check_differentiable

    rec = build_model(load_scenario("paper-3.1"), 0.01).record
    check_differentiable(rec)  # every shipped part has its tangents
    with pytest.raises(InputError, match=r"_LawWithoutTangent \(slot_law\).*contact_forces_jvp"):
        check_differentiable(rec._replace(slot_law=_LawWithoutTangent(1e6)))

    class NoTangentModel(NamedTuple):
        mass: float

    with pytest.raises(InputError, match=r"model NoTangentModel has no tangents"):
        check_differentiable(NoTangentModel(1.0))


def test_run_names_what_a_record_does_not_register_before_compiling() -> None:
    """A law registered for its force alone, a model without its functions, tangents asked
    of a law without its tangent: ``run`` names the record and the function at once (numba
    would fail after compiling with a typing error of thousands of characters)."""
    from braidsim.core.driver import Tangents

    model = build_model(load_scenario("paper-3.1"), 0.01)
    rec = model.record._replace(slot_law=_LawWithoutTangent(1e6))
    with pytest.raises(ValueError, match=r"model: _LawWithoutTangent \(slot_law\) does not "):
        run(rec, model.options, model.y0)

    class BareModel(NamedTuple):
        mass: float

    with pytest.raises(
        ValueError, match=r"model: the model BareModel does not register model_size"
    ):
        run(BareModel(1.0), model.options, np.zeros(2))

    law = KelvinVoigtContact.for_restitution(5e7, 0.5, 1.2, allow_tension=True)
    osc = ImpactOscillator(
        1.2, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, 1e-3, _KelvinVoigtNoTangent(*law)
    )
    y0 = np.zeros(state_size(osc, True))
    directions = (np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 0)), np.ones(1))
    tangents = Tangents([osc], *directions)
    with pytest.raises(
        ValueError,
        match=r"tangents: _KelvinVoigtNoTangent \(law\) does not register contact_forces_jvp",
    ):
        run(osc, TIGHT, y0, tangents=tangents)


class _KelvinVoigtNoTangent(KelvinVoigtContact):
    """The Kelvin-Voigt law under another class, registered for everything a run needs but
    its tangent."""


for _fn in (contact_forces, contact_potential, contact_force_rates, contact_onset_step):
    _fn.register(_KelvinVoigtNoTangent)(_fn.generic.impls[KelvinVoigtContact])
