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

import importlib as _importlib
import sys as _sys
import types as _types
import typing as _typing

from braidsim.errors import BraidsimError, InputError, SimulationError

if _typing.TYPE_CHECKING:
    from braidsim.contact import effective_restitution, get_law, law_names
    from braidsim.model import Model, build_model
    from braidsim.params import SCHEMA, Scenario, builtin_names, load_scenario
    from braidsim.result import Result
    from braidsim.simulate import simulate

# The public names are imported on first use (PEP 562), so that ``import braidsim`` and the
# command line's start do not pay for numba, pint and the compiled core until a verb needs
# them: name -> the module that defines it.
_LAZY = {
    "SCHEMA": "braidsim.params",
    "Scenario": "braidsim.params",
    "builtin_names": "braidsim.params",
    "load_scenario": "braidsim.params",
    "effective_restitution": "braidsim.contact",
    "get_law": "braidsim.contact",
    "law_names": "braidsim.contact",
    "Model": "braidsim.model",
    "build_model": "braidsim.model",
    "Result": "braidsim.result",
    "simulate": "braidsim.simulate",
}


def __getattr__(name: str) -> _typing.Any:
    """A public name (imported from its module on first use) or a submodule."""
    if name in _LAZY:
        value = getattr(_importlib.import_module(_LAZY[name]), name)
    elif not name.startswith("__"):
        try:
            value = _importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise  # a submodule that exists but fails to import says why
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({k for k in globals() if not k.startswith("_")} | set(__all__))


class _Package(_types.ModuleType):
    """The package's module type. Importing a submodule binds it to an attribute of its
    package; the submodule ``braidsim.simulate`` has the name of the public function
    :func:`braidsim.simulate`, which must keep that name whichever is imported first."""

    def __setattr__(self, name: str, value: _typing.Any) -> None:
        if name == "simulate" and isinstance(value, _types.ModuleType):
            value = value.simulate
        super().__setattr__(name, value)


_sys.modules[__name__].__class__ = _Package

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
