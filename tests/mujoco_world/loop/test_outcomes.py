"""Outcomes at the time limit: timeout, stopped_safely, no_progress (``loop.progress``)."""

import re

import pytest

from mujoco_world.loop.config import RunConfig
from mujoco_world.loop.progress import StallConfig, blocked_way
from mujoco_world.loop.runner import run_scenario
from mujoco_world.loop.world import World
from mujoco_world.scenario.spec import scenario_from_dict


def _parked(name, s, lane):
    """A car standing in ``lane`` facing +x (in lane 1, the other direction's lane: wrong way)."""
    route = {"lane": lane, "wrong_way": lane == 1}
    return {"name": name, "type": "car", "s0": s, "route": route, "behaviour": {"kind": "scripted"}}


def _standing(users=(), stop_lines=(), duration=6.0, speed=0.0):
    """The ego stands at s = 5 m (``emergency_brake`` from 0 m/s) on a two-lane 100 m road."""
    data = {
        "name": "t",
        "road": {"length": 100.0},
        "ego": {"s0": 5.0, "speed": speed, "goal_s": 90.0},
        "road_users": list(users),
        "stop_lines": list(stop_lines),
        "duration": duration,
    }
    return scenario_from_dict(data)


def _outcome(scenario, planner="emergency_brake", config=None):
    summary = run_scenario(scenario, planner, seed=0, config=config or RunConfig())
    return summary.outcome, summary.reason


def test_standing_on_an_empty_road_is_no_progress():
    outcome, reason = _outcome(_standing())
    assert outcome == "no_progress" and "passage of its width open" in reason


def test_standing_near_the_road_end_with_the_way_open_is_no_progress():
    """Review of stop 19: the cross-section 20 m ahead lay beyond the end of the shrunk
    drivable area (it ends half a width + 0.25 m before the road's end), so an ego
    standing on an empty road 18 m before its end read as a safe stop."""
    data = {
        "name": "t",
        "road": {"length": 100.0},
        "ego": {"s0": 80.0, "speed": 0.0, "goal_s": 98.0},
        "duration": 6.0,
    }
    scenario = scenario_from_dict(data)
    outcome, reason = _outcome(scenario)
    assert outcome == "no_progress" and "passage of its width open" in reason


def test_standing_behind_a_car_with_the_other_lane_free_is_no_progress():
    # One car across lane 0 (y = -1.75 m, 1.8 m wide), grown by the ego's half width 0.805 m
    # + 0.25 m, covers y in [-3.7, 0.2]; the road's 8 m shrunk by 1.055 m per side leaves
    # [0.2, 2.95] free.
    outcome, _ = _outcome(_standing([_parked("car", 15.0, 0)]))
    assert outcome == "no_progress"
    assert (
        _outcome(_standing([_parked("car", 15.0, 0)]), config=RunConfig(stall=StallConfig(margin=1.45)))[0]
        == "no_progress"
    )


def test_standing_before_two_cars_side_by_side_is_a_safe_stop():
    # The second car (lane 1, y = +1.75 m) covers [-0.2, 3.7]: no passage is left.
    outcome, reason = _outcome(_standing([_parked("a", 15.0, 0), _parked("b", 15.0, 1)]))
    assert outcome == "stopped_safely" and "no passage" in reason
    # Beyond the 20 m lookahead (front at 7.25 m, cars' rear at 37.75 m) they do not excuse it.
    outcome, _ = _outcome(_standing([_parked("a", 40.0, 0), _parked("b", 40.0, 1)]))
    assert outcome == "no_progress"
    # The single car with a margin beyond 1.62 m (above) closes the way.
    config = RunConfig(stall=StallConfig(margin=1.7))
    assert _outcome(_standing([_parked("car", 15.0, 0)]), config=config)[0] == "stopped_safely"


def test_waiting_at_a_red_light_is_a_safe_stop():
    red = {"name": "light", "s": 20.0, "red": [[0.0, 100.0]]}
    outcome, reason = _outcome(_standing(stop_lines=[red]))
    assert outcome == "stopped_safely" and "'light'" in reason
    # Green at the end: the wait has no reason left.
    green_at_end = {"name": "light", "s": 20.0, "red": [[0.0, 5.0]]}
    assert _outcome(_standing(stop_lines=[green_at_end]))[0] == "no_progress"
    # Red, but 40 m ahead of the front (beyond the 20 m lookahead): stalled.
    far = {"name": "light", "s": 47.5, "red": [[0.0, 100.0]]}
    assert _outcome(_standing(stop_lines=[far]))[0] == "no_progress"


def test_a_slow_ego_that_keeps_moving_is_a_timeout():
    outcome, reason = _outcome(_standing(speed=2.0, duration=7.0), planner="keep_lane")
    # About 2 m/s over the last 5 s of 7 (the window): about 10 m.
    moved = re.search(r"moved ([0-9.]+) m in the last 5 s", reason)
    assert outcome == "timeout" and float(moved.group(1)) == pytest.approx(10.0, abs=0.6)


@pytest.mark.parametrize("bad", [{"window": 0.0}, {"distance": -1.0}, {"margin": -0.1}])
def test_bad_stall_settings_are_named(bad):
    with pytest.raises(ValueError, match=f"stall.{next(iter(bad))}"):
        StallConfig(**bad)


def _oncoming(name, x, speed=10.0, length=100.0):
    """A car in the other direction's lane at x [m], driving towards the ego at ``speed``."""
    route = {"lane": 0, "direction": -1}
    behaviour = {"kind": "scripted", "speed": speed}
    return {"name": name, "type": "car", "s0": length - x, "route": route, "behaviour": behaviour}


def test_oncoming_traffic_closes_the_passage_it_will_drive_through():
    # The ego (front at 7.25 m) stands behind a car in its lane at 15 m; the way is
    # judged at the cross-section 20 m ahead of its front, x = 27.25 m. An oncoming car
    # at x = 50 m and 10 m/s covers x in [0 - 2.25, 50 + 2.25] in the next 5 s: closed.
    world = World(_standing([_parked("car", 15.0, 0), _oncoming("on", 50.0)]))
    assert blocked_way(world, 20.0, 0.25, oncoming_time=5.0)
    # Seen only where it is (the old test), the gap before it read as open.
    assert not blocked_way(world, 20.0, 0.25, oncoming_time=0.0)
    # At x = 90 m it covers [37.75, 92.25]; grown by the ego's half width + margin
    # (1.055 m) it starts at 36.7 m, beyond the cross-section: open.
    far = World(_standing([_parked("car", 15.0, 0), _oncoming("on", 90.0)]))
    assert not blocked_way(far, 20.0, 0.25, oncoming_time=5.0)
    # A car driving the ego's way in the other lane moves off: it blocks only where it is.
    ahead = {"name": "away", "type": "car", "s0": 50.0, "route": {"lane": 1, "wrong_way": True},
             "behaviour": {"kind": "scripted", "speed": 10.0}}  # fmt: skip
    assert not blocked_way(World(_standing([_parked("car", 15.0, 0), ahead])), 20.0, 0.25, oncoming_time=5.0)
