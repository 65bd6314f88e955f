"""Integrators: the compiled Dormand-Prince kernel and the SciPy reference backend."""
