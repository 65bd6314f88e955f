"""braidsim: carrier-track contact dynamics of maypole (horn-gear) braiding machines.

The public API is small::

    import braidsim
    sc = braidsim.load_scenario("paper-3.1", overrides={"track.clearance": "2 mm"})
    res = braidsim.simulate(sc, duration=0.5)
    res.summary()      # the dict of `braidsim run --json`
    res.impacts        # impact table (pandas DataFrame)
    res.to_xarray()    # time series with units in attrs

Data path: scenario (TOML, units) -> :mod:`braidsim.params` (validated SI) ->
:mod:`braidsim.model` (the core's records) -> :mod:`braidsim.core` (compiled physics and an
event-exact solver generic over models) -> :class:`braidsim.result.Result` -> analysis,
plots, reports.
"""

from braidsim.contact import effective_restitution, get_law, law_names
from braidsim.errors import BraidsimError, InputError, SimulationError
from braidsim.model import Model, build_model
from braidsim.params import SCHEMA, Scenario, builtin_names, load_scenario
from braidsim.result import Result
from braidsim.simulate import simulate

__version__ = "0.1.0"

__all__ = [
    "SCHEMA",
    "BraidsimError",
    "InputError",
    "Model",
    "Result",
    "Scenario",
    "SimulationError",
    "__version__",
    "build_model",
    "builtin_names",
    "effective_restitution",
    "get_law",
    "law_names",
    "load_scenario",
    "simulate",
]
