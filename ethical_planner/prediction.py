"""Predictions of other road users as a struct of arrays, and a first predictor.

The paper uses a learned predictor (WaleNet) that outputs a bivariate normal per
step; here the interface is the same and the first implementation is a
constant-turn-rate model with a covariance that grows over the horizon.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .config import PredictionConfig
from .road_users import MOTORISED_TYPES, VULNERABLE_TYPES, RoadUser, RoadUserType


@dataclass(frozen=True, slots=True, eq=False)
class Prediction:
    """Predicted Gaussian positions of every other road user over the horizon.

    Attributes:
        ids: road-user ids, shape (n_obs,).
        types: road-user types, length n_obs.
        mean: predicted centre [m], shape (n_obs, n_t, 2).
        cov: position covariance [m^2], shape (n_obs, n_t, 2, 2), symmetric PSD.
        heading: [rad], shape (n_obs, n_t).
        speed: [m/s], shape (n_obs, n_t).
        length, width: footprint [m], shape (n_obs,).
        mass: [kg], shape (n_obs,).
    """

    ids: np.ndarray
    types: tuple[RoadUserType, ...]
    mean: np.ndarray
    cov: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    length: np.ndarray
    width: np.ndarray
    mass: np.ndarray

    def __post_init__(self) -> None:
        n_obs = len(self.types)
        n_t = self.mean.shape[1] if self.mean.ndim == 3 else -1
        expected = {
            "ids": (n_obs,),
            "mean": (n_obs, n_t, 2),
            "cov": (n_obs, n_t, 2, 2),
            "heading": (n_obs, n_t),
            "speed": (n_obs, n_t),
            "length": (n_obs,),
            "width": (n_obs,),
            "mass": (n_obs,),
        }
        for name, shape in expected.items():
            value = np.asarray(getattr(self, name))
            if value.shape != shape:
                raise ValueError(f"Prediction.{name} must have shape {shape}, got {value.shape}")
            if name != "ids" and not np.all(np.isfinite(value)):
                raise ValueError(f"Prediction.{name} must be finite (found NaN or inf)")
        for name in ("length", "width", "mass"):
            if np.any(np.asarray(getattr(self, name)) <= 0):
                raise ValueError(f"Prediction.{name} must be > 0 for every road user")
        if n_obs:
            asym = np.abs(self.cov - np.swapaxes(self.cov, -1, -2)).max()
            if asym > 1e-9 * max(1.0, np.abs(self.cov).max()):
                raise ValueError("Prediction.cov must be symmetric")
            eig_min = np.linalg.eigvalsh(self.cov)[..., 0]
            bad = np.argwhere(eig_min < -1e-9)
            if len(bad):
                k, t = bad[0]
                raise ValueError(
                    f"Prediction.cov of road user {self.ids[k]} at step {t} is not positive "
                    f"semidefinite (smallest eigenvalue {eig_min[k, t]:.3g} m^2)"
                )

    @property
    def n_obs(self) -> int:
        """Number of predicted road users."""
        return len(self.types)

    @property
    def vulnerable(self) -> np.ndarray:
        """True for vulnerable road users, shape (n_obs,)."""
        return np.array([t in VULNERABLE_TYPES for t in self.types], dtype=bool)

    @property
    def motorised(self) -> np.ndarray:
        """True for motorised road users, shape (n_obs,)."""
        return np.array([t in MOTORISED_TYPES for t in self.types], dtype=bool)

    def with_covariance_floor(self, floor: float) -> Prediction:
        """Return a copy whose covariance eigenvalues are at least ``floor`` [m^2].

        A zero or degenerate covariance would make the collision probability a
        step function; the reference uses 0.1 I for ground-truth predictions.
        """
        if self.n_obs == 0:
            return self
        eigval, eigvec = np.linalg.eigh(self.cov)
        eigval = np.maximum(eigval, floor)
        cov = np.einsum("...ij,...j,...kj->...ik", eigvec, eigval, eigvec)
        return Prediction(
            self.ids,
            self.types,
            self.mean,
            cov,
            self.heading,
            self.speed,
            self.length,
            self.width,
            self.mass,
        )


def _rotated_covariance(sigma_long: np.ndarray, sigma_lat: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """Covariance [m^2] of stds along/across ``heading``; inputs broadcast, output (..., 2, 2)."""
    c, s = np.cos(heading), np.sin(heading)
    var_l, var_t = sigma_long**2, sigma_lat**2
    cov = np.empty(np.broadcast(c, var_l).shape + (2, 2))
    cov[..., 0, 0] = c * c * var_l + s * s * var_t
    cov[..., 1, 1] = s * s * var_l + c * c * var_t
    cov[..., 0, 1] = cov[..., 1, 0] = c * s * (var_l - var_t)
    return cov


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
        empty = np.zeros((0, n_t))
        return Prediction(
            np.zeros(0, dtype=int),
            (),
            np.zeros((0, n_t, 2)),
            np.zeros((0, n_t, 2, 2)),
            empty,
            empty.copy(),
            np.zeros(0),
            np.zeros(0),
            np.zeros(0),
        )
    ids = np.array([u.id for u in road_users])
    if len(set(ids.tolist())) != n_obs:
        raise ValueError("road-user ids must be unique")
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
    is_ped = np.array([u.type is RoadUserType.PEDESTRIAN for u in road_users])[:, None]
    # A parked vehicle does not move: its uncertainty stays that of the observation.
    moving = np.array([u.type is not RoadUserType.PARKED_VEHICLE for u in road_users])[:, None]
    sigma_long = (
        config.sigma0_long
        + moving
        * np.where(
            is_ped, config.pedestrian_growth, config.growth_long + config.growth_long_per_speed * np.abs(v0)
        )
        * t
    )
    sigma_lat = config.sigma0_lat + moving * np.where(is_ped, config.pedestrian_growth, config.growth_lat) * t
    cov = _rotated_covariance(sigma_long, sigma_lat, heading)
    prediction = Prediction(
        ids=ids,
        types=tuple(u.type for u in road_users),
        mean=np.stack([x, y], axis=-1),
        cov=cov,
        heading=heading,
        speed=np.broadcast_to(np.abs(v0), (n_obs, n_t)).copy(),
        length=np.array([u.shape.length for u in road_users]),
        width=np.array([u.shape.width for u in road_users]),
        mass=np.array([u.mass for u in road_users]),
    )
    return prediction.with_covariance_floor(config.covariance_floor)
