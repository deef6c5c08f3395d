"""Terminal safety (``ethical_planner.terminal``): each rule against numbers computed by hand."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
import shapely

from ethical_planner.config import TerminalConfig, preset
from ethical_planner.environment import RoadEnvironment
from ethical_planner.prediction import Prediction
from ethical_planner.road_users import RoadUserType, Shape
from ethical_planner.terminal import (
    crowds_static_obstacle,
    return_time,
    standstill_distance,
    terminally_unsafe,
)

#: A straight road along x from x = 0 (s = x): the ego lane centred on y = 0 (edges +-1.75), the oncoming
#: lane centred on y = 3.5 (1.75 to 5.25).
ROAD = RoadEnvironment.along_path([[0.0, 0.0], [500.0, 0.0]], lanes_left=1)
EGO = Shape(4.5, 1.8)
CONFIG = TerminalConfig()  # a_return 3 m/s^2, buffer 1 s


def _ends(d, s=50.0, speed=10.0):
    """Candidates of two steps that end at Frenet (s, d) at ``speed`` [m/s]."""
    d = np.atleast_1d(np.asarray(d, dtype=float))
    n = d.size
    return SimpleNamespace(
        n_traj=n,
        s=np.full((n, 2), s),
        d=np.stack([np.zeros(n), d], axis=1),
        s_dot=np.full((n, 2), speed),
    )


def _car(x, y=3.5, heading=math.pi, speed=10.0, length=4.5):
    """One car predicted at (x, y) with ``heading`` and ``speed`` at the last step."""
    mean = np.array([[[x, y], [x, y]]], dtype=float)
    return Prediction(
        ids=np.array([1]),
        types=(RoadUserType.CAR,),
        mean=mean,
        cov=np.broadcast_to(np.eye(2) * 0.1, (1, 2, 2, 2)).copy(),
        heading=np.full((1, 2), heading),
        speed=np.full((1, 2), speed),
        length=np.array([length]),
        width=np.array([1.8]),
        mass=np.array([1500.0]),
    )


def test_return_time_is_the_quintic_lane_change_at_the_lateral_limit():
    # A quintic rest-to-rest move of D in T peaks at 10 / sqrt(3) D / T^2 (its second
    # derivative 60 D/T^2 (tau - 3 tau^2 + 2 tau^3) peaks at tau = (3 - sqrt(3)) / 6).
    tau = (3.0 - math.sqrt(3.0)) / 6.0
    peak = 60.0 * (tau - 3 * tau**2 + 2 * tau**3)
    assert peak == pytest.approx(10.0 / math.sqrt(3.0))
    assert return_time(np.array(2.65), 3.0) == pytest.approx(math.sqrt(peak * 2.65 / 3.0))


def test_an_end_in_the_oncoming_lane_is_unsafe_until_the_car_is_far_enough():
    # Ego ends at s = 50, d = 3.5: it must move 3.5 + 0.9 - 1.75 = 2.65 m to leave the
    # oncoming lane, sqrt(5.7735 * 2.65 / 3) = 2.258 s, plus the 1 s buffer: 3.258 s.
    # Closing at 10 + 10 m/s, the free gap must be 65.17 m: the car's centre beyond
    # 50 + 4.5 + 65.17 = 119.67 m.
    needed = math.sqrt(10.0 / math.sqrt(3.0) * 2.65 / 3.0) + 1.0
    threshold = 50.0 + 0.5 * (4.5 + 4.5) + needed * 20.0
    assert threshold == pytest.approx(119.67, abs=0.01)
    for x, unsafe in ((threshold - 0.2, True), (threshold + 0.2, False), (60.0, True), (300.0, False)):
        assert terminally_unsafe(_ends(3.5), _car(x), ROAD, EGO, CONFIG)[0] == unsafe, x


def test_only_the_part_in_the_oncoming_lane_must_be_undone():
    # d = 1.0 ends 1.0 + 0.9 - 1.75 = 0.15 m in the oncoming lane: 0.537 s + 1 s back,
    # a free gap of 30.7 m at 20 m/s closing; d = 0.8 is wholly in the ego lane.
    needed = math.sqrt(10.0 / math.sqrt(3.0) * 0.15 / 3.0) + 1.0
    threshold = 50.0 + 4.5 + needed * 20.0
    ends = _ends([1.0, 0.8])
    assert terminally_unsafe(ends, _car(threshold - 0.2), ROAD, EGO, CONFIG).tolist() == [True, False]
    assert terminally_unsafe(ends, _car(threshold + 0.2), ROAD, EGO, CONFIG).tolist() == [False, False]
    # A standing ego closes at the car's speed alone: half the gap suffices.
    assert not terminally_unsafe(
        _ends(1.0, speed=0.0), _car(50.0 + 4.5 + needed * 10.0 + 0.2), ROAD, EGO, CONFIG
    )[0]


@pytest.mark.parametrize(
    ("car", "why"),
    [
        (_car(80.0, heading=0.0), "same direction"),
        (_car(80.0, speed=0.3), "standing"),
        (_car(40.0), "already past the ego's end"),
        (_car(80.0, y=0.0), "in the ego's lane: the risk decides there"),
    ],
)
def test_who_is_not_oncoming_traffic_in_a_lane_to_leave(car, why):
    assert not terminally_unsafe(_ends(3.5), car, ROAD, EGO, CONFIG)[0], why


def test_a_car_beside_the_ego_end_is_unsafe():
    assert terminally_unsafe(_ends(3.5), _car(52.0), ROAD, EGO, CONFIG)[0]


def test_disabled_condition_and_bad_configuration():
    assert not terminally_unsafe(_ends(3.5), _car(60.0), ROAD, EGO, TerminalConfig(enabled=False))[0]
    with pytest.raises(ValueError, match="terminal.return_lateral_acceleration"):
        preset("ethical").with_overrides({"terminal": {"return_lateral_acceleration": 0.0}})
    with pytest.raises(ValueError, match="terminal.oncoming_angle"):
        preset("ethical").with_overrides({"terminal": {"oncoming_angle": 2.0}})


def test_standstill_distance_is_the_room_to_swing_out_by_a_lane_at_the_steering_limit():
    # Quintic d(s) = D (10 u^3 - 15 u^4 + 6 u^5), u = s / S: d'' peaks at 10 / sqrt(3) D / S^2.
    s = np.linspace(0.0, 9.0135, 20001)
    u = s / s[-1]
    d = 3.5 * (10 * u**3 - 15 * u**4 + 6 * u**5)
    kappa = np.gradient(np.gradient(d, s), s) / (1.0 + np.gradient(d, s) ** 2) ** 1.5
    assert standstill_distance(3.5, math.tan(0.61) / 2.81) == pytest.approx(9.0135, abs=1e-3)
    # The small-slope formula is the curvature's upper bound (the slope only lowers it).
    assert np.abs(kappa).max() <= math.tan(0.61) / 2.81 + 1e-3


def test_a_plan_must_end_able_to_stop_short_of_debris_with_room_to_steer():
    # Debris 1.2 m long from x = 100 to 101.2 on the ego lane; ego 4.5 m long, front at
    # x_end + 2.25. Standing (v = 0): it needs 9 m before the debris, so x_end <= 88.75
    # is fine and beyond crowds it. At 6 m/s: 9 + 36 / 6 = 15 m, x_end <= 82.75.
    road = RoadEnvironment.along_path([[0.0, 0.0], [500.0, 0.0]], lanes_left=1)
    area = road.drivable_area.difference(shapely.box(100.0, -0.7, 101.2, 0.7))
    road = RoadEnvironment(road.reference_path, area, lane_offsets=road.lane_offsets)
    x = np.array([88.6, 88.9, 82.6, 82.9, 95.0])
    v = np.array([0.0, 0.0, 6.0, 6.0, 0.0])
    y = np.array([0.0, 0.0, 0.0, 0.0, 3.5])  # the last one waits in the other lane, beside it
    ends = SimpleNamespace(
        x=np.stack([x, x], 1), y=np.stack([y, y], 1), yaw=np.zeros((5, 2)), v=np.stack([v, v], 1)
    )
    crowds = crowds_static_obstacle(ends, np.arange(5), road, EGO, CONFIG)
    assert crowds.tolist() == [False, True, False, True, False]
    assert not crowds_static_obstacle(ends, np.arange(5), ROAD, EGO, CONFIG).any()  # no debris
