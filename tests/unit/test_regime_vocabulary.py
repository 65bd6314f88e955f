"""The one regime vocabulary: contact patterns and the steady-state regimes that refine them."""

from __future__ import annotations

import pytest

from braidsim.analysis.regimes import REGIME_LABELS, classify
from braidsim.batch import REGIMES
from braidsim.regimes import CONTACT_PATTERNS, STEADY_REGIMES, contact_pattern, pattern_of


def test_batches_and_analyses_use_the_module_names() -> None:
    assert REGIMES == CONTACT_PATTERNS
    assert REGIME_LABELS == STEADY_REGIMES


@pytest.mark.parametrize(
    ("contacts", "inner", "outer", "pattern"),
    [
        (False, 0, 0, "no_contact"),
        (True, 0, 0, "resting_contact"),
        (True, 3, 0, "one_sided_impacts"),
        (True, 0, 2, "one_sided_impacts"),
        (True, 1, 4, "two_sided_impacts"),
    ],
)
def test_a_classified_window_refines_its_contact_pattern(
    contacts: bool, inner: int, outer: int, pattern: str
) -> None:
    import numpy as np

    assert CONTACT_PATTERNS[contact_pattern(contacts, inner, outer)] == pattern
    # a period-1 strobe (rule 4) or a long contact (rule 3): the label refines the pattern
    strobe = np.tile([[1e-5, 2e-6]], (20, 1))
    for longest in (1e-6, 1.0):
        regime = classify(
            contacts=contacts,
            inner_impacts=inner,
            outer_impacts=outer,
            longest_contact=longest,
            stick_time=1e-3,
            strobe=strobe,
            length_scale=1e-4,
            cycles=20.0,
        )
        assert regime.pattern == pattern
        assert regime.to_dict()["pattern"] == pattern


def test_pattern_of_every_regime() -> None:
    assert pattern_of("chattering", "inner") == "one_sided_impacts"
    assert pattern_of("irregular", "both") == "two_sided_impacts"
    assert pattern_of("periodic_two_sided", "both") == "two_sided_impacts"
    assert pattern_of("failed", "none") == "failed"
    with pytest.raises(ValueError, match="regime"):
        pattern_of("sliding", "inner")
