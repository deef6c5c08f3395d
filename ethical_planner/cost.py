"""Ethical cost of candidates (paper Eqs. 5-11) and comfort and mobility terms."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ethical_planner.config import CostWeights
from ethical_planner.validity import Validity


@dataclass(frozen=True, slots=True, eq=False)
class CostBreakdown:
    """Every term of the cost of every candidate, shape (n,) each.

    Attributes:
        bayes: J_B (Eq. 8). equality: J_E (Eq. 9). maximin: J_M (Eq. 10).
        responsibility: J_R (Eq. 11). ego_risk: R_ego (selfish term).
        risk: J_risk (Eq. 7). comfort, mobility: their costs. total: J_total (Eqs. 5, 6).
    """

    bayes: np.ndarray
    equality: np.ndarray
    maximin: np.ndarray
    responsibility: np.ndarray
    ego_risk: np.ndarray
    risk: np.ndarray
    comfort: np.ndarray
    mobility: np.ndarray
    total: np.ndarray

    def row(self, index: int) -> dict[str, float]:
        """All terms of one candidate."""
        return {name: float(getattr(self, name)[index]) for name in self.__slots__}


def bayes(risks: np.ndarray) -> np.ndarray:
    """J_B = sum(S_R) / |S_R| (Eq. 8); ``risks`` (n, m), 0 for m = 0."""
    return risks.mean(axis=1) if risks.shape[1] else np.zeros(risks.shape[0])


def equality(risks: np.ndarray) -> np.ndarray:
    """J_E = sum_{i<j} |R_i - R_j| / (m (m - 1) / 2) (Eq. 9), in O(m log m).

    For ascending values x_(0..m-1): sum_{i<j} |x_i - x_j| = sum_i (2 i - m + 1) x_(i).
    """
    n, m = risks.shape
    if m < 2:
        return np.zeros(n)
    ordered = np.sort(risks, axis=1)
    coefficients = 2.0 * np.arange(m) - m + 1.0
    return (ordered @ coefficients) / (m * (m - 1) / 2.0)


def maximin(harms: np.ndarray, counted: np.ndarray, gamma: float) -> np.ndarray:
    """J_M = (max harm over entries with non-negligible collision probability)^gamma (Eq. 10).

    Args:
        harms: (n, m) harm of each potential collision.
        counted: (n, m) True where its collision probability exceeds epsilon (the
            reference counts the opposite set, against its own comment).
        gamma: discount exponent >= 1.
    """
    worst = np.where(counted, harms, 0.0).max(axis=1, initial=0.0)
    return worst**gamma


def responsibility(risks: np.ndarray, r: np.ndarray) -> np.ndarray:
    """J_R = sum(r_i R_i) / |S_R| (Eq. 11), normalised like J_B.

    With the same normalisation, w_B (J_B - J_R) = w_B / |S_R| sum (1 - r_i) R_i >= 0
    for r_i < 1: responsibility lowers the weight of a responsible road user's risk
    but never rewards raising it.
    """
    return (r * risks).mean(axis=1) if risks.shape[1] else np.zeros(risks.shape[0])


def total_cost(
    risks: np.ndarray,
    r: np.ndarray,
    harms: np.ndarray,
    counted: np.ndarray,
    ego_combined: np.ndarray,
    jerk_lon: np.ndarray,
    jerk_lat: np.ndarray,
    speed_deviation: np.ndarray,
    path_deviation: np.ndarray,
    levels: np.ndarray,
    weights: CostWeights,
) -> CostBreakdown:
    """Cost of every candidate.

    Args:
        risks: (n, m) the set S_R: R_k for every road user, R_ego,k for every
            partner, and the ego's boundary risk.
        r: (n, m) responsibility of each entry.
        harms: (n, m) harm of each entry.
        counted: (n, m) whether it counts for maximin.
        ego_combined: (n,) R_ego (Eq. 4).
        jerk_lon: (n,) integrated squared longitudinal jerk [m^2/s^5].
        jerk_lat: (n,) integrated squared lateral jerk [m^2/s^5].
        speed_deviation: (n,) mean |v - v_desired| [m/s].
        path_deviation: (n,) mean |d| from the reference path [m].
        levels: (n,) validity levels.
        weights: the weights.
    """
    j_b = bayes(risks)
    j_e = equality(risks)
    j_m = maximin(harms, counted, weights.maximin_gamma)
    j_r = responsibility(risks, r)
    j_risk = (
        weights.bayes * j_b
        + weights.equality * j_e
        + weights.maximin * j_m
        - weights.responsibility * weights.bayes * j_r
        + weights.ego_risk * ego_combined
    )
    comfort = weights.jerk_lon * jerk_lon + weights.jerk_lat * jerk_lat
    mobility = weights.speed * speed_deviation + weights.path_distance * path_deviation
    valid = levels == Validity.VALID
    total = np.where(valid, weights.risk * j_risk + comfort + mobility, j_risk)
    return CostBreakdown(j_b, j_e, j_m, j_r, ego_combined, j_risk, comfort, mobility, total)
