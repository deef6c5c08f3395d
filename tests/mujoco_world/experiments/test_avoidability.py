"""Avoidability search: exact branch states, and two cases with a known answer."""

from __future__ import annotations

import math

import pytest

from mujoco_world.evaluation.avoidability import ManoeuvreSpec
from mujoco_world.experiments.avoidability import AvoidabilityFamily, search
from mujoco_world.loop.runner import closed_loop, run_scenario
from mujoco_world.scenario.spec import scenario_from_dict


def parked_car_ahead():
    """The ego keeps its lane at 10 m/s towards a car parked in it 50 m ahead (contact ~4.5 s)."""
    return scenario_from_dict(
        {
            "name": "parked_ahead",
            "road": {"length": 200.0},
            "ego": {"s0": 10.0, "speed": 10.0, "goal_s": 150.0},
            "duration": 8.0,
            "road_users": [
                {
                    "name": "parked",
                    "type": "car",
                    "s0": 60.0,
                    "route": {"lane": 0},
                    "behaviour": {"kind": "parked"},
                }
            ],
        }
    )


def rear_ended_at_once():
    """A car 2 m behind the ego closes at 15 m/s: contact ~0.13 s after the start.

    Provably unavoidable by any manoeuvre: to escape, the ego must move its whole width
    (1.8 m) sideways or open the gap forward before the contact, i.e. ~1.8 m in 0.13 s,
    which needs 2 * 1.8 / 0.13^2 ~ 210 m/s^2, 24 times the friction limit (8.8 m/s^2);
    within the friction circle the ego moves at most 0.5 * 8.8 * 0.13^2 = 0.07 m.
    """
    return scenario_from_dict(
        {
            "name": "rear_ended",
            "road": {"length": 200.0},
            "ego": {"s0": 40.0, "speed": 5.0, "goal_s": 150.0},
            "duration": 4.0,
            "road_users": [
                {
                    "name": "tailgater",
                    "type": "car",
                    "s0": 40.0 - 4.6 - 2.0,
                    "route": {"lane": 0},
                    "behaviour": {"kind": "scripted", "speed": 20.0},
                }
            ],
        }
    )


def test_a_fork_continued_with_the_same_planner_is_the_run_itself():
    scenario = parked_car_ahead()
    whole = run_scenario(scenario, "keep_lane")
    loop = closed_loop(scenario, "keep_lane")
    loop.start()
    assert loop.advance(2.0) is None
    fork = loop.fork(loop.planner)
    forked = fork.resume()
    original = loop.resume()  # the original goes on untouched by its copy
    assert forked.comparable_dict() == whole.comparable_dict() == original.comparable_dict()
    assert whole.ego_collided


def test_a_crash_that_braking_avoids_is_avoidable():
    scenario = parked_car_ahead()
    run = run_scenario(scenario, "keep_lane")
    assert run.outcome == "crash" and run.ego_collided
    verdict = search(scenario, "keep_lane", 0, run)
    assert verdict.avoidable and verdict.partner == "parked"
    best = verdict.best
    assert not best.ego_collided and best.min_distance > 0
    assert best.manoeuvre.deceleration > 0  # braking: 10^2 / (2 * 4) = 12.5 m < 45 m of gap
    assert best.harm_ego_involved == {"ego": 0.0, "third_party": 0.0, "vulnerable": 0.0}
    assert verdict.crash_time == pytest.approx(4.5, abs=0.2)
    assert "AVOIDABLE" in verdict.describe()


def test_a_rear_end_within_0_13_s_is_not_avoidable():
    scenario = rear_ended_at_once()
    run = run_scenario(scenario, "keep_lane")
    assert run.ego_collided
    # a small family keeps the test short; the kinematic bound above holds for any manoeuvre
    family = AvoidabilityFamily(
        decelerations=(0.0, 8.0),
        swerves=(1.0,),
        durations=(1.0,),
        coarse_decelerations=(8.0,),
        coarse_durations=(1.0,),
        after=0.5,
    )
    verdict = search(scenario, "keep_lane", 0, run, family=family)
    assert not verdict.avoidable
    assert verdict.crash_time < 0.2 and verdict.earliest_branch == 0.0
    # the whole family at the one branch time (t = 0) was tried, and every manoeuvre collided
    assert verdict.branches >= len(family.manoeuvres(0.0, []))
    assert verdict.best.ego_collided and verdict.best.total_harm > 0


def test_search_refuses_a_run_without_ego_collision():
    scenario = parked_car_ahead()
    run = run_scenario(scenario, "emergency_brake")
    assert not run.ego_collided
    with pytest.raises(ValueError, match="no ego-involved collision"):
        search(scenario, "emergency_brake", 0, run)


def test_family_respects_the_friction_circle():
    family = AvoidabilityFamily()
    specs = family.manoeuvres(1.0, [3.5, -3.5])
    assert specs and all(s.start == 1.0 for s in specs)
    for s in specs:
        lateral = 10 / math.sqrt(3) * abs(s.offset) / s.duration**2 if s.duration else 0.0
        assert math.hypot(s.deceleration, lateral) <= family.friction + 1e-9
    # a lane change of 3.5 m over 1 s needs 20 m/s^2 sideways: not in the family
    assert not any(abs(s.offset) == 3.5 and s.duration == 1.0 for s in specs)
    assert ManoeuvreSpec(1.0, 0.0, 3.5, 2.5, True).kind == "lane_change"
