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
impacts cost too); sigma_t is the sample interval. The global stage of the fit works on
them; the final fit and its statistics on the record residuals.

Parameters are handled in the unit box u in [0, 1]^k (:class:`FreeParameter`).

Jacobians
---------
``exact``: the forward sensitivities of the simulator (``simulate(..., sensitivities=keys)``,
derivatives of the sampled state, acceleration and contact force and of each impact's onset
time), times d p / d u. ``fd``: central differences in u with step h = 1e-5 (one-sided
at the bounds); the solver's tolerance (relative 1e-8) makes their error about 1e-8 / h
relative, small against the noise of a measurement, and they need no support from the core.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from braidsim.errors import InputError, SimulationError
from braidsim.fit.data import Record, detect_pulses, noise_estimate
from braidsim.fit.spec import FreeParameter
from braidsim.params import Scenario
from braidsim.result import Result

#: step of the central differences in the unit box
FD_STEP = 1e-5
#: quantity -> column of the sensitivity series (braidsim.sensitivity.SERIES_QUANTITIES)
SENS_COLUMN = {"x": "x", "acceleration": "ax", "contact_force": "track_contact_force"}
#: residual given to every sample where the model fails (the step is then rejected)
FAILED_RESIDUAL = 1e6


def exact_available() -> bool:
    """Whether the simulator provides forward sensitivities (``braidsim.sensitivity``)."""
    try:
        import braidsim.sensitivity  # noqa: F401
    except ImportError:
        return False
    return True


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
    """

    def __init__(
        self,
        scenario: Scenario,
        record: Record,
        free: Sequence[FreeParameter],
        quantities: Sequence[str],
        noise: Mapping[str, float] | None = None,
        jacobian: str = "auto",
    ) -> None:
        for q in quantities:
            if q not in record.columns:
                raise InputError(
                    f"fit.quantity: {q!r} is not a column of the record {record.source}; "
                    f"allowed {', '.join(record.columns)}"
                )
        self.scenario = scenario
        self.record = record
        self.free = tuple(free)
        self.keys = tuple(p.key for p in self.free)
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
        if jacobian == "exact" and not exact_available():
            raise InputError(
                "fit.jacobian: 'exact' needs the simulator's forward sensitivities, which this "
                "installation lacks; allowed auto or fd"
            )
        self.exact = jacobian == "exact" or (jacobian == "auto" and exact_available())
        self.jacobian_choice = jacobian
        self.notes: set[str] = set()
        # impact onsets of the record, from its first acceleration or force column
        self.event_quantity = next(
            (q for q in ("acceleration", "contact_force") if q in record.columns), None
        )
        self.onsets = np.zeros(0)
        self.pulse_threshold = math.nan
        if self.event_quantity is not None:
            q = self.event_quantity
            self.onsets, self.pulse_threshold = detect_pulses(
                record.t, record.columns[q], sig.get(q) or noise_estimate(record.columns[q])
            )
        self.evaluations = 0
        #: whether the global stage works on the event residuals (when the record has some)
        self.use_events = True

    # -- parameters ------------------------------------------------------------------------

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
        return self.scenario.with_overrides(self.values(u))

    # -- model -----------------------------------------------------------------------------

    def run(self, u: np.ndarray, sensitivities: bool = False) -> Result:
        """Simulate at ``u``, sampled at the record's times."""
        from braidsim.simulate import simulate

        self.evaluations += 1
        kw: dict[str, Any] = {}
        if sensitivities:
            kw["sensitivities"] = list(self.keys)
        t = self.record.t
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

    def _record_r(self, res: Result) -> np.ndarray:
        m = np.concatenate([predict(res, q) / self.sigma[q] for q in self.quantities])
        if m.shape != self.data.shape:  # pragma: no cover - the solver samples every time
            raise SimulationError(f"the model gave {m.size} samples for {self.data.size}")
        return m - self.data

    def _record_J_exact(self, res: Result, u: np.ndarray) -> np.ndarray:
        from braidsim.sensitivity import SERIES_QUANTITIES

        sens = res.sensitivity
        S = np.asarray(sens.series)
        blocks = [
            S[:, :, SERIES_QUANTITIES.index(SENS_COLUMN[q])] / self.sigma[q]
            for q in self.quantities
        ]
        return np.vstack(blocks) * self.dp_du(u)[None, :]

    def residuals(self, u: np.ndarray, jac: bool = False) -> Evaluation:
        """Record residuals at ``u`` (and their Jacobian d r / d u when ``jac``)."""
        u = np.asarray(u, dtype=float)
        if jac and self.exact:
            try:
                res = self.run(u, sensitivities=True)
                return Evaluation(u, self._record_r(res), self._record_J_exact(res, u), res)
            except SimulationError as exc:
                if not self._exact_failed(exc):
                    raise
        res = self.run(u)
        r = self._record_r(res)
        J = self._fd(u, lambda v: self._record_r(self.run(v)), r) if jac else None
        return Evaluation(u, r, J, res)

    # -- events ----------------------------------------------------------------------------

    def _model_onsets(self, res: Result) -> tuple[np.ndarray, np.ndarray]:
        """Onsets [s] of the model's track impacts that the record would show (peak above
        the pulse threshold), and their rows in ``res.impacts``."""
        imp = res.impacts
        rows = np.flatnonzero(np.asarray(imp["pair"] == "track") & ~np.asarray(imp["initial"]))
        peak = np.abs(np.asarray(imp["peak_force"], dtype=float))[rows]
        if self.event_quantity == "acceleration":
            peak = peak / res.model.record.mass
        keep = rows[peak > self.pulse_threshold]
        return np.asarray(imp["t"], dtype=float)[keep], keep

    def _event_parts(self, res: Result) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        tm, rows = self._model_onsets(res)
        td = self.onsets
        sig_t = self.record.sample_interval
        T = self.record.duration
        if tm.size == 0:
            return (T - td) / sig_t, np.zeros(0, dtype=int), tm, rows
        near = np.abs(tm[None, :] - td[:, None]).argmin(axis=1)
        return (tm[near] - td) / sig_t, near, tm, rows

    def _event_r(self, res: Result) -> np.ndarray:
        r_d, _, tm, _ = self._event_parts(res)
        td = self.onsets
        if tm.size == 0 or td.size == 0:
            extra = 0.0
        else:
            d = np.abs(tm[:, None] - td[None, :]).min(axis=1)
            extra = float(np.sqrt(np.sum(d * d))) / self.record.sample_interval
        return np.concatenate([r_d, [extra]])

    def _event_J_exact(self, res: Result, u: np.ndarray) -> np.ndarray:
        sens = res.sensitivity
        dt = np.asarray(sens.impacts)[:, :, 0]  # (n_impacts, k): d t_onset / d key
        _r_d, near, tm, rows = self._event_parts(res)
        sig_t = self.record.sample_interval
        k = len(self.keys)
        J = np.zeros((self.onsets.size + 1, k))
        if tm.size:
            J[: self.onsets.size] = dt[rows[near]] / sig_t
            td = self.onsets
            diff = tm[:, None] - td[None, :]
            j_near = np.abs(diff).argmin(axis=1)
            d = diff[np.arange(tm.size), j_near]
            extra = float(np.sqrt(np.sum(d * d)))
            if extra > 0:
                J[-1] = (d[:, None] * dt[rows]).sum(axis=0) / extra / sig_t
        return np.nan_to_num(J) * self.dp_du(u)[None, :]

    def event_residuals(self, u: np.ndarray, jac: bool = False) -> Evaluation:
        """Event residuals at ``u`` (and their Jacobian d r / d u when ``jac``)."""
        u = np.asarray(u, dtype=float)
        if jac and self.exact:
            try:
                res = self.run(u, sensitivities=True)
                return Evaluation(u, self._event_r(res), self._event_J_exact(res, u), res)
            except SimulationError as exc:
                if not self._exact_failed(exc):
                    raise
        res = self.run(u)
        r = self._event_r(res)
        J = self._fd(u, lambda v: self._event_r(self.run(v)), r) if jac else None
        return Evaluation(u, r, J, res)

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

    def _fd(self, u: np.ndarray, f: Any, r0: np.ndarray) -> np.ndarray:
        """Central differences of ``f`` in the unit box (one-sided within h of a bound)."""
        J = np.empty((r0.size, u.size))
        h = FD_STEP
        for j in range(u.size):
            up, dn = u.copy(), u.copy()
            if u[j] + h > 1.0:
                dn[j] -= h
                J[:, j] = (r0 - f(dn)) / h
            elif u[j] - h < 0.0:
                up[j] += h
                J[:, j] = (f(up) - r0) / h
            else:
                up[j] += h
                dn[j] -= h
                J[:, j] = (f(up) - f(dn)) / (2 * h)
        return J

    def jacobian_fd(self, u: np.ndarray, kind: str = "record") -> np.ndarray:
        """The finite-difference Jacobian d r / d u (the fallback, and the cross-check of the
        exact one), of the record or the event residuals."""
        u = np.asarray(u, dtype=float)
        if kind == "record":
            r0 = self._record_r(self.run(u))
            return self._fd(u, lambda v: self._record_r(self.run(v)), r0)
        r0 = self._event_r(self.run(u))
        return self._fd(u, lambda v: self._event_r(self.run(v)), r0)
