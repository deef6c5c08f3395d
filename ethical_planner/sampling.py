"""Frenet sampling of candidate trajectories (paper Fig. 1, step 1), vectorised.

Every candidate is a Frenet motion, s(t) and d(t) with three time derivatives each,
converted to Cartesian states with exact derivatives of the Frenet frame (no finite
differences), so speed, acceleration and curvature are those of the motion. Families
(``CandidateKind``):

- grid (the paper's): a quartic s(t) to an end speed with zero end acceleration, a
  quintic d(t) to an end offset at rest, for every end speed x end offset x horizon;
  below ``SamplingConfig.low_speed`` the quintic follows arc length instead of time;
- brake: a jerk-limited ramp to a constant deceleration, braking to a stop and
  staying stopped, with a quintic lateral shift in arc length over part of the
  braking distance;
- continuation: the previous cycle's plan from where the ego is on it;
- emergency: braking at the emergency deceleration in the current lane position,
  the fallback when every other candidate breaks a physical limit.

All families share one time grid, that of the longest horizon, and one struct of
arrays of shape (n_traj, n_t).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np

from ethical_planner.config import SamplingConfig, VehicleConfig
from ethical_planner.geometry import wrap_angle
from ethical_planner.jit import kernel
from ethical_planner.reference_path import ReferencePath, cartesian_states
from ethical_planner.road_users import KinematicState


class CandidateKind(IntEnum):
    """Family of a candidate (``Candidates.kind``)."""

    GRID = 0
    BRAKE = 1
    CONTINUATION = 2
    EMERGENCY = 3


@dataclass(frozen=True, slots=True, eq=False)
class FrenetState:
    """Ego state in the Frenet frame of the reference path.

    Attributes:
        s, d: position [m]. s_dot, d_dot: [m/s]. s_ddot, d_ddot: [m/s^2].
        d_prime: dd/ds, the heading relative to the path (1 - kappa d) tan(yaw - theta)
            [1], defined at standstill too.
        d_prime2: d^2d/ds^2 [1/m] (0 below 1 m/s, where it is ill-defined).
    """

    s: float
    s_dot: float
    s_ddot: float
    d: float
    d_dot: float
    d_ddot: float
    d_prime: float = 0.0
    d_prime2: float = 0.0


def frenet_state(state: KinematicState, path: ReferencePath) -> FrenetState:
    """Convert a Cartesian state to Frenet coordinates along ``path``.

    Accelerations neglect the path's curvature terms; the error is second order and
    vanishes on straight roads.
    """
    s, d = path.to_frenet(np.array(state.x), np.array(state.y))
    s, d = float(s), float(d)
    _, _, theta, kappa, _ = path.evaluate(np.array(s))
    delta = float(wrap_angle(state.yaw - float(theta)))  # the path's heading may lie across +-pi
    one_minus_kd = 1.0 - float(kappa) * d
    if one_minus_kd <= 0.05:
        raise ValueError(f"ego lies {d:.1f} m from the reference path, beyond its radius of curvature")
    s_dot = state.v * np.cos(delta) / one_minus_kd
    s_ddot = state.a * np.cos(delta)
    d_ddot = state.a * np.sin(delta)
    d_prime = one_minus_kd * float(np.tan(np.clip(delta, -1.2, 1.2)))
    d_prime2 = (d_ddot - d_prime * s_ddot) / s_dot**2 if s_dot > 1.0 else 0.0
    return FrenetState(
        s=s,
        s_dot=s_dot,
        s_ddot=s_ddot,
        d=d,
        d_dot=state.v * np.sin(delta),
        d_ddot=d_ddot,
        d_prime=d_prime,
        d_prime2=d_prime2,
    )


@dataclass(frozen=True, slots=True, eq=False)
class Candidates:
    """All candidate trajectories of one cycle as a struct of arrays.

    Every per-step array has shape (n_traj, n_t); ``t`` has shape (n_t,).

    Attributes:
        t: time from now [s].
        x, y: ego centre [m]. yaw: [rad]. v: speed [m/s]. a: tangential
            acceleration [m/s^2]. kappa: curvature [1/m].
        s, d: Frenet position [m]. s_dot: longitudinal Frenet speed [m/s].
        end_speed, end_offset, horizon: sampling parameters, shape (n_traj,)
            (a braking candidate's horizon is its stop time).
        kind: ``CandidateKind`` of each candidate, shape (n_traj,).
        deceleration: braking candidates' deceleration [m/s^2], 0 for the others.
        jerk_lon, jerk_lat: integrated squared jerk [m^2/s^5], shape (n_traj,).
        lon, lat: the Frenet motion, s and d with their first three time
            derivatives, shape (4, n_traj, n_t) each (for the continuation).
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    v: np.ndarray
    a: np.ndarray
    kappa: np.ndarray
    s: np.ndarray
    d: np.ndarray
    s_dot: np.ndarray
    end_speed: np.ndarray
    end_offset: np.ndarray
    horizon: np.ndarray
    kind: np.ndarray
    deceleration: np.ndarray
    jerk_lon: np.ndarray
    jerk_lat: np.ndarray
    lon: np.ndarray
    lat: np.ndarray

    @property
    def n_traj(self) -> int:
        """Number of candidates."""
        return self.x.shape[0]


def every_row(rows: np.ndarray, n: int) -> bool:
    """Whether the indices ``rows`` are 0, 1, ..., n - 1: a gather by them would copy the array.

    Args:
        rows: candidate indices, shape (m,).
        n: the number of candidates.
    """
    return rows.size == n and bool((rows == np.arange(n)).all())


@dataclass(frozen=True, slots=True, eq=False)
class CandidatePart:
    """Candidates of one family before their conversion to Cartesian states.

    Candidates share longitudinal motions (a grid's depends on the end speed and the
    horizon, not on the end offset; a braking family's on the deceleration), so each
    distinct one is stored once and the path is evaluated once per distinct motion.

    Attributes:
        lon: distinct longitudinal motions, s and its first three time derivatives,
            shape (4, r, n_t).
        lon_row: the motion of each candidate, indices into ``lon``, shape (m,).
        lat: d and its first three time derivatives of each candidate, shape (4, m, n_t);
            with ``lat_row``, the distinct lateral motions, shape (4, q, n_t).
        end_speed, end_offset, horizon, deceleration: sampling parameters, shape (m,).
        kind: the family.
        lat_row: the lateral motion of each candidate, indices into ``lat``, shape (m,);
            None: ``lat`` holds one per candidate.
    """

    lon: np.ndarray
    lon_row: np.ndarray
    lat: np.ndarray
    end_speed: np.ndarray
    end_offset: np.ndarray
    horizon: np.ndarray
    kind: CandidateKind
    deceleration: np.ndarray
    lat_row: np.ndarray | None = None

    @property
    def candidate_lon(self) -> np.ndarray:
        """The longitudinal motion of every candidate, shape (4, m, n_t)."""
        return self.lon[:, self.lon_row]


def quartic_coefficients(
    s0: float, v0: float, a0: float, v_end: np.ndarray, horizon: np.ndarray
) -> np.ndarray:
    """Coefficients c0..c4 of s(t) with s(0)=s0, s'(0)=v0, s''(0)=a0, s'(T)=v_end, s''(T)=0.

    Args:
        s0: start position [m].
        v0: start speed [m/s].
        a0: start acceleration [m/s^2].
        v_end: end speeds [m/s], broadcastable with ``horizon``.
        horizon: horizons T [s].

    Returns:
        Shape (..., 5), lowest power first.
    """
    v_end, horizon = np.broadcast_arrays(np.asarray(v_end, float), np.asarray(horizon, float))
    delta = v_end - v0 - a0 * horizon
    c4 = -(delta + 0.5 * a0 * horizon) / (2.0 * horizon**3)
    c3 = (-a0 - 12.0 * c4 * horizon**2) / (6.0 * horizon)
    return np.stack([np.full_like(c4, s0), np.full_like(c4, v0), np.full_like(c4, 0.5 * a0), c3, c4], axis=-1)


def quintic_coefficients(
    d0: float, d1: float, d2: float, d_end: np.ndarray, horizon: np.ndarray
) -> np.ndarray:
    """Coefficients c0..c5 of d(t) from (d0, d0', d0'') to (d_end, 0, 0) at t = T.

    Returns:
        Shape (..., 6), lowest power first.
    """
    d_end, horizon = np.broadcast_arrays(np.asarray(d_end, float), np.asarray(horizon, float))
    h = d_end - d0 - d1 * horizon - 0.5 * d2 * horizon**2
    e1 = -d1 - d2 * horizon
    e2 = -d2
    c3 = (10.0 * h - 4.0 * e1 * horizon + 0.5 * e2 * horizon**2) / horizon**3
    c4 = (-15.0 * h + 7.0 * e1 * horizon - e2 * horizon**2) / horizon**4
    c5 = (6.0 * h - 3.0 * e1 * horizon + 0.5 * e2 * horizon**2) / horizon**5
    full = np.full_like(c3, 1.0)
    return np.stack([d0 * full, d1 * full, 0.5 * d2 * full, c3, c4, c5], axis=-1)


def _polynomial_derivatives(coeffs: np.ndarray, t: np.ndarray, horizon: np.ndarray) -> np.ndarray:
    """Value and first three time derivatives of polynomials, held past their horizon.

    After t = T the motion continues with the end velocity and zero acceleration.

    Args:
        coeffs: (n_traj, k) lowest power first.
        t: times [s], shape (n_t,).
        horizon: horizon T of each polynomial [s], shape (n_traj,).

    Returns:
        Shape (4, n_traj, n_t): value, first, second, third derivative.
    """
    out = np.empty((4, len(coeffs), t.size))
    coeffs = np.ascontiguousarray(coeffs, dtype=float)
    _polynomials(coeffs, np.ascontiguousarray(horizon, dtype=float), t, out)
    return out


@kernel
def _polynomials(coeffs: np.ndarray, horizon: np.ndarray, t: np.ndarray, out: np.ndarray) -> None:
    """Kernel of ``_polynomial_derivatives``, out (4, n, n_t) written.

    With tt = min(t, T): derivative r is sum_{p >= r} p! / (p - r)! c_p tt^(p - r), summed
    in order of p; the powers as numpy's ``tt ** p`` computes them. Past T the value
    grows with the end velocity and the higher derivatives are 0.
    """
    n, k = coeffs.shape
    powers = np.empty(k)
    for row in range(n):
        end = horizon[row]
        for step in range(t.size):
            tt = min(t[step], end)
            powers[0] = 1.0
            for p in range(1, k):  # as numpy's tt ** p: tt, tt * tt, then pow
                powers[p] = tt if p == 1 else (tt * tt if p == 2 else math.pow(tt, float(p)))
            for order in range(4):
                total = 0.0
                for p in range(order, k):
                    factor = 1.0
                    for q in range(p - order + 1, p + 1):
                        factor *= q
                    term = factor * coeffs[row, p] * powers[p - order]
                    total = term if p == order else total + term
                out[order, row, step] = total if order < k else 0.0
            overtime = max(t[step] - end, 0.0)
            out[0, row, step] += out[1, row, step] * overtime
            if t[step] > end:
                out[2, row, step] = 0.0
                out[3, row, step] = 0.0


def lateral_along_arc(
    start: FrenetState, d_end: np.ndarray, distance: np.ndarray, lon: np.ndarray
) -> np.ndarray:
    """Lateral motion as a quintic in arc length, completed over ``distance``.

    d(sigma), sigma = s - s0, runs from the start's (d, d', d'') to (d_end, 0, 0) at
    sigma = distance and holds d_end after it. Time derivatives by the chain rule, with
    primes for arc length and dots for time: d_t = d' s_t, d_tt = d'' s_t^2 + d' s_tt,
    d_ttt = d''' s_t^3 + 3 d'' s_t s_tt + d' s_ttt. A shift over less than
    ``_MIN_LATERAL_DISTANCE`` holds the offset (a standing car cannot move sideways).

    Args:
        start: ego Frenet state (d, d_prime, d_prime2 used).
        d_end: end offsets [m], shape (n,).
        distance: arc length of the shift [m], shape (n,).
        lon: (4, n, n_t) s and its time derivatives.

    Returns:
        (4, n, n_t) d and its first three time derivatives.
    """
    s, s_dot, s_ddot, s_dddot = lon
    n = s.shape[0]
    short = distance < _MIN_LATERAL_DISTANCE
    length = np.where(short, 1.0, distance)
    coeffs = quintic_coefficients(start.d, start.d_prime, start.d_prime2, d_end, length)
    coeffs[short] = [start.d, 0.0, 0.0, 0.0, 0.0, 0.0]
    sigma = s - start.s
    u = np.clip(sigma, 0.0, length[:, None])
    past = (sigma >= length[:, None]) | short[:, None]
    c = coeffs.T[:, :, None]  # (6, n, 1)
    d = c[0] + u * (c[1] + u * (c[2] + u * (c[3] + u * (c[4] + u * c[5]))))
    d1 = c[1] + u * (2 * c[2] + u * (3 * c[3] + u * (4 * c[4] + u * 5 * c[5])))
    d2 = 2 * c[2] + u * (6 * c[3] + u * (12 * c[4] + u * 20 * c[5]))
    d3 = 6 * c[3] + u * (24 * c[4] + u * 60 * c[5])
    d = np.where(past, np.where(short, start.d, d_end)[:, None], d)
    d1, d2, d3 = (np.where(past, 0.0, q) for q in (d1, d2, d3))
    out = np.empty((4, n, s.shape[1]))
    out[0] = d
    out[1] = d1 * s_dot
    out[2] = d2 * s_dot**2 + d1 * s_ddot
    out[3] = d3 * s_dot**3 + 3.0 * d2 * s_dot * s_ddot + d1 * s_dddot
    return out


def braking_motion(
    start: FrenetState, decelerations: np.ndarray, t: np.ndarray, max_jerk: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Brake to a stop at constant decelerations after a jerk-limited ramp, then stand.

    The acceleration moves from the current a0 to -b at ``max_jerk``; the speed falls to
    0 and stays there (no reversing, no creeping).

    Args:
        start: ego Frenet state (s, s_dot, s_ddot used).
        decelerations: b [m/s^2], shape (m,), > 0.
        t: (n_t,) [s].
        max_jerk: [m/s^3].

    Returns:
        (lon (4, m, n_t), stop_distance (m,) [m], stop_time (m,) [s]); the stop may lie
        beyond the grid.
    """
    v0, a0 = max(start.s_dot, 0.0), start.s_ddot
    b = np.asarray(decelerations, dtype=float)[:, None]
    k = np.where(-b < a0, -max_jerk, max_jerk)  # jerk of the ramp
    t_j = np.abs(-b - a0) / max_jerk
    v_j = v0 + a0 * t_j + 0.5 * k * t_j**2
    s_j = v0 * t_j + 0.5 * a0 * t_j**2 + k * t_j**3 / 6.0
    # Stop time: in the constant phase if the ramp ends moving, else a root of the ramp.
    disc = np.sqrt(np.maximum(a0 * a0 - 2.0 * k * v0, 0.0))
    roots = np.stack([(-a0 - disc) / k, (-a0 + disc) / k])
    first_root = np.where(roots > 0, roots, np.inf).min(axis=0)
    t_stop = np.where(v_j > 0, t_j + np.maximum(v_j, 0.0) / b, np.minimum(first_root, t_j))
    t_stop = np.where(v0 <= 0.0, 0.0, t_stop)

    def motion(time: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        ramp = time <= t_j
        tau = np.maximum(time - t_j, 0.0)
        distance = np.where(
            ramp, v0 * time + 0.5 * a0 * time**2 + k * time**3 / 6.0, s_j + v_j * tau - 0.5 * b * tau**2
        )
        speed = np.where(ramp, v0 + a0 * time + 0.5 * k * time**2, v_j - b * tau)
        return distance, speed, ramp

    tt = np.minimum(t[None, :], t_stop)
    distance, speed, ramp = motion(tt)
    moving = t[None, :] < t_stop
    lon = np.empty((4,) + distance.shape)
    lon[0] = start.s + distance
    lon[1] = np.where(moving, np.maximum(speed, 0.0), 0.0)
    lon[2] = np.where(moving, np.where(ramp, a0 + k * tt, -b), 0.0)
    lon[3] = np.where(moving & ramp, k, 0.0)
    stop_distance, _, _ = motion(t_stop)
    return lon, stop_distance[:, 0], t_stop[:, 0]


def _grid_motion(start: FrenetState, t: np.ndarray, config: SamplingConfig, v_max: float) -> CandidatePart:
    """The paper's grid: every end speed x end offset x horizon.

    The longitudinal quartic depends on (end speed, horizon) and, above the low speed,
    the lateral quintic on (end offset, horizon): each is evaluated once per distinct
    pair and copied to the candidates that share it.
    """
    v0 = max(start.s_dot, 0.0)
    speeds, offsets, horizons = [], [], []
    row_speeds, row_horizons = [], []
    d_grid = np.linspace(config.d_min, config.d_max, config.n_offsets)
    for horizon in config.horizons:  # a few horizons, not per trajectory
        lo = max(0.0, v0 - config.max_end_deceleration * horizon)
        hi = min(v_max, v0 + config.max_end_acceleration * horizon)
        v_grid = np.linspace(lo, max(hi, lo), config.n_speeds)
        vv, dd = np.meshgrid(v_grid, d_grid, indexing="ij")
        speeds.append(vv.ravel())
        offsets.append(dd.ravel())
        horizons.append(np.full(vv.size, horizon))
        row_speeds.append(v_grid)
        row_horizons.append(np.full(v_grid.size, horizon))
    end_speed = np.concatenate(speeds)
    end_offset = np.concatenate(offsets)
    horizon = np.concatenate(horizons)
    n_h, n_v, n_d = len(config.horizons), config.n_speeds, config.n_offsets
    # Speed index varies slower than the offset index within a horizon.
    per_horizon = np.repeat(np.arange(n_v), n_d)
    lon_row = (np.arange(n_h)[:, None] * n_v + per_horizon[None, :]).ravel()
    row_horizon = np.concatenate(row_horizons)
    lon = _polynomial_derivatives(
        quartic_coefficients(start.s, start.s_dot, start.s_ddot, np.concatenate(row_speeds), row_horizon),
        t,
        row_horizon,
    )
    lat_row = None  # one lateral motion per candidate
    if v0 < config.low_speed:
        # Werling's low-speed mode: the lateral shift follows the distance travelled.
        at_horizon = np.minimum(np.rint(row_horizon / config.dt).astype(int), len(t) - 1)
        distance = lon[0][np.arange(len(row_horizon)), at_horizon] - start.s
        lat = lateral_along_arc(start, end_offset, distance[lon_row], lon[:, lon_row])
    else:
        lat_horizon = np.repeat(np.asarray(config.horizons, dtype=float), n_d)
        lat = _polynomial_derivatives(
            quintic_coefficients(start.d, start.d_dot, start.d_ddot, np.tile(d_grid, n_h), lat_horizon),
            t,
            lat_horizon,
        )
        lat_row = (np.arange(n_h)[:, None] * n_d + np.tile(np.arange(n_d), n_v)[None, :]).ravel()
    zeros = np.zeros(len(horizon))
    return CandidatePart(
        lon, lon_row, lat, end_speed, end_offset, horizon, CandidateKind.GRID, zeros, lat_row
    )


def _brake_motion(
    start: FrenetState, t: np.ndarray, config: SamplingConfig, vehicle: VehicleConfig
) -> CandidatePart:
    """The braking family.

    Every deceleration (``config.brake_decelerations`` below the emergency deceleration,
    and the emergency deceleration) x every end offset (the grid's and the current one)
    x every lateral fraction of the braking distance. A standing ego gets one: stay.
    """
    emergency = vehicle.emergency_deceleration
    decels = np.array(sorted({b for b in config.brake_decelerations if b < emergency} | {emergency}))
    offsets = np.unique(np.append(np.linspace(config.d_min, config.d_max, config.n_offsets), start.d))
    fractions = np.asarray(config.brake_lateral_fractions)
    if start.s_dot < _STANDING_SPEED:
        decels, offsets, fractions = decels[-1:], np.array([start.d]), fractions[-1:]
    return _braking_part(start, t, decels, offsets, fractions, vehicle.max_jerk)


def _stop_target_motion(
    start: FrenetState,
    t: np.ndarray,
    config: SamplingConfig,
    vehicle: VehicleConfig,
    distances: np.ndarray,
    min_deceleration: float,
) -> CandidatePart | None:
    """Braking candidates that stop after the given distances (stop targets).

    For each distance D the deceleration b with which ``braking_motion`` stops after
    exactly D (its stop distance falls monotonically in b; 40 bisection steps),
    then every end offset and lateral fraction of the braking family. Distances that
    need less than ``min_deceleration`` (far targets) or more than the emergency
    deceleration (unreachable) get none; a standing ego gets none (the braking family
    already stays).

    Args:
        distances: arc lengths the centre travels to each stop [m], shape (k,).
        min_deceleration: [m/s^2].

    Returns:
        The part, or None if no target is reachable this way.
    """
    distances = np.asarray(distances, dtype=float)
    emergency = vehicle.emergency_deceleration
    if start.s_dot < _STANDING_SPEED or distances.size == 0:
        return None
    t0 = np.zeros(1)
    _, reach = braking_motion(start, np.array([min_deceleration, emergency]), t0, vehicle.max_jerk)[:2]
    distances = distances[(distances <= reach[0]) & (distances >= reach[1])]
    if distances.size == 0:
        return None
    lo, hi = np.full(distances.size, min_deceleration), np.full(distances.size, emergency)
    for _ in range(40):  # bisection, vectorised over the targets
        mid = 0.5 * (lo + hi)
        too_far = braking_motion(start, mid, t0, vehicle.max_jerk)[1] > distances
        lo, hi = np.where(too_far, mid, lo), np.where(too_far, hi, mid)
    offsets = np.unique(np.append(np.linspace(config.d_min, config.d_max, config.n_offsets), start.d))
    fractions = np.asarray(config.brake_lateral_fractions)
    return _braking_part(start, t, hi, offsets, fractions, vehicle.max_jerk)


def _braking_part(
    start: FrenetState,
    t: np.ndarray,
    decels: np.ndarray,
    offsets: np.ndarray,
    fractions: np.ndarray,
    max_jerk: float,
) -> CandidatePart:
    """Braking candidates: every deceleration x end offset x lateral fraction."""
    lon_b, stop_distance, stop_time = braking_motion(start, decels, t, max_jerk)
    n_b, n_d, n_f = len(decels), len(offsets), len(fractions)
    which = np.repeat(np.arange(n_b), n_d * n_f)  # deceleration varies slowest
    d_end = np.tile(np.repeat(offsets, n_f), n_b)
    fraction = np.tile(fractions, n_b * n_d)
    lat = lateral_along_arc(start, d_end, fraction * stop_distance[which], lon_b[:, which])
    zeros = np.zeros(len(which))
    kind = CandidateKind.BRAKE
    return CandidatePart(lon_b, which, lat, zeros, d_end, stop_time[which], kind, decels[which])


def sample_candidates(
    start: FrenetState,
    path: ReferencePath,
    config: SamplingConfig,
    vehicle: VehicleConfig,
    previous: PreviousPlan | None = None,
    max_deviation: float = 0.5,
    stop_targets: np.ndarray | None = None,
    min_stop_deceleration: float = 0.5,
) -> Candidates:
    """Sample every family of candidates (see the module docstring).

    Grid end speeds span [v0 - b T, v0 + a T] clipped to [0, v_max] (b and a from
    ``config``); end offsets span [d_min, d_max]. The continuation of ``previous`` is
    the last candidate if the ego is on it (``continue_plan``). ``stop_targets`` add
    braking candidates (kind ``BRAKE``) that stop after exactly those distances
    (``_stop_target_motion``: stop lines), before the continuation.

    Args:
        start: ego Frenet state.
        path: reference path.
        config: families and grid.
        vehicle: the ego's limits (top speed, braking, jerk).
        previous: the plan chosen in the previous cycle, if any.
        max_deviation: largest distance [m] and speed difference [m/s] between the ego
            and ``previous`` at which it is continued.
        stop_targets: arc lengths the centre travels to each stop target [m], shape (k,).
        min_stop_deceleration: stop targets that need less braking get no candidate
            [m/s^2].
    """
    dt = config.dt
    n_t = int(round(max(config.horizons) / dt)) + 1
    t = np.arange(n_t) * dt
    parts = [_grid_motion(start, t, config, vehicle.v_max)]
    if config.brake_candidates:
        parts.append(_brake_motion(start, t, config, vehicle))
    if stop_targets is not None:
        stops = _stop_target_motion(start, t, config, vehicle, stop_targets, min_stop_deceleration)
        if stops is not None:
            parts.append(stops)
    if previous is not None:
        continued = continue_plan(previous, start, t, max_deviation)
        if continued is not None:
            parts.append(continued)
    return _assemble(t, path, parts)


def emergency_braking(
    start: FrenetState, path: ReferencePath, t: np.ndarray, vehicle: VehicleConfig
) -> Candidates:
    """One candidate braking at the emergency deceleration to a stop in its lane position.

    The braking builds up at ``vehicle.max_jerk``; the lateral motion comes to rest at
    the current offset over the braking distance.
    """
    decel = np.array([vehicle.emergency_deceleration])
    lon, stop_distance, stop_time = braking_motion(start, decel, t, vehicle.max_jerk)
    lat = lateral_along_arc(start, np.array([start.d]), stop_distance, lon)
    row, kind = np.zeros(1, dtype=int), CandidateKind.EMERGENCY
    part = CandidatePart(lon, row, lat, np.zeros(1), np.array([start.d]), stop_time, kind, decel)
    return _assemble(t, path, [part])


@dataclass(frozen=True, slots=True)
class CandidateParameters:
    """What the chosen candidate is, in the terms it was sampled in.

    Attributes:
        kind: family (grid, brake, continuation, emergency).
        horizon: its horizon T [s] (a braking candidate's stop time; a continuation's
            remaining horizon).
        end_speed: [m/s]. end_offset: lateral offset from the reference path [m].
        deceleration: a braking candidate's deceleration [m/s^2], else 0.
    """

    kind: CandidateKind
    horizon: float
    end_speed: float
    end_offset: float
    deceleration: float

    @classmethod
    def of(cls, candidates: Candidates, index: int) -> CandidateParameters:
        """The parameters of candidate ``index``."""
        return cls(
            CandidateKind(int(candidates.kind[index])),
            float(candidates.horizon[index]),
            float(candidates.end_speed[index]),
            float(candidates.end_offset[index]),
            float(candidates.deceleration[index]),
        )

    def describe(self) -> str:
        """Short text: "brake 8 m/s^2 to offset -0.5 m", "grid T 1.5 s, 12 m/s, offset 3.5 m"."""
        if self.kind in (CandidateKind.BRAKE, CandidateKind.EMERGENCY) or self.deceleration > 0:
            what = f"brake at {self.deceleration:g} m/s^2 to a stop at offset {self.end_offset:+.2f} m"
        else:
            what = f"T {self.horizon:.2f} s to {self.end_speed:.1f} m/s at offset {self.end_offset:+.2f} m"
        return f"{self.kind.name.lower()}: {what}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form."""
        return {
            "kind": self.kind.name.lower(),
            "horizon": self.horizon,
            "end_speed": self.end_speed,
            "end_offset": self.end_offset,
            "deceleration": self.deceleration,
        }


@dataclass(frozen=True, slots=True, eq=False)
class PreviousPlan:
    """The plan chosen in the previous cycle, kept for its continuation.

    Attributes:
        t: its time grid [s], shape (n_t,).
        lon, lat: its Frenet motion, shape (4, n_t) each (s and d with three derivatives).
        parameters: its family and sampling parameters.
    """

    t: np.ndarray
    lon: np.ndarray
    lat: np.ndarray
    parameters: CandidateParameters

    @classmethod
    def of(cls, candidates: Candidates, index: int) -> PreviousPlan:
        """Candidate ``index`` of ``candidates``."""
        return cls(
            candidates.t.copy(),
            candidates.lon[:, index].copy(),
            candidates.lat[:, index].copy(),
            CandidateParameters.of(candidates, index),
        )


def continue_plan(
    previous: PreviousPlan, start: FrenetState, t: np.ndarray, max_deviation: float
) -> CandidatePart | None:
    """The previous plan from where the ego is on it, over the time grid ``t``.

    The time tau since the plan's start is where its s(t) reaches the ego's s; the plan
    is shifted by tau (whole steps exactly, otherwise linearly interpolated) and held
    after its end (constant speed along the path, constant offset).

    Returns:
        A part with one candidate, or None if the ego is further
        than ``max_deviation`` from the plan (position [m] or speed [m/s]) or the time
        steps differ.
    """
    if len(previous.t) < 2 or len(t) < 2 or not np.isclose(previous.t[1] - previous.t[0], t[1] - t[0]):
        return None
    dt = float(t[1] - t[0])
    s_prev = previous.lon[0]
    if not (s_prev[0] - max_deviation <= start.s <= s_prev[-1] + max_deviation):
        return None
    i = int(np.clip(np.searchsorted(s_prev, start.s), 1, len(s_prev) - 1))
    ds = s_prev[i] - s_prev[i - 1]
    fraction = float(np.clip((start.s - s_prev[i - 1]) / ds, 0.0, 1.0)) if ds > 1e-9 else 0.0
    tau = float(previous.t[i - 1] + fraction * dt)
    shifted_t = tau + t
    steps = tau / dt
    if abs(steps - round(steps)) < 1e-3:
        index = np.minimum(np.arange(len(t)) + int(round(steps)), len(previous.t) - 1)
        lon, lat = previous.lon[:, index].copy(), previous.lat[:, index].copy()
    else:
        lon = np.stack([np.interp(shifted_t, previous.t, q) for q in previous.lon])
        lat = np.stack([np.interp(shifted_t, previous.t, q) for q in previous.lat])
    beyond = shifted_t > previous.t[-1] + 1e-9
    if beyond.any():  # hold: constant speed along the path, constant offset
        extra = shifted_t[beyond] - previous.t[-1]
        lon[0, beyond] = previous.lon[0, -1] + previous.lon[1, -1] * extra
        lon[1, beyond] = previous.lon[1, -1]
        lon[2:, beyond] = 0.0
        lat[0, beyond] = previous.lat[0, -1]
        lat[1:, beyond] = 0.0
    if abs(lat[0, 0] - start.d) > max_deviation or abs(lon[1, 0] - start.s_dot) > max_deviation:
        return None
    kept = previous.parameters
    return CandidatePart(
        lon[:, None, :],
        np.zeros(1, dtype=int),
        lat[:, None, :],
        np.array([kept.end_speed]),
        np.array([kept.end_offset]),
        np.array([max(kept.horizon - tau, 0.0)]),
        CandidateKind.CONTINUATION,
        np.array([kept.deceleration]),
    )


def frenet_to_candidates(
    t: np.ndarray,
    lon: np.ndarray,
    lat: np.ndarray,
    path: ReferencePath,
    end_speed: np.ndarray,
    end_offset: np.ndarray,
    horizon: np.ndarray,
) -> Candidates:
    """Cartesian candidates (kind ``GRID``) from Frenet motion.

    Args:
        t: (n_t,) [s].
        lon: (4, n, n_t) s and its first three time derivatives.
        lat: (4, n, n_t) d and its first three time derivatives.
        path: reference path.
        end_speed: (n,) end speeds [m/s], kept as a sampling parameter.
        end_offset: (n,) end offsets [m], kept.
        horizon: (n,) horizons [s], kept.
    """
    n, kind = lon.shape[1], CandidateKind.GRID
    part = CandidatePart(lon, np.arange(n), lat, end_speed, end_offset, horizon, kind, np.zeros(n))
    return _assemble(t, path, [part])


#: Below this speed [m/s] the ego stands: the braking family collapses to one candidate.
_STANDING_SPEED = 0.05
#: Shorter lateral shifts [m] hold the offset (see lateral_along_arc).
_MIN_LATERAL_DISTANCE = 0.5


def _assemble(t: np.ndarray, path: ReferencePath, parts: list[CandidatePart]) -> Candidates:
    """Concatenate family parts and convert them to Cartesian candidates."""
    lon_rows = np.concatenate([p.lon for p in parts], axis=1)
    offsets = np.cumsum([0] + [p.lon.shape[1] for p in parts[:-1]])
    lon_row = np.concatenate([p.lon_row + offset for p, offset in zip(parts, offsets, strict=True)])
    # Each part's lateral motions written once into the whole set's (no gather, then copy).
    sizes = [p.end_speed.size for p in parts]
    lat = np.empty((4, sum(sizes), len(t)))
    first = 0
    for part, size in zip(parts, sizes, strict=True):  # a few families, not per trajectory
        if part.lat_row is None:
            lat[:, first : first + size] = part.lat
        else:
            np.take(part.lat, part.lat_row, axis=1, out=lat[:, first : first + size], mode="clip")
        first += size
    end_speed, end_offset, horizon, deceleration = (
        np.concatenate([getattr(p, name) for p in parts])
        for name in ("end_speed", "end_offset", "horizon", "deceleration")
    )
    kind = np.concatenate(
        [np.full(size, int(p.kind), dtype=np.int8) for p, size in zip(parts, sizes, strict=True)]
    )
    lon = lon_rows[:, lon_row]
    x, y, yaw, v, a, kappa = cartesian_states(lon_rows, lon_row, lat, path)
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.0
    weights = np.full(len(t), dt)  # rectangle rule over the samples
    return Candidates(
        t=t,
        x=x,
        y=y,
        yaw=yaw,
        v=v,
        a=a,
        kappa=kappa,
        s=lon[0],
        d=lat[0],
        s_dot=lon[1],
        end_speed=end_speed,
        end_offset=end_offset,
        horizon=horizon,
        kind=kind,
        deceleration=deceleration,
        jerk_lon=np.square(lon[3]) @ weights,
        jerk_lat=np.square(lat[3]) @ weights,
        lon=lon,
        lat=lat,
    )
