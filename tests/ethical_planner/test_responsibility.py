import math

import numpy as np
import pytest

from ethical_planner.config import ResponsibilityConfig, preset
from ethical_planner.environment import RoadEnvironment
from ethical_planner.planner import Planner
from ethical_planner.responsibility import LegalCorridors, base_responsibility
from ethical_planner.road_users import DEFAULT_SHAPES, KinematicState, LegalCorridor, RoadUser, RoadUserType

CONFIG = ResponsibilityConfig()


def test_base_responsibility_grows_with_mass_and_spares_vulnerable_users():
    r = base_responsibility(np.array([1500.0, 25000.0, 75.0]), np.array([True, True, False]), CONFIG)
    assert r[0] == pytest.approx(0.1 * (1 - math.exp(-1500 / 5000)))
    assert r[1] > r[0] > 0 and r[2] == 0


def test_legal_longitudinal_bounds_by_hand():
    env = RoadEnvironment.along_path([[0, 0], [100, 0]])
    user = RoadUser(
        1,
        "car",
        KinematicState(0, 0, 0, 10),
        DEFAULT_SHAPES[RoadUserType.CAR],
        legal=LegalCorridor(
            speed_limit=12.0, lateral_half_width=1.0, max_acceleration=2.0, max_deceleration=8.0
        ),
    )
    corridors = LegalCorridors.of([user], env)
    low, high = corridors.longitudinal_bounds(np.array([0.5, 2.0]))
    # braking: 10*0.5 - 4*0.25 = 4; stopped after 1.25 s at 6.25 m
    np.testing.assert_allclose(low, [4.0, 6.25])
    # accelerating 2 m/s^2 to 12 m/s (reached at 1 s): 0.5 -> 5.25; 2.0 -> 11 + 12 = 23
    np.testing.assert_allclose(high, [5.25, 23.0])
    stopped = LegalCorridors.of(
        [
            RoadUser(
                2,
                "car",
                KinematicState(0, 0, 0, 10),
                DEFAULT_SHAPES[RoadUserType.CAR],
                legal=LegalCorridor(12.0, 1.0, stop_distance=3.0),
            )
        ],
        env,
    )
    assert stopped.longitudinal_bounds(np.array([2.0]))[1][0] == pytest.approx(3.0)


def _crossing_scene(legal):
    env = RoadEnvironment.along_path([[-30, 0], [200, 0]], lanes_left=1, margin=2.5)
    pedestrian = RoadUser(
        1,
        RoadUserType.PEDESTRIAN,
        KinematicState(14.0, -3.0, math.pi / 2, 1.8),
        DEFAULT_SHAPES[RoadUserType.PEDESTRIAN],
        legal=legal,
    )
    config = preset("ethical_responsible")
    return Planner(config, env).plan(KinematicState(0, 0, 0, 8.0), [pedestrian])


def test_jaywalker_outside_legal_set_is_responsible_and_crosswalk_user_is_not():
    jaywalker = _crossing_scene(LegalCorridor(speed_limit=2.5, lateral_half_width=1.0, stop_distance=0.5))
    crossing = _crossing_scene(LegalCorridor(speed_limit=2.5, lateral_half_width=1.0))
    assert jaywalker.road_users[0].collision_probability > 0
    assert jaywalker.road_users[0].responsibility == pytest.approx(CONFIG.rule_violation)
    assert crossing.road_users[0].responsibility == 0.0


def test_rear_end_follower_is_responsible():
    env = RoadEnvironment.along_path([[-30, 0], [200, 0]], lanes_left=1)
    slow_ahead = RoadUser(1, "car", KinematicState(12.0, 0.0, 0.0, 2.0), DEFAULT_SHAPES[RoadUserType.CAR])
    fast_behind = RoadUser(2, "car", KinematicState(-10.0, 0.0, 0.0, 14.0), DEFAULT_SHAPES[RoadUserType.CAR])
    # Straight candidates only: the collision geometry is a rear-end whatever is chosen.
    straight = preset("standard").with_overrides(
        {
            "sampling": {"n_offsets": 1, "d_min": 0.0, "d_max": 0.0, "brake_candidates": False},
            "commitment": {"enabled": False},
        }
    )
    ahead = Planner(straight, env).plan(KinematicState(0, 0, 0, 12.0), [slow_ahead]).road_users[0]
    behind = Planner(straight, env).plan(KinematicState(0, 0, 0, 3.0), [fast_behind]).road_users[0]
    # r_base = 0.1 (1 - exp(-m / 5000 kg)); a 4.5 m x 1.8 m car weighs
    # -1333.5 + 526.9 * 8.1^0.8 = 1475.27 kg (SPEC), the ego 1475 kg
    base_car, base_ego = 0.0255509, 0.0255468
    assert ahead.collision_probability > 0 and behind.collision_probability > 0
    assert ahead.ego_responsibility == pytest.approx(base_ego + 0.3, abs=1e-7)  # rear_end = 0.3
    assert ahead.responsibility == pytest.approx(base_car, abs=1e-7)
    assert behind.responsibility == pytest.approx(base_car + 0.3, abs=1e-7)
