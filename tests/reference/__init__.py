"""Independent references for the tests: closed forms written without braidsim's solver.

Nothing in this package imports :mod:`braidsim`; the tests compare braidsim with it. Import
it as ``reference`` (pytest puts the ``tests`` folder on ``sys.path``), e.g.
``from reference.pwl_oscillator import periodic_orbit``.
"""
