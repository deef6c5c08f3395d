"""Sight (physics.sight, World.visible): heights, occlusion by any box, range, field of view."""

import math

import numpy as np
import pytest
import shapely

from mujoco_world.loop.world import World
from mujoco_world.physics.sight import Boxes, blocked, in_field_of_view, target_points
from mujoco_world.scenario.catalog import get_scenario
from mujoco_world.scenario.spec import scenario_from_dict


def _box(x, y, yaw, length, width, height) -> Boxes:
    return Boxes(*(np.array([v], dtype=float) for v in (x, y, yaw, 0.5 * length, 0.5 * width, height)))


def _blocked_by_shapely(eye, eye_h, point, point_h, box) -> bool:
    """Scalar reference: the segment's part inside the footprint, its lowest height there."""
    corners = [
        (sx * box.half_length[0], sy * box.half_width[0]) for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))
    ]
    c, s = math.cos(box.yaw[0]), math.sin(box.yaw[0])
    footprint = shapely.Polygon([(box.x[0] + u * c - v * s, box.y[0] + u * s + v * c) for u, v in corners])
    line = shapely.LineString([eye, point])
    inside = line.intersection(footprint)
    if inside.is_empty or inside.length < 1e-9:
        return False
    length = line.length
    heights = [eye_h + (math.dist(eye, q) / length) * (point_h - eye_h) for q in inside.coords]
    return min(heights) < box.height[0]


def test_blocked_matches_a_scalar_polygon_reference():
    rng = np.random.default_rng(3)
    eye = np.array([0.0, 0.0])
    agree = hits = 0
    for _ in range(300):
        point = rng.uniform(-25, 25, 2)
        # Boxes near the sight line, so that both answers occur often.
        centre = rng.uniform(0.0, 1.0) * point + rng.normal(0.0, 2.0, 2)
        shape = rng.uniform(0.5, 6.0, 2)
        box = _box(*centre, rng.uniform(-3, 3), *shape, rng.uniform(0.1, 3.0))
        point_h, eye_h = rng.uniform(0.2, 2.0), rng.uniform(0.5, 3.0)
        px, py = point[None, None, 0], point[None, None, 1]
        got = bool(blocked(eye, eye_h, px, py, np.array([point_h]), box)[0, 0])
        want = _blocked_by_shapely(tuple(eye), eye_h, tuple(point), point_h, box)
        agree += got == want
        hits += want
    assert agree == 300
    assert 50 < hits < 250  # both answers occur


@pytest.mark.parametrize(
    ("x", "height", "eye_height", "target_height", "hidden"),
    [
        # Target at x = 20 m, a box 1 m long across the line at x.
        (18.0, 1.0, 1.2, 0.725, True),  # a 1 m wall hides a car's middle from a roof camera
        (18.0, 0.15, 1.2, 0.725, False),  # a kerb does not
        (5.0, 1.45, 1.2, 1.8, True),  # a car just ahead hides a truck's middle (line at 1.35 m)
        (18.0, 1.45, 1.2, 1.8, False),  # a car just before the truck does not (line at 1.73 m)
        (5.0, 1.45, 3.0, 1.8, False),  # a bus driver's eye sees over the car (line at 2.7 m)
        (19.0, 0.5, 1.2, 0.6, False),  # 0.5 m debris is under the line to a child's middle
    ],
)
def test_heights_decide_what_blocks(x, height, eye_height, target_height, hidden):
    box = _box(x, 0.0, 0.0, 1.0, 4.0, height)
    got = blocked(
        np.array([0.0, 0.0]),
        eye_height,
        np.array([[20.0]]),
        np.array([[0.0]]),
        np.array([target_height]),
        box,
    )
    assert bool(got[0, 0]) is hidden


def test_a_body_never_hides_itself_and_no_boxes_hide_nothing():
    px, py = target_points(
        np.array([10.0]), np.array([0.0]), np.array([0.0]), np.array([4.5]), np.array([1.8])
    )
    assert px.shape == (1, 5)
    own = _box(10.0, 0.0, 0.0, 4.5, 1.8, 1.45)
    eye = np.array([0.0, 0.0])
    assert blocked(eye, 1.2, px, py, np.array([0.7]), own).all()
    assert not blocked(eye, 1.2, px, py, np.array([0.7]), own, ignore=np.array([[True]])).any()
    empty = Boxes.concatenate(own.take(np.array([], dtype=int)))
    assert not blocked(eye, 1.2, px, py, np.array([0.7]), empty).any()


def test_field_of_view_and_range():
    eye = np.array([0.0, 0.0])
    px = np.array([[10.0, -10.0, 0.0, 60.0]])
    py = np.array([[0.0, 0.0, 10.0, 0.0]])
    # Ahead, behind, to the left (90 deg), far ahead.
    assert in_field_of_view(eye, 0.0, px, py, None, 360.0).tolist() == [[True, True, True, True]]
    assert in_field_of_view(eye, 0.0, px, py, None, 120.0).tolist() == [[True, False, False, True]]
    assert in_field_of_view(eye, 0.0, px, py, None, 181.0).tolist() == [[True, False, True, True]]
    assert in_field_of_view(eye, 0.0, px, py, 50.0, 360.0).tolist() == [[True, True, True, False]]
    # Heading pi: behind becomes ahead (wrap-around at +-pi).
    assert in_field_of_view(eye, math.pi, px, py, None, 90.0).tolist() == [[False, True, False, False]]


def _world(**sensor):
    return World(
        scenario_from_dict(
            {
                "name": "t",
                "road": {"length": 120.0, "boundary": "none"},
                "ego": {"s0": 5.0, "speed": 0.0},
                "sensor": sensor,
                "road_users": [
                    {"name": "walker", "type": "pedestrian", "s0": 25.0, "behaviour": {"speed": 0.0}},
                    {"name": "kid", "type": "child", "s0": 40.0, "behaviour": {"speed": 0.0}},
                    {
                        "name": "beside",
                        "type": "car",
                        "s0": 0.0,
                        "route": {"lane": 1, "wrong_way": True},
                        "behaviour": {"speed": 0.0},
                    },
                ],
            }
        )
    )


def test_the_world_sees_through_its_sensor():
    # Unlimited sensor: everything; occlusion by every road user: the adult pedestrian
    # (1.75 m) hides the child (1.2 m) 15 m behind it in line (by default only vehicles
    # hide others); a 120 deg field of view misses the car behind on the left (145 deg
    # off the heading).
    assert _world().visible().tolist() == [True, True, True, True]
    assert _world(occlusion=True).visible().tolist() == [True, True, True, True]
    assert _world(occlusion=True, occluders="all").visible().tolist() == [True, True, False, True]
    assert _world(fov=120.0).visible().tolist() == [True, True, True, False]
    assert _world(range=21.0).visible().tolist() == [True, True, False, True]
    # A sensor 4 m up looks over the adult's head onto the child (the sight line passes
    # the adult 20 m out of 35 at 4 - 20 / 35 * (4 - 0.6) = 2.06 m > 1.75 m; from 3 m: 1.63 m).
    everyone = {"occlusion": True, "occluders": "all"}
    assert _world(**everyone, height=3.0).visible().tolist() == [True, True, False, True]
    assert _world(**everyone, height=4.0).visible().tolist() == [True, True, True, True]


def test_walls_hide_a_car_behind_a_curve_until_the_ego_is_about_45_m_away():
    """Geometry: on a left curve the inner wall bounds the sight line; first sight at ~45 m."""
    world = World(get_scenario("stopped_car_behind_curve"))
    distances, seen = [], []
    for s in np.arange(5.0, 90.0, 2.5):
        x, y, th, _, _ = world.ego_path.evaluate(np.array([s]))
        world.scene.qpos[0, :3] = [x[0], y[0], th[0]]
        distances.append(math.dist(world.scene.qpos[0, :2], world.scene.qpos[1, :2]))
        seen.append(bool(world.visible()[1]))
    first = seen.index(True)
    assert all(seen[first:]) and not any(seen[:first])
    # Chord tangent to the inner wall (radius 40 - 3.5 - 0.4 / 2 ... the wall's inner face
    # at 36.5 m, the ego lane at 41.75 m): 2 sqrt(41.75^2 - 36.5^2) = 40.5 m between the
    # lane points; the walls' height (1 m) is above the sight line (1.2 m -> 0.725 m).
    assert 38.0 < distances[first] < 48.0


def test_first_seen_is_in_the_summary():
    from mujoco_world.loop.runner import run_scenario

    scenario = get_scenario("stopped_car_behind_curve")
    import dataclasses

    summary = run_scenario(dataclasses.replace(scenario, duration=4.5), "keep_lane", seed=0)
    # Ego at 12.5 m/s from s = 5 m: about 3.0 s until it is 45 m from the car (s ~ 42 m).
    assert 2.0 < summary.first_seen["stopped"] < 3.6
    open_view = dataclasses.replace(
        scenario, duration=0.5, sensor=dataclasses.replace(scenario.sensor, occlusion=False)
    )
    assert run_scenario(open_view, "keep_lane", seed=0).first_seen == {"stopped": 0.0}


def test_a_car_hides_a_pedestrian_behind_it_unless_the_sensor_looks_over_it():
    # Car (1.45 m) 15 m ahead of the sensor, a pedestrian 10 m behind it in line: the
    # sight line to the pedestrian's middle (0.875 m) from 1.2 m stays below the roof; from
    # 4 m it passes the car at 4 - 15 / 25 * (4 - 0.875) = 2.1 m.
    def world(**sensor):
        return World(
            scenario_from_dict(
                {
                    "name": "t",
                    "road": {"length": 120.0, "boundary": "none"},
                    "ego": {"s0": 5.0, "speed": 0.0},
                    "sensor": {"occlusion": True, **sensor},
                    "road_users": [
                        {"name": "car", "type": "car", "s0": 20.0, "behaviour": {"speed": 0.0}},
                        {"name": "walker", "type": "pedestrian", "s0": 30.0, "behaviour": {"speed": 0.0}},
                    ],
                }
            )
        )

    assert world().visible().tolist() == [True, True, False]
    assert world(height=4.0).visible().tolist() == [True, True, True]
