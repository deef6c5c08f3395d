"""Traffic rules for the ego: stop lines (red lights, stop signs), violations, [expect]."""

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from ethical_planner.config import PlannerConfig, TrafficRulesConfig, VehicleConfig, preset
from ethical_planner.environment import StopLine
from mujoco_world.loop.metrics import RuleViolations
from mujoco_world.loop.runner import closed_loop, run_scenario
from mujoco_world.loop.world import World
from mujoco_world.scenario.catalog import get_scenario
from mujoco_world.scenario.spec import StopLineSpec, scenario_from_dict


class _Ego:
    """A stand-in world: the ego's centre arc length, speed and the time, set by the test.

    Its road has no markings (the stop lines are judged alone), and it does not accelerate.
    """

    def __init__(self) -> None:
        self.lengths = np.array([4.0])
        self.s, self.v, self.time = 0.0, 0.0, 0.0
        self.scene = SimpleNamespace(speeds=lambda: np.array([self.v]))

    def ego_progress(self) -> float:
        return self.s

    def accelerations_along_heading(self) -> np.ndarray:
        return np.zeros(1)

    def environment(self):
        return SimpleNamespace(no_overtaking=(), lane_edges=None, centre_line=None)


def _judge(lines, motion, values=False, planner_config=None):
    """Violations of an ego driving ``motion`` (time, centre s, speed) past ``lines`` (or all values)."""
    world = _Ego()
    scenario = SimpleNamespace(stop_lines=tuple(lines), road=SimpleNamespace(no_overtaking=()))
    run = SimpleNamespace(world=world, scenario=scenario, planner_config=planner_config or PlannerConfig())
    metric = RuleViolations()
    metric.start(run)
    for t, s, v in motion:
        world.time, world.s, world.v = t, s, v
        metric.sample(run)
    return metric.values(run) if values else metric.values(run)["rule_violations"]


def _drive(speed, s0=0.0, t_end=10.0, dt=0.01):
    return [(t, s0 + speed * t, speed) for t in np.arange(0.0, t_end, dt)]


def test_crossing_on_red_is_a_violation_and_on_green_is_not():
    # The front (centre + 2 m) reaches the line at s = 50 m at t = 48 / 10 = 4.8 s.
    light = StopLineSpec("light", s=50.0, red=((0.0, 5.0),))
    (v,) = _judge([light], _drive(10.0))
    assert (v.rule, v.line, v.speed) == ("red_light", "light", 10.0)
    assert v.time == pytest.approx(4.8, abs=0.011)
    assert _judge([StopLineSpec("light", s=50.0, red=((0.0, 4.7),))], _drive(10.0)) == ()
    # Red again later: only the moment of crossing counts, and a line counts once.
    assert _judge([StopLineSpec("light", s=50.0, red=((0.0, 4.7), (4.9, 9.0)))], _drive(10.0)) == ()


def test_a_crossing_the_ego_could_not_stop_for_when_the_light_turned_is_amber_not_red():
    # 10 m/s, no acceleration: braking at 8 m/s^2 after the 30 m/s^3 ramp (0.267 s,
    # 2.572 m, down to 8.933 m/s) then 8.933^2 / 16 = 4.988 m: 7.56 m in all. The front
    # (centre + 2 m) is at 10 t + 2 and reaches the line (50 m) at 4.8 s.
    # Red from 4.1 s: the gap is then 7.0 m < 7.56 m, the planner's dilemma zone.
    out = _judge([StopLineSpec("light", s=50.0, red=((4.1, 9.0),))], _drive(10.0), values=True)
    assert out["rule_violations"] == ()
    (amber,) = out["amber_crossings"]
    assert amber["line"] == "light" and amber["time"] == pytest.approx(4.8, abs=0.011)
    # Red from 4.0 s: the gap is 8.0 m > 7.56 m, it could have stopped: a red-light violation.
    out = _judge([StopLineSpec("light", s=50.0, red=((4.0, 9.0),))], _drive(10.0), values=True)
    (v,) = out["rule_violations"]
    assert v.rule == "red_light" and "amber_crossings" not in out


def test_the_dilemma_zone_is_measured_with_the_planner_s_vehicle():
    # The amber case above (red from 4.1 s, 7.0 m to the line at 10 m/s) with a planner whose
    # vehicle brakes at 12 m/s^2 after a 30 m/s^3 ramp: 0.4 s and 10 x 0.4 - 30 x 0.4^3 / 6 =
    # 3.68 m, down to 7.6 m/s, then 7.6^2 / 24 = 2.41 m: 6.09 m < 7.0 m, it could have stopped.
    light = StopLineSpec("light", s=50.0, red=((4.1, 9.0),))
    strong = PlannerConfig(vehicle=VehicleConfig(emergency_deceleration=12.0))
    out = _judge([light], _drive(10.0), values=True, planner_config=strong)
    (v,) = out["rule_violations"]
    assert v.rule == "red_light" and "amber_crossings" not in out


def test_the_run_hands_the_planner_s_configuration_to_the_judge():
    scenario = dataclasses.replace(get_scenario("red_light_for_ego"), duration=0.2)
    config = dataclasses.replace(preset("selfish"), vehicle=VehicleConfig(emergency_deceleration=9.0))
    loop = closed_loop(scenario, config)
    assert loop.run.planner_config is loop.planner.config
    assert loop.run.planner_config.vehicle.emergency_deceleration == 9.0
    assert closed_loop(scenario, "keep_lane").run.planner_config == PlannerConfig()


def test_a_stop_sign_needs_a_standstill_within_its_zone():
    sign = StopLineSpec("sign", s=50.0, stop=True, stop_zone=10.0)
    (v,) = _judge([sign], _drive(10.0))
    assert (v.rule, v.line) == ("stop_sign", "sign")
    # Stop with the front 5 m before the line (centre 43 m), wait, go: no violation.
    stop_and_go = [(0.0, 43.0, 0.0), (1.0, 43.0, 0.05)] + [
        (1.0 + t, 43.0 + 5 * t, 5.0) for t in np.arange(0.01, 3, 0.01)
    ]
    assert _judge([sign], stop_and_go) == ()
    # A standstill 15 m before the line (outside the 10 m zone) does not count.
    early = [(0.0, 33.0, 0.0)] + [(t, 33.0 + 5 * t, 5.0) for t in np.arange(0.01, 6, 0.01)]
    (v,) = _judge([sign], early)
    assert v.rule == "stop_sign"


def test_the_ego_running_the_red_light_is_reported_and_fails_its_expectation():
    scenario = get_scenario("red_light_for_ego")
    (line,) = scenario.stop_lines
    # Line at 80 - 4 (half width) - 0 (shoulder) - 2 = 74 m; the ego (4.5 m, centre at
    # 10 m, 12 m/s, keep_lane) puts its front on it at (74 - 2.25 - 10) / 12 = 5.146 s.
    assert line.s == pytest.approx(74.0)
    summary = run_scenario(dataclasses.replace(scenario, duration=5.5), "keep_lane", seed=0)
    (v,) = summary.rule_violations
    assert (
        v.rule == "red_light" and v.time == pytest.approx(5.146, abs=0.011) and v.speed == pytest.approx(12.0)
    )
    items = {e.name: e for e in summary.expectations}
    assert not items["max_rule_violations"].passed and items["max_rule_violations"].measured == "1"
    # Without the red window nothing is broken.
    green = dataclasses.replace(
        scenario, duration=5.5, stop_lines=(StopLineSpec("light", s=74.0, red=((6.0, 9.0),)),)
    )
    assert run_scenario(green, "keep_lane", seed=0).rule_violations == ()


@pytest.mark.parametrize(
    "planner",
    [
        "ethical",
        pytest.param("selfish", marks=pytest.mark.slow),
        pytest.param("standard", marks=pytest.mark.slow),
    ],
)
def test_the_planners_wait_for_the_green_and_meet_every_expectation(planner):
    """Closed loop: the planner respects the red light (ethical_planner.traffic_rules)."""
    summary = run_scenario(get_scenario("red_light_for_ego"), planner, seed=0)
    assert summary.rule_violations == ()
    assert all(e.passed for e in summary.expectations), summary.expectations
    assert summary.outcome == "goal"


def test_the_planner_stops_at_a_stop_sign_then_drives_on():
    """Closed loop: the planner's standstill memory and the world's judge agree."""
    scenario = scenario_from_dict(
        {
            "name": "stop_sign",
            "road": {"length": 150.0},
            "ego": {"s0": 10.0, "speed": 10.0, "goal_s": 120.0},
            "stop_lines": [{"name": "sign", "s": 60.0, "stop": True}],
            "duration": 25.0,
            "expect": {"max_rule_violations": 0, "reach_goal": True},
        }
    )
    summary = run_scenario(scenario, "ethical", seed=0)
    assert summary.rule_violations == () and summary.outcome == "goal"
    assert all(e.passed for e in summary.expectations)


def test_the_planner_receives_the_stop_lines_as_environment_data():
    env = World(get_scenario("red_light_for_ego")).environment()
    assert env.stop_lines == (StopLine(74.0, ((0.0, 9.0),), False),)
    assert env.stop_lines[0].red_at(8.99) and not env.stop_lines[0].red_at(9.0)


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ({"name": "a", "s": 50.0}, "stop_lines[0]: stop_line: give red windows"),
        ({"name": "a", "s": 50.0, "red": [[0.0, 5.0]], "stop": True}, "not both"),
        (
            {"name": "a", "s": 50.0, "red": [[5.0, 1.0]]},
            "stop_lines[0].red: each window needs 0 <= start < end",
        ),
        ({"name": "a", "s": 50.0, "red": [[0.0, 5.0], [4.0, 8.0]]}, "must be in order and not overlap"),
        ({"name": "a", "s": 50.0, "stop": True, "zone": 3.0}, "unknown key 'stop_lines[0].zone'"),
        # ego.s0 = 5, length 4.508: its front is at 7.254 m; a line there counts as crossed at once
        ({"name": "a", "s": 7.0, "stop": True}, ".s must lie ahead of the ego's front at the start"),
        ({"name": "a", "s": 150.0, "stop": True}, ".s must lie on the road"),
    ],
)
def test_bad_stop_lines_are_named(line, message):
    data = {"name": "t", "road": {"length": 100.0}, "ego": {"s0": 5.0}, "stop_lines": [line]}
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]").replace(".", r"\.")):
        scenario_from_dict(data)


def test_max_rule_violations_must_be_a_count():
    data = {"name": "t", "road": {"length": 100.0}, "ego": {"s0": 5.0}, "expect": {"max_rule_violations": -1}}
    with pytest.raises(ValueError, match="expect.max_rule_violations must be an integer >= 0"):
        scenario_from_dict(data)


# --------------------------------------------------------------------------- lane markings


def _zone_world(users=()):
    """Two lanes (one each way) of 3.5 m, shoulders 0.5 m, a no-overtaking zone from 50 to 100 m."""
    return World(
        scenario_from_dict(
            {
                "name": "zone",
                "road": {"length": 200.0, "no_overtaking": [{"start": 50.0, "end": 100.0}]},
                "ego": {"s0": 10.0, "speed": 0.0},
                "road_users": list(users),
            }
        )
    )


def _judge_values(world, poses, planner_config=None):
    """The judge's values for an ego placed at ``poses`` (time, x, y) in turn (ego lane: y = -1.75 m)."""
    run = SimpleNamespace(
        world=world, scenario=world.scenario, planner_config=planner_config or PlannerConfig()
    )
    metric = RuleViolations()
    metric.start(run)
    for t, x, y in poses:
        world.scene.data.time = t
        world.scene.qpos[0] = (x, y, 0.0)
        metric.sample(run)
    return metric.values(run)


def _judge_poses(world, poses, planner_config=None):
    """The world's judge's rule violations for an ego placed at ``poses`` in turn."""
    return _judge_values(world, poses, planner_config)["rule_violations"]


def test_the_world_judges_crossings_in_the_zone_and_shoulder_use():
    # The ego is 1.61 m wide: at y = -0.5 m (d = 1.25 m from its lane's centre) its left
    # edge reaches 2.055 m, 0.305 m across the centre line (d = 1.75 m; tolerance 0.1 m).
    # At y = -3.0 m its right edge reaches d = -2.055 m, 0.305 m beyond the lane edge.
    poses = [
        (0.0, 60.0, -1.75),
        (1.0, 62.0, -0.5),  # across, in the zone: no_overtaking
        (2.0, 70.0, -0.5),  # still across: the same crossing
        (3.0, 110.0, -1.75),
        (4.0, 120.0, -0.5),  # across behind the zone: allowed
        (5.0, 130.0, -3.0),  # right shoulder
        (6.0, 140.0, -1.75),
        (7.0, 150.0, -1.7),  # 0.05 m: within the tolerance
    ]
    found = _judge_poses(_zone_world(), poses)
    assert [(v.rule, v.line, v.time) for v in found] == [
        ("no_overtaking", "no_overtaking_0", 1.0),
        ("shoulder", "right", 5.0),
    ]
    # The zone's front edge counts: the ego's front (x + 2.254) in the zone at x = 48.
    assert [v.rule for v in _judge_poses(_zone_world(), [(0.0, 40.0, -1.75), (1.0, 48.0, -0.5)])] == [
        "no_overtaking"
    ]
    assert _judge_poses(_zone_world(), [(0.0, 40.0, -1.75), (1.0, 47.0, -0.5)]) == ()


def test_passing_a_standing_car_in_the_zone_is_not_overtaking():
    stalled = {"name": "stalled", "type": "car", "s0": 75.0, "behaviour": {"kind": "scripted", "speed": 0.0}}
    poses = [(0.0, 60.0, -1.75), (1.0, 62.0, -0.5)]
    assert _judge_poses(_zone_world([stalled]), poses) == ()
    # Beyond the 40 m lookahead (front 64.25 + 40 = 104.25 m) it does not excuse the crossing.
    far = dict(stalled, s0=110.0)
    assert [v.rule for v in _judge_poses(_zone_world([far]), poses)] == ["no_overtaking"]
    # The lookahead is the planner's (traffic_rules.pass_lookahead): 50 m reach 114.25 m.
    config = PlannerConfig(traffic_rules=TrafficRulesConfig(pass_lookahead=50.0))
    assert _judge_poses(_zone_world([far]), poses, config) == ()


def test_zones_are_validated_by_name():
    base = {"name": "z", "road": {"length": 200.0}}
    for zone, message in (
        (
            {"start": 80.0, "end": 60.0},
            r"road.no_overtaking\[0\].end must lie beyond no_overtaking.start \(80 m\)",
        ),
        (
            {"start": 50.0, "end": 250.0},
            r"road.no_overtaking\[0\] \(no_overtaking_0\).end must lie on the road",
        ),
        ({"start": -5.0, "end": 60.0}, r"road.no_overtaking\[0\].start must be >= 0"),
    ):
        with pytest.raises(ValueError, match=message):
            scenario_from_dict({**base, "road": {"length": 200.0, "no_overtaking": [zone]}})
    with pytest.raises(ValueError, match=r"road.no_overtaking needs a centre line"):
        scenario_from_dict(
            {
                **base,
                "road": {"length": 200.0, "lanes_forward": 2, "no_overtaking": [{"start": 1.0, "end": 9.0}]},
            }
        )


def test_the_planner_receives_the_markings_as_environment_data():
    env = _zone_world().environment()
    # Relative to the ego lane's centre (y = -1.75 m): the centre line at 1.75 m, the
    # outer lane edges at -1.75 and 5.25 m; the zone along the straight route unchanged.
    assert env.centre_line == pytest.approx(1.75)
    assert env.lane_edges == pytest.approx((-1.75, 5.25))
    (zone,) = env.no_overtaking
    assert (zone.start, zone.end, zone.pass_below) == pytest.approx((50.0, 100.0, 4.47))


def test_the_planner_follows_the_cyclist_through_the_zone_and_overtakes_after_it():
    """Closed loop (catalog ``no_overtaking_zone``): no violation, the cyclist passed after the zone."""
    scenario = dataclasses.replace(get_scenario("no_overtaking_zone"), duration=23.0)
    summary = run_scenario(scenario, "ethical", seed=0)
    assert summary.rule_violations == () and not summary.ego_collided
    # The cyclist rides 6 m/s from 60 m: at 23 s it is at 198 m; the ego is past it.
    assert summary.progress > 60.0 + 6.0 * 23.0 + 3.0


def test_without_the_rule_the_planner_overtakes_inside_the_zone():
    scenario = dataclasses.replace(get_scenario("no_overtaking_zone"), duration=6.0)
    config = preset("ethical").with_overrides({"traffic_rules": {"no_overtaking": False}})
    (v,) = run_scenario(scenario, config, seed=0).rule_violations
    assert (v.rule, v.line) == ("no_overtaking", "bend_ahead") and v.time < 6.0


def test_the_stop_sign_catalog_scenario_catches_a_rolling_ego():
    # keep_lane holds 11 m/s: its front (centre 10 m + 2.254 m) reaches the line at
    # 80 - 3.5 (half the lanes) - 0.5 (shoulder) - 2 = 74 m after (74 - 12.254) / 11 = 5.613 s.
    scenario = dataclasses.replace(get_scenario("stop_sign"), duration=6.0)
    (line,) = scenario.stop_lines
    assert line.stop and line.s == pytest.approx(74.0)
    (v,) = run_scenario(scenario, "keep_lane", seed=0).rule_violations
    assert (v.rule, v.line) == ("stop_sign", "stop") and v.time == pytest.approx(5.613, abs=0.02)


def test_an_evasive_move_onto_the_shoulder_is_excused():
    # A wrong-way car in the ego's lane at x = 85 m, 10 m/s towards the standing ego at
    # 60 m: bumper gap 25 - 2.254 - 2.25 = 20.5 m, closed after 2.05 s (< 3 s) however the
    # ego (standing) brakes.
    def ghost(x):
        route = {"lane": 1, "direction": -1, "wrong_way": True}
        return {"name": "ghost", "type": "car", "s0": 200.0 - x, "route": route,
                "behaviour": {"kind": "scripted", "speed": 10.0}}  # fmt: skip

    poses = [(0.0, 60.0, -1.75), (0.1, 60.0, -3.0)]
    values = _judge_values(_zone_world([ghost(85.0)]), poses)
    assert values["rule_violations"] == ()
    (entry,) = values["excused_rule_entries"]
    assert (entry["rule"], entry["line"], entry["excuse"]) == ("shoulder", "right", "evasive")
    # At x = 120 m the gap is 55.5 m, 5.5 s: a violation.
    assert [v.rule for v in _judge_poses(_zone_world([ghost(120.0)]), poses)] == ["shoulder"]
