"""Provenance of every output: package version, date, resolved scenario and settings.

Every JSON object the command line prints carries ``"braidsim_version"``; every file written
(JSON, netCDF attributes, reports) carries the record of :func:`provenance`, so that an
output found later says which braidsim made it, when, from which scenario (every parameter
in SI, as resolved after ``extends`` and ``--set``) and with which options.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any


def version() -> str:
    """The installed braidsim version (``braidsim.__version__``)."""
    from braidsim import __version__

    return __version__


def utc_now() -> str:
    """The current UTC time, ISO 8601 to the second (``2026-01-31T12:00:00+00:00``)."""
    from datetime import UTC, datetime

    return datetime.now(UTC).isoformat(timespec="seconds")


def provenance(scenario: Any = None, settings: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """``{"braidsim_version", "created", "scenario", "parameters", "settings"}``.

    Parameters
    ----------
    scenario : Scenario, optional
        The resolved scenario: its name and every parameter (SI) are recorded.
    settings : mapping, optional
        The options the output was made with (durations, windows, grid sizes, ...), as the
        values actually used after defaults were applied.
    """
    out: dict[str, Any] = {"braidsim_version": version(), "created": utc_now()}
    if scenario is not None:
        out["scenario"] = scenario.name
        out["parameters"] = scenario.to_dict()
    if settings is not None:
        out["settings"] = dict(settings)
    return out
