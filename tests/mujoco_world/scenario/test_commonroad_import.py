"""CommonRoad import: files written here by commonroad-io (run anywhere) and the shared real files."""

import math
from dataclasses import replace

import numpy as np
import pytest
import shapely

pytest.importorskip("commonroad")
pytest.importorskip("commonroad_route_planner")

from ethical_planner.road_users import RoadUserType  # noqa: E402
from mujoco_world.loop.replay import replay  # noqa: E402
from mujoco_world.loop.runner import run_scenario  # noqa: E402
from mujoco_world.loop.world import World  # noqa: E402
from mujoco_world.scenario.commonroad import (  # noqa: E402
    CommonRoadImportError,
    import_commonroad,
    load_commonroad,
    rejection_reason,
    split_reference,
)
from mujoco_world.scenario.commonroad_tracks import shared_commonroad  # noqa: E402
from mujoco_world.scenario.road import box_footprint, build_road, close_union  # noqa: E402
from mujoco_world.scenario.sources import resolve_scenario  # noqa: E402
from mujoco_world.scenario.spec import BehaviourKind, RoadKind  # noqa: E402
from mujoco_world.storage.recording import RecorderConfig, RerunRecorder  # noqa: E402
from tests.mujoco_world.scenario.commonroad_builder import (  # noqa: E402
    LANE,
    Circle,
    ObstacleType,
    Rectangle,
    lanelet,
    moving_obstacle,
    planning_problem,
    set_based_obstacle,
    static_obstacle,
    straight_line,
    straight_road_file,
)

SHARED = shared_commonroad()
needs_shared = pytest.mark.skipif(SHARED is None, reason="../shared/commonroad is absent")


def _traffic():
    """A car ahead in the right lane (whole run), a late pedestrian on the pavement, a bicycle."""
    car = moving_obstacle(
        10, ObstacleType.CAR, Rectangle(4.4, 1.8), 0, straight_line((60, -LANE / 2), 8, 0, 81), 0.0
    )
    walker = moving_obstacle(
        11,
        ObstacleType.PEDESTRIAN,
        Circle(0.3),
        20,
        straight_line((100, -6.0), 1.4, math.pi / 2, 31),
        math.pi / 2,
    )
    bike = moving_obstacle(
        12, ObstacleType.BICYCLE, Rectangle(1.8, 0.6), 5, straight_line((30, 2.5), 5, 0, 40), 0.0
    )
    return [car, walker, bike]


def test_a_written_file_becomes_a_map_scenario_with_its_recorded_road_users(tmp_path):
    path = straight_road_file(tmp_path, _traffic(), speed_sign=15.0)
    scenario = import_commonroad(path)
    assert scenario.road.kind is RoadKind.MAP
    # The drivable area is the union of the lanelets near the route: 300 m x 7 m.
    area = shapely.union_all([shapely.Polygon(r) for r in scenario.road.map.area])
    assert area.area == pytest.approx(300 * 2 * LANE, rel=1e-3)
    # Lanes: the ego's (offset 0) and the left one (+3.5 m).
    assert scenario.road.map.lane_offsets == pytest.approx((0.0, LANE), abs=0.02)
    assert scenario.road.map.lane_width == pytest.approx(LANE)
    assert scenario.road.speed_limit == pytest.approx(15.0)
    assert any("MAX_SPEED sign" in n for n in scenario.notes)
    # The ego: the planning problem's initial state; its goal region is the rectangle.
    ego = scenario.ego
    assert ego.pose == pytest.approx((20.0, -LANE / 2, 0.0)) and ego.speed == pytest.approx(10.0)
    goal = shapely.Polygon(ego.goal_region[0])
    assert goal.area == pytest.approx(30.0) and goal.centroid.x == pytest.approx(150.0)
    # Time limit: the goal allows 8.0 s, the traffic lasts 8.0 s.
    assert scenario.duration == pytest.approx(8.0)
    users = {u.name: u for u in scenario.road_users}
    assert set(users) == {"car_10", "pedestrian_11", "bicycle_12"}
    walker = users["pedestrian_11"]
    assert walker.type is RoadUserType.PEDESTRIAN and walker.shape == pytest.approx((0.6, 0.6))
    assert walker.behaviour.kind is BehaviourKind.RECORDED
    trajectory = walker.behaviour.trajectory
    assert trajectory.start == pytest.approx(2.0) and trajectory.end == pytest.approx(5.0)
    assert (trajectory.x[0], trajectory.y[0]) == pytest.approx((100.0, -6.0))


def test_the_route_changes_lane_to_reach_a_goal_on_the_other_lane(tmp_path):
    scenario = import_commonroad(straight_road_file(tmp_path))
    path = np.asarray(scenario.road.map.reference_path)
    assert path[0, 1] == pytest.approx(-LANE / 2, abs=0.01)  # starts in the ego's lane
    at_goal = path[np.argmin(np.abs(path[:, 0] - 200.0))]
    assert at_goal[1] == pytest.approx(LANE / 2, abs=0.01)  # in the goal's lane by the lanelet's end
    assert "1 lane change" in " ".join(scenario.notes)
    # Continued along the successor lanelet 4 (to x = 300) and straight beyond.
    assert path[-1, 0] > 300.0


def test_recorded_road_users_enter_and_leave_the_world(tmp_path):
    scenario = import_commonroad(straight_road_file(tmp_path, _traffic()))
    world = World(scenario)
    walker = 1 + [u.name for u in scenario.road_users].index("pedestrian_11")
    seen = {}
    for step in range(int(6.0 / world.scene.dt)):
        world.step()
        if step % 100 == 0:
            seen[round(world.time, 1)] = (bool(world.present[walker]), world.scene.qpos[walker, :2].copy())
    assert not seen[1.0][0] and seen[1.0][1][0] > 1e4  # not yet in the world: parked far away
    assert seen[3.0][0] and seen[3.0][1] == pytest.approx((100.0, -6.0 + 1.4 * 1.0), abs=0.01)
    assert not seen[5.5][0]  # its recording ended at 5.0 s
    events = {(world.scene.names[e], what): t for t, e, what in world.presence_events}
    # Presence is updated with the controllers (every 10 ms).
    assert events[("pedestrian_11", "enter")] == pytest.approx(2.0, abs=0.011)
    assert events[("pedestrian_11", "leave")] == pytest.approx(5.0, abs=0.011)
    # The planner sees only road users in the world.
    _, users = world.observe()
    assert walker not in {u.id for u in users}


def test_replay_without_the_ego_follows_every_recording_within_a_centimetre(tmp_path):
    report = replay(import_commonroad(straight_road_file(tmp_path, _traffic())))
    assert report.collisions == ()
    assert report.overall_rms < 0.01 and report.worst_rms < 0.01


def test_overlapping_recorded_shapes_get_no_contact_and_a_note(tmp_path):
    # Two cars recorded 3 m apart along the same line: their 4.4 m shapes overlap by 1.4 m.
    a = moving_obstacle(
        20, ObstacleType.CAR, Rectangle(4.4, 1.8), 0, straight_line((60, -LANE / 2), 8, 0, 40), 0.0
    )
    b = moving_obstacle(
        21, ObstacleType.CAR, Rectangle(4.4, 1.8), 0, straight_line((63, -LANE / 2), 8, 0, 40), 0.0
    )
    scenario = import_commonroad(straight_road_file(tmp_path, [a, b]))
    assert scenario.contact.exclude == (("car_20", "car_21"),)
    note = next(n for n in scenario.notes if "overlap" in n)
    assert "car_20 and car_21 overlap by up to 1.40 m" in note
    assert replay(scenario).collisions == ()
    # Without the exclusion the same recordings collide (the test can fail).
    import dataclasses

    forced = dataclasses.replace(scenario, contact=dataclasses.replace(scenario.contact, exclude=()))
    with pytest.raises(ValueError, match="overlap at the start"):
        replay(forced)


def test_a_time_step_disagreeing_with_the_velocities_is_corrected(tmp_path):
    # Positions move 2x further per declared 0.1 s step than the velocity (10 m/s) says.
    positions = straight_line((60, -LANE / 2), 10, 0, 40, step_scale=2.0)
    car = moving_obstacle(
        10, ObstacleType.CAR, Rectangle(4.4, 1.8), 0, positions, 0.0, speeds=np.full(40, 10.0)
    )
    scenario = import_commonroad(straight_road_file(tmp_path, [car]))
    trajectory = scenario.road_users[0].behaviour.trajectory
    assert trajectory.dt == pytest.approx(0.2)
    assert any("using 0.2 s" in n for n in scenario.notes)
    # The time limit and the goal's time are in the corrected step too: 40 states x 0.2 s.
    assert scenario.duration == pytest.approx(7.8)


def test_a_goal_of_time_only_ends_the_run_at_its_time(tmp_path):
    problem = planning_problem(goal=None, goal_steps=(0, 30))
    scenario = import_commonroad(straight_road_file(tmp_path, problems=[problem]))
    assert scenario.ego.goal_region == () and scenario.ego.goal_time == pytest.approx(3.0)
    assert scenario.duration == pytest.approx(3.0)
    assert any("goal of time only" in n for n in scenario.notes)
    world = World(scenario)
    for _ in range(int(2.9 / world.scene.dt)):
        world.step()
    assert not world.goal_reached()
    for _ in range(200):
        world.step()
    assert world.goal_reached() and "goal time 3 s" in world.goal_description()


def test_the_goal_region_is_reached_by_position(tmp_path):
    scenario = import_commonroad(straight_road_file(tmp_path))
    world = World(scenario)
    assert not world.goal_reached()
    world.scene.qpos[0, :2] = (150.0, LANE / 2)
    assert world.goal_reached()


def test_static_obstacles_become_fixed_or_parked_bodies(tmp_path):
    static = [
        static_obstacle(30, ObstacleType.PARKED_VEHICLE, (80.0, -5.0)),
        static_obstacle(31, ObstacleType.CONSTRUCTION_ZONE, (120.0, 1.75), length=6.0, width=3.0),
        static_obstacle(32, ObstacleType.UNKNOWN, (60.0, 1.75)),
    ]
    scenario = import_commonroad(straight_road_file(tmp_path, static=static))
    parked, blocking = scenario.road_users
    assert parked.type is RoadUserType.PARKED_VEHICLE and parked.behaviour.kind is BehaviourKind.PARKED
    # An obstacle of unknown type blocks a lane: the planner must perceive it, so it is parked too.
    assert blocking.type is RoadUserType.PARKED_VEHICLE
    assert blocking.route.waypoints[0] == pytest.approx((60.0, 1.75))
    assert any("32 (unknown) is a parked vehicle" in n for n in scenario.notes)
    fixed = scenario.obstacles[0]
    assert (fixed.x, fixed.y, fixed.length, fixed.width) == pytest.approx((120.0, 1.75, 6.0, 3.0))
    world = World(scenario)
    assert world.scene.qpos[1, :2] == pytest.approx((80.0, -5.0))
    boxes = [g for g in range(world.scene.model.ngeom) if world.scene.model.geom_bodyid[g] == 0]
    assert any(np.allclose(world.scene.model.geom_size[g][:2], (3.0, 1.5)) for g in boxes)


def test_speed_limit_without_a_sign_is_the_85th_percentile_of_the_recorded_traffic(tmp_path):
    cars = [
        moving_obstacle(
            40 + k,
            ObstacleType.CAR,
            Rectangle(4.4, 1.8),
            0,
            straight_line((60 + 10 * k, 1.75), v, 0, 30),
            0.0,
        )
        for k, v in enumerate([10.0, 12.0, 14.0, 16.0, 18.0])
    ]
    scenario = import_commonroad(straight_road_file(tmp_path, cars, problems=[planning_problem(speed=5.0)]))
    assert scenario.road.speed_limit == pytest.approx(np.percentile([10, 12, 14, 16, 18], 85), rel=1e-3)
    assert any("85th percentile" in n for n in scenario.notes)


def test_a_jerky_recording_is_named_and_still_followed(tmp_path):
    # 20 m/s, then 10 m/s from one step to the next: 100 m/s^2, beyond any tyre.
    x = np.concatenate([60 + np.arange(10) * 2.0, 60 + 18 + np.arange(1, 21) * 1.0])
    positions = np.column_stack([x, np.full_like(x, -LANE / 2)])
    car = moving_obstacle(10, ObstacleType.CAR, Rectangle(4.4, 1.8), 0, positions, 0.0)
    scenario = import_commonroad(straight_road_file(tmp_path, [car]))
    world = World(scenario)
    assert 1 in world.beyond_friction and world.accel_limit[1] > 9.81
    note = next(n for n in world.notes if "beyond tyre friction" in n)
    assert note.startswith("recording of car_10 asks")
    # The run summary says so (with the importer's notes).
    summary = run_scenario(replace(scenario, duration=0.3), "keep_lane", 0)
    assert note in summary.notes and scenario.notes[0] in summary.notes


@pytest.mark.parametrize(
    "case,reason,match",
    [
        ("no_problem", "no_planning_problem", "no planning problem"),
        ("set_based", "set_based", "set-based occupancies"),
        ("unknown_type", "unknown_obstacle_type", "type 'unknown', which the world does not simulate"),
        ("garbage", "unreadable", "not a readable CommonRoad file"),
        ("missing", "unreadable", "no such file"),
        ("ego_inside", "ego_overlaps", "initial state overlaps car_13 by 1.50 m"),
    ],
)
def test_files_that_cannot_become_scenarios_are_refused_with_the_reason(tmp_path, case, reason, match):
    if case == "no_problem":
        path = straight_road_file(tmp_path, problems=[])
    elif case == "set_based":
        path = straight_road_file(tmp_path, [set_based_obstacle(50)])
    elif case == "unknown_type":
        odd = moving_obstacle(
            51, ObstacleType.UNKNOWN, Rectangle(2, 2), 0, straight_line((60, 0), 1, 0, 5), 0.0
        )
        path = straight_road_file(tmp_path, [odd])
    elif case == "ego_inside":  # a car 3 m ahead of the ego's centre: 4.5 / 2 + 4.5 / 2 - 3 = 1.5 m
        car = moving_obstacle(
            13, ObstacleType.CAR, Rectangle(4.5, 1.8), 0, straight_line((23, -LANE / 2), 5, 0, 20), 0.0
        )
        path = straight_road_file(tmp_path, [car])
    elif case == "garbage":
        path = tmp_path / "garbage.xml"
        path.write_text("<commonRoad><broken")
    else:
        path = tmp_path / "missing.xml"
    with pytest.raises(CommonRoadImportError, match=match) as error:
        import_commonroad(path)
    assert error.value.reason == reason and str(path) in str(error.value)
    # A batch stores only the message: the key is read back from it.
    assert rejection_reason(f"CommonRoadImportError: {error.value}") == reason


def test_references_choose_a_planning_problem_and_resolve_through_the_sources(tmp_path):
    path = straight_road_file(
        tmp_path, problems=[planning_problem(100), planning_problem(7, start=(40.0, LANE / 2))]
    )
    assert split_reference(f"{path}#7") == (path, 7)
    default = resolve_scenario(str(path))
    assert default.ego.pose[0] == pytest.approx(40.0)  # the lowest id, 7
    assert any("planning problem 7 of [7, 100]" in n for n in default.notes)
    chosen = load_commonroad(f"{path}#100")
    assert chosen.ego.pose[0] == pytest.approx(20.0) and chosen.name.endswith("-pp100")
    with pytest.raises(CommonRoadImportError, match=r"no planning problem 3; the file has \[7, 100\]"):
        load_commonroad(f"{path}#3")


# --------------------------------------------------------------------------- the shared real files

REAL = [
    "drivability-checker-datasets/highD/DEU_LocationALower26-1_261353_T-1428.cr.xml",
    "drivability-checker-datasets/SinD/CHN_SIND-8021_1_T-75.cr.xml",
    "drivability-checker-datasets/exiD/DEU_AachenBrand-1_431052_T-1127.cr.xml",
    "tum-cps-scenarios/NGSIM/USA_US101-21_1_T-1.xml",
    "commonroad-io-tests/USA_Peach-4_8_T-1.xml",
]


@needs_shared
@pytest.mark.parametrize("relative", REAL)
def test_real_recordings_replay_without_collisions_within_a_decimetre(relative):
    scenario = import_commonroad(SHARED / relative)
    report = replay(scenario, until=min(scenario.duration, 6.0))
    assert report.collisions == ()
    assert report.overall_rms < 0.1, report.tracking_rms


@needs_shared
@pytest.mark.parametrize(
    "relative,reason",
    [
        ("tum-cps-scenarios/ZAM_Intersect-1_1_S-1.xml", "set_based"),
        ("commonroad-io-tests/DEU_Starnberg-1_1_T-1.xml", "no_planning_problem"),
        ("tum-cps-scenarios/DEU_Muc-2_1_T-1.xml", "no_route"),
        ("drivability-checker-datasets/SinD/CHN_SIND-7281_1_T-75.cr.xml", "ego_overlaps"),
    ],
)
def test_real_unusable_files_are_refused(relative, reason):
    with pytest.raises(CommonRoadImportError) as error:
        import_commonroad(SHARED / relative)
    assert error.value.reason == reason


@needs_shared
def test_real_sind_pedestrians_are_round_and_off_the_lanelets():
    scenario = import_commonroad(SHARED / "drivability-checker-datasets/SinD/CHN_SIND-8021_1_T-75.cr.xml")
    area = shapely.union_all([shapely.Polygon(r) for r in scenario.road.map.area])
    walkers = [u for u in scenario.road_users if u.type is RoadUserType.PEDESTRIAN]
    assert walkers and all(u.length == u.width for u in walkers)
    starts = [shapely.Point(u.behaviour.trajectory.x[0], u.behaviour.trajectory.y[0]) for u in walkers]
    assert any(not area.covers(p) for p in starts)
    assert any(u.behaviour.trajectory.start > 0 for u in scenario.road_users)
    assert scenario.road_users[0].behaviour.trajectory.dt == pytest.approx(0.5)


def test_an_ego_starting_across_the_road_edge_gets_no_kerb_there(tmp_path):
    # Centre 0.3 m inside the right edge: the ego's right side sticks 0.5 m out of the road.
    start = planning_problem(start=(20.0, -LANE + 0.3))
    scenario = import_commonroad(straight_road_file(tmp_path, problems=[start]))
    assert any("starts across the lanelets' outline" in n for n in scenario.notes)
    World(scenario)  # builds: no kerb overlaps the ego at the start
    right = [b for b in scenario.road.map.boundaries if min(y for _, y in b) < -LANE + 0.1]
    ends = sorted(x for b in right for x in (b[0][0], b[-1][0]))
    # The right edge is cut around the ego (4.5 m long, 1 m clearance): a gap from about 16.7 to 23.3 m.
    assert any(15.5 < x < 17.5 for x in ends) and any(22.5 < x < 24.5 for x in ends)


def test_a_map_of_separate_roads_is_recorded(tmp_path):
    # A parallel road 12 m away, not connected: the drivable area is two polygons.
    path = straight_road_file(tmp_path, extra_lanelets=[lanelet(9, 0, 200, 12.0)])
    scenario = import_commonroad(path)
    assert len(World(scenario).road.drivable_area.geoms) == 2
    recorder = RerunRecorder(tmp_path / "rec", RecorderConfig(candidates=0))
    summary = run_scenario(replace(scenario, duration=0.2), "keep_lane", 0, observer=recorder)
    assert summary.outcome == "timeout" and recorder.path.stat().st_size > 0


def test_close_union_fills_slivers_between_lanelets_but_keeps_islands():
    left = shapely.box(0.0, 0.0, 10.0, 3.5)
    right = shapely.box(0.0, 3.52, 10.0, 7.02)  # 2 cm apart: edges that miss each other
    merged = close_union([left, right])
    assert merged.geom_type == "Polygon" and len(merged.interiors) == 0
    assert merged.area == pytest.approx(10.0 * 7.02, rel=1e-6)  # the gap filled, corners kept
    island = shapely.box(0.0, 0.0, 10.0, 10.0).difference(shapely.box(4.0, 4.0, 6.0, 6.0))
    assert close_union([island]).area == pytest.approx(100.0 - 4.0, rel=1e-6)
    apart = close_union([left, shapely.box(0.0, 4.0, 10.0, 7.5)])  # 0.5 m apart: two roads
    assert apart.geom_type == "MultiPolygon"


@needs_shared
def test_real_ngsim_map_has_no_kerbs_inside_the_road():
    # US101's lanelets miss each other by millimetres: without closing, 79 holes lined with kerbs.
    scenario = import_commonroad(SHARED / "tum-cps-scenarios/hand-crafted/USA_US101-11_2_T-1.xml")
    area = close_union([shapely.Polygon(a) for a in scenario.road.map.area])
    assert area.geom_type == "Polygon" and len(area.interiors) == 0
    outline = area.exterior
    assert all(outline.distance(shapely.Point(p)) < 0.2 for b in scenario.road.map.boundaries for p in b)


@needs_shared
def test_real_a9_kerbs_lie_outside_the_road():
    # DEU_A9-3_1: the simplified outline of the left lane runs up to 0.08 m inside the road
    # over a 100 m segment, where a 5 cm probe took the road for the outside: its kerb stood
    # 0.3 m into the lane and every planner's ego scraped it at 28 m/s (t = 2.9-4.6 s).
    scenario = import_commonroad(SHARED / "commonroad-io-tests/DEU_A9-3_1_T-1.xml")
    road = build_road(scenario.road)
    boxes = road.static_boxes()
    assert len(boxes) > 20
    assert not any(road.drivable_area.contains(shapely.Point(b.center)) for b in boxes)
    # The ethical ego's front-left corner touched the kerb at (414.90, -5860.77), 0.4 m inside
    # the lane's edge (y = -5860.37 there): the kerb now begins at the edge.
    nearest = min(box_footprint(b).distance(shapely.Point(414.90, -5860.77)) for b in boxes)
    assert nearest == pytest.approx(0.4, abs=0.1)


@needs_shared
def test_real_lanker_kerbs_stand_off_the_road():
    # USA_Lanker-2_10: lanelets that part at an angle leave wedge-shaped cracks in the map;
    # their kerbs stood across the crack's tip on the next lane (0.45 m into it). In the
    # study (main 4293038) the ethical and the standard ego's front-right corner met one
    # at (-13.36, -23.94) at 8.3 m/s, 0.29 m inside the drivable area.
    scenario = import_commonroad(SHARED / "tum-cps-scenarios/NGSIM/USA_Lanker-2_10_T-1.xml")
    road = build_road(scenario.road)
    area = road.drivable_area
    boxes = road.static_boxes()
    assert len(boxes) > 50
    assert min(box_footprint(b).distance(shapely.Point(-13.36, -23.94)) for b in boxes) > 1.0
    # Independent of the rule: a 5 cm grid over every box, the deepest point in the road.
    deepest = 0.0
    for b in boxes:
        u, v = np.meshgrid(np.arange(-b.half_length, b.half_length + 1e-9, 0.05), np.linspace(-0.2, 0.2, 9))
        c, s = math.cos(b.yaw), math.sin(b.yaw)
        points = shapely.points(b.center[0] + u * c - v * s, b.center[1] + u * s + v * c).ravel()
        inside = points[shapely.contains(area, points)]
        if inside.size:
            deepest = max(deepest, float(shapely.distance(area.boundary, inside).max()))
    assert deepest < 0.15  # the outline's simplification (0.1 m, then 0.05 m); was 0.45


def test_a_run_ends_with_goal_when_the_ego_enters_its_goal_region(tmp_path):
    # The goal region (10 m x 3 m) lies on the ego's lane 50-60 m ahead; at about 10 m/s
    # the ego's centre enters it after about 5 s, long before the 10 s time limit. The
    # goal is the region, not the end of the route (which the path extends beyond the map).
    problem = planning_problem(goal=((75.0, -LANE / 2), 10.0, 3.0), goal_steps=(0, 100))
    scenario = import_commonroad(straight_road_file(tmp_path, problems=[problem]))
    summary = run_scenario(scenario, "standard", 0)
    assert summary.outcome == "goal", summary.reason
    assert "goal region" in summary.reason
    assert 3.5 < summary.duration < 7.0


def test_a_goal_of_time_only_is_a_goal_once_its_time_has_passed(tmp_path):
    problem = planning_problem(goal=None, goal_steps=(0, 30))
    scenario = import_commonroad(straight_road_file(tmp_path, problems=[problem]))
    summary = run_scenario(scenario, "standard", 0)
    assert summary.outcome == "goal", summary.reason
    assert "goal time 3 s" in summary.reason
    assert summary.duration == pytest.approx(3.0, abs=0.05)


def test_an_ego_that_passes_beside_its_goal_region_leaves_the_map_at_its_end(tmp_path):
    # The road ends at x = 300 m. The goal region (x 280-290 m) lies on the ego's lane,
    # its near edge 0.40 m right of the lane's centre line: the ego's centre (on the
    # centre line) passes beside it, which is not reaching it (CommonRoad's
    # GoalRegion.is_reached asks the position inside the region). The ego keeps its lane
    # at 10 m/s (a scripted manoeuvre: the planners stop at a map's end unless an
    # evasion takes them past it, as in the study's SinD runs) along the path's straight
    # extension and leaves the map: left_map, just past x = 300 m (the map's end at
    # s = 100 m along the path, which starts on lanelet 3 at x = 200 m) after about 4 s,
    # at most 1 m (0.1 s at 10 m/s) beyond it, long before the 8 s time
    # limit, and the reason says how close it came to the goal region.
    problem = planning_problem(start=(260.0, -LANE / 2), goal=((285.0, -LANE / 2 - 0.9), 10.0, 1.0))
    scenario = import_commonroad(straight_road_file(tmp_path, problems=[problem]))
    summary = run_scenario(scenario, "keep_lane", 0)
    assert summary.outcome == "left_map", summary.reason
    assert "the mapped road ends at s = 100.0 m" in summary.reason
    beyond = float(summary.reason.split("the ego left the map ")[1].split(" m")[0])
    assert 0.0 < beyond <= 1.05  # checked at 10 Hz at 10 m/s
    closest = float(summary.reason.split("came within ")[1].split(" m")[0])
    assert closest == pytest.approx(0.40, abs=0.1)
    assert 3.5 < summary.duration < 6.0
