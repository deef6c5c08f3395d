"""Scenario records, TOML loading, road geometry, catalog and generator."""

import dataclasses
import math
import re
from importlib import resources

import numpy as np
import pytest
import shapely

from mujoco_world.loop.world import World
from mujoco_world.scenario.catalog import (
    catalog_names,
    generate_scenarios,
    generated_names,
    get_scenario,
    random_scenario,
)
from mujoco_world.scenario.road import BOUNDARY_THICKNESS_M, RoadGeometry, box_footprint, build_road
from mujoco_world.scenario.sources import SCENARIO_SOURCES, resolve_scenario
from mujoco_world.scenario.spec import RoadSpec, RouteSpec, Scenario, load_scenario, scenario_from_dict

EXAMPLE = resources.files("mujoco_world").joinpath("data", "example_scenario.toml")


def minimal(**overrides):
    data = {
        "name": "t",
        "road": {"length": 100.0},
        "ego": {"s0": 5.0, "speed": 5.0},
        "road_users": [
            {"name": "car", "type": "car", "s0": 40.0, "behaviour": {"kind": "scripted", "speed": 5.0}}
        ],
    }
    data.update(overrides)
    return data


def test_example_file_loads_and_builds():
    scenario = load_scenario(str(EXAMPLE))
    assert scenario.name == "example_cut_in"
    assert [u.name for u in scenario.road_users] == ["cutter", "leader", "cyclist"]
    assert scenario.road_users[1].behaviour.idm.reaction_time == 0.3
    World(scenario)


@pytest.mark.parametrize(
    ("patch", "message"),
    [
        ({"roads": {}}, "unknown key 'roads'"),
        ({"road": {"lenght": 3}}, r"unknown key 'road.lenght'; allowed: "),
        ({"road": {"lanes": 0}}, r"road.lanes must be an integer in 1..8"),
        (
            {"road": {"kind": "roundabout"}},
            r"road.kind: unknown road kind 'roundabout'; allowed: straight, curved, intersection",
        ),
        ({"ego": {"speed": -1.0}}, r"ego.speed must be >= 0"),
        ({"duration": float("nan")}, r"scenario.duration must be a finite number"),
        (
            {"road_users": [{"name": "x", "type": "car", "behaviour": {"kind": "idm", "sped": 3}}]},
            r"unknown key 'road_users\[0\].behaviour.sped'",
        ),
        (
            {"road_users": [{"name": "x", "type": "spaceship"}]},
            r"road_users\[0\]: type: unknown road-user type 'spaceship'",
        ),
        (
            {"road_users": [{"name": "x", "type": "car", "behaviour": {"speed_profile": [[2, 1], [1, 2]]}}]},
            r"road_users\[0\].behaviour.speed_profile times must be >= 0 and strictly increasing",
        ),
        (
            {"road_users": [{"name": "x", "type": "car", "route": {"lane": 5}}]},
            r"road_users\[0\] \(x\).route.lane must be < road.lanes",
        ),
        (
            {"road_users": [{"name": "x", "type": "car", "route": {"road": "cross"}}]},
            r"needs road.kind = 'intersection'",
        ),
        (
            {"road_users": [{"name": "x", "type": "car", "behaviour": {"kind": "scripted", "idm": {}}}]},
            r"road_users\[0\].behaviour.idm is only allowed with kind 'idm'",
        ),
        ({"road_users": [{"name": "a", "type": "car"}, {"name": "a", "type": "car", "s0": 30}]}, "duplicate"),
        (
            {"contact": {"restitution": [{"a": "car", "b": "car", "e": 0.99}]}},
            r"contact.restitution\[0\].e must lie",
        ),
    ],
)
def test_invalid_scenarios_name_the_field(patch, message):
    with pytest.raises(ValueError, match=message):
        scenario_from_dict(minimal(**patch))


def test_invalid_file_names_the_file_and_field(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('name = "bad"\n[ego]\nspeed = "fast"\n')
    with pytest.raises(ValueError, match=r"bad.toml: ego.speed must be a finite number, got .fast."):
        load_scenario(path)
    path.write_text("name = \n")
    with pytest.raises(ValueError, match="not valid TOML"):
        load_scenario(path)
    with pytest.raises(ValueError, match="cannot read"):
        load_scenario(tmp_path / "missing.toml")


def test_overlapping_start_is_rejected():
    data = minimal(road_users=[{"name": "car", "type": "car", "s0": 7.0}])
    with pytest.raises(ValueError, match="ego and car overlap at the start"):
        World(scenario_from_dict(data))


@pytest.mark.parametrize("kind", ["straight", "curved", "intersection"])
def test_routes_lie_in_the_drivable_area(kind):
    road = build_road(RoadSpec(kind=kind, length=200.0))
    area = road.drivable_area.buffer(1e-6)
    for lane in range(road.spec.lanes):
        for direction in (1, -1):
            turns = ("straight", "left", "right") if kind == "intersection" else ("straight",)
            for turn in turns:
                line = road.route(RouteSpec(lane=lane, direction=direction, turn=turn))
                assert area.contains(shapely.LineString(line)), (lane, direction, turn)
    # Walls and kerbs sit outside the drivable area.
    for box in road.static_boxes():
        assert not road.drivable_area.buffer(-0.01).contains(shapely.Point(box.center))


def test_curved_road_turns_by_its_angle():
    road = build_road(RoadSpec(kind="curved", length=200.0, radius=50.0, curve_angle=90.0, lead_in=20.0))
    end = road.main_line[-1] - road.main_line[-2]
    assert math.degrees(math.atan2(end[1], end[0])) == pytest.approx(90.0, abs=0.5)


def test_catalog_has_the_classics():
    names = catalog_names()
    assert len(names) >= 8
    for required in (
        "overtake_cyclist",
        "pedestrian_behind_parked",
        "highway_cut_in",
        "tailgater_sudden_stop",
        "red_light_runner",
        "turning_truck_cyclist",
        "oncoming_drift",
        "dense_urban",
    ):
        assert required in names
    assert len(get_scenario("dense_urban").road_users) >= 18


@pytest.mark.parametrize("name", catalog_names())
def test_catalog_scenarios_build(name):
    world = World(get_scenario(name))
    assert world.n == 1 + len(world.scenario.road_users)


def test_generator_is_reproducible_and_varied():
    n = len(catalog_names())  # one of each family
    first = list(generate_scenarios(n, seed=3))
    again = list(generate_scenarios(n, seed=3))
    other = list(generate_scenarios(n, seed=4))
    assert first == again
    assert first != other
    assert {s.name.split("-")[0] for s in first} == set(catalog_names())
    # Any scenario can be rebuilt alone from (seed, index).
    rebuilt = random_scenario(first[5].name.split("-")[0], np.random.default_rng([3, 5]), name=first[5].name)
    assert rebuilt == first[5]


def test_generated_names_rebuild_their_scenarios():
    names = generated_names(12, seed=9, families=["oncoming_drift", "dense_urban"])
    scenarios = list(generate_scenarios(12, seed=9, families=["oncoming_drift", "dense_urban"]))
    assert [s.name for s in scenarios] == names
    assert resolve_scenario(names[7]) == scenarios[7]
    assert resolve_scenario("dense_urban") == get_scenario("dense_urban")
    with pytest.raises(ValueError, match="unknown scenario 'warp_drive'; allowed: overtake_cyclist"):
        resolve_scenario("warp_drive-s1-2")


def test_scenario_names_resolve_through_the_sources():
    assert SCENARIO_SOURCES.names() == ("toml", "commonroad", "generated", "catalog")
    assert resolve_scenario(str(EXAMPLE)).name == "example_cut_in"
    with pytest.raises(ValueError) as error:
        resolve_scenario("warp_drive")
    message = str(error.value)
    assert message.startswith("unknown scenario 'warp_drive'; allowed: a scenario file *.toml; ")
    assert "a CommonRoad file *.xml" in message
    assert "<family>-s<seed>-<index>" in message and "dense_urban" in message
    with pytest.raises(ValueError, match="cannot read scenario file missing.toml"):
        resolve_scenario("missing.toml")


def test_random_scenarios_build_without_overlap():
    for scenario in generate_scenarios(27, seed=11):
        World(scenario)


def test_every_family_draws_valid_random_variants():
    # red_light_for_ego put its cross car at s0 < 0 for cross speeds above 13.3 m/s;
    # the 27 mixed variants above drew none of them.
    for family in catalog_names():
        for k in range(30):
            random_scenario(family, np.random.default_rng([17, k]))


def test_scenarios_are_frozen():
    scenario = get_scenario("oncoming_drift")
    with pytest.raises(dataclasses.FrozenInstanceError):
        scenario.duration = 3.0  # type: ignore[misc]
    assert isinstance(scenario, Scenario)


def test_the_readme_lists_every_plausible_range():
    from pathlib import Path

    from mujoco_world.scenario.spec import RANGES

    readme = (Path(__file__).resolve().parents[3] / "mujoco_world" / "README.md").read_text()
    listed = re.findall(r"^\| `([a-z0-9_.]+)` \| ([-0-9.e]+) \.\. ([-0-9.e]+) \| (\S+) \|$", readme, re.M)
    assert {k: (float(lo), float(hi), unit) for k, lo, hi, unit in listed} == RANGES


@pytest.mark.parametrize(
    ("where", "value", "message"),
    [
        (("road", "length"), 0.001, "road.length must lie in [10, 20000] m, got 0.001"),
        (("ego", "mass"), 1e30, "ego.mass must lie in [100, 60000] kg"),
        (("ego", "s0"), -50.0, "ego.s0 must lie in [0, 20000] m"),
        (("ego", "goal_s"), 5000.0, "ego.goal_s must lie between ego.s0 (5 m) and road.length (100 m)"),
        (("road", "speed_limit"), 1e-9, "road.speed_limit must lie in [1, 70] m/s"),
        (("contact", "friction"), 3.0, "contact.friction must lie in [0, 2]"),
    ],
)
def test_implausible_values_are_refused_by_name(where, value, message):
    data = minimal()
    data.setdefault(where[0], {})[where[1]] = value
    with pytest.raises(ValueError, match=re.escape(message)):
        scenario_from_dict(data)


def test_each_range_bound_is_inclusive_and_a_step_beyond_is_refused():
    from mujoco_world.scenario.spec import RANGES

    for key in ("road.lane_width", "ego.speed", "contact.timeconst"):
        owner, name = key.split(".")
        low, high, _ = RANGES[key]
        for ok in (low, high):
            data = minimal()
            data.setdefault(owner, {})[name] = ok
            scenario_from_dict(data)
        data = minimal()
        data.setdefault(owner, {})[name] = high * 1.001 + 1e-9
        with pytest.raises(ValueError, match=re.escape(f"{key} must lie in")):
            scenario_from_dict(data)


def test_a_boundary_a_little_inside_the_road_gets_its_kerb_on_the_outside():
    # A 10 m wide road, y in [0, 10]; its left boundary simplified to y = 9.92 (8 cm inside,
    # as an imported outline can be). By hand: the kerb (0.4 m) lies on the outer side of the
    # line, centre y = 9.92 + 0.2 = 10.12, not at 9.72 inside the lane.
    spec = RoadSpec(kind="straight", length=100.0, boundary="kerb")
    area = shapely.box(0.0, 0.0, 100.0, 10.0)
    line = np.array([[0.0, 9.92], [100.0, 9.92]])
    road = RoadGeometry(spec, np.array([[0.0, 5.0], [100.0, 5.0]]), None, area, (line,))
    (kerb,) = road.static_boxes()
    assert kerb.center == pytest.approx((50.0, 9.92 + 0.5 * BOUNDARY_THICKNESS_M))


def test_no_kerb_in_a_crack_between_lanelets_narrower_than_the_kerb():
    # Two lanes that part at an angle (the tip of the gap between lanelets at a diverging
    # lane): lane A is y in [0, 3.5]; lane B's lower edge rises from (0, 3.5) by 2 cm per
    # metre. By hand: the crack is as wide as a kerb (0.4 m) at x = 20 m; nearer the tip a
    # kerb would stand on the other lane. The kerb along A's edge starts there (within one
    # 0.1 m sample), not at x = -0.2 m, 0.4 m deep into lane B at the tip.
    spec = RoadSpec(kind="straight", length=100.0, boundary="kerb")
    lane_a = shapely.box(0.0, 0.0, 100.0, 3.5)
    lane_b = shapely.Polygon([(0.0, 3.5), (100.0, 5.5), (100.0, 9.0), (0.0, 7.0)])
    area = shapely.union_all([lane_a, lane_b])
    edge_a = np.array([[0.0, 3.5], [100.0, 3.5]])
    edge_b = np.array([[0.0, 3.5], [100.0, 5.5]])
    road = RoadGeometry(spec, np.array([[0.0, 1.75], [100.0, 1.75]]), None, area, (edge_a, edge_b))
    kerbs = road.static_boxes()
    # Along A's edge: the long kerb, and a 0.2 m stub off the road before the crack's tip.
    stub, kerb_a = sorted((k for k in kerbs if abs(k.yaw) < 1e-9), key=lambda k: k.half_length)
    assert stub.center[0] + stub.half_length <= 0.0 + 1e-9
    assert kerb_a.center[0] - kerb_a.half_length == pytest.approx(20.0, abs=0.11)
    assert kerb_a.center[0] + kerb_a.half_length == pytest.approx(100.0 + 0.5 * BOUNDARY_THICKNESS_M)
    for kerb in kerbs:  # no kerb reaches more than a few centimetres into either lane
        assert box_footprint(kerb).intersection(area).area < 0.2 * 0.1


def test_a_kerb_ends_at_an_inner_corner_of_the_road():
    # A side road (x in [40, 50]) leaves the main road (y in [0, 10]) to the left; the main
    # road's left edge turns up the side road's left edge at (40, 10). By hand: a box runs
    # t / 2 = 0.2 m past its segment's end to close outer corners, but here that end would
    # stand in the side road, x in [40, 40.2]: the box ends at x = 40 and the side road's
    # kerb starts at y = 10 (the two still overlap: the corner stays closed).
    spec = RoadSpec(kind="straight", length=100.0, boundary="kerb")
    area = shapely.union_all([shapely.box(0.0, 0.0, 100.0, 10.0), shapely.box(40.0, 10.0, 50.0, 60.0)])
    edge = np.array([[0.0, 10.0], [40.0, 10.0], [40.0, 60.0]])
    road = RoadGeometry(spec, np.array([[0.0, 5.0], [100.0, 5.0]]), None, area, (edge,))
    main, side = road.static_boxes()
    assert main.center[0] - main.half_length == pytest.approx(-0.5 * BOUNDARY_THICKNESS_M)
    assert 40.0 - 0.11 < main.center[0] + main.half_length <= 40.0 + 1e-9  # sampled every 0.1 m
    assert side.center[1] - side.half_length == pytest.approx(10.0)
    assert side.center[1] + side.half_length == pytest.approx(60.0 + 0.5 * BOUNDARY_THICKNESS_M)
    assert shapely.union_all([box_footprint(main), box_footprint(side)]).intersection(area).area < 1e-9
