"""Design studies: make the paper's recommendations computable.

The paper ends with advice (section 4): slow the horn gears before a transfer and speed them
up after, use contact surfaces with a higher restitution, reduce the track vibration. This
package turns it into numbers on the whole machine (:mod:`braidsim.machine`):

* :mod:`~braidsim.design.profiles`: periodic horn-gear speed profiles over the transfer cycle
  (a smooth dip, harmonics, both) with the mean speed held exactly, and the drive's limits
  (speed range, angular acceleration, jerk);
* :mod:`~braidsim.design.evaluate`: a candidate's machine run on the two-DOF carrier model
  reduced to the figures of both contacts, track and slot (peak force, impact energy per
  second, impacts per second, a noise proxy), identical carriers run once;
* :mod:`~braidsim.design.drive`: the drive's inertia (gears, carriers, motor), the torque,
  power and yarn-tension swing of a profile, the motor's limits;
* :mod:`~braidsim.design.robust`: tolerance samples, the robust objective, the improvement
  distribution on held-out samples, the levers compared on the same samples;
* :mod:`~braidsim.design.optimise`: seeded differential evolution with the motion and drive
  limits as constraints;
* :mod:`~braidsim.design.sensitivity`: one-at-a-time swings and Morris elementary effects of
  the other levers (clearance, restitution, vibration amplitude and frequency, mass, tension);
* :mod:`~braidsim.design.speed_limits`: the speed at which transfers hit a force limit
  (simulated and closed form) and the chatter speed of docs/model.md §7;
* :mod:`~braidsim.design.spec`, :mod:`~braidsim.design.study`, :mod:`~braidsim.design.report`:
  ``braidsim design SPEC.toml --out DIR``.

Example::

    from braidsim.design import load_design_spec, run_design, write_report
    spec = load_design_spec("examples/design16.toml")
    res = run_design(spec, progress=print)
    res.robust.stats(), res.drive_after, res.optimisation.profile.params
    write_report(res, "design16")
"""

from braidsim.design.drive import Drive, DriveModel
from braidsim.design.evaluate import OBJECTIVES, evaluate, machine_for, objective_ratio
from braidsim.design.optimise import OptimizerOptions, optimise_profile
from braidsim.design.profiles import Limits, ProfileFamily, SpeedProfile, limit_margins
from braidsim.design.report import write_report
from braidsim.design.robust import (
    LeverMove,
    RobustObjective,
    RobustOptions,
    Tolerance,
    compare_levers,
    draw_samples,
    improvement,
)
from braidsim.design.sensitivity import Lever, make_levers, morris, one_at_a_time
from braidsim.design.spec import DesignSpec, load_design_spec, parse_design_spec
from braidsim.design.speed_limits import (
    chatter_speed,
    first_impact_speed,
    transfer_speed_estimate,
    transfer_speed_limit,
)
from braidsim.design.study import DesignResult, run_design

__all__ = [
    "OBJECTIVES",
    "DesignResult",
    "DesignSpec",
    "Drive",
    "DriveModel",
    "Lever",
    "LeverMove",
    "Limits",
    "OptimizerOptions",
    "ProfileFamily",
    "RobustObjective",
    "RobustOptions",
    "SpeedProfile",
    "Tolerance",
    "chatter_speed",
    "compare_levers",
    "draw_samples",
    "evaluate",
    "first_impact_speed",
    "improvement",
    "limit_margins",
    "load_design_spec",
    "machine_for",
    "make_levers",
    "morris",
    "objective_ratio",
    "one_at_a_time",
    "optimise_profile",
    "parse_design_spec",
    "run_design",
    "transfer_speed_estimate",
    "transfer_speed_limit",
    "write_report",
]
