"""Lanes per direction: ``road.lanes_forward``, which lane runs which way, route validation, markings."""

import numpy as np
import pytest

from mujoco_world.scenario.road import DASH_M, GAP_M, ZONE_LINE_GAP_M, build_road, dashes
from mujoco_world.scenario.spec import NoOvertakingSpec, RoadSpec, load_scenario, scenario_from_dict


def scenario(road=None, ego=None, users=()):
    return scenario_from_dict(
        {
            "name": "t",
            "road": {"length": 200.0, **(road or {})},
            "ego": {"s0": 5.0, "speed": 5.0, **(ego or {})},
            "road_users": list(users),
        }
    )


def car(route, name="x", **kw):
    return {"name": name, "type": "car", "s0": 60.0, "route": route, **kw}


@pytest.mark.parametrize(
    ("lanes", "forward", "expected"),
    [
        (2, None, (1, 1)),
        (1, None, (1, 0)),
        (3, None, (2, 1)),
        (4, None, (2, 2)),
        (3, 3, (3, 0)),
        (2, 0, (0, 2)),
    ],
)
def test_lanes_forward_defaults_to_half_rounded_up(lanes, forward, expected):
    road = RoadSpec(lanes=lanes, lanes_forward=forward)
    assert (road.lanes_forward, road.lanes_backward) == expected
    assert (road.lanes_of(1), road.lanes_of(-1)) == expected


@pytest.mark.parametrize("bad", [3, -1, True, 1.5])
def test_lanes_forward_out_of_range_names_the_field(bad):
    with pytest.raises(ValueError, match=r"road.lanes_forward must be an integer in 0..road.lanes \(2\)"):
        RoadSpec(lanes=2, lanes_forward=bad)


def test_geometry_answers_which_lanes_run_which_way():
    # Three lanes of 3.5 m, two along +x: edges at -5.25, -1.75, 1.75, 5.25 m; the centre
    # line between the directions is the third edge, d = 1.75 m.
    road = build_road(RoadSpec(lanes=3, lanes_forward=2))
    np.testing.assert_allclose(road.lane_edges(), [-5.25, -1.75, 1.75, 5.25])
    assert road.centre_offset == pytest.approx(1.75)
    assert road.lanes_in(1) == (0, 1)
    assert road.lanes_in(-1) == (0,)
    # Lane 0 against the reference is the leftmost lane (d = 3.5 m), lane 2 along it the same lane.
    assert road.lane_offset(0, -1) == pytest.approx(3.5)
    assert road.lane_offset(2, 1) == pytest.approx(3.5)
    assert road.lane_runs(2, 1) == -1
    assert road.lane_runs(1, 1) == 1
    # Lane 1 from the right of direction -1 is d = 0: the left lane of direction +1.
    assert road.lane_offset(1, -1) == pytest.approx(0.0)
    assert road.lane_runs(1, -1) == 1
    with pytest.raises(ValueError, match="direction must be 1 or -1"):
        road.lanes_in(0)


def test_default_two_lane_road_has_its_centre_line_on_the_reference():
    road = build_road(RoadSpec())
    assert road.centre_offset == 0.0
    assert road.lanes_in(1) == (0,) and road.lanes_in(-1) == (0,)


@pytest.mark.parametrize(("lanes", "forward"), [(1, None), (3, 3), (2, 0)])
def test_one_way_roads_have_no_centre_line(lanes, forward):
    assert build_road(RoadSpec(lanes=lanes, lanes_forward=forward)).centre_offset is None


def test_a_route_in_a_lane_of_the_other_direction_is_refused_by_name():
    other = r"road_users\[0\] \(x\).route.lane = 1 with direction = 1 is a lane of the other direction"
    with pytest.raises(ValueError, match=other + r".*route.wrong_way = true"):
        scenario(users=[car({"lane": 1})])
    with pytest.raises(ValueError, match=r"road_users\[0\] \(x\).route.lane = 1 with direction = -1"):
        scenario(users=[car({"lane": 1, "direction": -1})])
    # Three lanes, two along +x: lane 1 along +x is fine, lane 1 against it is not.
    scenario(road={"lanes": 3}, users=[car({"lane": 1})])
    with pytest.raises(ValueError, match=r"lanes that run against the reference direction are lanes 0..0"):
        scenario(road={"lanes": 3}, users=[car({"lane": 1, "direction": -1})])


def test_wrong_way_drivers_are_allowed_and_only_in_the_other_direction():
    s = scenario(users=[car({"lane": 1, "wrong_way": True})])
    assert s.road_users[0].route.wrong_way
    own = r"road_users\[0\] \(x\).route.wrong_way = true, but lane 0 .* runs its way"
    with pytest.raises(ValueError, match=own):
        scenario(users=[car({"lane": 0, "wrong_way": True})])
    with pytest.raises(ValueError, match="route.wrong_way must be true or false"):
        scenario(users=[car({"lane": 1, "wrong_way": 1})])


def test_pedestrians_and_parked_road_users_have_no_lane_direction():
    walker = {"name": "w", "type": "pedestrian", "s0": 60.0, "route": {"lane": 1}}
    parked = car({"lane": 1}, name="p", behaviour={"kind": "parked"})
    assert len(scenario(users=[walker, parked]).road_users) == 2


def test_the_ego_must_start_in_a_lane_of_its_direction():
    with pytest.raises(ValueError, match=r"ego.lane must be a lane that runs the ego's way .*lanes 0..0"):
        scenario(ego={"lane": 1})
    assert scenario(road={"lanes_forward": 2}, ego={"lane": 1}).ego.lane == 1


def test_old_files_keep_their_meaning(tmp_path):
    # A two-lane file without lanes_forward: one lane each way (as lane_offset always had it).
    path = tmp_path / "s.toml"
    path.write_text(
        'name = "s"\n[road]\nlanes = 2\n[[road_users]]\nname = "on"\ntype = "car"\ns0 = 90.0\n'
        "route = { lane = 0, direction = -1 }\n"
    )
    s = load_scenario(path)
    assert s.road.lanes_forward == 1
    road = build_road(s.road)
    assert road.route(s.road_users[0].route)[0, 1] == pytest.approx(1.75)


def test_lane_markings_solid_edges_and_centre_dashed_lanes():
    # Two lanes each way on 200 m: edges (d = -7, 7) and the centre (0) solid; the lines at
    # d = -3.5 and 3.5 dashed: dashes start every 9 m at 0, 9, ..., 198 m: 23 per line.
    road = build_road(RoadSpec(lanes=4, length=200.0))
    marks = road.lane_markings()
    assert sorted(round(float(line[0, 1]), 6) for line in marks.solid) == [-7.0, 0.0, 7.0]
    assert len(marks.dashed) == 46
    first = min((d for d in marks.dashed if d[0, 1] < 0), key=lambda d: d[0, 0])
    assert first[0] == pytest.approx([0.0, -3.5])
    assert first[-1] == pytest.approx([DASH_M, -3.5])
    # One way, three lanes: two solid edges, two dashed lines between.
    one_way = build_road(RoadSpec(lanes=3, lanes_forward=3)).lane_markings()
    assert len(one_way.solid) == 2
    assert sorted({round(float(d[0, 1]), 6) for d in one_way.dashed}) == [-1.75, 1.75]


def test_dashes_cut_a_polyline_by_arc_length():
    # An L of 10 m + 10 m: dashes of 3 m every 3 + 6 m start at 0, 9, 18; the second
    # (9 to 12 m) turns the corner at (10, 0).
    line = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    parts = dashes(line, 3.0, 6.0)
    assert len(parts) == 3
    np.testing.assert_allclose(parts[1], [[9.0, 0.0], [10.0, 0.0], [10.0, 2.0]])
    np.testing.assert_allclose(parts[2], [[10.0, 8.0], [10.0, 10.0]])
    assert GAP_M == 6.0


def test_a_no_overtaking_zone_is_drawn_as_a_double_centre_line():
    zone = NoOvertakingSpec(start=50.0, end=100.0)
    marks = build_road(RoadSpec(length=200.0, no_overtaking=(zone,))).lane_markings()
    assert len(marks.no_overtaking) == 2
    for line, d in zip(marks.no_overtaking, (-ZONE_LINE_GAP_M, ZONE_LINE_GAP_M), strict=True):
        assert line[0] == pytest.approx([50.0, d]) and line[-1] == pytest.approx([100.0, d])
    assert build_road(RoadSpec()).lane_markings().no_overtaking == ()
