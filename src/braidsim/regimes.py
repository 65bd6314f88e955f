"""The regime vocabulary of braidsim: one set of names for every path that reports one.

Two levels, the second refining the first:

* The **contact pattern** of a time window is what the impact table alone decides, so it is
  cheap enough for every run of a batch or a sweep (the ``regime`` metric of
  :mod:`braidsim.batch`)::

      no_contact          no track contact overlaps the window
      resting_contact     track contact, but no contact onset in the window
      one_sided_impacts   onsets on one track wall only
      two_sided_impacts   onsets on both track walls

* The **steady-state regime** (:mod:`braidsim.analysis.regimes`) adds what the stroboscopic
  samples and the contact durations tell: the impacting patterns are split into
  ``periodic_one_sided``, ``periodic_two_sided``, ``chattering`` and ``irregular``.
  ``no_contact`` and ``resting_contact`` are the same names with the same rules on both
  levels, and :func:`pattern_of` maps every steady-state regime back to its contact pattern.

A run that failed numerically is ``failed`` on both levels (code -1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CONTACT_PATTERNS = ("no_contact", "resting_contact", "one_sided_impacts", "two_sided_impacts")
"""Contact patterns of a window; the index is the code stored in batches and sweeps."""
FAILED = -1
"""Code of a run that failed numerically (label ``failed``)."""

STEADY_REGIMES = (
    "no_contact",
    "resting_contact",
    "periodic_one_sided",
    "periodic_two_sided",
    "chattering",
    "irregular",
)
"""Steady-state regimes (rules in :mod:`braidsim.analysis.regimes`)."""


def contact_pattern(contacts: bool, inner_impacts: int, outer_impacts: int) -> int:
    """Code (index into :data:`CONTACT_PATTERNS`) of a window with or without a track
    contact overlapping it and with these numbers of contact onsets on each track wall."""
    if inner_impacts and outer_impacts:
        return 3
    if inner_impacts or outer_impacts:
        return 2
    return 1 if contacts else 0


def pattern_of(regime: str, walls: str) -> str:
    """The contact pattern a steady-state regime refines (``walls``: the track walls hit in
    the window, ``none``, ``inner``, ``outer`` or ``both``)."""
    if regime == "failed":
        return "failed"
    if regime in ("no_contact", "resting_contact"):
        return regime
    if regime not in STEADY_REGIMES:
        raise ValueError(f"regime: {regime!r} is not one of {', '.join(STEADY_REGIMES)}")
    return "two_sided_impacts" if walls == "both" else "one_sided_impacts"


@dataclass(frozen=True)
class WindowContacts:
    """What a run's impact table says of a time window [t0, t1], per pair (0: the track,
    1: the slot); the one reduction behind the batch metrics and the steady-state regime.

    Attributes
    ----------
    onsets : np.ndarray
        (2, 2) contact onsets in the window (``initial`` rows, present at the start, are
        not onsets), per pair and wall: inner and outer for the track, rear and front for
        the slot.
    max_approach_speed : np.ndarray
        (2,) the largest approach speed of those onsets [m/s]; 0 without any.
    contact_fraction : np.ndarray
        (2,) the part of the window spent in contact, sum(overlap) / (t1 - t0).
    longest_contact : np.ndarray
        (2,) the longest whole contact that overlaps the window for a positive time [s]; 0
        without any.
    """

    onsets: np.ndarray
    max_approach_speed: np.ndarray
    contact_fraction: np.ndarray
    longest_contact: np.ndarray

    @property
    def track_pattern(self) -> int:
        """:func:`contact_pattern` of the track: in contact when a contact overlaps the
        window for a positive time."""
        return contact_pattern(
            bool(self.contact_fraction[0] > 0.0), int(self.onsets[0, 0]), int(self.onsets[0, 1])
        )


def window_contacts(episodes: np.ndarray, t0: float, t1: float) -> WindowContacts:
    """:class:`WindowContacts` of the impact table ``episodes`` (the core's episode rows;
    a contact still open at the run's end is closed there by the driver) over [t0, t1]."""
    t_on = episodes["t"]
    t_off = episodes["t_end"]
    pair = episodes["pair"]
    wall = episodes["wall"]
    onset = (episodes["initial"] == 0.0) & (t_on >= t0) & (t_on <= t1)
    inside = np.clip(np.minimum(t_off, t1) - np.maximum(t_on, t0), 0.0, None)
    onsets = np.zeros((2, 2), dtype=np.int64)
    vmax = np.zeros(2)
    fraction = np.zeros(2)
    longest = np.zeros(2)
    for ip in range(2):
        mine = pair == ip
        for k, side in enumerate((-1.0, 1.0)):
            onsets[ip, k] = np.count_nonzero(onset & mine & (wall == side))
        v = episodes["velocity"][onset & mine]
        vmax[ip] = float(v.max()) if v.size else 0.0
        fraction[ip] = float(inside[mine].sum()) / (t1 - t0)
        over = mine & (inside > 0.0)
        longest[ip] = float((t_off - t_on)[over].max()) if over.any() else 0.0
    return WindowContacts(onsets, vmax, fraction, longest)
