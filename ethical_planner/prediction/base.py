"""Predictions as a struct of arrays, and the predictor protocol every predictor follows.

The paper's planner takes its predictions from a learned network (WaleNet) that outputs
a bivariate normal per future step. Here any object with ``predict(road_users, times)``
returning a ``Prediction`` can stand in its place: the planner and the world take a
``Predictor``, never a particular function. Predictors are registered by name in
``PREDICTORS`` (``[prediction] model = "..."`` in a planner TOML file).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Protocol, runtime_checkable

import numpy as np

from ethical_planner.config import PredictionConfig
from ethical_planner.registry import Registry
from ethical_planner.road_users import MOTORISED_TYPES, VULNERABLE_TYPES, RoadUser, RoadUserType


@dataclass(frozen=True, slots=True, eq=False)
class Prediction:
    """Predicted Gaussian positions of every other road user over the horizon.

    A prediction is one bivariate normal per road user and step, or a Gaussian
    mixture with a shared mean: ``component_weight`` and ``component_cov`` then hold
    its K components, and ``cov`` is the mixture's own covariance
    (sum_k w_k Sigma_k, what a single-Gaussian consumer such as a drawing reads). A
    collision probability of a mixture is the weighted sum of its components'
    (``ethical_planner.risk.assess_risk``).

    Attributes:
        ids: road-user ids, shape (n_obs,).
        types: road-user types, length n_obs.
        mean: predicted centre [m], shape (n_obs, n_t, 2).
        cov: position covariance [m^2], shape (n_obs, n_t, 2, 2), symmetric PSD.
        heading: [rad], shape (n_obs, n_t).
        speed: [m/s], shape (n_obs, n_t).
        length, width: footprint [m], shape (n_obs,).
        mass: [kg], shape (n_obs,).
        component_weight: mixture weights, shape (n_obs, n_t, K), >= 0 and summing to
            1 over K; None for a single Gaussian.
        component_cov: the components' covariances [m^2], shape (n_obs, n_t, K, 2, 2),
            symmetric PSD; None for a single Gaussian.
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
    component_weight: np.ndarray | None = None
    component_cov: np.ndarray | None = None

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
            _check_covariance("cov", self.cov, self.ids)
        self._check_components(n_obs, n_t)

    def _check_components(self, n_obs: int, n_t: int) -> None:
        """Both mixture fields or neither; shapes, weights summing to 1, PSD covariances."""
        weight, cov = self.component_weight, self.component_cov
        if weight is None and cov is None:
            return
        if weight is None or cov is None:
            raise ValueError("Prediction.component_weight and component_cov must be given together")
        weight, cov = np.asarray(weight), np.asarray(cov)
        k = weight.shape[-1] if weight.ndim == 3 else -1
        for name, value, shape in (
            ("component_weight", weight, (n_obs, n_t, k)),
            ("component_cov", cov, (n_obs, n_t, k, 2, 2)),
        ):
            if value.shape != shape or k < 1:
                raise ValueError(f"Prediction.{name} must have shape {shape} with K >= 1, got {value.shape}")
            if not np.all(np.isfinite(value)):
                raise ValueError(f"Prediction.{name} must be finite (found NaN or inf)")
        if np.any(weight < 0) or not np.allclose(weight.sum(-1), 1.0, atol=1e-9):
            raise ValueError("Prediction.component_weight must be >= 0 and sum to 1 over the components")
        if n_obs:
            _check_covariance("component_cov", cov, self.ids)

    @property
    def n_components(self) -> int:
        """Gaussian components per road user and step (1: a single Gaussian)."""
        return 1 if self.component_weight is None else int(np.shape(self.component_weight)[-1])

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
        A mixture's components are floored each, and its ``cov`` recomputed from them.
        """
        if self.n_obs == 0:
            return self
        weight, components = self.component_weight, self.component_cov
        if components is None:
            cov = floor_eigenvalues(self.cov, floor)
        else:
            components = floor_eigenvalues(components, floor)
            cov = np.einsum("otk,otkij->otij", weight, components)
        return replace(self, cov=cov, component_cov=components)


def _check_covariance(name: str, cov: np.ndarray, ids: np.ndarray) -> None:
    """Symmetric positive semidefinite 2x2 matrices in the last two axes (axis 0: road users, 1: steps)."""
    asym = np.abs(cov - np.swapaxes(cov, -1, -2)).max()
    if asym > 1e-9 * max(1.0, np.abs(cov).max()):
        raise ValueError(f"Prediction.{name} must be symmetric")
    eig_min = smallest_eigenvalue(cov)
    bad = np.argwhere(eig_min < -1e-9)
    if len(bad):
        k, t = bad[0][:2]
        raise ValueError(
            f"Prediction.{name} of road user {ids[k]} at step {t} is not positive "
            f"semidefinite (smallest eigenvalue {eig_min[tuple(bad[0])]:.3g} m^2)"
        )


def smallest_eigenvalue(cov: np.ndarray) -> np.ndarray:
    """Smallest eigenvalue of symmetric 2x2 matrices [m^2], shape (..., 2, 2) -> (...).

    Closed form (a + c) / 2 - hypot((a - c) / 2, b), vectorised (no LAPACK call per
    matrix, ~8x faster than ``numpy.linalg.eigvalsh`` on a prediction's 20 x 51
    matrices); accurate to rounding relative to the matrix's norm, as ``eigvalsh``.
    """
    a, c = cov[..., 0, 0], cov[..., 1, 1]
    b = 0.5 * (cov[..., 0, 1] + cov[..., 1, 0])
    return 0.5 * (a + c) - np.hypot(0.5 * (a - c), b)


def floor_eigenvalues(cov: np.ndarray, floor: float) -> np.ndarray:
    """Symmetric 2x2 matrices [m^2], shape (..., 2, 2), with eigenvalues raised to at least ``floor``."""
    eigval, eigvec = np.linalg.eigh(cov)
    return np.einsum("...ij,...j,...kj->...ik", eigvec, np.maximum(eigval, floor), eigvec)


@runtime_checkable
class Predictor(Protocol):
    """Road users and prediction times in, a ``Prediction`` out.

    ``times`` are seconds from now, shape (n_t,), ``times[0] = 0``; the prediction
    covers the road users in the order given (``Prediction.ids`` equal their ids).
    A predictor may keep state between calls (a learned one keeps histories), but it
    must not change its arguments.
    """

    name: str

    def predict(self, road_users: Sequence[RoadUser], times: np.ndarray) -> Prediction:
        """Predict every road user at ``times`` [s]."""
        ...


#: Predictor factories by name: ``factory(config) -> Predictor``.
PREDICTORS: Registry[Callable[[PredictionConfig], Predictor]] = Registry("predictor")


def make_predictor(config: PredictionConfig) -> Predictor:
    """The predictor named by ``config.model``, built with ``config``.

    Raises:
        ValueError: an unknown model; the message lists the registered ones.
    """
    # Importing the package registers the built-in predictors.
    import ethical_planner.prediction  # noqa: F401

    return PREDICTORS.get(config.model)(config)


def rotated_covariance(sigma_long: np.ndarray, sigma_lat: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """Covariance [m^2] of standard deviations along and across ``heading`` [rad].

    Inputs broadcast against each other; the output has their shape + (2, 2).
    """
    c, s = np.cos(heading), np.sin(heading)
    var_l, var_t = sigma_long**2, sigma_lat**2
    cov = np.empty(np.broadcast(c, var_l, var_t).shape + (2, 2))
    cov[..., 0, 0] = c * c * var_l + s * s * var_t
    cov[..., 1, 1] = s * s * var_l + c * c * var_t
    cov[..., 0, 1] = cov[..., 1, 0] = c * s * (var_l - var_t)
    return cov


def growing_sigmas(
    road_users: Sequence[RoadUser],
    speed: np.ndarray,
    tau: np.ndarray,
    t: np.ndarray,
    config: PredictionConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """Standard deviations [m] along and across the heading without an acceleration term.

    sigma_long = sigma0_long + (growth_long + growth_long_per_speed |v|) tau,
    sigma_lat = sigma0_lat + growth_lat t; pedestrians grow by ``pedestrian_growth``
    in both directions, parked vehicles not at all (see ``PredictionConfig``).

    Args:
        road_users: the k road users.
        speed: observed speeds [m/s], shape (k, 1).
        tau: time of motion [s], shape (k, n_t) or (1, n_t).
        t: prediction times [s], shape (1, n_t).
        config: growth rates.

    Returns:
        (sigma_long, sigma_lat), each shape (k, n_t).
    """
    is_ped = np.array([u.type is RoadUserType.PEDESTRIAN for u in road_users])[:, None]
    # A parked vehicle does not move: its uncertainty stays that of the observation.
    moving = np.array([u.type is not RoadUserType.PARKED_VEHICLE for u in road_users])[:, None]
    vehicle_rate = config.growth_long + config.growth_long_per_speed * np.abs(speed)
    long_rate = np.where(is_ped, config.pedestrian_growth, vehicle_rate)
    lat_rate = np.where(is_ped, config.pedestrian_growth, config.growth_lat)
    sigma_long = config.sigma0_long + moving * long_rate * np.where(is_ped, t, tau)
    sigma_lat = config.sigma0_lat + moving * lat_rate * t
    return np.broadcast_to(sigma_long, (len(road_users), t.shape[-1])), sigma_lat


def check_unique_ids(road_users: Sequence[RoadUser]) -> np.ndarray:
    """The road users' ids, shape (k,); ValueError if two share an id."""
    ids = np.array([u.id for u in road_users], dtype=int).reshape(len(road_users))
    if len(set(ids.tolist())) != len(ids):
        raise ValueError("road-user ids must be unique")
    return ids


@functools.lru_cache(maxsize=16)
def empty_prediction(n_t: int) -> Prediction:
    """A prediction of no road users over ``n_t`` steps.

    One instance per ``n_t`` (its arrays hold no element, so nothing can change them):
    a planner without road users asks for it every cycle.
    """
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
