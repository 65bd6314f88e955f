"""Steady states of a run: stroboscopic samples, regime classification, contact-loss bound.

The track vibration h(t) = h_a cos(omega_h t + phase) makes the carrier's equations periodic
in time with period T_h = 2 pi / omega_h. The *stroboscopic (Poincare) map* samples the
state once per period, always at the same excitation phase:

    t_k = (2 pi k - phase + strobe_phase) / omega_h,      k = 1, 2, ...

(``strobe_phase = 0``: the wall at its outermost position h = h_a). A steady motion of period
q excitation cycles shows as q points that repeat; a chaotic or quasi-periodic one as a cloud.

Regime rules
------------
The steady state is taken over a window of whole excitation cycles after a discarded
transient. With the track contact episodes overlapping the window and the stroboscopic
samples z_k = (u_k, vx_k / omega_h), u = x - h(t) the position relative to the inner wall,
the regime is the first rule that holds:

1. ``no_contact``: no track contact overlaps the window.
2. ``resting_contact``: no contact *onset* in the window (the carrier stays on a wall; any
   contact that starts is an onset).
3. ``chattering``: impacts, and at least one contact in the window is *sustained*: it lasts
   longer than ``stick_time = max(0.1 T_h, 3 pi / omega_n)``, omega_n = sqrt(n K p_s^(n-1)/m)
   the linearised contact frequency at the static depth p_s = (m a_p / K)^(1/n) under the
   pressing load (a free impact lasts about pi / omega_n; a contact several times longer is
   the carrier resting on the wall after a sequence of decaying impacts and being thrown
   off again: the chatter-and-stick motion of Budd & Dux, Phil. Trans. R. Soc. A 347 (1994)
   365-389). Without a pressing load (a_p <= 0) nothing sticks and this rule never holds.
4. ``periodic_one_sided`` / ``periodic_two_sided``: the stroboscopic samples repeat with a
   period of q <= ``max_period`` cycles: max_k |z_{k+q} - z_k| <= ``period_tol`` * L over the
   window (infinity norm, L = max(peak-to-peak of u over the window, h_a, eps_g / 1000));
   impacts on one wall only, or on both.
5. ``irregular``: impacts without a period <= ``max_period``: chaotic, quasi-periodic, or a
   transient not yet settled (lengthen the transient to tell).

The period q is also reported for ``resting_contact`` (normally 1) and ``chattering``.
Rules 2-3 use the contact episodes (exact onset and exit times from the integrator), rule 4
the stroboscopic samples. The classification describes the track pair only.

Contact-loss bound (docs/model.md §7)
------------------------------------------
Ignoring contact compliance and friction, a carrier pressed on the inner wall with
acceleration a_p = (T1 cos phi + m r_c omega^2) / m [m/s^2] stays on a wall vibrating as
h(t) = h_a cos(omega_h t) only while a_p >= h_a omega_h^2: the wall cannot pull the carrier,
so it leaves when the wall's deceleration exceeds what the load can supply.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from braidsim.errors import InputError
from braidsim.params import Scenario, load_scenario
from braidsim.regimes import STEADY_REGIMES, contact_pattern, pattern_of, window_contacts

if TYPE_CHECKING:
    from braidsim.result import Result, State

REGIME_LABELS = STEADY_REGIMES
"""Regime labels (module docstring); ``failed`` marks a run that failed numerically."""
IMPACTING = ("periodic_one_sided", "periodic_two_sided", "chattering", "irregular")
"""The labels of steady states with impacts."""

DEFAULT_TRANSIENT_CYCLES = 100
DEFAULT_CYCLES = 50
DEFAULT_PERIOD_TOL = 1e-2
DEFAULT_MAX_PERIOD = 12


def as_scenario(
    scenario: Scenario | str | Any, overrides: Mapping[str, Any] | None = None
) -> Scenario:
    """A :class:`Scenario` from a scenario, a built-in name, a TOML path or a mapping."""
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    return sc.with_overrides(overrides) if overrides else sc


def excitation_period(sc: Scenario) -> float | None:
    """T_h = 2 pi / omega_h [s] of the track vibration, None when omega_h = 0."""
    w = float(sc["track.vibration_frequency"])
    return 2.0 * math.pi / w if w > 0.0 else None


def reference_period(sc: Scenario) -> float:
    """The period that sets transient and window lengths [s].

    T_h when the track vibrates at omega_h > 0; otherwise the horn-gear period 2 pi / omega;
    otherwise 10 ms.
    """
    T = excitation_period(sc)
    if T is not None:
        return T
    w = float(sc["horn_gear.angular_velocity"])
    return 2.0 * math.pi / w if w > 0.0 else 0.01


def pressing_acceleration(sc: Scenario) -> float:
    """a_p = (T1 cos phi + m r_c omega^2) / m [m/s^2], the constant load per unit mass that
    presses the carrier on the inner wall (omega the mean horn-gear speed)."""
    m = float(sc["carrier.mass"])
    load = float(sc["yarn.tension_horizontal"]) * math.cos(float(sc["yarn.angle"]))
    w = float(sc["horn_gear.angular_velocity"])
    return (load + m * float(sc["carrier.turning_radius"]) * w * w) / m


def wall_acceleration_amplitude(sc: Scenario) -> float:
    """Largest |h''(t)| of the track walls [m/s^2].

    h_a omega_h^2 for the single harmonic of the paper; with ``track.harmonics`` the maximum
    of |sum a_i w_i^2 cos(w_i t + phi_i)| over a fine grid of 20 000 points spanning the
    slowest term's period.
    """
    terms = [
        (
            float(sc["track.vibration_amplitude"]),
            float(sc["track.vibration_frequency"]),
            float(sc["track.vibration_phase"]),
        )
    ]
    terms += [(float(a), float(w), float(p)) for a, w, p in sc["track.harmonics"]]
    terms = [t for t in terms if t[0] != 0.0 and t[1] > 0.0]
    if not terms:
        return 0.0
    if len(terms) == 1:
        a, w, _ = terms[0]
        return abs(a) * w * w
    wmin = min(w for _, w, _ in terms)
    t = np.linspace(0.0, 2.0 * math.pi / wmin, 20001)
    acc = sum(a * w * w * np.cos(w * t + p) for a, w, p in terms)
    return float(np.max(np.abs(acc)))


def contact_loss_bound(scenario: Scenario | str | Any) -> dict[str, Any]:
    """The analytic contact-loss bound of docs/model.md §7 for any scenario.

    The carrier stays on the vibrating inner wall while a_p >= a_w, with
    a_p = (T1 cos phi + m r_c omega^2)/m and a_w = h_a omega_h^2 the wall's acceleration
    amplitude (contact compliance and friction neglected).

    Returns
    -------
    dict
        ``pressing_acceleration`` a_p [m/s^2], ``wall_acceleration`` a_w [m/s^2],
        ``ratio`` a_w / a_p [-], ``stays_on_wall`` (a_p >= a_w), and the critical values
        at which a_p = a_w when only one parameter changes: ``critical_amplitude``
        a_p / omega_h^2 [m], ``critical_vibration_frequency`` sqrt(a_p / h_a) [rad/s],
        ``critical_angular_velocity`` sqrt((h_a omega_h^2 - T1 cos phi / m) / r_c) [rad/s]
        (None where it does not exist), ``formula``; and the refinement with the friction
        force f_x = mu1 |m g - T2| of Eq. (14), which is saturated (|x'| >> x_hat) and pulls
        the carrier off the wall once the wall moves away from it:
        ``pressing_acceleration_with_friction`` a_p - mu1 |m g - T2| / m [m/s^2] and
        ``critical_amplitude_with_friction`` [m]. The simulated carrier (compliant contact)
        leaves the wall within 2 % of these amplitudes
        (``tests/integration/test_analysis.py``).
    """
    sc = as_scenario(scenario)
    ap = pressing_acceleration(sc)
    aw = wall_acceleration_amplitude(sc)
    h_a = float(sc["track.vibration_amplitude"])
    w_h = float(sc["track.vibration_frequency"])
    m = float(sc["carrier.mass"])
    load_per_mass = float(sc["yarn.tension_horizontal"]) * math.cos(float(sc["yarn.angle"])) / m
    rc = float(sc["carrier.turning_radius"])
    crit_amp = ap / (w_h * w_h) if w_h > 0.0 and ap > 0.0 else None
    # friction of Eq. (14) (saturated) pulls the carrier off the wall as soon as the wall
    # moves away from it: a refinement of docs/model.md §7
    mu_n = 0.0
    if sc["friction.law"] != "none":
        mu_n = float(sc["friction.carrier_horn_gear"]) * abs(
            m * float(sc["gravity"]) - float(sc["yarn.tension_vertical"])
        )
    ap_f = ap - mu_n / m
    crit_amp_f = ap_f / (w_h * w_h) if w_h > 0.0 and ap_f > 0.0 else None
    crit_wh = math.sqrt(ap / h_a) if h_a > 0.0 and ap > 0.0 else None
    rhs = (h_a * w_h * w_h - load_per_mass) / rc
    crit_w = math.sqrt(rhs) if rhs > 0.0 else None
    return {
        "pressing_acceleration": ap,
        "wall_acceleration": aw,
        "ratio": aw / ap if ap > 0.0 else math.inf,
        "stays_on_wall": bool(ap > 0.0 and ap >= aw),
        "critical_amplitude": crit_amp,
        "critical_vibration_frequency": crit_wh,
        "critical_angular_velocity": crit_w,
        "formula": "stays on the inner wall while (T1 cos phi + m r_c omega^2)/m >= h_a omega_h^2",
        "pressing_acceleration_with_friction": ap_f,
        "critical_amplitude_with_friction": crit_amp_f,
    }


def stick_time(sc: Scenario) -> float:
    """Duration above which a contact counts as sustained (resting) [s]: the larger of
    0.1 T_h and 3 pi / omega_n (module docstring); inf when nothing presses the carrier."""
    ap = pressing_acceleration(sc)
    if ap <= 0.0:
        return math.inf
    from braidsim.model import pair_model

    pm = pair_model(sc, "track")
    m = float(sc["carrier.mass"])
    n = pm.exponent
    p_s = (m * ap / pm.stiffness) ** (1.0 / n)
    omega_n = math.sqrt(n * pm.stiffness * p_s ** (n - 1.0) / m)
    return max(0.1 * reference_period(sc), 3.0 * math.pi / omega_n)


# ----------------------------------------------------------------------------------------
# period detection (generic: used for the carrier and for the textbook checks)
# ----------------------------------------------------------------------------------------


def detect_period(samples: np.ndarray, tol: float, max_period: int) -> int | None:
    """Smallest q in 1..max_period with max_k |z_{k+q} - z_k|_inf <= tol, else None.

    Parameters
    ----------
    samples : array, shape (n,) or (n, d)
        Successive samples z_k of a map (the stroboscopic samples of a flow).
    tol : float
        Absolute tolerance, same units as the samples.
    max_period : int
        Largest period tried; a period q is only accepted with at least q comparisons
        (n >= 2 q samples).
    """
    z = np.asarray(samples, dtype=float)
    if z.ndim == 1:
        z = z[:, None]
    n = z.shape[0]
    if n < 2 or not np.all(np.isfinite(z)):
        return None
    for q in range(1, max_period + 1):
        if n < 2 * q:
            break
        if float(np.max(np.abs(z[q:] - z[:-q]))) <= tol:
            return q
    return None


# ----------------------------------------------------------------------------------------
# steady states
# ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Regime:
    """The classified steady state of one run (rules in the module docstring).

    Attributes
    ----------
    label : str
        One of :data:`REGIME_LABELS`, or ``failed``.
    period : int or None
        Period in excitation cycles of the stroboscopic samples (None: none found).
    walls : str
        Walls hit in the window: ``none``, ``inner``, ``outer`` or ``both``.
    impacts_per_cycle : float
        Track contact onsets per excitation cycle in the window.
    rule : str
        The rule that decided, in words.
    """

    label: str
    period: int | None
    walls: str
    impacts_per_cycle: float
    rule: str

    @property
    def pattern(self) -> str:
        """The contact pattern this regime refines (:mod:`braidsim.regimes`): the
        ``regime`` a batch or a sweep reports for the same window."""
        return pattern_of(self.label, self.walls)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "label": self.label,
            "pattern": self.pattern,
            "period": self.period,
            "walls": self.walls,
            "impacts_per_cycle": self.impacts_per_cycle,
            "rule": self.rule,
        }


@dataclass(frozen=True)
class SteadyState:
    """What a run settles into: stroboscopic samples and contact statistics over a window.

    Attributes
    ----------
    parameters : dict
        The overrides of this run (as given), for sweeps; ``{}`` for a single run.
    window : (float, float)
        Window (t0, t1) [s], whole excitation cycles after the transient.
    period : float
        Sampling period of the stroboscopic samples [s] (T_h, or :func:`reference_period`).
    strobe_t, strobe_x, strobe_vx, strobe_u : np.ndarray
        Sample times [s], x [m], dx/dt [m/s] and u = x - h(t) [m] at the samples.
    inner_impacts, outer_impacts : int
        Track contact onsets on each wall in the window.
    contact_fraction : float
        Fraction of the window in contact with a track wall.
    longest_contact : float
        Longest track contact overlapping the window [s] (a contact cut by the window
        counts with its whole duration; one still going at the end up to the end).
    max_approach_speed : float
        Largest approach speed of those onsets [m/s] (0: none).
    stick_time : float
        Threshold of rule 3 [s].
    length_scale : float
        L of rule 4 [m].
    regime : Regime
        The classification.
    final : State or None
        The final state of the run (to continue it).
    failure : str
        "" for a run that finished, else why it failed (``regime.label`` is ``failed``).
    omega_h : float
        The track vibration's angular frequency [rad/s] that scales the speeds of the
        stroboscopic points (0: none; ``2 pi / period`` is used then).
    """

    parameters: dict[str, Any]
    window: tuple[float, float]
    period: float
    strobe_t: np.ndarray
    strobe_x: np.ndarray
    strobe_vx: np.ndarray
    strobe_u: np.ndarray
    inner_impacts: int
    outer_impacts: int
    contact_fraction: float
    longest_contact: float
    max_approach_speed: float
    stick_time: float
    length_scale: float
    regime: Regime
    final: State | None = None
    failure: str = ""
    omega_h: float = field(default=0.0)

    def strobe_points(self) -> np.ndarray:
        """(n, 2) stroboscopic points (u [m], dx/dt / omega_h [m]) in the window."""
        w = self.omega_h if self.omega_h > 0.0 else 2.0 * math.pi / self.period
        return np.column_stack([self.strobe_u, self.strobe_vx / w])

    def to_dict(self, samples: bool = True) -> dict[str, Any]:
        """JSON-ready form (SI units); ``samples=False`` leaves the strobe arrays out."""
        out: dict[str, Any] = {
            "parameters": dict(self.parameters),
            "window": list(self.window),
            "sampling_period": self.period,
            "regime": self.regime.to_dict(),
            "inner_impacts": self.inner_impacts,
            "outer_impacts": self.outer_impacts,
            "contact_fraction": self.contact_fraction,
            "longest_contact": self.longest_contact,
            "max_approach_speed": self.max_approach_speed,
            "stick_time": self.stick_time,
            "failure": self.failure,
        }
        if samples:
            out["strobe"] = {
                "t": self.strobe_t.tolist(),
                "x": self.strobe_x.tolist(),
                "vx": self.strobe_vx.tolist(),
                "u": self.strobe_u.tolist(),
            }
        return out


def strobe_times(sc: Scenario, t_from: float, cycles: int, strobe_phase: float = 0.0) -> np.ndarray:
    """``cycles + 1`` stroboscopic times [s] from the first one at or after ``t_from``.

    With vibration: omega_h t + phase = 2 pi k + strobe_phase; otherwise multiples of
    :func:`reference_period`.
    """
    T = reference_period(sc)
    w = float(sc["track.vibration_frequency"])
    offset = 0.0
    if w > 0.0:
        offset = (strobe_phase - float(sc["track.vibration_phase"])) / w
    k0 = math.ceil((t_from - offset) / T - 1e-9)
    t = offset + (k0 + np.arange(cycles + 1)) * T
    if t[0] < 0.0:  # an offset before t = 0: shift by whole periods
        t = t + T * math.ceil(-t[0] / T - 1e-12)
    return t


def _walls(inner: int, outer: int) -> str:
    if inner and outer:
        return "both"
    if inner:
        return "inner"
    if outer:
        return "outer"
    return "none"


def classify(
    *,
    contacts: bool,
    inner_impacts: int,
    outer_impacts: int,
    longest_contact: float,
    stick_time: float,
    strobe: np.ndarray,
    length_scale: float,
    cycles: float,
    period_tol: float = DEFAULT_PERIOD_TOL,
    max_period: int = DEFAULT_MAX_PERIOD,
) -> Regime:
    """Apply the regime rules of the module docstring.

    Parameters
    ----------
    contacts : bool
        Whether any track contact overlaps the window.
    inner_impacts, outer_impacts : int
        Contact onsets on each wall in the window.
    longest_contact : float
        Longest contact overlapping the window [s].
    stick_time : float
        Threshold of rule 3 [s].
    strobe : array (n, d)
        Stroboscopic samples (u [m], vx / omega_h [m]).
    length_scale : float
        L of rule 4 [m].
    cycles : float
        Window length in excitation cycles.
    period_tol : float
        Relative tolerance of rule 4.
    max_period : int
        Largest period tried [cycles].
    """
    n_imp = inner_impacts + outer_impacts
    walls = _walls(inner_impacts, outer_impacts)
    rate = n_imp / cycles if cycles > 0 else math.nan
    q = detect_period(strobe, period_tol * length_scale, max_period)
    pattern = contact_pattern(contacts, inner_impacts, outer_impacts)
    if pattern == 0:
        return Regime("no_contact", q, walls, rate, "no track contact in the window")
    if pattern == 1:
        return Regime("resting_contact", q, walls, rate, "in contact, no contact onset")
    if longest_contact > stick_time:
        return Regime(
            "chattering",
            q,
            walls,
            rate,
            f"impacts and a sustained contact of {longest_contact:.3g} s > {stick_time:.3g} s",
        )
    if q is not None:
        label = "periodic_two_sided" if walls == "both" else "periodic_one_sided"
        return Regime(label, q, walls, rate, f"stroboscopic samples repeat every {q} cycles")
    return Regime(
        "irregular", None, walls, rate, f"impacts, no period <= {max_period} cycles in the window"
    )


def steady_state_from_result(
    result: Result,
    window: tuple[float, float],
    strobe: np.ndarray,
    parameters: Mapping[str, Any] | None = None,
    period_tol: float = DEFAULT_PERIOD_TOL,
    max_period: int = DEFAULT_MAX_PERIOD,
) -> SteadyState:
    """Reduce a run to its :class:`SteadyState` over ``window``.

    ``strobe`` are the stroboscopic times; they must be among the run's sample times (pass
    them in ``sample_times`` to :func:`braidsim.simulate`).
    """
    from braidsim.core.layout import KIND_SAMPLE

    sc = result.model.scenario
    s = result.series
    samp = s["kind"] == KIND_SAMPLE
    ts = s["t"][samp]
    idx = np.searchsorted(ts, strobe)
    idx = np.clip(idx, 0, max(ts.size - 1, 0))
    if ts.size == 0 or not np.allclose(ts[idx], strobe, rtol=0.0, atol=1e-12):
        raise InputError("strobe: the stroboscopic times are not among the run's sample times")
    x = s["x"][samp][idx]
    vx = s["vx"][samp][idx]
    u = x - s["track_position"][samp][idx]
    t0, t1 = window
    # (the reduction of the batch metrics: braidsim.regimes.window_contacts)
    wc = window_contacts(result.episodes, t0, t1)
    inner = int(wc.onsets[0, 0])
    outer = int(wc.onsets[0, 1])
    fraction = float(wc.contact_fraction[0])
    longest = float(wc.longest_contact[0])
    vmax = float(wc.max_approach_speed[0])
    h_a = float(sc["track.vibration_amplitude"])
    ptp = float(np.ptp(u)) if u.size else 0.0
    L = max(ptp, h_a, 1e-3 * float(sc["track.clearance"]))
    T = reference_period(sc)
    w_h = float(sc["track.vibration_frequency"])
    w = w_h if w_h > 0.0 else 2.0 * math.pi / T
    st = stick_time(sc)
    regime = classify(
        contacts=fraction > 0.0,
        inner_impacts=inner,
        outer_impacts=outer,
        longest_contact=longest,
        stick_time=st,
        strobe=np.column_stack([u, vx / w]),
        length_scale=L,
        cycles=(t1 - t0) / T,
        period_tol=period_tol,
        max_period=max_period,
    )
    return SteadyState(
        dict(parameters or {}),
        (float(t0), float(t1)),
        T,
        np.asarray(strobe, dtype=float),
        x,
        vx,
        u,
        inner,
        outer,
        fraction,
        longest,
        vmax,
        st,
        L,
        regime,
        result.final_state,
        "",
        w_h,
    )


def steady_state(
    scenario: Scenario | str | Any,
    overrides: Mapping[str, Any] | None = None,
    *,
    transient_cycles: float = DEFAULT_TRANSIENT_CYCLES,
    cycles: int = DEFAULT_CYCLES,
    strobe_phase: float = 0.0,
    period_tol: float = DEFAULT_PERIOD_TOL,
    max_period: int = DEFAULT_MAX_PERIOD,
) -> SteadyState:
    """Simulate a scenario past its transient and classify the steady state.

    The run lasts ``transient_cycles`` excitation periods (discarded) plus a window of
    ``cycles`` whole periods, sampled stroboscopically (module docstring); only the
    stroboscopic samples are kept (the contact episodes are exact).

    Parameters
    ----------
    scenario : Scenario, str, Path or mapping
        The scenario.
    overrides : mapping, optional
        ``{key: value}`` on top of it.
    transient_cycles : float
        Discarded start [excitation cycles], >= 0.
    cycles : int
        Window [excitation cycles], >= 2.
    strobe_phase : float
        Excitation phase of the samples [rad] (0: the wall at h = h_a).
    period_tol, max_period : float, int
        Rule 4 of the module docstring.

    Raises
    ------
    InputError
        Bad options. :class:`braidsim.SimulationError` when the run fails.
    """
    from braidsim.simulate import simulate

    sc = as_scenario(scenario, overrides)
    check_window_options(transient_cycles, cycles, period_tol, max_period)
    T = reference_period(sc)
    st = strobe_times(sc, transient_cycles * T, cycles, strobe_phase)
    res = simulate(sc, duration=float(st[-1]), sample_times=st, record_events=False)
    return steady_state_from_result(
        res, (float(st[0]), float(st[-1])), st, overrides, period_tol, max_period
    )


def check_window_options(
    transient_cycles: float, cycles: int, period_tol: float, max_period: int
) -> None:
    """InputError naming the option when a transient/window option is out of range."""
    if not (math.isfinite(transient_cycles) and transient_cycles >= 0):
        raise InputError(
            f"transient_cycles: {transient_cycles!r} is out of range; allowed >= 0 (cycles)"
        )
    if int(cycles) != cycles or cycles < 2:
        raise InputError(f"cycles: {cycles!r} is out of range; allowed an integer >= 2")
    if not (math.isfinite(period_tol) and period_tol > 0):
        raise InputError(f"period_tol: {period_tol!r} is out of range; allowed > 0")
    if int(max_period) != max_period or max_period < 1:
        raise InputError(f"max_period: {max_period!r} is out of range; allowed an integer >= 1")


def failed_steady_state(
    parameters: Mapping[str, Any], reason: str, window: tuple[float, float], period: float
) -> SteadyState:
    """The record of a run that failed numerically (``regime.label == 'failed'``)."""
    empty = np.zeros(0)
    return SteadyState(
        dict(parameters),
        window,
        period,
        empty,
        empty,
        empty,
        empty,
        0,
        0,
        math.nan,
        math.nan,
        math.nan,
        math.nan,
        math.nan,
        Regime("failed", None, "none", math.nan, reason),
        None,
        reason,
    )
