"""CommonRoad files written by commonroad-io for tests that must run anywhere.

``straight_road_file`` writes a 300 m two-lane road (lanelets 1 | 2 from x = 0 to 200,
their successors 3 | 4 to x = 300; lane centres at y = -1.75 and +1.75), a planning
problem and whatever obstacles a test asks for.
"""

from __future__ import annotations

import math

import numpy as np
from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile
from commonroad.common.util import Interval
from commonroad.geometry.shape import Circle, Rectangle
from commonroad.planning.goal import GoalRegion
from commonroad.planning.planning_problem import PlanningProblem, PlanningProblemSet
from commonroad.prediction.prediction import SetBasedPrediction, TrajectoryPrediction
from commonroad.scenario.lanelet import Lanelet
from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType, StaticObstacle
from commonroad.scenario.scenario import Scenario, ScenarioID
from commonroad.scenario.state import CustomState, InitialState
from commonroad.scenario.traffic_sign import TrafficSign, TrafficSignElement, TrafficSignIDZamunda
from commonroad.scenario.trajectory import Trajectory

LANE = 3.5


def lanelet(lid, x0, x1, y_centre, **links):
    """A straight lanelet from x0 to x1 centred on y_centre, points every 10 m."""
    x = np.linspace(x0, x1, int((x1 - x0) / 10) + 1)
    centre = np.column_stack([x, np.full_like(x, y_centre)])
    return Lanelet(
        centre + [0, LANE / 2], centre, centre - [0, LANE / 2], lid, **links
    )  # left, centre, right


def road_lanelets():
    return [
        lanelet(1, 0, 200, -LANE / 2, successor=[3], adjacent_left=2, adjacent_left_same_direction=True),
        lanelet(2, 0, 200, LANE / 2, successor=[4], adjacent_right=1, adjacent_right_same_direction=True),
        lanelet(3, 200, 300, -LANE / 2, predecessor=[1], adjacent_left=4, adjacent_left_same_direction=True),
        lanelet(4, 200, 300, LANE / 2, predecessor=[2], adjacent_right=3, adjacent_right_same_direction=True),
    ]


def moving_obstacle(oid, kind, shape, t0, positions, headings, dt=0.1, speeds=None):
    """A dynamic obstacle through ``positions`` (n, 2) from time step t0.

    Speeds default to the displacement per ``dt`` (so a test can make them disagree).
    """
    positions = np.asarray(positions, dtype=float)
    headings = np.broadcast_to(np.asarray(headings, dtype=float), (len(positions),))
    if speeds is None:
        step = np.hypot(*np.diff(positions, axis=0).T) / dt
        speeds = np.concatenate([step[:1], step])
    states = [
        dict(
            time_step=t0 + k, position=positions[k], orientation=float(headings[k]), velocity=float(speeds[k])
        )
        for k in range(len(positions))
    ]
    initial = InitialState(**states[0], acceleration=0.0, yaw_rate=0.0, slip_angle=0.0)
    trajectory = Trajectory(t0 + 1, [CustomState(**s) for s in states[1:]])
    return DynamicObstacle(oid, kind, shape, initial, TrajectoryPrediction(trajectory, shape))


def straight_line(start, speed, heading, n, dt=0.1, step_scale=1.0):
    """(n, 2) positions from ``start`` at ``speed`` along ``heading`` (step_scale x further per step)."""
    direction = np.array([math.cos(heading), math.sin(heading)])
    return np.asarray(start, dtype=float) + np.outer(np.arange(n) * speed * dt * step_scale, direction)


def set_based_obstacle(oid):
    from commonroad.prediction.prediction import Occupancy

    occupancies = [Occupancy(k, Rectangle(4.0, 1.8, center=np.array([60.0 + k, -1.75]))) for k in range(1, 5)]
    initial = InitialState(
        time_step=0, position=np.array([60.0, -1.75]), orientation=0.0, velocity=10.0,
        acceleration=0.0, yaw_rate=0.0, slip_angle=0.0,
    )  # fmt: skip
    return DynamicObstacle(
        oid, ObstacleType.CAR, Rectangle(4.0, 1.8), initial, SetBasedPrediction(1, occupancies)
    )


def planning_problem(
    pid=100, start=(20.0, -LANE / 2), speed=10.0, goal=((150.0, LANE / 2), 10.0, 3.0), goal_steps=(0, 80)
):
    """A planning problem from ``start`` along +x; ``goal`` is (centre, length, width) or None (time only)."""
    initial = InitialState(
        time_step=0,
        position=np.asarray(start, dtype=float),
        orientation=0.0,
        velocity=speed,
        acceleration=0.0,
        yaw_rate=0.0,
        slip_angle=0.0,
    )
    fields = {"time_step": Interval(*goal_steps)}
    if goal is not None:
        centre, length, width = goal
        fields["position"] = Rectangle(length, width, center=np.asarray(centre, dtype=float))
    return PlanningProblem(pid, initial, GoalRegion([CustomState(**fields)]))


def straight_road_file(
    tmp_path,
    obstacles=(),
    static=(),
    problems=None,
    dt=0.1,
    name="ZAM_Straight-1_1_T-1",
    speed_sign=None,
    extra_lanelets=(),
):
    """Write the two-lane road with ``obstacles`` (dynamic), ``static`` obstacles and planning
    problems (default: one, from the right lane to a goal on the left lane); return the path."""
    scenario = Scenario(dt, ScenarioID.from_benchmark_id(name, "2020a"))
    scenario.add_objects([*road_lanelets(), *extra_lanelets])
    if speed_sign is not None:
        element = TrafficSignElement(TrafficSignIDZamunda.MAX_SPEED, [str(speed_sign)])
        sign = TrafficSign(900, [element], {1}, np.array([5.0, -4.0]))
        scenario.add_objects(sign, lanelet_ids={1})
    for obstacle in (*obstacles, *static):
        scenario.add_objects(obstacle)
    problem_set = PlanningProblemSet(list(problems) if problems is not None else [planning_problem()])
    path = tmp_path / f"{name}.xml"
    CommonRoadFileWriter(
        scenario, problem_set, author="tests", affiliation="tests", source="tests", tags=set()
    ).write_to_file(str(path), OverwriteExistingFile.ALWAYS)
    return path


def static_obstacle(oid, kind, centre, length=4.5, width=2.0, yaw=0.0):
    initial = InitialState(
        time_step=0, position=np.asarray(centre, dtype=float), orientation=yaw, velocity=0.0,
        acceleration=0.0, yaw_rate=0.0, slip_angle=0.0,
    )  # fmt: skip
    return StaticObstacle(oid, kind, Rectangle(length, width), initial)


__all__ = [
    "Circle",
    "ObstacleType",
    "Rectangle",
    "lanelet",
    "moving_obstacle",
    "planning_problem",
    "set_based_obstacle",
    "static_obstacle",
    "straight_line",
    "straight_road_file",
]
