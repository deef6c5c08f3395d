"""Small built-in planning situations (open loop) for the CLI, examples and tests.

The closed-loop scenario catalog lives in ``mujoco_world``; these are the single
planning problems the paper uses to show how the principles act.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ethical_planner.environment import RoadEnvironment
from ethical_planner.road_users import DEFAULT_SHAPES, KinematicState, RoadUser, RoadUserType


@dataclass(frozen=True, slots=True)
class Situation:
    """A road, the ego's state and the other road users."""

    name: str
    environment: RoadEnvironment
    ego: KinematicState
    road_users: tuple[RoadUser, ...]


def overtaking_cyclist(
    cyclist_ahead: float = 14.0, oncoming_distance: float = 55.0, ego_speed: float = 10.0
) -> Situation:
    """Paper Fig. 3: a cyclist ahead in the ego lane, a car oncoming in the other lane.

    Two lanes of 3.5 m on a straight road; the ego lane is the reference path, the
    oncoming lane is to its left. The cyclist rides at 4 m/s near the right edge.

    Args:
        cyclist_ahead: distance from the ego's centre to the cyclist [m].
        oncoming_distance: distance to the oncoming car [m].
        ego_speed: [m/s].
    """
    env = RoadEnvironment.along_path(
        [[-30.0, 0.0], [400.0, 0.0]], lanes_left=1, lanes_right=0, speed_limit=13.9, margin=0.3
    )
    cyclist = RoadUser(
        id=1,
        type=RoadUserType.BICYCLE,
        state=KinematicState(cyclist_ahead, -0.7, 0.0, 4.0),
        shape=DEFAULT_SHAPES[RoadUserType.BICYCLE],
    )
    oncoming = RoadUser(
        id=2,
        type=RoadUserType.CAR,
        state=KinematicState(oncoming_distance, 3.5, math.pi, 12.0),
        shape=DEFAULT_SHAPES[RoadUserType.CAR],
    )
    return Situation("overtaking_cyclist", env, KinematicState(0.0, 0.0, 0.0, ego_speed), (cyclist, oncoming))


def oncoming_in_ego_lane_with_pedestrian(ego_speed: float = 14.0) -> Situation:
    """A dilemma: an oncoming car overtakes in the ego's lane, a pedestrian is on the shoulder.

    Car 3 comes towards the ego in the ego lane, car 2 in the oncoming lane beside it;
    a pedestrian walks on the right shoulder. Braking does not avoid car 3 (it keeps
    coming). Risk has to go to someone: to the ego and car 3 (stay), car 2 (swerve left)
    or the pedestrian (swerve right onto the shoulder).
    """
    env = RoadEnvironment.along_path(
        [[-30.0, 0.0], [300.0, 0.0]], lanes_left=1, lanes_right=0, speed_limit=13.9, margin=3.0
    )
    users = (
        RoadUser(
            1,
            RoadUserType.PEDESTRIAN,
            KinematicState(16.0, -3.0, 0.0, 1.0),
            DEFAULT_SHAPES[RoadUserType.PEDESTRIAN],
        ),
        RoadUser(
            2, RoadUserType.CAR, KinematicState(25.0, 3.5, math.pi, 12.0), DEFAULT_SHAPES[RoadUserType.CAR]
        ),
        RoadUser(
            3, RoadUserType.CAR, KinematicState(30.0, 0.0, math.pi, 12.0), DEFAULT_SHAPES[RoadUserType.CAR]
        ),
    )
    return Situation(
        "oncoming_in_ego_lane_with_pedestrian", env, KinematicState(0.0, 0.0, 0.0, ego_speed), users
    )


SITUATIONS = {
    "overtaking_cyclist": overtaking_cyclist,
    "oncoming_in_ego_lane_with_pedestrian": oncoming_in_ego_lane_with_pedestrian,
}
