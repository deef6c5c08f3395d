"""MOBIL's European passing rule (``mobil.no_passing_right``): hand values and closed loop."""

import math
import re

import numpy as np
import pytest

from mujoco_world.agents.mobil import (
    IdmParameters,
    lane_neighbours,
    mobil_accelerations,
    no_passing_on_the_right,
)
from mujoco_world.loop.world import World
from mujoco_world.scenario.spec import scenario_from_dict

W = 3.5  # lane width [m]
A, B, T, S0, V0 = 1.5, 2.0, 1.5, 2.0, 30.0  # IDM defaults; every body wants 30 m/s
V_CRIT = 60.0 / 3.6


def _idm_by_hand(v, gap, v_lead):
    free = 1.0 - (v / V0) ** 4
    if math.isinf(gap):
        return A * free
    s_star = S0 + max(0.0, v * T + v * (v - v_lead) / (2.0 * math.sqrt(A * B)))
    return A * (free - (s_star / gap) ** 2)


def _own(left_leader_speed, left_runs=True, rule=True):
    """Own accelerations of a 28 m/s car in lane 0 (lane free ahead), a leader 40 m ahead in lane 1.

    Bodies 4 m x 2 m; the ego (body 0) far behind.
    """
    position = np.array([[-1000.0, 0.0], [0.0, 0.0], [40.0, W]])
    velocity = np.array([[0.0, 0.0], [28.0, 0.0], [left_leader_speed, 0.0]])
    n = 3
    samples = np.arange(-80.0, 150.0 + 1e-9, 1.0)
    x, y = samples[None, :], np.zeros((1, samples.size))
    me = np.array([1])
    nb = lane_neighbours(
        x, y, np.zeros_like(x), samples[None, :], me, np.zeros(1), W,
        position, velocity, np.zeros(n), np.full(n, 4.0), np.full(n, 2.0),
        np.ones(n, dtype=bool), np.ones((1, n), dtype=bool), np.full((1, 3), np.inf),
    )  # fmt: skip
    idm = IdmParameters(*(np.full(n, value) for value in (V0, A, B, T, S0)))
    v_crit = np.array([V_CRIT if rule else math.inf])
    return mobil_accelerations(nb, me, np.array([28.0]), idm, np.array([left_runs]), v_crit).own[0]


def test_the_own_lane_is_limited_by_the_faster_than_v_crit_left_leader_by_hand():
    free = _idm_by_hand(28.0, math.inf, 0.0)  # 1.5 (1 - (28/30)^4) = 0.3618
    behind_left = _idm_by_hand(28.0, 36.0, 25.0)  # s* = 2 + 42 + 28 x 3 / (2 sqrt 3) = 68.25 m: -5.029
    assert free == pytest.approx(0.3618, abs=1e-4)
    assert behind_left == pytest.approx(-5.0293, abs=1e-4)
    # Without the rule it would pass at its free-road acceleration; with it, it follows the left leader.
    assert _own(25.0, rule=False)[1] == pytest.approx(free, rel=1e-9)
    assert _own(25.0)[1] == pytest.approx(behind_left, rel=1e-9)
    # The lane to its right (none here, free road) is limited by its current lane's leader (none): free.
    assert _own(25.0)[0] == pytest.approx(free, rel=1e-9)
    # Congestion: a left leader at 10 m/s (< 16.7 m/s) may be passed on the right.
    assert _own(10.0)[1] == pytest.approx(free, rel=1e-9)
    # An oncoming lane to its left is no passing lane.
    assert _own(25.0, left_runs=False)[1] == pytest.approx(free, rel=1e-9)


def test_no_passing_on_the_right_takes_the_minimum_lane_by_lane():
    own = np.array([[1.0, 0.5, -2.0], [1.0, 0.5, -2.0], [-3.0, 0.5, 0.2]])
    lead_speed = np.array([[0.0, 20.0, 20.0], [0.0, 10.0, 10.0], [0.0, 20.0, 20.0]])
    limited = no_passing_on_the_right(own, lead_speed, np.array([True, True, True]), np.full(3, V_CRIT))
    # row 0: both limits bind; row 1: congestion, none; row 2: the minimum is the lane's own
    np.testing.assert_array_equal(limited, [[0.5, -2.0, -2.0], [1.0, 0.5, -2.0], [-3.0, 0.2, 0.2]])


def _hogger_world(no_passing_right):
    """Two-lane one-way road: a 20 m/s idm car in the left lane, a 28 m/s MOBIL car behind it in the right."""
    scenario = scenario_from_dict(
        {
            "name": "hogger",
            "duration": 20.0,
            "road": {
                "length": 900.0,
                "lanes": 2,
                "lanes_forward": 2,
                "speed_limit": 30.0,
                "boundary": "wall",
            },
            "ego": {"s0": 5.0, "speed": 0.0, "lane": 0, "goal_s": 880.0},
            "road_users": [
                {
                    "name": "slow_left",
                    "type": "car",
                    "s0": 100.0,
                    "route": {"lane": 1},
                    "behaviour": {"kind": "idm", "speed": 20.0},
                },
                {
                    "name": "fast",
                    "type": "car",
                    "s0": 60.0,
                    "route": {"lane": 0},
                    "behaviour": {
                        "kind": "idm",
                        "speed": 28.0,
                        "mobil": {"no_passing_right": no_passing_right},
                    },
                },
            ],
        }
    )
    return World(scenario)


@pytest.mark.parametrize("rule", [False, True])
def test_closed_loop_a_faster_car_does_not_pass_a_slower_one_on_the_right(rule):
    world = _hogger_world(rule)
    fleet = world.fleet
    hits = []
    while world.time < 15.0:
        hits += world.step()
    assert hits == []
    ahead = fleet.s[1] - fleet.s[0]
    if rule:
        # It stays behind, in its lane, at the left car's speed.
        assert ahead < -4.5 and fleet.v[1] == pytest.approx(20.0, abs=0.5)
        assert fleet.lane_changes == [] and fleet.d[1] == 0.0
    else:
        # 8 m/s faster for 15 s: it has passed on the right (40 m behind at the start).
        assert ahead > 40.0
        assert fleet.lane_changes == []


@pytest.mark.parametrize(
    ("mobil", "message"),
    [
        ({"no_passing_right": "yes"}, "mobil.no_passing_right must be true or false, got 'yes'"),
        ({"pass_right_below": 90.0}, "mobil.pass_right_below must lie in [0, 70] m/s, got 90.0"),
    ],
)
def test_passing_rule_fields_are_validated_by_name(mobil, message):
    user = {"name": "u", "type": "car", "behaviour": {"kind": "idm", "mobil": mobil}}
    with pytest.raises(ValueError, match=re.escape(message)):
        scenario_from_dict({"name": "t", "road_users": [user]})
