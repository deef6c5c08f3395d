"""Tracking control of the planar bodies: PD plus feed-forward, friction-circle clamp.

All functions are vectorised over bodies. The planar force of a body is
F = m (a_ref + kp (p_ref - p) + kd (v_ref - v)), clamped to the friction circle
|F| <= mu m g; its yaw torque is I (kp_yaw (yaw_ref - yaw) + kd_yaw (r_ref - r)),
clamped to ``torque_limit_per_inertia`` I. A crashed body gets no drive force: it
brakes to rest with at most mu m g (``brake_forces``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ethical_planner.geometry import wrap_angle_in_place
from ethical_planner.validation import check_positive

GRAVITY = 9.81  # [m/s^2]


@dataclass(frozen=True, slots=True)
class ControlConfig:
    """Gains and limits of the tracking controller.

    Attributes:
        kp: position gain [1/s^2]. kd: velocity gain [1/s].
        kp_yaw: heading gain [1/s^2]. kd_yaw: yaw-rate gain [1/s].
        friction_mu: tyre friction coefficient; the force is clamped to mu m g.
        torque_limit_per_inertia: largest yaw acceleration [rad/s^2].
        brake_time_constant: below speed / this, braking scales down smoothly [s].
    """

    kp: float = 100.0
    kd: float = 20.0
    kp_yaw: float = 400.0
    kd_yaw: float = 40.0
    friction_mu: float = 0.9
    torque_limit_per_inertia: float = 40.0
    brake_time_constant: float = 0.05

    def __post_init__(self) -> None:
        check_positive(
            "control",
            kp=self.kp,
            kd=self.kd,
            kp_yaw=self.kp_yaw,
            kd_yaw=self.kd_yaw,
            friction_mu=self.friction_mu,
            torque_limit_per_inertia=self.torque_limit_per_inertia,
            brake_time_constant=self.brake_time_constant,
        )


def tracking_forces(
    config: ControlConfig,
    mass: np.ndarray,
    inertia: np.ndarray,
    qpos: np.ndarray,
    qvel: np.ndarray,
    p_ref: np.ndarray,
    v_ref: np.ndarray,
    a_ref: np.ndarray,
    yaw_ref: np.ndarray,
    yaw_rate_ref: np.ndarray,
    accel_limit: np.ndarray | None = None,
) -> np.ndarray:
    """Motor inputs that make bodies track references.

    Args:
        config: gains and limits.
        mass: [kg], shape (k,).
        inertia: yaw inertia [kg m^2], shape (k,).
        qpos: (k, 3) x, y [m], yaw [rad].
        qvel: (k, 3) vx, vy [m/s], yaw rate [rad/s].
        p_ref: (k, 2) reference positions [m].
        v_ref: (k, 2) reference velocities [m/s].
        a_ref: (k, 2) feed-forward accelerations [m/s^2].
        yaw_ref: (k,) reference headings [rad].
        yaw_rate_ref: (k,) reference yaw rates [rad/s].
        accel_limit: (k,) largest planar acceleration of each body [m/s^2]; None is
            the friction circle ``friction_mu g`` for every body.

    Returns:
        (k, 3) Fx [N], Fy [N], torque [N m].
    """
    acc = a_ref + config.kp * (p_ref - qpos[:, :2]) + config.kd * (v_ref - qvel[:, :2])
    norm = np.hypot(acc[:, 0], acc[:, 1])
    limit = config.friction_mu * GRAVITY if accel_limit is None else accel_limit
    scale = np.minimum(1.0, limit / np.maximum(norm, 1e-9))
    out = np.empty((len(mass), 3))
    out[:, :2] = acc * (scale * mass)[:, None]
    # A heading error of exactly +-pi wraps to +pi and turns counter-clockwise (either
    # way is equally short).
    heading_error = wrap_angle_in_place(yaw_ref - qpos[:, 2])
    yaw_acc = config.kp_yaw * heading_error + config.kd_yaw * (yaw_rate_ref - qvel[:, 2])
    lim = config.torque_limit_per_inertia
    out[:, 2] = inertia * np.clip(yaw_acc, -lim, lim)
    return out


def brake_forces(
    config: ControlConfig, mass: np.ndarray, inertia: np.ndarray, qvel: np.ndarray
) -> np.ndarray:
    """Forces of bodies braking (sliding) to rest after a crash.

    Decelerates at mu g, less below ``speed / brake_time_constant`` so the body
    stops without chattering; the yaw rate is damped the same way.

    Args:
        config: limits.
        mass: (k,) [kg].
        inertia: (k,) yaw inertia [kg m^2].
        qvel: (k, 3) velocities: vx, vy [m/s], yaw rate [rad/s].

    Returns:
        (k, 3) Fx [N], Fy [N], torque [N m].
    """
    speed = np.hypot(qvel[:, 0], qvel[:, 1])
    decel = np.minimum(config.friction_mu * GRAVITY, speed / config.brake_time_constant)
    direction = qvel[:, :2] / np.maximum(speed, 1e-9)[:, None]
    out = np.empty((len(mass), 3))
    out[:, :2] = -(decel * mass)[:, None] * direction
    lim = config.torque_limit_per_inertia
    out[:, 2] = -inertia * np.clip(qvel[:, 2] / config.brake_time_constant, -lim, lim)
    return out


class TrajectoryReference:
    """A planned trajectory sampled for the controller.

    Positions are interpolated with cubic Hermite splines through the planned
    positions and velocities, the other quantities linearly; beyond the end the
    trajectory continues at its last speed along its last heading.

    Args:
        t0: absolute time of the first sample [s].
        t: sample times relative to the first [s], shape (m,), increasing, t[0] = 0.
        x, y: positions [m], shape (m,). yaw: headings [rad]. v: speeds [m/s].
        a: accelerations along the path [m/s^2]. kappa: curvatures [1/m].
    """

    __slots__ = ("t0", "t", "x", "y", "yaw", "v", "a", "kappa", "_vx", "_vy")

    def __init__(
        self,
        t0: float,
        t: np.ndarray,
        x: np.ndarray,
        y: np.ndarray,
        yaw: np.ndarray,
        v: np.ndarray,
        a: np.ndarray,
        kappa: np.ndarray,
    ) -> None:
        arrays = [np.asarray(q, dtype=float) for q in (t, x, y, yaw, v, a, kappa)]
        m = arrays[0].shape
        if len(m) != 1 or m[0] < 2 or any(q.shape != m for q in arrays):
            raise ValueError("trajectory arrays t, x, y, yaw, v, a, kappa must share a shape (m>=2,)")
        if not all(np.all(np.isfinite(q)) for q in arrays):
            raise ValueError("trajectory arrays must be finite")
        if np.any(np.diff(arrays[0]) <= 0):
            raise ValueError("trajectory times t must be strictly increasing")
        self.t0 = float(t0)
        self.t, self.x, self.y = arrays[0], arrays[1], arrays[2]
        self.yaw = np.unwrap(arrays[3])
        self.v, self.a, self.kappa = arrays[4], arrays[5], arrays[6]
        self._vx = self.v * np.cos(self.yaw)
        self._vy = self.v * np.sin(self.yaw)

    @property
    def end_time(self) -> float:
        """Absolute time of the last sample [s]."""
        return self.t0 + float(self.t[-1])

    def sample(self, time: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
        """Reference at absolute ``time`` [s].

        Returns:
            (p (2,) [m], v (2,) [m/s], a (2,) [m/s^2], yaw [rad], yaw rate [rad/s]).
        """
        tau = time - self.t0
        t = self.t
        if tau >= t[-1]:
            extra = tau - t[-1]
            yaw = float(self.yaw[-1])
            v = float(max(self.v[-1], 0.0))
            heading = np.array([np.cos(yaw), np.sin(yaw)])
            p = np.array([self.x[-1], self.y[-1]]) + extra * v * heading
            return p, v * heading, np.zeros(2), yaw, 0.0
        tau = max(tau, 0.0)
        i = int(np.searchsorted(t, tau, side="right") - 1)
        i = min(max(i, 0), len(t) - 2)
        h = t[i + 1] - t[i]
        u = (tau - t[i]) / h
        u2, u3 = u * u, u * u * u
        h00, h10, h01, h11 = 2 * u3 - 3 * u2 + 1, u3 - 2 * u2 + u, -2 * u3 + 3 * u2, u3 - u2
        d00, d10, d01, d11 = 6 * u2 - 6 * u, 3 * u2 - 4 * u + 1, -6 * u2 + 6 * u, 3 * u2 - 2 * u
        px = h00 * self.x[i] + h10 * h * self._vx[i] + h01 * self.x[i + 1] + h11 * h * self._vx[i + 1]
        py = h00 * self.y[i] + h10 * h * self._vy[i] + h01 * self.y[i + 1] + h11 * h * self._vy[i + 1]
        vx = (d00 * self.x[i] + d01 * self.x[i + 1]) / h + d10 * self._vx[i] + d11 * self._vx[i + 1]
        vy = (d00 * self.y[i] + d01 * self.y[i + 1]) / h + d10 * self._vy[i] + d11 * self._vy[i + 1]
        yaw = float(self.yaw[i] + u * (self.yaw[i + 1] - self.yaw[i]))
        v = float(self.v[i] + u * (self.v[i + 1] - self.v[i]))
        a_lon = float(self.a[i] + u * (self.a[i + 1] - self.a[i]))
        kappa = float(self.kappa[i] + u * (self.kappa[i + 1] - self.kappa[i]))
        c, s = np.cos(yaw), np.sin(yaw)
        a_lat = v * v * kappa
        acc = np.array([a_lon * c - a_lat * s, a_lon * s + a_lat * c])
        return np.array([px, py]), np.array([vx, vy]), acc, yaw, v * kappa
