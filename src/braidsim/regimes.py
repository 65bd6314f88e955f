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
