"""Risk of every candidate for every road user (paper Eqs. 3 and 4), vectorised.

Shapes: n candidates, k road users, t time steps. Harm is evaluated only where the
collision probability survived the distance gate (p > 0), which is what keeps the
cycle fast with many road users.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from .collision_probability import _parallel_for, _submit, collision_probability
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


#: Extra inward margin [m] of the eroded drivable area, above the sagitta of shapely's
#: arc approximation (r (1 - cos(pi / 32)) < 0.5 % of r at quad_segs = 8) and rounding.
_ERODE_MARGIN = 0.05
_ERODED: dict[tuple[int, float], tuple[object, object]] = {}


def _eroded_area(area: shapely.Geometry, radius: float) -> shapely.Geometry:
    """``area`` shrunk by ``radius`` [m] plus a margin, prepared, cached per area object."""
    key = (id(area), radius)
    cached = _ERODED.get(key)
    if cached is None or cached[0] is not area:
        if len(_ERODED) >= 8:
            _ERODED.clear()
        inner = area.buffer(-(radius * 1.01 + _ERODE_MARGIN))
        shapely.prepare(inner)
        # The entry keeps ``area`` alive, so its id cannot be reused while cached.
        cached = _ERODED[key] = (area, inner)
    return cached[1]


def outside_drivable_area(
    candidates: Candidates, shape: Shape, environment: RoadEnvironment
) -> np.ndarray:
    """True where a corner of the ego footprint lies outside the drivable area, shape (n, t).

    A centre inside the area shrunk by the footprint's half-diagonal has all corners
    inside, so only the other centres (near the road edge) get the corner test.
    """
    area = environment.drivable_area
    half_diagonal = 0.5 * float(np.hypot(shape.length, shape.width))
    deep = shapely.contains_xy(_eroded_area(area, half_diagonal), candidates.x, candidates.y)
    outside = np.zeros(candidates.x.shape, dtype=bool)
    edge = np.flatnonzero(~deep)
    if edge.size:
        cx, cy = footprint_corners(
            candidates.x.ravel()[edge], candidates.y.ravel()[edge], candidates.yaw.ravel()[edge],
            shape.length, shape.width,
        )
        outside.ravel()[edge] = ~np.all(shapely.contains_xy(area, cx, cy), axis=-1)
    return outside


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
    # shapely releases the GIL: the road-edge test runs beside the collision probability.
    outside_job = _submit(lambda: outside_drivable_area(candidates, ego_shape, environment))
    cp = collision_probability(
        candidates.x, candidates.y, candidates.yaw, ego_shape.length, ego_shape.width,
        prediction.mean, prediction.cov, prediction.heading, prediction.length,
        prediction.width, gate_sigmas=config.gate_sigmas,
    )
    p = cp.probability
    harm_obs = np.zeros((n, k, n_t))
    harm_ego = np.zeros((n, k, n_t))
    risk_obs = np.zeros((n, k))
    risk_ego = np.zeros((n, k))
    # Triples with p > 0 in (traj, obs, t) order; rows of the (traj, t) and (obs, t) tables.
    flat = np.flatnonzero(p > 0.0)
    if flat.size:
        per_traj = k * n_t
        step = flat % n_t
        pair = flat // n_t  # (traj, obs)
        ego_row = (flat // per_traj) * n_t + step
        obs_row = flat % per_traj
        obs_index = obs_row // n_t
        harms = _harm_of_survivors(
            candidates, prediction, ego_mass, config, ego_row, obs_row, obs_index
        )
        harm_obs.ravel()[flat] = harms[0]
        harm_ego.ravel()[flat] = harms[1]
        # R = max over t of p H (Eq. 3): p H is 0 where p = 0, so the maximum over the
        # surviving steps of each (traj, obs) pair, >= 0, is the same.
        p_s = p.ravel()[flat]
        starts = np.flatnonzero(np.diff(pair, prepend=-1))
        risk_obs.ravel()[pair[starts]] = np.maximum.reduceat(p_s * harms[0], starts)
        risk_ego.ravel()[pair[starts]] = np.maximum.reduceat(p_s * harms[1], starts)
    peak_step = p.argmax(axis=2) if n_t else np.zeros((n, k), dtype=int)

    outside = (
        outside_drivable_area(candidates, ego_shape, environment)
        if outside_job is None
        else outside_job.result()
    )
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


def _harm_of_survivors(
    candidates: Candidates,
    prediction: Prediction,
    ego_mass: float,
    config: RiskConfig,
    ego_row: np.ndarray,
    obs_row: np.ndarray,
    obs_index: np.ndarray,
) -> np.ndarray:
    """Harm of the road user and of the ego at the m given (traj, obs, t) triples.

    Args:
        candidates, prediction, ego_mass, config: as for ``assess_risk``.
        ego_row: traj * n_t + t of each triple, shape (m,).
        obs_row: obs * n_t + t, shape (m,).
        obs_index: obs, shape (m,).

    Returns:
        (harm_obs, harm_ego), shape (2, m).
    """
    # Velocities per (traj, t) and (obs, t) once, then gathered: trigonometry on the
    # small tables instead of on every triple.
    ego_yaw = candidates.yaw.ravel()
    ego_table = np.stack(
        [
            candidates.x.ravel(), candidates.y.ravel(), ego_yaw,
            candidates.v.ravel() * np.cos(ego_yaw), candidates.v.ravel() * np.sin(ego_yaw),
        ]
    )
    obs_yaw = prediction.heading.ravel()
    obs_speed = prediction.speed.ravel()
    obs_table = np.stack(
        [
            prediction.mean[..., 0].ravel(), prediction.mean[..., 1].ravel(), obs_yaw,
            obs_speed * np.cos(obs_yaw), obs_speed * np.sin(obs_yaw),
        ]
    )
    model = HarmModel(config.harm_model)
    pedestrian_model = HarmModel(config.pedestrian_model)
    out = np.empty((2, ego_row.size))

    def run(part: slice) -> None:
        ego = ego_table.take(ego_row[part], axis=1)
        obs = obs_table.take(obs_row[part], axis=1)
        index = obs_index[part]
        result = collision_harm(
            ego_mass=ego_mass,
            ego_vel=ego[3:5].T,
            ego_pos=ego[0:2].T,
            ego_yaw=ego[2],
            obs_mass=prediction.mass.take(index),
            obs_vel=obs[3:5].T,
            obs_pos=obs[0:2].T,
            obs_yaw=obs[2],
            obs_unprotected=prediction.vulnerable.take(index),
            model=model,
            pedestrian_model=pedestrian_model,
        )
        out[0, part] = result.harm_obs
        out[1, part] = result.harm_ego

    # Elementwise, so any split gives the same numbers; two halves keep two cores busy.
    m = ego_row.size
    parts = [slice(0, m)] if m < _HARM_PARALLEL_MIN else [slice(0, m // 2), slice(m // 2, m)]
    _parallel_for(parts, run)
    return out


#: Below this many triples harm is evaluated on the calling thread only.
_HARM_PARALLEL_MIN = 50_000
