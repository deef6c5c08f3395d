"""CommonRoad track reading: files written here by commonroad-io, and the shared real files."""

import math

import numpy as np
import pytest

pytest.importorskip("commonroad")

from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile  # noqa: E402
from commonroad.geometry.shape import Circle, Rectangle  # noqa: E402
from commonroad.planning.planning_problem import PlanningProblemSet  # noqa: E402
from commonroad.prediction.prediction import TrajectoryPrediction  # noqa: E402
from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType  # noqa: E402
from commonroad.scenario.scenario import Scenario, ScenarioID  # noqa: E402
from commonroad.scenario.state import CustomState, InitialState  # noqa: E402
from commonroad.scenario.trajectory import Trajectory  # noqa: E402

from ethical_planner.road_users import RoadUserType  # noqa: E402
from mujoco_world.scenario.commonroad_tracks import (  # noqa: E402
    UnusableScenarioError,
    check_step,
    location_of,
    read_tracks,
    shared_commonroad,
)

SHARED = shared_commonroad()


def _obstacle(oid, kind, shape, t0, n, speed, heading, step_scale, start=(0.0, 0.0)):
    """An obstacle moving straight; it moves step_scale x speed x dt per declared step."""
    direction = np.array([math.cos(heading), math.sin(heading)])
    states = [
        dict(
            time_step=t0 + k,
            position=np.array(start) + direction * speed * 0.1 * step_scale * k,
            orientation=heading,
            velocity=speed,
        )
        for k in range(n)
    ]
    initial = InitialState(**states[0], acceleration=0.0, yaw_rate=0.0, slip_angle=0.0)
    trajectory = Trajectory(t0 + 1, [CustomState(**s) for s in states[1:]])
    return DynamicObstacle(oid, kind, shape, initial, TrajectoryPrediction(trajectory, shape))


def _write(tmp_path, obstacles, name="ZAM_Test-1_1_T-1"):
    scenario = Scenario(0.1, ScenarioID.from_benchmark_id(name, "2020a"))
    for o in obstacles:
        scenario.add_objects(o)
    path = tmp_path / f"{name}.xml"
    CommonRoadFileWriter(
        scenario, PlanningProblemSet(), author="tests", affiliation="tests", source="tests", tags=set()
    ).write_to_file(str(path), OverwriteExistingFile.ALWAYS)
    return path


def test_step_disagreeing_with_velocities_is_corrected_and_late_obstacles_keep_their_times(tmp_path):
    # Positions move 2x further per declared 0.1 s step than the velocity says: the true step is 0.2 s.
    path = _write(
        tmp_path,
        [
            _obstacle(1, ObstacleType.CAR, Rectangle(4.0, 1.8), 0, 30, 10.0, 0.3, 2.0),
            _obstacle(2, ObstacleType.PEDESTRIAN, Circle(0.35), 12, 10, 1.5, -1.0, 2.0, start=(5.0, 5.0)),
            _obstacle(3, ObstacleType.BUILDING, Rectangle(10.0, 10.0), 0, 3, 0.0, 0.0, 1.0),
        ],
    )
    scenario = read_tracks(path)
    assert scenario.declared_dt == pytest.approx(0.1)
    assert scenario.step_check.ratio == pytest.approx(2.0, rel=1e-3)
    assert scenario.dt == pytest.approx(0.2) and scenario.step_check.corrected
    assert "using 0.2 s" in scenario.step_check.message
    car, ped = scenario.tracks
    assert car.type is RoadUserType.CAR and (car.length, car.width) == (4.0, 1.8) and not car.circle
    # Speeds agree with the displacement on the corrected times (independent of the reader).
    moved = np.hypot(*np.diff(car.positions, axis=0).T) / np.diff(car.times)
    assert moved == pytest.approx(10.0, rel=1e-3)
    # The pedestrian appears at step 12 and leaves after 10 states: its own times.
    assert ped.type is RoadUserType.PEDESTRIAN and ped.circle and ped.length == pytest.approx(0.7)
    assert ped.time_steps[0] == 12 and len(ped) == 10 and ped.times[0] == pytest.approx(12 * 0.2)
    assert scenario.skipped == ((3, "obstacle type 'building' is not a road user"),)
    declared = read_tracks(path, step="declared")
    assert declared.dt == pytest.approx(0.1) and not declared.step_check.corrected
    assert "inconsistent" in declared.step_check.message


def test_consistent_step_is_kept(tmp_path):
    path = _write(tmp_path, [_obstacle(1, ObstacleType.TRUCK, Rectangle(10.0, 2.5), 0, 20, 20.0, 0.0, 1.0)])
    scenario = read_tracks(path)
    assert scenario.dt == pytest.approx(0.1) and not scenario.step_check.corrected
    assert "consistent" in scenario.step_check.message


def test_unusable_files_are_refused_by_name(tmp_path):
    empty = _write(tmp_path, [], name="ZAM_Empty-1_1_T-1")
    with pytest.raises(UnusableScenarioError, match="ZAM_Empty-1_1_T-1.xml: no dynamic obstacles"):
        read_tracks(empty)
    garbage = tmp_path / "garbage.xml"
    garbage.write_text("<commonRoad><broken")
    with pytest.raises(UnusableScenarioError, match="not a readable CommonRoad file"):
        read_tracks(garbage)
    with pytest.raises(UnusableScenarioError, match="no such file"):
        read_tracks(tmp_path / "missing.xml")
    with pytest.raises(ValueError, match="step must be one of velocity, declared"):
        read_tracks(empty, step="guess")
    check = check_step([], 0.1)
    assert check.dt == 0.1 and "no moving samples" in check.message


def test_location_keys():
    assert location_of("DEU_LocationALower26-1_261353_T-1428") == "highD-A"
    assert location_of("DEU_LocationEUpper23-1_1_T-1") == "highD-E"
    assert location_of("CHN_SIND-851_1_T-75") == "SinD"
    assert location_of("USA_US101-14_1_T-1") == "NGSIM-US101"
    assert location_of("C-USA_Lanker-2_1_T-1") == "NGSIM-Lanker"
    assert location_of("DEU_AachenBrand-1_431052_T-1127") == "exiD-AachenBrand"
    assert location_of("DEU_Muc-2_1_T-1") == "DEU_Muc"


needs_shared = pytest.mark.skipif(SHARED is None, reason="../shared/commonroad is absent")


@needs_shared
@pytest.mark.parametrize(
    "relative,declared,dt",
    [
        ("drivability-checker-datasets/SinD/CHN_SIND-7281_1_T-75.cr.xml", 0.1, 0.5),
        ("drivability-checker-datasets/highD/DEU_LocationALower26-1_261353_T-1428.cr.xml", 0.1, 0.2),
        ("drivability-checker-datasets/exiD/DEU_AachenBrand-1_431052_T-1127.cr.xml", 0.2, 0.2),
        ("tum-cps-scenarios/NGSIM/USA_US101-14_1_T-1.xml", 0.1, 0.1),
    ],
)
def test_real_files_step_check(relative, declared, dt):
    scenario = read_tracks(SHARED / relative)
    assert scenario.declared_dt == pytest.approx(declared) and scenario.dt == pytest.approx(dt)
    speeds = np.concatenate([t.speeds for t in scenario.tracks])
    assert np.median(speeds) < 40.0  # plausible speeds [m/s]


@needs_shared
def test_real_sind_has_circular_pedestrians_and_late_obstacles():
    scenario = read_tracks(SHARED / "drivability-checker-datasets/SinD/CHN_SIND-7281_1_T-75.cr.xml")
    pedestrians = [t for t in scenario.tracks if t.type is RoadUserType.PEDESTRIAN]
    assert pedestrians and all(t.circle for t in pedestrians)
    assert any(t.time_steps[0] > 0 for t in scenario.tracks)


@needs_shared
@pytest.mark.parametrize(
    "relative,match",
    [
        ("tum-cps-scenarios/ZAM_Intersect-1_1_S-1.xml", "SetBasedPrediction"),
        ("commonroad-io-tests/DEU_Starnberg-1_1_T-1.xml", "no dynamic obstacles"),
    ],
)
def test_real_unusable_files(relative, match):
    with pytest.raises(UnusableScenarioError, match=match):
        read_tracks(SHARED / relative)
