"""Exceptions of braidsim.

Three kinds of failure reach a user, and the command line maps them to exit codes:

* :class:`InputError` (exit code 2): the input is wrong. The message is one line that
  names the parameter and the allowed range or the closest known name.
* :class:`SimulationError` (exit code 1): the numbers went wrong. The message says what
  failed, at what simulated time, and what to change.
* :class:`StoreError` (exit code 1): stored data cannot be read back as written (a checksum
  fails, a file is damaged). The message names the path and how to recover.
"""

from __future__ import annotations


class BraidsimError(Exception):
    """Base class of every error braidsim raises on purpose."""


class InputError(BraidsimError, ValueError):
    """Bad input: unknown key, wrong unit, value out of range, malformed file.

    The message is kept to one line: line breaks and tabs that a quoted user value brings in
    are turned into spaces.
    """

    def __init__(self, message: object = "") -> None:
        text = str(message)
        if any(c in text for c in "\n\r\t\v\f"):
            text = " ".join(text.split())
        super().__init__(text)


class SimulationError(BraidsimError, RuntimeError):
    """A numerical failure of the integrator.

    Attributes
    ----------
    time : float
        Simulated time [s] at which the failure happened (NaN when unknown).
    """

    def __init__(self, message: str, time: float = float("nan")) -> None:
        super().__init__(message)
        self.time = time


class StoreError(BraidsimError, RuntimeError):
    """Stored data is damaged or unreadable (a checksum fails); the message names the path."""
