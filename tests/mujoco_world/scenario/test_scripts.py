"""Scripted events of road users: conditions, actions, order, validation."""

import re

import pytest

from mujoco_world.loop.world import World
from mujoco_world.scenario.spec import ActionSpec, ConditionSpec, scenario_from_dict


def _world(events, other_speed=8.0):
    scenario = scenario_from_dict(
        {
            "name": "t",
            "road": {"length": 300.0},
            "ego": {"s0": 5.0, "speed": 0.0},
            "road_users": [
                {
                    "name": "a",
                    "type": "car",
                    "s0": 40.0,
                    "behaviour": {"kind": "scripted", "speed": 10.0, "events": events},
                },
                {
                    "name": "b",
                    "type": "car",
                    "s0": 10.0,
                    "route": {"lane": 1, "wrong_way": True},
                    "behaviour": {"kind": "scripted", "speed": other_speed},
                },
            ],
        }
    )
    return World(scenario)


def _run(world, until):
    while world.time < until - 1e-9:
        world.step()


def test_stop_start_change_lane_and_a_condition_on_another_road_user_run_in_order():
    world = _world(
        [
            {"when": {"time": 1.0}, "do": {"stop": True, "acceleration": 5.0}},
            {
                "when": {"speed_below": 0.1, "delay": 0.5},
                "do": {"start": True, "change_lane": 1, "duration": 2},
            },
            {"when": {"of": "b", "s_above": 60.0}, "do": {"speed": 15.0, "acceleration": 2.0}},
        ]
    )
    fleet = world.fleet
    _run(world, 1.0)
    assert fleet.script.fired[0] == []  # the tick at t = 1 s has not been taken yet
    _run(world, 2.99)
    # Braking from 10 m/s at 5 m/s^2 from t = 1 s: 10 m to a stop at t = 3 s.
    assert fleet.script.fired[0] == [pytest.approx(1.0)]
    assert fleet.s[0] == pytest.approx(50.0 + 10.0, abs=0.15)
    _run(world, 5.2)
    # Fired at the stop (its speed fell below 0.1 m/s, 2 s after the first): a full
    # lane (3.5 m) to the left in 2 s, back to 10 m/s at 3 m/s^2.
    assert fleet.script.fired[0][1] == pytest.approx(3.0, abs=0.06)
    assert fleet.d[0] == pytest.approx(3.5, abs=1e-6)
    assert fleet.v[0] == pytest.approx(3.0 * (5.2 - fleet.script.fired[0][1]), abs=0.2)
    _run(world, 6.6)
    # b starts at 10 m and drives 8 m/s: beyond 60 m after 6.25 s; the next tick is 6.30 s.
    assert fleet.script.fired[0][2] == pytest.approx(6.30, abs=1e-6)
    _run(world, 12.0)
    assert fleet.v[0] == pytest.approx(15.0)


def test_an_event_waits_for_the_one_before_it():
    # The second event's condition holds from the start, but the first fires only at 2 s.
    world = _world(
        [
            {"when": {"time": 2.0}, "do": {"speed": 5.0}},
            {"when": {"time": 0.5}, "do": {"speed": 12.0, "acceleration": 1.0}},
        ]
    )
    _run(world, 2.2)
    # One event per road user and behaviour tick (0.05 s): the second fires on the next.
    assert world.fleet.script.fired[0] == [pytest.approx(2.0), pytest.approx(2.05)]
    assert world.fleet.script.longitudinal[0][1][-1][1] == 12.0


def test_distance_and_time_to_collision_conditions():
    world = _world(
        [
            {"when": {"time": 0.0}, "do": {"stop": True, "acceleration": 10.0}},
            {"when": {"to": "b", "distance_below": 10.0}, "do": {"speed": 2.0, "acceleration": 1.0}},
        ]
    )
    _run(world, 6.0)
    fired = world.fleet.script.fired[0]
    # a stops at 40 + 10^2 / (2 10) = 45 m; b (x = 10 + 8 t, 3.5 m aside) comes within
    # 10 m centre distance when it is sqrt(100 - 3.5^2) = 9.37 m behind: t = 3.20 s.
    assert fired[1] == pytest.approx((45.0 - (100.0 - 3.5**2) ** 0.5 - 10.0) / 8.0, abs=0.06)
    assert world.fleet.v[0] == pytest.approx(2.0)  # 2 s of 1 m/s^2 after 3.2 s
    head_on = scenario_from_dict(
        {
            "name": "t",
            "road": {"length": 300.0},
            "ego": {"s0": 5.0, "speed": 0.0},
            "road_users": [
                {
                    "name": "a",
                    "type": "car",
                    "s0": 250.0,
                    "route": {"lane": 1, "direction": -1, "wrong_way": True},  # the ego's lane, towards it
                    "behaviour": {
                        "kind": "scripted",
                        "speed": 10.0,
                        "events": [{"when": {"to": "ego", "ttc_below": 2.0}, "do": {"stop": True}}],
                    },
                },
            ],
        }
    )
    world = World(head_on)
    _run(world, 3.0)
    # Its centre starts at x = 50 and closes at 10 m/s on the standing ego (x = 5): the
    # bumpers (4.5 m and 4.508 m long) are 2 s = 20 m apart at t = (45 - 4.504 - 20) / 10.
    expected = (45.0 - 4.504 - 20.0) / 10.0
    assert world.fleet.script.fired[0] == [pytest.approx(expected, abs=0.06)]
    away = _world([{"when": {"to": "ego", "ttc_below": 2.0}, "do": {"stop": True}}])
    _run(away, 1.0)
    assert away.fleet.script.fired[0] == []  # driving away from the ego: no time-to-collision


@pytest.mark.parametrize(
    ("event", "message"),
    [
        ({"when": {}, "do": {"stop": True}}, "events[0].when: needs at least one condition of time, delay"),
        ({"when": {"time": 1.0}, "do": {}}, "events[0].do: needs an action: speed, stop"),
        ({"when": {"time": 1.0, "to": "bob"}, "do": {"stop": True}}, "when.to: unknown road user 'bob'"),
        ({"when": {"time": 1.0}, "do": {"stop": True, "speed": 3.0}}, "takes one of speed, stop, start"),
        (
            {"when": {"time": 1.0}, "do": {"change_lane": 1, "lateral": [[1, 1]]}},
            "one of lateral, change_lane",
        ),
        (
            {"when": {"tim": 1.0}, "do": {"stop": True}},
            "unknown key 'road_users[0].behaviour.events[0].when.tim'",
        ),
        (
            {"when": {"ttc_below": -1.0}, "do": {"stop": True}},
            "events[0].when.ttc_below must lie in [0.01, 60] s",
        ),
        ({"when": {"time": 1.0}, "do": {"change_lane": 9}}, "do.change_lane must lie in -4..4"),
        (
            {"when": {"time": 1.0}, "do": {"change_lane": -1}},
            "events[0].do.change_lane = -1 takes it to lane -1, off the road: its lanes are 0 to 1 "
            "(from the right in its direction), it starts in lane 0",
        ),
        ({"when": {"time": 1.0, "to": "a"}, "do": {"stop": True}}, "a road user measures to others"),
        (
            {"when": {"distance_above": 10.0, "distance_below": 5.0}, "do": {"stop": True}},
            "events[0].when.distance_above (10) must be below when.distance_below (5)",
        ),
        ({"when": {"speed_above": 3.0, "speed_below": 3.0}, "do": {"stop": True}}, "can never fire"),
    ],
)
def test_bad_events_are_named(event, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        _world([event])


def test_lane_changes_add_up_in_script_order():
    left = {"when": {"time": 1.0}, "do": {"change_lane": 1}}
    back = {"when": {"delay": 1.0}, "do": {"change_lane": -1}}
    assert _world([left, back, left]).fleet  # 0 -> 1 -> 0 -> 1: on the road throughout
    message = "events[1].do.change_lane = 1 takes it to lane 2, off the road"
    with pytest.raises(ValueError, match=re.escape(message)):
        _world([left, left])


def test_parked_road_users_take_no_events():
    with pytest.raises(ValueError, match="takes no speed, speed_profile, lateral or events"):
        scenario_from_dict(
            {
                "name": "t",
                "road_users": [
                    {
                        "name": "p",
                        "type": "car",
                        "s0": 40.0,
                        "behaviour": {
                            "kind": "parked",
                            "events": [{"when": {"time": 1}, "do": {"start": True}}],
                        },
                    }
                ],
            }
        )


def test_records_are_frozen_and_validated_at_construction():
    assert ConditionSpec(time=1.0).needs_ego_s is False
    assert ConditionSpec(of="ego", s_above=10.0).needs_ego_s is True
    with pytest.raises(ValueError, match="when.to must be 'ego' or another road user's name"):
        ConditionSpec(time=1.0, to="self")
    assert ActionSpec(speed_profile=((1.0, 3.0),)).speed_profile == ((1.0, 3.0),)
