"""The compiled core of braidsim: physics apart from a solver generic over models.

The data path::

    model record (physics records inside)  +  SolverOptions
        -> braidsim.core.driver.run()  (buffers, flushing)
            -> braidsim.core.solver.loop.integrate()  (compiled, resumable)
        -> RawRun (series rows, impact table, ranges, statistics, restart record)

- :mod:`~braidsim.core.layout`: the named records at the boundary (options, impact rows,
  statistics, restart state, codes);
- :mod:`~braidsim.core.generic`: how one compiled function serves many record types;
- :mod:`~braidsim.core.interfaces`: the generic functions a law, an excitation or a model
  provides;
- :mod:`~braidsim.core.physics`: contact laws, friction laws, excitations;
- :mod:`~braidsim.core.models`: the carrier (x or xy) and a 1-DOF impact oscillator;
- :mod:`~braidsim.core.solver`: the event-exact Dormand-Prince solver;
- :mod:`~braidsim.core.driver`: the driver.

This package is the only way into the compiled code: the rest of braidsim imports from
here (``braidsim.core`` and its public modules), never from ``braidsim.core.solver``.
"""

from braidsim import startup
from braidsim.core import layout
from braidsim.core.driver import RawRun, SeriesOverflow, model_sizes, run, state_size
from braidsim.core.interfaces import (
    apply_transfer,
    derivatives,
    pair_gaps,
    pair_law,
    quadrature_names,
    series_columns,
    wall_motion,
)
from braidsim.core.models import CARRIER_COLUMNS, CarrierX, CarrierXY, ImpactOscillator
from braidsim.core.physics import (
    CoulombViscousFriction,
    HornGear,
    KelvinVoigtContact,
    MeasuredTrack,
    PowerLawContact,
    RegularizedFriction,
    TrackHarmonics,
)
from braidsim.core.physics.excitation import horn_gear_state
from braidsim.core.solver.pairs import contact_quantities, gaps_along

# A process that runs braidsim alone (the command line) loads cached functions without
# numba's registries (braidsim.startup); nothing above calls a compiled function.
if startup.LIGHT_CACHE_LOADS:
    startup.load_cached_functions_without_refresh()

__all__ = [
    "CARRIER_COLUMNS",
    "CarrierX",
    "CarrierXY",
    "CoulombViscousFriction",
    "HornGear",
    "ImpactOscillator",
    "KelvinVoigtContact",
    "MeasuredTrack",
    "PowerLawContact",
    "RawRun",
    "RegularizedFriction",
    "SeriesOverflow",
    "TrackHarmonics",
    "apply_transfer",
    "contact_quantities",
    "derivatives",
    "gaps_along",
    "horn_gear_state",
    "layout",
    "model_sizes",
    "pair_gaps",
    "pair_law",
    "quadrature_names",
    "run",
    "series_columns",
    "state_size",
    "wall_motion",
]
