"""A step's dense output: the state anywhere inside the step, for the events, the recorders
and the loop.

It is a polynomial in theta = (t - t0) / h of one of two kinds:

- the continuous extension of the Runge-Kutta step, 5 rows in the nested form of
  :func:`~braidsim.core.solver.dopri5.interpolant_component` (the implicit step writes its
  collocation polynomial in the same form): a plain array;
- in a loop compiled with the Taylor step, either that, the Taylor polynomial
  sum_k RT[k] theta^k of :mod:`braidsim.core.solver.taylor`, or an onset step's polynomial
  in s, sum_k RS[k] sqrt(theta)^k, told apart at run time: a :class:`StepPolynomial`.
  The loop makes it once, before its first step, and sets its flag at each step: a record
  of arrays made at every step cost numba's reference counting (an atomic increment and
  decrement of each array) at every step.

The readers below are chosen by the type of the dense output when their caller is compiled.
A loop compiled without the Taylor step passes a plain array and its readers hold the nested
form alone: with the test of the kind and the Horner loop in every reader, the loop of
paper-3.3 had 20 % more LLVM IR and 11 % more machine code (15,513 against 12,878 lines of
IR, 17,738 against 16,031 of assembly). (The cold start, 20-21 s of CPU, could not tell the
two apart on a shared 2-core machine: 19.2-22.0 against 16.5-22.5 s in three alternated
pairs.)
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import types

from braidsim.core.generic import inline_helper, overload_inlined, record_class
from braidsim.core.solver.dopri5 import interpolant_component, interpolant_deriv
from braidsim.core.solver.taylor import (
    onset_component,
    onset_deriv,
    taylor_component,
    taylor_deriv,
)


class StepPolynomial(NamedTuple):
    """The dense output of a step in a loop compiled with the Taylor step.

    Attributes
    ----------
    interpolant : array (5, n)
        The Runge-Kutta (or implicit) step's polynomial in the nested form.
    taylor : array (N + 1, n)
        The Taylor step's polynomial, RT[k, i] = C[i, k] h^k.
    is_taylor : array (1,) of int
        Which of them is the step's: ``is_taylor[0]`` 0 for the interpolant, 1 for the
        Taylor polynomial, 2 for the onset step's
        (:attr:`braidsim.core.layout.TaylorWork.kind`, which the loop sets at each step).
    onset : array (M + 1, n)
        The onset step's polynomial in s, RS[k, i] = C[i, k] S^k (read at sqrt(theta)).
    """

    interpolant: np.ndarray
    taylor: np.ndarray
    is_taylor: np.ndarray
    onset: np.ndarray


def _either_component(theta, RC, i):
    kind = RC.is_taylor[0]
    if kind == 1:
        return taylor_component(theta, RC.taylor, i)
    if kind == 2:
        return onset_component(theta, RC.onset, i)
    return interpolant_component(theta, RC.interpolant, i)


def _either_deriv(theta, h, RC, out, n):
    kind = RC.is_taylor[0]
    if kind == 1:
        taylor_deriv(theta, h, RC.taylor, out, n)
    elif kind == 2:
        onset_deriv(theta, h, RC.onset, out, n)
    else:
        interpolant_deriv(theta, h, RC.interpolant, out, n)


def dense_component(theta: float, RC: Any, i: int) -> float:
    """Component i of the state at fraction theta of the step whose dense output is RC."""
    if isinstance(RC, StepPolynomial):
        return _either_component(theta, RC, i)
    return interpolant_component(theta, RC, i)


def dense_deriv(theta: float, h: float, RC: Any, out: np.ndarray, n: int) -> None:
    """Time derivative of the dense output RC at theta for the first ``n`` components; it
    equals the step's derivative at both ends."""
    if isinstance(RC, StepPolynomial):
        _either_deriv(theta, h, RC, out, n)
    else:
        interpolant_deriv(theta, h, RC, out, n)


# the interpolant's readers are inline helpers, compiled once (core.generic.inline_helper):
# these one-line implementations call them, where handing numba their Python functions had
# their IR typed and lowered again at every call site


def _interpolant_component(theta, RC, i):
    return interpolant_component(theta, RC, i)


def _interpolant_deriv(theta, h, RC, out, n):
    interpolant_deriv(theta, h, RC, out, n)


def _component_typer(theta: Any, RC: Any, i: Any) -> Any:
    if isinstance(RC, types.Array):
        return _interpolant_component
    if record_class(RC) is StepPolynomial:
        return _either_component
    return None


def _deriv_typer(theta: Any, h: Any, RC: Any, out: Any, n: Any) -> Any:
    if isinstance(RC, types.Array):
        return _interpolant_deriv
    if record_class(RC) is StepPolynomial:
        return _either_deriv
    return None


def _either(RC, TAY):
    return StepPolynomial(RC, TAY.RT, TAY.kind, TAY.RS)


def step_output(RC: np.ndarray, TAY: Any) -> Any:
    """The dense output the loop hands to the readers: the interpolant RC itself where the
    Taylor step is compiled out (``TAY`` None), else ``StepPolynomial(RC, TAY.RT,
    TAY.kind, TAY.RS)``. (Chosen by the type of ``TAY``: numba prunes a test ``TAY is None`` only
    where ``TAY`` is None, so a branch in the loop would type both kinds in a loop with
    the Taylor step, and fail.)"""
    return RC if TAY is None else _either(RC, TAY)


def _interpolant_only(RC, TAY):
    return RC


def _output_typer(RC: Any, TAY: Any) -> Any:
    return _interpolant_only if isinstance(TAY, types.NoneType) else _either


overload_inlined(dense_component, _component_typer)
overload_inlined(dense_deriv, _deriv_typer)
overload_inlined(step_output, _output_typer)


@inline_helper
def dense_eval(theta, RC, out, n):
    """The state at fraction theta of the step whose dense output is RC."""
    for i in range(n):
        out[i] = dense_component(theta, RC, i)
