"""Traffic rules for the ego: stop lines of red lights and stop signs, vectorised.

A candidate that crosses a *binding* stop line breaks the rule and gets validity level
``Validity.BREAKS_TRAFFIC_RULE`` (4): invalid, not costed. A weight would let the cost
of a detour or of the speed deficit buy a red light; an automated vehicle treats the
law as a constraint that only safety may override, and the validity hierarchy is that
constraint (level 4 ranks above the risk levels 0-3 and below every valid plan).

When a candidate crosses a line (its front, the centre's arc length plus half the
ego's length, reaching the line's arc length):

- within the horizon: at the first step at or past the line, linearly interpolated
  between the samples;
- after the horizon: if its end state cannot stop before the line at the comfortable
  deceleration b_c, or at its own braking if it brakes harder (a braking candidate
  brakes on to its stop: v_T^2 / (2 max(b_c, b)) > gap_T), it is committed to crossing
  and does so at t_T + gap_T / v_T (its end speed held); otherwise it is taken to stop.

A red light is broken if the light is red at now + the crossing time (the red windows
are known: a light that will be red when the ego gets there binds already); a stop
sign is broken by any crossing before the ego has stood still (below
``STANDSTILL_MPS``) with its front within the line's stop zone.

Dilemma zone: a line binds only while the ego can still stop before it, from its
present state with the jerk-limited braking of the braking candidates
(``sampling.braking_motion``). For a light that turns red later, and that the ego
reaches before its red at its present speed, the deceleration is the comfortable one
(``TrafficRulesConfig.comfortable_deceleration``, 3 m/s^2): an ego that cannot stop
comfortably when the light is about to change proceeds, as the amber phase intends.
One that would reach the line in the red is held to the emergency deceleration, as
is a light that is red now and a stop sign (8 m/s^2): a red light or a stop sign is
never run while full braking still stops before it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ethical_planner.config import TrafficRulesConfig, VehicleConfig
from ethical_planner.environment import NoOvertakingZone, RoadEnvironment, StopLine
from ethical_planner.prediction.base import Prediction
from ethical_planner.reference_path import ReferencePath
from ethical_planner.risk import static_obstacles
from ethical_planner.road_users import Shape
from ethical_planner.sampling import Candidates, FrenetState, braking_motion

#: Below this speed [m/s] the ego stands still (stop signs; the world's judge uses it too).
STANDSTILL_MPS = 0.1


@dataclass(frozen=True, slots=True, eq=False)
class StopLines:
    """The stop lines of one planning cycle as arrays, m lines, w windows each.

    Attributes:
        s: arc lengths of the lines [m], shape (m,).
        binding: the line binds this cycle (ahead of the ego's front, not released by
            the dilemma zone, a stop sign not yet stopped at), shape (m,).
        stop_sign: shape (m,).
        red_start, red_end: red windows on the run's clock [s], shape (m, w), padded
            with empty windows (inf, inf).
        now: the cycle's time on the run's clock [s].
    """

    s: np.ndarray
    binding: np.ndarray
    stop_sign: np.ndarray
    red_start: np.ndarray
    red_end: np.ndarray
    now: float

    @classmethod
    def of(
        cls,
        lines: tuple[StopLine, ...],
        start: FrenetState,
        front_offset: float,
        now: float,
        stood: np.ndarray,
        vehicle: VehicleConfig,
        rules: TrafficRulesConfig,
    ) -> StopLines:
        """The lines as they bind the ego in its present state (see the module docstring).

        Args:
            lines: the road's stop lines.
            start: the ego's Frenet state (centre).
            front_offset: front of the ego ahead of its centre [m] (half its length).
            now: time of the cycle on the lines' clock [s].
            stood: stop signs the ego has stood still at, shape (m,).
            vehicle: its emergency deceleration and jerk.
            rules: the comfortable deceleration.
        """
        m = len(lines)
        w = max((len(line.red) for line in lines), default=0)
        red = np.full((m, max(w, 1), 2), np.inf)
        for i, line in enumerate(lines):  # a few lines, a few windows
            if line.red:
                red[i, : len(line.red)] = line.red
        # Widened by the margin (config), so that a plan keeps clear of the red's edges.
        red[:, :, 0] -= rules.red_margin
        red[:, :, 1] += rules.red_margin
        s = np.array([line.s for line in lines], dtype=float)
        sign = np.array([line.stop for line in lines], dtype=bool)
        real = np.isfinite(red[:, :, 1])  # padding windows are (inf, inf)
        red_now = np.any((red[:, :, 0] <= now) & (now < red[:, :, 1]), axis=1)
        future_red = np.any(real & (red[:, :, 1] > now), axis=1)
        next_red = np.min(np.where(red[:, :, 0] > now, red[:, :, 0], np.inf), axis=1)
        gap = s - (start.s + front_offset)
        # The amber release is for an ego that gets past the line before the red starts
        # (at its present speed); one that would arrive in the red gains nothing by
        # holding on, and the line binds as firmly as a red one.
        arrival = gap / start.s_dot if start.s_dot > 0.0 else np.full(m, np.inf)
        clears = arrival < next_red - now
        # Emergency braking for a light red now, a stop sign and a light the ego would
        # reach in its red; comfortable braking for one it clears before the red
        # (the amber dilemma zone).
        firm = sign | red_now | ~clears
        decel = np.where(firm, vehicle.emergency_deceleration, rules.comfortable_deceleration)
        can_stop = stop_distance(start, decel, vehicle.max_jerk) <= gap
        binding = (gap > 0.0) & can_stop & np.where(sign, ~np.asarray(stood, dtype=bool), future_red)
        return cls(s, binding, sign, red[:, :, 0], red[:, :, 1], float(now))


def stop_distance(start: FrenetState, deceleration: np.ndarray, max_jerk: float) -> np.ndarray:
    """Distance to a stop from ``start`` braking at ``deceleration`` after a jerk ramp [m].

    The braking of the braking candidates (``sampling.braking_motion``): the
    acceleration goes from the present one to -b at ``max_jerk``, then stays -b.

    Args:
        start: ego Frenet state (s_dot, s_ddot used).
        deceleration: b [m/s^2], shape (m,), > 0.
        max_jerk: [m/s^3].

    Returns:
        Shape (m,).
    """
    deceleration = np.asarray(deceleration, dtype=float)
    if deceleration.size == 0:
        return np.zeros(0)
    _, distance, _ = braking_motion(start, deceleration, np.zeros(1), max_jerk)
    return distance


def crossing_times(
    front: np.ndarray,
    end_speed: np.ndarray,
    t: np.ndarray,
    line_s: np.ndarray,
    comfortable_deceleration: float,
    end_braking: np.ndarray | None = None,
) -> np.ndarray:
    """When each candidate's front crosses each line, from now [s]; inf if it does not.

    Args:
        front: arc length of the front [m], shape (n, n_t).
        end_speed: longitudinal speed at the last step [m/s], shape (n,).
        t: times [s], shape (n_t,).
        line_s: the lines' arc lengths [m], shape (m,).
        comfortable_deceleration: b_c [m/s^2] of the end-state test.
        end_braking: deceleration each candidate keeps after its horizon [m/s^2],
            shape (n,) (a braking candidate brakes on to its stop; 0 for the others).
            The end-state test uses the larger of it and b_c.

    Returns:
        Shape (n, m); 0 for a line at or behind the front at t = 0.
    """
    n, n_t = front.shape
    past = front[:, None, :] >= line_s[None, :, None]  # (n, m, n_t)
    crosses = past.any(axis=2)
    k = past.argmax(axis=2)  # first step at or past the line
    before = np.maximum(k - 1, 0)
    f0 = np.take_along_axis(front, before, axis=1)
    f1 = np.take_along_axis(front, k, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        fraction = np.clip(np.where(f1 > f0, (line_s[None, :] - f0) / (f1 - f0), 1.0), 0.0, 1.0)
    inside = np.where(k == 0, 0.0, t[before] + fraction * (t[k] - t[before]))
    gap = line_s[None, :] - front[:, -1:]  # (n, m)
    v = np.maximum(end_speed, 0.0)[:, None]
    b = (
        np.full(n, comfortable_deceleration)
        if end_braking is None
        else np.maximum(end_braking, comfortable_deceleration)
    )
    committed = ~crosses & (v * v > 2.0 * b[:, None] * gap)
    with np.errstate(divide="ignore"):
        after = t[-1] + gap / v
    return np.where(crosses, inside, np.where(committed, after, np.inf))


def breaks_stop_lines(
    front: np.ndarray,
    end_speed: np.ndarray,
    t: np.ndarray,
    lines: StopLines,
    comfortable_deceleration: float,
    end_braking: np.ndarray | None = None,
) -> np.ndarray:
    """Which candidates cross a binding stop line, shape (n,) (module docstring).

    Args:
        front: arc length of the ego's front along each candidate [m], shape (n, n_t).
        end_speed: longitudinal speed at the last step [m/s], shape (n,).
        t: times from now [s], shape (n_t,).
        lines: this cycle's lines.
        comfortable_deceleration: b_c of the end-state test [m/s^2].
        end_braking: deceleration kept after the horizon [m/s^2], shape (n,)
            (``crossing_times``).
    """
    n = front.shape[0]
    rows = np.flatnonzero(lines.binding)
    if rows.size == 0:
        return np.zeros(n, dtype=bool)
    when = crossing_times(front, end_speed, t, lines.s[rows], comfortable_deceleration, end_braking)
    at = lines.now + when[:, :, None]  # (n, b, 1)
    red = np.any((lines.red_start[rows] <= at) & (at < lines.red_end[rows]), axis=2)
    broken = np.where(lines.stop_sign[rows], np.isfinite(when), red)
    return broken.any(axis=1)


def stood_at(lines: tuple[StopLine, ...], front: float, speed: float) -> np.ndarray:
    """Stop signs at which the ego stands still now (front within the stop zone), shape (m,)."""
    s = np.array([line.s for line in lines], dtype=float)
    zone = np.array([line.stop_zone for line in lines], dtype=float)
    sign = np.array([line.stop for line in lines], dtype=bool)
    return sign & (speed < STANDSTILL_MPS) & (front >= s - zone) & (front < s)


def stop_targets(lines: StopLines, start: FrenetState, front_offset: float, stop_gap: float) -> np.ndarray:
    """Distances the ego's centre travels to stop ``stop_gap`` before each binding line [m]."""
    return lines.s[lines.binding] - stop_gap - front_offset - start.s


# --------------------------------------------------------------------------- lane markings


@dataclass(frozen=True, slots=True, eq=False)
class LaneRules:
    """The lane markings that bind the ego in one planning cycle.

    Attributes:
        centre: offset d of the centre line from the reference path [m], or None if no
            no-overtaking zone binds this cycle.
        zones: the binding zones' (start, end) arc lengths [m], shape (z, 2).
        edges: offsets d (right, left) of the outer lane edges [m], or None if the
            shoulder rule does not apply.
    """

    centre: float | None
    zones: np.ndarray
    edges: tuple[float, float] | None

    @classmethod
    def of(
        cls,
        environment: RoadEnvironment,
        start: FrenetState,
        ego_length: float,
        prediction: Prediction,
        rules: TrafficRulesConfig,
    ) -> LaneRules | None:
        """The rules of this cycle; None if none applies.

        A zone binds unless something slower than its ``pass_below`` blocks the ego's
        lane ahead (``lane_blocked``): passing it is not overtaking.
        """
        zones = environment.no_overtaking if rules.no_overtaking else ()
        edges = environment.lane_edges if rules.shoulder else None
        binding = [
            z
            for z in zones
            if z.end > start.s - ego_length
            and not _passable(z, environment, start, ego_length, prediction, rules)
        ]
        if not binding and edges is None:
            return None
        # Margins: the executed path lags and strays from the plan by a few centimetres and
        # the plan is judged at its samples only (0.6 m apart at 6 m/s).
        margin = rules.marking_margin
        centre = environment.centre_line - margin if binding and environment.centre_line is not None else None
        spans = np.array(
            [(z.start - rules.zone_margin, z.end + rules.zone_margin) for z in binding], dtype=float
        )
        if edges is not None:
            edges = (edges[0] + margin, edges[1] - margin)
        return cls(centre, spans.reshape(-1, 2), edges)


def _passable(
    zone: NoOvertakingZone,
    environment: RoadEnvironment,
    start: FrenetState,
    ego_length: float,
    prediction: Prediction,
    rules: TrafficRulesConfig,
) -> bool:
    """True if the zone's exception holds: something slower than ``pass_below`` blocks the lane."""
    if zone.pass_below <= 0.0:
        return False
    return lane_blocked(
        environment,
        (start.s, start.d),
        ego_length,
        prediction.mean[:, 0],
        prediction.speed[:, 0],
        prediction.width,
        zone.pass_below,
        rules.pass_lookahead,
    )


def lane_blocked(
    environment: RoadEnvironment,
    ego: tuple[float, float],
    ego_length: float,
    positions: np.ndarray,
    speeds: np.ndarray,
    widths: np.ndarray,
    below: float,
    lookahead: float,
) -> bool:
    """True if debris or a road user slower than ``below`` lies in the ego's lane ahead.

    The ego's lane is the lane (``environment.lane_offsets``) nearest to its centre;
    "ahead" reaches from the ego's rear to ``lookahead`` beyond its front. A road user
    is in the lane if its footprint's lateral extent (its centre's offset +- half its
    width) overlaps the lane; debris (a hole of the drivable area) if its outline does.
    The planner (its prediction's present state) and the world's judge (the true
    state) both ask this.

    Args:
        environment: the road (reference path, lanes, drivable area).
        ego: the ego centre's Frenet (s, d) [m].
        ego_length: [m].
        positions: road users' centres [m], shape (k, 2).
        speeds: their speeds [m/s], shape (k,).
        widths: their widths [m], shape (k,).
        below: speed below which a road user blocks [m/s].
        lookahead: [m].
    """
    path = environment.reference_path
    offsets = np.asarray(environment.lane_offsets, dtype=float)
    s_ego, d_ego = ego
    lane = offsets[np.argmin(np.abs(offsets - d_ego))]
    half_lane = 0.5 * environment.lane_width
    low, high = s_ego - 0.5 * ego_length, s_ego + 0.5 * ego_length + lookahead
    positions = np.asarray(positions, dtype=float).reshape(-1, 2)
    if positions.size:
        s_k, d_k = path.to_frenet(positions[:, 0], positions[:, 1])
        reach = 0.5 * np.asarray(widths, dtype=float)
        slow = np.asarray(speeds, dtype=float) < below
        ahead = (s_k >= low) & (s_k <= high)
        inside = ahead & (d_k + reach > lane - half_lane) & (d_k - reach < lane + half_lane)
        if np.any(slow & inside):
            return True
    holes = static_obstacles(environment)
    if holes is None:
        return False
    for hole in getattr(holes, "geoms", (holes,)):  # a few pieces of debris
        xy = np.asarray(hole.exterior.coords)
        s_h, d_h = path.to_frenet(xy[:, 0], xy[:, 1])
        along = s_h.max() >= low and s_h.min() <= high
        if along and d_h.max() > lane - half_lane and d_h.min() < lane + half_lane:
            return True
    return False


def lateral_extent(
    candidates: Candidates, path: ReferencePath, shape: Shape
) -> tuple[np.ndarray, np.ndarray]:
    """Right and left edges of the ego's footprint as offsets d from the path [m], shape (n, n_t) each.

    The rectangle at heading ``yaw`` against the path's heading ``theta(s)`` reaches
    ``L/2 |sin(yaw - theta)| + W/2 |cos(yaw - theta)|`` to either side of its centre.
    """
    relative = candidates.yaw - path.heading(candidates.s)
    half = 0.5 * shape.length * np.abs(np.sin(relative)) + 0.5 * shape.width * np.abs(np.cos(relative))
    return candidates.d - half, candidates.d + half


def breaks_lane_rules(
    candidates: Candidates, path: ReferencePath, shape: Shape, rules: LaneRules
) -> np.ndarray:
    """Which candidates cross the centre line in a binding zone or drive onto a shoulder, shape (n,).

    A candidate breaks the no-overtaking rule if, at a step t > 0 at which its
    footprint (arc lengths s +- L/2) overlaps a binding zone, its footprint reaches
    further across the centre line than the ego's does now (t = 0): an ego already
    across (an overtaking begun before the zone) may return, never go further. It
    breaks the shoulder rule if its footprint reaches further beyond an outer lane edge
    than now, at any step; an ego already beyond the edge breaks it only at steps at which
    its centre is also further out than now (turning back into the lane, or with a
    curve, swings a corner further out).

    Args:
        candidates: the cycle's candidates.
        path: the reference path.
        shape: the ego's footprint.
        rules: this cycle's ``LaneRules``.
    """
    n = candidates.n_traj
    right, left = lateral_extent(candidates, path, shape)
    broken = np.zeros(n, dtype=bool)
    if rules.centre is not None and rules.zones.size:
        across = np.maximum(left - rules.centre, 0.0)
        half = 0.5 * shape.length
        s = candidates.s[:, :, None]
        in_zone = np.any((s + half > rules.zones[:, 0]) & (s - half < rules.zones[:, 1]), axis=2)
        further = across[:, 1:] > across[:, :1] + _GROWTH_M
        broken |= np.any(in_zone[:, 1:] & further, axis=1)
    if rules.edges is not None:
        d = candidates.d
        for past, outward in (
            (np.maximum(rules.edges[0] - right, 0.0), d[:, 1:] < d[:, :1] - _GROWTH_M),
            (np.maximum(left - rules.edges[1], 0.0), d[:, 1:] > d[:, :1] + _GROWTH_M),
        ):
            further = past[:, 1:] > past[:, :1] + _GROWTH_M
            # An ego already beyond the edge swings a corner further out whenever it
            # turns (back into the lane, or with a curve); only moving further out
            # itself (its centre) counts then, else no plan but standing still keeps
            # the rule and it stands on the shoulder for good.
            on_it = past[:, :1] > 0.0
            broken |= np.any(further & (~on_it | outward), axis=1)
    return broken


#: A footprint reaching further across a marking than now by more than this breaks the rule [m]
#: (rounding only: a plan that holds its lateral position is not a new crossing).
_GROWTH_M = 1e-3
