"""The whole braiding machine: horn gears on a ring, carrier paths, transfers, every carrier.

The paper studies one carrier on one horn gear and one transfer. This package builds the
machine around that model:

* :mod:`~braidsim.machine.geometry`: N horn gears with S slots on a ring, the two
  counter-travelling carrier paths (alternating inner and outer arcs, switching at the tangency
  points), lanes, loading patterns (full, 1/1 diamond, 2/2 regular, 3/3 Hercules) and the exact
  collision check;
* :mod:`~braidsim.machine.kinematics`: the horn-gear rotation and its inverse (transfer times),
  the speed profile over the transfer cycle with the mean speed held, carrier speed, braid
  angle, production rate;
* :mod:`~braidsim.machine.spec`: the TOML machine specification;
* :mod:`~braidsim.machine.run`: every carrier through its own transfers, reduced per transfer
  and per carrier, machine totals;
* :mod:`~braidsim.machine.report` and :mod:`~braidsim.machine.animation`: tables, figures and
  the GIF (``braidsim machine SPEC.toml --out DIR``).

Example::

    from braidsim.machine import load_machine_spec, run_machine, write_report
    spec = load_machine_spec("examples/machine16.toml")
    run = run_machine(spec, duration=0.5)
    run.totals["impacts_per_second"], run.transfers.head()
    write_report(run, "machine16")
"""

from braidsim.machine.geometry import (
    Loading,
    MachineGeometry,
    braid_pattern,
    check_collisions,
    custom_loading,
    find_collisions,
    interlacing,
    loading_pattern,
)
from braidsim.machine.kinematics import SpeedLaw, braid_angle, carrier_angular_speed, cycle_profile
from braidsim.machine.report import summary, write_report
from braidsim.machine.run import MachineRun, plan_transfers, run_machine
from braidsim.machine.spec import MachineSpec, load_machine_spec, parse_machine_spec

__all__ = [
    "Loading",
    "MachineGeometry",
    "MachineRun",
    "MachineSpec",
    "SpeedLaw",
    "braid_angle",
    "braid_pattern",
    "carrier_angular_speed",
    "check_collisions",
    "custom_loading",
    "cycle_profile",
    "find_collisions",
    "interlacing",
    "load_machine_spec",
    "loading_pattern",
    "parse_machine_spec",
    "plan_transfers",
    "run_machine",
    "summary",
    "write_report",
]
