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
from ethical_planner.environment import StopLine
from ethical_planner.sampling import FrenetState, braking_motion

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
