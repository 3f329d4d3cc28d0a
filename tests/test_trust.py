"""Trust: each reason is raised by the fact it names, and only by it."""

from __future__ import annotations

from dataclasses import replace

import pytest

from volec.trust import REASONS, TrustConfig, TrustFacts, assess, reason_descriptions

GOOD = TrustFacts(frames=100, registered=100, orbit_coverage_deg=355.0, support_found=True,
                  carved_fraction=0.05, dropped_volume_ml=0.0, volume_ml=250.0,
                  completion_share=0.1, scale_estimates=(0.010, 0.0101, 0.00995),
                  unusable_masks=0, far_point_fraction=0.0)

#: reason code -> a change of GOOD's facts that must raise it
TRIGGERS = {
    "no_support_plane": {"support_found": False},
    "narrow_orbit": {"orbit_coverage_deg": 120.0},
    "few_registered_frames": {"registered": 70},
    "large_carving": {"carved_fraction": 0.4},
    "pieces_dropped": {"dropped_volume_ml": 30.0},
    "completion_dominates": {"completion_share": 0.4},
    "scale_disagreement": {"scale_estimates": (0.010, 0.0104, 0.010)},
    "implausible_volume": {"volume_ml": 25000.0},
    "unusable_masks": {"unusable_masks": 9},
    "far_points": {"far_point_fraction": 0.05},
    "unknown_space": {"unknown_share": 0.4},
}


def test_good_facts_are_trusted():
    assert assess(GOOD) == []
    assert assess(replace(GOOD, completion_share=None)) == []  # no completion: nothing to say
    assert assess(replace(GOOD, unknown_share=0.1)) == []


@pytest.mark.parametrize("code", sorted(TRIGGERS))
def test_each_reason_is_raised_by_its_fact_alone(code):
    reasons = assess(replace(GOOD, **TRIGGERS[code]))
    assert [r.code for r in reasons] == [code]
    assert reasons[0].message


def test_every_documented_reason_has_a_trigger_and_a_description():
    assert set(TRIGGERS) == set(REASONS)
    descriptions = reason_descriptions(TrustConfig(min_orbit_deg=200.0))
    assert "200 degrees" in descriptions["narrow_orbit"]
    assert "{" not in "".join(descriptions.values())


def test_thresholds_are_the_configs():
    just_below = replace(GOOD, carved_fraction=0.24)
    assert assess(just_below) == []
    assert [r.code for r in assess(just_below, TrustConfig(max_carved_fraction=0.2))] == [
        "large_carving"]
    tiny = replace(GOOD, volume_ml=1.0)
    assert [r.code for r in assess(tiny)] == ["implausible_volume"]
