"""The constant-turn-rate predictor: each road user keeps its observed speed and turn rate.

The position covariance grows over the horizon (``PredictionConfig``). Registered as
``"constant_turn_rate"``; the default predictor is ``constant_acceleration``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ethical_planner.config import PredictionConfig
from ethical_planner.prediction.base import (
    PREDICTORS,
    Prediction,
    check_unique_ids,
    empty_prediction,
    growing_sigmas,
    rotated_covariance,
)
from ethical_planner.road_users import RoadUser


def predict_constant_turn_rate(
    road_users: Sequence[RoadUser], times: np.ndarray, config: PredictionConfig
) -> Prediction:
    """Predict every road user with constant speed and turn rate.

    Args:
        road_users: observed road users.
        times: prediction times [s] from now, shape (n_t,), times[0] = 0.
        config: growth of the covariance and its floor.

    Returns:
        The prediction, covariances floored at ``config.covariance_floor``.
    """
    times = np.asarray(times, dtype=float)
    n_obs, n_t = len(road_users), len(times)
    if n_obs == 0:
        return empty_prediction(n_t)
    ids = check_unique_ids(road_users)
    x0, y0, yaw0, v0, omega = (
        np.array([getattr(u.state, name) for u in road_users])[:, None]
        for name in ("x", "y", "yaw", "v", "yaw_rate")
    )
    if not config.use_turn_rate:
        omega = np.zeros_like(omega)
    t = times[None, :]
    heading = yaw0 + omega * t
    turning = np.abs(omega) > 1e-6
    safe_omega = np.where(turning, omega, 1.0)
    # Constant turn rate arcs; straight lines where the turn rate vanishes.
    x = np.where(turning, x0 + v0 / safe_omega * (np.sin(heading) - np.sin(yaw0)), x0 + v0 * t * np.cos(yaw0))
    y = np.where(turning, y0 - v0 / safe_omega * (np.cos(heading) - np.cos(yaw0)), y0 + v0 * t * np.sin(yaw0))
    sigma_long, sigma_lat = growing_sigmas(road_users, v0, t, t, config)
    prediction = Prediction(
        ids=ids,
        types=tuple(u.type for u in road_users),
        mean=np.stack([x, y], axis=-1),
        cov=rotated_covariance(sigma_long, sigma_lat, heading),
        heading=heading,
        speed=np.broadcast_to(np.abs(v0), (n_obs, n_t)).copy(),
        length=np.array([u.shape.length for u in road_users]),
        width=np.array([u.shape.width for u in road_users]),
        mass=np.array([u.mass for u in road_users]),
    )
    return prediction.with_covariance_floor(config.covariance_floor)


@dataclass(frozen=True, slots=True)
class ConstantTurnRatePredictor:
    """``Predictor`` with constant speed and turn rate (``predict_constant_turn_rate``).

    Attributes:
        config: covariance growth and floor.
    """

    config: PredictionConfig
    name: str = "constant_turn_rate"

    def predict(self, road_users: Sequence[RoadUser], times: np.ndarray) -> Prediction:
        """Predict every road user at ``times`` [s] from now, shape (n_t,)."""
        return predict_constant_turn_rate(road_users, times, self.config)


PREDICTORS.register("constant_turn_rate", ConstantTurnRatePredictor)
