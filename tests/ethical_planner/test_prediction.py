import math

import numpy as np
import pytest

from ethical_planner.config import PredictionConfig
from ethical_planner.prediction import Prediction, predict_constant_turn_rate
from ethical_planner.road_users import DEFAULT_SHAPES, KinematicState, RoadUser, RoadUserType


def _car(state, uid=1):
    return RoadUser(uid, RoadUserType.CAR, state, DEFAULT_SHAPES[RoadUserType.CAR])


def test_constant_velocity_and_turn_rate_means():
    times = np.linspace(0, 2, 21)
    straight = _car(KinematicState(1, 2, math.pi / 2, 5))
    circle = _car(KinematicState(0, 0, 0, 5, yaw_rate=0.5), uid=2)
    pred = predict_constant_turn_rate([straight, circle], times, PredictionConfig())
    np.testing.assert_allclose(pred.mean[0, :, 0], 1, atol=1e-12)
    np.testing.assert_allclose(pred.mean[0, :, 1], 2 + 5 * times)
    # A constant turn rate keeps the distance to the turning centre (0, 10): radius v / omega.
    np.testing.assert_allclose(np.hypot(pred.mean[1, :, 0], pred.mean[1, :, 1] - 10), 10)
    np.testing.assert_allclose(pred.heading[1], 0.5 * times)


def test_covariance_grows_and_is_aligned_with_heading():
    times = np.linspace(0, 2, 21)
    config = PredictionConfig(covariance_floor=1e-6)
    pred = predict_constant_turn_rate([_car(KinematicState(0, 0, math.pi / 2, 10))], times, config)
    sigma_long = config.sigma0_long + (config.growth_long + config.growth_long_per_speed * 10) * times
    np.testing.assert_allclose(pred.cov[0, :, 1, 1], sigma_long**2)
    np.testing.assert_allclose(pred.cov[0, :, 0, 1], 0, atol=1e-12)
    assert np.all(np.diff(np.linalg.det(pred.cov[0])) > 0)


def test_covariance_floor_replaces_zero_covariance():
    pred = predict_constant_turn_rate(
        [_car(KinematicState(0, 0, 0, 0))],
        np.zeros(1),
        PredictionConfig(sigma0_long=0, sigma0_lat=0, covariance_floor=0.1),
    )
    np.testing.assert_allclose(np.linalg.eigvalsh(pred.cov[0, 0]), [0.1, 0.1])


def _prediction(cov):
    return Prediction(
        np.array([7]),
        (RoadUserType.CAR,),
        np.zeros((1, 1, 2)),
        cov,
        np.zeros((1, 1)),
        np.zeros((1, 1)),
        np.ones(1),
        np.ones(1),
        np.ones(1),
    )


def test_non_psd_covariance_is_rejected_naming_the_road_user():
    with pytest.raises(ValueError, match="road user 7 at step 0 is not positive semidefinite"):
        _prediction(np.array([[[[1.0, 2.0], [2.0, 1.0]]]]))
    with pytest.raises(ValueError, match="symmetric"):
        _prediction(np.array([[[[1.0, 0.5], [0.0, 1.0]]]]))


def test_empty_prediction_and_duplicate_ids():
    assert predict_constant_turn_rate([], np.zeros(3), PredictionConfig()).mean.shape == (0, 3, 2)
    with pytest.raises(ValueError, match="unique"):
        predict_constant_turn_rate(
            [_car(KinematicState(0, 0, 0, 1)), _car(KinematicState(5, 0, 0, 1))],
            np.zeros(2),
            PredictionConfig(),
        )


def test_parked_vehicles_keep_their_initial_uncertainty():
    parked = RoadUser(
        4, RoadUserType.PARKED_VEHICLE, KinematicState(0, 0, 0, 0), DEFAULT_SHAPES[RoadUserType.CAR]
    )
    pred = predict_constant_turn_rate(
        [parked], np.linspace(0, 3, 31), PredictionConfig(covariance_floor=1e-6)
    )
    np.testing.assert_allclose(pred.cov[0, -1], pred.cov[0, 0])
