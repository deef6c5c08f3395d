"""Validity levels of candidates (SPEC section 4), vectorised."""

from __future__ import annotations

from enum import IntEnum

import numpy as np

from ethical_planner.config import VehicleLimits
from ethical_planner.sampling import Candidates

#: A small negative Frenet speed tolerated before a candidate counts as reversing [m/s].
_REVERSE_TOLERANCE = 0.05


class Validity(IntEnum):
    """Validity level; the planner chooses from the highest level available."""

    PHYSICALLY_INVALID = 0
    COLLISION = 1
    LEAVES_ROAD = 2
    ABOVE_MAX_RISK = 3
    VALID = 10


def physically_invalid(candidates: Candidates, limits: VehicleLimits) -> dict[str, np.ndarray]:
    """Which limit each candidate breaks, shape (n,) per reason.

    Speed, longitudinal acceleration and curvature are all checked (the reference
    checks speed twice and never acceleration). Curvature is checked only above
    ``limits.kappa_check_speed``, since it is ill-defined at standstill.
    """
    return {
        "speed": np.any(candidates.v > limits.v_max, axis=1)
        | np.any(candidates.s_dot < -_REVERSE_TOLERANCE, axis=1),
        "acceleration": np.any((candidates.a > limits.a_max) | (candidates.a < limits.a_min), axis=1),
        "curvature": np.any(
            (np.abs(candidates.kappa) > limits.kappa_max) & (candidates.v > limits.kappa_check_speed),
            axis=1,
        ),
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
