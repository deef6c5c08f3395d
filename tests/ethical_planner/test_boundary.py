"""The road edge as a body (``ethical_planner.boundary``), against values computed by hand.

The road of every test: the box x in [-50, 150] m, y in [-2, 1.8] m, so its left edge
(a wall, as the planner sees every edge) is the line y = 1.8 m and its end the line
x = 150 m. The footprint is 4 m x 2 m, so a corner sits 2 m ahead and 1 m aside of the
centre.
"""

import math

import numpy as np
import pytest
import shapely.affinity
from shapely.geometry import box

from ethical_planner.boundary import (
    _edge_segments,
    _nearest_on_segments,
    edge_impact_speed,
    physical_view,
    push_back,
)
from ethical_planner.environment import RoadEnvironment
from ethical_planner.reference_path import ReferencePath
from ethical_planner.road_users import Shape
from ethical_planner.sampling import Candidates

SHAPE = Shape(4.0, 2.0)
WALL_Y = 1.8  # the left edge [m]
END_X = 150.0  # the road's end [m]


def _road(area=None):
    path = ReferencePath.from_polyline([[-50.0, 0.0], [150.0, 0.0]])
    return RoadEnvironment(path, area if area is not None else box(-50.0, -2.0, END_X, WALL_Y))


def _candidates(x, y, yaw, v):
    """A struct of arrays with these poses and speeds, shape (n, n_t); the rest zeros."""
    x, y, yaw, v = (np.atleast_2d(np.asarray(a, dtype=float)) for a in np.broadcast_arrays(x, y, yaw, v))
    n, n_t = x.shape
    zeros, per = np.zeros((n, n_t)), np.zeros(n)
    return Candidates(
        t=0.1 * np.arange(n_t),
        x=x,
        y=y,
        yaw=yaw,
        v=v,
        a=zeros,
        kappa=zeros,
        s=x,
        d=y,
        s_dot=v,
        end_speed=per,
        end_offset=per,
        horizon=per,
        kind=np.zeros(n, dtype=np.int8),
        deceleration=per,
        jerk_lon=per,
        jerk_lat=per,
        lon=np.zeros((4, n, n_t)),
        lat=np.zeros((4, n, n_t)),
    )


def test_a_footprint_across_a_straight_wall_is_pushed_back_along_its_normal():
    # Heading 0.2 rad into the wall, centre 0.3 m short of it: the front left corner
    # is at y = 1.5 + 2 sin 0.2 + cos 0.2 = 2.8774, 1.0774 m beyond the wall. The
    # centre moves straight back by that much: to y = 1.8 - 2 sin 0.2 - cos 0.2.
    theta = 0.2
    dx, dy = push_back(np.array([10.0]), np.array([1.5]), np.array([theta]), SHAPE, _road())
    reach = 2.0 * math.sin(theta) + math.cos(theta)  # the corner's height above the centre
    assert dx[0] == pytest.approx(0.0, abs=1e-8)
    assert dy[0] == pytest.approx(-(1.5 + reach - WALL_Y), abs=1e-8)
    assert 1.5 + dy[0] == pytest.approx(0.42259, abs=1e-5)


def test_a_footprint_inside_the_road_is_not_moved():
    dx, dy = push_back(np.array([10.0, 40.0]), np.array([0.7, -0.9]), np.array([0.0, 0.05]), SHAPE, _road())
    assert np.all(dx == 0.0) and np.all(dy == 0.0)


def test_a_footprint_beyond_a_corner_of_the_road_goes_back_to_the_corner():
    # Centre (149, 1.5), heading 0: the front left corner (151, 2.5) is 1 m beyond the
    # end and 0.7 m beyond the wall; its nearest point of the road is the corner
    # (150, 1.8), so the centre moves by (-1, -0.7) and every corner is inside after it.
    dx, dy = push_back(np.array([149.0]), np.array([1.5]), np.array([0.0]), SHAPE, _road())
    assert (dx[0], dy[0]) == pytest.approx((-1.0, -0.7), abs=1e-8)


def test_physical_view_presses_a_plan_against_the_wall_at_its_speed_along_it():
    # A plan at 10 m/s heading 0.2 rad left, its centre rising 0.2 m per step from
    # y = 0: steps 0-2 (y 0, 0.2, 0.4) are clear of the wall (corner at y + 1.3774);
    # from step 3 (y = 0.6) the corner crosses y = 1.8 and the centre stops at
    # 1.8 - 1.3774 = 0.4226 m with x unchanged; its speed is 10 cos 0.2 = 9.801 m/s,
    # the normal 10 sin 0.2 = 1.987 m/s being taken by the wall.
    theta, n_t = 0.2, 6
    x = 10.0 * np.arange(n_t) * 0.1
    y = 0.2 * np.arange(n_t)
    plan = _candidates(x, y, theta, 10.0)
    view, pressed = physical_view(plan, np.array([0]), SHAPE, _road())
    reach = 2.0 * math.sin(theta) + math.cos(theta)
    clear = y + reach <= WALL_Y
    np.testing.assert_array_equal(pressed[0], ~clear)
    assert clear.tolist() == [True, True, True, False, False, False]
    np.testing.assert_allclose(view.y[0], np.where(clear, y, WALL_Y - reach), atol=1e-8)
    np.testing.assert_allclose(view.x, plan.x, atol=1e-8)
    np.testing.assert_array_equal(view.yaw, plan.yaw)  # the car presses turned as planned
    np.testing.assert_allclose(view.v[0], np.where(clear, 10.0, 10.0 * math.cos(theta)), atol=1e-8)
    assert view.v[0, -1] == pytest.approx(9.80067, abs=1e-5)
    # The plan itself is left as it is.
    np.testing.assert_array_equal(plan.y[0], y)


def test_physical_view_keeps_the_present_and_plans_that_stay_on_the_road():
    # Row 0 starts across the wall (step 0, the ego's present state, is not moved);
    # row 1 stays in its lane. A plan moving away from the wall keeps its speed.
    rows = _candidates(
        [[0.0, 1.0, 2.0], [0.0, 1.0, 2.0]],
        [[1.0, 1.0, 0.95], [0.0, 0.0, 0.0]],
        [[0.0, 0.0, -0.1], [0.0] * 3],
        8.0,
    )
    view, pressed = physical_view(rows, np.array([0, 1]), SHAPE, _road())
    assert pressed.tolist() == [[False, True, True], [False, False, False]]
    assert view.y[0, 0] == 1.0 and view.y[0, 1] == pytest.approx(0.8, abs=1e-8)
    # Step 2 heads 0.1 rad away from the wall (t . n > 0): its 8 m/s are kept.
    assert view.v[0].tolist() == [8.0, 8.0, 8.0]
    np.testing.assert_array_equal(view.y[1], rows.y[1])
    # Only the rows asked for are looked at.
    untouched, none = physical_view(rows, np.array([1]), SHAPE, _road())
    assert untouched is rows and not none.any()


@pytest.mark.parametrize("theta", [0.1, 0.3, 0.6])
def test_impact_speed_is_the_speed_into_the_wall(theta):
    # First step off the road at 12 m/s heading theta into the wall: 12 sin(theta).
    plan = _candidates([[0.0, 1.0]], [[0.0, 1.0]], theta, 12.0)
    outside = np.array([[False, True]])
    speed = edge_impact_speed(plan, np.array([0]), outside, SHAPE, _road(), 0.25)
    assert speed[0] == pytest.approx(12.0 * math.sin(theta), rel=1e-8)


def test_impact_speed_head_on_is_the_full_speed_and_zero_on_the_road():
    # Row 0 drives straight at the road's end (x = 150 m): its full 9 m/s; row 1 never
    # leaves; row 2 runs parallel to the wall within the margin, row 3 heads 0.1 rad
    # away from it there: neither moves into it.
    plan = _candidates(
        [[140.0, 148.5], [10.0, 11.0], [10.0, 11.0], [10.0, 11.0]],
        [[0.0, 0.0], [0.0, 0.0], [0.7, 0.7], [0.7, 0.7]],
        [[0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [-0.1, -0.1]],
        9.0,
    )
    outside = np.array([[False, True], [False, False], [False, True], [False, True]])
    speed = edge_impact_speed(plan, np.arange(4), outside, SHAPE, _road(), 0.25)
    assert speed.tolist() == pytest.approx([9.0, 0.0, 0.0, 0.0], abs=1e-8)


def test_the_push_back_turns_with_the_road():
    # The straight-wall case of the test above, turned by 0.5 rad about the origin:
    # the pressed positions are the turned hand values (x = 3, 4, 5 m, y = 0.4226 m).
    phi, theta = 0.5, 0.2
    turn = np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])
    road = shapely.affinity.rotate(box(-50.0, -2.0, END_X, WALL_Y), phi, origin=(0, 0), use_radians=True)
    steps = np.arange(6)
    x, y = turn @ np.stack([1.0 * steps, 0.2 * steps])
    plan = _candidates(x, y, theta + phi, 10.0)
    view, pressed = physical_view(plan, np.array([0]), SHAPE, _road(road))
    local_y = np.minimum(0.2 * steps, WALL_Y - 2.0 * math.sin(theta) - math.cos(theta))
    want_x, want_y = turn @ np.stack([1.0 * steps, local_y])
    assert pressed[0].tolist() == [False, False, False, True, True, True]
    np.testing.assert_allclose(view.x[0], want_x, atol=1e-9)
    np.testing.assert_allclose(view.y[0], want_y, atol=1e-9)


def test_impact_speed_where_no_edge_is_crossed_is_the_full_speed():
    # A plan marked off the road without crossing any edge (it ends crowding debris,
    # terminal.crowds_static_obstacle) hits what it crowds head-on.
    plan = _candidates([[0.0, 1.0]], [[0.0, 0.0]], 0.0, 7.0)
    speed = edge_impact_speed(plan, np.array([0]), np.array([[False, True]]), SHAPE, _road(), 0.25)
    assert speed[0] == 7.0


def test_nearest_edge_points_match_shapely():
    # The compiled scan against GEOS's distance to the boundary, on a curved road with a
    # hole (debris), for points inside, outside and in the hole; the edge is simplified
    # within 5 mm, so distances and points agree to that.
    path = np.column_stack([np.linspace(0, 60, 61), 3.0 * np.sin(np.linspace(0, 60, 61) / 12.0)])
    area = shapely.LineString(path).buffer(3.0, quad_segs=4).difference(box(20.0, -1.0, 22.0, 1.0))
    rng = np.random.default_rng(7)
    px, py = rng.uniform(-5.0, 65.0, 400), rng.uniform(-8.0, 8.0, 400)
    qx, qy = _nearest_on_segments(px, py, _edge_segments(area))
    got = np.hypot(qx - px, qy - py)
    want = shapely.distance(area.boundary, shapely.points(px, py))
    np.testing.assert_allclose(got, want, atol=0.005)
    assert shapely.distance(area.boundary, shapely.points(qx, qy)).max() < 0.005
