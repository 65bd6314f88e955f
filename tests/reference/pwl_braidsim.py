"""braidsim's side of the piecewise-linear impact oscillator comparisons: the compiled
core's :class:`~braidsim.core.ImpactOscillator` with a Kelvin-Voigt wall that may pull,
built from the reference's :class:`~reference.pwl_oscillator.PWLParams` (one place for the
tests of the core, the sensitivities and continuation).

``reference.pwl_oscillator`` itself imports nothing from braidsim (it is the independent
side); this module joins the two.
"""

from __future__ import annotations

import math
from typing import Any

from braidsim.core import ImpactOscillator, KelvinVoigtContact


def braidsim_oscillator(p: Any) -> ImpactOscillator:
    """``ImpactOscillator(m, k, c, F, Omega, phi, gap_inner=inf, gap_outer=gap,
    KelvinVoigtContact(k_c, c_c, allow_tension=True))`` of the reference's parameters."""
    law = KelvinVoigtContact(p.contact_stiffness, p.contact_damping, allow_tension=True)
    return ImpactOscillator(
        p.mass,
        p.stiffness,
        p.damping,
        p.force_amplitude,
        p.force_frequency,
        p.force_phase,
        math.inf,
        p.gap,
        law,
    )


def oscillator_system(p: Any) -> Any:
    """The oscillator as a continuation system (length scale: the gap)."""
    from braidsim.continuation import ModelSystem

    return ModelSystem(braidsim_oscillator(p), length_scale=p.gap, name="pwl")
