"""Ethical cost of candidates (paper Eqs. 5-11) and comfort and mobility terms."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ethical_planner.config import CostWeights, PathReference
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


def risk_set(
    risk_obs: np.ndarray, risk_ego: np.ndarray, boundary_risk: np.ndarray, leaves_road: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The set S_R of every candidate and which of its entries exist.

    S_R holds R_k for every road user and R_ego,k for the ego with every partner: 2k
    entries (paper Eqs. 8-9, as the reference does). A candidate that leaves the road
    has one more potential collision, the ego's with the road edge: its risk is an
    entry of the ego's in S_R for that candidate only. For a candidate on the road no
    such entry exists (an entry of 0 would turn J_E = |R_k - R_ego,k| into
    2/3 max(R_k, R_ego,k) with one road user).

    Args:
        risk_obs: (n, k) R_k. risk_ego: (n, k) R_ego,k.
        boundary_risk: (n,) the ego's risk at the road edge (0 on the road).
        leaves_road: (n,) True where the candidate leaves the drivable area.

    Returns:
        (risks (n, 2k + 1), present (n, 2k + 1)): the last column is the road edge.
    """
    n, k = risk_obs.shape
    risks = np.concatenate([risk_obs, risk_ego, boundary_risk[:, None]], axis=1)
    present = np.concatenate([np.ones((n, 2 * k), dtype=bool), leaves_road[:, None]], axis=1)
    return risks, present


def _present(risks: np.ndarray, present: np.ndarray | None) -> np.ndarray:
    return np.ones(risks.shape, dtype=bool) if present is None else np.asarray(present, dtype=bool)


def bayes(risks: np.ndarray, present: np.ndarray | None = None) -> np.ndarray:
    """J_B = sum(S_R) / |S_R| (Eq. 8), 0 for an empty set.

    Args:
        risks: (n, m) candidate risks.
        present: (n, m) which entries belong to each candidate's S_R (default all).
    """
    mask = _present(risks, present)
    count = mask.sum(axis=1)
    return np.where(mask, risks, 0.0).sum(axis=1) / np.maximum(count, 1)


def equality(risks: np.ndarray, present: np.ndarray | None = None) -> np.ndarray:
    """J_E = sum_{i<j} |R_i - R_j| / (m (m - 1) / 2) (Eq. 9) in O(m log m), 0 for m < 2.

    For ascending values x_(0..m-1): sum_{i<j} |x_i - x_j| = sum_i (2 i - m + 1) x_(i).

    Args:
        risks: (n, m) candidate risks.
        present: (n, m) which entries belong to each candidate's S_R (default all);
            m is counted per candidate.
    """
    mask = _present(risks, present)
    n, width = risks.shape
    if width < 2:
        return np.zeros(n)
    m = mask.sum(axis=1, keepdims=True)
    ordered = np.sort(np.where(mask, risks, np.inf), axis=1)  # absent entries last
    rank = np.arange(width)[None, :]
    coefficients = np.where(rank < m, 2.0 * rank - m + 1.0, 0.0)
    total = (np.where(rank < m, ordered, 0.0) * coefficients).sum(axis=1)
    # Sum of |differences| >= 0; the rank form can round to about -1e-20 for nearly equal
    # risks, and the planner's branch and bound relies on every risk term being >= 0.
    total = np.maximum(total, 0.0)
    pairs = (m[:, 0] * (m[:, 0] - 1)) / 2.0
    return np.where(pairs > 0, total / np.maximum(pairs, 1.0), 0.0)


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


def responsibility(risks: np.ndarray, r: np.ndarray, present: np.ndarray | None = None) -> np.ndarray:
    """J_R = sum(r_i R_i) / |S_R| (Eq. 11), normalised like J_B.

    With the same normalisation, w_B (J_B - J_R) = w_B / |S_R| sum (1 - r_i) R_i >= 0
    for r_i < 1: responsibility lowers the weight of a responsible road user's risk
    but never rewards raising it.
    """
    return bayes(r * risks, present)


#: Lanes of the lane grid continued beyond the road's outer lanes (see path_deviation).
_VIRTUAL_LANES = 3


def path_deviation(
    d: np.ndarray, lane_offsets: tuple[float, ...], lane_width: float, reference: PathReference
) -> tuple[np.ndarray, np.ndarray]:
    """Lateral deviation of candidates for the mobility term.

    With ``LANES`` a candidate is measured at every step against the centre of the lane
    it is in (the nearest lane centre of the environment; beyond the outer lanes the
    lane grid continues at ``lane_width``, so a shoulder or a parking strip counts as
    another lane), so a candidate that changes lanes pays for the transition, not for
    the lane it ends in; the second output is the mean number of lanes between that
    lane and the route's (the lane centre nearest the reference path), for the lane
    preference. With ``ROUTE`` the reference
    is the reference path itself (d = 0; the reference implementation) and no lane is
    counted.

    Args:
        d: lateral offsets from the reference path [m], shape (n, n_t).
        lane_offsets: lane centres' offsets from the reference path [m].
        lane_width: [m].
        reference: what to measure against.

    Returns:
        (mean |d - lane centre| [m], mean lanes away from the route's lane), (n,) each.
    """
    n = d.shape[0]
    if reference is PathReference.ROUTE or not lane_offsets:
        return np.abs(d).mean(axis=1), np.zeros(n)
    centre, route_centre = _nearest_lane_centre(d, lane_offsets, lane_width)
    lanes_away = np.abs(centre - route_centre) / lane_width
    return np.abs(d - centre).mean(axis=1), lanes_away.mean(axis=1)


def _nearest_lane_centre(
    d: np.ndarray, lane_offsets: tuple[float, ...], lane_width: float
) -> tuple[np.ndarray, float]:
    """Centre offset [m] of the lane each (candidate, step) is in, (n, n_t), and the route lane's.

    The road's lane centres, continued at ``lane_width`` for ``_VIRTUAL_LANES`` beyond
    the outer lanes (a shoulder, a parking strip count as further lanes); the route's
    lane is the centre nearest the reference path.
    """
    road = np.sort(np.asarray(lane_offsets, dtype=float))
    route_centre = float(road[np.abs(road).argmin()])
    # Beyond the outer lanes (shoulder, parking strip, kerb) the lane grid goes on: being
    # there counts as being in another lane, not as a small offset from the outer one.
    beyond = lane_width * np.arange(1, _VIRTUAL_LANES + 1)
    centres = np.concatenate([road[0] - beyond[::-1], road, road[-1] + beyond])
    # Nearest lane centre of every (candidate, step): between midpoints of sorted centres.
    lane = np.searchsorted(0.5 * (centres[1:] + centres[:-1]), d)
    return centres[lane], route_centre


def oncoming_lanes(
    d: np.ndarray,
    lane_offsets: tuple[float, ...],
    lane_width: float,
    centre_line: float | None,
    reference: PathReference,
) -> np.ndarray:
    """Mean number of lanes across the centre line, of oncoming traffic, per candidate, (n,).

    The lane each (candidate, step) is in (as ``path_deviation``), counted from the
    centre line: 0 in a lane of the ego's direction (or on its shoulder), 1 in the first
    oncoming lane, 2 in the next. It prices driving on the wrong side beyond what any
    other lane costs (``CostWeights.oncoming_lane``). Zero without a centre line (one-way
    roads, roads without markings) and with the ``ROUTE`` reference.

    Args:
        d: lateral offsets from the reference path [m], shape (n, n_t).
        lane_offsets: lane centres' offsets from the reference path [m].
        lane_width: [m].
        centre_line: offset of the line between the ego's and the oncoming lanes
            (``RoadEnvironment.centre_line``) [m], or None.
        reference: what the path term measures against.
    """
    n = d.shape[0]
    if centre_line is None or reference is PathReference.ROUTE or not lane_offsets:
        return np.zeros(n)
    centre, _ = _nearest_lane_centre(d, lane_offsets, lane_width)
    across = np.where(centre > centre_line, np.floor((centre - centre_line) / lane_width) + 1.0, 0.0)
    return across.mean(axis=1)


def comfort_and_mobility(
    jerk_lon: np.ndarray,
    jerk_lat: np.ndarray,
    speed_deviation: np.ndarray,
    lateral_deviation: np.ndarray,
    lanes_away: np.ndarray,
    weights: CostWeights,
    lanes_oncoming: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The risk-free parts of Eq. 5: comfort and mobility costs, shape (n,) each.

    Args: as ``total_cost``.
    """
    comfort = weights.jerk_lon * jerk_lon + weights.jerk_lat * jerk_lat
    mobility = (
        weights.speed * speed_deviation
        + weights.path_distance * lateral_deviation
        + weights.other_lane * lanes_away
    )
    if lanes_oncoming is not None:
        mobility = mobility + weights.oncoming_lane * lanes_oncoming
    return comfort, mobility


def eq5_cost(
    j_risk: np.ndarray, comfort: np.ndarray, mobility: np.ndarray, weights: CostWeights
) -> np.ndarray:
    """J_total of Eq. 5, w_risk J_risk + comfort + mobility, shape (n,).

    Every operation rounds monotonically, so with ``j_risk`` = 0 this is a lower bound,
    in floating point too, of the cost of any J_risk >= 0 (the planner's branch and bound).
    """
    return weights.risk * j_risk + comfort + mobility


def total_cost(
    risks: np.ndarray,
    present: np.ndarray,
    r: np.ndarray,
    harms: np.ndarray,
    counted: np.ndarray,
    ego_combined: np.ndarray,
    jerk_lon: np.ndarray,
    jerk_lat: np.ndarray,
    speed_deviation: np.ndarray,
    lateral_deviation: np.ndarray,
    lanes_away: np.ndarray,
    levels: np.ndarray,
    weights: CostWeights,
    lanes_oncoming: np.ndarray | None = None,
) -> CostBreakdown:
    """Cost of every candidate.

    Args:
        risks: (n, m) the set S_R (see ``risk_set``).
        present: (n, m) which entries belong to each candidate's S_R.
        r: (n, m) responsibility of each entry.
        harms: (n, m) harm of each entry.
        counted: (n, m) whether it counts for maximin.
        ego_combined: (n,) R_ego (Eq. 4).
        jerk_lon: (n,) integrated squared longitudinal jerk [m^2/s^5].
        jerk_lat: (n,) integrated squared lateral jerk [m^2/s^5].
        speed_deviation: (n,) mean |v - v_desired| [m/s].
        lateral_deviation: (n,) mean lateral offset from the path reference [m]
            (``path_deviation``).
        lanes_away: (n,) mean lanes between the current lane and the route's lane.
        levels: (n,) validity levels.
        weights: the weights.
        lanes_oncoming: (n,) mean lanes across the centre line (``oncoming_lanes``);
            None: 0.
    """
    j_b = bayes(risks, present)
    j_e = equality(risks, present)
    j_m = maximin(harms, counted, weights.maximin_gamma)
    j_r = responsibility(risks, r, present)
    j_risk = (
        weights.bayes * j_b
        + weights.equality * j_e
        + weights.maximin * j_m
        - weights.responsibility * weights.bayes * j_r
        + weights.ego_risk * ego_combined
    )
    comfort, mobility = comfort_and_mobility(
        jerk_lon, jerk_lat, speed_deviation, lateral_deviation, lanes_away, weights, lanes_oncoming
    )
    valid = levels == Validity.VALID
    total = np.where(valid, eq5_cost(j_risk, comfort, mobility, weights), j_risk)
    return CostBreakdown(j_b, j_e, j_m, j_r, ego_combined, j_risk, comfort, mobility, total)
