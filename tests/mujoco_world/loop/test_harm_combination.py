"""Harm over repeated contacts: per body 1 - prod(1 - h_i), per group an expected count."""

import math
from types import SimpleNamespace

import pytest

from mujoco_world.loop.metrics import combined_harm


def _record(a, b):
    """A collision between bodies a and b, each (entity, group, measured harm)."""
    return SimpleNamespace(
        measurement=SimpleNamespace(a=SimpleNamespace(entity=a[0]), b=SimpleNamespace(entity=b[0])),
        a=SimpleNamespace(group=a[1], harm_measured=a[2]),
        b=SimpleNamespace(group=b[1], harm_measured=b[2]),
    )


def test_one_body_hit_twice_is_injured_unless_both_impacts_spare_it():
    # The ego hits the same pedestrian twice (0.5 each): 1 - 0.5 * 0.5 = 0.75, not 1.0.
    records = [
        _record((0, "ego", 0.1), (1, "vulnerable", 0.5)),
        _record((0, "ego", 0.2), (1, "vulnerable", 0.5)),
    ]
    harm = combined_harm(records)
    assert harm["vulnerable"] == pytest.approx(0.75)
    assert harm["ego"] == pytest.approx(1.0 - 0.9 * 0.8)
    assert harm["third_party"] == 0.0


def test_a_group_is_an_expected_count_over_its_bodies():
    # Two pedestrians (0.8, 0.9) and a car hit twice (0.95 each): the vulnerable group
    # expects 1.7 injured (a count, above 1); the car stays below 1 (0.9975).
    records = [
        _record((0, "ego", 0.0), (1, "vulnerable", 0.8)),
        _record((0, "ego", 0.0), (2, "vulnerable", 0.9)),
        _record((0, "ego", 0.0), (3, "third_party", 0.95)),
        _record((3, "third_party", 0.95), (4, "static", math.nan)),
    ]
    harm = combined_harm(records)
    assert harm["vulnerable"] == pytest.approx(1.7)
    assert harm["third_party"] == pytest.approx(1.0 - 0.05 * 0.05)
    assert harm["ego"] == 0.0 and set(harm) == {"ego", "third_party", "vulnerable"}


def test_no_collisions_no_harm_and_harms_are_clipped():
    assert combined_harm([]) == {"ego": 0.0, "third_party": 0.0, "vulnerable": 0.0}
    assert combined_harm([_record((0, "ego", 1.2), (1, "third_party", -0.1))])["ego"] == 1.0
