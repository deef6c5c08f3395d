"""Stop lines in the planner: stop distances, red-window timing, the dilemma zone, stop targets."""

from types import SimpleNamespace

import numpy as np
import pytest
import shapely

from ethical_planner.config import SamplingConfig, TrafficRulesConfig, VehicleConfig, preset
from ethical_planner.environment import NoOvertakingZone, RoadEnvironment, StopLine
from ethical_planner.planner import Planner
from ethical_planner.road_users import EGO_SHAPE, KinematicState, RoadUser, Shape
from ethical_planner.sampling import CandidateKind, FrenetState, _stop_target_motion
from ethical_planner.traffic_rules import (
    LaneRules,
    StopLines,
    breaks_lane_rules,
    breaks_stop_lines,
    crossing_times,
    lane_blocked,
    lateral_extent,
    stop_distance,
)
from ethical_planner.validity import Validity

VEHICLE = VehicleConfig()  # emergency 8 m/s^2, jerk 30 m/s^3
RULES = TrafficRulesConfig(red_margin=0.0)  # comfortable 3 m/s^2; windows as written


def _start(v: float, a: float = 0.0, s: float = 0.0) -> FrenetState:
    return FrenetState(s=s, s_dot=v, s_ddot=a, d=0.0, d_dot=0.0, d_ddot=0.0)


def test_stop_distance_by_hand():
    # From 12 m/s, a0 = 0, jerk 30 m/s^3 to -b, then -b:
    # b = 3: ramp 0.1 s, 1.2 - 30 * 0.001 / 6 = 1.195 m, speed 12 - 15 * 0.01 = 11.85 m/s,
    #        then 11.85^2 / 6 = 23.40375 m: 24.59875 m.
    # b = 8: ramp 0.2667 s, 3.2 - 5 * 0.2667^3 = 3.105185 m, speed 10.93333 m/s,
    #        then 10.93333^2 / 16 = 7.471111 m: 10.576296 m.
    d = stop_distance(_start(12.0), np.array([3.0, 8.0]), 30.0)
    assert d == pytest.approx([24.59875, 10.576296], abs=1e-5)
    # Without a ramp it is v^2 / (2 b).
    assert stop_distance(_start(12.0), np.array([3.0]), 1e9) == pytest.approx([24.0], abs=1e-6)


def _lines(lines, front, v, now=0.0, stood=None):
    stood = np.zeros(len(lines), dtype=bool) if stood is None else np.asarray(stood)
    return StopLines.of(tuple(lines), _start(v), front, now, stood, VEHICLE, RULES)


def test_a_light_turning_red_later_binds_while_the_ego_can_stop_comfortably():
    # Front at the centre (offset 0); comfortable stop from 12 m/s takes 24.59875 m.
    red_later = ((5.0, 10.0),)
    near = _lines([StopLine(24.5, red_later)], 0.0, 12.0)
    far = _lines([StopLine(24.7, red_later)], 0.0, 12.0)
    assert not near.binding[0]  # dilemma zone: proceeds
    assert far.binding[0]
    # The same gaps with the light red now: the emergency stop (10.58 m) decides.
    assert _lines([StopLine(24.5, ((0.0, 10.0),))], 0.0, 12.0).binding[0]
    assert _lines([StopLine(10.7, ((0.0, 10.0),))], 0.0, 12.0).binding[0]
    assert not _lines([StopLine(10.5, ((0.0, 10.0),))], 0.0, 12.0).binding[0]


def test_lines_that_do_not_bind():
    green_now_on = _lines([StopLine(50.0, ((0.0, 4.0),))], 0.0, 10.0, now=4.0)
    assert not green_now_on.binding[0]  # its last red window is over
    behind = _lines([StopLine(3.0, ((0.0, 9.0),))], 4.0, 10.0)  # front 4 m, line 3 m
    assert not behind.binding[0]
    sign = StopLine(50.0, stop=True)
    assert _lines([sign], 0.0, 10.0).binding[0]
    assert not _lines([sign], 0.0, 10.0, stood=[True]).binding[0]


def test_crossing_times_inside_and_after_the_horizon():
    t = np.arange(31) * 0.1
    front = 10.0 * t[None, :].repeat(2, axis=0)  # 10 m/s from 0: 30 m at 3 s
    front[1] = np.minimum(front[1], 20.0)  # stops at 20 m
    end_speed = np.array([10.0, 0.0])
    when = crossing_times(front, end_speed, t, np.array([15.0, 40.0, 50.0]), 3.0)
    # Line 15 m: 1.5 s. Line 40 m: gap 10 m < 10^2 / 6 = 16.7 m, committed: 3 + 10 / 10 = 4 s.
    # Line 50 m: gap 20 m > 16.7 m: it can still stop, no crossing.
    assert when[0] == pytest.approx([1.5, 4.0, np.inf])
    assert when[1] == pytest.approx([1.5, np.inf, np.inf])  # stops at 20 m, past 15 m only
    # Between samples the crossing is interpolated: 15.05 m at 1.505 s.
    assert crossing_times(front, end_speed, t, np.array([15.05]), 3.0)[0, 0] == pytest.approx(1.505)


def test_red_window_timing_of_the_crossing():
    t = np.arange(31) * 0.1
    front = 10.0 * t[None, :]  # crosses 15 m at 1.5 s
    v = np.array([10.0])

    def broken(red, now=0.0, s=15.0):
        lines = _lines([StopLine(s, red)], 0.0, 0.0, now=now)
        return bool(breaks_stop_lines(front, v, t, lines, 3.0)[0])

    assert not broken(((4.0, 9.0),))  # crosses before the red
    assert broken(((1.0, 2.0),))  # crosses inside it
    assert not broken(((0.5, 1.5),))  # red ends exactly as it crosses (windows are [start, end))
    assert broken(((1.5, 2.5),))
    assert broken(((4.0, 9.0),), now=3.0)  # 3 + 1.5 = 4.5 s on the run's clock
    assert broken(((4.0, 9.0), (10.0, 12.0)), now=9.0)  # the second window
    assert not broken(((4.0, 9.0), (10.0, 12.0)), now=7.6)  # 9.1 s: between windows


def test_stop_target_candidates_stop_at_the_target():
    start = _start(12.0, s=5.0)
    t = np.arange(101) * 0.1  # 10 s: the stop lies inside
    part = _stop_target_motion(start, t, SamplingConfig(), VEHICLE, np.array([30.0, 60.0, 500.0, 5.0]), 0.5)
    # 500 m needs < 0.5 m/s^2 and 5 m more than 8 m/s^2: no candidates for them.
    b = np.unique(part.deceleration)
    assert b.size == 2
    stops = part.lon[0][:, -1]
    assert np.sort(np.unique(stops.round(6))) == pytest.approx([35.0, 65.0], abs=1e-6)
    assert np.all(part.lon[1][:, -1] == 0.0)
    # By hand: ramp t_j = b / 30, s_j = 12 t_j - 5 t_j^3, v_j = 12 - 15 t_j^2, then v_j^2 / (2 b).
    t_j = b / 30.0
    assert 12 * t_j - 5 * t_j**3 + (12 - 15 * t_j**2) ** 2 / (2 * b) == pytest.approx([60.0, 30.0], abs=1e-6)
    assert b == pytest.approx([1.2, 2.4], abs=0.05)  # v^2 / (2 D) without the ramp
    assert part.kind == CandidateKind.BRAKE


def _road(lines):
    env = RoadEnvironment.along_path(np.array([[0.0, 0.0], [300.0, 0.0]]), lanes_left=1, speed_limit=13.9)
    return RoadEnvironment(
        env.reference_path, env.drivable_area, env.lane_width, env.lane_offsets, env.speed_limit, lines
    )


def _front_end(decision):
    return decision.trajectory.x.max() + 0.5 * EGO_SHAPE.length


def test_the_planner_stops_for_a_red_light_it_can_stop_for():
    ego = KinematicState(x=10.0, y=0.0, yaw=0.0, v=12.0)
    front = 10.0 + 0.5 * EGO_SHAPE.length
    line = StopLine(front + 30.0, ((0.0, 20.0),))  # 30 m ahead, red for 20 s
    planner = Planner(preset("ethical"), _road((line,)))
    decision = planner.plan(ego, [], now=0.0)
    assert decision.level == Validity.VALID
    assert decision.level_counts[int(Validity.BREAKS_TRAFFIC_RULE)] > 0
    end = decision.trajectory
    # The plan ends before the line and can still stop before it at 3 m/s^2.
    gap = line.s - (end.x[-1] + 0.5 * EGO_SHAPE.length)
    assert gap > end.v[-1] ** 2 / 6.0 - 1e-9
    # The same light green by then (red ended at 1 s): the planner keeps its speed.
    green = Planner(preset("ethical"), _road((StopLine(line.s, ((0.0, 1.0),)),)))
    assert _front_end(green.plan(ego, [], now=0.0)) > front + 33.0
    assert Validity.BREAKS_TRAFFIC_RULE not in green.plan(ego, [], now=0.0).level_counts
    # Rules off: the same red line is ignored.
    off = Planner(preset("ethical").with_overrides({"traffic_rules": {"enabled": False}}), _road((line,)))
    assert int(Validity.BREAKS_TRAFFIC_RULE) not in off.plan(ego, [], now=0.0).level_counts


def test_in_the_dilemma_zone_the_planner_proceeds():
    # Red now, 9 m ahead at 12 m/s: even braking at 8 m/s^2 takes 10.58 m.
    ego = KinematicState(x=10.0, y=0.0, yaw=0.0, v=12.0)
    front = 10.0 + 0.5 * EGO_SHAPE.length
    planner = Planner(preset("ethical"), _road((StopLine(front + 9.0, ((0.0, 20.0),)),)))
    decision = planner.plan(ego, [], now=0.0)
    assert decision.level == Validity.VALID and int(Validity.BREAKS_TRAFFIC_RULE) not in decision.level_counts
    assert _front_end(decision) > front + 30.0  # it goes on, it does not brake to a stop past the line
    # 12 m ahead it can stop (10.58 m): it must, and does.
    planner = Planner(preset("ethical"), _road((StopLine(front + 12.0, ((0.0, 20.0),)),)))
    decision = planner.plan(ego, [], now=0.0)
    assert decision.level == Validity.VALID and _front_end(decision) < front + 12.0


def test_a_stop_sign_is_stopped_at_then_passed():
    sign = StopLine(60.0, stop=True)
    planner = Planner(preset("ethical"), _road((sign,)))
    # Approaching at 10 m/s, 25 m before the line: the plan stops before it.
    front = 60.0 - 25.0
    decision = planner.plan(KinematicState(x=front - 0.5 * EGO_SHAPE.length, y=0.0, yaw=0.0, v=10.0), [])
    assert _front_end(decision) < 60.0
    # Standing 1 m before it: noted as the stop; the next cycle drives on.
    standing = KinematicState(x=59.0 - 0.5 * EGO_SHAPE.length, y=0.0, yaw=0.0, v=0.0)
    planner.plan(standing, [], now=5.0)
    assert planner._stood.tolist() == [True]
    rolling = KinematicState(x=59.0 - 0.5 * EGO_SHAPE.length, y=0.0, yaw=0.0, v=0.5)
    assert _front_end(planner.plan(rolling, [], now=5.2)) > 61.0
    planner.reset()
    assert _front_end(planner.plan(rolling, [], now=5.2)) < 60.0


def test_a_braking_candidate_that_stops_beyond_the_horizon_keeps_the_red_light():
    """Review of stop 19: from 20 m/s, 45 m before a red line, the stop-line candidate
    brakes at about 4.7 m/s^2 and stops after the 3 s horizon; the end-state test used
    3 m/s^2 and called it a crossing (level 4), so the planner braked at -7.5 m/s^2."""
    start = _start(20.0)
    t = np.arange(31) * 0.1
    part = _stop_target_motion(start, t, SamplingConfig(), VEHICLE, np.array([44.0]), 0.5)
    b = float(part.deceleration[0])
    front = part.lon[0][:1]
    end_speed = part.lon[1][:1, -1]
    gap = 44.0 - front[0, -1]
    # By hand: it still moves at the horizon, and 3 m/s^2 cannot stop it in the gap left,
    # its own braking can (it stops at exactly 44 m).
    assert end_speed[0] > 5.0 and end_speed[0] ** 2 / 6.0 > gap > end_speed[0] ** 2 / (2 * b) - 1e-6
    line = np.array([44.0 + 1e-6])
    assert np.isfinite(crossing_times(front, end_speed, t, line, 3.0)[0, 0])  # the old test
    assert crossing_times(front, end_speed, t, line, 3.0, np.array([b]))[0, 0] == np.inf


def test_the_planner_brakes_no_harder_than_needed_for_a_far_red_light():
    ego = KinematicState(x=10.0, y=0.0, yaw=0.0, v=20.0)
    front = 10.0 + 0.5 * EGO_SHAPE.length
    line = StopLine(front + 45.0, ((0.0, 30.0),))
    planner = Planner(preset("ethical"), _road((line,)))
    decision = planner.plan(ego, [], now=0.0)
    assert decision.level == Validity.VALID
    # v^2 / (2 * 44 m) = 4.55 m/s^2 stops 1 m before the line; the emergency 8 is not needed.
    assert decision.trajectory.a.min() > -6.0


def test_an_amber_release_only_for_an_ego_that_clears_the_line_before_the_red():
    # 20 m/s, 50 m before a light turning red at 10 s: comfortable stop needs about 68 m.
    before_red = _lines([StopLine(50.0, ((10.0, 20.0),))], 0.0, 20.0, now=8.0)  # arrives 10.5 s
    assert before_red.binding[0]  # it would cross in the red: full braking (about 27 m) binds
    in_time = _lines([StopLine(50.0, ((10.0, 20.0),))], 0.0, 20.0, now=7.0)  # arrives 9.5 s
    assert not in_time.binding[0]  # amber dilemma zone: it clears the line before the red
    # Stepping across the red onset changes nothing for an ego that would arrive in the red.
    assert _lines([StopLine(50.0, ((10.0, 20.0),))], 0.0, 20.0, now=10.0).binding[0]


def test_a_light_whose_red_is_over_does_not_bind_beside_one_with_more_windows():
    lines = [StopLine(100.0, ((0.0, 5.0),)), StopLine(200.0, ((0.0, 5.0), (50.0, 60.0)))]
    assert list(_lines(lines, 0.0, 10.0, now=20.0).binding) == [False, True]
    assert not _lines([StopLine(100.0, ())], 0.0, 10.0).binding[0]  # a light that is never red


def test_a_plan_keeps_clear_of_the_red_by_the_margin():
    """A random red_light_for_ego variant (s0-29) planned to cross as the red ended and
    crossed 13 ms early; with the default 0.5 s margin such a plan breaks the rule."""
    t = np.arange(31) * 0.1
    front = 10.0 * t[None, :]  # crosses 15 m at 1.5 s
    v = np.array([10.0])

    def broken(red, margin):
        rules = TrafficRulesConfig(red_margin=margin)
        lines = StopLines.of((StopLine(15.0, red),), _start(0.0), 0.0, 0.0, np.zeros(1, bool), VEHICLE, rules)
        return bool(breaks_stop_lines(front, v, t, lines, 3.0)[0])

    assert not broken(((0.0, 1.45),), 0.0)  # 0.05 s after the red
    assert broken(((0.0, 1.45),), 0.5)
    assert not broken(((0.0, 0.95),), 0.5)  # 0.55 s after it
    assert broken(((1.9, 5.0),), 0.5)  # 0.4 s before the next red
    assert not broken(((2.05, 5.0),), 0.5)
    with pytest.raises(ValueError, match="red_margin"):
        TrafficRulesConfig(red_margin=-0.1)


# --------------------------------------------------------------------------- lane markings


def _marked_road(zones=(), edges=None, debris=None):
    """A straight two-lane road along +x, the ego lane centred on y = 0, the centre line at d = 1.75 m.

    ``edges`` (the outer lane edges, the shoulder rule) only if given: the zone tests keep it off.
    """
    env = RoadEnvironment.along_path(
        np.array([[0.0, 0.0], [400.0, 0.0]]), lanes_left=1, speed_limit=16.7, margin=0.5
    )
    area = env.drivable_area if debris is None else env.drivable_area.difference(debris)
    return RoadEnvironment(
        env.reference_path,
        area,
        env.lane_width,
        env.lane_offsets,
        env.speed_limit,
        centre_line=1.75,
        lane_edges=edges,
        no_overtaking=tuple(zones),
    )


def _poses(s, d, yaw=0.0):
    """Stand-in candidates along the straight path: s, d [m], yaw [rad], shape (n, n_t)."""
    s, d = np.atleast_2d(np.asarray(s, dtype=float)), np.atleast_2d(np.asarray(d, dtype=float))
    return SimpleNamespace(
        s=s, d=d, yaw=np.broadcast_to(np.asarray(yaw, dtype=float), s.shape), n_traj=s.shape[0]
    )


def test_footprint_extent_across_the_path_by_hand():
    path = _marked_road().reference_path
    shape = Shape(4.0, 2.0)
    # At 30 deg to the path: half extent 2 sin 30 + 1 cos 30 = 1 + 0.866 = 1.866 m.
    right, left = lateral_extent(_poses([[10.0]], [[0.5]], np.radians(30.0)), path, shape)
    assert left[0, 0] == pytest.approx(0.5 + 1.0 + 0.8660254, abs=1e-6)
    assert right[0, 0] == pytest.approx(0.5 - 1.8660254, abs=1e-6)


def test_crossing_the_centre_line_in_a_zone_breaks_the_rule_and_outside_does_not():
    path = _marked_road().reference_path
    shape = Shape(4.0, 2.0)
    rules = LaneRules(1.75, np.array([[50.0, 100.0]]), None)
    # Each row: s over 3 steps, d over 3 steps. The footprint's left edge is d + 1 m,
    # its s extent s +- 2 m.
    s = [
        [40.0, 50.0, 60.0],  # d 0 -> 1.0: left edge 2.0 > 1.75 at s = 60 (footprint 58..62 in the zone)
        [110.0, 120.0, 130.0],  # the same move behind the zone (footprint from 108 m)
        [43.0, 45.0, 48.5],  # across only at s = 48.5: its front (50.5 m) is in the zone
        [43.0, 45.0, 47.5],  # across only at s = 47.5: its front (49.5 m) is not
        [60.0, 70.0, 80.0],  # across now (d = 1.0) and returning: allowed
        [60.0, 70.0, 80.0],  # d 0.7: left edge 1.7 m, short of the line
    ]
    d = [[0.0, 0.5, 1.0], [0.0, 0.5, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [1.0, 0.6, 0.0], [0.0, 0.7, 0.7]]
    broken = breaks_lane_rules(_poses(s, d), path, shape, rules)
    assert broken.tolist() == [True, False, True, False, False, False]
    # A heading counts: d = 0.5 at 30 deg reaches 2.366 m, at 0 deg 1.5 m.
    turned = _poses([[60.0, 61.0]], [[0.5, 0.5]], [0.0, np.radians(30.0)])
    assert breaks_lane_rules(turned, path, shape, rules).tolist() == [True]


def test_driving_onto_a_shoulder_breaks_the_rule_unless_returning():
    path = _marked_road().reference_path
    shape = Shape(4.0, 2.0)
    rules = LaneRules(None, np.zeros((0, 2)), (-1.75, 5.25))
    d = [[0.0, -0.5, -0.8], [0.0, -0.5, -0.7], [-1.2, -0.9, -0.5], [0.0, 2.0, 4.3], [0.0, 2.0, 4.2]]
    s = [[10.0, 20.0, 30.0]] * 5
    # Right edges -1.8 (beyond -1.75), -1.7; returning from -2.2; left edges 5.3 (beyond 5.25), 5.2.
    assert breaks_lane_rules(_poses(s, d), path, shape, rules).tolist() == [True, False, False, True, False]


def test_an_ego_on_the_shoulder_may_turn_back_into_the_lane():
    # curve_truck with the rule on (ethical and selfish stood still for good): an ego
    # standing 0.18 m beyond the right edge (d = -0.93, right side -1.93) whose every
    # moving plan swings a corner further out. Turned 0.1 rad left to return, d = -0.93:
    # its right rear corner reaches -0.93 - 2 sin 0.1 - cos 0.1 = -2.1297 m, 0.2 m further
    # out, with the centre no further out: allowed. Moving the centre right: broken.
    path = _marked_road().reference_path
    shape = Shape(4.0, 2.0)
    rules = LaneRules(None, np.zeros((0, 2)), (-1.75, 5.25))
    right, _ = lateral_extent(_poses([[10.0]], [[-0.93]], 0.1), path, shape)
    assert right[0, 0] == pytest.approx(-0.93 - 2.0 * np.sin(0.1) - np.cos(0.1), abs=1e-9)
    s = [[10.0, 12.0, 14.0]] * 3
    d = [[-0.93, -0.93, -0.6], [-0.93, -0.95, -1.0], [-0.93, -0.93, -0.93]]
    yaw = [[0.0, 0.1, 0.1], [0.0, 0.0, 0.0], [0.0, -0.05, -0.05]]
    assert breaks_lane_rules(_poses(s, d, yaw), path, shape, rules).tolist() == [False, True, False]
    # From inside the lane the same swing of a corner over the edge still breaks it.
    inside = _poses([[10.0, 12.0]], [[-0.7, -0.7]], [[0.0, -0.1]])
    assert breaks_lane_rules(inside, path, shape, rules).tolist() == [True]


def _slow_car(x, v):
    return RoadUser(1, "truck", KinematicState(x=x, y=0.0, yaw=0.0, v=v), Shape(6.0, 2.5), mass=7000.0)


def _crosses(decision, centre=1.75):
    return float(np.max(decision.trajectory.y)) + 0.5 * EGO_SHAPE.width > centre


def test_the_planner_keeps_behind_a_slow_vehicle_in_a_zone_and_not_outside():
    ego = KinematicState(x=40.0, y=0.0, yaw=0.0, v=14.0)
    tractor = _slow_car(62.0, 7.0)  # 7 m/s: faster than the 10 mph exception
    inside = Planner(preset("ethical"), _marked_road([NoOvertakingZone(0.0, 300.0)]))
    decision = inside.plan(ego, [tractor], now=0.0)
    assert decision.level == Validity.VALID and not _crosses(decision)
    assert decision.level_counts[int(Validity.BREAKS_TRAFFIC_RULE)] > 0
    # The zone behind the ego (it ended 10 m behind its rear, 37.7 m), or the rule off:
    # no candidate breaks a rule.
    behind = Planner(preset("ethical"), _marked_road([NoOvertakingZone(0.0, 27.0)]))
    assert int(Validity.BREAKS_TRAFFIC_RULE) not in behind.plan(ego, [tractor], now=0.0).level_counts
    off = preset("ethical").with_overrides({"traffic_rules": {"no_overtaking": False}})
    decision = Planner(off, _marked_road([NoOvertakingZone(0.0, 300.0)])).plan(ego, [tractor], now=0.0)
    assert int(Validity.BREAKS_TRAFFIC_RULE) not in decision.level_counts


def test_a_zone_lets_the_ego_pass_something_slower_than_its_exception():
    ego = KinematicState(x=40.0, y=0.0, yaw=0.0, v=8.0)
    zone = NoOvertakingZone(0.0, 300.0)
    # A stalled car (0.5 m/s < 4.47 m/s) 22 m ahead blocks the lane: passing it is allowed.
    decision = Planner(preset("ethical"), _marked_road([zone])).plan(ego, [_slow_car(62.0, 0.5)], now=0.0)
    assert int(Validity.BREAKS_TRAFFIC_RULE) not in decision.level_counts
    # Debris in the lane (a hole of the drivable area) likewise.
    debris = shapely.box(70.0, -1.0, 71.2, 0.4)
    lane = _marked_road([zone], debris=debris)
    assert (
        int(Validity.BREAKS_TRAFFIC_RULE)
        not in Planner(preset("ethical"), lane).plan(ego, [], now=0.0).level_counts
    )
    # A zone without the exception (pass_below = 0) binds.
    strict = _marked_road([NoOvertakingZone(0.0, 300.0, pass_below=0.0)], debris=debris)
    decision = Planner(preset("ethical"), strict).plan(ego, [], now=0.0)
    assert decision.level_counts[int(Validity.BREAKS_TRAFFIC_RULE)] > 0 and not _crosses(decision)


def test_lane_blocked_by_hand():
    env = _marked_road()
    # Ego centre at s = 40 m, 4 m long: "ahead" is 38 .. 82 m (front 42 + 40 m).
    at = np.array([[81.0, 0.0], [83.0, 0.0], [60.0, 3.5], [60.0, 2.2]])
    speeds, widths = np.zeros(4), np.full(4, 2.0)
    blocked = [
        lane_blocked(env, (40.0, 0.0), 4.0, at[i : i + 1], speeds[:1], widths[:1], 1.0, 40.0)
        for i in range(4)
    ]
    # In reach; beyond it; in the other lane; reaching 1.2 m into the ego lane (edge at 1.75).
    assert blocked == [True, False, False, True]
    assert not lane_blocked(
        env, (40.0, 0.0), 4.0, at[:1], np.array([1.0]), widths[:1], 1.0, 40.0
    )  # not slower
