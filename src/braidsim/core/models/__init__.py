"""Models of the compiled core: equations of motion over coordinates with contact pairs.

Each model is a record class (a ``NamedTuple`` of numbers, arrays and physics records) with
its implementations of the model functions of :mod:`braidsim.core.interfaces`; its series
columns and energy quadratures are named by
:func:`~braidsim.core.interfaces.describe_model`. The solver (:mod:`braidsim.core.solver`)
is compiled once per model class, with no copy of its code.
"""

from braidsim.core.models.carrier import CARRIER_COLUMNS, CarrierX, CarrierXY
from braidsim.core.models.oscillator import ImpactOscillator

__all__ = ["CARRIER_COLUMNS", "CarrierX", "CarrierXY", "ImpactOscillator"]
