"""MOBIL lane changes: decisions against hand-computed IDM accelerations, keep-right, the ego."""

import math
import re

import numpy as np
import pytest
import shapely

from mujoco_world.agents.mobil import (
    IdmParameters,
    idm_acceleration,
    lane_layout,
    lane_neighbours,
    mobil_accelerations,
    mobil_decide,
)
from mujoco_world.loop.world import World
from mujoco_world.scenario.catalog import get_scenario
from mujoco_world.scenario.road import box_footprint, build_road
from mujoco_world.scenario.spec import RoadSpec, scenario_from_dict

W = 3.5  # lane width [m]
# IDM defaults (IdmSpec): a = 1.5, b = 2, T = 1.5 s, s0 = 2 m; every body wants 30 m/s.
A, B, T, S0, V0 = 1.5, 2.0, 1.5, 2.0, 30.0


def _idm_by_hand(v, gap, v_lead):
    """The IDM written out once more, scalar."""
    s_star = S0 + max(0.0, v * T + v * (v - v_lead) / (2.0 * math.sqrt(A * B)))
    return A * (1.0 - (v / V0) ** 4 - (s_star / gap) ** 2)


def _decide(bodies, me_offset=0.0, politeness=0.3, threshold=0.1, b_safe=4.0, bias=0.2, sees_ego=True):
    """MOBIL for body 1 (4 m x 2 m, 20 m/s at x = 0) among ``bodies`` on a straight two-lane route.

    Args:
        bodies: (x [m], lane 0 or 1, speed [m/s]) of the others; body 0 is the first.
        me_offset: body 1's offset left of its route (lane 0) [m].
    """
    rows = [(x, lane * W, v) for x, lane, v in bodies]
    rows.insert(1, (0.0, me_offset, 20.0))
    n = len(rows)
    position = np.array([[x, y] for x, y, _ in rows])
    velocity = np.array([[v, 0.0] for _, _, v in rows])
    samples = np.arange(-80.0, 150.0 + 1e-9, 1.0)
    x, y = samples[None, :], np.zeros((1, samples.size))
    me = np.array([1])
    sees = np.ones((1, n), dtype=bool)
    sees[0, 0] = sees_ego
    nb = lane_neighbours(
        x, y, np.zeros_like(x), samples[None, :], me, np.array([me_offset]), W,
        position, velocity, np.zeros(n), np.full(n, 4.0), np.full(n, 2.0),
        np.ones(n, dtype=bool), sees, np.full((1, 3), np.inf),
    )  # fmt: skip
    idm = IdmParameters(*(np.full(n, value) for value in (V0, A, B, T, S0)))
    current = round(me_offset / W)
    allowed = np.array([[0 <= current + side <= 1 for side in (-1, 0, 1)]])
    one = np.ones(1)
    return mobil_decide(
        mobil_accelerations(nb, me, np.array([20.0]), idm), allowed,
        politeness * one, threshold * one, b_safe * one, bias * one, np.ones(1, dtype=bool),
    )  # fmt: skip


def test_idm_acceleration_matches_the_formula_by_hand():
    # v 20, leader 26 m ahead at 15 m/s: s* = 2 + 30 + 20*5/(2 sqrt 3) = 60.87 m.
    assert idm_acceleration(20.0, V0, 26.0, 15.0, A, B, T, S0) == pytest.approx(-7.0170, abs=1e-3)
    assert idm_acceleration(20.0, V0, np.inf, 0.0, A, B, T, S0) == pytest.approx(1.5 * (1 - (2 / 3) ** 4))


def test_a_change_left_past_a_slow_leader_matches_the_hand_computed_incentive():
    # Own lane: a 15 m/s leader 26 m ahead (gap); target lane: a 25 m/s leader at x = 100
    # and a new follower 26 m behind at 20 m/s; no old follower.
    decision = _decide([(30.0, 0, 15.0), (100.0, 1, 25.0), (-30.0, 1, 20.0)])
    a_c = _idm_by_hand(20.0, 26.0, 15.0)  # -7.017
    a_c_new = _idm_by_hand(20.0, 96.0, 25.0)  # 1.2021
    a_n = _idm_by_hand(20.0, 126.0, 25.0)  # the new follower behind the target lane's leader
    a_n_new = _idm_by_hand(20.0, 26.0, 20.0)  # ... behind me: -1.0685
    expected = (a_c_new - a_c) + 0.3 * (a_n_new - a_n) - 0.2
    assert expected == pytest.approx(7.338, abs=1e-3)
    assert decision.incentive[0, 2] == pytest.approx(expected, rel=1e-9)
    assert decision.safe[0, 2]
    assert decision.change[0] == 1


def test_a_change_is_refused_by_the_safety_criterion():
    # The new follower only 8 m behind: a~_n = 1.5 (1 - (2/3)^4 - (32/8)^2) = -22.8 < -4.
    decision = _decide([(30.0, 0, 15.0), (100.0, 1, 25.0), (-12.0, 1, 20.0)])
    assert _idm_by_hand(20.0, 8.0, 20.0) == pytest.approx(-22.796, abs=1e-3)
    assert decision.incentive[0, 2] > 0.1  # worth it (above the threshold), but unsafe
    assert not decision.safe[0, 2]
    assert decision.change[0] == 0
    # A follower that brakes only a little less than b_safe does not stop it.
    assert _decide([(30.0, 0, 15.0), (100.0, 1, 25.0), (-12.0, 1, 20.0)], b_safe=23.0).change[0] == 1


def test_a_change_is_refused_by_the_threshold():
    # Both leaders at 25 m/s, 56 m and 96 m ahead: the gain is only a_c~ - a_c.
    gain = _idm_by_hand(20.0, 96.0, 25.0) - _idm_by_hand(20.0, 56.0, 25.0)
    assert gain == pytest.approx(0.00312, abs=1e-4)
    bodies = [(60.0, 0, 25.0), (100.0, 1, 25.0)]
    refused = _decide(bodies, bias=0.0, threshold=0.1)
    assert refused.incentive[0, 2] == pytest.approx(gain, rel=1e-9)
    assert refused.safe[0, 2] and refused.change[0] == 0
    assert _decide(bodies, bias=0.0, threshold=0.0).change[0] == 1


def test_keep_right_bias_brings_a_car_back_to_the_right_on_a_free_road():
    # In the left lane, both lanes free: the incentive to the right is the bias alone.
    far_ego = [(-1000.0, 0, 0.0)]  # body 0, out of sight
    back = _decide(far_ego, me_offset=W)
    assert back.incentive[0, 0] == pytest.approx(0.2, abs=1e-12)
    assert back.change[0] == -1
    # A free left lane from the right lane costs the bias: no change.
    stay = _decide(far_ego, me_offset=0.0)
    assert stay.incentive[0, 2] == pytest.approx(-0.2, abs=1e-12)
    assert stay.change[0] == 0
    # A slow car ahead in the right lane keeps it left.
    assert _decide([*far_ego, (40.0, 0, 15.0)], me_offset=W).change[0] == 0


def test_the_ego_counts_as_new_follower_unless_the_road_user_is_blind_to_it():
    # Body 0 is the ego, 12 m behind in the target lane.
    bodies = [(-12.0, 1, 20.0), (30.0, 0, 15.0), (100.0, 1, 25.0)]
    assert _decide(bodies).change[0] == 0  # MOBIL's safety criterion protects the ego
    assert _decide(bodies, sees_ego=False).change[0] == 1  # blind: it cuts in


def test_lane_layout_directions_and_the_merge_lane_end():
    one_way = scenario_from_dict({"name": "t", "road": {"lanes": 3, "lanes_forward": 3}, "ego": {"lane": 1}})
    assert lane_layout(one_way).own_lanes == {1: frozenset({0, 1, 2}), -1: frozenset()}
    layout = lane_layout(scenario_from_dict({"name": "t", "road": {"lanes": 4}}))
    assert layout.own_lanes == {1: frozenset({0, 1}), -1: frozenset({0, 1})}
    layout = lane_layout(scenario_from_dict({"name": "t", "road": {"lanes": 2}}))
    assert layout.own_lanes == {1: frozenset({0}), -1: frozenset({0})}
    assert not layout.allowed(np.array([1]), np.array([1]))[0]  # the oncoming lane is not its own
    merge = scenario_from_dict(
        {
            "name": "m",
            "road": {"kind": "merge", "lanes": 3, "length": 300.0, "lane_drop": 160.0, "taper": 40.0},
        }
    )
    ends = lane_layout(merge).end_of(np.array([0, 1, 2]), np.array([1, 1, 1]))
    assert ends.tolist() == [120.0, math.inf, math.inf]  # the acceleration lane ends where its taper starts


def _overtake_world(**fast):
    scenario = scenario_from_dict(
        {
            "name": "overtake",
            "road": {
                "length": 600.0,
                "lanes": 2,
                "lanes_forward": 2,
                "speed_limit": 30.0,
                "boundary": "wall",
            },
            "ego": {"s0": 5.0, "speed": 0.0, "lane": 0, "goal_s": 560.0},
            "road_users": [
                {
                    "name": "slow",
                    "type": "truck",
                    "s0": 100.0,
                    "behaviour": {"kind": "idm", "speed": 15.0},
                },
                {
                    "name": "fast",
                    "type": "car",
                    "s0": 40.0,
                    "behaviour": {"kind": "idm", "speed": 28.0, **fast},
                },
            ],
        }
    )
    return World(scenario)


def test_closed_loop_a_fast_car_overtakes_a_slow_truck_and_returns_right():
    world = _overtake_world(mobil={})
    fleet = world.fleet
    hits = []
    while world.time < 16.0:
        hits += world.step()
    # One change to the left at the start, one back to the right once past the truck.
    assert [(i, start, end) for _, i, start, end in fleet.lane_changes] == [(1, 0, 1), (1, 1, 0)]
    t_back = fleet.lane_changes[1][0]
    assert 5.0 < t_back < 12.0
    assert fleet.d[1] == pytest.approx(0.0, abs=1e-9)  # back in the right lane
    assert fleet.s[1] > fleet.s[0] + 0.5 * (10.0 + 4.5)  # ahead of the truck
    assert hits == []  # nobody touched
    # Without MOBIL it stays behind the truck.
    world = _overtake_world()
    while world.time < 16.0:
        world.step()
    assert world.fleet.s[1] < world.fleet.s[0] and world.fleet.lane_changes == []


def _standing_ego_world(reaction):
    scenario = scenario_from_dict(
        {
            "name": "react",
            "road": {"length": 200.0, "lanes": 2},
            "ego": {"s0": 60.0, "speed": 0.0, "lane": 0},
            "road_users": [
                {
                    "name": "car",
                    "type": "car",
                    "s0": 10.0,
                    "behaviour": {"kind": "idm", "speed": 12.0, "ego_reaction": reaction},
                }
            ],
        }
    )
    return World(scenario)


@pytest.mark.parametrize("reaction", ["idm", "none"])
def test_ego_reaction_idm_stops_behind_the_standing_ego_none_runs_into_it(reaction):
    world = _standing_ego_world(reaction)
    hits = []
    while world.time < 12.0 and not hits:
        hits += world.step()
    if reaction == "idm":
        assert hits == [] and world.fleet.v[0] < 0.3
        gap = 60.0 - world.fleet.s[0] - 4.5
        assert 1.5 < gap < 4.0  # about the standstill gap s0 = 2 m
    else:
        assert [(m.a.entity, m.b.entity) for m in hits] == [(0, 1)]


def _user(behaviour, route=None):
    return {"name": "u", "type": "car", "s0": 50.0, "route": route or {"lane": 0}, "behaviour": behaviour}


@pytest.mark.parametrize(
    ("road", "user", "message"),
    [
        (
            {},
            _user({"kind": "scripted", "mobil": {}}),
            "behaviour.mobil (lane changes) is only allowed with kind 'idm'",
        ),
        (
            {},
            _user({"kind": "scripted", "ego_reaction": "none"}),
            "behaviour.ego_reaction is only allowed with kind",
        ),
        (
            {},
            _user({"kind": "idm", "ego_reaction": "brake"}),
            "unknown ego reaction 'brake'; allowed: none, idm",
        ),
        ({}, _user({"kind": "idm", "mobil": {"politeness": 9.0}}), "mobil.politeness must lie in [-1, 5] -"),
        ({}, _user({"kind": "idm", "mobil": {"b_safe": 0.1}}), "mobil.b_safe must lie in [0.5, 15] m/s^2"),
        (
            {},
            _user({"kind": "idm", "mobil": {"polite": 0.3}}),
            "unknown key 'road_users[0].behaviour.mobil.polite'",
        ),
        (
            {},
            _user({"kind": "idm", "mobil": {}}, {"road": "waypoints", "waypoints": [[0, 0], [90, 0]]}),
            "road_users[0] (u).behaviour.mobil: lane changes need a route on the main road's lanes",
        ),
        (
            {"kind": "intersection"},
            _user({"kind": "idm", "mobil": {}}),
            "lane changes need a straight, curved or merge road, not road.kind = 'intersection'",
        ),
        (
            {"kind": "merge", "lanes": 1},
            None,
            "road.lanes of a merge road counts the acceleration lane and the main road's lanes (at least 2)",
        ),
        (
            {"kind": "merge", "lane_drop": 40.0, "taper": 50.0},
            None,
            "road.lane_drop (40 m) must lie after road.taper",
        ),
        ({"kind": "merge", "taper": 0.5}, None, "road.taper must lie in [1, 1000] m"),
        (
            {"lane_drop": 120.0},
            None,
            "road.lane_drop is only allowed with road.kind = 'merge' (an on-ramp's acceleration lane), "
            "not 'straight'",
        ),
        ({"kind": "curved", "taper": 30.0}, None, "road.taper is only allowed with road.kind = 'merge'"),
        (
            {"radius": 60.0},
            None,
            "road.radius is only used by road.kind = 'curved', not 'straight': remove it or set "
            "road.kind = 'curved'",
        ),
        (
            {"kind": "merge", "curve_angle": 30.0},
            None,
            "road.curve_angle is only used by road.kind = 'curved'",
        ),
        (
            {"kind": "intersection", "lead_in": 20.0},
            None,
            "road.lead_in is only used by road.kind = 'curved'",
        ),
        (
            {"kind": "curved", "corner_radius": 5.0},
            None,
            "road.corner_radius is only used by road.kind = 'intersection', not 'curved'",
        ),
        (
            {"kind": "merge", "lanes": 3, "lanes_forward": 2},
            None,
            "road.lanes_forward of a merge road must be",
        ),
    ],
)
def test_lane_change_merge_and_road_kind_fields_are_validated_by_name(road, user, message):
    data = {"name": "t", "road": road, "road_users": [user] if user else []}
    with pytest.raises(ValueError, match=re.escape(message)):
        scenario_from_dict(data)


def test_road_fields_of_their_own_kind_are_accepted():
    """The kind-specific fields stay allowed on the kind that reads them."""
    curved = {"kind": "curved", "length": 300.0, "radius": 60.0, "curve_angle": 45.0, "lead_in": 30.0}
    scenario = scenario_from_dict({"name": "t", "road": curved})
    assert (scenario.road.radius, scenario.road.curve_angle, scenario.road.lead_in) == (60.0, 45.0, 30.0)
    crossing = {"kind": "intersection", "length": 160.0, "corner_radius": 5.0}
    assert scenario_from_dict({"name": "t", "road": crossing}).road.corner_radius == 5.0


def test_an_ego_on_the_acceleration_lane_must_start_before_its_taper():
    road = {"kind": "merge", "lanes": 3, "lane_drop": 150.0, "taper": 50.0}
    with pytest.raises(
        ValueError, match=re.escape("ego.s0 (90 m) on the acceleration lane (ego.lane = 0) must lie")
    ):
        scenario_from_dict({"name": "t", "road": road, "ego": {"lane": 0, "s0": 90.0}})
    scenario_from_dict({"name": "t", "road": road, "ego": {"lane": 1, "s0": 90.0}})  # on the main road: fine


def test_merge_road_geometry_taper_lane_end_and_drivable_area():
    spec = RoadSpec(kind="merge", length=300.0, lanes=3, lane_drop=160.0, taper=40.0, shoulder=0.5)
    road = build_road(spec)
    # Cross-sections: full width (3 lanes + 2 shoulders, 11.5 m) before the taper, the
    # acceleration lane half gone mid-taper, two lanes + shoulders (8 m) after the drop.
    for x, right in ((50.0, -5.75), (119.9, -5.75), (140.0, -4.0), (160.0, -2.25), (250.0, -2.25)):
        section = shapely.LineString([(x, -20.0), (x, 20.0)]).intersection(road.drivable_area)
        assert section.bounds[1] == pytest.approx(right, abs=1e-6) and section.bounds[3] == pytest.approx(
            5.75
        )
    # Area: 300 m x 11.5 m minus the dropped lane after 160 m and the taper's triangle.
    assert road.drivable_area.area == pytest.approx(300 * 11.5 - 3.5 * 140 - 0.5 * 3.5 * 40)
    # The kerb follows the taper: a kerb box covers its middle, just outside the area.
    mid = shapely.Point(140.0, -4.0 - 0.2)
    assert any(box_footprint(b).distance(mid) < 1e-6 for b in road.static_boxes())
    # The acceleration lane's outer marking follows the taper and ends at the drop; the
    # line to the main road is dashed up to the drop and the road's solid edge after it.
    markings = road.lane_markings()
    edge = markings.solid[0]
    assert edge[-1] == pytest.approx([160.0, -1.75]) and edge[0] == pytest.approx([0.0, -5.25])
    assert max(d[:, 0].max() for d in markings.dashed if d[0, 1] == pytest.approx(-1.75)) <= 160.0
    assert any(
        s[0] == pytest.approx([160.0, -1.75]) and s[-1, 0] == pytest.approx(300.0) for s in markings.solid
    )
    # The ego's merged reference: lane 0's centre (-3.5) until 10 m past its start, lane 1's (0) at the taper.
    path = road.merge_route(10.0)
    d = np.interp([15.0, 40.0, 80.0, 120.0, 200.0], path[:, 0], path[:, 1])
    assert d == pytest.approx([-3.5, -3.5, -1.75, 0.0, 0.0], abs=1e-9)


def test_an_ego_on_the_ramp_plans_along_the_merged_reference():
    world = World(get_scenario("on_ramp_merge"))  # lane_drop 220 m, taper 60 m, lanes 3
    x, y, *_ = world.ego_path.evaluate(np.array([10.0, 60.0, 160.0, 300.0]))
    assert y == pytest.approx([-3.5, -3.5, 0.0, 0.0], abs=0.05)  # lane 0's centre, then lane 1's
    env = world.environment()
    assert env.lane_offsets == pytest.approx((-3.5, 0.0, 3.5))  # relative to the merged reference
    # Edges relative to lane 1 would sit 3.5 m off the route's start in lane 0 (the review
    # measured (-5.25, 5.25) against the true (-1.75, 8.75)): a ramp ego gets none.
    assert env.lane_edges is None


def test_a_plain_idm_car_stops_at_the_lane_end_a_mobil_car_merges():
    def world(behaviour):
        scenario = scenario_from_dict(
            {
                "name": "m",
                "road": {"kind": "merge", "lanes": 2, "length": 300.0, "lane_drop": 150.0, "taper": 30.0},
                "ego": {"lane": 1, "s0": 5.0, "speed": 0.0, "goal_s": 280.0},
                "road_users": [
                    {"name": "r", "type": "car", "s0": 20.0, "route": {"lane": 0}, "behaviour": behaviour}
                ],
            }
        )
        w = World(scenario)
        hits = []
        while w.time < 15.0:
            hits += w.step()
        return w, hits

    plain, hits = world({"kind": "idm", "speed": 15.0})
    assert hits == [] and plain.fleet.v[0] < 0.3
    # It stands before the lane's end (the taper's start, 120 m) with its front.
    assert 110.0 < plain.fleet.s[0] + 2.25 <= 120.0
    merging, hits = world({"kind": "idm", "speed": 15.0, "mobil": {}})
    assert hits == [] and merging.fleet.d[0] == pytest.approx(3.5)
    assert [(a, b) for _, _, a, b in merging.fleet.lane_changes] == [(0, 1)]


def test_a_merge_road_gets_the_default_lane_drop_and_taper_other_roads_none():
    merge = scenario_from_dict({"name": "m", "road": {"kind": "merge", "lanes": 3, "length": 300.0}}).road
    assert (merge.lane_drop, merge.taper) == (150.0, 50.0)
    straight = scenario_from_dict({"name": "s"}).road
    assert (straight.lane_drop, straight.taper) == (None, None)
