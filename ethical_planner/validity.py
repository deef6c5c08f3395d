"""Validity levels of candidates (SPEC section 4), vectorised."""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np

from ethical_planner.config import VehicleConfig
from ethical_planner.jit import kernel
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
#: rule; which is unknown. At a fallback level (``Planner._fallback_branch_and_bound``):
#: a candidate at that level whose Eq. 6 cost is bounded from below above the chosen
#: plan's; its risk is unknown, never 0.
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
    slack = _ACCELERATION_TOLERANCE
    limits = np.array(
        [
            vehicle.v_max,
            -_REVERSE_TOLERANCE,
            vehicle.a_max + slack,
            -vehicle.emergency_deceleration - slack,
            vehicle.curvature_check_speed,
            vehicle.steering_curvature,
            vehicle.max_lateral_acceleration,
            vehicle.friction_acceleration + slack,
        ]
    )
    broken = np.zeros((len(LIMITS), candidates.v.shape[0]), dtype=np.bool_)
    _limits_broken(
        *(np.ascontiguousarray(getattr(candidates, name)) for name in ("v", "a", "kappa", "s_dot")),
        limits,
        broken,
    )
    return dict(zip(LIMITS, broken, strict=True))


#: Below this fraction of the friction circle's radius, |a| + v^2 |kappa| (rounded)
#: proves the point inside without ``hypot`` (whose error is below 1 ulp, 2^-52).
_FRICTION_SURE = 1.0 - 2.0**-40


@kernel
def _limits_broken(
    v: np.ndarray, a: np.ndarray, kappa: np.ndarray, s_dot: np.ndarray, limits: np.ndarray, out: np.ndarray
) -> None:
    """Kernel of ``physically_invalid``: out (5, n) per ``LIMITS``, from step 1 on.

    ``limits``: v_max, the reversing speed, the acceleration's upper and lower limit,
    the curvature check's speed, the steering curvature, the lateral acceleration
    limit and the friction circle's radius (the last three with their slack where it
    applies). The tests are those of the numpy expressions they replace: v^2 |kappa| as
    ``np.square(v) * np.abs(kappa)`` and the friction circle by ``hypot``.
    """
    v_max, reverse, a_hi, a_lo, check_speed, steering, lateral_max, friction = limits
    n, n_t = v.shape
    for row in range(n):
        for step in range(1, n_t):
            speed, acc, curv = v[row, step], a[row, step], kappa[row, step]
            if speed > v_max or s_dot[row, step] < reverse:
                out[0, row] = True
            if acc > a_hi or acc < a_lo:
                out[1, row] = True
            if speed > check_speed:
                lateral = (speed * speed) * abs(curv)
                if abs(curv) > steering:
                    out[2, row] = True
                if lateral > lateral_max:
                    out[3, row] = True
                # hypot(acc, lateral) <= |acc| + lateral: far enough below the circle's
                # radius (more than hypot's and the sum's rounding), or already outside
                # it, the row's answer stands without the call.
                if out[4, row] or abs(acc) + lateral <= friction * _FRICTION_SURE:
                    continue
                if math.hypot(acc, lateral) > friction:
                    out[4, row] = True


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
