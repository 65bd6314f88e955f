"""Physics of the compiled core: contact laws, friction laws and excitations, each a record
class with its implementations of the generic functions of :mod:`braidsim.core.interfaces`.

Importing this package imports every module in it, which registers every law and excitation:
a new law is one new file here (its record class and its implementations), nothing else.
"""

import importlib
import pkgutil

from braidsim.core.physics.contact_laws import PowerLawContact
from braidsim.core.physics.coulomb_viscous import CoulombViscousFriction
from braidsim.core.physics.excitation import HornGear, TrackHarmonics
from braidsim.core.physics.friction import RegularizedFriction
from braidsim.core.physics.kelvin_voigt import KelvinVoigtContact
from braidsim.core.physics.measured_track import MeasuredTrack

for _module in pkgutil.iter_modules(__path__):
    importlib.import_module(f"{__name__}.{_module.name}")

__all__ = [
    "CoulombViscousFriction",
    "HornGear",
    "KelvinVoigtContact",
    "MeasuredTrack",
    "PowerLawContact",
    "RegularizedFriction",
    "TrackHarmonics",
]
