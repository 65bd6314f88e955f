"""Estimation: global start, local least squares, statistics, profiles, model selection.

Method
------
1. *Global stage* (where the objective is multimodal: a wrong impact time makes the record
   residuals flat or oscillating in the parameters). From ``starts`` points of the unit box
   (the spec's start and a Latin hypercube, seeded) a short least-squares run on the event
   residuals when the record shows impacts (else on the record residuals); or scipy's
   ``differential_evolution`` on the same sum of squares.
2. *Local stage*: ``scipy.optimize.least_squares`` (trust-region reflective, bounds = the unit
   box) on the record residuals from the best two global end points; the lower cost wins.
3. *Statistics* at the optimum p^ with J = d r / d p (r scaled by the noise):
   s^2 = sum r^2 / (n - k), Cov = s^2 (J^T J)^-1, standard errors sqrt(diag Cov),
   95 % intervals p^ +- t_{0.975, n-k} se, correlation Cov_ij / (se_i se_j)
   (Bates & Watts, Nonlinear Regression Analysis and Its Applications, Wiley 1988,
   doi:10.1002/9780470316757, ch. 2). These linearised intervals are exact for a model
   linear in p and good where the curvature is small over the interval; the profile
   likelihood checks that.
4. *Profile likelihood* of a key: fixed at a grid of values around p^, the others refitted;
   Delta chi^2 = (sum r^2 - sum r^2 min) / s^2, whose 95 % region is Delta < 3.84
   (chi^2_1; Venzon & Moolgavkar, Appl. Stat. 37 (1988) 87, doi:10.2307/2347496).
5. *Model selection* across contact laws: every law fitted the same way (its free parameters
   that change nothing dropped), then with RSS = sum r^2 on the same noise scale
   AIC = n ln(RSS/n) + 2k and BIC = n ln(RSS/n) + k ln n (Akaike, IEEE TAC 19 (1974) 716,
   doi:10.1109/TAC.1974.1100705; Schwarz, Ann. Stat. 6 (1978) 461,
   doi:10.1214/aos/1176344136); the lowest AIC is selected. A dissipative law that ends
   worse than the best of its exponent is fitted once more from that law's optimum mapped
   onto it (the c_r where the damping factors agree, :func:`restart_from_twins`): with the
   restitution free the two are one force law, and a search of its own can end in a local
   minimum.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from braidsim.errors import InputError, SimulationError
from braidsim.fit.data import ImpactList, Record
from braidsim.fit.problem import (
    FAILED_RESIDUAL,
    Evaluation,
    ImpactProblem,
    MultiProblem,
    Problem,
    TooFewImpacts,
    single_problem,
)
from braidsim.fit.spec import (
    TIME_OFFSET,
    FitSpec,
    FreeParameter,
    is_offset,
    offset_key,
    per_record_offsets,
)
from braidsim.params import Scenario, load_scenario
from braidsim.units import to_si

Progress = Callable[[str], None]

#: |correlation| above which a pair is reported as not separable
CORRELATION_LIMIT = 0.99
#: condition number of the column-scaled J above which J^T J counts as near-singular
#: (J^T J then has condition above 1e12)
CONDITION_LIMIT = 1e6
#: a free parameter whose column of J is below this fraction of the largest does not
#: change the fitted residuals at the start: the data cannot inform it
UNINFORMED = 1e-9


@dataclass
class LocalFit:
    """One local least-squares run."""

    u: np.ndarray
    cost: float  # 0.5 sum r^2
    converged: bool
    nfev: int
    njev: int
    message: str


@dataclass
class Statistics:
    """Estimates and their uncertainty at an optimum (SI)."""

    keys: tuple[str, ...]
    values: np.ndarray
    stderr: np.ndarray
    ci95: np.ndarray  # (k, 2)
    covariance: np.ndarray
    correlation: np.ndarray
    residual_std: float  # s
    dof: int
    singular_values: np.ndarray  # of the column-scaled J
    warnings: list[str]


@dataclass
class Profile:
    key: str
    values: np.ndarray
    delta: np.ndarray  # Delta chi^2
    ci95: tuple[float | None, float | None]


@dataclass
class LawResult:
    law: str
    keys: tuple[str, ...]
    values: dict[str, float]
    cost: float
    n: int
    k: int
    aic: float
    bic: float
    restitution: float
    effective_restitution: float
    converged: bool
    exponent: float = math.nan  # the force exponent n of the fitted scenario
    restitution_inside: bool = False  # the restitution free and not at a bound


@dataclass
class FitResult:
    """Everything a fit found (see :func:`fit_record`)."""

    law: str
    keys: tuple[str, ...]
    free: tuple[FreeParameter, ...]
    stats: Statistics
    converged: bool
    cost: float
    n_data: int
    noise: dict[str, float]
    quantities: tuple[str, ...]
    record: Record | ImpactList
    prediction: dict[str, np.ndarray]
    scenario: Scenario
    jacobian: str
    starts: list[dict[str, Any]]
    profiles: list[Profile] = field(default_factory=list)
    laws: list[LawResult] = field(default_factory=list)
    impacts_in_record: int = 0
    evaluations: int = 0
    seconds: float = 0.0
    onsets: np.ndarray = field(default_factory=lambda: np.zeros(0))
    notes: list[str] = field(default_factory=list)
    #: every record fitted (one entry for a single record): source, kind, data, model,
    #: residual and noise per quantity
    parts: list[dict[str, Any]] = field(default_factory=list)

    @property
    def values(self) -> dict[str, float]:
        return dict(zip(self.keys, (float(v) for v in self.stats.values), strict=True))

    @property
    def warnings(self) -> list[str]:
        return self.stats.warnings


def _guard(f: Callable[[np.ndarray], Evaluation], n: int) -> Callable[[np.ndarray], Evaluation]:
    """A residual function that answers a failed simulation with large residuals (the
    trust region then shrinks away from the failing parameters) instead of stopping."""

    def g(u: np.ndarray) -> Evaluation:
        try:
            return f(u)
        except SimulationError:
            return Evaluation(u, np.full(n, FAILED_RESIDUAL), None, None)

    return g


def local_fit(
    problem: Problem, u0: np.ndarray, kind: str = "record", max_nfev: int = 60
) -> LocalFit:
    """``scipy.optimize.least_squares`` (trf, unit box) on the record or event residuals."""
    from scipy.optimize import least_squares

    f = problem.residuals if kind == "record" else problem.event_residuals
    n = f(u0).r.size
    cache: dict[bytes, Evaluation] = {}

    def ev(u: np.ndarray, jac: bool) -> Evaluation:
        key = np.asarray(u, dtype=float).tobytes()
        e = cache.get(key)
        if e is not None and (e.J is not None or not jac):
            return e
        try:
            e = f(np.asarray(u, dtype=float), jac)
        except SimulationError:
            e = Evaluation(
                u, np.full(n, FAILED_RESIDUAL), np.zeros((n, len(u))) if jac else None, None
            )
        cache.clear()
        cache[key] = e
        return e

    u0 = np.clip(np.asarray(u0, dtype=float), 0.0, 1.0)
    out = least_squares(
        lambda u: ev(u, False).r,
        u0,
        jac=lambda u: ev(u, True).J,
        bounds=(0.0, 1.0),
        method="trf",
        x_scale=1.0,
        max_nfev=max_nfev,
        xtol=1e-10,
        ftol=1e-10,
        gtol=1e-10,
    )
    return LocalFit(
        np.asarray(out.x),
        float(out.cost),
        bool(out.status > 0),
        int(out.nfev),
        int(out.njev or 0),
        str(out.message),
    )


def check_informed(problem: Problem, u: np.ndarray) -> np.ndarray:
    """Raise :class:`InputError` for a free parameter that does not change the fitted
    residuals at ``u`` (its column of J is zero): the chosen data cannot inform it.
    Returns J."""
    J = problem.residuals(u, jac=True).J
    assert J is not None
    norms = np.sqrt(np.sum(J * J, axis=0))
    top = float(norms.max()) if norms.size else 0.0
    for key, nrm in zip(problem.keys, norms, strict=True):
        if not nrm > UNINFORMED * top or top == 0.0:
            raise InputError(
                f"fit.free.{key}: the chosen data ({', '.join(problem.quantities)}) do not "
                f"depend on {key} at the start; allowed a parameter that changes the "
                "fitted quantity (fix it, or fit another quantity)"
            )
    return J


def statistics(problem: Problem, u: np.ndarray) -> tuple[Statistics, Evaluation]:
    """Estimates, standard errors, 95 % intervals, correlation and identifiability
    warnings at ``u`` (see the module docstring)."""
    from scipy.stats import t as student_t

    e = problem.residuals(u, jac=True)
    assert e.J is not None
    k = u.size
    n = e.r.size
    dof = max(n - k, 1)
    Jp = e.J / problem.dp_du(u)[None, :]  # d r / d p, SI
    s2 = float(np.sum(e.r * e.r)) / dof
    D = np.sqrt(np.sum(Jp * Jp, axis=0))
    D = np.where(D > 0, D, 1.0)
    Jn = Jp / D[None, :]
    _, sv, Vt = np.linalg.svd(Jn, full_matrices=False)
    tiny = sv[0] * 1e-12 if sv.size and sv[0] > 0 else 1.0
    inv = (Vt.T / np.maximum(sv, tiny) ** 2) @ Vt
    cov = s2 * inv / np.outer(D, D)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    corr = np.clip(np.nan_to_num(corr), -1.0, 1.0)
    values = np.array(list(problem.values(u).values()))
    q = float(student_t.ppf(0.975, dof))
    ci = np.column_stack([values - q * se, values + q * se])
    warnings: list[str] = []
    keys = problem.keys
    cond = float(sv[0] / sv[-1]) if sv.size and sv[-1] > 0 else math.inf
    if cond > CONDITION_LIMIT:
        v = np.abs(Vt[-1])
        names = [keys[i] for i in np.flatnonzero(v > 0.3)] or [keys[int(v.argmax())]]
        warnings.append(
            f"near-singular J^T J (condition number {cond * cond:.3g}): the data cannot "
            f"separate {', '.join(names)}; fix one of them or add data that tell them apart"
        )
    for i in range(k):
        for j in range(i + 1, k):
            if abs(corr[i, j]) > CORRELATION_LIMIT:
                warnings.append(
                    f"{keys[i]} and {keys[j]} are correlated (r = {corr[i, j]:+.4f}): the data "
                    "determine a combination of them, not each one"
                )
    for i, p in enumerate(problem.free):
        if 2 * q * se[i] > p.high - p.low:
            warnings.append(
                f"the data barely inform {p.key}: its 95 % interval is wider than its bounds"
            )
        if u[i] < 1e-6 or u[i] > 1 - 1e-6:
            warnings.append(
                f"{p.key} ended at its bound ({values[i]:.6g} {p.unit}); the interval assumes "
                "an optimum inside the bounds: widen them"
            )
    return (
        Statistics(keys, values, se, ci, cov, corr, math.sqrt(s2), dof, sv, warnings),
        e,
    )


def _lhs(k: int, n: int, seed: int) -> np.ndarray:
    from scipy.stats import qmc

    if n <= 0:
        return np.zeros((0, k))
    return qmc.LatinHypercube(d=k, seed=seed).random(n)


def global_stage(
    problem: Problem,
    method: str,
    starts: int,
    seed: int,
    max_nfev: int,
    progress: Progress | None = None,
) -> list[dict[str, Any]]:
    """End points of the global stage, best first: ``[{"u", "cost", "start"}]``."""
    kind = "events" if problem.has_events and problem.use_events else "record"
    u0 = problem.u_start
    if method == "none" or (starts <= 1 and method == "multistart"):
        return [{"u": u0, "cost": math.nan, "start": u0, "kind": "none"}]
    if method == "differential_evolution":
        from scipy.optimize import differential_evolution

        f = problem.event_residuals if kind == "events" else problem.residuals
        n = f(u0).r.size
        g = _guard(f, n)

        def obj(u: np.ndarray) -> float:
            r = g(u).r
            return 0.5 * float(np.dot(r, r))

        out = differential_evolution(
            obj,
            [(0.0, 1.0)] * u0.size,
            seed=seed,
            maxiter=max(10, max_nfev),
            popsize=max(5, starts),
            x0=u0,
            polish=False,
            tol=1e-8,
        )
        return [{"u": np.asarray(out.x), "cost": float(out.fun), "start": u0, "kind": kind}]
    points = np.vstack([u0[None, :], _lhs(u0.size, starts - 1, seed)])
    ends = []
    for i, s in enumerate(points):
        if progress is not None:
            progress(f"global stage: start {i + 1} of {len(points)} ({kind} residuals)")
        try:
            lf = local_fit(problem, s, kind, max_nfev=max(10, max_nfev // 2))
        except SimulationError:
            continue
        ends.append({"u": lf.u, "cost": lf.cost, "start": s, "kind": kind})
    if not ends:
        raise SimulationError("every start of the global stage failed; narrow the bounds")
    ends.sort(key=lambda d: d["cost"])
    return ends


def _distinct(ends: list[dict[str, Any]], m: int) -> list[np.ndarray]:
    out: list[np.ndarray] = []
    for e in ends:
        if all(np.max(np.abs(e["u"] - o)) > 1e-3 for o in out):
            out.append(e["u"])
        if len(out) == m:
            break
    return out


def fit_problem(
    problem: Problem,
    method: str = "multistart",
    starts: int = 6,
    seed: int = 1,
    max_nfev: int = 60,
    progress: Progress | None = None,
) -> tuple[LocalFit, list[dict[str, Any]]]:
    """Global stage, then local least squares on the record residuals from the best two
    end points; returns the best local fit and the global end points."""
    ends = global_stage(problem, method, starts, seed, max_nfev, progress)
    best: LocalFit | None = None
    for i, u in enumerate(_distinct(ends, 2)):
        if progress is not None:
            progress(f"local least squares {i + 1} (record residuals)")
        lf = local_fit(problem, u, "record", max_nfev=max_nfev)
        if best is None or lf.cost < best.cost:
            best = lf
    assert best is not None
    return best, ends


def profile(
    problem: Problem,
    key: str,
    u_opt: np.ndarray,
    stats: Statistics,
    points: int,
    max_nfev: int,
) -> Profile:
    """Profile likelihood of ``key``: fixed on a grid of ``points`` values over
    p^ +- 4 se (within the bounds), the other free parameters refitted from the optimum."""
    i = problem.keys.index(key)
    p = problem.free[i]
    v0, se = float(stats.values[i]), float(stats.stderr[i])
    span = 4.0 * se if math.isfinite(se) and se > 0 else 0.25 * (p.high - p.low)
    grid = np.linspace(max(p.low, v0 - span), min(p.high, v0 + span), points)
    others = [q for q in problem.free if q.key != key]
    base = problem.residuals(u_opt).r
    rss0 = float(np.dot(base, base))
    s2 = stats.residual_std**2
    delta = np.empty(points)
    u_others = np.delete(u_opt, i)
    for j, v in enumerate(grid):
        # (a record's time offset is fixed on the problem, the others on its scenario; of
        # several records' offsets the others stay free, and a part whose offset is free
        # does not read the fixed one)
        off = float(v) if is_offset(key) else None
        sc = problem.scenario if off is not None else problem.scenario.with_overrides({key: v})
        if others:
            sub = problem.rebuild(sc, others, "exact" if problem.exact else "fd", off)
            lf = local_fit(sub, u_others, "record", max_nfev=max_nfev)
            r = sub.residuals(lf.u).r
        else:
            sub = problem.rebuild(sc, [p], "fd")
            r = sub.residuals(np.array([p.to_unit(float(v))])).r
        delta[j] = (float(np.dot(r, r)) - rss0) / s2
    return Profile(key, grid, delta, _crossings(grid, delta, v0, 3.841))


def _crossings(
    x: np.ndarray, d: np.ndarray, x0: float, level: float
) -> tuple[float | None, float | None]:
    """Where the profile rises through ``level`` on each side of the optimum x0 (linear
    interpolation between grid points); None where it stays below within the grid."""
    lo = hi = None
    left = np.flatnonzero(x <= x0)
    for a in left[::-1]:
        if a + 1 < x.size and d[a] >= level > d[a + 1]:
            lo = float(x[a] + (level - d[a]) * (x[a + 1] - x[a]) / (d[a + 1] - d[a]))
            break
    right = np.flatnonzero(x >= x0)
    for b in right:
        if b > 0 and d[b] >= level > d[b - 1]:
            hi = float(x[b - 1] + (level - d[b - 1]) * (x[b] - x[b - 1]) / (d[b] - d[b - 1]))
            break
    return lo, hi


def information_criteria(rss: float, n: int, k: int) -> tuple[float, float]:
    """(AIC, BIC) of a least-squares fit with Gaussian errors of unknown variance."""
    ll = n * math.log(max(rss, 1e-300) / n)
    return ll + 2 * k, ll + k * math.log(n)


def fit_law(
    spec: FitSpec, base: Problem, law: str, progress: Progress | None
) -> tuple[LawResult, Problem, LocalFit, list[dict[str, Any]]]:
    """Fit with the track contact law ``law`` (free parameters it ignores dropped); returns
    its result, problem (``base`` rebuilt), local fit and the end points of its global
    stage."""
    sc = spec.scenario.with_overrides({"contact.track.model": law})
    pr = base.rebuild(sc, base.free, spec.jacobian)
    J = pr.residuals(pr.u_start, jac=True).J
    assert J is not None
    norms = np.sqrt(np.sum(J * J, axis=0))
    used = [
        p
        for p, nrm in zip(base.free, norms, strict=True)
        if nrm > UNINFORMED * max(norms.max(), 1e-300)
    ]
    if len(used) != len(base.free):
        pr = base.rebuild(sc, used, spec.jacobian)
    pr.use_events = spec.events
    lf, ends = fit_problem(
        pr, spec.global_method, spec.starts, spec.seed, spec.max_evaluations, progress
    )
    return law_result(law, pr, lf), pr, lf, ends


def law_result(law: str, pr: Problem, lf: LocalFit) -> LawResult:
    """The comparison's figures of ``law`` fitted as ``pr`` to ``lf``: cost, AIC and BIC
    with k = the free parameters it uses, the nominal and effective restitution, the
    exponent, and whether a free restitution ended inside its bounds."""
    from braidsim.contact import get_law

    e = pr.residuals(lf.u)
    rss = float(np.dot(e.r, e.r))
    k = len(pr.free)
    aic, bic = information_criteria(rss, e.r.size, k)
    fitted = pr.scenario_at(lf.u)
    assert e.result is not None
    eff = float(e.result.stats.get("track_effective_restitution", math.nan))
    n = fitted["contact.track.exponent"]
    i_rest = pr.keys.index(REST) if REST in pr.keys else -1
    return LawResult(
        law,
        pr.keys,
        pr.values(lf.u),
        0.5 * rss,
        e.r.size,
        k,
        aic,
        bic,
        float(fitted["contact.track.restitution"]),
        eff,
        lf.converged,
        exponent=float(get_law(law).default_exponent if n is None else n),
        restitution_inside=i_rest >= 0 and 1e-6 < lf.u[i_rest] < 1 - 1e-6,
    )


def twin_start(pr: Problem, law: str, twin: LawResult) -> tuple[np.ndarray, str]:
    """The point of ``pr``'s unit box (``law`` fitted) at the optimum of ``twin``, another
    law of the family N = K p^n (1 + D(c_r) p'/v0), mapped onto ``law``.

    Every free parameter takes the twin's fitted value (its own start where the twin did not
    fit it), so K and n are the same, and a free restitution the c_r at which the damping
    factors agree, D_law(c_r) = D_twin(c_twin) (:meth:`braidsim.contact.ContactLaw.
    restitution_at`): the two laws are then one force law and fit equally. A c_r outside
    the restitution's bounds (or none, where D_twin exceeds every D of ``law``) is clipped
    to them; the second item is then a note saying so, else "".
    """
    from braidsim.contact import get_law

    values = {p.key: twin.values.get(p.key, p.start) for p in pr.free}
    if REST not in values:
        return pr.to_unit(values), ""
    d = get_law(twin.law).damping_factor(twin.restitution)
    c = get_law(law).restitution_at(d)
    p = pr.free[pr.keys.index(REST)]
    values[REST] = min(max(c, p.low), p.high)
    if p.low <= c <= p.high:
        return pr.to_unit(values), ""
    where = f"c_r = {c:.4g}" if c > 0 else f"no c_r of {law} (its D stays below {d:.4g})"
    note = (
        f"{law}: {twin.law}'s optimum (D = {d:.4g} at c_r = {twin.restitution:.4g}) maps to "
        f"{where}, outside {REST}'s bounds [{p.low:g}, {p.high:g}]; its further start took "
        f"c_r = {values[REST]:g}: within them {law} cannot give {twin.law}'s force law"
    )
    return pr.to_unit(values), note


def restart_from_twins(
    spec: FitSpec,
    fits: dict[str, tuple[LawResult, Problem, LocalFit, list[dict[str, Any]]]],
    progress: Progress | None = None,
) -> list[str]:
    """Give each dissipative law that fits worse than the best other law of its exponent a
    further local fit from that law's optimum mapped onto it (:func:`twin_start`); keep it
    where it lowers the cost. Updates ``fits`` in place; returns notes (a clipped mapping,
    a law whose fit came from its twin's optimum).

    With the restitution free, laws of one exponent are one force law at matching c_r, and
    their searches differ only in where the restitution's scale puts the same optimum: one
    can end in a local minimum far from it (Flores 4,950 AIC worse than Hunt-Crossley on
    Lankarani-Nikravesh data with 3 starts, equal with 6). Started at the optimum another
    law found, the local fit stays there in a few evaluations. It is in addition to the
    law's own starts, which still search for an optimum of its own (the restitution fixed,
    where the laws' losses differ, or a mapping clipped by the bounds). The source is the
    best law fitted, not the first: the scenario's own law can be the stuck one.
    """
    from braidsim.contact import get_law

    notes: list[str] = []
    family = [f[0] for f in fits.values() if get_law(f[0].law).dissipative]
    for law, (lr, pr, lf, ends) in list(fits.items()):
        twins = [t for t in family if t.law != law and t.exponent == lr.exponent]
        if not get_law(law).dissipative or not twins:
            continue
        twin = min(twins, key=lambda t: t.aic)
        if lr.aic - twin.aic < AIC_TIE:
            continue  # as good as its best twin already
        if progress is not None:
            progress(f"contact law {law}: from the optimum of {twin.law}")
        u, note = twin_start(pr, law, twin)
        if note:
            notes.append(note)
        try:
            again = local_fit(pr, u, "record", max_nfev=spec.max_evaluations)
        except SimulationError:
            continue
        if again.cost < lf.cost:
            better = law_result(law, pr, again)
            notes.append(
                f"{law}: fitted from {twin.law}'s optimum mapped onto it (c_r = "
                f"{better.restitution:.6g}); its own starts ended {lr.aic - better.aic:.3g} "
                "AIC worse"
            )
            fits[law] = (better, pr, again, ends)
    return notes


#: AIC differences below this are numerically equal fits (the same force law reparametrised)
AIC_TIE = 0.01
#: an AIC this much worse than a law of the same force form flags a stuck search
STUCK_AIC = 10.0
#: the restitution key, the one a law's damping factor maps
REST = "contact.track.restitution"


def select_law(laws: Sequence[LawResult], preferred: str) -> tuple[str, list[str]]:
    """The law of lowest AIC (among numerically equal fits, ``preferred`` or the first
    listed), and notes on the laws the data do not tell apart (Delta AIC < 2).

    With the restitution free, every dissipative law of the same exponent gives the same
    force law for a matching c_r (the laws differ only in the damping factor D(c_r)): their
    fits are equal and only the fitted restitutions differ.
    """
    best = min(lr.aic for lr in laws)
    ties = [lr for lr in laws if lr.aic - best < AIC_TIE]
    pick = next((lr for lr in ties if lr.law == preferred), ties[0])
    notes = []
    close = [lr for lr in laws if lr.law != pick.law and lr.aic - best < 2.0]
    if close:
        eq = [lr for lr in close if lr.aic - best < AIC_TIE]
        text = ", ".join(f"{lr.law} (Delta AIC {lr.aic - best:.3g})" for lr in close)
        why = (
            " (equal fits: the same force law with another restitution; fix "
            "contact.track.restitution to compare the laws' damping factors)"
            if eq
            else ""
        )
        notes.append(f"the data do not distinguish {pick.law} from {text}{why}")
    # With the restitution free and inside its bounds, laws of one exponent are one force
    # law (a matching c_r gives the same damping factor): a much worse fit of one of them is
    # a local minimum of its search, not a verdict on the law (Flores on Lankarani-Nikravesh
    # data: 4,950 AIC worse with 3 starts, equal with 6)
    for lr in laws:
        twin = pick if pick is not lr else None
        if (
            twin is not None
            and lr.restitution_inside
            and twin.restitution_inside
            and lr.exponent == twin.exponent
            and lr.aic - twin.aic > STUCK_AIC
        ):
            notes.append(
                f"{lr.law} fits {lr.aic - twin.aic:.3g} AIC worse than {twin.law}, though with "
                "the restitution free the two are the same force law: its fit is likely a "
                "local minimum (raise fit.starts); the comparison says nothing against it"
            )
    return pick.law, notes


#: a record, or several: each a record (or impact list) or ``(record, overrides)``
Records = Record | ImpactList | Sequence[Record | ImpactList | tuple[Any, Mapping[str, Any]]]


def _items(records: Any) -> list[tuple[Record | ImpactList, dict[str, Any]]]:
    if isinstance(records, Record | ImpactList):
        return [(records, {})]
    out = []
    for item in records:
        if isinstance(item, tuple):
            out.append((item[0], dict(item[1] or {})))
        else:
            out.append((item, {}))
    if not out:
        raise InputError("data (--data): no record; allowed one or more records")
    return out


def record_quantities(
    spec: FitSpec, records: Sequence[Record | ImpactList]
) -> list[tuple[str, ...]]:
    """The quantities each record fits: where the spec names none, ``x`` of a sampled
    record and every column of an impact list (``()``); else the named ones of its kind.

    Raises
    ------
    InputError
        A record that has none of the named quantities, or a named quantity that no record
        has (``velocity`` of an acceleration record was once replaced by its acceleration
        without a word). A sampled record lacking a named sampled quantity is refused by
        its :class:`Problem`.
    """
    from braidsim.fit.data import QUANTITY_UNITS

    if not spec.quantity_given:
        return [() if isinstance(rec, ImpactList) else ("x",) for rec in records]
    named = spec.quantities
    out: list[tuple[str, ...]] = []
    have_all: dict[str, None] = {}
    for rec in records:
        if isinstance(rec, ImpactList):
            have = tuple(rec.columns)
            mine = tuple(q for q in named if q in have)
            kind = "impact list"
        else:
            have = tuple(rec.columns)
            mine = tuple(q for q in named if q in QUANTITY_UNITS)
            kind = "record"
        have_all.update(dict.fromkeys(have))
        if not mine:
            listed = ", ".join(repr(q) for q in named)
            raise InputError(
                f"fit.quantity: {listed} {'is' if len(named) == 1 else 'are'} not a column of "
                f"the {kind} {rec.source}; allowed {', '.join(have)}"
            )
        out.append(mine)
    fitted = {q for qs in out for q in qs}
    for q in named:
        if q not in fitted:
            raise InputError(
                f"fit.quantity: {q!r} is not a column of "
                f"{'the record ' + records[0].source if len(records) == 1 else 'any record'}; "
                f"allowed {', '.join(have_all)}"
            )
    return out


def build_problem(spec: FitSpec, records: Records) -> Problem:
    """The problem of one record, or a :class:`MultiProblem` of several (each on the
    scenario with its own overrides)."""
    items = _items(records)
    free = set(spec.keys)
    several = len(items) > 1
    free_parameters = spec.free
    if TIME_OFFSET in free and several:
        # (each record has its trigger: one offset each, record[i].time_offset)
        free_parameters = per_record_offsets(spec.free, len(items))
        if TIME_OFFSET in spec.profile:
            raise InputError(
                f"fit.profile: {TIME_OFFSET} stands for {len(items)} offsets with "
                f"{len(items)} records; allowed one of them, {offset_key(0)} to "
                f"{offset_key(len(items) - 1)}"
            )
    offsets = {p.key for p in free_parameters if is_offset(p.key)}
    for k in spec.profile:
        if is_offset(k) and k != TIME_OFFSET and k not in offsets:
            many = f"{offset_key(0)} to {offset_key(len(items) - 1)}" if several else TIME_OFFSET
            raise InputError(
                f"fit.profile: {k!r} is not a free parameter with {len(items)} "
                f"record{'s' if several else ''}; allowed {many}"
            )
    parts = []
    fitted = record_quantities(spec, [rec for rec, _ in items])
    for i, (rec, ov) in enumerate(items):
        for key in ov:
            if key in free:
                raise InputError(
                    f"data[{i}].overrides.{key}: a free parameter; allowed fixed keys only "
                    "(e.g. initial.vx)"
                )
        sc = spec.scenario.with_overrides(ov) if ov else spec.scenario
        parts.append(
            single_problem(
                sc,
                rec,
                free_parameters,
                fitted[i],
                spec.noise,
                spec.jacobian,
                i if several else None,
            )
        )
    fitted_all = list(dict.fromkeys(q for part in parts for q in part.quantities))
    for q in spec.noise:
        if q not in fitted_all:
            # (it was accepted and ignored: a typo'd or misplaced level weighted nothing)
            raise InputError(
                f"fit.noise.{q}: {q} is not fitted; allowed the fitted quantities "
                f"{', '.join(fitted_all)}"
            )
    if len(parts) == 1 and not items[0][1]:
        return parts[0]
    return MultiProblem(spec.scenario, parts, [ov for _, ov in items])


def _parts(problem: Problem) -> list[Problem]:
    return list(problem.parts) if isinstance(problem, MultiProblem) else [problem]


def _source(problem: Problem) -> str:
    return problem.impacts.source if isinstance(problem, ImpactProblem) else problem.record.source


def _check_covers_an_impact(problem: Problem) -> None:
    """A record shorter than one impact cannot inform contact parameters; an impact list
    needs as many model impacts as it holds."""
    for part in _parts(problem):
        start_run = part.run(part.u_start)
        if isinstance(part, ImpactProblem):
            imp = start_run.impacts
            tm = np.asarray(imp["t"], dtype=float)[
                np.asarray(imp["pair"] == "track") & ~np.asarray(imp["initial"])
            ]
            if tm.size and part.impacts.t[0] + part.time_offset(part.u_start) > tm[-1]:
                # (times in ms read as s put a list 1000 times later than the carrier's
                # impacts: every listed one would be matched to a model impact seconds
                # earlier, the fit ending at its bounds with residuals 1e5 times the noise)
                raise InputError(
                    f"data (--data): the impact list {part.impacts.source} starts at t = "
                    f"{part.impacts.t[0]:.6g} s, after the last track impact of the scenario "
                    f"at the start values (t = {tm[-1]:.6g} s; none from then to "
                    f"{part.duration:.6g} s); allowed a time column in the unit its header "
                    "says (t [s] or t [ms]) and an impact list the scenario can reach"
                )
            try:
                part.model_values(start_run, part.u_start)
            except SimulationError as exc:
                raise InputError(
                    f"data (--data): at the start values {exc}; allowed an impact list the "
                    "scenario can reach (check its times, the scenario's overrides and the start)"
                ) from None
            continue
        record = part.record
        n_model = int(
            np.sum(
                np.asarray(start_run.impacts["pair"] == "track")
                & ~np.asarray(start_run.impacts["initial"])
            )
        )
        if part.event_quantity is not None and not part.has_events and n_model == 0:
            raise InputError(
                f"data (--data): the record {record.source} ({record.duration:g} s) holds no "
                "impact; allowed a record of at least one impact"
            )
        if part.has_events and n_model == 0:
            # (times in seconds headed [ms] made a record 1000 times shorter: the fit said
            # the data did not depend on the restitution)
            raise InputError(
                f"data (--data): the record {record.source} ({record.duration:g} s) shows "
                f"{part.onsets.size} impact pulses, but the scenario at the start values makes "
                "none in that time; allowed a time column in the unit its header says (t [s] "
                "or t [ms]) and a scenario that reaches the record's impacts"
            )
        if part.event_quantity is None and n_model == 0:
            raise InputError(
                f"data (--data): the record {record.source} ({record.duration:g} s) is shorter "
                "than the first impact of the scenario at the start values; allowed a record of at "
                "least one impact"
            )


def _check_shows_pulses(problem: Problem) -> None:
    """Refuse, before any simulation, a record whose fitted acceleration or force columns
    show no impact pulse (:func:`braidsim.fit.data.detect_pulses`: every sample within
    ``max(6 noise, 5 % of the largest)`` of the median), unless its displacement is fitted
    too (whose impacts the model is judged on, :func:`_check_covers_an_impact`).

    A constant column (all 0: a sensor not connected) or noise alone holds nothing about
    the contact: fitted, its residuals pulled the model's impacts out of the record and the
    fit reported estimates with a cost of 1e85."""
    from braidsim.fit.data import QUANTITY_UNITS, detect_pulses, pulse_levels

    for part in _parts(problem):
        if isinstance(part, ImpactProblem) or "x" in part.quantities:
            continue
        record = part.record
        pulses = [q for q in part.quantities if q in ("acceleration", "contact_force")]
        if not pulses or any(
            detect_pulses(record.t, record.columns[q], part.sigma[q])[0].size for q in pulses
        ):
            continue
        q = pulses[0]
        base, thr, top = pulse_levels(record.columns[q], part.sigma[q])
        unit = QUANTITY_UNITS[q]
        why = (
            f"is constant ({base:.6g} {unit})"
            if top == 0.0
            else f"shows no pulse (its largest distance from its median, {top:.3g} {unit}, "
            f"is within the detection threshold {thr:.3g} {unit}, max(6 noise, 5 % of the "
            "largest))"
        )
        raise InputError(
            f"data (--data): the record {record.source} ({record.duration:g} s) holds no "
            f"impact: column {q} {why}; allowed a record of at least one impact pulse"
        )


#: time units a refusal of a too coarse time column may suggest, coarsest first [s]
_FINER_UNITS = {"ms": 1e-3, "us": 1e-6}


def _check_time_scale(problem: Problem, laws: Sequence[str] = ()) -> None:
    """Refuse, before any simulation, a sampled record whose sample interval is longer
    than the motion it records can last (typically times in ms under a header that reads
    them as s, ``t [s]`` or a bare ``t``): the fit would simulate a record 1000 times too
    long for minutes and end in warnings.

    The bounds are closed forms (:mod:`braidsim.fit.timescale`), the largest over the
    scenario variants the fit may reach (start values, corners of the free parameters'
    box, the laws compared), so that a record the fit can use is never refused:

    - acceleration or contact force: the elastic contact duration of the impacts the record
      can show, at its smallest and largest pulse height (the pulse threshold of
      :func:`braidsim.fit.data.detect_pulses`, and its largest pulse);
    - displacement: the longest flight between the track walls.

    Impact lists have no sample interval, and may skip impacts or the carrier's rests
    between them: no closed form bounds their times (:func:`_check_covers_an_impact`
    compares them with the run at the start values).
    """
    from braidsim.fit.timescale import longest_flight, variants

    for part in _parts(problem):
        if isinstance(part, ImpactProblem):
            continue
        record = part.record
        dt = record.sample_interval
        scenarios = variants(part.scenario, part.free, laws)
        pulses = [q for q in part.quantities if q in ("acceleration", "contact_force")]
        if pulses:
            # An impact pulse is resolved only if at least two samples fall within its
            # contact. The record's pulses rise above its detection threshold; for n > 1 an
            # impact of smaller peak force lasts longer (T ~ F^((1 - n) / (2 n)) at given
            # m, K), so the longest pulse the record can show is the one that just reaches
            # the threshold (for n < 1 its largest pulse). Damping lengthens a contact
            # mostly in its low-force rebound, below the threshold of a pulse that barely
            # reaches it; the pulses that rise well above it are shorter. A sample interval
            # longer than this bound leaves every pulse one sample at most: the impacts are
            # not in the record at this time scale. (The example record, 10 kHz: 8.6 sample
            # intervals in its bound of 0.86 ms; its times in ms read as s, 0.1 s: 117 bounds.)
            bound = _pulse_bound(record.columns, pulses, part.sigma, scenarios)
            if dt > bound:
                _check_lone_sample(record, pulses, part.sigma, scenarios)
            what = (
                f"the longest impact pulse it can show ({bound * 1e3:.3g} ms, the elastic "
                "contact of an impact at its detection threshold, over the free parameters' "
                "bounds): no pulse can be resolved"
            )
        else:
            # A displacement record does not need the contacts resolved, only the flights
            # between them: its samples must follow the carrier from wall to wall. Under a
            # load that exceeds the friction every flight is shorter than the bound; a
            # sample interval longer than it straddles every flight (the record shows the
            # walls in an order the samples cannot tell).
            bound = max(longest_flight(sc) for sc in scenarios)
            what = (
                f"the longest flight of the carrier between the track walls ({bound * 1e3:.3g}"
                " ms, under the least constant load, over the free parameters' bounds): the "
                "samples cannot follow it from wall to wall"
            )
        if not dt > bound:
            continue
        unit = record.units_read.get("t", "")
        factor = to_si("t", f"1 {unit}", "s") if unit else 1.0
        finer = [u for u, f in _FINER_UNITS.items() if f < factor and dt * f / factor <= bound]
        fix = (
            f"if its times are in {finer[0]}, head the column t [{finer[0]}]"
            if finer
            else "a record sampled faster"
        )
        header = f"t [{unit}]" if unit else "t (no unit: read as s)"
        raise InputError(
            f"data (--data): {record.source}: column {header} has a sample interval of "
            f"{dt:.3g} s ({record.t.size} samples over {record.duration:.3g} s), longer than "
            f"{what}; allowed a time column in the unit its header says: {fix}"
        )


def _pulse_bound(
    columns: Mapping[str, np.ndarray],
    pulses: Sequence[str],
    sigma: Mapping[str, float],
    scenarios: Sequence[Scenario],
) -> float:
    """The longest impact pulse [s] that the acceleration or force ``columns`` named in
    ``pulses`` can show, over ``scenarios`` (see :func:`_check_time_scale`)."""
    from braidsim.fit.data import pulse_levels
    from braidsim.fit.timescale import pulse_duration

    bound = 0.0
    for q in pulses:
        _, thr, top = pulse_levels(columns[q], sigma[q])
        for sc in scenarios:
            mass = float(sc["carrier.mass"]) if q == "acceleration" else 1.0
            for level in (thr, top):
                bound = max(bound, pulse_duration(sc, mass * level))
    return bound


def _check_offset_reach(problem: Problem, laws: Sequence[str] = ()) -> None:
    """Refuse, before any simulation, a free time offset whose upper bound asks for a run
    over the ``steps`` limit (:mod:`braidsim.limits`: duration / simulation.max_step, the
    smallest step over the scenario variants the fit may reach).

    A record's run lasts to its last sample plus the offset, an impact list's to 1.2 times
    its last onset plus the largest offset, plus 10 ms. The fit may step to the upper bound
    (the trust region's first step, a start of the global stage), where the run would be
    refused anyway, after minutes of fitting and naming only its duration; an offset of
    1e6 s made runs of half an hour each."""
    from braidsim import limits
    from braidsim.fit.timescale import variants
    from braidsim.model import default_max_step

    for part in _parts(problem):
        if part.i_offset is None:
            continue
        p = part.free[part.i_offset]
        hmax = min(
            float(sc["simulation.max_step"] or default_max_step(sc))
            for sc in variants(part.scenario, part.free, laws)
        )
        reach = limits.limit("steps") * hmax
        if isinstance(part, ImpactProblem):
            longest = part.duration
            allowed = (reach - 0.01) / 1.2 - part.impacts.duration
        else:
            longest = part.record.duration + p.high
            allowed = reach - part.record.duration
        limits.check(
            "steps",
            longest / hmax,
            f"fit.free.{TIME_OFFSET}: an upper bound of {p.high:g} s runs the model to "
            f"{longest:g} s at simulation.max_step = {hmax:.3g} s (allowed upper bounds up to "
            f"{allowed:.9g} s), at least",
        )


def _check_lone_sample(
    record: Record,
    pulses: Sequence[str],
    sigma: Mapping[str, float],
    scenarios: Sequence[Scenario],
) -> None:
    """Refuse, naming it, a lone sample that alone makes :func:`_check_time_scale` refuse
    ``record``: where the bound :func:`_pulse_bound` passes the sample interval once the
    sample farthest from the median of a pulse column is left out.

    One glitch sets the pulse threshold (5 % of the largest pulse) so high that only
    impacts much shorter than a sample could reach it: the check then blamed the time
    column's unit (1e15 m/s^2 in the example: "head the column t [us]"), where the record's
    real pulses are resolved."""
    from braidsim.fit.data import QUANTITY_UNITS, pulse_levels

    dt = record.sample_interval
    for q in pulses:
        y = record.columns[q]
        base = pulse_levels(y, sigma[q])[0]
        dist = np.abs(y - base)
        i = int(np.argmax(dist))
        if not dt <= _pulse_bound({**record.columns, q: np.delete(y, i)}, pulses, sigma, scenarios):
            continue
        rest = float(np.max(np.delete(dist, i)))
        times = f"{dist[i] / rest:.3g} times" if rest > 0 else "infinitely far beyond"
        unit = QUANTITY_UNITS[q]
        raise InputError(
            f"data (--data): {record.source}: column {q} has {y[i]:.3g} {unit} at t = "
            f"{record.t[i]:.9g} s (row {i}), {times} the largest distance of any other sample "
            f"from the median ({base:.3g} {unit}): a glitch? Alone it sets the pulse threshold "
            "(5 % of the largest) beyond every impact the sample interval can resolve; allowed "
            "a record without it (check that sample)"
        )


def _first_record(problem: Problem) -> Record | ImpactList:
    first = _parts(problem)[0]
    return first.impacts if isinstance(first, ImpactProblem) else first.record


def _part_table(problem: Problem, u: np.ndarray) -> list[dict[str, Any]]:
    """Per record: source, kind, times, measured and model values and noise."""
    out = []
    for part in _parts(problem):
        res = part.run(u)
        if isinstance(part, ImpactProblem):
            model = part.model_values(res, u)
            data = {"t": part.impacts.t, **part.impacts.columns}
            t = part.impacts.t
            kind = "impacts"
        else:
            model = {q: _predict(res, q) for q in part.quantities}
            data = dict(part.record.columns)
            t = part.record.t
            kind = "series"
        row = {
            "source": _source(part),
            "kind": kind,
            "t": t,
            "quantities": part.quantities,
            "data": {q: data[q] for q in part.quantities},
            "model": model,
            "noise": dict(part.sigma),
        }
        if not isinstance(part, ImpactProblem) and part.has_events:
            t_may, _, t_must, _ = part._model_onsets(res, u)
            row["pulses"] = (part.onsets, t_may, t_must, part.record.sample_interval)
        out.append(row)
    return out


#: the normalised residuals' standard deviation above which the fit warns that the model
#: does not explain the record (a right model gives 0.9-1.1 with white noise; a record
#: offset by half a sample 1.6-1.8; a wrong vibration, friction or fixed parameter 4-83)
MISFIT_LIMIT = 1.5


def fit_warnings(
    stats: Statistics, converged: bool, parts: Sequence[Mapping[str, Any]]
) -> list[str]:
    """Warnings on the fit as a whole, beside the identifiability ones of
    :func:`statistics`: a local run that did not converge, residuals larger than the noise,
    and impact pulses of the record that the fitted model does not make (or the reverse).
    The intervals assume none of these: each says what to check."""
    out = []
    if not converged:
        out.append(
            "the local least squares did not converge (fit.max_evaluations reached, or no "
            "step lowered the cost): the values and intervals are those of its last point; "
            "raise fit.max_evaluations or fit.starts"
        )
    if stats.residual_std > MISFIT_LIMIT:
        out.append(
            f"the residuals are {stats.residual_std:.3g} times the noise: the model does not "
            "explain the record to its noise (a fixed law or parameter, the record's units "
            "or time origin: free record.time_offset), or the noise is not white (then give "
            "fit.noise); the intervals assume it does"
        )
    for part in parts:
        if "pulses" not in part:
            continue
        # (a pulse near the threshold is in the record or not by its noise: a record pulse
        # is matched among the model's that may show, a model impact that must show among
        # the record's; see Problem._model_onsets)
        td, tm_may, tm_must, dt = part["pulses"]
        lone_d = [t for t in td if tm_may.size == 0 or np.min(np.abs(tm_may - t)) > 5 * dt]
        lone_m = [t for t in tm_must if td.size == 0 or np.min(np.abs(td - t)) > 5 * dt]
        if not (lone_d or lone_m):
            continue
        where = []
        if lone_d:
            where.append(f"record pulses at t = {', '.join(f'{t:.6g}' for t in lone_d[:3])} s")
        if lone_m:
            where.append(f"model impacts at t = {', '.join(f'{t:.6g}' for t in lone_m[:3])} s")
        out.append(
            f"{part['source']}: the record shows {td.size} impact pulses, the fitted model "
            f"{tm_may.size} above the same threshold ({' and '.join(where)} match none): a "
            "glitch in the record, an impact the model misses, or a model that does not "
            "follow the record; the intervals assume they match"
        )
    return out


def fit_record(spec: FitSpec, record: Records, progress: Progress | None = None) -> FitResult:
    """Fit ``spec`` to ``record``: a sampled record, an impact list, or a sequence of them
    (each optionally ``(record, overrides)``), fitted together (see the module docstring
    for the method).

    Raises
    ------
    InputError
        A fitted quantity missing from the record; a record without an impact; an impact
        list with more impacts than the model gives; a free parameter that the data cannot
        inform.
    SimulationError
        The simulator failed at every start.
    """
    t0 = time.perf_counter()
    say = progress or (lambda s: None)
    problem = build_problem(spec, record)
    problem.use_events = spec.events
    _check_shows_pulses(problem)
    _check_time_scale(problem, spec.laws)
    _check_offset_reach(problem, spec.laws)
    _check_covers_an_impact(problem)
    check_informed(problem, problem.u_start)
    try:
        return _fit_checked(spec, problem, say, t0)
    except TooFewImpacts as exc:
        # (the start's own run is checked above; the fit can still end where the model
        # gives fewer impacts than a list, as bad input as the same list at the start)
        raise InputError(
            f"data (--data): at the fitted values {exc}; allowed an impact list the scenario "
            "can reach (check its times and values, the scenario's overrides, the start and "
            "the bounds)"
        ) from None


def _fit_checked(spec: FitSpec, problem: Problem, say: Progress, t0: float) -> FitResult:
    """The fit of :func:`fit_record` once its input is checked."""
    laws = list(spec.laws)
    law0 = str(spec.scenario["contact.track.model"])
    law_results: list[LawResult] = []
    chosen: tuple[Problem, LocalFit] | None = None
    ends: list[dict[str, Any]] = []
    law_notes: list[str] = []
    selected = ""
    if laws:
        if law0 not in laws:
            laws.insert(0, law0)
        fits: dict[str, tuple[LawResult, Problem, LocalFit, list[dict[str, Any]]]] = {}
        for law in laws:
            say(f"contact law {law}")
            fits[law] = fit_law(spec, problem, law, say)
        problem.notes.update(restart_from_twins(spec, fits, say))
        law_results = [f[0] for f in fits.values()]
        selected, law_notes = select_law(law_results, law0)
        chosen = fits[selected][1:3]
        ends = fits[selected][3]
        # by AIC, the selected law first among equal fits
        law_results.sort(key=lambda r: r.aic - (AIC_TIE if r.law == selected else 0.0))
    if chosen is None:
        lf, ends = fit_problem(
            problem, spec.global_method, spec.starts, spec.seed, spec.max_evaluations, say
        )
        chosen = (problem, lf)
    pr, lf = chosen
    say("statistics at the optimum")
    stats, e = statistics(pr, lf.u)
    stats.warnings.extend(law_notes)

    dropped = [k for k in problem.keys if k not in pr.keys]
    if dropped:
        stats.warnings.append(
            f"the selected law {selected} does not use {', '.join(dropped)}: not estimated"
        )
    profiles = []
    for key in spec.profile:
        say(f"profile likelihood of {key}")
        profiles.append(profile(pr, key, lf.u, stats, spec.profile_points, spec.max_evaluations))
    parts = _part_table(pr, lf.u)
    stats.warnings.extend(fit_warnings(stats, lf.converged, parts))
    return FitResult(
        law=str(pr.scenario["contact.track.model"]),
        keys=pr.keys,
        free=pr.free,
        stats=stats,
        converged=lf.converged,
        cost=lf.cost,
        n_data=int(e.r.size),
        noise=dict(pr.sigma),
        quantities=pr.quantities,
        record=_first_record(pr),
        prediction=parts[0]["model"],
        scenario=pr.scenario_at(lf.u),
        jacobian="exact" if pr.exact else "fd",
        starts=[
            {
                "start": pr.values(d["start"]),
                "end": pr.values(d["u"]),
                "cost": d["cost"],
                "residuals": d["kind"],
            }
            for d in ends
        ],
        profiles=profiles,
        laws=law_results,
        impacts_in_record=int(
            sum(
                p.impacts.t.size if isinstance(p, ImpactProblem) else p.onsets.size
                for p in _parts(problem)
            )
        ),
        evaluations=problem.evaluations + pr.evaluations
        if pr is not problem
        else problem.evaluations,
        seconds=time.perf_counter() - t0,
        onsets=problem.onsets,
        notes=sorted(problem.notes | pr.notes),
        parts=parts,
    )


def _predict(res: Any, q: str) -> np.ndarray:
    from braidsim.fit.problem import predict

    return predict(res, q)


def fit(
    scenario: Scenario | str | Mapping[str, Any],
    data: Any,
    free: Mapping[str, Sequence[Any]],
    quantity: str | Sequence[str] | None = None,
    overrides: Mapping[str, Any] | None = None,
    progress: Progress | None = None,
    **options: Any,
) -> FitResult:
    """Fit free scenario parameters to a measured record (the Python face of ``braidsim fit``).

    Parameters
    ----------
    scenario : Scenario, str or mapping
        A loaded scenario, a built-in name, a scenario TOML path, or ``{dotted key:
        value}``.
    data : path, xarray.Dataset, DataFrame, dict of arrays, Record or ImpactList, or a list
        The record (see :mod:`braidsim.fit.data`): samples or an impact list, told by its
        columns. A list fits several records together (stacked residuals, one covariance);
        an item ``(record, overrides)`` runs that record on the scenario with its own
        overrides (e.g. ``{"initial.vx": "0.5 m/s"}``).
    free : mapping
        ``{key: [low, high]}``, numbers in SI or unit strings.
    quantity : str or list of str, optional
        The record's columns to fit (``x``, ``acceleration``, ``contact_force``; default
        ``x``); an impact list fits its onset times and every column it has unless some are
        named here (``peak_force``, ``velocity``, ``rebound_velocity``,
        ``dissipated_energy``). A named quantity that no record has is refused.
    overrides : mapping, optional
        Applied to the scenario first.
    progress : callable, optional
        Called with a line of text at each stage of the fit (the command line's status).
    **options
        Any other key of the spec's ``[fit]`` table (``noise``, ``start``, ``jacobian``,
        ``global_method`` for ``global``, ``starts``, ``events``, ``profile``,
        ``profile_points``, ``laws``, ``seed``, ``max_evaluations``).

    Returns
    -------
    FitResult
    """
    from braidsim.fit.data import read_record
    from braidsim.fit.spec import parse_fit_spec

    if "global_method" in options:  # `global` is a Python keyword
        options["global"] = options.pop("global_method")
    # (a list or None here raised TypeError from dict())
    if not isinstance(free, Mapping):
        raise InputError(
            f"free: {type(free).__name__} is not allowed; allowed a mapping {{key: [low, high]}}, "
            'e.g. {"track.clearance": ["2.5 mm", "3.5 mm"]}'
        )
    if overrides is not None and not isinstance(overrides, Mapping):
        raise InputError(
            f"overrides: {type(overrides).__name__} is not allowed; allowed a mapping "
            "{key: value}"
        )

    table: dict[str, Any] = {"fit": {"free": dict(free), **options}}
    if quantity is not None:
        table["fit"]["quantity"] = quantity
    if overrides:
        table["overrides"] = dict(overrides)
    if isinstance(scenario, Scenario):
        spec = parse_fit_spec(table, scenario=scenario)
    else:
        table["scenario"] = str(scenario) if not isinstance(scenario, Mapping) else ""
        spec = parse_fit_spec(
            table,
            scenario=load_scenario(scenario) if isinstance(scenario, Mapping) else None,
        )
    if isinstance(data, list):
        for i, d in enumerate(data):
            if isinstance(d, tuple) and (len(d) != 2 or not isinstance(d[1], Mapping | None)):
                got = (
                    f"a tuple of {len(d)} items"
                    if len(d) != 2
                    else f"overrides of type {type(d[1]).__name__}"
                )
                raise InputError(
                    f"data[{i}]: {got} is not allowed; allowed a record or (record, overrides) "
                    "with overrides a mapping"
                )
        items: list[Any] = [
            (read_record(d[0]), d[1]) if isinstance(d, tuple) else read_record(d) for d in data
        ]
        return fit_record(spec, items, progress)
    return fit_record(spec, read_record(data), progress)
