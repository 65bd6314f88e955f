"""Resource limits checked before any work starts, each raisable by the user.

A typo in a spec (``num = 1000000000``), a huge ``--points`` or a series of every run can ask
for more runs, memory or disk than a machine has; braidsim then refuses up front with an
estimate instead of running for hours or growing until the out-of-memory killer strikes.
Each limit has a default that suits a workstation and an environment variable that raises
it (for example ``BRAIDSIM_MAX_RUNS=100000000``). The values below are defaults, not
physics.
"""

from __future__ import annotations

import os
from collections.abc import Callable

from braidsim.errors import InputError

#: name -> (default, unit, what it bounds)
DEFAULTS: dict[str, tuple[float, str, str]] = {
    "runs": (10_000_000, "runs", "simulations of one command (sweep, restitution, grids)"),
    "values": (1_000_000, "values", "values of one sweep axis or samples of a sweep"),
    "series_points": (1_000_000, "times", "sample times of a sweep's stored series"),
    "bytes": (50e9, "bytes", "size of a sweep store on disk"),
    "memory": (4e9, "bytes", "memory of one chunk of work or of an animation"),
    "frames": (10_000, "frames", "frames of an animation"),
    "transfers": (1_000_000, "transfers", "transfer times of one run (transfer.period)"),
    "steps": (1e9, "steps", "least integration steps of one run (duration / max_step)"),
}


def env_name(name: str) -> str:
    """The environment variable that raises limit ``name``."""
    return f"BRAIDSIM_MAX_{name.upper()}"


def limit(name: str) -> float:
    """The current value of limit ``name`` (its environment variable, else the default)."""
    default = DEFAULTS[name][0]
    text = os.environ.get(env_name(name))
    if text is None or not text.strip():
        return float(default)
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0:
        raise InputError(f"{env_name(name)}: {text!r} is not allowed; allowed a number > 0")
    return value


def check(name: str, amount: float, what: str | Callable[[], str]) -> None:
    """Raise an :class:`InputError` when ``amount`` exceeds limit ``name``.

    The message gives the estimate, the limit and the variable that raises it. ``what``
    names the estimate: a string, or a function that makes it (called only for the
    message: a run checks its limits on every call).
    """
    cap = limit(name)
    if amount > cap:
        unit = DEFAULTS[name][1]
        if callable(what):
            what = what()
        shown, limit_shown = _two_numbers(amount, cap)
        raise InputError(
            f"{what}: {shown} {unit} exceeds the limit of {limit_shown} {unit}; "
            f"reduce it, or raise the limit with {env_name(name)}=N"
        )


def _two_numbers(amount: float, cap: float) -> tuple[str, str]:
    """``amount`` and ``cap`` with four significant digits, or as many more as it takes to
    tell them apart (10001 over 10000 read "1e+04 exceeds the limit of 1e+04")."""
    for digits in range(4, 18):
        a, c = f"{amount:.{digits}g}", f"{cap:.{digits}g}"
        if a != c:
            break
    return a, c
