"""Shared geometry against values worked out by hand."""

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from ethical_planner.geometry import (
    impact_offset_fraction,
    rectangle_corners,
    rectangle_half_extent,
    rectangle_overlap,
    velocity_angle,
    wrap_angle,
    wrap_angle_in_place,
)

PI = math.pi

# --------------------------------------------------------------------------- wrap


@pytest.mark.parametrize(
    ("angle", "expected"),
    [
        (0.0, 0.0),
        (PI / 2, PI / 2),
        (3 * PI / 2, -PI / 2),
        (-3 * PI / 2, PI / 2),
        (2 * PI, 0.0),
        (-2 * PI, 0.0),
        (PI, PI),  # the boundary belongs to the upper end: (-pi, pi]
        (-PI, PI),
        (3 * PI, PI),
        (-3 * PI, PI),
        (7 * PI / 4, -PI / 4),
        (-7 * PI / 4, PI / 4),
        (10 * PI + 0.5, 0.5),
    ],
)
def test_wrap_known_angles(angle, expected):
    assert float(wrap_angle(angle)) == pytest.approx(expected, abs=1e-12)


def test_wrap_boundary_is_exact_and_just_past_it_flips():
    got = wrap_angle([PI, -PI, np.nextafter(PI, 4.0), np.nextafter(-PI, -4.0), np.nextafter(-PI, 0.0)])
    assert got[0] == PI and got[1] == PI
    assert -PI < got[2] < -3.14  # just above pi -> just above -pi
    assert 3.14 < got[3] <= PI  # just below -pi -> just below pi
    assert got[4] == np.nextafter(-PI, 0.0)  # inside: unchanged to the bit


@given(st.floats(min_value=-1e4, max_value=1e4, allow_nan=False))
def test_wrap_range_and_direction(angle):
    wrapped = float(wrap_angle(angle))
    assert -PI < wrapped <= PI
    assert math.cos(wrapped) == pytest.approx(math.cos(angle), abs=1e-9)
    assert math.sin(wrapped) == pytest.approx(math.sin(angle), abs=1e-9)


@given(st.floats(min_value=-PI, max_value=PI, exclude_min=True))
def test_wrap_keeps_wrapped_values_to_the_bit(angle):
    assert float(wrap_angle(angle)) == angle


def test_wrap_keeps_nan_and_its_input():
    angles = np.array([4.0, math.nan])
    out = wrap_angle(angles)
    assert angles[0] == 4.0 and math.isnan(out[1]) and out[0] == pytest.approx(4.0 - 2 * PI)
    own = np.array([4.0, -4.0])
    assert wrap_angle_in_place(own) is own and own[1] == pytest.approx(2 * PI - 4.0)


# --------------------------------------------------------------------------- rectangles


def test_corners_of_a_rotated_rectangle_by_hand():
    # heading (0.8, 0.6), left normal (-0.6, 0.8); half length 5, half width 2.5:
    # front right = 5 (0.8, 0.6) - 2.5 (-0.6, 0.8) = (5.5, 1.0), and so on.
    x, y = rectangle_corners(1.0, 2.0, math.atan2(3.0, 4.0), 10.0, 5.0)
    expected = np.array([[5.5, 1.0], [2.5, 5.0], [-5.5, -1.0], [-2.5, -5.0]]) + [1.0, 2.0]
    np.testing.assert_allclose(np.column_stack([x, y]), expected, atol=1e-12)


def test_corners_are_counter_clockwise_and_broadcast():
    yaw = np.array([[0.0, 0.3], [2.0, -2.5]])
    x, y = rectangle_corners(np.zeros((2, 2)), np.ones((2, 2)), yaw, 4.0, np.array([1.0, 2.0]))
    assert x.shape == y.shape == (2, 2, 4)
    # shoelace area: positive (counter-clockwise) and equal to length x width
    area = 0.5 * (x * np.roll(y, -1, axis=-1) - np.roll(x, -1, axis=-1) * y).sum(axis=-1)
    np.testing.assert_allclose(area, [[4.0, 8.0], [4.0, 8.0]])
    # the front right corner at yaw 0: (+2, -w/2) from the centre (0, 1)
    assert (x[0, 0, 0], y[0, 0, 0]) == pytest.approx((2.0, 0.5))


def test_half_extent_by_hand():
    # a 4 x 2 rectangle: 2 along its heading, 1 across, sqrt(5) along its diagonal
    assert rectangle_half_extent(0.0, 4.0, 2.0, 1.0, 0.0) == pytest.approx(2.0)
    assert rectangle_half_extent(0.0, 4.0, 2.0, 0.0, 1.0) == pytest.approx(1.0)
    assert rectangle_half_extent(PI / 2, 4.0, 2.0, 1.0, 0.0) == pytest.approx(1.0)
    d = np.array([2.0, 1.0]) / math.sqrt(5.0)
    assert rectangle_half_extent(0.0, 4.0, 2.0, *d) == pytest.approx(math.sqrt(5.0))


# --------------------------------------------------------------------------- impact geometry


def _offset(ego_pos, ego_vel, ego_yaw, ego_shape, obs_pos, obs_vel, obs_yaw, obs_shape):
    return float(
        impact_offset_fraction(ego_pos, ego_vel, ego_yaw, *ego_shape, obs_pos, obs_vel, obs_yaw, *obs_shape)
    )


def test_offset_fraction_of_hand_drawn_impacts():
    # Head-on, 1 m sideways: the approach runs along x, the footprints touch up to
    # 1 + 1 m sideways (half widths), so the offset is 1 / 2.
    assert _offset((0, 0), (10, 0), 0.0, (4, 2), (10, 1), (-10, 0), PI, (4, 2)) == pytest.approx(0.5)
    # T-bone into a car at rest: the other body comes from below 1.5 m right of centre;
    # reach across the approach = ego half length 2 + the other's half width 0.5.
    assert _offset((0, 0), (0, 0), 0.0, (4, 2), (1.5, -10), (0, 5), PI / 2, (4, 1)) == pytest.approx(0.6)
    # A square turned by 45 deg reaches sqrt(2) sideways: 1 / (1 + sqrt(2)).
    got = _offset((0, 0), (10, 0), 0.0, (4, 2), (10, 1), (0, 0), PI / 4, (2, 2))
    assert got == pytest.approx(1.0 / (1.0 + math.sqrt(2.0)))
    # Central, grazing beyond the edge (clipped) and no approach.
    assert _offset((0, 0), (10, 0), 0.0, (4, 2), (10, 0), (0, 0), 0.0, (4, 2)) == 0.0
    assert _offset((0, 0), (10, 0), 0.0, (4, 2), (10, 5), (0, 0), 0.0, (4, 2)) == 1.0
    assert _offset((0, 0), (3, 4), 0.0, (4, 2), (10, 5), (3, 4), 0.0, (4, 2)) == 0.0


def test_offset_fraction_rejects_non_finite_positions():
    with pytest.raises(ValueError, match="obs_pos"):
        impact_offset_fraction([0, 0], [1, 0], 0.0, 4.0, 2.0, [math.nan, 0], [0, 0], 0.0, 4.0, 2.0)


def test_velocity_angle_by_hand():
    ego = [[10, 0], [10, 0], [10, 0], [0, 0], [3, 3]]
    other = [[5, 0], [0, -3], [-2, 0], [0, 0], [-1, 1]]
    # same direction, T-bone, head-on, both at rest (headings 0 and pi/2 stand in), 90 deg
    got = velocity_angle(ego, other, 0.0, [0.0, 0.0, 0.0, PI / 2, 0.0])
    np.testing.assert_allclose(got, [0.0, PI / 2, PI, PI / 2, PI / 2], atol=1e-12)


# --------------------------------------------------------------------------- rectangle overlap


def _box(x, y, yaw, length, width):
    cx, cy = rectangle_corners(x, y, yaw, length, width)
    return shapely.Polygon(np.column_stack([cx, cy]))


def test_rectangle_overlap_by_hand():
    # Two axis-aligned 4 x 2 boxes 3 m apart along x: 1 m deep along x.
    assert rectangle_overlap(0, 0, 0, 4, 2, 3, 0, 0, 4, 2) == pytest.approx(1.0)
    # 5 m apart: a gap of 1 m.
    assert rectangle_overlap(0, 0, 0, 4, 2, 5, 0, 0, 4, 2) == pytest.approx(-1.0)
    # Side by side, 1.5 m apart across: 0.5 m deep across.
    assert rectangle_overlap(0, 0, 0, 4, 2, 0, 1.5, 0, 4, 2) == pytest.approx(0.5)


@settings(max_examples=300, deadline=None)
@given(
    st.floats(-6, 6), st.floats(-6, 6), st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi),
    st.floats(0.3, 6), st.floats(0.3, 3), st.floats(0.3, 6), st.floats(0.3, 3),
)  # fmt: skip
def test_rectangle_overlap_agrees_with_polygon_intersection(x, y, yaw_a, yaw_b, la, wa, lb, wb):
    depth = float(rectangle_overlap(0.0, 0.0, yaw_a, la, wa, x, y, yaw_b, lb, wb))
    area = _box(0.0, 0.0, yaw_a, la, wa).intersection(_box(x, y, yaw_b, lb, wb)).area
    if abs(depth) > 1e-6:
        assert (depth > 0) == (area > 1e-9)
