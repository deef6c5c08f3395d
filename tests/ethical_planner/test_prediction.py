import math

import numpy as np
import pytest

from ethical_planner.config import PredictionConfig
from ethical_planner.prediction import Prediction, predict_constant_turn_rate
from ethical_planner.prediction.base import smallest_eigenvalue
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


def _symmetric_cases(rng: np.random.Generator) -> np.ndarray:
    """Random symmetric 2x2 matrices: PSD, indefinite, rank 1, zero, diagonal, huge and tiny."""
    a = rng.normal(size=(500, 2, 2))
    psd = a @ np.swapaxes(a, -1, -2)
    sym = 0.5 * (a + np.swapaxes(a, -1, -2))
    v = rng.normal(size=(300, 2)) * rng.choice([1e-6, 1.0, 1e4], size=(300, 1))
    rank1 = v[:, :, None] * v[:, None, :]
    special = np.array(
        [
            np.zeros((2, 2)),
            np.eye(2),
            0.1 * np.eye(2),
            [[4.0, 0.0], [0.0, 0.0]],
            [[0.0, 0.0], [0.0, 4.0]],
            [[1.0, 1.0], [1.0, 1.0]],
            [[-1.0, 0.0], [0.0, -3.0]],
            [[1e8, 0.0], [0.0, 1e-8]],
            [[2.0, -2.0], [-2.0, 2.0]],
        ]
    )
    return np.concatenate([psd, sym, rank1, 1e6 * psd[:50], 1e-6 * psd[:50], special])


def test_smallest_eigenvalue_closed_form_matches_lapack():
    """The closed form against numpy.linalg.eigvalsh, to rounding relative to the matrix norm.

    A mutant taking the larger root (``+`` for ``-``) or dropping b from the radius goes red.
    """
    cov = _symmetric_cases(np.random.default_rng(13))
    expected = np.linalg.eigvalsh(cov)
    scale = np.abs(expected).max(axis=-1)
    got = smallest_eigenvalue(cov)
    assert got.shape == (len(cov),)
    np.testing.assert_array_less(np.abs(got - expected[:, 0]), 1e-14 * scale + 1e-300)
    # Same shape handling over leading axes (road users, steps).
    grid = cov[:600].reshape(20, 30, 2, 2)
    np.testing.assert_array_equal(smallest_eigenvalue(grid), got[:600].reshape(20, 30))
    # PSD matrices, rank 1 included, pass the planner's -1e-9 m^2 check; indefinite ones do not.
    assert np.all(got[:500] >= -1e-9) and np.all(got[1000:1300] >= -1e-9 * scale[1000:1300])
    assert np.array_equal(got[500:1000] < -1e-9, expected[500:1000, 0] < -1e-9)


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

    Without a history the course is the current heading: the heading deviation e
    (e(0) = 0, e'(0) = omega) returns critically damped, e'' = -2 e' / T - e / T^2,
    while moving; u' = a (braking, until u = 0) or a exp(-t / T_a) (a >= 0);
    p' = u (cos theta, sin theta).
    """
    from scipy.integrate import solve_ivp

    t_a, t_w = config.acceleration_time_constant, config.turn_rate_time_constant

    def rhs(t, z):
        x, y, theta, u, e, e_dot = z
        moving = u > 1e-12
        du = (state.a if state.a < 0 else state.a * math.exp(-t / t_a)) if (moving or state.a > 0) else 0.0
        e_ddot = -2.0 * e_dot / t_w - e / t_w**2
        if not moving:
            e_dot, e_ddot = 0.0, 0.0
        return [u * math.cos(theta), u * math.sin(theta), e_dot, du, e_dot, e_ddot]

    stop = (lambda t, z: z[3]) if state.a < 0 else None
    if stop is not None:
        stop.terminal = True
        stop.direction = -1
    sol = solve_ivp(
        rhs,
        (0.0, times[-1]),
        [state.x, state.y, state.yaw, state.v, 0.0, state.yaw_rate],
        t_eval=times,
        events=stop,
        rtol=1e-10,
        atol=1e-10,
        max_step=0.01,
    )
    out = np.empty((len(times), 4))
    out[: sol.y.shape[1]] = sol.y[:4].T
    if sol.y.shape[1] < len(times):  # stopped: stays where it stopped
        x_stop, y_stop, th_stop, _ = sol.y_events[0][0][:4]
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
    # The heading returns to the course: omega t exp(-t / T), at most omega T / e = 0.088 rad.
    np.testing.assert_allclose(decayed.heading[0], 0.3 * times * np.exp(-times / 0.8), atol=1e-12)
    assert decayed.heading[0].max() <= 0.3 * 0.8 / math.e + 1e-12
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


def _with_history(state, rate_before, uid=1):
    """A car whose 3 s history turned at ``rate_before`` [rad/s] (10 Hz samples)."""
    from ethical_planner.road_users import MotionHistory

    times = np.linspace(-3.0, 0.0, 31)
    headings = state.yaw + rate_before * times
    history = MotionHistory(times, np.zeros((31, 2)), headings, np.full(31, state.v))
    return RoadUser(uid, RoadUserType.CAR, state, DEFAULT_SHAPES[RoadUserType.CAR], history=history)


def test_a_curve_in_the_history_is_followed_a_fresh_swerve_decays():
    """The sustained course (fitted to 2.5 to 1 s ago) is kept; a deviation returns to it.

    On a curve (radius 70 m at 12 m/s: 0.171 rad/s for 3 s) the prediction stays on the
    circle like the constant turn rate; a car that starts turning now (straight before)
    gets the decaying turn rate.
    """
    from ethical_planner.prediction import predict_constant_acceleration

    times = np.linspace(0, 3, 31)
    config = PredictionConfig()
    rate = 12.0 / 70.0
    state = KinematicState(0, 0, 0, 12.0, yaw_rate=rate)
    on_curve = predict_constant_acceleration([_with_history(state, rate)], times, config)
    np.testing.assert_allclose(on_curve.heading[0], rate * times, atol=1e-9)
    np.testing.assert_allclose(
        np.hypot(on_curve.mean[0, :, 0], on_curve.mean[0, :, 1] - 70.0), 70.0, atol=5e-3
    )
    fresh = predict_constant_acceleration([_with_history(state, 0.0)], times, config)
    np.testing.assert_allclose(fresh.heading[0], rate * times * np.exp(-times / 0.8), atol=1e-9)
    # A curve that is ending (turning less now) is followed at the current, lower rate;
    # a swing the other way is not a curve at all.
    ending = predict_constant_acceleration(
        [_with_history(KinematicState(0, 0, 0, 12.0, yaw_rate=0.05), rate)], times, config
    )
    np.testing.assert_allclose(ending.heading[0], 0.05 * times, atol=1e-9)
    swing = predict_constant_acceleration(
        [_with_history(KinematicState(0, 0, 0, 12.0, yaw_rate=-0.05), rate)], times, config
    )
    np.testing.assert_allclose(swing.heading[0], -0.05 * times * np.exp(-times / 0.8), atol=1e-9)


def test_a_drift_returns_to_its_course():
    """A car 0.2 rad off the course its history shows (and still turning away at 0.1
    rad/s) straightens out: its heading relaxes to the course, its lateral excursion is
    bounded by v (e0 2T + e1 T^2) instead of growing with the horizon."""
    from ethical_planner.prediction import predict_constant_acceleration

    times = np.linspace(0, 3, 31)
    config = PredictionConfig()
    drifting = _with_history(KinematicState(0, 0, 0.2, 15.0, yaw_rate=0.1), 0.0)
    # The history's headings are those of a car on course 0.2 rad earlier: rebuild it on course 0.
    from ethical_planner.road_users import MotionHistory

    history = MotionHistory(np.linspace(-3, 0, 31), np.zeros((31, 2)), np.zeros(31), np.full(31, 15.0))
    drifting = RoadUser(1, RoadUserType.CAR, drifting.state, drifting.shape, history=history)
    pred = predict_constant_acceleration([drifting], times, config)
    t_w = config.turn_rate_time_constant
    expected = (0.2 + (0.2 / t_w + 0.1) * times) * np.exp(-times / t_w)
    np.testing.assert_allclose(pred.heading[0], expected, atol=1e-9)
    bound = 15.0 * (0.2 * 2 * t_w + 0.1 * t_w**2)
    assert pred.mean[0, -1, 1] < bound
