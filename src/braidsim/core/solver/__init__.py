"""The event-exact solver of the compiled core, generic over models.

- :mod:`~braidsim.core.solver.dopri5`: the Dormand-Prince 5(4) step, its error estimate and
  its continuous extension;
- :mod:`~braidsim.core.solver.events`: contact onset and exit located on the interpolant;
- :mod:`~braidsim.core.solver.recorders`: what a run writes (series rows, window ranges,
  extremes, the impact table);
- :mod:`~braidsim.core.solver.pairs`: each contact pair's summary at an instant (depth,
  rates, forces), shared by the events, extremes and recorders;
- :mod:`~braidsim.core.solver.radau`: the L-stable Radau IIA step for contacts at rest
  (compiled only when asked);
- :mod:`~braidsim.core.solver.tangent`: forward sensitivities through steps, impacts and
  transfers (compiled only when asked);
- :mod:`~braidsim.core.solver.calls`: the model functions the loop calls rather than inlines;
- :mod:`~braidsim.core.solver.loop`: the step loop, resumable at any accepted step.
"""
