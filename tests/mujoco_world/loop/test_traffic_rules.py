"""Traffic rules for the ego: stop lines (red lights, stop signs), violations, [expect]."""

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from ethical_planner.environment import StopLine
from mujoco_world.loop.metrics import RuleViolations
from mujoco_world.loop.runner import run_scenario
from mujoco_world.loop.world import World
from mujoco_world.scenario.catalog import get_scenario
from mujoco_world.scenario.spec import StopLineSpec, scenario_from_dict


class _Ego:
    """A stand-in world: the ego's centre arc length, speed and the time, set by the test."""

    def __init__(self) -> None:
        self.lengths = np.array([4.0])
        self.s, self.v, self.time = 0.0, 0.0, 0.0
        self.scene = SimpleNamespace(speeds=lambda: np.array([self.v]))

    def ego_progress(self) -> float:
        return self.s


def _judge(lines, motion):
    """Violations of an ego driving ``motion`` (time, centre s, speed) past ``lines``."""
    world = _Ego()
    run = SimpleNamespace(world=world, scenario=SimpleNamespace(stop_lines=tuple(lines)))
    metric = RuleViolations()
    metric.start(run)
    for t, s, v in motion:
        world.time, world.s, world.v = t, s, v
        metric.sample(run)
    return metric.values(run)["rule_violations"]


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
