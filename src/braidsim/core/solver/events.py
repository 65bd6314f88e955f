"""Contact onset and exit, located on the step's interpolant.

Event function j belongs to pair j // 2 and its inner (j even) or outer (j odd) wall: in
free flight it is the gap to that wall, in contact with that wall the penetration (minus the
gap); it turns negative when the event happens. In every accepted step the event functions
are sampled at the ``N_SUB + 1`` points k / N_SUB of the step (its two ends and 7 interior
points of the interpolant; after a screen that rules a pair out when its gap cannot close
within the step); a sign change is located by the Illinois method (the regula falsi that
halves the retained end's value when the same end is kept twice: Dowell & Jarratt, BIT 11
(1971) 168-174, doi:10.1007/BF01934364), and an interior minimum that does not change sign
at the samples is searched for by golden section, so that a contact cannot hide between two
samples.

Where a contact law clamps its force, N = max(0, F_k + F_c), the force has a kink where the
unclamped F_k + F_c crosses 0 (the damping term outpulls the stiffness term: the wall
releases the body before it leaves the contact, and may press it again): the right-hand side
is continuous there but not its derivative, and a step over it is of order h^2 however its
error estimate reads it. A step that ends on the other side of the clamp from where the
contact is (:func:`clamp_crossing`: the solver keeps which side that is) is cut there as at
an event (functions ``CLAMP0 + 2 pair + rising``: the unclamped force, negated for a rising
crossing), located on 9 samples by the same method, without the dip search (the force is 0
to the bit past an exit, where the search would only creep).
"""

from __future__ import annotations

import math

from braidsim.core.generic import helper, inline_helper
from braidsim.core.interfaces import free_accel_bound, pair_gaps
from braidsim.core.layout import MAX_PAIRS
from braidsim.core.solver.dense import dense_eval
from braidsim.core.solver.pairs import I_FC, I_FK, I_GIN, I_GOUT, I_N, I_P, I_PDD, pair_forces

N_SUB = 8  # a step is sampled at k / N_SUB, k = 0..N_SUB, for events and extremes
GOLD = 0.3819660112501051  # 2 - golden ratio
# event functions 0 .. CLAMP0 - 1: a pair's walls (j // 2 the pair, j % 2 the wall); from
# CLAMP0 on, the clamps of the contact forces (CLAMP0 + 2 pair + 1 where the force is clamped
# at the step's start and rises from it, + 0 where it falls to it)
CLAMP0 = 2 * MAX_PAIRS
N_EVENTS = CLAMP0 + 2 * MAX_PAIRS
# where a step ends past a contact's exit, its force is looked at this fraction of the way
# before the exit for a crossing of its clamp (locate_clamp)
EXIT_LOOKBACK = 1e-3


@helper
def event_value(model, j, t, y, modes, v0s):
    """Event function j (>= 0 allowed, < 0 means the event happened); +1 when inactive."""
    if j >= CLAMP0:
        c = j - CLAMP0
        pair = c // 2
        _, _, fk, fc, nn = pair_forces(model, pair, t, y, modes[pair], v0s[pair])
        if c % 2 == 1:
            return -(fk + fc)
        # (falling: only where the law holds N at 0; one that allows tension has no kink)
        return fk + fc if nn == 0.0 or fk + fc >= 0.0 else 1.0
    pair = j // 2
    side = -1 if j % 2 == 0 else 1
    mode = modes[pair]
    if mode != 0 and mode != side:
        return 1.0
    g_in, g_out, _ = pair_gaps(model, pair, t, y)
    if mode == 0:
        return g_in if side < 0 else g_out
    return -g_in if side < 0 else -g_out


@inline_helper
def clamp_crossing(INF0, INF1, pair, clamped):
    """Which clamp event a contact's step may hold, from the pair's summaries at its two ends
    (rows ``pair`` of INF0, INF1: indexed here, a row view made in the loop costs numba's
    reference counting at every step) and whether its force is held at the clamp
    (``clamped``, set at the last clamp event, not read from the force's sign: at the end of
    a step cut at the kink the force is 0 to within the interpolant's error, of either
    sign, and read from it the same kink would be found again and again, a step of a few
    ulps each time). 0 where an unclamped force ends the step at or below 0 (at or past an
    exit it is 0) and the law clamps it there (N = 0; a law that allows tension returns
    N = F_k + F_c < 0: no kink); 1 where a clamped one ends it above 0; -1 for neither."""
    f1 = INF1[pair, I_FK] + INF1[pair, I_FC]
    if clamped:
        return 1 if f1 > 0.0 else -1
    if f1 <= 0.0 and INF1[pair, I_N] == 0.0:
        return 0
    return -1


@inline_helper
def clamp_state(INF, pair):
    """Whether a contact's force is at its clamp, read from its sign where no clamp event
    says it (at the start of a run, or of a contact after a transfer): 1 where F_k + F_c < 0
    and the law holds N at 0."""
    if INF[pair, I_FK] + INF[pair, I_FC] < 0.0 and INF[pair, I_N] == 0.0:
        return 1
    return 0


@inline_helper
def clamp_pending(n_pairs, modes, clamped, INF0, INF1):
    """Whether any contact's step may hold a clamp event (:func:`clamp_crossing`): a test of
    the summaries, inlined in the loop, before :func:`locate_clamp` is called."""
    for pair in range(n_pairs):
        if modes[pair] != 0 and clamp_crossing(INF0, INF1, pair, clamped[pair]) >= 0:
            return True
    return False


@helper
def locate_clamp(
    model, n_pairs, t0, h, RC, modes, v0s, clamped, n, ys, GS, INF0, INF1, theta_wall, j_wall
):
    """(theta, j): the earliest clamp event in the step (:func:`clamp_crossing`; its function
    sampled at the N_SUB + 1 points into GS[j], then located by :func:`locate_event`), or
    (2.0, -1). A call, made only where :func:`clamp_pending` says so: inlined, the loop of
    every step grew and ran 1-3 % slower on paper-3.3, where no force is ever clamped; called
    in every step with a contact, Taylor runs there were 3-15 % slower.

    ``theta_wall``, ``j_wall``: the earliest wall event of the step. Where it is the exit of
    the contact looked at, the unclamped force ends the step at 0 (no depth) whether or not
    it crossed 0 before: one value at EXIT_LOOKBACK of the way before the exit decides
    (positive: no crossing; one within that last stretch is stepped over), not 9 samples.
    """
    theta = 2.0
    j_ev = -1
    for pair in range(n_pairs):
        if modes[pair] == 0:
            continue
        rising = clamp_crossing(INF0, INF1, pair, clamped[pair])
        if rising < 0:
            continue
        j = CLAMP0 + 2 * pair + rising
        if rising == 0 and j_wall >= 0 and j_wall // 2 == pair:
            before = theta_wall * (1.0 - EXIT_LOOKBACK)
            if _event_at(model, j, t0, h, before, RC, modes, v0s, n, ys) > 0.0:
                continue
        for k in range(N_SUB + 1):
            GS[j, k] = _event_at(model, j, t0, h, k / N_SUB, RC, modes, v0s, n, ys)
        th = locate_event(model, j, t0, h, RC, modes, v0s, n, ys, GS)
        if th < theta:
            theta = th
            j_ev = j
    return theta, j_ev


@inline_helper
def event_active(j, modes):
    """Whether event function j can fire in the contact modes."""
    side = -1 if j % 2 == 0 else 1
    mode = modes[j // 2]
    return mode == 0 or mode == side


@inline_helper
def secant_point(lo, hi, glo, ghi, tol):
    """The next point of the Illinois method on [lo, hi], where the function is glo > 0
    at lo and ghi <= 0 at hi: the zero of the secant, moved half the tolerance ``tol``
    inside where it falls nearer an end, so that the bracket closes from that end's side
    next (else the last steps creep towards the root from one side); the midpoint where
    that point is not strictly inside (or not a number)."""
    mid = lo + glo * (hi - lo) / (glo - ghi)
    if mid - lo < 0.5 * tol:
        mid = lo + 0.5 * tol
    elif hi - mid < 0.5 * tol:
        mid = hi - 0.5 * tol
    if not (lo < mid < hi):
        mid = 0.5 * (lo + hi)
    return mid


@helper
def _event_at(model, j, t0, h, theta, RC, modes, v0s, n, ys):
    dense_eval(theta, RC, ys, n)
    return event_value(model, j, t0 + theta * h, ys, modes, v0s)


@helper
def _golden_dip(model, j, t0, h, a, b, RC, modes, v0s, n, ys):
    """Golden-section search of event function j on [a, b] for a value below zero.

    Returns the first theta found with a negative value, or 2.0 when the minimum is >= 0.
    """
    c = a + GOLD * (b - a)
    d = b - GOLD * (b - a)
    fc = _event_at(model, j, t0, h, c, RC, modes, v0s, n, ys)
    fd = _event_at(model, j, t0, h, d, RC, modes, v0s, n, ys)
    for _ in range(80):
        if fc < 0.0:
            return c
        if fd < 0.0:
            return d
        if b - a < 1e-13:
            break
        if fc < fd:
            b = d
            d = c
            fd = fc
            c = a + GOLD * (b - a)
            fc = _event_at(model, j, t0, h, c, RC, modes, v0s, n, ys)
        else:
            a = c
            c = d
            fc = fd
            d = b - GOLD * (b - a)
            fd = _event_at(model, j, t0, h, d, RC, modes, v0s, n, ys)
    return 2.0


@helper
def events_possible(model, pair, h, f0, f1, mode, i0, i1):
    """Screen: can an event of ``pair`` (onset when free, exit in contact) happen in the step?

    For a function g with |g''| <= A on a step of length h, g >= min(g(0), g(h)) - A h^2 / 8.
    In free flight g is a gap and A the model's bound of its second derivative; in contact g
    is the penetration and A twice the larger |p''| at the ends (the contact force varies
    smoothly over the tens of steps a contact takes). A pair without a bound (+inf) is always
    sampled. ``i0``, ``i1``: the pair's summaries at the two ends of the step.
    """
    acc = free_accel_bound(model, pair, f0, f1)
    if acc == math.inf:
        return True
    if mode == 0:
        margin = acc * h * h / 8.0
        return min(i0[I_GIN], i1[I_GIN]) <= margin or min(i0[I_GOUT], i1[I_GOUT]) <= margin
    margin = 2.0 * max(abs(i0[I_PDD]), abs(i1[I_PDD])) * h * h / 8.0
    return min(i0[I_P], i1[I_P]) <= margin


@helper(always_inline=True)  # (called at every step: see core.generic.helper)
def sample_events(model, n_pairs, t0, h, RC, modes, n, ys, GS, f0, f1, INF0, INF1):
    """Event functions at the N_SUB + 1 equally spaced points of the step (GS[j, k]).

    A pair the screen rules out is not sampled (its rows are +1). Returns False when nothing
    needs sampling.
    """
    any_on = False
    for pair in range(n_pairs):
        on = events_possible(model, pair, h, f0, f1, modes[pair], INF0[pair], INF1[pair])
        for k in range(N_SUB + 1):
            GS[2 * pair, k] = 1.0
            GS[2 * pair + 1, k] = 1.0
        if not on:
            continue
        any_on = True
        j0 = 2 * pair
        a0 = event_active(j0, modes)
        a1 = event_active(j0 + 1, modes)
        mode = modes[pair]
        for k in range(N_SUB + 1):
            dense_eval(k / N_SUB, RC, ys, n)
            # one evaluation of the gaps serves both walls of the pair
            g_in, g_out, _ = pair_gaps(model, pair, t0 + k / N_SUB * h, ys)
            if mode == 0:
                GS[j0, k] = g_in if a0 else 1.0
                GS[j0 + 1, k] = g_out if a1 else 1.0
            else:
                GS[j0, k] = -g_in if a0 else 1.0
                GS[j0 + 1, k] = -g_out if a1 else 1.0
    return any_on


@helper
def sample_events_call(model, n_pairs, t0, h, RC, modes, n, ys, GS, f0, f1, INF0, INF1):
    """:func:`sample_events` as a call, for the loop that carries tangents. Inlined there as
    well, it made runs with sensitivities 3-8 % slower (paper-3.3 and paper-3.4a, 0.2 s,
    one and two directions; alternated processes), where in the other loops it makes them
    faster: the larger loop then holds more live values than registers."""
    return sample_events(model, n_pairs, t0, h, RC, modes, n, ys, GS, f0, f1, INF0, INF1)


@helper
def locate_event(model, j, t0, h, RC, modes, v0s, n, ys, GS):
    """Earliest theta in (0, 1] where event function j turns negative; 2.0 when none.

    Uses the samples GS[j] (:func:`sample_events`, :func:`locate_clamp`); a sign change is
    refined by the Illinois method, an interior local minimum of the samples of a wall's
    function by golden section.
    """
    if j < CLAMP0 and not event_active(j, modes):
        return 2.0
    gs = GS[j]
    # where the wall's function is below 0 at the step's start, the pair has just left its
    # wall (or met it) and the state there, recomputed on the step to that event, lies within
    # rounding or the step's error on the other side (measured: 2.5e-15 m of depth after an
    # exit at 1 mm/s). The event is then the crossing after the function has risen above 0,
    # not the start: a step of a millisecond whose first sample falls past the carrier's
    # next contact found that start (a contact of 2.6e-12 s at a negative approach speed).
    # The rise is looked for at doubling distances from the start, up to the first sample.
    lo0 = 0.0
    if j < CLAMP0 and gs[0] < 0.0 and gs[1] < 0.0:
        th = 2e-15 * max(1.0, abs(t0) / max(h, 1e-300))  # (twice the tolerance below)
        while th < 1.0 / N_SUB:
            g = _event_at(model, j, t0, h, th, RC, modes, v0s, n, ys)
            if g >= 0.0:
                lo0 = th
                gs[0] = g
                break
            th *= 2.0
    gs[0] = max(gs[0], 0.0)
    lo = -1.0
    hi = -1.0
    glo = 0.0
    ghi = 0.0
    for k in range(1, N_SUB + 1):
        if gs[k] < 0.0:
            lo = (k - 1) / N_SUB if k > 1 else lo0
            hi = k / N_SUB
            glo = gs[k - 1]  # (the samples are the function at these points)
            ghi = gs[k]
            break
        if (
            k < N_SUB
            and j < CLAMP0
            and gs[k] < gs[k - 1]
            and gs[k] <= gs[k + 1]
            and gs[k] < max(gs[k - 1] - gs[k], gs[k + 1] - gs[k])
        ):
            # interior local minimum of the samples, close enough to zero that the function
            # could dip below it between the samples: golden section for that dip
            dip = _golden_dip(
                model, j, t0, h, (k - 1) / N_SUB, (k + 1) / N_SUB, RC, modes, v0s, n, ys
            )
            if dip < 2.0:
                lo = (k - 1) / N_SUB
                hi = dip
                glo = gs[k - 1]
                ghi = _event_at(model, j, t0, h, hi, RC, modes, v0s, n, ys)
                break
    if hi < 0.0:
        return 2.0
    # Illinois on [lo, hi] with g(lo) >= 0 > g(hi) (:func:`secant_point`; the value kept
    # at an end halved when the other end moves twice in a row)
    glo = max(glo, 0.0)
    tol = 1e-15 * max(1.0, abs(t0) / max(h, 1e-300))
    side = 0
    zstep = 0.5 * tol  # the step past an lo where g = 0 exactly (doubled while it stays 0)
    for _ in range(200):
        if hi - lo <= tol:
            break
        if glo > 0.0:
            mid = secant_point(lo, hi, glo, ghi, tol)
            zstep = 0.5 * tol
        else:
            # g(lo) = 0 exactly: the secant's zero is lo itself. The event is just past it
            # (a secant that landed on the root) or past a run of exact zeros (a function
            # flat to the last bit over a short step): steps from lo that double
            mid = min(lo + zstep, 0.5 * (lo + hi))
            zstep *= 2.0
            if not (lo < mid < hi):
                mid = 0.5 * (lo + hi)
        gm = _event_at(model, j, t0, h, mid, RC, modes, v0s, n, ys)
        if gm < 0.0:
            hi = mid
            ghi = gm
            if side == -1:
                glo *= 0.5
            side = -1
        else:
            lo = mid
            glo = gm
            if side == 1:
                ghi *= 0.5
            side = 1
    return hi


@helper
def first_event(model, n_pairs, t, h, RC, modes, v0s, clamped, n, ys, GS, f0, f1, INF0, INF1):
    """(theta, j): the step's earliest event, a wall's or a clamp's, found as the loop finds
    it (the same calls on the same values: the same bits), or (2.0, -1). For the loop that
    carries tangents, which asks it before its step is accepted (tangent.clamp_step_end)."""
    theta = 2.0
    j_ev = -1
    if sample_events(model, n_pairs, t, h, RC, modes, n, ys, GS, f0, f1, INF0, INF1):
        for j in range(2 * n_pairs):
            th = locate_event(model, j, t, h, RC, modes, v0s, n, ys, GS)
            if th < theta:
                theta = th
                j_ev = j
    if clamp_pending(n_pairs, modes, clamped, INF0, INF1):
        th, j = locate_clamp(
            model, n_pairs, t, h, RC, modes, v0s, clamped, n, ys, GS, INF0, INF1, theta, j_ev
        )
        if th < theta:
            theta = th
            j_ev = j
    return theta, j_ev
