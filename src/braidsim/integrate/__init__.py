"""The SciPy reference backend (the compiled solver is :mod:`braidsim.core`)."""
