"""Validity levels of candidates (SPEC section 4), vectorised."""

from __future__ import annotations

from enum import IntEnum

import numpy as np

from ethical_planner.config import VehicleConfig
from ethical_planner.sampling import Candidates

#: A small negative Frenet speed tolerated before a candidate counts as reversing [m/s].
_REVERSE_TOLERANCE = 0.05
#: Rounding slack of the acceleration limits [m/s^2] (a plan braking at exactly the
#: emergency deceleration is valid).
_ACCELERATION_TOLERANCE = 1e-6


class Validity(IntEnum):
    """Validity level; the planner chooses from the highest level available.

    ``BREAKS_TRAFFIC_RULE`` (``ethical_planner.traffic_rules``): the candidate crosses a
    binding stop line; a candidate's level is the lowest that applies, so a rule
    breaker that is also above R_max is level 3. It ranks above level 3: a plan within
    R_max that runs a red light is chosen over plans that keep the rule at an
    unacceptable risk (safety before the rule), and below every valid plan.
    """

    PHYSICALLY_INVALID = 0
    COLLISION = 1
    LEAVES_ROAD = 2
    ABOVE_MAX_RISK = 3
    BREAKS_TRAFFIC_RULE = 4
    VALID = 10


#: Not a validity level: the mark of a candidate whose risk the planner did not evaluate,
#: because its Eq. 5 cost cannot be below the chosen plan's even at zero risk
#: (``Planner._branch_and_bound``). Its level is valid, above R_max or breaks a traffic
#: rule; which is unknown.
UNASSESSED = -1

#: Reasons of validity level 0, in the order of ``physically_invalid``.
LIMITS = ("speed", "acceleration", "curvature", "lateral_acceleration", "friction")


def physically_invalid(candidates: Candidates, vehicle: VehicleConfig) -> dict[str, np.ndarray]:
    """Which limit each candidate breaks, shape (n,) per reason (``LIMITS``).

    - speed: above v_max, or reversing;
    - acceleration: above a_max or braking harder than the emergency deceleration;
    - curvature: beyond the steering limit tan(delta_max) / wheelbase (kinematic bicycle);
    - lateral_acceleration: v^2 |kappa| above the tyres' lateral limit;
    - friction: sqrt(a^2 + (v^2 kappa)^2) outside the friction circle.

    The three curvature-based limits are checked where the speed exceeds
    ``vehicle.curvature_check_speed`` (the heading of a standing plan is ill-defined).
    The reference checks speed twice and never acceleration: all are checked here.

    The first sample (t = 0) is the present state, which no candidate can change: it is
    not checked. A measured acceleration a hair beyond the emergency deceleration (the
    ego braking at its limit, seen through the physics) would otherwise make every
    candidate invalid, and the planner would fall back to whatever level 1 offers.
    """
    v, a, kappa = candidates.v[:, 1:], candidates.a[:, 1:], candidates.kappa[:, 1:]
    s_dot = candidates.s_dot[:, 1:]
    moving = v > vehicle.curvature_check_speed
    lateral = np.square(v) * np.abs(kappa)
    slack = _ACCELERATION_TOLERANCE
    return {
        "speed": np.any(v > vehicle.v_max, axis=1) | np.any(s_dot < -_REVERSE_TOLERANCE, axis=1),
        "acceleration": np.any(
            (a > vehicle.a_max + slack) | (a < -vehicle.emergency_deceleration - slack), axis=1
        ),
        "curvature": np.any(moving & (np.abs(kappa) > vehicle.steering_curvature), axis=1),
        "lateral_acceleration": np.any(moving & (lateral > vehicle.max_lateral_acceleration), axis=1),
        "friction": np.any(moving & (np.hypot(a, lateral) > vehicle.friction_acceleration + slack), axis=1),
    }


def validity_levels(
    invalid_reasons: dict[str, np.ndarray],
    mean_overlap: np.ndarray,
    outside_road: np.ndarray,
    risk_obs: np.ndarray,
    ego_combined: np.ndarray,
    max_acceptable_risk: float,
) -> np.ndarray:
    """Validity level of every candidate, shape (n,).

    Args:
        invalid_reasons: from ``physically_invalid``.
        mean_overlap: (n, k, t) collision with a predicted mean occupancy.
        outside_road: (n, t) footprint outside the drivable area.
        risk_obs: (n, k) R_k.
        ego_combined: (n,) R_ego.
        max_acceptable_risk: R_max.
    """
    n = outside_road.shape[0]
    level = np.full(n, int(Validity.VALID))
    too_risky = (ego_combined > max_acceptable_risk) | np.any(risk_obs > max_acceptable_risk, axis=1)
    level[too_risky] = Validity.ABOVE_MAX_RISK
    level[np.any(outside_road, axis=1)] = Validity.LEAVES_ROAD
    level[np.any(mean_overlap, axis=(1, 2))] = Validity.COLLISION
    invalid = np.zeros(n, dtype=bool)
    for broken in invalid_reasons.values():
        invalid |= broken
    level[invalid] = Validity.PHYSICALLY_INVALID
    return level
