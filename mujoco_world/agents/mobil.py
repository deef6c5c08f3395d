"""Reactive lane changes: MOBIL (Kesting, Treiber, Helbing 2007) on IDM accelerations.

Pure functions over arrays (struct of arrays, vectorised over road users):

* ``idm_acceleration``: the intelligent driver model's acceleration.
* ``mobil_incentive`` / ``mobil_safe``: MOBIL's incentive and safety criteria.
* ``lane_neighbours``: leader and follower of each road user in its current lane and
  in the lanes on either side, read from the bodies' true positions projected onto
  the road user's route (the ego is a body like any other unless a road user is blind
  to it), with a lane's end (a lane drop) as a standing obstacle.
* ``mobil_accelerations`` / ``mobil_decide``: the accelerations MOBIL weighs and the
  decision of every MOBIL road user at one behaviour tick.

Conventions: lanes are counted from the right in the road user's direction of
travel; ``k`` is a lane *relative* to the lane of the road user's route (``+1`` the
lane to its left, whose centre lies ``lane_width`` to the left of the route).
Accelerations [m/s^2], speeds [m/s], gaps bumper to bumper [m].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ethical_planner.geometry import rectangle_half_extent
from mujoco_world.scenario.spec import RoadKind, Scenario

#: Lanes weighed by a decision, relative to the road user's current lane: right, stay, left.
SIDES = np.array([-1, 0, 1])
#: A body occupies a lane when its footprint reaches this far into it across the road [m].
LANE_OVERLAP_M = 0.3
#: How far behind a road user followers are looked for [m].
LOOK_BACK_M = 80.0
#: Smallest gap the IDM divides by [m] (as ``_IntelligentDriver``).
MIN_GAP_M = 0.1


@dataclass(frozen=True, slots=True)
class LaneLayout:
    """Which lanes a road user may change into, and where lanes end.

    Attributes:
        width: lane width [m].
        own_lanes: per direction (+1, -1), the lanes (from the right in that direction)
            that run in that direction.
        lane_end: per lane (from the right in direction +1), the arc length along the
            main road where the lane has ended [m] (inf: it does not end). Only direction
            +1 lanes of straight roads end (merge roads).
    """

    width: float
    own_lanes: dict[int, frozenset[int]]
    lane_end: tuple[float, ...]

    def end_of(self, lane: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """Arc length where lanes ``lane`` of direction ``direction`` end [m], inf if never.

        Args:
            lane: absolute lane indices (any shape; outside the road: inf).
            direction: +1 or -1, broadcast with ``lane``.
        """
        ends = np.asarray(self.lane_end, dtype=float)
        lane, direction = np.broadcast_arrays(np.asarray(lane), np.asarray(direction))
        inside = (lane >= 0) & (lane < ends.size) & (direction > 0)
        out = np.full(lane.shape, np.inf)
        out[inside] = ends[lane[inside]]
        return out

    def allowed(self, lane: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """(same shape) bool: lane ``lane`` runs in ``direction`` (a lane of the road user's own)."""
        lane, direction = np.broadcast_arrays(np.asarray(lane), np.asarray(direction))
        forward = np.isin(lane, sorted(self.own_lanes.get(1, ())))
        backward = np.isin(lane, sorted(self.own_lanes.get(-1, ())))
        return np.where(direction > 0, forward, backward)


def idm_acceleration(
    v: np.ndarray,
    v0: np.ndarray,
    gap: np.ndarray,
    v_lead: np.ndarray,
    a_max: np.ndarray,
    b_comf: np.ndarray,
    headway: np.ndarray,
    min_gap: np.ndarray,
) -> np.ndarray:
    """IDM acceleration a (1 - (v/v0)^4 - (s*/s)^2), s* = s0 + max(0, v T + v dv / (2 sqrt(a b))).

    Not clipped: MOBIL's safety criterion compares it with ``-b_safe``. An infinite
    gap (no leader) gives the free-road term only. All arguments broadcast.

    Args:
        v: speed [m/s]. v0: desired speed [m/s] (> 0). gap: bumper-to-bumper gap [m]
            (inf: none). v_lead: the leader's speed [m/s]. a_max, b_comf: [m/s^2].
        headway: time gap T [s]. min_gap: standstill gap s0 [m].
    """
    v = np.asarray(v, dtype=float)
    free = 1.0 - (v / np.maximum(v0, 0.1)) ** 4
    finite = np.isfinite(gap)
    s_star = min_gap + np.maximum(0.0, v * headway + v * (v - v_lead) / (2.0 * np.sqrt(a_max * b_comf)))
    interaction = np.where(finite, (s_star / np.maximum(np.where(finite, gap, 1.0), MIN_GAP_M)) ** 2, 0.0)
    return a_max * (free - interaction)


def mobil_incentive(
    a_c: np.ndarray,
    a_c_new: np.ndarray,
    a_n: np.ndarray,
    a_n_new: np.ndarray,
    a_o: np.ndarray,
    a_o_new: np.ndarray,
    side: np.ndarray,
    politeness: np.ndarray,
    bias_right: np.ndarray,
) -> np.ndarray:
    """MOBIL's incentive of a lane change [m/s^2] (change if it exceeds the threshold).

    ``(a~_c - a_c) + p ((a~_n - a_n) + (a~_o - a_o)) - side * bias_right``: the road
    user's own gain, the politeness-weighted gains of the new follower (in the target
    lane) and of the old follower (in the lane it leaves), and the keep-right bias
    (``side`` +1 for a change to the left, -1 to the right). A tilde is the acceleration
    after the change. All arguments broadcast.
    """
    return (a_c_new - a_c) + politeness * ((a_n_new - a_n) + (a_o_new - a_o)) - side * bias_right


def mobil_safe(a_n_new: np.ndarray, a_c_new: np.ndarray, b_safe: np.ndarray) -> np.ndarray:
    """MOBIL's safety criterion: the new follower, and the road user itself, brake less than ``b_safe``."""
    return (a_n_new >= -b_safe) & (a_c_new >= -b_safe)


@dataclass(frozen=True, slots=True)
class Neighbours:
    """Leaders and followers of m road users in the lanes ``lane + SIDES``, each (m, 3).

    Attributes:
        lead_gap: gap to the nearest body ahead occupying the lane, or to the lane's
            end [m] (inf: none).
        lead_speed: its speed along the route [m/s] (0 for a lane end).
        follow: body index of the nearest body behind occupying the lane (-1: none).
        follow_gap: its gap to the road user [m] (inf: none).
        follow_speed: its speed along the route [m/s].
        follow_lead_gap: the follower's gap to the lane's leader, past the road user
            (inf: none) [m].
        occupied: the road user's own footprint reaches into the lane.
    """

    lead_gap: np.ndarray
    lead_speed: np.ndarray
    follow: np.ndarray
    follow_gap: np.ndarray
    follow_speed: np.ndarray
    follow_lead_gap: np.ndarray
    occupied: np.ndarray


def lane_neighbours(
    x: np.ndarray,
    y: np.ndarray,
    theta: np.ndarray,
    s_route: np.ndarray,
    me: np.ndarray,
    offset: np.ndarray,
    lane_width: float,
    position: np.ndarray,
    velocity: np.ndarray,
    yaw: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
    can_follow: np.ndarray,
    sees: np.ndarray,
    lane_end_gap: np.ndarray,
) -> Neighbours:
    """Leaders and followers of m road users in their lane and the lanes either side.

    Every body is projected onto a sampled stretch of each road user's route (the
    nearest sample, refined along its tangent): ``along`` its centre's distance ahead,
    ``lateral`` its offset left of the route. A body occupies the lane whose centre is
    ``k lane_width`` left of the route if its footprint reaches ``LANE_OVERLAP_M``
    into it; it leads if its centre is ahead, follows if behind.

    Args:
        x, y, theta: (m, n_s) route samples around each road user [m, rad].
        s_route: (m, n_s) arc lengths of the samples relative to the road user [m].
        me: (m,) body index of each road user.
        offset: (m,) lateral offset of each road user from its route [m].
        lane_width: [m].
        position, velocity: (n, 2) of every body [m, m/s]. yaw, length, width: (n,).
        can_follow: (n,) bool, bodies that count as followers (vehicles, not
            pedestrians; absent bodies neither lead nor follow).
        sees: (m, n) bool, the bodies each road user reacts to.
        lane_end_gap: (m, 3) distance from each road user's front to the end of each
            lane [m] (inf: the lane does not end).

    Returns:
        ``Neighbours`` for lanes ``round(offset / lane_width) + SIDES``.
    """
    m = me.size
    rows = np.arange(m)
    dx = position[None, :, 0, None] - x[:, None, :]  # (m, n, n_s)
    dy = position[None, :, 1, None] - y[:, None, :]
    nearest = np.argmin(dx * dx + dy * dy, axis=2)  # (m, n)
    dxn = np.take_along_axis(dx, nearest[..., None], axis=2)[..., 0]
    dyn = np.take_along_axis(dy, nearest[..., None], axis=2)[..., 0]
    heading = np.take_along_axis(theta, nearest, axis=1)
    c, s = np.cos(heading), np.sin(heading)
    along = np.take_along_axis(s_route, nearest, axis=1) + dxn * c + dyn * s
    lateral = -dxn * s + dyn * c
    in_window = (nearest > 0) & (nearest < x.shape[1] - 1)
    rel = yaw[None, :] - heading
    half_along = rectangle_half_extent(rel, length[None, :], width[None, :], 1.0, 0.0)
    half_across = rectangle_half_extent(rel, length[None, :], width[None, :], 0.0, 1.0)
    speed = velocity[None, :, 0] * c + velocity[None, :, 1] * s  # (m, n)

    current = np.rint(offset / lane_width)
    centres = (current[:, None] + SIDES[None, :]) * lane_width  # (m, 3)
    reach = 0.5 * lane_width + half_across[:, None, :] - LANE_OVERLAP_M
    occupies = np.abs(lateral[:, None, :] - centres[:, :, None]) < reach  # (m, 3, n)
    others = sees & in_window
    others[rows, me] = False
    half_me = 0.5 * length[me]
    ahead = others & (along > 0.0)
    behind = others & (along <= 0.0) & can_follow[None, :]
    gap_ahead = np.where(ahead, along - half_me[:, None] - half_along, np.inf)[:, None, :]
    gap_ahead = np.where(occupies, gap_ahead, np.inf)  # (m, 3, n)
    lead = np.argmin(gap_ahead, axis=2)
    lead_gap = np.take_along_axis(gap_ahead, lead[..., None], axis=2)[..., 0]
    lead_speed = np.where(np.isfinite(lead_gap), speed[rows[:, None], lead], 0.0)
    lead_rear = np.where(
        np.isfinite(lead_gap), along[rows[:, None], lead] - half_along[rows[:, None], lead], np.inf
    )
    # A lane's end is a standing obstacle at the end.
    end_first = lane_end_gap < lead_gap
    lead_gap = np.where(end_first, lane_end_gap, lead_gap)
    lead_speed = np.where(end_first, 0.0, lead_speed)
    lead_rear = np.where(end_first, lane_end_gap + half_me[:, None], lead_rear)

    gap_behind = np.where(behind, -along - half_me[:, None] - half_along, np.inf)[:, None, :]
    gap_behind = np.where(occupies, gap_behind, np.inf)
    follow = np.argmin(gap_behind, axis=2)
    follow_gap = np.take_along_axis(gap_behind, follow[..., None], axis=2)[..., 0]
    has_follower = np.isfinite(follow_gap)
    follow_front = along[rows[:, None], follow] + half_along[rows[:, None], follow]
    follow_speed = np.where(has_follower, speed[rows[:, None], follow], 0.0)
    follow_lead_gap = np.where(has_follower, lead_rear - follow_front, np.inf)
    own = np.abs(offset[:, None] - centres) < 0.5 * lane_width + 0.5 * width[me][:, None] - LANE_OVERLAP_M
    return Neighbours(
        lead_gap=lead_gap,
        lead_speed=lead_speed,
        follow=np.where(has_follower, follow, -1),
        follow_gap=follow_gap,
        follow_speed=follow_speed,
        follow_lead_gap=follow_lead_gap,
        occupied=own,
    )


@dataclass(frozen=True, slots=True)
class IdmParameters:
    """IDM parameters of every body (n,), for the accelerations MOBIL weighs.

    Attributes:
        v0: desired speed [m/s]. a_max, b_comf: [m/s^2]. headway: [s]. min_gap: [m].
    """

    v0: np.ndarray
    a_max: np.ndarray
    b_comf: np.ndarray
    headway: np.ndarray
    min_gap: np.ndarray

    def acceleration(
        self, body: np.ndarray, v: np.ndarray, gap: np.ndarray, v_lead: np.ndarray
    ) -> np.ndarray:
        """IDM acceleration of bodies ``body`` (any shape; -1 gives 0) at speed ``v`` behind a gap."""
        b = np.where(body >= 0, body, 0)
        acc = idm_acceleration(
            v, self.v0[b], gap, v_lead, self.a_max[b], self.b_comf[b], self.headway[b], self.min_gap[b]
        )
        return np.where(body >= 0, acc, 0.0)


@dataclass(frozen=True, slots=True)
class MobilDecision:
    """What MOBIL decided for m road users at one tick, each (m,) unless stated.

    Attributes:
        incentive: (m, 3) incentive of a change to the right, (0), to the left [m/s^2]
            (-inf where the lane is not allowed).
        safe: (m, 3) the safety criterion holds.
        change: -1 right, 0 stay, +1 left.
    """

    incentive: np.ndarray
    safe: np.ndarray
    change: np.ndarray


@dataclass(frozen=True, slots=True)
class MobilAccelerations:
    """The IDM accelerations MOBIL weighs for m road users, each (m, 3) over ``SIDES``.

    Attributes:
        own: the road user's own in each lane (the middle column: a_c, the others a~_c).
        follower_now: each lane's follower behind the lane's leader (a_n; in the own
            lane a~_o, the old follower after the road user has left).
        follower_behind_me: each lane's follower behind the road user (a~_n; in the own
            lane a_o).
    """

    own: np.ndarray
    follower_now: np.ndarray
    follower_behind_me: np.ndarray

    def blend(self, seeing: MobilAccelerations, weight: np.ndarray) -> MobilAccelerations:
        """``(1 - w) self + w seeing`` row by row (``weight`` (m,) in [0, 1]; 0 and 1 exact)."""
        w = weight[:, None]
        return MobilAccelerations(
            *((1.0 - w) * a + w * b for a, b in ((self.own, seeing.own),
              (self.follower_now, seeing.follower_now),
              (self.follower_behind_me, seeing.follower_behind_me)))
        )  # fmt: skip


def no_passing_on_the_right(
    own: np.ndarray, lead_speed: np.ndarray, left_runs: np.ndarray, pass_right_below: np.ndarray
) -> np.ndarray:
    """The European passing rule: a lane's acceleration at most the one behind the left lane's leader.

    MOBIL's asymmetric variant (Kesting, Treiber, Helbing 2007): a vehicle must not pass
    a vehicle in the lane to its left, except in congestion, so its acceleration in a
    lane is ``min(a, a_left)``, ``a_left`` its acceleration behind the leader of the lane
    to the left, while that leader moves faster than ``pass_right_below`` (v_crit). A
    lane without a leader, a lane end (speed 0) and a leader in congestion do not limit.

    Args:
        own: (m, 3) the road user's acceleration in lanes ``current + SIDES`` [m/s^2].
        lead_speed: (m, 3) the leaders' speeds in those lanes [m/s] (0: none).
        left_runs: (m,) bool, the lane left of the current one runs the road user's way.
        pass_right_below: (m,) v_crit [m/s] (inf: the rule is off for that row).

    Returns:
        (m, 3) the accelerations under the rule. The current lane is limited by the left
        lane's leader, the lane to the right by the current lane's; the left lane's own
        left neighbour is not looked at.
    """
    flowing = lead_speed > pass_right_below[:, None]
    limited = own.copy()
    limited[:, 0] = np.where(flowing[:, 1], np.minimum(own[:, 0], own[:, 1]), own[:, 0])
    limited[:, 1] = np.where(flowing[:, 2] & left_runs, np.minimum(own[:, 1], own[:, 2]), own[:, 1])
    return limited


def mobil_accelerations(
    nb: Neighbours,
    me: np.ndarray,
    v: np.ndarray,
    idm: IdmParameters,
    left_runs: np.ndarray | None = None,
    pass_right_below: np.ndarray | None = None,
) -> MobilAccelerations:
    """The IDM accelerations of m road users and of their followers, in lanes ``current + SIDES``.

    Args:
        nb: leaders and followers (``lane_neighbours``).
        me: (m,) body indices. v: (m,) their speeds [m/s].
        idm: IDM parameters of every body (the followers' accelerations use theirs).
        left_runs, pass_right_below: (m,) the European passing rule
            (``no_passing_on_the_right``) for the road users' own accelerations; None:
            off for all.
    """
    f = nb.follow
    own = idm.acceleration(me[:, None], v[:, None], nb.lead_gap, nb.lead_speed)
    if pass_right_below is not None:
        own = no_passing_on_the_right(own, nb.lead_speed, left_runs, pass_right_below)
    return MobilAccelerations(
        own=own,
        follower_now=idm.acceleration(f, nb.follow_speed, nb.follow_lead_gap, nb.lead_speed),
        follower_behind_me=idm.acceleration(f, nb.follow_speed, nb.follow_gap, v[:, None]),
    )


def mobil_decide(
    acc: MobilAccelerations,
    allowed: np.ndarray,
    politeness: np.ndarray,
    threshold: np.ndarray,
    b_safe: np.ndarray,
    bias_right: np.ndarray,
    ready: np.ndarray,
) -> MobilDecision:
    """MOBIL's decision for m road users from the accelerations it weighs.

    Args:
        acc: the accelerations (``mobil_accelerations``, or a blend of two).
        allowed: (m, 3) bool, the lane exists, runs in the road user's direction and has
            not ended ahead of it (the middle column: its own lane).
        politeness, threshold, b_safe, bias_right: (m,) MOBIL parameters.
        ready: (m,) bool, may decide now (not changing lane, cooldown over).

    Returns:
        The decision; the larger incentive wins if both sides qualify.
    """
    own, follower_now, follower_behind_me = acc.own, acc.follower_now, acc.follower_behind_me
    a_c = own[:, 1:2]
    # New follower (target lane): before it follows the lane's leader, after it follows me.
    # Old follower (my lane): before it follows me, after my leader.
    a_o, a_o_new = follower_behind_me[:, 1:2], follower_now[:, 1:2]
    incentive = mobil_incentive(
        a_c,
        own,
        follower_now,
        follower_behind_me,
        a_o,
        a_o_new,
        SIDES[None, :],
        politeness[:, None],
        bias_right[:, None],
    )
    safe = mobil_safe(follower_behind_me, own, b_safe[:, None])
    incentive = np.where(allowed, incentive, -np.inf)
    incentive[:, 1] = -np.inf
    qualifies = safe & allowed & (incentive > threshold[:, None]) & ready[:, None]
    score = np.where(qualifies, incentive, -np.inf)
    best = np.argmax(score, axis=1)
    change = np.where(np.isfinite(score[np.arange(own.shape[0]), best]), SIDES[best], 0)
    return MobilDecision(incentive=incentive, safe=safe, change=change)


def lane_layout(scenario: Scenario) -> LaneLayout:
    """The lanes of each direction and the lane ends of a scenario's road.

    The lanes of a direction are ``road.lanes_of(direction)`` (``road.lanes_forward``
    along the reference direction, the rest against it; a merge road is one way). A
    merge road's lane 0 (the acceleration lane) ends where its taper starts
    (``road.lane_drop - road.taper``).

    Args:
        scenario: the scenario.
    """
    road = scenario.road
    ends = [math.inf] * road.lanes
    if road.kind is RoadKind.MERGE:
        ends[0] = road.lane_drop - road.taper
    own = {d: frozenset(range(road.lanes_of(d))) for d in (1, -1)}
    return LaneLayout(road.lane_width, own, tuple(ends))
