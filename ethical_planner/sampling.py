"""Frenet sampling of candidate trajectories (paper Fig. 1, step 1), vectorised.

Longitudinal motion is a quartic s(t) to an end speed with zero end acceleration,
lateral motion a quintic d(t) to an end offset at rest; both are converted to
Cartesian states with exact derivatives of the Frenet frame (no finite
differences), so speed, acceleration and curvature are those of the motion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ethical_planner.config import SamplingConfig
from ethical_planner.reference_path import ReferencePath
from ethical_planner.road_users import KinematicState


@dataclass(frozen=True, slots=True, eq=False)
class FrenetState:
    """Ego state in the Frenet frame of the reference path (time derivatives)."""

    s: float
    s_dot: float
    s_ddot: float
    d: float
    d_dot: float
    d_ddot: float


def frenet_state(state: KinematicState, path: ReferencePath) -> FrenetState:
    """Convert a Cartesian state to Frenet coordinates along ``path``.

    Accelerations neglect the path's curvature terms; the error is second order and
    vanishes on straight roads.
    """
    s, d = path.to_frenet(np.array(state.x), np.array(state.y))
    s, d = float(s), float(d)
    _, _, theta, kappa, _ = path.evaluate(np.array(s))
    delta = state.yaw - float(theta)
    one_minus_kd = 1.0 - float(kappa) * d
    if one_minus_kd <= 0.05:
        raise ValueError(f"ego lies {d:.1f} m from the reference path, beyond its radius of curvature")
    return FrenetState(
        s=s,
        s_dot=state.v * np.cos(delta) / one_minus_kd,
        s_ddot=state.a * np.cos(delta),
        d=d,
        d_dot=state.v * np.sin(delta),
        d_ddot=state.a * np.sin(delta),
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
        end_speed, end_offset, horizon: sampling parameters, shape (n_traj,).
        jerk_lon, jerk_lat: integrated squared jerk [m^2/s^5], shape (n_traj,).
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
    jerk_lon: np.ndarray
    jerk_lat: np.ndarray

    @property
    def n_traj(self) -> int:
        """Number of candidates."""
        return self.x.shape[0]


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
    Candidates share one to three horizons, so the powers tt^p, tt = min(t, T), are
    computed once per horizon on (n_t,) instead of per element; the sums keep their
    order, so the results are the same to the last bit (a stopped candidate's heading,
    atan2 of two rounding residues, depends on those bits).

    Args:
        coeffs: (n_traj, k) lowest power first.
        t: times [s], shape (n_t,).
        horizon: horizon T of each polynomial [s], shape (n_traj,).

    Returns:
        Shape (4, n_traj, n_t): value, first, second, third derivative.
    """
    n, k = coeffs.shape
    out = np.zeros((4, n, t.size))
    degree = k - 1
    for value in np.unique(horizon):  # one to three horizons, not per trajectory
        rows = np.flatnonzero(horizon == value)
        if rows[-1] - rows[0] + 1 == rows.size:  # contiguous, as sample_candidates builds them
            rows = slice(rows[0], rows[-1] + 1)
        tt = np.minimum(t, value)
        powers = np.stack([tt**p for p in range(degree + 1)])  # (k, n_t)
        c = coeffs[rows].T[:, :, None]  # (k, n, 1)
        for order in range(4):  # four derivative orders, not a loop over data
            if order > degree:
                continue
            # factor_p c_p tt^(p - order) for p = order..degree, (k - order, n, n_t),
            # summed over p in order (a reduction over the first axis is sequential).
            factors = np.array(
                [np.prod(np.arange(p - order + 1, p + 1)) if order else 1.0 for p in range(order, k)]
            )
            terms = factors[:, None, None] * c[order:] * powers[: k - order, None, :]
            np.add.reduce(terms, axis=0, out=out[order, rows])
        past = t > value
        if past.any():
            overtime = np.maximum(t - value, 0.0)
            out[0, rows] += out[1, rows] * overtime
            out[2:, rows, past] = 0.0
    return out


def sample_candidates(
    start: FrenetState,
    path: ReferencePath,
    config: SamplingConfig,
    v_max: float,
) -> Candidates:
    """Sample the candidate grid: end speeds x end offsets x horizons.

    End speeds span [v0 - b T, v0 + a T] clipped to [0, v_max] (b and a from
    ``config``); end offsets span [d_min, d_max].

    Args:
        start: ego Frenet state.
        path: reference path.
        config: grid.
        v_max: highest end speed [m/s].
    """
    dt = config.dt
    t_max = max(config.horizons)
    n_t = int(round(t_max / dt)) + 1
    t = np.arange(n_t) * dt
    v0 = max(start.s_dot, 0.0)
    speeds, offsets, horizons = [], [], []
    for horizon in config.horizons:  # one to three horizons, not per trajectory
        lo = max(0.0, v0 - config.max_end_deceleration * horizon)
        hi = min(v_max, v0 + config.max_end_acceleration * horizon)
        v_grid = np.linspace(lo, max(hi, lo), config.n_speeds)
        d_grid = np.linspace(config.d_min, config.d_max, config.n_offsets)
        vv, dd = np.meshgrid(v_grid, d_grid, indexing="ij")
        speeds.append(vv.ravel())
        offsets.append(dd.ravel())
        horizons.append(np.full(vv.size, horizon))
    end_speed = np.concatenate(speeds)
    end_offset = np.concatenate(offsets)
    horizon = np.concatenate(horizons)

    lon_coeffs = quartic_coefficients(start.s, start.s_dot, start.s_ddot, end_speed, horizon)
    lat_coeffs = quintic_coefficients(start.d, start.d_dot, start.d_ddot, end_offset, horizon)
    out = _empty_states(len(end_speed), n_t)
    # Blocks of trajectories, not single ones: every temporary then stays small enough to
    # be reused by the allocator instead of page-faulting in a fresh mapping.
    for first in range(0, len(end_speed), _BLOCK):
        block = slice(first, first + _BLOCK)
        _cartesian_states(
            t,
            _polynomial_derivatives(lon_coeffs[block], t, horizon[block]),
            _polynomial_derivatives(lat_coeffs[block], t, horizon[block]),
            path,
            {name: array[block] for name, array in out.items()},
        )
    return _candidates(t, out, end_speed, end_offset, horizon)


def emergency_braking(
    start: FrenetState, path: ReferencePath, t: np.ndarray, deceleration: float
) -> Candidates:
    """One candidate braking at ``deceleration`` [m/s^2] to a stop in its current lane position.

    Its lateral motion comes to rest at the current offset within one second.
    """
    v0 = max(start.s_dot, 0.0)
    t_stop = v0 / deceleration
    moving = t < t_stop
    s = start.s + np.where(moving, v0 * t - 0.5 * deceleration * t**2, 0.5 * v0 * t_stop)
    lon = np.stack(
        [
            s,
            np.where(moving, v0 - deceleration * t, 0.0),
            np.where(moving, -deceleration, 0.0),
            np.zeros_like(t),
        ]
    )[:, None, :]
    settle = np.array([min(1.0, float(t[-1])) if t[-1] > 0 else 1.0])
    lat = _polynomial_derivatives(
        quintic_coefficients(start.d, start.d_dot, start.d_ddot, np.array([start.d]), settle),
        t,
        settle,
    )
    return frenet_to_candidates(t, lon, lat, path, np.array([0.0]), np.array([start.d]), np.array([t_stop]))


def frenet_to_candidates(
    t: np.ndarray,
    lon: np.ndarray,
    lat: np.ndarray,
    path: ReferencePath,
    end_speed: np.ndarray,
    end_offset: np.ndarray,
    horizon: np.ndarray,
) -> Candidates:
    """Cartesian candidates from Frenet motion.

    Args:
        t: (n_t,) [s].
        lon: (4, n, n_t) s and its first three time derivatives.
        lat: (4, n, n_t) d and its first three time derivatives.
        path: reference path.
        end_speed: (n,) end speeds [m/s], kept as a sampling parameter.
        end_offset: (n,) end offsets [m], kept.
        horizon: (n,) horizons [s], kept.
    """
    out = _empty_states(lon.shape[1], len(t))
    _cartesian_states(t, lon, lat, path, out)
    return _candidates(t, out, end_speed, end_offset, horizon)


#: Trajectories converted per block (see sample_candidates).
_BLOCK = 256
_STATE_NAMES = ("x", "y", "yaw", "v", "a", "kappa", "s", "d", "s_dot", "jerk_lon", "jerk_lat")


def _empty_states(n: int, n_t: int) -> dict[str, np.ndarray]:
    """Uninitialised per-step (n, n_t) and per-candidate (n,) output arrays by name."""
    return {name: np.empty(n if name.startswith("jerk") else (n, n_t)) for name in _STATE_NAMES}


def _candidates(
    t: np.ndarray,
    out: dict[str, np.ndarray],
    end_speed: np.ndarray,
    end_offset: np.ndarray,
    horizon: np.ndarray,
) -> Candidates:
    """Wrap filled output arrays (see _empty_states) as ``Candidates``."""
    return Candidates(t=t, end_speed=end_speed, end_offset=end_offset, horizon=horizon, **out)


def _cartesian_states(
    t: np.ndarray, lon: np.ndarray, lat: np.ndarray, path: ReferencePath, out: dict[str, np.ndarray]
) -> None:
    """Cartesian states of Frenet motions, written into ``out`` (see _empty_states).

    Args:
        t: (n_t,) [s].
        lon: (4, n, n_t) s and its first three time derivatives.
        lat: (4, n, n_t) d and its first three time derivatives.
        path: reference path.
        out: arrays of shape (n, n_t), jerks (n,), written.
    """
    s, s_dot, s_ddot, s_dddot = lon
    d, d_dot, d_ddot, d_dddot = lat
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.0
    x_r, y_r, theta_r, kappa_r, dkappa_r = path.evaluate(s)

    # Velocity and acceleration in the path's (tangent, normal) frame, exact. Written
    # with in-place operations (every temporary of this size costs page faults) but
    # the same operations in the same order as the plain formulas, so the results are
    # the same to the last bit (see _polynomial_derivatives).
    one_minus_kd = kappa_r * d
    np.subtract(1.0, one_minus_kd, out=one_minus_kd)
    along = s_dot * one_minus_kd
    across = d_dot
    # along_dot = s'' (1 - kappa d) - s' (kappa' s' d + kappa d')
    along_dot = dkappa_r * s_dot
    along_dot *= d
    tmp = kappa_r * d_dot
    along_dot += tmp
    np.multiply(s_dot, along_dot, out=along_dot)
    np.multiply(s_ddot, one_minus_kd, out=tmp)
    np.subtract(tmp, along_dot, out=along_dot)
    # acc_t = along_dot - across s' kappa, acc_n = along s' kappa + d''
    acc_t = across * s_dot
    acc_t *= kappa_r
    np.subtract(along_dot, acc_t, out=acc_t)
    acc_n = along * s_dot
    acc_n *= kappa_r
    acc_n += d_ddot
    speed = out["v"]
    np.hypot(along, across, out=speed)
    safe = np.maximum(speed, 1e-9)
    moving = speed > 1e-3
    # kappa = (along acc_n - across acc_t) / |v|^3, a = (along acc_t + across acc_n) / |v|
    kappa = out["kappa"]
    np.multiply(along, acc_n, out=kappa)
    np.multiply(across, acc_t, out=tmp)
    kappa -= tmp
    accel = out["a"]
    np.multiply(along, acc_t, out=accel)
    np.multiply(across, acc_n, out=tmp)
    accel += tmp
    accel /= safe
    np.power(safe, 3, out=tmp)
    kappa /= tmp
    np.logical_not(moving, out=moving)
    kappa[moving] = 0.0
    np.copyto(accel, s_ddot, where=moving)

    x = out["x"]
    np.sin(theta_r, out=x)
    x *= d
    np.subtract(x_r, x, out=x)
    y = out["y"]
    np.cos(theta_r, out=y)
    y *= d
    y += y_r
    yaw = out["yaw"]
    np.arctan2(across, along, out=yaw)
    yaw += theta_r
    out["s"][...] = s
    out["d"][...] = d
    out["s_dot"][...] = s_dot
    weights = np.full(len(t), dt)  # rectangle rule over the samples
    np.square(s_dddot, out=tmp)
    np.matmul(tmp, weights, out=out["jerk_lon"])
    np.square(d_dddot, out=tmp)
    np.matmul(tmp, weights, out=out["jerk_lat"])
