"""Truncated Taylor series ("jets") and the recurrences of automatic differentiation.

A jet is the coefficient array A[0..] of a function's expansion a(t + tau) = sum_k A[k] tau^k
about a point t. Each function below gives coefficient ``k`` of a result from the
coefficients 0..k of its arguments (and, where the recurrence needs them, the result's own
coefficients below k), so that a series is built order by order, as the Taylor step needs it:
the coefficient k + 1 of the state follows from the coefficient k of its derivative.

The recurrences (Griewank & Walther, Evaluating Derivatives, 2nd ed., SIAM 2008, Sect. 13.2,
doi:10.1137/1.9780898717761; Jorba & Zou, Experimental Mathematics 14 (2005) 99-117,
doi:10.1080/10586458.2005.10128904), with A' the derivative in tau, whose coefficient j - 1
is j A[j]:

    product   (A B)_k = sum_{j=0}^{k} A_j B_{k-j}
    quotient  Q = A / B:   Q_k = (A_k - sum_{j=1}^{k} B_j Q_{k-j}) / B_0
    power     R = A^n (A_0 > 0), from R' A = n A' R:
              k A_0 R_k = sum_{j=0}^{k-1} (n (k - j) - j) A_{k-j} R_j
    exp       E = exp(G), from E' = G' E:   k E_k = sum_{j=1}^{k} j G_j E_{k-j}
    atan      Z = atan(U), W = 1 + U^2, from Z' W = U':
              k W_0 Z_k = k U_k - sum_{j=1}^{k-1} j Z_j W_{k-j}
    tanh      T = tanh(U), from T' = (1 - T^2) U':
              k T_k = sum_{j=1}^{k} j U_j (1 - T^2)_{k-j}
    cos, sin of a linear argument w (t + tau) + phi: closed form.
    in s      A(t + s^2) for s = sqrt(tau): coefficient j at s^(2 j), the odd ones 0.

Each costs O(k) for coefficient k, so a series of order N costs O(N^2).
"""

from __future__ import annotations

import math

from braidsim.core.generic import inline_helper


@inline_helper
def jet_mul(A, B, k):
    """Coefficient k of the product of the jets A and B."""
    acc = 0.0
    for j in range(k + 1):
        acc += A[j] * B[k - j]
    return acc


@inline_helper
def jet_mul_const(A, B, k):
    """Coefficient k of A B, where an A of length 1 is the constant A[0] (its product is
    A[0] B[k], not a sum of k + 1 products: a friction law under a constant normal force)."""
    if A.shape[0] == 1:
        return A[0] * B[k]
    return jet_mul(A, B, k)


@inline_helper
def jet_sq(A, k):
    """Coefficient k of A^2 (the product's symmetric half, doubled)."""
    acc = 0.0
    for j in range((k + 1) // 2):
        acc += A[j] * A[k - j]
    acc *= 2.0
    if k % 2 == 0:
        acc += A[k // 2] * A[k // 2]
    return acc


@inline_helper
def jet_div(A, B, Q, k):
    """Coefficient k of Q = A / B (B[0] != 0), given Q[0..k-1]."""
    acc = A[k]
    for j in range(1, k + 1):
        acc -= B[j] * Q[k - j]
    return acc / B[0]


@inline_helper
def jet_pow(A, R, n, k):
    """Coefficient k of R = A^n (A[0] > 0), given R[0..k-1]."""
    if k == 0:
        a0 = A[0]
        if n == 1.5:  # the Hertz exponent: cheaper than pow
            return a0 * math.sqrt(a0)
        return a0**n
    # sum_j (n (k - j) - j) A_{k-j} R_j = n k sum_j A_{k-j} R_j - (n + 1) sum_j j A_{k-j} R_j:
    # two independent sums (the step waits on chains of dependent additions, not on their
    # number) and no conversion of j in the loop; the reciprocal is taken apart from them
    r = 1.0 / (k * A[0])
    s0 = 0.0
    s1 = 0.0
    fj = 0.0
    for j in range(k):
        term = A[k - j] * R[j]
        s0 += term
        s1 += fj * term
        fj += 1.0
    return (n * k * s0 - (n + 1.0) * s1) * r


@inline_helper
def jet_exp(G, E, k):
    """Coefficient k of E = exp(G), given E[0..k-1]."""
    if k == 0:
        return math.exp(G[0])
    acc = 0.0
    for j in range(1, k + 1):
        acc += j * G[j] * E[k - j]
    return acc / k


@inline_helper
def jet_atan(U, W, Z, k):
    """Coefficient k of Z = atan(U); also writes W[k], the coefficient k of 1 + U^2 (W and Z
    hold coefficients 0..k-1 from the earlier calls)."""
    W[k] = jet_sq(U, k) + (1.0 if k == 0 else 0.0)
    if k == 0:
        return math.atan(U[0])
    r = 1.0 / (k * W[0])
    acc = k * U[k]
    fj = 1.0
    for j in range(1, k):
        acc -= fj * Z[j] * W[k - j]
        fj += 1.0
    return acc * r


@inline_helper
def jet_tanh(U, T, Q, k):
    """Coefficient k of T = tanh(U); Q holds the coefficients of 1 - T^2: this call writes
    Q[k] (T[0..k-1] and Q[0..k-1] from the earlier calls)."""
    if k == 0:
        t0 = math.tanh(U[0])
        T[0] = t0
        Q[0] = 1.0 - t0 * t0
        return t0
    acc = 0.0
    for j in range(1, k + 1):
        acc += j * U[j] * Q[k - j]
    tk = acc / k
    T[k] = tk
    Q[k] = -jet_sq(T, k)
    return tk


@inline_helper
def jet_cos_linear(a, w, phase, t, order, out, add):
    """The coefficients out[0..order] of a cos(w (t + tau) + phase), added to ``out`` when
    ``add`` (else written): a w^k / k! cos(w t + phase + k pi / 2)."""
    th = w * t + phase
    c = math.cos(th)
    s = math.sin(th)
    fk = a
    for k in range(order + 1):
        r = k & 3
        cy = c if r == 0 else (-s if r == 1 else (-c if r == 2 else s))
        if add:
            out[k] += fk * cy
        else:
            out[k] = fk * cy
        fk *= w / (k + 1)


@inline_helper
def jet_in_sqrt(A, half, order):
    """Rewrite in place the coefficients A[0..half] of a(t + tau) as those of a(t + s^2) in
    s = sqrt(tau), A[0..order] (order >= 2 half): coefficient j at s^(2 j), the odd ones 0
    (the series in time of an onset step, :mod:`braidsim.core.solver.taylor`)."""
    for j in range(half, 0, -1):
        A[2 * j] = A[j]
        A[2 * j - 1] = 0.0
    for j in range(2 * half + 1, order + 1):
        A[j] = 0.0


# ---- where a saturating function's series stops showing its change ---------------------------
# exp(-E) for E >= SATURATED is below the last bit of a force (e^-40 = 4e-18)
SATURATED = 40.0
# the largest fall of the exponent E over one step: the series of exp(-E) along a step where E
# falls by D has the terms D^k / k! exp(-E_0), which shrink from k ~ D on; with D = 6 those
# past the 12th sum to less than the 12th (a series of order 12), so the last terms the step
# rule reads bound what the series leaves out
HIDDEN_FALL = 6.0
REACH_SAMPLES = 8  # points of a step at which the exponent is checked


@inline_helper
def _horner(V, sigma):
    """sum_j V[j] sigma^j."""
    deg = V.shape[0] - 1
    acc = V[deg]
    for j in range(deg - 1, -1, -1):
        acc = acc * sigma + V[j]
    return acc


@inline_helper
def _exponent(v, scale, power):
    """E = (|v| / scale)^power (power 1 or 2)."""
    e = abs(v) / scale
    return e if power == 1 else e * e


@inline_helper
def _below_floor(V, sigma, scale, power, floor, v0):
    """Whether E < floor at sigma, or v has left the sign of v0 (then |v| has passed 0
    since the start, below any floor)."""
    v = _horner(V, sigma)
    if v * v0 <= 0.0:
        return True
    return _exponent(v, scale, power) < floor


@inline_helper
def saturation_reach(V, scale, power, h):
    """The part [0, h'] of a step of length h over which the series of a function that
    saturates as exp(-E), E = (|v| / scale)^power (tanh(v / v_hat): 1 - |tanh| ~ 2 exp(-2 |v|
    / v_hat), scale v_hat / 2, power 1; exp(-(v / v_s)^2): scale v_s, power 2), along the
    polynomial v = sum_j V[j] sigma^j, shows its change to a last-terms step rule.

    Far in saturation the function's coefficients are exp(-E_0) D^k / k! (D the fall of E
    over the step), exponentially small: a series of order N does not see a fall of E much
    beyond N, although the function then changes by exp(D) of its size, and near v = 0 by
    all of it (a friction force that turns over unseen). So E may fall over the step by at
    most HIDDEN_FALL below min(E_0, SATURATED): h' is the first sigma where it would, h
    where it does not, or where E_0 is already within HIDDEN_FALL of 0 (the function is not
    saturated: its poles show in its coefficients). Jorba & Zou's rule assumes coefficients
    that decay with the radius of convergence (doi:10.1080/10586458.2005.10128904); an
    entire function's do not. The fall is checked at REACH_SAMPLES points of the step (a
    change of the sign of v between two of them counts: |v| passed 0), the first crossing
    then bisected; a dip of |v| that turns back between two points is not seen.
    """
    v0 = V[0]
    floor = min(_exponent(v0, scale, power), SATURATED) - HIDDEN_FALL
    if not floor > 0.0:
        return h
    lo = 0.0
    for j in range(1, REACH_SAMPLES + 1):
        hi = h * j / REACH_SAMPLES
        if _below_floor(V, hi, scale, power, floor, v0):
            # a crossing lies in [lo, hi]: bisected to 2^-30 of the interval (the reach
            # needs no more; E >= floor at lo)
            for _ in range(30):
                mid = 0.5 * (lo + hi)
                if _below_floor(V, mid, scale, power, floor, v0):
                    hi = mid
                else:
                    lo = mid
            return lo
        lo = hi
    return h
