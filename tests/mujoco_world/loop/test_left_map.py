"""The ``left_map`` stop rule: where a mapped road ends along the ego's route, and the rule."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from shapely.geometry import box

from ethical_planner.reference_path import ReferencePath
from mujoco_world.loop.rules import NO_CRASH_OUTCOMES, LeftMap
from mujoco_world.loop.runner import run_scenario
from mujoco_world.loop.state import RunState
from mujoco_world.loop.summary import OUTCOMES
from mujoco_world.loop.world import World
from mujoco_world.scenario.commonroad_tracks import shared_commonroad
from mujoco_world.scenario.road import MAP_END_STEP_M, map_end
from mujoco_world.scenario.spec import ContactSpec, scenario_from_dict

SHARED = shared_commonroad()
needs_shared = pytest.mark.skipif(SHARED is None, reason="../shared/commonroad is absent")
SIND_8021_225 = "drivability-checker-datasets/SinD/CHN_SIND-8021_225_T-300.cr.xml"
SIND_834_752 = "drivability-checker-datasets/SinD/CHN_SIND-834_752_T-827.cr.xml"

STRAIGHT = ReferencePath.from_polyline(np.column_stack([np.linspace(0.0, 200.0, 21), np.zeros(21)]))


def test_the_map_ends_where_the_path_leaves_the_area_for_good():
    # A 40 m x 4 m road along the path: the path leaves it at x = 40 m.
    road = box(0.0, -2.0, 40.0, 2.0)
    assert map_end(road, STRAIGHT, 5.0) == pytest.approx(40.0, abs=MAP_END_STEP_M)
    # A 1 m sliver cut across the road (a joint between lanelets) is bridged, and so is a
    # 3 m gap (a junction or median the map leaves out): the path comes back onto the
    # road, so the map goes on; it ends where the path leaves it for good.
    sliver = box(0.0, -2.0, 20.0, 2.0).union(box(21.0, -2.0, 40.0, 2.0))
    assert map_end(sliver, STRAIGHT, 5.0) == pytest.approx(40.0, abs=MAP_END_STEP_M)
    gap = box(0.0, -2.0, 20.0, 2.0).union(box(23.0, -2.0, 40.0, 2.0))
    assert map_end(gap, STRAIGHT, 5.0) == pytest.approx(40.0, abs=MAP_END_STEP_M)
    # A second stretch of road the path crosses 60 m beyond the first one's end: the map
    # ends only past it.
    crossing = box(0.0, -2.0, 40.0, 2.0).union(box(100.0, -30.0, 104.0, 30.0))
    assert map_end(crossing, STRAIGHT, 5.0) == pytest.approx(104.0, abs=MAP_END_STEP_M)
    # A path that starts off the road (an ego on the pavement) is followed until it enters.
    assert map_end(box(10.0, -2.0, 40.0, 2.0), STRAIGHT, 0.0) == pytest.approx(40.0, abs=MAP_END_STEP_M)
    # A road that covers the whole path, or that the path never enters: no end.
    assert map_end(box(-1.0, -2.0, 250.0, 2.0), STRAIGHT, 0.0) == math.inf
    assert map_end(box(0.0, 10.0, 40.0, 14.0), STRAIGHT, 0.0) == math.inf


def _map_scenario(goal_region=()):
    """A 40 m mapped road along x (y in [-2, 2]) with a road off to the right at its end
    (x 36-46 m, y -8 to -2 m); the ego's path runs on straight to x = 200 m; no road users."""
    return scenario_from_dict(
        {
            "name": "short_map",
            "duration": 5.0,
            "road": {
                "kind": "map",
                "length": 200.0,
                "boundary": "none",
                "map": {
                    "area": [
                        [[0.0, -2.0], [40.0, -2.0], [40.0, 2.0], [0.0, 2.0]],
                        [[36.0, -8.0], [46.0, -8.0], [46.0, -2.0], [36.0, -2.0]],
                    ],
                    "reference_path": [[0.0, 0.0], [200.0, 0.0]],
                },
            },
            "ego": {"s0": 5.0, "speed": 10.0, "goal_region": goal_region},
        }
    )


def _ego_at(world, x, y):
    n = world.n
    world.scene.set_states(
        np.r_[x, world.positions[1:, 0]],
        np.r_[y, world.positions[1:, 1]],
        np.zeros(n),
        np.zeros(n),
        np.zeros(n),
    )


def test_the_rule_fires_off_the_map_beyond_its_end_only():
    goal = [[[20.0, 1.0], [30.0, 1.0], [30.0, 2.0], [20.0, 2.0]]]  # 1 m left of the path
    scenario = _map_scenario(goal_region=goal)
    world = World(scenario)
    run = RunState(world, scenario, "test", 0)
    rule = LeftMap(rate=10.0, interval_multiple=10)
    rule.start(run)
    assert rule.interval == 100  # 0.1 s at 1 ms steps
    assert rule.end == pytest.approx(40.0, abs=MAP_END_STEP_M)
    _ego_at(world, 25.0, 0.0)  # on the road, beside the goal region
    assert rule.check(run) is None
    _ego_at(world, 30.0, -3.0)  # off the road's side, before its end: not left_map
    assert rule.check(run) is None
    _ego_at(world, 40.0 - 0.2, 1.0)  # still on the road at its end
    assert rule.check(run) is None
    _ego_at(world, 43.0, -4.0)  # beyond the end along the path, but on the side road
    assert rule.check(run) is None
    _ego_at(world, 42.5, 0.0)
    stop = rule.check(run)
    assert stop.outcome == "left_map"
    assert "left the map 2.5 m beyond its end" in stop.reason
    assert "came within 1.00 m of its goal region" in stop.reason
    # After a crash the crash rules end the run.
    run.crash_time = 1.0
    assert rule.check(run) is None


def test_left_map_is_an_outcome_without_a_crash():
    assert "left_map" in OUTCOMES and "left_map" in NO_CRASH_OUTCOMES


def test_the_rule_is_off_on_catalog_roads():
    # A straight catalog road ends too (at its length), but the ego's goal lies on the
    # route before it (ego.goal_s is validated), so no catalog run meets the end.
    scenario = scenario_from_dict({"name": "straight", "road": {"length": 100.0}, "ego": {"s0": 5.0}})
    rule = LeftMap()
    rule.start(RunState(World(scenario), scenario, "test", 0))
    assert rule.end == math.inf


@needs_shared
def test_real_sind_map_ends_at_the_route_lanelets_end_and_a_lane_keeper_leaves_it():
    # SinD 8021_225: the route's last lanelet (id 1, no successor) ends on the edge from
    # (12.68, 43.65) to (16.79, 43.69) (commonroad-io, read here); the path crosses it at
    # x = 14.74 m, where the edge lies at y = 43.67 m.
    pytest.importorskip("commonroad")
    from commonroad.common.file_reader import CommonRoadFileReader

    from mujoco_world.scenario.commonroad import load_commonroad

    path = SHARED / SIND_8021_225
    network = CommonRoadFileReader(str(path)).open()[0].lanelet_network
    last = network.find_lanelet_by_id(1)
    assert not last.successor
    (x0, y0), (x1, y1) = last.left_vertices[-1], last.right_vertices[-1]
    scenario = load_commonroad(str(path))
    world = World(scenario)
    end = map_end(world.road.drivable_area, world.ego_path, world.ego_progress())
    ex, ey = (float(v[0]) for v in world.ego_path.evaluate(np.array([end]))[:2])
    edge_y = y0 + (ex - x0) / (x1 - x0) * (y1 - y0)
    assert ey == pytest.approx(edge_y, abs=MAP_END_STEP_M)
    # Its goal region ends 4.4 m before the map (y <= 39.22 m).
    assert ey - world.goal_area.bounds[3] == pytest.approx(4.4, abs=0.1)
    # Without its goal region and traffic, an ego that keeps its lane (7.71 m/s) drives
    # the 11.7 m from its start to the map's end in 1.5 s and leaves the map at the next
    # 0.1 s check.
    alone = replace(scenario, ego=replace(scenario.ego, goal_region=()), road_users=(), contact=ContactSpec())
    summary = run_scenario(alone, "keep_lane", 0)
    assert summary.outcome == "left_map", summary.reason
    assert f"the mapped road ends at s = {end:.1f} m" in summary.reason
    assert summary.duration == pytest.approx((end - world.ego_progress()) / 7.71, abs=0.15)


@needs_shared
@pytest.mark.slow
def test_real_sind_ethical_ego_passes_beside_its_goal_region_and_leaves_the_map():
    # SinD 834_752 (the study's ethical run stood 4 m beyond the map's end until the
    # time limit, stopped_safely, level 2 on 228 of 375 cycles): it now ends left_map
    # at 16.3 s, 0.29 m beside its goal region.
    pytest.importorskip("commonroad")
    from mujoco_world.scenario.commonroad import load_commonroad

    summary = run_scenario(load_commonroad(str(SHARED / SIND_834_752)), "ethical", 0)
    assert summary.outcome == "left_map", summary.reason
    assert summary.duration == pytest.approx(16.3, abs=0.5)
    assert "came within 0.29 m of its goal region" in summary.reason
