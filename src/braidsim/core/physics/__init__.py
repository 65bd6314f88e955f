"""Physics of the compiled core: contact laws, friction laws and excitations, each a record
class with its implementations of the generic functions of :mod:`braidsim.core.interfaces`.

Importing this package registers every built-in law and excitation.
"""

from braidsim.core.physics.contact_laws import PowerLawContact
from braidsim.core.physics.excitation import HornGear, TrackHarmonics
from braidsim.core.physics.friction import RegularizedFriction

__all__ = ["HornGear", "PowerLawContact", "RegularizedFriction", "TrackHarmonics"]
