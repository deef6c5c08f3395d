"""Terminal safety: a plan must end in a state the ego can get out of (vectorised).

A sampling planner judges a plan over its horizon only. A plan that ends in the
oncoming lane with an oncoming vehicle just beyond the horizon is collision-free over
the horizon, yet the state it ends in may be an inevitable collision state (Fraichard
and Asama 2004): from there no manoeuvre avoids the vehicle. Fail-safe planning (Pek
and Althoff 2018, "Computationally efficient fail-safe trajectory planning for
self-driving vehicles using convex optimization"; Magdici and Althoff 2016, "Fail-safe
motion planning of autonomous vehicles") requires every plan to end where a safe
manoeuvre still exists. Here that manoeuvre is the return to the ego's side of the
lane boundary, checked against the oncoming traffic's predicted arrival beyond the
horizon (the overtaking rule of thumb "the way back must be clear before the oncoming
car gets there"):

- an oncoming road user is one moving against the reference path (heading within
  ``oncoming_angle`` of the path's opposite direction) faster than ``min_speed``; its lane is the lane whose
  centre is nearest to its predicted position at the end of the horizon;
- a plan ends *in its way* if the ego's footprint at the end overlaps that lane by
  ``intrusion`` [m] (the ego's own lane, offset 0, is never in anyone's way: there the
  prediction and the risk decide);
- getting out takes ``t_return = sqrt(10 / sqrt(3) * intrusion / a_return)``, a
  rest-to-rest quintic lateral move whose peak lateral acceleration is ``a_return``
  (the shape of the planner's own lateral moves);
- the oncoming road user reaches the ego's end position after
  ``tau = gap / (v_ego,s + v_k,along)``, with ``gap`` the free distance along the path
  between the two footprints at the end of the horizon, both keeping their speeds;
- the plan is *terminally unsafe* if ``tau < t_return + time_buffer``, or if the road
  user is already beside the ego's end position (gap < 0, not yet past).

A terminally unsafe plan is a predicted collision, beyond the horizon: validity level 1.
The check needs no integral and costs one Frenet projection per road user.

The same idea for static obstacles inside the road (debris, holes of the drivable
area): a plan must end where the ego can still stop ``standstill_distance`` before the
obstacle, braking at ``stopping_deceleration`` (``crowds_static_obstacle``). An ego that
stops right behind debris cannot steer around it without reversing: the standstill
distance is the arc length a quintic lateral move of one lane width needs at the
steering limit, sqrt(10 / sqrt(3) w / kappa_max) (9.0 m for 3.5 m and 0.249 1/m). Such a
plan comes too close to the edge of the drivable area: validity level 2.

Limits: the return is checked against oncoming traffic only (a plan ending behind a
stopped vehicle or at a wall is judged by the risk and the road edge); a road user
standing still in the oncoming lane is not taken to start; the return path itself
(a walker beside the ego's lane) is not checked.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from ethical_planner.config import TerminalConfig
from ethical_planner.environment import RoadEnvironment
from ethical_planner.geometry import rectangle_corners, wrap_angle
from ethical_planner.prediction import Prediction
from ethical_planner.risk import static_obstacles
from ethical_planner.road_users import Shape
from ethical_planner.sampling import Candidates

#: Peak lateral acceleration of a rest-to-rest quintic move of distance D in time T is
#: QUINTIC_PEAK D / T^2 (10 / sqrt(3)).
QUINTIC_PEAK = 10.0 / math.sqrt(3.0)


def return_time(intrusion: np.ndarray, lateral_acceleration: float) -> np.ndarray:
    """Duration [s] of a rest-to-rest quintic lateral move of ``intrusion`` [m].

    Its peak lateral acceleration is ``lateral_acceleration`` [m/s^2].
    """
    return np.sqrt(QUINTIC_PEAK * np.maximum(intrusion, 0.0) / lateral_acceleration)


def terminally_unsafe(
    candidates: Candidates,
    prediction: Prediction,
    environment: RoadEnvironment,
    ego_shape: Shape,
    config: TerminalConfig,
) -> np.ndarray:
    """Which candidates end in an oncoming road user's lane too late to get out, shape (n,).

    See the module docstring for the rule.

    Args:
        candidates: the cycle's candidates (their last sample is the end state).
        prediction: the other road users' prediction on the candidates' time grid.
        environment: the road (reference path, lane offsets and width).
        ego_shape: the ego's footprint [m].
        config: the terminal condition's parameters.
    """
    n = candidates.n_traj
    unsafe = np.zeros(n, dtype=bool)
    if not config.enabled or prediction.n_obs == 0:
        return unsafe
    path = environment.reference_path
    end = prediction.mean[:, -1]
    s_k, d_k = path.to_frenet(end[:, 0], end[:, 1])
    theta = path.heading(s_k)
    along = prediction.speed[:, -1] * np.cos(wrap_angle(prediction.heading[:, -1] - theta))
    oncoming = (along < -config.min_speed) & (
        np.cos(wrap_angle(prediction.heading[:, -1] - theta)) < -math.cos(config.oncoming_angle)
    )
    offsets = np.asarray(environment.lane_offsets)
    centre = offsets[np.argmin(np.abs(d_k[:, None] - offsets[None, :]), axis=1)]
    oncoming &= centre != 0.0
    if not oncoming.any():
        return unsafe
    users = np.flatnonzero(oncoming)
    half_lane = 0.5 * environment.lane_width
    low, high = centre[users] - half_lane, centre[users] + half_lane  # (k,)
    d_end = candidates.d[:, -1][:, None]  # (n, 1)
    half_width = 0.5 * ego_shape.width
    # Distance the ego must move towards its own lane to leave the user's lane, (n, k).
    intrusion = np.where(centre[users] > 0.0, d_end + half_width - low, high - (d_end - half_width))
    inside = (intrusion > 0.0) & (d_end + half_width > low) & (d_end - half_width < high)
    gap = s_k[users] - candidates.s[:, -1][:, None] - 0.5 * (ego_shape.length + prediction.length[users])
    past = gap < -(ego_shape.length + prediction.length[users])
    closing = np.maximum(candidates.s_dot[:, -1], 0.0)[:, None] - along[users]
    needed = return_time(intrusion, config.return_lateral_acceleration) + config.time_buffer
    with np.errstate(divide="ignore", invalid="ignore"):
        too_late = (gap <= 0.0) | (gap < needed * closing)
    unsafe = np.any(inside & ~past & too_late, axis=1)
    return unsafe


def standstill_distance(lateral_shift: float, max_curvature: float) -> float:
    """Arc length [m] a quintic lateral move of ``lateral_shift`` [m] needs at ``max_curvature`` [1/m].

    The curvature of a lateral quintic over arc length S peaks at about
    10 / sqrt(3) D / S^2 (small slopes), so S = sqrt(10 / sqrt(3) D / kappa_max).
    """
    return math.sqrt(QUINTIC_PEAK * lateral_shift / max_curvature)


def crowds_static_obstacle(
    candidates: Candidates,
    rows: np.ndarray,
    environment: RoadEnvironment,
    ego_shape: Shape,
    config: TerminalConfig,
) -> np.ndarray:
    """Which candidates of ``rows`` end unable to stop short of a static obstacle, shape (m,).

    The end footprint is stretched forward by the standstill distance plus the stopping
    distance v^2 / (2 b) at the end speed; it must not touch an obstacle of the road.

    Args:
        candidates: the cycle's candidates (their last sample is the end state).
        rows: the candidates to test.
        environment: the road; its drivable area's holes are the static obstacles.
        ego_shape: the ego's footprint [m].
        config: ``standstill_distance`` [m], ``stopping_deceleration`` [m/s^2].
    """
    rows = np.asarray(rows, dtype=int)
    out = np.zeros(rows.size, dtype=bool)
    obstacles = static_obstacles(environment)
    if not config.enabled or obstacles is None or not rows.size:
        return out
    x, y, yaw, v = (getattr(candidates, name)[rows, -1] for name in ("x", "y", "yaw", "v"))
    reach = config.standstill_distance + np.square(v) / (2.0 * config.stopping_deceleration)
    # The footprint from its rear to ``reach`` beyond its front.
    shift = 0.5 * reach
    cx, cy = rectangle_corners(
        x + shift * np.cos(yaw), y + shift * np.sin(yaw), yaw, ego_shape.length + reach, ego_shape.width
    )
    ring = np.stack([cx, cy], axis=-1)
    boxes = shapely.polygons(np.concatenate([ring, ring[:, :1]], axis=1))
    return shapely.intersects(obstacles, boxes)


__all__ = [
    "QUINTIC_PEAK",
    "crowds_static_obstacle",
    "return_time",
    "standstill_distance",
    "terminally_unsafe",
]
