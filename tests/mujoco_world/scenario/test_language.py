"""Scenario language: leaving at the road's end, child and debris types, the [expect] table."""

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest

from ethical_planner.records import from_mapping, to_plain
from ethical_planner.risk import outside_drivable_area
from ethical_planner.road_users import KinematicState, RoadUserType, Shape
from mujoco_world.evaluation.compare import compare_impact
from mujoco_world.loop.expectations import EXPECTATIONS, check_expectations
from mujoco_world.loop.runner import run_scenario
from mujoco_world.loop.summary import RunSummary
from mujoco_world.loop.world import PARK_ORIGIN_M, World
from mujoco_world.physics.impact import measure_impact
from mujoco_world.physics.scene import STATIC
from mujoco_world.scenario.road import build_road, debris_boxes
from mujoco_world.scenario.spec import (
    Boundary,
    DebrisSpec,
    ExpectSpec,
    RoadSpec,
    RoadUserSpec,
    Scenario,
    scenario_from_dict,
)
from mujoco_world.storage.run_record import RunRecord


def _scenario(**overrides):
    data = {
        "name": "t",
        "road": {"length": 60.0},
        "ego": {"s0": 5.0, "speed": 0.0},
        "road_users": [
            {"name": "car", "type": "car", "s0": 45.0, "behaviour": {"kind": "scripted", "speed": 10.0}}
        ],
    }
    data.update(overrides)
    return scenario_from_dict(data)


# ----------------------------------------------------------------------------- road's end


def test_a_road_user_leaves_the_world_once_its_rear_passes_the_roads_end():
    world = World(_scenario())
    # Rear past x = 60: centre at 60 + 4.5 / 2 = 62.25 m, reached at (62.25 - 45) / 10 = 1.725 s.
    while world.time < 1.70:
        world.step()
    assert world.present[1] and np.isnan(world.exit_pose[1]).all()
    while world.time < 1.80:
        world.step()
    assert not world.present[1] and world.fleet.left[0]
    (t_leave, entity, what), *_ = world.presence_events
    assert (entity, what) == (1, "leave")
    assert t_leave == pytest.approx(1.725, abs=0.015)
    assert world.exit_pose[1, 0] == pytest.approx(62.25, abs=0.3)
    assert world.exit_pose[1, 1] == pytest.approx(-1.75, abs=0.05)
    # Out of the world: parked far away at rest, no contacts, unseen, at the distance cap.
    for _ in range(200):
        world.step()
    assert world.positions[1, 0] >= PARK_ORIGIN_M
    assert world.present[0] and len(world.presence_events) == 1  # it does not come back
    assert np.all(world.velocities[1] == 0.0)
    geom = world.scene.geom_ids[1]
    assert world.scene.model.geom_contype[geom] == 0 and world.scene.model.geom_conaffinity[geom] == 0
    _, users = world.observe()
    assert users == []
    assert world.ego_distances(distmax=50.0)[0] == 50.0


def test_a_road_user_leaving_one_fork_of_a_run_stays_in_the_others():
    """Forks (avoidability branches) share the MuJoCo model; leaving must not reach across."""
    import copy

    # Soft contact: the only mode in which MuJoCo's own contacts (contype) are on.
    world = World(_scenario(contact={"mode": "soft"}))
    while world.time < 1.0:
        world.step()
    fork = copy.deepcopy(world)
    while fork.time < 1.80:
        fork.step()
    geom = world.scene.geom_ids[1]
    assert not fork.present[1] and fork.scene.model.geom_contype[geom] == 0
    assert world.present[1] and world.scene.model.geom_contype[geom] != 0
    assert world.scene.model.geom_conaffinity[geom] != 0 and not world.fleet.left[0]


def test_a_crashed_road_user_does_not_leave():
    world = World(_scenario())
    world.crashed[1] = True
    world.fleet.deactivate(np.array([True]))
    world.fleet.s[0] = 100.0
    world.step()
    assert not world.fleet.left[0] and world.present[1]


# ----------------------------------------------------------------------------- child


def test_a_child_is_a_small_light_pedestrian():
    spec = RoadUserSpec(name="kid", type="child")
    assert spec.type is RoadUserType.PEDESTRIAN and spec.kind == "child"
    assert spec.shape == (0.3, 0.3) and spec.body_mass == 23.0
    heavier = RoadUserSpec(name="kid", type="child", mass=30.0, width=0.35)
    assert heavier.body_mass == 30.0 and heavier.shape == (0.3, 0.35)
    # The stored form (type pedestrian, kind child) reads back to the same record.
    assert from_mapping(RoadUserSpec, to_plain(spec)) == spec
    adult = RoadUserSpec(name="adult", type="pedestrian")
    assert adult.kind is None and adult.body_mass is None and adult.shape == (0.5, 0.5)


def test_a_child_in_the_world_and_in_the_summary():
    scenario = _scenario(
        road_users=[{"name": "kid", "type": "child", "s0": 30.0, "route": {"offset": -3.0}}], duration=0.2
    )
    world = World(scenario)
    assert world.scene.masses[1] == pytest.approx(23.0)
    assert world.scene.bodies[1].radius == pytest.approx(0.15)
    summary = run_scenario(scenario, "keep_lane", seed=0)
    assert summary.body(1).kind == "child" and summary.body(1).type is RoadUserType.PEDESTRIAN
    assert summary.body(0).kind is None


@pytest.mark.parametrize(
    ("user", "message"),
    [
        ({"name": "a", "type": "kid"}, "road_users[0]: type: unknown road-user type 'kid'; allowed: car"),
        ({"name": "a", "type": "car", "kind": "child"}, "road_users[0].kind must be one of ['child']"),
        ({"name": "a", "type": "child", "kind": "dwarf"}, "road_users[0].kind: type 'child' cannot"),
    ],
)
def test_bad_kinds_are_named(user, message):
    with pytest.raises(ValueError, match=re_escape(message)):
        _scenario(road_users=[user])


def re_escape(text):
    import re

    return re.escape(text)


# ----------------------------------------------------------------------------- debris


def test_debris_sits_where_its_arc_length_and_offset_say():
    straight = build_road(RoadSpec(length=100.0))
    (box,) = debris_boxes(straight, (DebrisSpec("b", s=50.0, offset=-1.75, length=1.2, width=1.0, yaw=30.0),))
    assert box.center == pytest.approx((50.0, -1.75))
    assert box.yaw == pytest.approx(math.radians(30.0))
    assert (box.half_length, box.half_width) == (0.6, 0.5)
    assert box.kind is Boundary.WALL
    curved = build_road(RoadSpec(kind="curved", length=200.0, radius=80.0, curve_angle=60.0, lead_in=40.0))
    arc = math.radians(30.0)
    (box,) = debris_boxes(curved, (DebrisSpec("b", s=40.0 + 80.0 * arc, offset=2.0),))
    # 30 degrees into the left-hand arc of radius 80 m, 2 m left of the centre line.
    x = 40.0 + 80.0 * math.sin(arc) - 2.0 * math.sin(arc)
    y = 80.0 * (1.0 - math.cos(arc)) + 2.0 * math.cos(arc)
    assert box.center == pytest.approx((x, y), abs=0.02)
    assert box.yaw == pytest.approx(arc, abs=0.01)


def test_debris_is_a_hole_the_planner_keeps_off_even_between_its_corners():
    scenario = _scenario(road_users=[], debris=[{"name": "tyre", "s": 40.0, "offset": -1.75, "length": 0.6}])
    env = World(scenario).environment()
    assert len(env.drivable_area.interiors) == 1
    ego = Shape(4.5, 1.8)
    # Centred on the debris: every corner of the ego lies outside it, the body over it.
    poses = SimpleNamespace(
        x=np.array([[40.0, 30.0, 40.0]]), y=np.array([[-1.75, -1.75, 1.75]]), yaw=np.zeros((1, 3))
    )
    outside = outside_drivable_area(poses, ego, env)
    assert outside.tolist() == [[True, False, False]]


def test_debris_under_the_ego_at_the_start_is_refused_naming_both():
    # The ego (4.508 x 1.61 m) at s0 = 5 m in lane 0 (offset -1.75 m) covers s 2.746 to
    # 7.254 m and offset -2.555 to -0.945 m.
    under = {"name": "rock", "s": 7.0, "offset": -1.0, "length": 1.0, "width": 1.0}
    message = "debris[0] (rock) lies under the ego at the start"
    with pytest.raises(ValueError, match=re_escape(message)) as info:
        _scenario(debris=[under])
    assert "s 2.746 to 7.254 m and offset -2.555 to -0.945 m (lane 0)" in str(info.value)
    # Rotated 45 deg, a 1 m square at s = 8.1 m reaches back to 7.39 m: clear of the front.
    _scenario(debris=[under | {"s": 8.1, "yaw": 45.0}])
    # At s = 7.9 m its corner (7.19 m) is under the front, and the second piece is named.
    with pytest.raises(ValueError, match=re_escape("debris[1] (stone) lies under the ego")):
        _scenario(debris=[under | {"s": 30.0}, under | {"name": "stone", "s": 7.9, "yaw": 45.0}])


def test_a_car_hitting_debris_hits_a_static_obstacle():
    scenario = _scenario(
        road={"length": 100.0},
        debris=[{"name": "rock", "s": 60.0, "offset": -1.75, "length": 1.0, "width": 1.0}],
        duration=2.5,
    )
    summary = run_scenario(scenario, "keep_lane", seed=0)
    # A collision without the ego is third-party: measured, but the run goes on.
    assert summary.outcome == "timeout" and not summary.ego_collided
    assert not summary.ego_collisions and summary.third_party_collisions
    record = summary.collisions[0]
    bodies = {record.measurement.a.entity, record.measurement.b.entity}
    assert bodies == {1, STATIC}
    static = record.a if record.measurement.a.entity == STATIC else record.b
    assert static.group == "static" and math.isnan(static.harm_measured)
    assert summary.harm["third_party"] > 0.0  # the car's occupants; debris adds nothing


def test_debris_is_validated_by_name():
    with pytest.raises(ValueError, match=re_escape("debris[0] (b).s must lie on the road")):
        _scenario(debris=[{"name": "b", "s": 90.0}])
    with pytest.raises(ValueError, match=re_escape("debris: duplicate names ['b']")):
        _scenario(debris=[{"name": "b", "s": 10.0}, {"name": "b", "s": 20.0}])
    with pytest.raises(ValueError, match=re_escape("debris[0].length must lie in [0.1, 20] m")):
        _scenario(debris=[{"name": "b", "s": 10.0, "length": 50.0}])
    # Two lanes of 3.5 m and 0.5 m shoulders: the road spans -4 to 4 m.
    with pytest.raises(ValueError, match=re_escape("(b).offset must put it on the road (-4 to 4 m")):
        _scenario(debris=[{"name": "b", "s": 30.0, "offset": 19.0}])
    assert _scenario(debris=[{"name": "b", "s": 30.0, "offset": -4.3}]).debris[0].offset == -4.3  # reaches in


# ----------------------------------------------------------------------------- [expect]


def _summary(**fields):
    base = {"scenario": "t", "planner": "p", "seed": 0, "outcome": "timeout", "reason": ""}
    return RunSummary(**{**base, **fields})


def test_every_expect_item_has_a_check():
    names = [f.name for f in dataclasses.fields(ExpectSpec)]
    assert list(EXPECTATIONS.names()) == names


def test_expectations_pass_and_fail_by_hand():
    summary = _summary(
        harm={"ego": 0.0, "third_party": 0.0, "vulnerable": 0.2},
        min_distance=math.nan,
        min_ttc=1.5,
        progress=50.0,
    )
    expect = ExpectSpec(
        outcome=("goal", "timeout"),
        reach_goal=True,
        ego_collision=False,
        max_vulnerable_harm=0.2,
        max_third_party_harm=0.0,
        min_distance=1.0,
        min_ttc=2.0,
        min_progress=50.0,
    )
    results = {r.name: r for r in check_expectations(expect, summary)}
    assert list(results) == [
        "outcome",
        "reach_goal",
        "ego_collision",
        "max_third_party_harm",
        "max_vulnerable_harm",
        "min_distance",
        "min_ttc",
        "min_progress",
    ]
    passed = {name: r.passed for name, r in results.items()}
    assert passed == {
        "outcome": True,
        "reach_goal": False,  # timeout is not the goal
        "ego_collision": True,
        "max_third_party_harm": True,
        "max_vulnerable_harm": True,  # bounds are inclusive
        "min_distance": True,  # no road user: nothing came closer
        "min_ttc": False,
        "min_progress": True,
    }
    assert (results["reach_goal"].expected, results["reach_goal"].measured) == ("true", "false")
    assert results["max_vulnerable_harm"].expected == "<= 0.2"
    assert results["outcome"].expected == "goal or timeout"
    stricter = check_expectations(ExpectSpec(max_vulnerable_harm=0.19), summary)
    assert [r.passed for r in stricter] == [False]


def _impact(ego, other, ego_entity=0):
    """A measured car-car impact (``physics.impact.measure_impact``), the ego first."""
    m = measure_impact("car", ego, "car", other, shape_a=(4.5, 1.8), shape_b=(4.5, 1.8))
    assert m is not None
    if ego_entity != 0:  # two other road users
        m = dataclasses.replace(m, a=dataclasses.replace(m.a, entity=ego_entity))
    return compare_impact(m)


def test_ego_strikes_and_max_ego_collisions_tell_a_struck_ego_from_one_that_strikes():
    # Approach speeds by hand: the ego at 2 m/s hit from behind by a car at 10 m/s moves
    # away from its rear contact (-2 m/s), the follower drives into it (+10 m/s); the
    # ego at 10 m/s into a car at 3 m/s ahead approaches at 10 m/s, the car leaves at 3.
    struck = _impact(KinematicState(0.0, 0.0, 0.0, 2.0), KinematicState(-6.0, 0.0, 0.0, 10.0))
    strikes = _impact(KinematicState(0.0, 0.0, 0.0, 10.0), KinematicState(6.0, 0.0, 0.0, 3.0))
    side = _impact(KinematicState(0.0, 0.0, 0.0, 0.0), KinematicState(0.0, 3.5, -math.pi / 2, 8.0))
    others = _impact(KinematicState(0.0, 0.0, 0.0, 10.0), KinematicState(6.0, 0.0, 0.0, 3.0), ego_entity=2)
    kerb = dataclasses.replace(strikes.measurement.b, entity=STATIC, type="kerb", velocity=(0.0, 0.0))
    into_kerb = dataclasses.replace(strikes, measurement=dataclasses.replace(strikes.measurement, b=kerb))
    assert struck.measurement.a.reduced_area == "rear"
    assert side.measurement.a.reduced_area == "driver_side"  # a car from the left into a standing ego
    expect = ExpectSpec(ego_collision=True, ego_strikes=False, max_ego_collisions=1)

    def check(*collisions):
        summary = _summary(collisions=collisions, ego_collided=any(c.involves_ego for c in collisions))
        return {r.name: (r.passed, r.measured) for r in check_expectations(expect, summary)}

    hit_only = check(struck, others)  # a third-party collision is not the ego's
    assert hit_only == {"ego_collision": (True, "true"), "ego_strikes": (True, "false"),
                        "max_ego_collisions": (True, "1")}  # fmt: skip
    assert check(side)["ego_strikes"] == (True, "false")
    assert check(strikes)["ego_strikes"] == (False, "true")
    assert check(into_kerb)["ego_strikes"] == (False, "true")
    # World-frame approach speeds (documented limit): a car 2 m ahead turning in at
    # 0.25 rad, both at about 10 m/s, meets the ego's front with its rear side; the ego's
    # approach (9.3 m/s) beats the cutter's (5.0 m/s), so it counts as the ego's strike.
    cut_in = _impact(KinematicState(0.0, 0.0, 0.0, 10.0), KinematicState(2.0, 3.0, -0.25, 10.3))
    assert cut_in.measurement.b.reduced_area == "right_side"
    assert check(cut_in)["ego_strikes"] == (False, "true")
    # Hit, then pushed into the car ahead: a second impact, one the ego drives into.
    assert check(struck, strikes) == {"ego_collision": (True, "true"), "ego_strikes": (False, "true"),
                                      "max_ego_collisions": (False, "2")}  # fmt: skip
    assert check()["ego_strikes"] == (True, "false")  # no contact: ego_collision = true fails instead
    assert check()["ego_collision"] == (False, "false")


def test_a_failed_run_fails_every_expectation_but_an_outcome_that_allows_it():
    failed = _summary(outcome="failed", harm={"vulnerable": 0.0})
    results = check_expectations(ExpectSpec(outcome=("failed",), max_vulnerable_harm=1.0), failed)
    assert [(r.name, r.passed) for r in results] == [("outcome", True), ("max_vulnerable_harm", False)]


def test_verdict_and_record_round_trip():
    assert _summary().verdict == "none"
    results = check_expectations(ExpectSpec(collision=False, max_collisions=0), _summary())
    summary = dataclasses.replace(_summary(), expectations=results)
    assert summary.verdict == "pass"
    record = RunRecord("t__p__s0", summary)
    assert RunRecord.from_dict(record.to_dict()).summary == summary
    unmet = check_expectations(ExpectSpec(reach_goal=True), summary)
    failing = dataclasses.replace(summary, expectations=unmet)
    assert failing.verdict == "fail"


@pytest.mark.parametrize(
    ("expect", "message"),
    [
        ({"outcome": "goals"}, "expect.outcome must name outcomes among goal, timeout"),
        ({"outcome": 3}, "expect.outcome must be an outcome name or a list of them, got 3"),
        ({"ego_collision": "no"}, "expect.ego_collision must be true or false, got 'no'"),
        ({"max_collisions": 1.5}, "expect.max_collisions"),
        ({"ego_strikes": 0}, "expect.ego_strikes must be true or false, got 0"),
        ({"max_ego_collisions": -1}, "expect.max_ego_collisions must be an integer >= 0, got -1"),
        ({"max_vulnerable_harm": -0.1}, "expect.max_vulnerable_harm must lie in [0, 1000]"),
        ({"reach_gaol": True}, "unknown key 'expect.reach_gaol'; allowed: collision, ego_collision"),
    ],
)
def test_bad_expectations_are_named(expect, message):
    with pytest.raises(ValueError, match=re_escape(message)):
        _scenario(expect=expect)


def test_run_scenario_checks_the_scenario_expectations():
    scenario = _scenario(
        road_users=[], duration=0.5, expect={"outcome": "timeout", "collision": False, "min_progress": 50.0}
    )
    summary = run_scenario(scenario, "keep_lane", seed=0)
    assert [(r.name, r.passed) for r in summary.expectations] == [
        ("outcome", True),
        ("collision", True),
        ("min_progress", False),
    ]
    assert summary.verdict == "fail"
    assert isinstance(scenario, Scenario)
