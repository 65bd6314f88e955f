"""The model's equations as one compiled call, for the places that evaluate them rarely (at
events, transfers, and in the implicit step of resting contacts). Everywhere else the solver
inlines them (:func:`~braidsim.core.solver.dopri5.rk_step`); each inlined copy is compiled
anew, and a call compiles the model's code once for all these places."""

from __future__ import annotations

from braidsim.core.generic import helper
from braidsim.core.interfaces import derivatives


@helper
def rhs(model, t, y, modes, v0s, n, out):
    """:func:`~braidsim.core.interfaces.derivatives` as a call."""
    derivatives(model, t, y, modes, v0s, n, out)
