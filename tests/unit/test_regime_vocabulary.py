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


def test_window_contacts_is_the_one_reduction_of_a_window() -> None:
    """The batch metrics and the steady-state regime read a window through one function:
    onsets per wall (rows present at the start are none), the largest approach speed, the
    part of the window in contact, the longest contact that overlaps it for a positive
    time (one that ends exactly at its start does not, nor a zero-length row)."""
    import numpy as np

    from braidsim.core.layout import EPISODE_DTYPE
    from braidsim.regimes import window_contacts

    rows = [  # (t, t_end, pair, wall, initial, velocity)
        (0.0, 1.0, 0, -1, 1.0, 0.0),  # present at the start: no onset; ends at t0
        (1.5, 1.75, 0, -1, 0.0, 0.3),  # inner onset, inside
        (1.8, 1.8, 0, 1, 0.0, 0.9),  # outer onset of zero length
        (2.9, 3.5, 0, 1, 0.0, 0.5),  # outer onset, runs past t1
        (1.2, 1.4, 1, 1, 0.0, 0.1),  # slot, front wall
        (3.2, 3.3, 0, -1, 0.0, 2.0),  # after the window
    ]
    EP = np.zeros(len(rows), dtype=EPISODE_DTYPE)
    for i, (t, te, pair, wall, initial, v) in enumerate(rows):
        EP[i]["t"], EP[i]["t_end"], EP[i]["pair"], EP[i]["wall"] = t, te, pair, wall
        EP[i]["initial"], EP[i]["velocity"] = initial, v
    wc = window_contacts(EP, 1.0, 3.0)
    assert wc.onsets.tolist() == [[1, 2], [0, 1]]
    assert wc.max_approach_speed.tolist() == [0.9, 0.1]
    assert wc.contact_fraction.tolist() == pytest.approx([(0.25 + 0.1) / 2.0, 0.2 / 2.0])
    assert wc.longest_contact.tolist() == pytest.approx([0.6, 0.2])
    assert wc.track_pattern == 3  # two_sided_impacts
    quiet = window_contacts(EP[:1], 1.0, 3.0)  # a contact that ends at t0: no contact
    assert quiet.track_pattern == 0 and quiet.longest_contact[0] == 0.0
