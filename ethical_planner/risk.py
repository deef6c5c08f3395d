"""Risk of every candidate for every road user (paper Eqs. 3 and 4), vectorised.

Shapes: n candidates, k road users, t time steps. Harm is evaluated only where the
collision probability survived the distance gate (p > 0), which is what keeps the
cycle fast with many road users.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from ethical_planner.collision_probability import CollisionProbability, collision_probability
from ethical_planner.config import RiskConfig
from ethical_planner.environment import RoadEnvironment
from ethical_planner.geometry import rectangle_corners
from ethical_planner.harm import HarmModel, boundary_harm, collision_harm
from ethical_planner.prediction.base import Prediction
from ethical_planner.road_users import RoadUserType, Shape
from ethical_planner.sampling import Candidates
from ethical_planner.workers import Workers


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


#: From this many candidate poses (n * n_t) the road-edge test overlaps the collision
#: probability on a helper thread.
_OVERLAP_MIN_POSES = 20_000

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
    candidates: Candidates, shape: Shape, environment: RoadEnvironment, margin: float = 0.0
) -> np.ndarray:
    """True where the ego footprint comes within ``margin`` [m] of the edge, shape (n, t).

    The footprint grown by ``margin`` on every side must lie inside the drivable area:
    a plan that skims the kerb is not executable by a controller with a tracking error
    and a body that yaws. A centre inside the area shrunk by the grown footprint's
    half-diagonal has all corners inside, so only the other centres (near the road
    edge) get the corner test; if the area has holes (debris on the road), footprints
    with all corners inside then get the exact polygon containment test.
    """
    area = environment.drivable_area
    shape = Shape(shape.length + 2.0 * margin, shape.width + 2.0 * margin)
    half_diagonal = 0.5 * float(np.hypot(shape.length, shape.width))
    deep = shapely.contains_xy(_eroded_area(area, half_diagonal), candidates.x, candidates.y)
    outside = np.zeros(candidates.x.shape, dtype=bool)
    edge = np.flatnonzero(~deep)
    if edge.size:
        cx, cy = rectangle_corners(
            candidates.x.ravel()[edge],
            candidates.y.ravel()[edge],
            candidates.yaw.ravel()[edge],
            shape.length,
            shape.width,
        )
        corners_in = np.all(shapely.contains_xy(area, cx, cy), axis=-1)
        holes = _holes(area)
        if holes is not None and corners_in.any():
            # A hole (debris) smaller than the footprint can lie between its corners:
            # footprints with all corners inside and near a hole get the exact test.
            near = np.flatnonzero(corners_in)
            px, py = candidates.x.ravel()[edge[near]], candidates.y.ravel()[edge[near]]
            near = near[shapely.dwithin(holes, shapely.points(px, py), half_diagonal)]
            if near.size:
                ring = np.stack([cx[near], cy[near]], axis=-1)
                footprints = shapely.polygons(np.concatenate([ring, ring[:, :1]], axis=1))
                corners_in[near] = ~shapely.intersects(holes, footprints)
        outside.ravel()[edge] = ~corners_in
    return outside


def prediction_collision_probability(
    candidates: Candidates,
    prediction: Prediction,
    ego_shape: Shape,
    gate_sigmas: float,
    workers: Workers | None = None,
) -> CollisionProbability:
    """Collision probabilities of every candidate with every predicted road user.

    A Gaussian-mixture prediction (K components with a shared mean) is integrated in
    one call with each component as a road user of its own; its probability is the
    weighted sum sum_k w_k(t) p_k(u, t), and the mean overlap that of the shared mean.

    Returns:
        Probabilities and mean overlaps, shape (n, n_obs, n_t).
    """
    k = prediction.n_components
    if k == 1:
        mean, cov, heading = prediction.mean, prediction.cov, prediction.heading
        length, width = prediction.length, prediction.width
    else:
        n_obs, n_t = prediction.mean.shape[:2]
        # Road user o's component c becomes virtual road user o * K + c.
        mean = np.repeat(prediction.mean, k, axis=0)
        cov = np.moveaxis(prediction.component_cov, 2, 1).reshape(n_obs * k, n_t, 2, 2)
        heading = np.repeat(prediction.heading, k, axis=0)
        length, width = np.repeat(prediction.length, k), np.repeat(prediction.width, k)
    cp = collision_probability(
        candidates.x,
        candidates.y,
        candidates.yaw,
        ego_shape.length,
        ego_shape.width,
        mean,
        cov,
        heading,
        length,
        width,
        gate_sigmas=gate_sigmas,
        workers=workers,
    )
    if k == 1:
        return cp
    n = candidates.x.shape[0]
    per_component = cp.probability.reshape(n, n_obs, k, n_t)
    probability = np.einsum("nokt,otk->not", per_component, prediction.component_weight)
    return CollisionProbability(np.clip(probability, 0.0, 1.0), cp.mean_overlap[:, ::k])


def _holes(area: shapely.Geometry) -> shapely.Geometry | None:
    """The interior rings of the drivable area (obstacles inside the road) as polygons, or None."""
    parts = getattr(area, "geoms", (area,))
    rings = [shapely.Polygon(r) for p in parts for r in p.interiors]
    if not rings:
        return None
    holes = shapely.union_all(rings)
    shapely.prepare(holes)
    return holes


def assess_risk(
    candidates: Candidates,
    prediction: Prediction,
    ego_shape: Shape,
    ego_mass: float,
    environment: RoadEnvironment,
    config: RiskConfig,
    workers: Workers | None = None,
) -> RiskAssessment:
    """Collision probability, harm and risk of every candidate for every road user.

    Delta-v by ``config.delta_v_model``: paper Eq. 1 or the planar impulse model
    (``ethical_planner.impulse``), whose contact comes from the two footprints.
    ``workers`` lends its threads to large problems (a planner
    passes its own; None makes a fresh one for this call).
    """
    workers = Workers() if workers is None else workers
    n, n_t = candidates.x.shape
    k = prediction.n_obs
    # shapely releases the GIL: on large problems the road-edge test runs on a helper
    # thread beside the collision probability (on small ones the hand-over costs more).
    outside_job = None
    if k and n * n_t >= _OVERLAP_MIN_POSES:
        outside_job = workers.submit(
            lambda: outside_drivable_area(candidates, ego_shape, environment, config.road_edge_margin)
        )
    cp = prediction_collision_probability(candidates, prediction, ego_shape, config.gate_sigmas, workers)
    p = cp.probability
    harm_obs = np.zeros((n, k, n_t))
    harm_ego = np.zeros((n, k, n_t))
    risk_obs = np.zeros((n, k))
    risk_ego = np.zeros((n, k))
    # Triples with p > 0, in (traj, obs, t) order.
    flat = np.flatnonzero(p > 0.0)
    if flat.size:
        _harm_and_risk(
            candidates,
            prediction,
            ego_mass,
            config,
            p,
            flat,
            ego_shape,
            (harm_obs, harm_ego, risk_obs, risk_ego),
            workers,
        )
    peak_step = p.argmax(axis=2) if n_t else np.zeros((n, k), dtype=int)

    outside = (
        outside_drivable_area(candidates, ego_shape, environment, config.road_edge_margin)
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


#: Triples per harm evaluation: the temporaries of ``collision_harm`` then stay small and
#: are reused instead of page-faulting. With two threads (from _HARM_PARALLEL_MIN triples
#: on) the chunks are a quarter of the work each: numpy must run long loops between
#: Python statements for two threads to pay off (see collision_probability._CHUNK_THREADED).
_HARM_CHUNK = 16384
_HARM_PARALLEL_MIN = 100_000


def _harm_and_risk(
    candidates: Candidates,
    prediction: Prediction,
    ego_mass: float,
    config: RiskConfig,
    p: np.ndarray,
    flat: np.ndarray,
    ego_shape: Shape,
    out: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    workers: Workers,
) -> None:
    """Harm at the triples with p > 0 and the risks R = max_t p H (Eq. 3), in chunks.

    Args:
        candidates: the n candidates.
        prediction: the k road users.
        ego_mass: [kg].
        config: harm models.
        p: collision probabilities, shape (n, k, t).
        flat: flat indices of the triples with p > 0, ascending, shape (m,).
        ego_shape: the ego's footprint (used by the planar delta-v model).
        out: harm_obs, harm_ego (n, k, t) and risk_obs, risk_ego (n, k), zeros, written.
        workers: threads for large problems.
    """
    n_traj, k, n_t = p.shape
    harm_obs, harm_ego, risk_obs, risk_ego = out
    # Velocities per (traj, t) and (obs, t) once, then gathered: trigonometry on the
    # small tables instead of on every triple.
    ego_yaw = candidates.yaw.ravel()
    ego_table = np.stack(
        [
            candidates.x.ravel(),
            candidates.y.ravel(),
            ego_yaw,
            candidates.v.ravel() * np.cos(ego_yaw),
            candidates.v.ravel() * np.sin(ego_yaw),
        ]
    )
    obs_yaw = prediction.heading.ravel()
    obs_speed = prediction.speed.ravel()
    obs_table = np.stack(
        [
            prediction.mean[..., 0].ravel(),
            prediction.mean[..., 1].ravel(),
            obs_yaw,
            obs_speed * np.cos(obs_yaw),
            obs_speed * np.sin(obs_yaw),
        ]
    )
    obs_mass = prediction.mass
    obs_unprotected = prediction.vulnerable
    obs_round = np.array([t is RoadUserType.PEDESTRIAN for t in prediction.types], dtype=bool)
    model = HarmModel(config.harm_model)
    pedestrian_model = HarmModel(config.pedestrian_model)
    # Chunk boundaries at the start of a (traj, obs) pair, so that each chunk owns the
    # risks of its pairs: chunks then write disjoint parts of every output.
    size = _HARM_CHUNK
    if flat.size >= _HARM_PARALLEL_MIN and workers.threads > 1:
        size = max(size, -(-flat.size // 4))
    cuts = [0]
    while cuts[-1] + size < flat.size:
        pair_start = (flat[cuts[-1] + size] // n_t) * n_t
        cut = int(np.searchsorted(flat, pair_start))
        cuts.append(cut if cut > cuts[-1] else cuts[-1] + size)
    cuts.append(flat.size)
    p_flat = p.ravel()

    def run(part: tuple[int, int]) -> None:
        f = flat[part[0] : part[1]]
        pair, step = np.divmod(f, n_t)
        traj, obs = np.divmod(pair, k)
        ego = ego_table.take(traj * n_t + step, axis=1)
        obs_now = obs_table.take(obs * n_t + step, axis=1)
        result = collision_harm(
            ego_mass=ego_mass,
            ego_vel=ego[3:5].T,
            ego_pos=ego[0:2].T,
            ego_yaw=ego[2],
            obs_mass=obs_mass.take(obs),
            obs_vel=obs_now[3:5].T,
            obs_pos=obs_now[0:2].T,
            obs_yaw=obs_now[2],
            obs_unprotected=obs_unprotected.take(obs),
            model=model,
            pedestrian_model=pedestrian_model,
            delta_v_model=config.delta_v_model,
            restitution=config.restitution_law,
            impulse_ratio=config.impulse_ratio,
            obs_round=obs_round.take(obs),
            ego_shape=(ego_shape.length, ego_shape.width),
            obs_shape=(prediction.length.take(obs), prediction.width.take(obs)),
        )
        harm_obs.ravel()[f] = result.harm_obs
        harm_ego.ravel()[f] = result.harm_ego
        # p H is 0 where p = 0, so the maximum over the surviving steps of a pair equals
        # the maximum over all its steps (R >= 0).
        p_f = p_flat.take(f)
        starts = np.flatnonzero(np.diff(pair, prepend=-1))
        risk_obs.ravel()[pair[starts]] = np.maximum.reduceat(p_f * result.harm_obs, starts)
        risk_ego.ravel()[pair[starts]] = np.maximum.reduceat(p_f * result.harm_ego, starts)

    # Elementwise per triple and disjoint per chunk: any split gives the same numbers.
    workers.parallel_for(list(zip(cuts[:-1], cuts[1:], strict=True)), run)
