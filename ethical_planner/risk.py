"""Risk of every candidate for every road user (paper Eqs. 3 and 4), vectorised.

Shapes: n candidates, k road users, t time steps. Harm is evaluated only where the
collision probability survived the distance gate (p > 0), which is what keeps the
cycle fast with many road users.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from .collision_probability import collision_probability
from .config import RiskConfig
from .environment import RoadEnvironment
from .harm import HarmModel, boundary_harm, collision_harm
from .prediction import Prediction
from .road_users import Shape
from .sampling import Candidates


@dataclass(frozen=True, slots=True, eq=False)
class RiskAssessment:
    """Collision probability, harm and risk of all candidates.

    Attributes:
        probability: p_k(u, t), shape (n, k, t).
        mean_overlap: footprints overlap at the predicted mean, shape (n, k, t).
        harm_obs: harm of road user k if it collides at t, shape (n, k, t) (0 where p = 0).
        harm_ego: harm of the ego in that collision, shape (n, k, t).
        risk_obs: R_k(u) = max_t p H_obs, shape (n, k) (Eq. 3).
        risk_ego: R_ego,k(u) = max_t p H_ego, shape (n, k).
        peak_step: step of the highest collision probability, shape (n, k).
        outside_road: the ego footprint leaves the drivable area, shape (n, t).
        boundary_risk: harm of hitting a wall at the first step outside (p = 1), shape (n,).
        ego_combined: R_ego(u) = 1 - prod(1 - R_ego,k) incl. the boundary, shape (n,) (Eq. 4).
    """

    probability: np.ndarray
    mean_overlap: np.ndarray
    harm_obs: np.ndarray
    harm_ego: np.ndarray
    risk_obs: np.ndarray
    risk_ego: np.ndarray
    peak_step: np.ndarray
    outside_road: np.ndarray
    boundary_risk: np.ndarray
    ego_combined: np.ndarray


def footprint_corners(
    x: np.ndarray, y: np.ndarray, yaw: np.ndarray, length: float, width: float
) -> tuple[np.ndarray, np.ndarray]:
    """Corners of rectangles centred at (x, y); inputs any shape S, outputs S + (4,)."""
    c, s = np.cos(yaw)[..., None], np.sin(yaw)[..., None]
    half_l = 0.5 * length * np.array([1.0, 1.0, -1.0, -1.0])
    half_w = 0.5 * width * np.array([1.0, -1.0, -1.0, 1.0])
    return x[..., None] + c * half_l - s * half_w, y[..., None] + s * half_l + c * half_w


def outside_drivable_area(
    candidates: Candidates, shape: Shape, environment: RoadEnvironment
) -> np.ndarray:
    """True where a corner of the ego footprint lies outside the drivable area, shape (n, t)."""
    cx, cy = footprint_corners(candidates.x, candidates.y, candidates.yaw, shape.length, shape.width)
    inside = shapely.contains_xy(environment.drivable_area, cx, cy)
    return ~np.all(inside, axis=-1)


def assess_risk(
    candidates: Candidates,
    prediction: Prediction,
    ego_shape: Shape,
    ego_mass: float,
    environment: RoadEnvironment,
    config: RiskConfig,
) -> RiskAssessment:
    """Collision probability, harm and risk of every candidate for every road user."""
    n, n_t = candidates.x.shape
    k = prediction.n_obs
    cp = collision_probability(
        candidates.x, candidates.y, candidates.yaw, ego_shape.length, ego_shape.width,
        prediction.mean, prediction.cov, prediction.heading, prediction.length,
        prediction.width, gate_sigmas=config.gate_sigmas,
    )
    p = cp.probability
    harm_obs = np.zeros((n, k, n_t))
    harm_ego = np.zeros((n, k, n_t))
    i_traj, i_obs, i_t = np.nonzero(p > 0.0)
    if i_traj.size:
        ego_v = candidates.v[i_traj, i_t]
        ego_yaw = candidates.yaw[i_traj, i_t]
        obs_yaw = prediction.heading[i_obs, i_t]
        obs_v = prediction.speed[i_obs, i_t]
        result = collision_harm(
            ego_mass=ego_mass,
            ego_vel=np.stack([ego_v * np.cos(ego_yaw), ego_v * np.sin(ego_yaw)], axis=-1),
            ego_pos=np.stack([candidates.x[i_traj, i_t], candidates.y[i_traj, i_t]], axis=-1),
            ego_yaw=ego_yaw,
            obs_mass=prediction.mass[i_obs],
            obs_vel=np.stack([obs_v * np.cos(obs_yaw), obs_v * np.sin(obs_yaw)], axis=-1),
            obs_pos=prediction.mean[i_obs, i_t],
            obs_yaw=obs_yaw,
            obs_unprotected=prediction.vulnerable[i_obs],
            model=HarmModel(config.harm_model),
            pedestrian_model=HarmModel(config.pedestrian_model),
        )
        harm_obs[i_traj, i_obs, i_t] = result.harm_obs
        harm_ego[i_traj, i_obs, i_t] = result.harm_ego
    risk_obs = (p * harm_obs).max(axis=2, initial=0.0)
    risk_ego = (p * harm_ego).max(axis=2, initial=0.0)
    peak_step = p.argmax(axis=2) if n_t else np.zeros((n, k), dtype=int)

    outside = outside_drivable_area(candidates, ego_shape, environment)
    boundary = np.zeros(n)
    if config.boundary_harm:
        leaves = outside.any(axis=1)
        first = outside.argmax(axis=1)
        boundary = np.where(leaves, boundary_harm(candidates.v[np.arange(n), first]), 0.0)
    survive = np.prod(1.0 - risk_ego, axis=1) * (1.0 - boundary)
    return RiskAssessment(
        probability=p,
        mean_overlap=cp.mean_overlap,
        harm_obs=harm_obs,
        harm_ego=harm_ego,
        risk_obs=risk_obs,
        risk_ego=risk_ego,
        peak_step=peak_step,
        outside_road=outside,
        boundary_risk=boundary,
        ego_combined=1.0 - survive,
    )
