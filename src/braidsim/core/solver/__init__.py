"""The event-exact solver of the compiled core, generic over models.

- :mod:`~braidsim.core.solver.dopri5`: the Dormand-Prince 5(4) step, its error estimate and
  its continuous extension;
- :mod:`~braidsim.core.solver.events`: contact onset and exit located on the interpolant;
- :mod:`~braidsim.core.solver.recorders`: what a run writes (series rows, window ranges,
  extremes, the impact table);
- :mod:`~braidsim.core.solver.loop`: the step loop, resumable at any accepted step.
"""
