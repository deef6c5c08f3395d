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
    # defaults: sigma_long = 0.3 + (0.3 + 0.05 * 10 m/s) t, sigma_lat = 0.2 + 0.25 t [m];
    # heading north, so the longitudinal variance is the y variance
    at = [0, 10, 20]  # t = 0, 1, 2 s
    np.testing.assert_allclose(pred.cov[0, at, 1, 1], [0.3**2, 1.1**2, 1.9**2])
    np.testing.assert_allclose(pred.cov[0, at, 0, 0], [0.2**2, 0.45**2, 0.7**2])
    np.testing.assert_allclose(pred.cov[0, :, 0, 1], 0, atol=1e-12)
    assert np.all(np.diff(np.linalg.det(pred.cov[0])) > 0)
    # heading 45 deg: R diag(l^2, w^2) R^T has off-diagonal (l^2 - w^2) / 2 = (3.61 - 0.49) / 2
    diagonal = predict_constant_turn_rate([_car(KinematicState(0, 0, math.pi / 4, 10))], times, config)
    np.testing.assert_allclose(diagonal.cov[0, 20], [[2.05, 1.56], [1.56, 2.05]])


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


# ----------------------------------------------------------------- constant acceleration


def _ode_reference(state, times, config):
    """Independent solution of the predictor's motion law with scipy's ODE solver.

    u' = a (braking, until u = 0) or a exp(-t / T_a) (a >= 0); theta' = omega exp(-t / T_w)
    while moving; p' = u (cos theta, sin theta).
    """
    from scipy.integrate import solve_ivp

    t_a, t_w = config.acceleration_time_constant, config.turn_rate_time_constant

    def rhs(t, z):
        x, y, theta, u = z
        moving = u > 1e-12
        du = (state.a if state.a < 0 else state.a * math.exp(-t / t_a)) if (moving or state.a > 0) else 0.0
        dtheta = state.yaw_rate * math.exp(-t / t_w) if moving else 0.0
        return [u * math.cos(theta), u * math.sin(theta), dtheta, du]

    stop = (lambda t, z: z[3]) if state.a < 0 else None
    if stop is not None:
        stop.terminal = True
        stop.direction = -1
    sol = solve_ivp(
        rhs,
        (0.0, times[-1]),
        [state.x, state.y, state.yaw, state.v],
        t_eval=times,
        events=stop,
        rtol=1e-10,
        atol=1e-10,
        max_step=0.01,
    )
    out = np.empty((len(times), 4))
    out[: sol.y.shape[1]] = sol.y.T
    if sol.y.shape[1] < len(times):  # stopped: stays where it stopped
        x_stop, y_stop, th_stop, _ = sol.y_events[0][0]
        out[sol.y.shape[1] :] = [x_stop, y_stop, th_stop, 0.0]
    return out


@pytest.mark.parametrize(
    "state",
    [
        KinematicState(0, 0, 0.3, 15.0, a=-7.5, yaw_rate=0.0),
        KinematicState(5, -2, 1.0, 12.0, a=-4.0, yaw_rate=0.4),
        KinematicState(0, 0, 0.0, 8.0, a=2.0, yaw_rate=-0.3),
        KinematicState(0, 0, 2.0, 0.0, a=1.5, yaw_rate=0.2),
    ],
)
def test_constant_acceleration_means_match_an_ode_solver(state):
    from ethical_planner.prediction import predict_constant_acceleration

    times = np.linspace(0, 3, 31)
    config = PredictionConfig()
    pred = predict_constant_acceleration([_car(state)], times, config)
    ref = _ode_reference(state, times, config)
    np.testing.assert_allclose(pred.mean[0], ref[:, :2], atol=2e-3)
    np.testing.assert_allclose(pred.heading[0], ref[:, 2], atol=1e-6)
    np.testing.assert_allclose(pred.speed[0], ref[:, 3], atol=1e-6)


def test_braking_road_user_stops_and_never_reverses():
    """A lead braking at 7.5 m/s^2 from 15 m/s stops after 15 m (v^2 / 2a), not 45 m at 3 s."""
    from ethical_planner.prediction import predict_constant_acceleration

    times = np.linspace(0, 3, 31)
    lead = _car(KinematicState(0, 0, 0, 15.0, a=-7.5))
    pred = predict_constant_acceleration([lead], times, PredictionConfig())
    x = pred.mean[0, :, 0]
    expected = np.where(times < 2.0, 15 * times - 3.75 * times**2, 15.0)
    np.testing.assert_allclose(x, expected, atol=2e-3)
    assert np.all(np.diff(x) >= -1e-12) and np.all(pred.speed[0] >= 0)
    np.testing.assert_allclose(pred.speed[0, times >= 2.0], 0.0)
    # The constant-turn-rate model keeps 15 m/s: 45 m at 3 s.
    assert predict_constant_turn_rate([lead], times, PredictionConfig()).mean[0, -1, 0] == pytest.approx(45)


def test_turn_rate_decays_so_a_swerve_is_not_a_circle():
    from ethical_planner.prediction import predict_constant_acceleration

    times = np.linspace(0, 3, 31)
    config = PredictionConfig()
    swerving = _car(KinematicState(0, 0, 0, 15.0, yaw_rate=0.3))
    decayed = predict_constant_acceleration([swerving], times, config)
    circle = predict_constant_turn_rate([swerving], times, config)
    # Total heading change is omega T_w (1 - exp(-t / T_w)) <= omega T_w = 0.24 rad.
    limit = 0.3 * config.turn_rate_time_constant
    np.testing.assert_allclose(decayed.heading[0, -1], limit * (1 - math.exp(-3 / 0.8)))
    assert circle.heading[0, -1] == pytest.approx(0.9)
    assert decayed.mean[0, -1, 1] < 0.5 * circle.mean[0, -1, 1]


def test_acceleration_uncertainty_widens_the_longitudinal_spread():
    from ethical_planner.prediction import predict_constant_acceleration

    times = np.linspace(0, 3, 31)
    config = PredictionConfig(covariance_floor=1e-9)
    braking = predict_constant_acceleration([_car(KinematicState(0, 0, 0, 15.0, a=-5.0))], times, config)
    steady = predict_constant_acceleration([_car(KinematicState(0, 0, 0, 15.0))], times, config)
    sigma_a = config.acceleration_sigma + config.acceleration_sigma_per_observed * 5.0
    tau = np.minimum(times, 3.0)  # stops at 3 s
    sigma_long = config.sigma0_long + (config.growth_long + config.growth_long_per_speed * 15) * tau
    np.testing.assert_allclose(np.sqrt(braking.cov[0, :, 0, 0]), sigma_long + 0.5 * sigma_a * tau**2)
    steady_sigma = sigma_long + 0.5 * config.acceleration_sigma * times**2
    np.testing.assert_allclose(np.sqrt(steady.cov[0, :, 0, 0]), steady_sigma)
    # A stopped road user's spread stops growing when it stops.
    stopping = predict_constant_acceleration([_car(KinematicState(0, 0, 0, 6.0, a=-6.0))], times, config)
    np.testing.assert_allclose(stopping.cov[0, 10:, 0, 0], stopping.cov[0, 10, 0, 0])


def test_the_default_predictor_is_constant_acceleration_and_both_are_registered():
    from ethical_planner.prediction import PREDICTORS, make_predictor

    assert make_predictor(PredictionConfig()).name == "constant_acceleration"
    assert {"constant_acceleration", "constant_turn_rate"} <= set(PREDICTORS.names())
    with pytest.raises(ValueError, match="turn_rate_time_constant"):
        PredictionConfig(turn_rate_time_constant=0.0)
