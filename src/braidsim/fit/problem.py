"""The least-squares problem of a fit: model predictions, residuals and their Jacobians.

Residuals
---------
*Record residuals* compare the model with every sample of every fitted quantity q:

    r_qi = (m_q(t_i; p) - d_qi) / sigma_q,

with m_q the model sampled at the record's own times (no interpolation: the solver stops
at each sample time) and sigma_q the sensor noise (given, or estimated from the record by
:func:`braidsim.fit.data.noise_estimate`). The model's acceleration is the right-hand side
of the carrier's equation of motion, a_x = (-F_c - f_x - F_x - m r_c omega^2) / m (contact
force F_c, friction f_x, constant load F_x, centrifugal load; docs/model.md), evaluated on
the sampled state.

*Event residuals* compare impact times, which stay well posed when an impact moves by more
than its own duration (then a sampled pulse of the model no longer overlaps the measured
one, and the record residuals lose their slope): for every impact found in the record
(:func:`braidsim.fit.data.detect_pulses`) at t_dk, r_k = (t_m(k) - t_dk) / sigma_t with
t_m(k) the model's nearest impact onset, and one residual sqrt(sum_j (t_mj - t_d(j))^2) /
sigma_t for the model's impacts against their nearest measured ones (so that extra model
impacts cost too); sigma_t is the sample interval. The model's impacts are those the record
would show, judged on the model's own samples at the record's times against the record's
pulse threshold: a measured onset is matched among those that reach it less 3 noise levels,
the extra residual counts those beyond it by 3 (a pulse near the threshold is in the record
or not by its noise). The global stage of the fit works on
them; the final fit and its statistics on the record residuals.

*Impact-list residuals* (:class:`ImpactProblem`): each measured impact k (onset t_dk) is
matched to a model track impact j(k), the matching that keeps their order and minimises
sum_k (t_mj(k) - t_dk)^2 (dynamic programming; the nearest in time when that keeps the
order); then r = (t_mj(k) - t_dk) / sigma_t and, for each given quantity q of the list,
(q_mj(k) - q_dk) / sigma_q. Default noise: sigma_t = 1e-4 s (a 10 kHz sensor's sample
interval), sigma_q = 5 % of the median measured |q| (the scale of the intervals comes from
the residuals, s^2 = sum r^2 / (n - k): only the ratios of the sigmas weight the fit).

*Several records* (:class:`MultiProblem`): each record with its own problem (and its own
scenario overrides, e.g. another initial speed), the residual vectors and Jacobians
stacked, one covariance for the shared free parameters.

*The record's time offset* (free key ``record.time_offset``; with several records one each,
``record[i].time_offset``): the model's time of the record's t = 0, tau, so that sample i
is the model at t_i + tau and an impact the record shows at t_dk is the model's at
t_dk + tau. A record triggered a fraction of a sample
late or early (unavoidable where the trigger is the first impact) otherwise leaves residuals
of the size of the signal's change over that fraction, which the fit absorbs into the
contact parameters. Its Jacobian column: d m_q / d tau, the model's time derivative (x': the
sampled speed; the acceleration and force by central differences in tau, which move only
the samples, not the run); for impact times -1 / sigma_t.

Parameters are handled in the unit box u in [0, 1]^k (:class:`FreeParameter`).

Jacobians
---------
``exact``: the forward sensitivities of the simulator (``simulate(..., sensitivities=keys)``,
derivatives of the sampled state, acceleration and contact force and of each impact's onset
time, approach speed, peak force, rebound speed and dissipated energy), times d p / d u.
``fd``: central differences in u with step h = 1e-5 (one-sided at the bounds); the solver's
tolerance (relative 1e-8) makes their error about 1e-8 / h relative, small against the noise
of a measurement, and they need no support from the core.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from braidsim.errors import InputError, SimulationError
from braidsim.fit.data import ImpactList, Record, detect_pulses, noise_estimate, pulse_levels
from braidsim.fit.spec import FreeParameter, is_offset, offset_key, scenario_values
from braidsim.params import Scenario
from braidsim.result import Result

#: step of the central differences in the unit box
FD_STEP = 1e-5
#: quantity -> column of the sensitivity series (braidsim.sensitivity.SERIES_QUANTITIES)
SENS_COLUMN = {"x": "x", "acceleration": "ax", "contact_force": "track_contact_force"}
#: noise levels by which a model impact's sampled pulse must reach past the record's pulse
#: threshold to count as one the record must show, and may fall short of it and still be
#: one it may show (a pulse near the threshold is in the record or not by its noise)
PULSE_MARGIN = 3.0
#: residual given to every sample where the model fails (the step is then rejected)
FAILED_RESIDUAL = 1e6


def exact_available() -> bool:
    """Whether the simulator provides forward sensitivities (``braidsim.sensitivity``)."""
    try:
        import braidsim.sensitivity  # noqa: F401
    except ImportError:
        return False
    return True


def _exact_jacobian(jacobian: str) -> bool:
    """Whether a problem uses the exact Jacobian for ``fit.jacobian`` = ``jacobian``
    ("exact", "auto" or "fd"): "auto" where the installation has the forward sensitivities;
    "exact" without them is refused."""
    if jacobian == "exact" and not exact_available():
        raise InputError(
            "fit.jacobian: 'exact' needs the simulator's forward sensitivities, which this "
            "installation lacks; allowed auto or fd"
        )
    return jacobian == "exact" or (jacobian == "auto" and exact_available())


def model_acceleration(res: Result) -> np.ndarray:
    """The carrier's acceleration dvx/dt [m/s^2] on the rows of ``res.series``:
    a_x = (-F_c - f_x - F_x - m r_c omega^2) / m, the equation of motion of the core."""
    rec = res.model.record
    s = res.series
    om = np.asarray(s["omega"])
    load = rec.load_x + rec.mass_radius * om * om
    return (-np.asarray(s["track_contact_force"]) - np.asarray(s["friction_x"]) - load) / rec.mass


def predict(res: Result, quantity: str) -> np.ndarray:
    """The model's value of a measured quantity on the rows of ``res.series``."""
    if quantity == "x":
        return np.asarray(res.series["x"], dtype=float)
    if quantity == "acceleration":
        return model_acceleration(res)
    if quantity == "contact_force":
        return np.asarray(res.series["track_contact_force"], dtype=float)
    raise InputError(f"quantity: {quantity!r} is not a measured quantity")


class TooFewImpacts(SimulationError):
    """The model gives fewer track impacts than an impact list holds."""


class _ExactUnavailable(SimulationError):
    """The simulator's sensitivities failed with an error outside their contract."""


@dataclass
class Evaluation:
    """Residuals (and Jacobian, when asked) at one point of the unit box."""

    u: np.ndarray
    r: np.ndarray
    J: np.ndarray | None
    result: Result | None


class Problem:
    """The fit of ``free`` parameters of ``scenario`` to ``record``.

    Parameters
    ----------
    scenario : Scenario
        Every fixed parameter (the free ones are overridden).
    record : Record
    free : sequence of FreeParameter
    quantities : sequence of str
        The record's columns to fit.
    noise : mapping, optional
        Sensor noise sigma_q [SI] per quantity; estimated from the record where absent.
    jacobian : {"auto", "exact", "fd"}
    time_offset : float, optional
        The record's time offset [s] where it is not free (a profile fixes it).
    part : int, optional
        The record's index among several fitted together (:class:`MultiProblem`): its
        offset is the free key ``record[part].time_offset``, and the others' offsets are
        free keys it does not depend on.
    """

    def __init__(
        self,
        scenario: Scenario,
        record: Record,
        free: Sequence[FreeParameter],
        quantities: Sequence[str],
        noise: Mapping[str, float] | None = None,
        jacobian: str = "auto",
        time_offset: float = 0.0,
        part: int | None = None,
    ) -> None:
        for q in quantities:
            if q not in record.columns:
                raise InputError(
                    f"fit.quantity: {q!r} is not a column of the record {record.source}; "
                    f"allowed {', '.join(record.columns)}"
                )
        self.scenario = scenario
        self.record = record
        self._set_free(free, time_offset, part)
        for p in self.free:
            if p.key == self.offset_key and record.t[0] + p.low < 0:
                raise InputError(
                    f"fit.free.{offset_key(None)}: a lower bound of {p.low:g} s puts the record "
                    f"{record.source}'s "
                    f"first sample (t = {record.t[0]:g} s) before the model's start at t = 0; "
                    f"allowed >= {-record.t[0]:g} s"
                )
        self.quantities = tuple(quantities)
        sig: dict[str, float] = {}
        for q in self.quantities:
            s = (noise or {}).get(q) or noise_estimate(record.columns[q])
            if not s > 0:
                # a noiseless record (synthetic): a tiny floor keeps the scale finite
                s = 1e-9 * max(float(np.max(np.abs(record.columns[q]))), 1e-30)
            sig[q] = float(s)
        self.sigma = sig
        self.data = np.concatenate([record.columns[q] / sig[q] for q in self.quantities])
        self.n_t = record.t.size
        self.exact = _exact_jacobian(jacobian)
        self.jacobian_choice = jacobian
        self.notes: set[str] = set()
        # impact onsets of the record, from its first acceleration or force column
        self.event_quantity = next(
            (q for q in ("acceleration", "contact_force") if q in record.columns), None
        )
        self.onsets = np.zeros(0)
        self.pulse_threshold = self.pulse_base = self.pulse_noise = math.nan
        if self.event_quantity is not None:
            y = record.columns[self.event_quantity]
            noise_q = sig.get(self.event_quantity) or noise_estimate(y)
            self.onsets, self.pulse_threshold = detect_pulses(record.t, y, noise_q)
            self.pulse_base = pulse_levels(y, noise_q)[0]
            self.pulse_noise = noise_q
        self.evaluations = 0
        #: whether the global stage works on the event residuals (when the record has some)
        self.use_events = True

    # -- parameters ------------------------------------------------------------------------

    def _set_free(
        self, free: Sequence[FreeParameter], time_offset: float, part: int | None = None
    ) -> None:
        """The free parameters; which of them the scenario takes, and this record's time
        offset (``part``: its index among several records)."""
        self.free = tuple(free)
        self.keys = tuple(p.key for p in self.free)
        self.part = part
        self.offset_key = offset_key(part)
        #: the free keys the scenario takes (in order), and where this record's offset is
        self.scenario_keys = tuple(k for k in self.keys if not is_offset(k))
        self.i_offset = self.keys.index(self.offset_key) if self.offset_key in self.keys else None
        self.fixed_offset = float(time_offset)

    def time_offset(self, u: np.ndarray) -> float:
        """The record's time offset [s] at ``u``: the model's time of the record's t = 0."""
        if self.i_offset is None:
            return self.fixed_offset
        return self.free[self.i_offset].from_unit(float(u[self.i_offset]))

    def _scenario_columns(self) -> list[int]:
        """The Jacobian's columns of :attr:`scenario_keys`."""
        return [i for i, k in enumerate(self.keys) if not is_offset(k)]

    def _columns(self) -> list[int]:
        """The Jacobian's columns this record's residuals depend on: the scenario's keys
        and its own offset (another record's offset moves none of its residuals)."""
        own = [] if self.i_offset is None else [self.i_offset]
        return sorted(self._scenario_columns() + own)

    def values(self, u: np.ndarray) -> dict[str, float]:
        """``{key: SI value}`` at the unit-box point ``u``."""
        return {p.key: p.from_unit(float(v)) for p, v in zip(self.free, u, strict=True)}

    def to_unit(self, values: Mapping[str, float]) -> np.ndarray:
        return np.array([p.to_unit(values[p.key]) for p in self.free])

    @property
    def u_start(self) -> np.ndarray:
        return np.array([p.to_unit(p.start) for p in self.free])

    def dp_du(self, u: np.ndarray) -> np.ndarray:
        return np.array([p.dp_du(float(v)) for p, v in zip(self.free, u, strict=True)])

    def scenario_at(self, u: np.ndarray) -> Scenario:
        values = scenario_values(self.values(u))
        return self.scenario.with_overrides(values) if values else self.scenario

    # -- model -----------------------------------------------------------------------------

    def run(self, u: np.ndarray, sensitivities: bool = False) -> Result:
        """Simulate at ``u``, sampled at the record's times (shifted by the time offset)."""
        from braidsim.simulate import simulate

        self.evaluations += 1
        kw: dict[str, Any] = {}
        sensitivities = sensitivities and bool(self.scenario_keys)
        if sensitivities:
            kw["sensitivities"] = list(self.scenario_keys)
        t = self.record.t + self.time_offset(u)
        if sensitivities:
            try:
                return simulate(
                    self.scenario_at(u),
                    duration=float(t[-1]),
                    sample_times=t,
                    record_events=False,
                    **kw,
                )
            except (ValueError, TypeError, AttributeError) as exc:
                if isinstance(exc, InputError):
                    raise
                # the simulator's sensitivities failed outside their documented errors
                raise _ExactUnavailable(f"{type(exc).__name__}: {exc}") from exc
        return simulate(
            self.scenario_at(u),
            duration=float(t[-1]),
            sample_times=t,
            record_events=False,
            **kw,
        )

    def _record_r(self, res: Result, u: np.ndarray) -> np.ndarray:
        m = np.concatenate([predict(res, q) / self.sigma[q] for q in self.quantities])
        if m.shape != self.data.shape:  # pragma: no cover - the solver samples every time
            raise SimulationError(f"the model gave {m.size} samples for {self.data.size}")
        return m - self.data

    def _record_J_exact(self, res: Result, u: np.ndarray) -> np.ndarray:
        from braidsim.sensitivity import SERIES_QUANTITIES

        J = np.zeros((self.data.size, len(self.keys)))
        if self.scenario_keys:
            S = np.asarray(res.sensitivity.series)
            blocks = [
                S[:, :, SERIES_QUANTITIES.index(SENS_COLUMN[q])] / self.sigma[q]
                for q in self.quantities
            ]
            J[:, self._scenario_columns()] = np.vstack(blocks)
        if self.i_offset is not None:
            J[:, self.i_offset] = self._offset_column(res, u)
        return J * self.dp_du(u)[None, :]

    def _offset_column(self, res: Result, u: np.ndarray) -> np.ndarray:
        """d r / d tau [1/s] of the record residuals: the model's time derivative at the
        samples, the sampled speed for x; central differences in tau for the others (two
        runs, whose steps are the same: the offset moves only the samples)."""
        assert self.i_offset is not None
        i = self.i_offset
        cols: list[np.ndarray | None] = [
            np.asarray(res.series["vx"], dtype=float) / self.sigma[q] if q == "x" else None
            for q in self.quantities
        ]
        if any(c is None for c in cols):
            fd = self._fd(u, lambda v: self._record_r(self.run(v), v), None, columns=[i])
            fd = fd[:, i] / self.dp_du(u)[i]
            n = self.n_t
            cols = [c if c is not None else fd[j * n : (j + 1) * n] for j, c in enumerate(cols)]
        return np.concatenate([c for c in cols if c is not None])

    def residuals(self, u: np.ndarray, jac: bool = False) -> Evaluation:
        """Record residuals at ``u`` (and their Jacobian d r / d u when ``jac``)."""
        return self._evaluate(u, jac, self._record_r, self._record_J_exact)

    def _evaluate(
        self,
        u: np.ndarray,
        jac: bool,
        r_of: Callable[[Result, np.ndarray], np.ndarray],
        J_exact_of: Callable[[Result, np.ndarray], np.ndarray],
    ) -> Evaluation:
        """The residuals ``r_of(run, u)`` of the run at ``u`` and, with ``jac``, their
        Jacobian: exact from the run's sensitivities (``J_exact_of``) where the problem
        allows them and they succeed, else by finite differences."""
        u = np.asarray(u, dtype=float)
        if jac and self.exact:
            try:
                res = self.run(u, sensitivities=True)
                return Evaluation(u, r_of(res, u), J_exact_of(res, u), res)
            except SimulationError as exc:
                if not self._exact_failed(exc):
                    raise
        res = self.run(u)
        r = r_of(res, u)
        J = self._fd(u, lambda v: r_of(self.run(v), v), r) if jac else None
        return Evaluation(u, r, J, res)

    # -- events ----------------------------------------------------------------------------

    def _model_onsets(
        self, res: Result, u: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Onsets [s, the record's time] of the model's track impacts that the record may
        show, and their rows in ``res.impacts``, then the same of those it must show: the
        first those whose samples of the model's own series (at the record's times) within
        the contact reach the record's pulse threshold less :data:`PULSE_MARGIN` noise
        levels, the second beyond it by as much, as :func:`~braidsim.fit.data.detect_pulses`
        sees the record. (By the contact's continuous peak instead, an impact 3-4 samples long
        whose noisy samples all missed the threshold counted as a pulse the record lacks,
        4.4 ms from any: on paper-3.1 that residual moved the impact-time stage's optimum
        to a clearance 2.4 % off, and the record residuals' fit from there ended in a local
        minimum with residuals 12 times the noise in 5 of 20 records.)"""
        imp = res.impacts
        rows = np.flatnonzero(np.asarray(imp["pair"] == "track") & ~np.asarray(imp["initial"]))
        assert self.event_quantity is not None
        excursion = np.abs(predict(res, self.event_quantity) - self.pulse_base)
        ts = self.record.t + self.time_offset(u)
        t_on = np.asarray(imp["t"], dtype=float)[rows]
        t_end = np.nan_to_num(np.asarray(imp["t_end"], dtype=float)[rows], nan=np.inf)
        a = np.searchsorted(ts, t_on)
        b = np.searchsorted(ts, t_end, "right")
        peak = np.array([excursion[i:j].max() if j > i else 0.0 for i, j in zip(a, b, strict=True)])
        margin = PULSE_MARGIN * self.pulse_noise
        t_rec = t_on - self.time_offset(u)
        may = peak > self.pulse_threshold - margin
        must = peak > self.pulse_threshold + margin
        return t_rec[may], rows[may], t_rec[must], rows[must]

    def _event_parts(
        self, tm: np.ndarray, rows: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(the measured onsets' residuals, the index of each one's nearest model impact
        among those the record may show, whose onsets ``tm`` and rows are given, those
        onsets and rows)."""
        td = self.onsets
        sig_t = self.record.sample_interval
        T = self.record.duration
        if tm.size == 0:
            return (T - td) / sig_t, np.zeros(0, dtype=int), tm, rows
        near = np.abs(tm[None, :] - td[:, None]).argmin(axis=1)
        return (tm[near] - td) / sig_t, near, tm, rows

    def _extra_parts(self, tm: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(each model impact the record must show, of onsets ``tm`` and rows given: its
        onset less its nearest measured one [s], its row)."""
        td = self.onsets
        if tm.size == 0 or td.size == 0:
            return np.zeros(0), rows[:0]
        diff = tm[:, None] - td[None, :]
        return diff[np.arange(tm.size), np.abs(diff).argmin(axis=1)], rows

    def _event_r(self, res: Result, u: np.ndarray) -> np.ndarray:
        t_may, rows_may, t_must, rows_must = self._model_onsets(res, u)
        r_d = self._event_parts(t_may, rows_may)[0]
        d = self._extra_parts(t_must, rows_must)[0]
        extra = float(np.sqrt(np.sum(d * d))) / self.record.sample_interval
        return np.concatenate([r_d, [extra]])

    def _event_J_exact(self, res: Result, u: np.ndarray) -> np.ndarray:
        n_imp = np.asarray(res.impacts["t"]).size
        k = len(self.keys)
        # (n_impacts, k): d t_onset / d key, in the record's time; the offset's -1
        dt = np.zeros((n_imp, k))
        if self.scenario_keys:
            dt[:, self._scenario_columns()] = np.asarray(res.sensitivity.impacts)[:, :, 0]
        if self.i_offset is not None:
            dt[:, self.i_offset] = -1.0
        t_may, rows_may, t_must, rows_must = self._model_onsets(res, u)
        _r_d, near, tm, rows = self._event_parts(t_may, rows_may)
        sig_t = self.record.sample_interval
        J = np.zeros((self.onsets.size + 1, k))
        if tm.size:
            J[: self.onsets.size] = dt[rows[near]] / sig_t
        d, rows_x = self._extra_parts(t_must, rows_must)
        extra = float(np.sqrt(np.sum(d * d)))
        if extra > 0:
            J[-1] = (d[:, None] * dt[rows_x]).sum(axis=0) / extra / sig_t
        return np.nan_to_num(J) * self.dp_du(u)[None, :]

    def event_residuals(self, u: np.ndarray, jac: bool = False) -> Evaluation:
        """Event residuals at ``u`` (and their Jacobian d r / d u when ``jac``)."""
        return self._evaluate(u, jac, self._event_r, self._event_J_exact)

    @property
    def has_events(self) -> bool:
        return self.onsets.size > 0

    def _exact_failed(self, exc: SimulationError) -> bool:
        """Whether to answer this point with central differences instead of the exact
        Jacobian: at a grazing contact (no derivative exists there; the differences give
        the secant) and, under ``jacobian = "auto"``, when the simulator's sensitivities
        fail otherwise (then for the rest of the fit, with a note)."""
        from braidsim.sensitivity import SensitivityError

        if isinstance(exc, SensitivityError):
            self.notes.add(
                f"exact Jacobian undefined at a grazing contact ({exc}); central "
                "differences used there"
            )
            return True
        if isinstance(exc, _ExactUnavailable) and self.jacobian_choice == "auto":
            self.exact = False
            self.notes.add(
                f"the simulator's sensitivities failed ({exc}); central differences used"
            )
            return True
        return False

    # -- finite differences ----------------------------------------------------------------

    def _fd(
        self, u: np.ndarray, f: Any, r0: np.ndarray | None, columns: Sequence[int] | None = None
    ) -> np.ndarray:
        """Central differences of ``f`` in the unit box (one-sided within h of a bound), in
        ``columns`` of u (by default those the residuals depend on, :meth:`_columns`; the
        others are 0); ``r0``, f(u), may be None where they need none."""
        cols = self._columns() if columns is None else columns
        J = np.empty((0, 0))
        h = FD_STEP
        for j in cols:
            up, dn = u.copy(), u.copy()
            if u[j] + h > 1.0:
                dn[j] -= h
                col = ((f(u) if r0 is None else r0) - f(dn)) / h
            elif u[j] - h < 0.0:
                up[j] += h
                col = (f(up) - (f(u) if r0 is None else r0)) / h
            else:
                up[j] += h
                dn[j] -= h
                col = (f(up) - f(dn)) / (2 * h)
            if not J.size:
                J = np.zeros((col.size, u.size))
            J[:, j] = col
        if not J.size:
            J = np.zeros(((f(u) if r0 is None else r0).size, u.size))
        return J

    def rebuild(
        self,
        scenario: Scenario,
        free: Sequence[FreeParameter],
        jacobian: str,
        time_offset: float | None = None,
    ) -> Problem:
        """The same data and noise with another scenario and free set (profiles, laws), and
        the time offset fixed at ``time_offset`` where given (else this one's fixed one)."""
        off = self.fixed_offset if time_offset is None else time_offset
        return Problem(
            scenario, self.record, free, self.quantities, self.sigma, jacobian, off, self.part
        )

    def jacobian_fd(self, u: np.ndarray, kind: str = "record") -> np.ndarray:
        """The finite-difference Jacobian d r / d u (the fallback, and the cross-check of the
        exact one), of the record or the event residuals."""
        u = np.asarray(u, dtype=float)
        if kind == "record":
            r0 = self._record_r(self.run(u), u)
            return self._fd(u, lambda v: self._record_r(self.run(v), v), r0)
        r0 = self._event_r(self.run(u), u)
        return self._fd(u, lambda v: self._event_r(self.run(v), v), r0)


#: default noise of an impact list: onset times [s] ...
IMPACT_TIME_NOISE = 1e-4
#: ... and the other quantities, relative to the median measured magnitude
IMPACT_RELATIVE_NOISE = 0.05


def match_impacts(td: np.ndarray, tm: np.ndarray) -> np.ndarray:
    """Indices j(k) into ``tm`` (strictly increasing) matching the measured onsets ``td``:
    the order-keeping assignment of least sum (tm[j(k)] - td[k])^2, by dynamic programming
    over C[k, j] = min(C[k, j - 1], C[k - 1, j - 1] + (tm[j] - td[k])^2).
    Needs ``tm.size >= td.size``."""
    n, m = td.size, tm.size
    d2 = (tm[None, :] - td[:, None]) ** 2
    take = np.full((n, m), np.inf)  # cost with measured k matched to model j
    best = np.zeros(m)  # C[k - 1, j]: the first k measured within model 0..j
    for k in range(n):
        prev = np.r_[0.0, best[:-1]] if k == 0 else np.r_[np.inf, best[:-1]]
        take[k] = prev + d2[k]
        take[k, :k] = np.inf
        best = np.minimum.accumulate(take[k])
    out = np.empty(n, dtype=int)
    hi = m - 1
    for k in range(n - 1, -1, -1):
        out[k] = int(np.argmin(take[k, : hi + 1]))
        hi = out[k] - 1
    return out


class ImpactProblem(Problem):
    """The fit of ``free`` parameters of ``scenario`` to a measured impact list.

    The model runs to 1.2 t_last + 10 ms (t_last the list's last onset, plus the largest
    time offset), so that the last impact ends and a model impact late against the list can
    still be matched.
    """

    def __init__(
        self,
        scenario: Scenario,
        record: ImpactList,
        free: Sequence[FreeParameter],
        quantities: Sequence[str] = (),
        noise: Mapping[str, float] | None = None,
        jacobian: str = "auto",
        time_offset: float = 0.0,
        part: int | None = None,
    ) -> None:
        self.scenario = scenario
        self.impacts = record
        self._set_free(free, time_offset, part)
        # (none named: every column; the onset times are fitted always)
        chosen = (
            [q for q in quantities if q in record.columns] if quantities else list(record.columns)
        )
        self.quantities = ("t", *chosen)
        noise = noise or {}
        sig = {"t": float(noise.get("t") or IMPACT_TIME_NOISE)}
        for q in chosen:
            med = float(np.median(np.abs(record.columns[q])))
            s = noise.get(q) or IMPACT_RELATIVE_NOISE * med
            if not s > 0:
                # (a floor of 1e-9 made residuals beyond FAILED_RESIDUAL: the fit then
                # preferred parameters where the model failed)
                raise InputError(
                    f"fit.noise.{q}: not given, and the default (5 % of the median of "
                    f"{record.source}'s column {q}) is 0; allowed a noise level > 0 in "
                    "fit.noise, or a column whose median is > 0"
                )
            sig[q] = float(s)
        self.sigma = sig
        latest = max([self.fixed_offset, *(p.high for p in self.free if p.key == self.offset_key)])
        self.duration = 1.2 * (record.duration + max(latest, 0.0)) + 0.01
        self.exact = _exact_jacobian(jacobian)
        self.jacobian_choice = jacobian
        self.notes: set[str] = set()
        self.event_quantity = None
        self.onsets = np.zeros(0)
        self.pulse_threshold = self.pulse_base = self.pulse_noise = math.nan
        self.evaluations = 0
        self.use_events = False
        self.n_t = record.t.size

    @property
    def source(self) -> str:
        return self.impacts.source

    def run(self, u: np.ndarray, sensitivities: bool = False) -> Result:
        """Simulate at ``u`` to :attr:`duration` (impacts only; one sample at the end)."""
        from braidsim.simulate import simulate

        self.evaluations += 1
        sensitivities = sensitivities and bool(self.scenario_keys)
        kw: dict[str, Any] = {"sensitivities": list(self.scenario_keys)} if sensitivities else {}
        return simulate(
            self.scenario_at(u),
            duration=self.duration,
            sample_times=np.array([self.duration]),
            record_events=False,
            **kw,
        )

    def model_rows(self, res: Result, u: np.ndarray) -> np.ndarray:
        """Rows of ``res.impacts`` matched to the measured impacts (see :func:`match_impacts`;
        the model's onsets in the list's time, at the time offset of ``u``).

        Raises
        ------
        SimulationError
            The model has fewer track impacts than the list.
        """
        imp = res.impacts
        rows = np.flatnonzero(np.asarray(imp["pair"] == "track") & ~np.asarray(imp["initial"]))
        n = self.impacts.t.size
        if rows.size < n:
            raise TooFewImpacts(
                f"the model gives {rows.size} track impacts up to t = {self.duration:g} s, "
                f"fewer than the {n} of the impact list {self.impacts.source}"
            )
        tm = np.asarray(imp["t"], dtype=float)[rows] - self.time_offset(u)
        return rows[match_impacts(self.impacts.t, tm)]

    def model_values(self, res: Result, u: np.ndarray) -> dict[str, np.ndarray]:
        """The matched model impacts' values of each fitted quantity (SI; onsets in the
        list's time)."""
        imp = res.impacts
        rows = self.model_rows(res, u)
        out = {"t": np.asarray(imp["t"], dtype=float)[rows] - self.time_offset(u)}
        for q in self.quantities[1:]:
            v = np.asarray(imp[q], dtype=float)[rows]
            if q == "peak_force":
                v = np.abs(v)
            if not np.all(np.isfinite(v)):
                k = int(np.flatnonzero(~np.isfinite(v))[0])
                raise SimulationError(
                    f"the model's impact at t = {out['t'][k]:.6g} s has no {q} (its contact "
                    "lasts to the end of the run)"
                )
            out[q] = v
        return out

    def _r_of(self, res: Result, u: np.ndarray) -> np.ndarray:
        m = self.model_values(res, u)
        data = {"t": self.impacts.t, **self.impacts.columns}
        return np.concatenate([(m[q] - data[q]) / self.sigma[q] for q in self.quantities])

    def _record_r(self, res: Result, u: np.ndarray) -> np.ndarray:
        return self._r_of(res, u)

    def _record_J_exact(self, res: Result, u: np.ndarray) -> np.ndarray:
        from braidsim.sensitivity import IMPACT_QUANTITIES

        rows = self.model_rows(res, u)
        peak = np.asarray(res.impacts["peak_force"], dtype=float)[rows]
        k = len(self.keys)
        S = np.zeros((rows.size, k, len(IMPACT_QUANTITIES)))  # (n, k, 7)
        if self.scenario_keys:
            S[:, self._scenario_columns()] = np.asarray(res.sensitivity.impacts)[rows]
        if self.i_offset is not None:
            # (in the list's time a model onset moves back as the offset grows; the other
            # quantities do not move)
            S[:, self.i_offset, IMPACT_QUANTITIES.index("t")] = -1.0
        blocks = []
        for q in self.quantities:
            b = S[:, :, IMPACT_QUANTITIES.index(q)] / self.sigma[q]
            if q == "peak_force":
                b = b * np.sign(peak)[:, None]
            blocks.append(b * self.dp_du(u)[None, :])
        return np.nan_to_num(np.vstack(blocks))

    def residuals(self, u: np.ndarray, jac: bool = False) -> Evaluation:
        """Impact-list residuals at ``u`` (and their Jacobian d r / d u when ``jac``)."""
        return Problem.residuals(self, u, jac)

    def event_residuals(self, u: np.ndarray, jac: bool = False) -> Evaluation:
        # the impact-list residuals are event residuals already
        return self.residuals(u, jac)

    @property
    def has_events(self) -> bool:
        return False

    def rebuild(
        self,
        scenario: Scenario,
        free: Sequence[FreeParameter],
        jacobian: str,
        time_offset: float | None = None,
    ) -> ImpactProblem:
        off = self.fixed_offset if time_offset is None else time_offset
        return ImpactProblem(
            scenario, self.impacts, free, self.quantities, self.sigma, jacobian, off, self.part
        )

    def jacobian_fd(self, u: np.ndarray, kind: str = "record") -> np.ndarray:
        u = np.asarray(u, dtype=float)
        r0 = self._r_of(self.run(u), u)
        return self._fd(u, lambda v: self._r_of(self.run(v), v), r0)


def single_problem(
    scenario: Scenario,
    record: Record | ImpactList,
    free: Sequence[FreeParameter],
    quantities: Sequence[str],
    noise: Mapping[str, float] | None,
    jacobian: str,
    part: int | None = None,
) -> Problem:
    """The problem of one record of either kind (``part``: its index among several), fitting
    ``quantities`` (of an impact list: its onset times and these columns, every column where
    none is named)."""
    if isinstance(record, ImpactList):
        return ImpactProblem(scenario, record, free, quantities, noise, jacobian, 0.0, part)
    return Problem(scenario, record, free, quantities, noise, jacobian, 0.0, part)


class MultiProblem(Problem):
    """Several records fitted together: ``parts`` (one problem each, built on the scenario
    with the record's own overrides) share the free parameters; residuals and Jacobians
    are stacked, so the statistics give one covariance."""

    def __init__(
        self,
        scenario: Scenario,
        parts: Sequence[Problem],
        overrides: Sequence[Mapping[str, Any]],
    ) -> None:
        self.scenario = scenario
        self.parts = list(parts)
        self.part_overrides = [dict(o) for o in overrides]
        first = self.parts[0]
        self._set_free(first.free, 0.0)
        self.quantities = tuple(dict.fromkeys(q for p in self.parts for q in p.quantities))
        self.jacobian_choice = first.jacobian_choice
        self.notes = first.notes
        for p in self.parts:
            p.notes = self.notes  # one set of notes
        self.event_quantity = first.event_quantity
        self.onsets = first.onsets
        self.pulse_threshold = first.pulse_threshold
        self.pulse_base, self.pulse_noise = first.pulse_base, first.pulse_noise
        self.n_t = sum(p.n_t for p in self.parts)

    @property
    def sigma(self) -> dict[str, float]:  # type: ignore[override]
        return dict(self.parts[0].sigma)

    @property
    def record(self) -> Record:  # type: ignore[override]
        return self.parts[0].record

    @property
    def exact(self) -> bool:  # type: ignore[override]
        return all(p.exact for p in self.parts)

    @property
    def evaluations(self) -> int:  # type: ignore[override]
        return sum(p.evaluations for p in self.parts)

    @property
    def use_events(self) -> bool:
        return self.parts[0].use_events

    @use_events.setter
    def use_events(self, value: bool) -> None:
        for p in self.parts:
            p.use_events = value

    def run(self, u: np.ndarray, sensitivities: bool = False) -> Result:
        """The first record's run (the others through :meth:`residuals`)."""
        return self.parts[0].run(u, sensitivities)

    def residuals(self, u: np.ndarray, jac: bool = False) -> Evaluation:
        es = [p.residuals(u, jac) for p in self.parts]
        J = None
        if jac:
            J = np.vstack([e.J for e in es if e.J is not None])
        return Evaluation(
            np.asarray(u, dtype=float), np.concatenate([e.r for e in es]), J, es[0].result
        )

    def event_residuals(self, u: np.ndarray, jac: bool = False) -> Evaluation:
        es = [
            p.event_residuals(u, jac) if p.has_events else p.residuals(u, jac) for p in self.parts
        ]
        J = np.vstack([e.J for e in es if e.J is not None]) if jac else None
        return Evaluation(
            np.asarray(u, dtype=float), np.concatenate([e.r for e in es]), J, es[0].result
        )

    @property
    def has_events(self) -> bool:
        return any(p.has_events for p in self.parts)

    def rebuild(
        self,
        scenario: Scenario,
        free: Sequence[FreeParameter],
        jacobian: str,
        time_offset: float | None = None,
    ) -> MultiProblem:
        # (a time offset given here is each part's where its own offset is not free: a
        # profile of one record's offset of several, record[i].time_offset, leaves the
        # others free)
        parts = [
            p.rebuild(scenario.with_overrides(o) if o else scenario, free, jacobian, time_offset)
            for p, o in zip(self.parts, self.part_overrides, strict=True)
        ]
        return MultiProblem(scenario, parts, self.part_overrides)

    def jacobian_fd(self, u: np.ndarray, kind: str = "record") -> np.ndarray:
        return np.vstack([p.jacobian_fd(u, kind) for p in self.parts])
