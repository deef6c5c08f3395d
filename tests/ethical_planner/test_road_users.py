import math

import numpy as np
import pytest

from ethical_planner.road_users import (
    DEFAULT_SHAPES,
    MIN_CAR_MASS_KG,
    KinematicState,
    MotionHistory,
    RoadUser,
    RoadUserType,
    Shape,
    mass_of,
)


def test_car_mass_regression_and_floor():
    # -1333.5 + 526.9 (l w)^0.8 by hand: 4.508 x 1.610 m = 7.25788 m^2, ^0.8 = 4.88266;
    # the catalog's 5.5 x 2.1 m van: 11.55 m^2, ^0.8 = 7.07053
    assert mass_of(RoadUserType.CAR, 4.508, 1.610) == pytest.approx(1239.12, abs=0.01)
    assert mass_of(RoadUserType.CAR, 5.5, 2.1) == pytest.approx(2397.23, abs=0.01)
    assert mass_of(RoadUserType.CAR, 1.5, 1.0) == 500.0  # below 3.19 m^2 the regression is < 0: floor
    assert MIN_CAR_MASS_KG == 500.0
    assert mass_of(RoadUserType.TRUCK, 10, 2.5) == 25000
    assert mass_of(RoadUserType.PEDESTRIAN, 0.5, 0.5) == 75


@pytest.mark.parametrize(
    "build,match",
    [
        (lambda: Shape(0.0, 1.0), "> 0"),
        (lambda: Shape(-1.0, 1.0), "> 0"),
        (lambda: KinematicState(math.nan, 0, 0, 1), "KinematicState.x"),
        (lambda: KinematicState(0, 0, 0, math.inf), "KinematicState.v"),
        (lambda: RoadUser(1, "spaceship", KinematicState(0, 0, 0, 0), Shape(1, 1)), "allowed: car"),
        (lambda: RoadUser(1, "car", KinematicState(0, 0, 0, 0), Shape(1, 1), mass=-5.0), "mass"),
    ],
)
def test_bad_input_is_named(build, match):
    with pytest.raises(ValueError, match=match):
        build()


def test_type_strings_are_parsed_and_advanced_moves_along_heading():
    user = RoadUser(3, "bicycle", KinematicState(0, 0, math.pi / 2, 4), DEFAULT_SHAPES[RoadUserType.BICYCLE])
    assert user.type is RoadUserType.BICYCLE and user.is_vulnerable and user.mass == 90
    moved = user.advanced(0.5)
    assert moved.state.x == pytest.approx(0, abs=1e-12) and moved.state.y == pytest.approx(2)


def _history(times, x0=0.0, v=2.0):
    times = np.asarray(times, dtype=float)
    pos = np.stack([x0 + v * times, np.zeros_like(times)], axis=-1)
    return MotionHistory(times, pos, np.zeros_like(times), np.full_like(times, v))


@pytest.mark.parametrize(
    "times,patch,match",
    [
        ([], {}, "n >= 1"),
        ([-0.2, -0.1, 0.1], {}, "<= 0"),
        ([-0.3, -0.1, 0.0], {}, "fixed step"),
        ([-0.1, -0.2, 0.0], {}, "fixed step"),
        ([-0.5, -0.4, -0.3], {}, "older than one step"),
        ([-0.2, -0.1, 0.0], {"speeds": [1.0, math.nan, 1.0]}, "MotionHistory.speeds must be finite"),
        ([-0.2, -0.1, 0.0], {"positions": np.zeros((3, 3))}, r"positions must have shape \(3, 2\)"),
        ([-0.2, -0.1, 0.0], {"headings": "north"}, "headings must be numeric"),
    ],
)
def test_history_bad_input_is_named(times, patch, match):
    times = np.asarray(times, dtype=float)
    fields = {
        "times": times,
        "positions": np.zeros((len(times), 2)),
        "headings": np.zeros(len(times)),
        "speeds": np.zeros(len(times)),
        **patch,
    }
    with pytest.raises(ValueError, match=match):
        MotionHistory(**fields)


def test_history_is_read_only_and_reports_step_and_duration():
    history = _history([-0.2, -0.1, 0.0])
    assert history.step == pytest.approx(0.1) and history.duration == pytest.approx(0.2) and len(history) == 3
    with pytest.raises(ValueError):
        history.positions[0, 0] = 5.0
    assert _history([0.0]).step is None
    with pytest.raises(ValueError, match="history must be a MotionHistory"):
        RoadUser(1, "car", KinematicState(0, 0, 0, 1), Shape(4, 2), history=[1, 2])


def test_advanced_shifts_the_history_and_appends_the_state_it_leaves():
    history = _history([-0.2, -0.1, 0.0])
    user = RoadUser(1, "car", KinematicState(0.0, 0.0, 0.0, 2.0), Shape(4, 2), history=history)
    moved = user.advanced(0.1)
    # Independent: at 2 m/s along x, samples 0.1 s apart sit 0.2 m apart; the newest is the new state.
    assert moved.history.times == pytest.approx([-0.3, -0.2, -0.1, 0.0])
    assert moved.history.positions[:, 0] == pytest.approx([-0.4, -0.2, 0.0, 0.2])
    assert moved.history.positions[-1, 0] == pytest.approx(moved.state.x)
    half = user.advanced(0.05)
    assert half.history.times == pytest.approx([-0.25, -0.15, -0.05])
