"""Closed-form reference for the forced piecewise-linear impact oscillator.

The system, one mass against one wall at x = +g, with a linear spring-dashpot contact that
may pull (so that each phase is exactly linear)::

    free     (x < g):  m x'' + c x' + k x = F cos(Omega t + phi)
    contact  (x > g):  m x'' + c x' + k x = F cos(Omega t + phi) - (k_c p + c_c p'),
                       p = x - g

m [kg], c [N s/m], k [N/m], F [N], Omega [rad/s], phi [rad], g [m], k_c [N/m], c_c [N s/m].
A contact begins where the gap g - x reaches zero from above and ends where the penetration
p returns to zero from above (the sign of the normal force plays no part): the surfaces at
which braidsim's solver switches a contact with a Kelvin-Voigt law that may pull. In contact the
equation is m x'' + (c + c_c) x' + (k + k_c) x = F cos(Omega t + phi) + k_c g, again linear
with constant coefficients. This is the piecewise-linear impact oscillator of Shaw, S. W. and
Holmes, P. J. (1983), A periodically forced piecewise linear oscillator, J. Sound Vib. 90(1),
129-155, doi:10.1016/0022-460X(83)90407-8, here with a soft (spring-dashpot) wall.

Each phase, z = (x, v), solves z' = A z + e_2 (F cos(Omega t + phi) + d) / m with

    A = [[0, 1], [-K/m, -C/m]],   (K, C, d) = (k, c, 0) free, (k + k_c, c + c_c, k_c g) contact,

so z(t) = z_p(t) + exp(A (t - t0)) (z(t0) - z_p(t0)) exactly, where z_p is the steady state
of the phase: the static offset d / K plus the harmonic response Re(X e^{i(Omega t + phi)}),
X = F / (K - m Omega^2 + i C Omega). The matrix exponential of the 2x2 matrix is written with
its eigenvalues lambda = mu +- delta, mu = -C / (2 m), delta^2 = mu^2 - K / m:

    exp(A t) = e^{mu t} [cosh(delta t) I + t sinhc(delta t) (A - mu I)],  sinhc(z) = sinh(z)/z,

valid for under-, over- and critically damped phases alike (Moler, C. and Van Loan, C.
(2003), Nineteen dubious ways to compute the exponential of a matrix, twenty-five years
later, SIAM Review 45(1), 3-49, doi:10.1137/S00361445024180).

Switching times are roots of the closed-form gap g - x (free) or penetration x - g
(contact): the phase is sampled at 64 points per shortest time scale, the critical points of
the switching function are located between samples (roots of its derivative, the closed-form
velocity) so that a gap closing and reopening between two samples is not missed, and the
first sign change is refined by Brent's method to a relative accuracy of about 1e-15.

A periodic orbit of k forcing periods with n impacts is found by matching the phases
(:func:`periodic_orbit`): the unknowns are the onset and exit times and the speeds there, the
equations say that each contact phase started on the wall at an onset ends on the wall at the
next exit, and each free phase the next onset, 4 n equations in 4 n unknowns. Its stability
comes from the monodromy (:func:`monodromy`): the product of the exact phase Jacobians
exp(A dt) and of the saltation matrices at the switchings,

    S = I + (f+ - f-) n^T / (n^T f-),   n = (1, 0) the normal of the wall x = g,

where f- and f+ are the vector fields just before and after (di Bernardo, M., Budd, C. J.,
Champneys, A. R. and Kowalczyk, P. (2008), Piecewise-smooth Dynamical Systems: Theory and
Applications, Springer, doi:10.1007/978-1-84628-708-4). The dashpot makes the
force jump by c_c v at the wall, so S = [[1, 0], [-c_c/m, 1]] at onset and
[[1, 0], [+c_c/m, 1]] at exit, whatever the speed there. The monodromy from a time t0 is the
Jacobian of the stroboscopic map z(t0) -> z(t0 + k T), T = 2 pi / Omega
(:func:`stroboscopic_map`); its eigenvalues are the Floquet multipliers (di Bernardo et al.
2008), which do not depend on t0.

Parameter sets for other tests (SI units, ``PARAMETER_SETS``; the orbits' times, speeds and
multipliers are written beside them, guesses in ``ORBIT_GUESSES``):

- ``"stable_p1"``: a stable period-1 orbit with one impact, complex multipliers;
- ``"stable_p1_stiff"``: the same forcing against a ten times stiffer wall, stable;
- ``"period_doubled"``: past the period doubling at Omega = 2.29213915 rad/s: the period-1
  orbit is unstable with a real multiplier below -1, and a stable period-2 orbit with two
  impacts per two periods exists.

Nothing here imports braidsim: the module is the independent side of the comparison.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from itertools import pairwise
from typing import NamedTuple

import numpy as np
from scipy.optimize import brentq, root

FREE = 0  # phase index: away from the wall
CONTACT = 1  # phase index: in contact with the wall
SAMPLES_PER_SCALE = 64  # samples of a switching function per shortest time scale

StateLike = Sequence[float] | np.ndarray  # a state (x [m], v [m/s])


class PWLParams(NamedTuple):
    """Parameters of the forced oscillator against one spring-dashpot wall (SI units).

    braidsim's equivalent is ``ImpactOscillator(mass, stiffness, damping, force_amplitude,
    force_frequency, force_phase, gap_inner=inf, gap_outer=gap,
    law=KelvinVoigtContact(contact_stiffness, contact_damping, allow_tension=True))``.
    """

    mass: float  # m [kg]
    stiffness: float  # k [N/m]
    damping: float  # c [N s/m]
    force_amplitude: float  # F [N]
    force_frequency: float  # Omega [rad/s]
    force_phase: float  # phi [rad]
    gap: float  # wall at x = +gap [m]
    contact_stiffness: float  # k_c [N/m]
    contact_damping: float  # c_c [N s/m]

    @property
    def period(self) -> float:
        """Forcing period T = 2 pi / Omega [s]."""
        return 2.0 * math.pi / self.force_frequency


# ---- the two linear phases -----------------------------------------------------------------


def _sinhc(z: np.ndarray) -> np.ndarray:
    """sinh(z) / z for complex z, by its series where z is small (no cancellation)."""
    z = np.asarray(z, dtype=complex)
    small = np.abs(z) < 1e-3
    zs = np.where(small, 1.0, z)
    z2 = z * z
    return np.where(small, 1.0 + z2 / 6.0 + z2 * z2 / 120.0, np.sinh(zs) / zs)


@dataclass(frozen=True)
class Phase:
    """One linear phase m x'' + C x' + K x = F cos(Omega t + phi) + d (module docstring)."""

    mass: float
    K: float  # effective stiffness [N/m]
    C: float  # effective damping [N s/m]
    d: float  # constant force [N]
    F: float
    Omega: float
    phi: float
    sign: float  # switching function s = sign * (x - gap): -1 free (gap), +1 contact (depth)
    gap: float
    A: np.ndarray = field(init=False, repr=False)
    X: complex = field(init=False)  # harmonic amplitude of the steady state [m]
    x_static: float = field(init=False)  # static offset d / K [m]
    mu: float = field(init=False)  # real part of the eigenvalues [1/s]
    delta: complex = field(init=False)  # half the difference of the eigenvalues [1/s]

    def __post_init__(self) -> None:
        m = self.mass
        A = np.array([[0.0, 1.0], [-self.K / m, -self.C / m]])
        den = complex(self.K - m * self.Omega**2, self.C * self.Omega)
        if self.F != 0.0 and den == 0.0:
            raise ValueError("undamped forcing at resonance: no steady state of the phase")
        X = self.F / den if self.F != 0.0 else 0.0j
        if self.d != 0.0 and self.K == 0.0:
            raise ValueError("a constant force on a phase without stiffness has no steady state")
        xs = self.d / self.K if self.d != 0.0 else 0.0
        mu = -self.C / (2.0 * m)
        delta = complex(np.emath.sqrt(mu * mu - self.K / m))
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "X", X)
        object.__setattr__(self, "x_static", xs)
        object.__setattr__(self, "mu", mu)
        object.__setattr__(self, "delta", delta)

    @property
    def eigenvalues(self) -> tuple[complex, complex]:
        """Roots of m lambda^2 + C lambda + K = 0."""
        return self.mu + self.delta, self.mu - self.delta

    @property
    def time_scale(self) -> float:
        """The shortest time scale of the phase [s]: 1 / max(Omega, |lambda|)."""
        rate = max(self.Omega, abs(self.mu) + abs(self.delta), 1e-300)
        return 1.0 / rate

    def steady(self, t: np.ndarray | float) -> np.ndarray:
        """Steady state z_p(t) = (x_p, v_p) of the phase, shape (2,) + shape(t)."""
        t = np.asarray(t, dtype=float)
        e = np.exp(1j * (self.Omega * t + self.phi))
        x = self.x_static + (self.X * e).real
        v = (1j * self.Omega * self.X * e).real
        return np.stack([x, v])

    def expm(self, dt: np.ndarray | float) -> np.ndarray:
        """exp(A dt), shape shape(dt) + (2, 2), from the eigenvalues (module docstring)."""
        dt = np.asarray(dt, dtype=float)
        zt = self.delta * dt
        ch = np.cosh(zt).real
        sh = (dt * _sinhc(zt)).real
        g = np.exp(self.mu * dt)
        B = self.A - self.mu * np.eye(2)
        out = ch[..., None, None] * np.eye(2) + sh[..., None, None] * B
        return g[..., None, None] * out

    def solution(self, t0: float, z0: StateLike, t: np.ndarray | float) -> np.ndarray:
        """The state z(t) = z_p(t) + exp(A (t - t0)) (z0 - z_p(t0)), shape (2,) + shape(t)."""
        t = np.asarray(t, dtype=float)
        w = np.asarray(z0, dtype=float) - self.steady(t0)
        E = self.expm(t - t0)
        return self.steady(t) + np.moveaxis(E @ w, -1, 0)

    def field(self, t: float, z: StateLike) -> np.ndarray:
        """The vector field (v, a) of the phase at (t, z)."""
        force = self.F * math.cos(self.Omega * t + self.phi) + self.d
        return np.array([z[1], (force - self.C * z[1] - self.K * z[0]) / self.mass])

    def switching(self, t0: float, z0: StateLike, t: np.ndarray) -> tuple[np.ndarray, ...]:
        """The switching function s = sign (x - gap) and its rate at the times t."""
        z = self.solution(t0, z0, t)
        return self.sign * (z[0] - self.gap), self.sign * z[1]

    def first_switch(
        self, t0: float, z0: StateLike, t_max: float, on_surface: bool
    ) -> float | None:
        """The first time in (t0, t_max] where the switching function turns <= 0, or None.

        ``on_surface``: the phase starts on the wall (just switched), so t0 itself is no
        root; a phase that starts on the wall moving out of it ends at once (returns t0).
        """
        s0, r0 = self.switching(t0, z0, np.array([t0]))
        if on_surface and r0[0] < 0.0:
            return t0
        h = self.time_scale * 2.0 * math.pi / SAMPLES_PER_SCALE
        a = t0
        chunk = 256
        sa, ra = float(s0[0]), float(r0[0])
        a_valid = not on_surface

        def s_of(t: float) -> float:
            return float(self.switching(t0, z0, np.array([t]))[0][0])

        def r_of(t: float) -> float:
            return float(self.switching(t0, z0, np.array([t]))[1][0])

        while a < t_max:
            ts = np.minimum(a + h * np.arange(1, chunk + 1), t_max)
            ts = ts[np.concatenate(([True], ts[1:] > ts[:-1]))]
            ss, rs = self.switching(t0, z0, ts)
            for b, sb, rb in zip(ts, ss, rs, strict=True):
                pts = [(a, sa, a_valid)]
                if ra * rb < 0.0:
                    c = brentq(r_of, a, b, xtol=1e-300, maxiter=200)
                    pts.append((c, s_of(c), True))
                pts.append((b, float(sb), True))
                for (tl, sl, vl), (tr, sr, _) in pairwise(pts):
                    if vl and sl > 0.0 and sr <= 0.0:
                        if sr == 0.0:
                            return float(tr)
                        return float(brentq(s_of, tl, tr, xtol=1e-300, maxiter=200))
                a, sa, ra = float(b), float(sb), float(rb)
                a_valid = True
        return None


@lru_cache(maxsize=64)
def phases(params: PWLParams) -> tuple[Phase, Phase]:
    """The (free, contact) phases of ``params``."""
    p = params
    if not (p.mass > 0.0 and p.force_frequency > 0.0):
        raise ValueError("mass and force_frequency must be > 0")
    common = dict(mass=p.mass, F=p.force_amplitude, Omega=p.force_frequency, phi=p.force_phase)
    free = Phase(K=p.stiffness, C=p.damping, d=0.0, sign=-1.0, gap=p.gap, **common)
    contact = Phase(
        K=p.stiffness + p.contact_stiffness,
        C=p.damping + p.contact_damping,
        d=p.contact_stiffness * p.gap,
        sign=1.0,
        gap=p.gap,
        **common,
    )
    return free, contact


def phase_solution(
    params: PWLParams, phase: int, t0: float, z0: StateLike, t: np.ndarray | float
) -> np.ndarray:
    """State (x, v) at the time(s) t of the phase ``phase`` (FREE or CONTACT) started at
    (t0, z0), in closed form; shape (2,) + shape(t). It ignores the switching surfaces."""
    return phases(params)[phase].solution(t0, z0, t)


def switching_time(
    params: PWLParams,
    phase: int,
    t0: float,
    z0: StateLike,
    t_max: float,
    on_surface: bool = True,
) -> float | None:
    """First time in (t0, t_max] where the phase ends: the gap g - x reaches 0 (FREE: onset)
    or the depth x - g returns to 0 (CONTACT: exit); None when it does not end by t_max."""
    return phases(params)[phase].first_switch(t0, z0, t_max, on_surface)


def phase_jacobian(params: PWLParams, phase: int, dt: float) -> np.ndarray:
    """d z(t0 + dt) / d z(t0) = exp(A dt) of the phase, exact for a linear phase."""
    return phases(params)[phase].expm(dt)


def saltation_matrix(params: PWLParams, kind: str) -> np.ndarray:
    """Saltation matrix at an ``"onset"`` or an ``"exit"`` of contact.

    S = I + (f+ - f-) n^T / (n^T f-) with n = (1, 0); f+ - f- = (0, -/+ c_c v / m) and
    n^T f- = v, so S = [[1, 0], [-/+ c_c / m, 1]] (di Bernardo et al. 2008,
    doi:10.1007/978-1-84628-708-4).
    """
    if kind not in ("onset", "exit"):
        raise ValueError(f"kind {kind!r}; allowed 'onset' or 'exit'")
    s = -1.0 if kind == "onset" else 1.0
    return np.array([[1.0, 0.0], [s * params.contact_damping / params.mass, 1.0]])


def saltation_from_fields(params: PWLParams, kind: str, t: float, z: StateLike) -> np.ndarray:
    """The saltation matrix from the two vector fields at a switching point (t, z) on the
    wall: the general formula, for checking :func:`saltation_matrix`."""
    free, contact = phases(params)
    before, after = (free, contact) if kind == "onset" else (contact, free)
    f_minus = before.field(t, z)
    f_plus = after.field(t, z)
    n = np.array([1.0, 0.0])
    return np.eye(2) + np.outer(f_plus - f_minus, n) / float(n @ f_minus)


# ---- hybrid flow -----------------------------------------------------------------------------


@dataclass
class Trajectory:
    """The end of a hybrid flow and its switchings.

    ``events``: (time, kind, speed) with kind ``"onset"`` or ``"exit"`` and the speed v at
    the wall; ``z``: the state at ``t``; ``phase``: the phase at ``t``.
    """

    t: float
    z: np.ndarray
    phase: int
    events: list[tuple[float, str, float]]

    @property
    def onsets(self) -> np.ndarray:
        """Onset times [s]."""
        return np.array([e[0] for e in self.events if e[1] == "onset"])

    @property
    def exits(self) -> np.ndarray:
        """Exit times [s]."""
        return np.array([e[0] for e in self.events if e[1] == "exit"])


def initial_phase(params: PWLParams, z: StateLike) -> int:
    """CONTACT beyond the wall or on it moving in, else FREE (the rule braidsim's solver
    applies at the start of a run)."""
    x, v = float(z[0]), float(z[1])
    return CONTACT if (x > params.gap or (x == params.gap and v > 0.0)) else FREE


def simulate(
    params: PWLParams,
    t0: float,
    z0: StateLike,
    t_end: float,
    phase: int | None = None,
    max_events: int = 100_000,
) -> Trajectory:
    """Flow from (t0, z0) to t_end phase by phase in closed form, switching at the exact
    roots of the switching functions."""
    ph = phases(params)
    cur = initial_phase(params, z0) if phase is None else phase
    t = float(t0)
    z = np.array(z0, dtype=float)
    on_surface = z[0] == params.gap
    events: list[tuple[float, str, float]] = []
    while True:
        ts = ph[cur].first_switch(t, z, t_end, on_surface)
        if ts is None:
            z = ph[cur].solution(t, z, t_end)
            return Trajectory(float(t_end), z, cur, events)
        z = ph[cur].solution(t, z, ts)
        z[0] = params.gap  # on the wall exactly (the root)
        t = ts
        events.append((t, "onset" if cur == FREE else "exit", float(z[1])))
        cur = 1 - cur
        on_surface = True
        if len(events) > max_events:
            raise RuntimeError(
                f"more than {max_events} switchings before t = {t_end} (chatter?); "
                "shorten the run or raise max_events"
            )


def stroboscopic_map(
    params: PWLParams, z: StateLike, t0: float = 0.0, period_k: int = 1
) -> np.ndarray:
    """z(t0) -> z(t0 + k T) along the hybrid flow (T the forcing period)."""
    return simulate(params, t0, z, t0 + period_k * params.period).z


# ---- periodic orbits -------------------------------------------------------------------------


@dataclass
class PeriodicOrbit:
    """A periodic orbit of ``period_k`` forcing periods with n impacts.

    Attributes: onset and exit times t_on[j] < t_off[j] < t_on[j+1] (t_on[0] in
    [0, k T)), the speeds at onset (> 0) and exit (< 0), the section time t_section and the
    state there, and the largest scaled residual of the matching equations.
    """

    params: PWLParams
    period_k: int
    t_on: np.ndarray
    t_off: np.ndarray
    v_on: np.ndarray
    v_off: np.ndarray
    t_section: float
    z_section: np.ndarray
    residual: float

    @property
    def period(self) -> float:
        """k T [s]."""
        return self.period_k * self.params.period

    @property
    def impacts(self) -> int:
        """Impacts per period k T."""
        return int(self.t_on.size)

    def phase_at(self, t: float) -> int:
        """Phase of the orbit at time t."""
        P = self.period
        for a, b in zip(self.t_on, self.t_off, strict=True):
            if (t - a) % P < (b - a):
                return CONTACT
        return FREE

    def state(self, t: float) -> np.ndarray:
        """State on the orbit at time t (from the last switching before t, in closed form)."""
        free, contact = phases(self.params)
        P = self.period
        if self.impacts == 0:
            return free.steady(t)
        best = None
        for j in range(self.impacts):
            for t_sw, v, ph in (
                (self.t_on[j], self.v_on[j], contact),
                (self.t_off[j], self.v_off[j], free),
            ):
                back = (t - t_sw) % P
                if best is None or back < best[0]:
                    best = (back, v, ph)
        assert best is not None
        back, v, ph = best
        return ph.solution(t - back, (self.params.gap, v), t)


def _unpack(u: np.ndarray, n: int) -> tuple[np.ndarray, ...]:
    return u[:n], u[n : 2 * n], u[2 * n : 3 * n], u[3 * n :]


def _matching_residual(
    u: np.ndarray, params: PWLParams, n: int, P: float, L: float, V: float
) -> np.ndarray:
    """4 n matching equations: each contact phase from (g, v_on) at t_on ends at (g, v_off)
    at t_off; each free phase from (g, v_off) at t_off ends at (g, v_on) at the next t_on."""
    free, contact = phases(params)
    t_on, t_off, v_on, v_off = _unpack(u, n)
    g = params.gap
    r = np.empty(4 * n)
    for j in range(n):
        z = contact.solution(t_on[j], (g, v_on[j]), t_off[j])
        r[4 * j] = (z[0] - g) / L
        r[4 * j + 1] = (z[1] - v_off[j]) / V
        jn = (j + 1) % n
        t_next = t_on[jn] + (P if jn == 0 else 0.0)
        z = free.solution(t_off[j], (g, v_off[j]), t_next)
        r[4 * j + 2] = (z[0] - g) / L
        r[4 * j + 3] = (z[1] - v_on[jn]) / V
    return r


def _matching_jacobian(
    u: np.ndarray, params: PWLParams, n: int, P: float, L: float, V: float
) -> np.ndarray:
    """Jacobian of :func:`_matching_residual` in closed form: for a phase from (t_a, z_a) to
    t_b, dz(t_b)/dz_a = exp(A (t_b - t_a)), dz(t_b)/dt_b = f(t_b, z(t_b)) and
    dz(t_b)/dt_a = -exp(A (t_b - t_a)) f(t_a, z_a)."""
    free, contact = phases(params)
    t_on, t_off, v_on, v_off = _unpack(u, n)
    g = params.gap
    J = np.zeros((4 * n, 4 * n))
    scale = np.array([L, V])
    for j in range(n):
        jn = (j + 1) % n
        t_next = t_on[jn] + (P if jn == 0 else 0.0)
        for ph, row, ia, ib, va, (it_a, it_b, iv_a, iv_b) in (
            (contact, 4 * j, t_on[j], t_off[j], v_on[j], (j, n + j, 2 * n + j, 3 * n + j)),
            (free, 4 * j + 2, t_off[j], t_next, v_off[j], (n + j, jn, 3 * n + j, 2 * n + jn)),
        ):
            za = np.array([g, va])
            E = ph.expm(ib - ia)
            zb = ph.solution(ia, za, ib)
            rows = slice(row, row + 2)
            J[rows, it_a] += -(E @ ph.field(ia, za)) / scale
            J[rows, it_b] += ph.field(ib, zb) / scale
            J[rows, iv_a] += E[:, 1] / scale
            J[row + 1, iv_b] += -1.0 / V
    return J


def _transient_guess(
    params: PWLParams, period_k: int, seed: StateLike, periods: int
) -> tuple[np.ndarray, ...]:
    """Onsets and exits of the last k periods of a long run from the seed state at t = 0."""
    T = params.period
    traj = simulate(params, 0.0, seed, (periods + 1) * T)
    t_start = (periods - period_k - 1) * T
    ev = [e for e in traj.events if e[0] >= t_start]
    first = next((i for i, e in enumerate(ev) if e[1] == "onset"), None)
    if first is None:
        raise ValueError(
            "the transient from the seed state makes no impact in its last periods; "
            "give a guess (onset/exit times and speeds) or another seed"
        )
    t0 = ev[first][0]
    on, off, von, voff = [], [], [], []
    for i in range(first, len(ev) - 1):
        t, kind, v = ev[i]
        if t >= t0 + period_k * T - 1e-12 * T:
            break
        if kind == "onset" and ev[i + 1][1] == "exit":
            on.append(t)
            von.append(v)
            off.append(ev[i + 1][0])
            voff.append(ev[i + 1][2])
    return np.array(on), np.array(off), np.array(von), np.array(voff)


def periodic_orbit(
    params: PWLParams,
    period_k: int = 1,
    guess: PeriodicOrbit | tuple[StateLike, ...] | None = None,
    *,
    t_section: float = 0.0,
    seed: StateLike = (0.0, 0.0),
    transient_periods: int = 200,
    check: bool = True,
) -> PeriodicOrbit:
    """A periodic orbit of ``period_k`` forcing periods, by matching the closed-form phases.

    ``guess``: a :class:`PeriodicOrbit` (of these or nearby parameters) or a tuple
    (t_on, t_off, v_on, v_off) of n impacts each; by default the impacts of the last k
    periods of a run of ``transient_periods`` periods from ``seed`` at t = 0 (this finds a
    stable orbit; an unstable one needs a guess near it). n = 0 impacts: the harmonic steady
    state of the free phase (checked not to reach the wall).

    ``check``: raise ValueError unless the orbit is admissible: onset speeds > 0, exit
    speeds < 0, and no phase switching before its matched end (the closed-form flow from
    each switching point finds the next one as its first root).
    """
    free, _ = phases(params)
    T = params.period
    P = period_k * T
    if guess is None:
        g_on, g_off, g_von, g_voff = _transient_guess(params, period_k, seed, transient_periods)
    elif isinstance(guess, PeriodicOrbit):
        g_on, g_off, g_von, g_voff = guess.t_on, guess.t_off, guess.v_on, guess.v_off
    else:
        g_on, g_off, g_von, g_voff = (np.asarray(a, dtype=float) for a in guess)
    n = int(np.size(g_on))
    if n == 0:
        ts = np.linspace(0.0, P, 4097)
        if check and np.max(free.steady(ts)[0]) >= params.gap:
            raise ValueError(
                "the harmonic steady state reaches the wall: not an orbit without impacts"
            )
        empty = np.zeros(0)
        return PeriodicOrbit(
            params, period_k, empty, empty, empty, empty, t_section, free.steady(t_section), 0.0
        )
    L = max(abs(params.gap), abs(free.X), 1e-300)
    V = L * max(params.force_frequency, math.sqrt(abs(params.stiffness) / params.mass))
    # times near [0, k T): the forcing's phase Omega t then carries no large rounding
    shift = math.floor(float(np.ravel(g_on)[0]) / P) * P
    u0 = np.concatenate([g_on - shift, g_off - shift, g_von, g_voff]).astype(float)
    args = (params, n, P, L, V)
    sol = root(_matching_residual, u0, args=args, jac=_matching_jacobian, method="hybr")
    u = sol.x
    # Newton steps to polish hybr's answer down to the rounding of the residual
    for _ in range(3):
        u = u - np.linalg.solve(_matching_jacobian(u, *args), _matching_residual(u, *args))
    res = float(np.max(np.abs(_matching_residual(u, *args))))
    if res > 1e-10:
        raise ValueError(
            f"the matching equations did not converge (residual {res:.2e}: "
            f"{' '.join(sol.message.split())}); "
            "give a closer guess"
        )
    t_on, t_off, v_on, v_off = (a.copy() for a in _unpack(u, n))
    # onsets into [0, k T), in increasing order (a cyclic shift of the impacts)
    shifts = np.floor(t_on / P) * P
    t_on -= shifts
    t_off -= shifts
    order = np.argsort(t_on)
    t_on, t_off, v_on, v_off = t_on[order], t_off[order], v_on[order], v_off[order]
    orbit = PeriodicOrbit(params, period_k, t_on, t_off, v_on, v_off, t_section, np.zeros(2), res)
    if check:
        _check_admissible(orbit)
    orbit.z_section = orbit.state(t_section)
    return orbit


def _check_admissible(orbit: PeriodicOrbit) -> None:
    """Raise ValueError unless the matched phases are the flow's own (see periodic_orbit)."""
    free, contact = phases(orbit.params)
    g = orbit.params.gap
    P = orbit.period
    n = orbit.impacts
    tol = 1e-9 * P
    if np.any(orbit.v_on <= 0.0) or np.any(orbit.v_off >= 0.0):
        raise ValueError("not admissible: an onset speed <= 0 or an exit speed >= 0")
    for j in range(n):
        t_next = orbit.t_on[(j + 1) % n] + (P if j == n - 1 else 0.0)
        if not orbit.t_on[j] < orbit.t_off[j] < t_next:
            raise ValueError("not admissible: the switching times are out of order")
        for ph, t_a, v, t_b, what in (
            (contact, orbit.t_on[j], orbit.v_on[j], orbit.t_off[j], "contact"),
            (free, orbit.t_off[j], orbit.v_off[j], t_next, "free"),
        ):
            ts = ph.first_switch(t_a, (g, v), t_b + tol, on_surface=True)
            if ts is None or abs(ts - t_b) > tol:
                found = "never" if ts is None else f"at t = {ts:.9g}"
                raise ValueError(
                    f"not admissible: the {what} phase from t = {t_a:.9g} meant to end at "
                    f"t = {t_b:.9g} switches {found}"
                )


# ---- stability ---------------------------------------------------------------------------------


def monodromy(orbit: PeriodicOrbit, t_section: float | None = None) -> np.ndarray:
    """Jacobian of the stroboscopic map z(t0) -> z(t0 + k T) on the orbit, t0 = t_section.

    The product, in time order, of the phase Jacobians exp(A dt) and of the saltation
    matrices at each onset and exit in (t0, t0 + k T] (:func:`saltation_matrix`).
    """
    params = orbit.params
    ph = phases(params)
    P = orbit.period
    t0 = orbit.t_section if t_section is None else float(t_section)
    if orbit.impacts == 0:
        return ph[FREE].expm(P)
    events = []
    for j in range(orbit.impacts):
        for t_sw, kind in ((orbit.t_on[j], "onset"), (orbit.t_off[j], "exit")):
            t_ev = t0 + ((t_sw - t0) % P)
            if t_ev <= t0:
                t_ev += P
            events.append((t_ev, kind))
    events.sort()
    cur = CONTACT if events[0][1] == "exit" else FREE
    M = np.eye(2)
    t = t0
    for t_ev, kind in events:
        M = ph[cur].expm(t_ev - t) @ M
        M = saltation_matrix(params, kind) @ M
        cur = 1 - cur
        t = t_ev
    return ph[cur].expm(t0 + P - t) @ M


def floquet_multipliers(orbit: PeriodicOrbit, t_section: float | None = None) -> np.ndarray:
    """Eigenvalues of :func:`monodromy`, largest modulus first."""
    mult = np.linalg.eigvals(monodromy(orbit, t_section))
    return mult[np.argsort(-np.abs(mult))]


def grazing_force_amplitude(params: PWLParams) -> float:
    """The forcing amplitude F [N] at which the orbit without impacts grazes the wall.

    Its steady state x = Re(X e^{i(Omega t + phi)}) peaks at |X| = F / |k - m Omega^2 +
    i c Omega|, so it touches x = g (> 0) at F = g |k - m Omega^2 + i c Omega|; below, it is
    an orbit of the impact oscillator, above it is not.
    """
    if not params.gap > 0.0:
        raise ValueError(f"gap {params.gap!r}; the grazing amplitude needs gap > 0")
    w = params.force_frequency
    return params.gap * abs(complex(params.stiffness - params.mass * w * w, params.damping * w))


def bifurcation_function(orbit: PeriodicOrbit, kind: str) -> float:
    """A smooth function of the monodromy M that vanishes at a bifurcation of the orbit.

    ``"period_doubling"``: det(M + I) = 1 + tr M + det M = (1 + m1)(1 + m2), zero when a
    multiplier is -1; ``"fold"``: det(M - I) = 1 - tr M + det M, zero when one is +1. Both
    are real and smooth even where the multipliers are a complex pair (Kuznetsov, Y. A.
    (2004), Elements of Applied Bifurcation Theory, 3rd ed., Springer,
    doi:10.1007/978-1-4757-3978-7).
    """
    M = monodromy(orbit)
    sign = {"period_doubling": 1.0, "fold": -1.0}.get(kind)
    if sign is None:
        raise ValueError(f"kind {kind!r}; allowed 'period_doubling' or 'fold'")
    return float(1.0 + sign * np.trace(M) + np.linalg.det(M))


def critical_parameter(
    params: PWLParams,
    name: str,
    lo: float,
    hi: float,
    kind: str = "period_doubling",
    period_k: int = 1,
    steps: int = 20,
    guess: PeriodicOrbit | None = None,
) -> tuple[float, PeriodicOrbit]:
    """The value of parameter ``name`` in [lo, hi] where the orbit meets ``kind``.

    The orbit is followed from lo to hi in ``steps`` equal steps (each solved from the
    previous one; at lo from ``guess`` or a transient), the first sign change of
    :func:`bifurcation_function` is refined by Brent's method (each evaluation solves the
    matching equations anew). Returns the value and the orbit there.
    """
    if name not in PWLParams._fields:
        raise ValueError(f"parameter {name!r}; allowed one of {PWLParams._fields}")

    def orbit_at(value: float, near: PeriodicOrbit | None) -> PeriodicOrbit:
        return periodic_orbit(params._replace(**{name: value}), period_k, near)

    values = np.linspace(lo, hi, steps + 1)
    prev = orbit_at(values[0], guess)
    f_prev = bifurcation_function(prev, kind)
    for a, b in pairwise(values):
        cur = orbit_at(b, prev)
        f_cur = bifurcation_function(cur, kind)
        if f_prev * f_cur <= 0.0:
            value = brentq(
                lambda x, near=prev: bifurcation_function(orbit_at(x, near), kind),
                a,
                b,
                xtol=1e-13 * max(abs(a), abs(b)),
            )
            return float(value), orbit_at(value, prev)
        prev, f_prev = cur, f_cur
    raise ValueError(f"no {kind} of the orbit for {name} in [{lo}, {hi}]")


def stroboscopic_jacobian_fd(
    params: PWLParams, z: StateLike, t0: float = 0.0, period_k: int = 1, rel: float = 1e-6
) -> np.ndarray:
    """Central finite difference of :func:`stroboscopic_map` at z (for checks; it involves
    no saltation matrix and no matrix exponential)."""
    z = np.asarray(z, dtype=float)
    J = np.empty((2, 2))
    scale = np.maximum(np.abs(z), [abs(params.gap), abs(params.gap) * params.force_frequency])
    for i in range(2):
        e = np.zeros(2)
        e[i] = rel * scale[i]
        J[:, i] = (
            stroboscopic_map(params, z + e, t0, period_k)
            - stroboscopic_map(params, z - e, t0, period_k)
        ) / (2.0 * e[i])
    return J


# ---- documented parameter sets -----------------------------------------------------------------

_BASE = PWLParams(
    mass=1.0,
    stiffness=1.0,
    damping=0.1,
    force_amplitude=1.0,
    force_frequency=1.8,
    force_phase=0.0,
    gap=0.1,
    contact_stiffness=20.0,
    contact_damping=1.0,
)

PARAMETER_SETS: dict[str, PWLParams] = {
    # m = k = 1 (natural frequency 1 rad/s), damping ratio 0.05, wall 0.1 m out, contact
    # 20 times stiffer than the spring; Omega = 1.8 rad/s. Period-1, one impact: onset
    # t = 1.0899800713 s at 2.0739328214 m/s, exit t = 1.7318009285 s at -1.556348289 m/s;
    # z(0) = (-1.7630593803 m, 0.6983689386 m/s); multipliers 0.4740320334 +- 0.3828067247 i.
    "stable_p1": _BASE,
    # the same forcing against a wall 200 times stiffer than the spring. Period-1, one
    # impact: onset t = 0.5580063095 s at 4.1587073322 m/s, exit t = 0.7808890821 s at
    # -3.3036377614 m/s; z(0) = (-2.0622073357 m, 3.3370572989 m/s); multipliers
    # 0.661381077 +- 0.119299836 i.
    "stable_p1_stiff": _BASE._replace(contact_stiffness=200.0, contact_damping=2.0),
    # Omega = 2.4 rad/s, past the period doubling of the period-1 orbit at Omega =
    # 2.29213915 rad/s (:func:`critical_parameter` from Omega = 2.2). Period-1 (unstable),
    # one impact: onset t = 1.0215863895 s at 0.4421789492 m/s, exit t = 1.4842287957 s at
    # -0.3723038292 m/s; z(0) = (-0.3713677184 m, 0.0483261473 m/s); multipliers
    # -1.7517583583 and -0.2766334723. Period-2 (stable, the attractor), two impacts:
    # onsets t = 0.5562863993, 3.9471932136 s at 0.4743414522, 0.5194618765 m/s, exits
    # t = 1.1389674533, 4.458803213 s at -0.4724404205, -0.3507294674 m/s;
    # z(0) = (-0.0810019893 m, 0.0820999881 m/s); multipliers -0.5775914739, -0.3433512249.
    "period_doubled": _BASE._replace(force_frequency=2.4),
}
"""Parameter sets with known orbits (values computed by this module, section t = 0)."""

ORBIT_GUESSES: dict[tuple[str, int], tuple[tuple[float, ...], ...]] = {
    ("stable_p1", 1): ((1.09,), (1.73,), (2.07,), (-1.56,)),
    ("stable_p1_stiff", 1): ((0.558,), (0.781,), (4.16,), (-3.30,)),
    ("period_doubled", 1): ((1.02,), (1.48,), (0.442,), (-0.372,)),
    ("period_doubled", 2): ((0.556, 3.947), (1.139, 4.459), (0.474, 0.519), (-0.472, -0.351)),
}
"""Guesses (t_on, t_off, v_on, v_off) of the orbits above, keyed by (set, period_k): the
unstable period-1 orbit of "period_doubled" cannot be reached by a transient."""
