"""Shared test fixtures."""

from __future__ import annotations

import os

import matplotlib

# Figures render off-screen in tests.
matplotlib.use("Agg")
os.environ.setdefault("MPLBACKEND", "Agg")
