"""Post-processing of simulated runs: impacts, energy, restitution, regimes, nonlinear dynamics.

Nothing here reaches back into the integrator: every function takes a scenario (and runs
:func:`braidsim.simulate`) or a :class:`braidsim.Result`.

========================  ===============================================================
module                    what it gives
========================  ===============================================================
:mod:`.restitution`       effective restitution of each law against nominal c_r
:mod:`.impacts`           impact statistics and the energy balance of a run
:mod:`.regimes`           steady states, regime classification, contact-loss bound
:mod:`.bifurcation`       stroboscopic bifurcation diagrams, locating transitions
:mod:`.basins`            basins of attraction over a grid of starts
:mod:`.lyapunov`          largest Lyapunov exponent (two-trajectory method)
:mod:`.spectra`           amplitude spectra, dominant frequencies, harmonics
:mod:`.report`            all of the above for one run (``braidsim analyze``)
:mod:`.reference`         textbook systems that check the methods (logistic, Lorenz)
:mod:`.plots`             figures
========================  ===============================================================
"""

from braidsim.analysis.basins import BasinMap, basins
from braidsim.analysis.bifurcation import (
    BifurcationDiagram,
    bifurcation,
    locate_transition,
    refine_transition,
)
from braidsim.analysis.impacts import (
    EnergyBalance,
    ImpactStatistics,
    energy_balance,
    impact_statistics,
)
from braidsim.analysis.lyapunov import (
    CarrierLyapunov,
    LyapunovEstimate,
    benettin,
    carrier_lyapunov,
)
from braidsim.analysis.regimes import (
    REGIME_LABELS,
    Regime,
    SteadyState,
    classify,
    contact_loss_bound,
    detect_period,
    steady_state,
)
from braidsim.analysis.report import RunAnalysis, analyze
from braidsim.analysis.restitution import RestitutionTable, restitution_table
from braidsim.analysis.spectra import Spectrum, amplitude_spectrum, run_spectra

__all__ = [
    "REGIME_LABELS",
    "BasinMap",
    "BifurcationDiagram",
    "CarrierLyapunov",
    "EnergyBalance",
    "ImpactStatistics",
    "LyapunovEstimate",
    "Regime",
    "RestitutionTable",
    "RunAnalysis",
    "Spectrum",
    "SteadyState",
    "amplitude_spectrum",
    "analyze",
    "basins",
    "benettin",
    "bifurcation",
    "carrier_lyapunov",
    "classify",
    "contact_loss_bound",
    "detect_period",
    "energy_balance",
    "impact_statistics",
    "locate_transition",
    "refine_transition",
    "restitution_table",
    "run_spectra",
    "steady_state",
]
