import math

import pytest

from ethical_planner.road_users import (
    DEFAULT_SHAPES,
    MIN_CAR_MASS_KG,
    KinematicState,
    RoadUser,
    RoadUserType,
    Shape,
    mass_of,
)


def test_car_mass_regression_and_floor():
    assert mass_of(RoadUserType.CAR, 4.508, 1.610) == pytest.approx(-1333.5 + 526.9 * (4.508 * 1.610) ** 0.8)
    assert mass_of(RoadUserType.CAR, 1.5, 1.0) == MIN_CAR_MASS_KG
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
