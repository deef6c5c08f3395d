"""Responsibility r_i of road users for potential collisions (paper Eq. 11).

Three sources, added and kept below 1 by ``ResponsibilityConfig``:

1. base: motorised road users bring risk into traffic in proportion to their mass,
   r_base = base_max (1 - exp(-m / base_mass_scale)); pedestrians and cyclists get 0;
2. traffic rules: if road user k, moving as predicted, is outside its legal
   reachable set at the potential collision (its ``LegalCorridor``: between full
   braking and accelerating up to its speed limit, within its lane, before a stop
   line), the collision arises from its violation and k is responsible;
3. rear-end: the follower of a rear-end collision is responsible.

The collision geometry is taken at the first step at which the collision probability
reaches half its peak (the onset of the potential collision).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ethical_planner.config import ResponsibilityConfig
from ethical_planner.environment import RoadEnvironment
from ethical_planner.geometry import wrap_angle_in_place
from ethical_planner.harm import impact_angles
from ethical_planner.prediction.base import Prediction
from ethical_planner.road_users import LegalCorridor, RoadUser, RoadUserType
from ethical_planner.sampling import Candidates

_FRONT = np.pi / 4
#: Slack of the legal-set test [m], so that rounding never makes a legal road user responsible.
_LEGAL_TOLERANCE = 0.1
_REAR = 3 * np.pi / 4

#: Legal speed [m/s] and lateral freedom [m] of road users without a given corridor.
_DEFAULT_VRU_CORRIDOR = {
    RoadUserType.PEDESTRIAN: (2.5, 1.5),
    RoadUserType.BICYCLE: (8.0, 1.0),
}


def default_corridor(user: RoadUser, environment: RoadEnvironment) -> LegalCorridor:
    """Legal corridor of a road user that the scene does not describe further.

    Vehicles may keep within their lane at the road's speed limit; pedestrians and
    cyclists get a walking or cycling speed and a small lateral freedom.
    """
    if user.legal is not None:
        return user.legal
    if user.type in _DEFAULT_VRU_CORRIDOR:
        speed, lateral = _DEFAULT_VRU_CORRIDOR[user.type]
        return LegalCorridor(speed_limit=speed, lateral_half_width=lateral)
    lateral = max(0.0, 0.5 * (environment.lane_width - user.shape.width)) + 0.3
    return LegalCorridor(speed_limit=environment.speed_limit, lateral_half_width=lateral)


@dataclass(frozen=True, slots=True, eq=False)
class LegalCorridors:
    """Legal corridors of all road users as arrays, shape (k,) each."""

    x0: np.ndarray
    y0: np.ndarray
    yaw0: np.ndarray
    v0: np.ndarray
    speed_limit: np.ndarray
    lateral_half_width: np.ndarray
    stop_distance: np.ndarray  # inf where there is no stop line
    max_acceleration: np.ndarray
    max_deceleration: np.ndarray

    @classmethod
    def of(cls, users: Sequence[RoadUser], environment: RoadEnvironment) -> LegalCorridors:
        """Collect the corridors of ``users`` (defaults from the road where not given)."""
        corridors = [default_corridor(u, environment) for u in users]

        def arr(values: list[float]) -> np.ndarray:
            return np.asarray(values, dtype=float).reshape(len(users))

        return cls(
            x0=arr([u.state.x for u in users]),
            y0=arr([u.state.y for u in users]),
            yaw0=arr([u.state.yaw for u in users]),
            v0=arr([abs(u.state.v) for u in users]),
            speed_limit=arr([c.speed_limit for c in corridors]),
            lateral_half_width=arr([c.lateral_half_width for c in corridors]),
            stop_distance=arr([np.inf if c.stop_distance is None else c.stop_distance for c in corridors]),
            max_acceleration=arr([c.max_acceleration for c in corridors]),
            max_deceleration=arr([c.max_deceleration for c in corridors]),
        )

    def longitudinal_bounds(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Legal travel along the initial heading after time ``t`` [s] (broadcast with (k,)).

        Returns:
            (lowest, highest) distance [m]: full braking, and accelerating up to the
            speed limit (a road user already above the limit may legally travel only
            at the limit), capped by a stop line.
        """
        v0, limit = self.v0, self.speed_limit
        b, acc = self.max_deceleration, np.maximum(self.max_acceleration, 1e-9)
        t_stop = v0 / b
        lowest = np.where(t < t_stop, v0 * t - 0.5 * b * t**2, v0**2 / (2 * b))
        v_start = np.minimum(v0, limit)
        t_reach = (limit - v_start) / acc
        highest = np.where(
            t < t_reach,
            v_start * t + 0.5 * acc * t**2,
            v_start * t_reach + 0.5 * acc * t_reach**2 + limit * (t - t_reach),
        )
        return lowest, np.minimum(highest, self.stop_distance)


def collision_onset(probability: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Highest collision probability and the first step where p reaches half of it.

    Args:
        probability: p over the steps, shape (..., t).

    Returns:
        (peak, onset), shape (...) each; onset is 0 where p is 0 throughout.
    """
    peak = probability.max(axis=-1)
    return peak, np.argmax(probability >= 0.5 * peak[..., None], axis=-1)


def base_responsibility(mass: np.ndarray, motorised: np.ndarray, config: ResponsibilityConfig) -> np.ndarray:
    """r_base = base_max (1 - exp(-m / scale)) for motorised road users, else 0."""
    base = config.base_max * (1.0 - np.exp(-np.asarray(mass) / config.base_mass_scale))
    return np.where(motorised, base, 0.0)


def responsibilities(
    candidates: Candidates,
    rows: np.ndarray,
    peak: np.ndarray,
    onset: np.ndarray,
    prediction: Prediction,
    corridors: LegalCorridors,
    ego_mass: float,
    config: ResponsibilityConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """Responsibility of each road user and of the ego for each potential collision.

    The geometry of a potential collision is read at its onset: the first step at which
    the collision probability reaches half its peak. (At the peak itself the predicted
    means may already overlap deeply and the centres have passed each other: a rear-end
    would look like the leader running into the follower.)

    Args:
        candidates: the cycle's candidates.
        rows: the m candidates to assess, indices into ``candidates``.
        peak: highest collision probability of each pair, shape (m, k).
        onset: first step at which p reaches half its peak, shape (m, k).
        prediction: k road users.
        corridors: their legal corridors.
        ego_mass: [kg].
        config: magnitudes.

    Returns:
        (r_obs, r_ego), shape (m, k) each: responsibility of road user k for the risk
        it runs, and of the ego for the risk it runs in a collision with k.
    """
    n, k = peak.shape
    base_obs = np.broadcast_to(base_responsibility(prediction.mass, prediction.motorised, config), (n, k))
    base_ego = np.full((n, k), float(base_responsibility(np.array(ego_mass), np.array(True), config)))
    r_obs, r_ego = base_obs, base_ego
    if k == 0 or n == 0:
        return r_obs, r_ego
    n_t = candidates.t.size
    step = onset
    # Rows of the (traj, t) and (obs, t) tables at the onset step, gathered flat.
    ego_row = np.asarray(rows)[:, None] * n_t + step
    obs_row = np.arange(k)[None, :] * n_t + step
    ex, ey = candidates.x.ravel()[ego_row], candidates.y.ravel()[ego_row]
    eyaw = candidates.yaw.ravel()[ego_row]
    ox = prediction.mean[..., 0].ravel()[obs_row]
    oy = prediction.mean[..., 1].ravel()[obs_row]
    oyaw = prediction.heading.ravel()[obs_row]

    # Rear-end: same direction of travel, one body's front meets the other's rear.
    ego_angle, obs_angle = impact_angles(ex, ey, eyaw, ox, oy, oyaw)
    same_direction = np.abs(wrap_angle_in_place(eyaw - oyaw)) < _FRONT
    ego_follows = same_direction & (np.abs(ego_angle) < _FRONT) & (np.abs(obs_angle) > _REAR)
    obs_follows = same_direction & (np.abs(obs_angle) < _FRONT) & (np.abs(ego_angle) > _REAR)
    r_ego = r_ego + np.where(ego_follows, config.rear_end, 0.0)
    r_obs = r_obs + np.where(obs_follows, config.rear_end, 0.0)

    # Traffic rules: does k's predicted motion up to the potential collision leave its
    # legal reachable set? Then the collision arises from k's violation (a jaywalker
    # entering the road, a red-light runner past the stop line, a speeder).
    c0, s0 = np.cos(corridors.yaw0), np.sin(corridors.yaw0)
    dx, dy = ox - corridors.x0, oy - corridors.y0
    lon = dx * c0 + dy * s0
    lat = -dx * s0 + dy * c0
    # The bounds depend on (t, obs) only: an (n_t, k) table, gathered at the peak steps.
    lowest, highest = corridors.longitudinal_bounds(candidates.t[:, None])
    step_obs = step * k + np.arange(k)[None, :]
    lowest = np.broadcast_to(lowest, (n_t, k)).ravel()[step_obs]
    highest = np.broadcast_to(highest, (n_t, k)).ravel()[step_obs]
    legal = (
        (lon <= highest + _LEGAL_TOLERANCE)
        & (lon >= lowest - _LEGAL_TOLERANCE)
        & (np.abs(lat) <= corridors.lateral_half_width + _LEGAL_TOLERANCE)
    )
    r_obs = r_obs + np.where(legal, 0.0, config.rule_violation)
    # Without any chance of collision there is nothing to be responsible for beyond the base.
    possible = peak > 0.0
    r_obs = np.where(possible, r_obs, base_obs)
    r_ego = np.where(possible, r_ego, base_ego)
    return r_obs, r_ego
