"""The default predictor: observed acceleration and a decaying turn rate.

Each road user moves along its heading with its observed acceleration: braking is
held until it stops and it then stays stopped (a prediction never reverses); a
positive acceleration decays with ``acceleration_time_constant`` (acceleration phases
end). A swerve is an episode: the deviation of its heading from the course it has been
keeping (``sustained_course``: the heading and turn rate of its recent motion history,
a curve it follows) returns to that course, critically damped with
``turn_rate_time_constant``, starting from the observed heading and turn rate. So a
drift is not a circle driven to the kerb, a curve is still followed, and without a
history a turn rate fades out. The heading freezes when the road user stops.
The position covariance grows with speed and with the uncertainty of the future
acceleration (``PredictionConfig``). Registered as ``"constant_acceleration"``.

With psi_s and omega_s the sustained course and turn rate, e0 = yaw0 - psi_s,
e1 = omega0 - omega_s, T_w the time constant and tau(t) = min(t, t_stop):

    u(t) = max(v0 + a t, 0)                          (a < 0; t_stop = v0 / -a)
    u(t) = v0 + a T_a (1 - exp(-t / T_a))            (a >= 0)
    theta(t) = psi_s + omega_s tau + (e0 + (e0 / T_w + e1) tau) exp(-tau / T_w)
    p(t) = p0 + integral_0^t u [cos theta, sin theta] dt'
    sigma_long(t) = sigma0 + (g + g_v v0) tau + 0.5 sigma_a tau^2

The integral is a trapezoid rule on ``_SUBSTEPS`` sub-steps per prediction step
(millimetres on a 0.1 s grid).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ethical_planner.config import PredictionConfig
from ethical_planner.geometry import wrap_angle
from ethical_planner.prediction.base import (
    PREDICTORS,
    Prediction,
    check_unique_ids,
    empty_prediction,
    growing_sigmas,
    rotated_covariance,
)
from ethical_planner.road_users import RoadUser, RoadUserType

#: Sub-steps of the position integral per prediction step.
_SUBSTEPS = 8


def _fine_grid(times: np.ndarray) -> np.ndarray:
    """``times`` refined by ``_SUBSTEPS`` equal sub-steps per interval, shape (m,)."""
    if len(times) < 2:
        return times.copy()
    fractions = np.arange(_SUBSTEPS) / _SUBSTEPS
    inner = times[:-1, None] + np.diff(times)[:, None] * fractions[None, :]
    return np.concatenate([inner.ravel(), times[-1:]])


def _cumulative_trapezoid(values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Integral of ``values`` (k, m) over ``grid`` (m,) from grid[0], shape (k, m)."""
    steps = 0.5 * np.diff(grid)[None, :] * (values[:, 1:] + values[:, :-1])
    return np.concatenate([np.zeros((len(values), 1)), np.cumsum(steps, axis=1)], axis=1)


def _step_columns(n_t: int) -> np.ndarray:
    """Columns of the fine grid that are the prediction times."""
    return np.arange(n_t) * (_SUBSTEPS if n_t > 1 else 1)


def sustained_course(
    road_users: Sequence[RoadUser], config: PredictionConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Course each road user has been keeping: heading now [rad] and turn rate [rad/s], (k,) each.

    A straight line fitted to the headings of its motion history between ``start`` and
    ``end`` seconds ago (``config.sustained_turn_window``) gives the turn rate it has
    kept (a curve it follows) and, extrapolated to now, the heading it would have if it
    had kept it. The rate kept from now on is capped at the current turn rate and 0 where the two have
    opposite signs (a curve ends, a swerve swings back). Without a history that long,
    for pedestrians (who turn to cross) and below 2 m/s (no meaningful heading) the
    course is the current heading and no turning.
    """
    start, end = config.sustained_turn_window
    yaw = np.array([u.state.yaw for u in road_users], dtype=float)
    now = np.array([u.state.yaw_rate for u in road_users], dtype=float)
    course, rates = yaw.copy(), np.zeros(len(road_users))
    for k, user in enumerate(road_users):  # per road user, on its own short history
        history = user.history
        if history is None or history.duration < start - 1e-6 or user.type is RoadUserType.PEDESTRIAN:
            continue
        window = (history.times >= -start - 1e-6) & (history.times <= -end + 1e-6)
        if window.sum() < 2 or history.speeds[window].mean() < _COURSE_MIN_SPEED:
            continue
        headings = np.unwrap(history.headings)[window]
        slope, heading_at_end = np.polyfit(history.times[window] + end, headings, 1)
        rate = np.sign(now[k]) * min(abs(slope), abs(now[k])) if np.sign(slope) == np.sign(now[k]) else 0.0
        rates[k] = rate
        # The course now: the fitted line carried on to now; from now on it turns at the
        # (capped) kept rate.
        deviation = float(wrap_angle(yaw[k] - (heading_at_end + slope * end)))
        course[k] = yaw[k] - np.clip(deviation, -_MAX_COURSE_DEVIATION, _MAX_COURSE_DEVIATION)
    return course, rates


#: Below this mean speed in the window [m/s] a history has no meaningful course.
_COURSE_MIN_SPEED = 2.0
#: Largest heading deviation from the course that is relaxed [rad] (beyond: a turn).
_MAX_COURSE_DEVIATION = 0.5


def _motion(
    v0: np.ndarray,
    a: np.ndarray,
    omega: np.ndarray,
    course: np.ndarray,
    omega_s: np.ndarray,
    yaw0: np.ndarray,
    t: np.ndarray,
    config: PredictionConfig,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Speed, heading and time of motion of k road users at times ``t``.

    Args:
        v0, a, omega, course, omega_s, yaw0: shape (k, 1): speed [m/s] (>= 0),
            acceleration [m/s^2], turn rate [rad/s], sustained course [rad] and turn
            rate [rad/s], heading [rad].
        t: times [s], shape (1, m).
        config: time constants.

    Returns:
        (u, theta, tau), each shape (k, m): speed [m/s], heading [rad], time of motion [s].
    """
    braking = a < 0
    with np.errstate(divide="ignore"):
        t_stop = np.where(braking, v0 / np.where(braking, -a, 1.0), np.inf)
    tau = np.minimum(t, t_stop)
    t_a = config.acceleration_time_constant
    u = np.where(braking, np.maximum(v0 + a * t, 0.0), v0 + a * t_a * (1.0 - np.exp(-t / t_a)))
    # Critically damped return of the heading deviation e to the sustained course.
    t_w = config.turn_rate_time_constant
    e0, e1 = yaw0 - course, omega - omega_s
    deviation = (e0 + (e0 / t_w + e1) * tau) * np.exp(-tau / t_w)
    theta = course + omega_s * tau + deviation
    return u, theta, tau


def predict_constant_acceleration(
    road_users: Sequence[RoadUser], times: np.ndarray, config: PredictionConfig
) -> Prediction:
    """Predict every road user with its observed acceleration and a decaying turn rate.

    Args:
        road_users: observed road users (``state.a`` [m/s^2], ``state.yaw_rate``
            [rad/s] and ``history`` are used; a negative observed speed counts as
            standing).
        times: prediction times [s] from now, shape (n_t,), increasing, times[0] = 0.
        config: time constants, growth of the covariance and its floor.

    Returns:
        The prediction, covariances floored at ``config.covariance_floor``.
    """
    times = np.asarray(times, dtype=float)
    n_obs, n_t = len(road_users), len(times)
    if n_obs == 0:
        return empty_prediction(n_t)
    if n_t > 1 and np.any(np.diff(times) <= 0):
        raise ValueError("prediction times must be strictly increasing")
    ids = check_unique_ids(road_users)
    x0, y0, yaw0, v0, a, omega = (
        np.array([getattr(u.state, name) for u in road_users], dtype=float)[:, None]
        for name in ("x", "y", "yaw", "v", "a", "yaw_rate")
    )
    v0 = np.maximum(v0, 0.0)
    limit = config.max_observed_acceleration
    a = np.clip(a, -limit, limit)
    parked = np.array([u.type is RoadUserType.PARKED_VEHICLE for u in road_users])[:, None]
    v0, a = np.where(parked, 0.0, v0), np.where(parked, 0.0, a)
    course, omega_s = (q[:, None] for q in sustained_course(road_users, config))
    if not config.use_turn_rate:
        omega, omega_s, course = np.zeros_like(omega), np.zeros_like(omega), yaw0

    fine = _fine_grid(times)
    u_f, theta_f, _ = _motion(v0, a, omega, course, omega_s, yaw0, fine[None, :], config)
    vx, vy = u_f * np.cos(theta_f), u_f * np.sin(theta_f)
    x = x0 + _cumulative_trapezoid(vx, fine)[:, _step_columns(n_t)]
    y = y0 + _cumulative_trapezoid(vy, fine)[:, _step_columns(n_t)]

    t = times[None, :]
    u, theta, tau = _motion(v0, a, omega, course, omega_s, yaw0, t, config)
    sigma_long, sigma_lat = growing_sigmas(road_users, v0, tau, t, config)
    sigma_a = config.acceleration_sigma + config.acceleration_sigma_per_observed * np.abs(a)
    is_ped = np.array([u.type is RoadUserType.PEDESTRIAN for u in road_users])[:, None]
    sigma_long = sigma_long + np.where(parked | is_ped, 0.0, 0.5 * sigma_a * tau**2)
    prediction = Prediction(
        ids=ids,
        types=tuple(u.type for u in road_users),
        mean=np.stack([x, y], axis=-1),
        cov=rotated_covariance(sigma_long, sigma_lat, theta),
        heading=theta,
        speed=u,
        length=np.array([u.shape.length for u in road_users]),
        width=np.array([u.shape.width for u in road_users]),
        mass=np.array([u.mass for u in road_users]),
    )
    return prediction.with_covariance_floor(config.covariance_floor)


@dataclass(frozen=True, slots=True)
class ConstantAccelerationPredictor:
    """``Predictor`` with the observed acceleration and a decaying turn rate.

    Attributes:
        config: time constants, covariance growth and floor.
    """

    config: PredictionConfig
    name: str = "constant_acceleration"

    def predict(self, road_users: Sequence[RoadUser], times: np.ndarray) -> Prediction:
        """Predict every road user at ``times`` [s] from now, shape (n_t,)."""
        return predict_constant_acceleration(road_users, times, self.config)


PREDICTORS.register("constant_acceleration", ConstantAccelerationPredictor)
