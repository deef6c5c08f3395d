"""The reaction level to the ego (``behaviour.ego_reaction`` in [0, 1]): hand values, the ends, validation."""

import dataclasses
import math
import re

import numpy as np
import pytest

from ethical_planner.road_users import RoadUserType
from mujoco_world.agents.behaviour import Fleet, WorldView
from mujoco_world.agents.mobil import IdmParameters, lane_neighbours, mobil_accelerations, mobil_decide
from mujoco_world.loop.runner import closed_loop
from mujoco_world.scenario.catalog import get_scenario
from mujoco_world.scenario.spec import scenario_from_dict

# IDM defaults (IdmSpec): a = 1.5, b = 2, T = 1.5 s, s0 = 2 m.
A, B, T, S0 = 1.5, 2.0, 1.5, 2.0


def _fleet_acceleration(level, gap, ego_speed=0.0, speed=14.0):
    """Decided acceleration of an idm car at ``speed`` (its desired speed) with the ego ``gap`` ahead.

    Both bodies 4 m long, 2 m wide, on a straight route along +x; nothing else ahead.
    """
    scenario = scenario_from_dict(
        {
            "name": "t",
            "road_users": [
                {
                    "name": "car",
                    "type": "car",
                    "behaviour": {"kind": "idm", "speed": speed, "ego_reaction": level},
                }
            ],
        }
    )
    fleet = Fleet(scenario.road_users, [np.array([[0.0, 0.0], [300.0, 0.0]])], road_speed_limit=speed)
    view = WorldView(
        time=0.0,
        position=np.array([[gap + 4.0, 0.0], [0.0, 0.0]]),
        velocity=np.array([[ego_speed, 0.0], [speed, 0.0]]),
        yaw=np.zeros(2),
        length=np.full(2, 4.0),
        width=np.full(2, 2.0),
        types=(RoadUserType.CAR, RoadUserType.CAR),
    )
    fleet.decide(view)
    return float(fleet.a[0])


def test_the_acceleration_is_the_blend_of_blind_and_seeing_by_hand():
    # 14 m/s at its desired speed, the standing ego 60 m ahead (bumper to bumper):
    # s* = 2 + 14 x 1.5 + 14 x 14 / (2 sqrt(1.5 x 2)) = 79.58 m, a_seeing = 1.5 (0 - (s*/60)^2).
    s_star = S0 + 14.0 * T + 14.0 * 14.0 / (2.0 * math.sqrt(A * B))
    a_seeing = -A * (s_star / 60.0) ** 2
    assert a_seeing == pytest.approx(-2.6388, abs=1e-4)
    a_blind = 0.0  # free road at its desired speed: 1.5 (1 - (14/14)^4)
    for level, expected in ((0.0, a_blind), (0.25, -0.6597), (0.5, -1.3194), (1.0, a_seeing)):
        assert expected == pytest.approx((1 - level) * a_blind + level * a_seeing, abs=1e-4)
        assert _fleet_acceleration(level, 60.0) == pytest.approx(expected, abs=1e-4)


def test_the_blend_takes_the_clipped_accelerations():
    # 20 m ahead: a_seeing = 1.5 (0 - (79.58/20)^2) = -23.7, clipped to the 8 m/s^2 limit:
    # at level 0.5 it brakes at 4 m/s^2, half the limit.
    assert _fleet_acceleration(0.5, 20.0) == pytest.approx(-4.0, abs=1e-9)
    assert _fleet_acceleration("idm", 20.0) == pytest.approx(-8.0, abs=1e-9)
    assert _fleet_acceleration("none", 20.0) == pytest.approx(0.0, abs=1e-9)


def _mobil_with_ego_behind(level):
    """MOBIL of a 20 m/s car in lane 0 behind a 15 m/s leader, the 20 m/s ego 12 m behind in lane 1.

    The same bodies as ``test_mobil``'s safety case: seeing the ego, the ego is the new
    follower with a~_n = -22.8 m/s^2; blind to it, the target lane has no follower (0).
    """
    W = 3.5
    position = np.array([[-12.0, W], [0.0, 0.0], [30.0, 0.0], [100.0, W]])
    velocity = np.array([[20.0, 0.0], [20.0, 0.0], [15.0, 0.0], [25.0, 0.0]])
    n = 4
    samples = np.arange(-80.0, 150.0 + 1e-9, 1.0)
    x, y = samples[None, :], np.zeros((1, samples.size))
    me = np.array([1])

    def accelerations(sees_ego):
        sees = np.ones((1, n), dtype=bool)
        sees[0, 0] = sees_ego
        nb = lane_neighbours(
            x, y, np.zeros_like(x), samples[None, :], me, np.zeros(1), W,
            position, velocity, np.zeros(n), np.full(n, 4.0), np.full(n, 2.0),
            np.ones(n, dtype=bool), sees, np.full((1, 3), np.inf),
        )  # fmt: skip
        idm = IdmParameters(*(np.full(n, value) for value in (30.0, A, B, T, S0)))
        return mobil_accelerations(nb, me, np.array([20.0]), idm)

    acc = accelerations(False).blend(accelerations(True), np.array([float(level)]))
    one = np.ones(1)
    allowed = np.array([[False, True, True]])
    return acc, mobil_decide(acc, allowed, 0.3 * one, 0.1 * one, 4.0 * one, 0.2 * one, np.ones(1, dtype=bool))


def test_mobil_weighs_the_ego_as_new_follower_by_the_reaction_level():
    # a~_n = r x (-22.796) + (1 - r) x 0 >= -b_safe = -4 holds up to r = 4 / 22.796 = 0.1755.
    a_n_new = A * (1 - (20.0 / 30.0) ** 4 - ((S0 + 20.0 * T) / 8.0) ** 2)
    assert a_n_new == pytest.approx(-22.796, abs=1e-3)
    for level, changes in ((0.0, True), (0.17, True), (0.18, False), (0.5, False), (1.0, False)):
        acc, decision = _mobil_with_ego_behind(level)
        assert acc.follower_behind_me[0, 2] == pytest.approx(level * a_n_new, abs=1e-9)
        assert decision.change[0] == (1 if changes else 0), level


def _follower(level):
    """The ego (14 m/s) brakes at 8 m/s^2 from t = 0; an idm car 18 m behind, 0.5 s reaction time."""
    return scenario_from_dict(
        {
            "name": "brake_follower",
            "duration": 6.0,
            "road": {"length": 200.0, "lanes": 2},
            "ego": {"s0": 40.0, "speed": 14.0, "lane": 0, "goal_s": 190.0},
            "road_users": [
                {
                    "name": "follower",
                    "type": "car",
                    "s0": 22.0,
                    "behaviour": {
                        "kind": "idm",
                        "speed": 14.0,
                        "ego_reaction": level,
                        "idm": {"reaction_time": 0.5},
                    },
                }
            ],
        }
    )


def _run(scenario, planner):
    loop = closed_loop(scenario, planner)
    summary = loop.execute()
    return summary, loop.world.fleet


def test_levels_0_and_1_reproduce_none_and_idm_of_the_code_before_levels():
    """Today's numbers (main 544813f, ``ego_reaction = "none"`` / ``"idm"``), run for run."""
    summary, fleet = _run(_follower(0.0), "emergency_brake")
    assert fleet.s[0] == pytest.approx(47.619999999998925, abs=1e-9)
    assert [round(c.measurement.time, 4) for c in summary.collisions] == [1.8389]
    assert summary.harm["ego"] == pytest.approx(0.02896839934138018, rel=1e-9)
    summary, fleet = _run(_follower(1.0), "emergency_brake")
    assert fleet.s[0] == pytest.approx(45.22467884834197, abs=1e-9)
    assert summary.collisions == ()
    # MOBIL: the cut-in of cut_in_blind / cut_in_reactive, the ego at constant speed.
    today = ((0.0, 73.3541240706739, (0.05, 0, 0, 1)), (1.0, 116.9502162577844, (4.0, 0, 0, 1)))
    for level, s, change in today:
        scenario = get_scenario("cut_in_reactive")
        cutter = scenario.road_users[0]
        behaviour = dataclasses.replace(cutter.behaviour, ego_reaction=level)
        users = (dataclasses.replace(cutter, behaviour=behaviour), *scenario.road_users[1:])
        scenario = dataclasses.replace(scenario, road_users=users, duration=6.0)
        summary, fleet = _run(scenario, "keep_lane")
        assert fleet.s[0] == pytest.approx(s, abs=1e-9)
        assert [(round(t, 4), i, a, b) for t, i, a, b in fleet.lane_changes] == [change]


def test_an_intermediate_level_rear_ends_later_and_softer_than_a_blind_driver():
    blind, _ = _run(_follower(0.0), "emergency_brake")
    weak, _ = _run(_follower(0.5), "emergency_brake")
    assert len(weak.collisions) == 1
    assert weak.collisions[0].measurement.time > blind.collisions[0].measurement.time + 0.2
    assert weak.harm["ego"] < 0.75 * blind.harm["ego"]


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (1.5, "behaviour.ego_reaction must lie in [0, 1] -, got 1.5"),
        (-0.1, "behaviour.ego_reaction must lie in [0, 1] -, got -0.1"),
        ("brake", "behaviour.ego_reaction: unknown ego reaction 'brake'; allowed: none, idm"),
        (True, "behaviour.ego_reaction must be a level in [0, 1] or one of none, idm, got True"),
        (math.nan, "behaviour.ego_reaction must be finite, got nan"),
    ],
)
def test_a_bad_reaction_level_is_refused_by_name(value, message):
    user = {"name": "u", "type": "car", "behaviour": {"kind": "idm", "ego_reaction": value}}
    with pytest.raises(ValueError, match=re.escape(message)):
        scenario_from_dict({"name": "t", "road_users": [user]})


def test_names_are_levels():
    def level(value):
        user = {"name": "u", "type": "car", "behaviour": {"kind": "idm", "ego_reaction": value}}
        return scenario_from_dict({"name": "t", "road_users": [user]}).road_users[0].behaviour.ego_reaction

    assert (level("none"), level("idm"), level(0.3), level(1)) == (0.0, 1.0, 0.3, 1.0)
    default = {"name": "u", "type": "car", "behaviour": {"kind": "idm"}}
    scenario = scenario_from_dict({"name": "t", "road_users": [default]})
    assert scenario.road_users[0].behaviour.ego_reaction == 1.0
