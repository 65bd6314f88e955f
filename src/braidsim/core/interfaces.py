"""The generic functions the solver is written against: what a contact law, a friction law,
an excitation and a model each provide.

Each function below is declared once; each record class implements it in its own file with
``@name.register(RecordClass)`` (see :mod:`braidsim.core.generic`). The stubs only document
the contract: compiled code calls the implementation of the argument's class.

Signs and conventions: a contact pair is a coordinate between two walls. ``g_in`` is the
gap to the inner (lower) wall, ``g_out`` the gap to the outer (upper) wall, both positive
when free; ``rate`` is d g_in / dt (= -d g_out / dt). In contact with a wall, the
penetration is ``p = -gap`` >= 0 and ``p_dot`` its rate. A one-sided pair has an infinite
gap to its missing wall.

Besides these functions the solver reads two fields of every model record by name, for its
contact policy (:func:`braidsim.core.solver.loop.integrate`): ``min_impact_velocity``
[m/s], the floor of the approach speed latched at contact onset, and
``initial_impact_velocity`` [m/s], the approach speed given to a contact that overlaps a
wall at the start (<= 0: none, the overlap is released elastically, v0 = inf). A model
without them fails to compile with "unknown attribute".

A model has at most two contact pairs (:data:`braidsim.core.layout.MAX_PAIRS`); the
driver refuses more.
"""

from __future__ import annotations

from typing import Any

from braidsim.core.generic import generic, inline_helper

# What each model writes: its series columns (``t`` first, ``kind`` last) and the names of
# its energy quadratures in state order. Filled by :func:`describe_model`, read by
# :func:`series_columns`.
_COLUMNS: dict[type, tuple[str, ...]] = {}
_QUADS: dict[type, tuple[str, ...]] = {}


def describe_model(cls: type, columns: tuple[str, ...], quads: tuple[str, ...]) -> None:
    """Register the series columns and energy quadratures of a model class. The columns
    start with ``t`` (the driver sorts and streams rows by it) and end with ``kind`` (the
    row's kind: a sample or an event, :mod:`braidsim.core.layout`)."""
    if not columns or columns[0] != "t" or columns[-1] != "kind":
        raise ValueError(
            f"{cls.__name__}: series columns must start with 't' and end with 'kind', got {columns}"
        )
    _COLUMNS[cls] = columns
    _QUADS[cls] = quads


def first_missing(record: Any, model_functions: Any, roles: Any) -> tuple[str, Any, Any] | None:
    """What a model record lacks of a group of generic functions (its tangents, its series):
    ``("", None, fn)`` for the first of ``model_functions`` not registered for the record's
    class; ``(field, value, companion)`` for the first field whose value implements the
    primal of a ``(primal, companion)`` pair of ``roles`` (a contact law, a friction law, an
    excitation, whatever the field's name) but not the companion; ``None`` when nothing."""
    for fn in model_functions:
        if type(record) not in fn.generic.impls:
            return "", None, fn
    for field in getattr(record, "_fields", ()):
        sub = getattr(record, field)
        for primal, companion in roles:
            if type(sub) in primal.generic.impls and type(sub) not in companion.generic.impls:
                return field, sub, companion
    return None


def described(model: Any) -> bool:
    """Whether ``model`` (a record or its class) has its series columns described
    (:func:`describe_model`)."""
    return (model if isinstance(model, type) else type(model)) in _COLUMNS


def series_columns(model: Any) -> tuple[str, ...]:
    """The columns of the sampled series of ``model`` (a record or its class)."""
    return _COLUMNS[model if isinstance(model, type) else type(model)]


def quadrature_names(model: Any) -> tuple[str, ...]:
    """The energy quadratures of ``model`` in state order."""
    return _QUADS[model if isinstance(model, type) else type(model)]


@inline_helper
def penetration(mode, g_in, g_out, rate):
    """(p, p') into the wall of ``mode`` (-1 inner, +1 outer) from the pair's gaps and
    rate (the convention above), p clamped at 0."""
    if mode < 0:
        p = -g_in
        pd = -rate
    else:
        p = -g_out
        pd = rate
    if p < 0.0:
        p = 0.0
    return p, pd


# =======================================================================================
# Contact laws: the normal force of a compliant contact
# =======================================================================================


@generic
def contact_forces(law, p, p_dot, v0):
    """(F_k, F_c, N) [N] at penetration ``p`` >= 0 [m], rate ``p_dot`` [m/s], with the
    approach speed ``v0`` [m/s] latched at onset: the stiffness-related force, the
    damping-related force and the normal force (>= 0 unless the law allows tension).

    A law that cannot pull returns N = max(0, F_k + F_c): the solver reads N = 0 where
    F_k + F_c < 0 as the clamp and ends its steps at the kink where F_k + F_c crosses 0
    (:mod:`braidsim.core.solver.events`); one that may pull returns N = F_k + F_c."""
    raise NotImplementedError


@generic
def contact_potential(law, p):
    """Elastic energy stored at penetration ``p`` >= 0 [J]: int_0^p F_k dp."""
    raise NotImplementedError


@generic
def contact_force_rates(law, p, p_dot, p_ddot, v0, f_k, f_c):
    """(dN/dt, dF_c/dt) [N/s] given the penetration, its first two time derivatives and the
    forces ``f_k``, ``f_c`` of :func:`contact_forces` at the same instant. Only their signs
    matter at p = 0 (they decide whether a step holds a force peak)."""
    raise NotImplementedError


@generic
def contact_onset_step(law, mass, v):
    """(h, q): a first step [s] for a contact that starts at approach speed ``v`` [m/s] on a
    body of ``mass`` [kg] (about 1/12 of the contact's duration), and the exponent q used to
    rescale that step when it is rejected, h_new = h err^(-1/q): the force grows as p^n after
    onset, so for n not an integer the step's error grows as h^(n+1), q = n + 1. The solver
    also corrects that step's error estimate by q (``dopri5.onset_error_ratio``: the
    embedded estimate misses the tau^n onset, 11.3 times in the speed for n = 3/2), so a
    wrong q changes the accuracy of each contact's first step, not only its retries. (For an
    integer n the error is the method's regular one; the laws still return n + 1, which
    shrinks a rejected first step somewhat more than needed.)"""
    raise NotImplementedError


# =======================================================================================
# Friction laws: a regularised sign function times a normal force
# =======================================================================================


@generic
def friction_force(law, v, normal, mu):
    """Friction force [N] opposing the sliding speed ``v`` [m/s] under the normal force
    ``normal`` [N] with coefficient ``mu`` [-]."""
    raise NotImplementedError


# =======================================================================================
# Excitations: the prescribed motion of a wall pair
# =======================================================================================


@generic
def wall_motion(ex, t):
    """(position [m], speed [m/s], acceleration [m/s^2]) of the inner wall at time t."""
    raise NotImplementedError


@generic
def wall_accel_bound(ex):
    """An upper bound of |acceleration| of the wall over all time [m/s^2] (for the contact
    screens of the solver)."""
    raise NotImplementedError


# =======================================================================================
# Models: equations of motion over coordinates with contact pairs
# =======================================================================================
# A model's state vector is (q0, q0', q1, q1', ...) for its n_coords coordinates, followed
# by its n_quads energy quadratures when the run integrates them.


@generic
def model_size(model):
    """(n_coords, n_pairs, n_quads): coordinates, contact pairs (<= 2), energy quadratures;
    constants of the record class (the driver asks the interpreter for them, once per class:
    write them in plain Python).

    The quadratures are ordered so that a run can integrate a prefix of them: first the
    energy each pair's contact law dissipates, in pair order (:func:`dissipation_index`),
    then the friction work along each coordinate, then the rest."""
    raise NotImplementedError


@generic
def derivatives(model, t, y, modes, v0s, n_state, out):
    """Write dy/dt into ``out[:n_state]`` in the contact modes ``modes`` (per pair: -1 inner,
    +1 outer, 0 free) with the latched approach speeds ``v0s``; ``n_state`` is 2 n_coords, or
    2 n_coords + n_quads when the energy quadratures are integrated, or 2 n_coords + n_pairs
    (the dissipations only) or 2 n_coords + n_pairs + n_coords (and the friction works)."""
    raise NotImplementedError


@generic
def pair_gaps(model, pair, t, y):
    """(g_in, g_out, rate) of contact pair ``pair`` at (t, y) (see the module docstring)."""
    raise NotImplementedError


@generic
def pair_gap_accel(model, pair, t, f):
    """d^2 g_in / dt^2 [m/s^2] at t, ``f`` being dy/dt there (an RK stage or the derivative
    of the interpolant)."""
    raise NotImplementedError


@generic
def pair_law(model, pair, p, p_dot, v0):
    """:func:`contact_forces` of the law of pair ``pair``."""
    raise NotImplementedError


@generic
def pair_law_rates(model, pair, p, p_dot, p_ddot, v0, f_k, f_c):
    """:func:`contact_force_rates` of the law of pair ``pair``."""
    raise NotImplementedError


@generic
def pair_onset_step(model, pair, v):
    """:func:`contact_onset_step` of the law of pair ``pair`` for this model's mass."""
    raise NotImplementedError


@generic
def free_accel_bound(model, pair, f0, f1):
    """An estimate, with a margin, of the largest |d^2 g / dt^2| of pair ``pair`` in free
    flight over a step whose ends have the derivatives ``f0``, ``f1`` (the screen rules a
    pair out of a step when its gap cannot close under it); +inf when no useful estimate
    exists (the pair's events are then sampled in every step)."""
    raise NotImplementedError


@generic
def apply_transfer(model, t, y):
    """Apply a transfer (a jump of the state at a prescribed time) to ``y`` in place, and
    return the number k (0 <= k <= n_pairs) of leading pairs whose contacts end at the
    transfer and are started anew by the contact policy (the carrier: 1, its track pair; a
    model whose jump leaves its contacts alone: 0)."""
    raise NotImplementedError


@generic
def dissipation_index(model, pair):
    """Index in the state vector of the energy dissipated by pair ``pair``'s contact law; a
    constant of the record class (the driver asks the interpreter for it, once per class and
    pair: write it in plain Python). With the quadratures
    ordered as :func:`model_size` says, it is 2 n_coords + pair."""
    raise NotImplementedError


@generic
def series_row(model, t, y, modes, v0s, n_state, kind, row):
    """Fill one row of the model's sampled series (its :func:`series_columns`, ``kind``
    last)."""
    raise NotImplementedError


# =======================================================================================
# Taylor series: the coefficients of the solution's expansion in time
# =======================================================================================
# A Taylor step (:mod:`braidsim.core.solver.taylor`) expands the state in tau = t' - t,
# y_i(t + tau) = sum_k C[i, k] tau^k, by the recurrences of automatic differentiation: the
# coefficient k + 1 of y follows from the coefficients 0..k of dy/dt, and those of each
# function of y from the coefficients of its argument (:mod:`braidsim.core.jets`). The
# functions below give, each for its own record, coefficient k of its output from the
# coefficients 0..k of its inputs; the caller calls them for k = 0, 1, 2, ... in turn, and
# each keeps the coefficients it needs again in the rows of its work array ``S`` (shape
# (SERIES_ROWS, >= order + 2); its rows are its own). A run asked for Taylor steps of a
# record without them is refused before it starts (core.driver.taylor_capable names the
# record and the function).

SERIES_ROWS = 8  # rows of work a physics record's series may use
TAYLOR_ROWS = 48  # rows of work a model's series may use


@generic
def contact_force_series(law, k, P, v0, S):
    """Coefficient k of (F_k, F_c, N) [N s^-k] of :func:`contact_forces` along the
    penetration p(t + tau) = sum_j P[j] tau^j, with P[0] > 0 (the series of p^n does not
    exist at p = 0). Reads P[0..k+1] (the coefficient k of p' is (k + 1) P[k + 1]). The
    series is that of the unclamped force F_k + F_c: the solver takes no Taylor step over
    which it turns negative."""
    raise NotImplementedError


@generic
def friction_force_series(law, k, V, NS, mu, S):
    """Coefficient k of :func:`friction_force` along the sliding speed v(t + tau) =
    sum_j V[j] tau^j under the normal force with coefficients NS[0..k] (a constant normal
    force: NS of length 1), coefficient ``mu`` (constant)."""
    raise NotImplementedError


@generic
def friction_series_reach(law, V, h):
    """How far [0, h'] along a step of length ``h`` the law's series (:func:`friction_force_series`)
    along the sliding speed's polynomial v = sum_j V[j] sigma^j (sigma the step's variable:
    tau, or s = sqrt(tau) in an onset step) shows the force's change to the step-size rule,
    h' <= h. A law whose series has only algebraic singularities (arctan) returns ``h``: its
    coefficients carry them. A saturating part (tanh(v / v_hat), exp(-(v / v_s)^2)) hides a
    turn-over that is far away in its argument: its coefficients are exponentially small there
    (1 - tanh(u)^2 is 0 in double precision beyond |u| ~ 19), so a series of order 12 is
    constant while the force is about to change sign, and the rule would step across; such a
    law returns the part of the step before that (:func:`braidsim.core.jets.saturation_reach`)."""
    raise NotImplementedError


@generic
def wall_series(ex, t, order, H):
    """Write the coefficients H[0..order] of the inner wall's position h(t + tau) [m s^-k];
    return the time [s] from t over which this series is the wall's motion (inf for an
    analytic motion; for a piecewise one, the time to the end of the piece holding t)."""
    raise NotImplementedError


@generic
def model_series_start(model, t, modes, order, W):
    """Prepare a Taylor step of ``order`` from t in the contact modes ``modes``: write the
    series of what the equations take from time alone (the walls' motions) into the model's
    rows of the work array ``W`` (shape (TAYLOR_ROWS, >= order + 2)); return the time [s]
    over which these series hold (the smallest :func:`wall_series` horizon)."""
    raise NotImplementedError


@generic
def model_series(model, k, modes, v0s, n_state, C, W):
    """Write C[:n_state, k + 1], the coefficient k + 1 of the state's Taylor series, from
    C[:n_state, 0..k] (coefficient k of dy/dt divided by k + 1), after
    :func:`model_series_start`; called for k = 0, 1, 2, ... in turn. A pair in contact has
    a penetration > 0 at the start of the step."""
    raise NotImplementedError


@generic(inline=False)  # (a call, once a step: not its checks compiled into the loop twice)
def model_series_reach(model, C, h):
    """The part [0, h'] of a series step of length ``h`` (in the series' variable: tau, or
    s = sqrt(tau) in an onset step) over which the model's series, the state's coefficients
    C[i, k] in that variable, show every change of the model's forces to the step-size rule:
    ``h`` unless a law's series hides one (:func:`friction_series_reach` of each sliding
    speed). Called on each Taylor and onset step after its size is chosen."""
    raise NotImplementedError


@generic
def pair_series_rows(model, pair):
    """The rows of the work array ``W`` in which :func:`model_series` leaves pair ``pair``'s
    penetration p, damping force F_c and normal force N as series in time (coefficients
    0..k + 1 of p and 0..k of F_c and N after the call for k): (row_p, row_fc, row_n), -1
    for a quantity the model does not keep there. The solver finds the extremes inside a
    Taylor step on these polynomials (:mod:`braidsim.core.solver.recorders`)."""
    raise NotImplementedError


# The onset series: at a contact's onset p = 0 and p' > 0, so a power law's p^n has a branch
# point there (no Taylor series in tau, and a radius of convergence equal to the time since
# the onset just after it). In s = sqrt(tau) it is gone: p(t_on + s^2) = s^2 q(s) with q
# analytic and q(0) = p'(t_on) > 0, so p^n = s^(2n) q(s)^n is a series in s wherever 2n is
# an integer. The state then follows dy/ds = 2 s f(t_on + s^2, y), and the onset step expands
# it in s (braidsim.core.solver.taylor, "The onset step"). A law or model without these
# functions starts each contact with a Runge-Kutta step.


@generic
def contact_onset_power(law):
    """The power m of s at which the law's stiffness force starts, K p^n = K s^m q^n (m = 2n),
    when its forces are series in s = sqrt(t - t_onset) from an onset; 0 when they are not (a
    non-integer 2n)."""
    raise NotImplementedError


@generic
def contact_force_onset_series(law, k, Q, v0, S):
    """Coefficient k, in s = sqrt(t - t_onset), of (F_c, N) of :func:`contact_forces` from a
    contact's onset, where the penetration is p(t_onset + s^2) = s^2 q(s) with
    q(s) = sum_j Q[j] s^j, Q[0] = p'(t_onset) > 0; reads Q[0..k]. The rate in the damping
    term is p' = dp/dt = sum_j (j + 2) Q[j] s^j / 2. Unclamped, as
    :func:`contact_force_series`."""
    raise NotImplementedError


@generic
def model_onset_start(model, t, pair, modes, order, W):
    """Prepare an onset step of ``order`` in s = sqrt(tau) from t, where pair ``pair`` has
    just touched (p = 0 at t; ``modes`` hold its new mode): as :func:`model_series_start`,
    with each series of time alone written in s (h(t + s^2): its coefficient j in tau at
    s^(2 j)); return the time [s] over which they hold, or 0.0 when the model has no onset
    series in these modes."""
    raise NotImplementedError


@generic
def model_onset_series(model, k, pair, modes, v0s, n_state, C, W):
    """Write C[:n_state, k + 2], the coefficient k + 2 in s = sqrt(tau) of the state from the
    onset of pair ``pair``, after :func:`model_onset_start`: along t + s^2 the state follows
    dy/ds = 2 s f, so (k + 2) C[:, k + 2] = 2 f_k, f_k the coefficient k of dy/dt (and
    C[:, 1] = 0). Called for k = 0, 1, 2, ... in turn; the coordinates' C[i, k + 2] =
    2 C[i + 1, k] / (k + 2) are known before f_k is, and the penetration's coefficients to
    k + 2 with them."""
    raise NotImplementedError


# =======================================================================================
# Tangents: directional derivatives for the forward sensitivities
# =======================================================================================
# A tangent record ``d...`` has the class of its primal record; its float fields and float
# arrays hold the derivatives of the primal's fields along one direction (d field / d key),
# its integer fields copy the primal's. Each function returns (or writes) the derivative of
# its primal counterpart along the direction given by the tangents of all its arguments
# (``dp`` for ``p``, ...). See docs/sensitivities.md for the method.


@generic
def contact_forces_jvp(law, dlaw, p, dp, p_dot, dp_dot, v0, dv0):
    """(dF_k, dF_c, dN): the tangent of :func:`contact_forces`."""
    raise NotImplementedError


@generic
def friction_force_jvp(law, dlaw, v, dv, normal, dnormal, mu, dmu):
    """The tangent of :func:`friction_force`."""
    raise NotImplementedError


@generic
def wall_motion_jvp(ex, dex, t):
    """(dh, dh', dh''): the tangent of :func:`wall_motion` at fixed t along the excitation's
    tangent record ``dex``."""
    raise NotImplementedError


@generic(inline=False)  # a call, not inlined: 52 s to compile a solver with tangents, not 73
def derivatives_jvp(model, dmodel, t, y, s, modes, v0s, dv0s, out):
    """Write the tangent of dy/dt (coordinates and speeds only, ``out[:2 n_coords]``) at
    (t, y) along the state tangent ``s`` and the model tangent ``dmodel``, with latched
    speeds ``v0s`` and their tangents ``dv0s``."""
    raise NotImplementedError


@generic
def pair_gaps_jvp(model, dmodel, pair, t, y, s):
    """(dg_in, dg_out, drate): the tangent of :func:`pair_gaps` at fixed t."""
    raise NotImplementedError


@generic
def pair_law_jvp(model, dmodel, pair, p, dp, p_dot, dp_dot, v0, dv0):
    """:func:`contact_forces_jvp` of the law of pair ``pair``."""
    raise NotImplementedError


@generic
def apply_transfer_jvp(model, dmodel, t, y, s, dt, out):
    """Tangent of a transfer: write into ``out[:2 n_coords]`` the derivative of the state
    after the transfer applied at time t to the state ``y`` (before it), along the state
    tangent ``s``, the model tangent and a shift ``dt`` of the transfer time (at fixed
    state)."""
    raise NotImplementedError


@inline_helper
def penetration_jvp(mode, dg_in, dg_out, drate):
    """The tangent (dp, dp') of :func:`penetration` (p not clamped: in contact p >= 0)."""
    if mode < 0:
        return -dg_in, -drate
    return -dg_out, drate
