"""Arc-length parameterised, smooth reference path and Frenet <-> Cartesian conversion.

The pose of the path at an arc length, and the Cartesian states of Frenet motions along
it (``cartesian_states``), are compiled kernels (``ethical_planner.jit``); both read the
path's samples by linear interpolation with exactly the arithmetic of ``numpy.interp``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial import cKDTree

from ethical_planner.jit import kernel

#: Spacing of the dense internal resampling [m].
_RESAMPLE_STEP_M = 0.25


def curvature(dx: np.ndarray, dy: np.ndarray, ddx: np.ndarray, ddy: np.ndarray) -> np.ndarray:
    """Signed curvature [1/m] of a planar curve from its first and second derivatives.

    kappa = (x' y'' - y' x'') / (x'^2 + y'^2)^(3/2), for any parameterisation (the
    reference implementation misplaces a parenthesis here).
    """
    return (dx * ddy - dy * ddx) / np.power(dx * dx + dy * dy, 1.5)


@dataclass(frozen=True, slots=True, eq=False)
class ReferencePath:
    """A smooth planar curve sampled densely by true arc length.

    Build it with ``ReferencePath.from_polyline``. Beyond its ends the path is
    continued as a straight line along the end heading (zero curvature), so
    Frenet conversion is defined for every s.

    Attributes:
        s: arc length of the samples [m], shape (m,), s[0] = 0.
        x, y: sample positions [m], shape (m,).
        theta: heading [rad], shape (m,), unwrapped.
        kappa: curvature [1/m], shape (m,).
        dkappa: d kappa / d s [1/m^2], shape (m,).
    """

    s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    kappa: np.ndarray
    dkappa: np.ndarray
    _tree: cKDTree

    @classmethod
    def from_polyline(cls, points: np.ndarray | list) -> ReferencePath:
        """Fit a cubic spline through a polyline and resample it by arc length.

        Args:
            points: waypoints [m], shape (n, 2), n >= 2, consecutive points distinct.

        Raises:
            ValueError: for a wrong shape, non-finite values or repeated points.
        """
        pts = np.asarray(points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2:
            raise ValueError(f"reference path points must have shape (n, 2) with n >= 2, got {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise ValueError("reference path points must be finite numbers")
        chord = np.hypot(*np.diff(pts, axis=0).T)
        if np.any(chord < 1e-6):
            raise ValueError("reference path points must not repeat (two consecutive are equal)")
        u = np.concatenate([[0.0], np.cumsum(chord)])
        # Two points give a straight line; a natural spline keeps three or more smooth.
        bc = "natural" if len(pts) > 2 else "not-a-knot"
        spline = CubicSpline(u, pts, bc_type=bc)
        n_dense = max(int(np.ceil(u[-1] / (_RESAMPLE_STEP_M / 4))), 8)
        u_dense = np.linspace(0.0, u[-1], n_dense + 1)
        p = spline(u_dense)
        # True arc length by integrating |p'(u)| (trapezoid on a 4x finer grid).
        speed = np.linalg.norm(spline(u_dense, 1), axis=1)
        s_dense = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(u_dense))])
        n_out = max(int(np.ceil(s_dense[-1] / _RESAMPLE_STEP_M)), 2)
        s = np.linspace(0.0, s_dense[-1], n_out + 1)
        u_s = np.interp(s, s_dense, u_dense)
        p = spline(u_s)
        d1 = spline(u_s, 1)
        d2 = spline(u_s, 2)
        theta = np.unwrap(np.arctan2(d1[:, 1], d1[:, 0]))
        kappa = curvature(d1[:, 0], d1[:, 1], d2[:, 0], d2[:, 1])
        dkappa = np.gradient(kappa, s)
        return cls(s, p[:, 0].copy(), p[:, 1].copy(), theta, kappa, dkappa, cKDTree(p))

    @property
    def length(self) -> float:
        """Total arc length [m]."""
        return float(self.s[-1])

    def evaluate(self, s: np.ndarray) -> tuple[np.ndarray, ...]:
        """Pose and curvature of the path at arc lengths ``s`` (any shape).

        Returns:
            (x, y, theta, kappa, dkappa), each of the shape of ``s``; beyond the
            ends the path continues straight.
        """
        s = np.asarray(s, dtype=float)
        out = np.empty((5, s.size))
        _evaluate_path(np.ascontiguousarray(s).reshape(-1), *self._samples(), out)
        return tuple(row.reshape(s.shape) for row in out)

    def _samples(self) -> tuple[np.ndarray, ...]:
        """The sample arrays the kernels read: s, x, y, theta, kappa, dkappa."""
        return self.s, self.x, self.y, self.theta, self.kappa, self.dkappa

    def heading(self, s: np.ndarray | float) -> np.ndarray:
        """Path heading [rad] at arc length ``s``."""
        return self.evaluate(s)[2]

    def to_cartesian(self, s: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Cartesian position [m] of Frenet coordinates (s along, d left of the path)."""
        x_r, y_r, theta, _, _ = self.evaluate(s)
        d = np.asarray(d, dtype=float)
        return x_r - d * np.sin(theta), y_r + d * np.cos(theta)

    def to_frenet(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project Cartesian points onto the path.

        Args:
            x, y: positions [m], same shape.

        Returns:
            (s, d): arc length of the foot point [m] (may lie beyond the ends) and
            signed lateral offset [m], positive to the left.
        """
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        shape = np.broadcast_shapes(x.shape, y.shape)
        px = np.broadcast_to(x, shape).ravel()
        py = np.broadcast_to(y, shape).ravel()
        if not (np.isfinite(px).all() and np.isfinite(py).all()):
            # The compiled nearest-sample search would leave a non-finite point's foot
            # unset (no distance compares below inf), i.e. return memory garbage.
            raise ValueError("to_frenet: positions x and y must be finite (a diverged simulation?)")
        if px.size * self.s.size <= _BRUTE_FORCE_PAIRS:
            nearest = np.empty(px.size, dtype=np.int64)
            _nearest_sample(px, py, self.x, self.y, nearest)
        else:
            _, nearest = self._tree.query(np.column_stack([px, py]))
        # Project onto the segment after (or, at the end, before) the nearest sample.
        best_s = np.empty_like(px)
        best_d = np.empty_like(px)
        _project(px, py, np.asarray(nearest, dtype=np.int64), self.s, self.x, self.y, best_s, best_d)
        return best_s.reshape(shape), best_d.reshape(shape)


def cartesian_states(
    lon: np.ndarray, lon_row: np.ndarray, lat: np.ndarray, path: ReferencePath
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cartesian states of Frenet motions along ``path``, with exact derivatives.

    Velocity and acceleration in the path's (tangent, normal) frame follow from s, d and
    their time derivatives and the path's curvature kappa and its derivative:
    along = s' (1 - kappa d), across = d', acc_t = along' - across s' kappa,
    acc_n = along s' kappa + d''; speed |v| = hypot(along, across), heading
    theta + atan2(across, along), curvature (along acc_n - across acc_t) / |v|^3 and
    tangential acceleration (along acc_t + across acc_n) / |v|. Below 1 mm/s a body
    stands: its curvature is 0, its acceleration s'', and it keeps the heading it
    stopped with (atan2 of two rounding residues is no heading); one standing from the
    start points along the path. A motion rolling backwards (s' < 0, which the validity
    check tolerates up to a few cm/s) keeps its nose forward: its heading is that of
    the reversed velocity.

    Motions that share their longitudinal part (``lon_row``) share the path's pose,
    evaluated once per distinct longitudinal motion.

    Args:
        lon: distinct longitudinal motions, s and its first three time derivatives,
            shape (4, r, n_t).
        lon_row: the longitudinal motion of each of the n motions, indices into ``lon``,
            shape (n,).
        lat: d and its first three time derivatives, shape (4, n, n_t).
        path: the reference path.

    Returns:
        (x, y, yaw, v, a, kappa), each of shape (n, n_t): centre [m], heading [rad],
        speed [m/s], tangential acceleration [m/s^2], curvature [1/m].
    """
    lon = np.ascontiguousarray(lon, dtype=float)
    lat = np.ascontiguousarray(lat, dtype=float)
    lon_row = np.ascontiguousarray(lon_row, dtype=np.int64)
    in_range = not lon_row.size or 0 <= lon_row.min() <= lon_row.max() < lon.shape[1]
    if lon_row.shape != lat.shape[1:2] or not in_range:
        raise ValueError(
            f"lon_row must index the {lon.shape[1]} longitudinal motions, one per lateral motion"
        )
    out = np.empty((6,) + lat.shape[1:])
    _cartesian_states(lon, lon_row, lat, *path._samples(), out)
    return out[0], out[1], out[2], out[3], out[4], out[5]


#: ``to_frenet`` finds the nearest sample by comparing every (point, sample) pair up to
#: this many pairs (one point on a path of up to ~20,000 samples, ~1 ns a pair), and by
#: the k-d tree beyond (whose call alone costs tens of microseconds).
_BRUTE_FORCE_PAIRS = 20_000

# --- compiled kernels ------------------------------------------------------------------------


@kernel
def _nearest_sample(
    px: np.ndarray, py: np.ndarray, path_x: np.ndarray, path_y: np.ndarray, out: np.ndarray
) -> None:
    """Index of the path sample nearest to each point (squared Euclidean distance), out (m,).

    The first of equally near samples; the k-d tree finds the same sample unless two are
    equally near to the last bit.
    """
    for i in range(px.size):
        best, nearest = math.inf, 0
        for j in range(path_x.size):
            dx, dy = path_x[j] - px[i], path_y[j] - py[i]
            distance = dx * dx + dy * dy
            if distance < best:
                best, nearest = distance, j
        out[i] = nearest


@kernel
def _project(
    px: np.ndarray,
    py: np.ndarray,
    nearest: np.ndarray,
    path_s: np.ndarray,
    path_x: np.ndarray,
    path_y: np.ndarray,
    best_s: np.ndarray,
    best_d: np.ndarray,
) -> None:
    """Kernel of ``ReferencePath.to_frenet``: each point onto the segments beside its nearest sample.

    The segment after the nearest sample (before it at the path's end) is tried first,
    then the one before it (after it at the start); the second replaces the first only
    if it is nearer by more than 1e-12 m. Only the first and the last segment extend
    beyond the path's ends. Writes best_s (arc length of the foot point [m]) and best_d
    (signed lateral offset [m], positive to the left), shape (m,) each.
    """
    last = path_s.size - 1
    for i in range(px.size):
        x, y = px[i], py[i]
        found = math.inf
        for attempt in range(2):
            j = min(nearest[i], last - 1) if attempt == 0 else max(nearest[i] - 1, 0)
            ax, ay = path_x[j], path_y[j]
            ex, ey = path_x[j + 1] - ax, path_y[j + 1] - ay
            seg = math.hypot(ex, ey)
            ux, uy = ex / seg, ey / seg
            along = (x - ax) * ux + (y - ay) * uy
            lo = -math.inf if j == 0 else 0.0
            hi = math.inf if j == last - 1 else seg
            along = min(max(along, lo), hi)
            lateral = -(x - ax) * uy + (y - ay) * ux
            dist = math.hypot(x - (ax + along * ux), y - (ay + along * uy))
            if dist < abs(found) - 1e-12:
                best_s[i] = path_s[j] + along
                found = math.copysign(dist, lateral)
        best_d[i] = found


@kernel
def _sample_index(value: float, samples: np.ndarray) -> int:
    """Largest j with samples[j] <= value, for samples[0] <= value <= samples[-1].

    The samples are equally spaced up to rounding, so a guess from the spacing is moved
    by at most a step or two; the result is the index ``numpy.interp`` works with.
    """
    last = samples.size - 1
    j = min(int(value * last / samples[last]), last) if samples[last] > 0.0 else 0
    while j > 0 and samples[j] > value:
        j -= 1
    while j < last and samples[j + 1] <= value:
        j += 1
    return j


@kernel
def _interpolate(value: float, j: int, samples: np.ndarray, values: np.ndarray) -> float:
    """``numpy.interp(value, samples, values)`` at the sample index j of ``_sample_index``."""
    if j == samples.size - 1 or samples[j] == value:
        return values[j]
    slope = (values[j + 1] - values[j]) / (samples[j + 1] - samples[j])
    return slope * (value - samples[j]) + values[j]


@kernel
def _pose_at(
    value: float,
    path_s: np.ndarray,
    path_x: np.ndarray,
    path_y: np.ndarray,
    path_theta: np.ndarray,
    path_kappa: np.ndarray,
    path_dkappa: np.ndarray,
) -> tuple[float, float, float, float, float]:
    """(x, y, theta, kappa, dkappa) at arc length ``value``; straight beyond the ends."""
    clipped = min(max(value, 0.0), path_s[path_s.size - 1])
    beyond = value - clipped
    j = _sample_index(clipped, path_s)
    theta = _interpolate(clipped, j, path_s, path_theta)
    x = _interpolate(clipped, j, path_s, path_x)
    y = _interpolate(clipped, j, path_s, path_y)
    if beyond != 0.0:
        return x + beyond * math.cos(theta), y + beyond * math.sin(theta), theta, 0.0, 0.0
    kappa = _interpolate(clipped, j, path_s, path_kappa)
    return x, y, theta, kappa, _interpolate(clipped, j, path_s, path_dkappa)


@kernel
def _evaluate_path(
    s: np.ndarray,
    path_s: np.ndarray,
    path_x: np.ndarray,
    path_y: np.ndarray,
    path_theta: np.ndarray,
    path_kappa: np.ndarray,
    path_dkappa: np.ndarray,
    out: np.ndarray,
) -> None:
    """Poses at arc lengths ``s`` (m,), written to ``out`` (5, m): x, y, theta, kappa, dkappa."""
    for i in range(s.size):
        pose = _pose_at(s[i], path_s, path_x, path_y, path_theta, path_kappa, path_dkappa)
        for row in range(5):
            out[row, i] = pose[row]


@kernel
def _cartesian_states(
    lon: np.ndarray,
    lon_row: np.ndarray,
    lat: np.ndarray,
    path_s: np.ndarray,
    path_x: np.ndarray,
    path_y: np.ndarray,
    path_theta: np.ndarray,
    path_kappa: np.ndarray,
    path_dkappa: np.ndarray,
    out: np.ndarray,
) -> None:
    """Kernel of ``cartesian_states``: out (6, n, n_t) = x, y, yaw, v, a, kappa."""
    rows, n_t = lon.shape[1], lon.shape[2]
    # The path's pose once per distinct longitudinal motion: x, y, theta, kappa,
    # dkappa, sin theta, cos theta.
    pose = np.empty((7, rows, n_t))
    for row in range(rows):
        for step in range(n_t):
            x_r, y_r, theta_r, kappa_r, dkappa_r = _pose_at(
                lon[0, row, step], path_s, path_x, path_y, path_theta, path_kappa, path_dkappa
            )
            pose[0, row, step] = x_r
            pose[1, row, step] = y_r
            pose[2, row, step] = theta_r
            pose[3, row, step] = kappa_r
            pose[4, row, step] = dkappa_r
            pose[5, row, step] = math.sin(theta_r)
            pose[6, row, step] = math.cos(theta_r)
    for traj in range(lat.shape[1]):
        row = lon_row[traj]
        last_moving = -1
        for step in range(n_t):
            theta_r, kappa_r, dkappa_r = pose[2, row, step], pose[3, row, step], pose[4, row, step]
            s_dot, s_ddot = lon[1, row, step], lon[2, row, step]
            d, d_dot, d_ddot = lat[0, traj, step], lat[1, traj, step], lat[2, traj, step]
            one_minus_kd = 1.0 - kappa_r * d
            along = s_dot * one_minus_kd
            across = d_dot
            # along' = s'' (1 - kappa d) - s' (kappa' s' d + kappa d')
            along_dot = s_ddot * one_minus_kd - s_dot * ((dkappa_r * s_dot) * d + kappa_r * d_dot)
            acc_t = along_dot - (across * s_dot) * kappa_r
            acc_n = (along * s_dot) * kappa_r + d_ddot
            # Along the path (d' = 0, a plan past its lateral horizon) hypot(along, +-0) is
            # |along| and atan2(+-0, x > 0) is +-0 exactly (C99 Annex F): the same values
            # without the calls.
            sideways = across != 0.0
            speed = math.hypot(along, across) if sideways else abs(along)
            if speed > 1e-3:
                safe = max(speed, 1e-9)
                out[4, traj, step] = (along * acc_t + across * acc_n) / safe
                out[5, traj, step] = (along * acc_n - across * acc_t) / math.pow(safe, 3.0)
                # Rolling back (within the validity check's reversing tolerance) keeps
                # the nose forward: a car does not turn round to creep backwards.
                if along >= 0.0:
                    heading = math.atan2(across, along) if sideways else across
                else:
                    heading = math.atan2(-across, -along) if sideways else -across
                out[2, traj, step] = heading + theta_r
                last_moving = step
            else:
                out[4, traj, step] = s_ddot
                out[5, traj, step] = 0.0
                out[2, traj, step] = out[2, traj, last_moving] if last_moving >= 0 else theta_r
            out[0, traj, step] = pose[0, row, step] - pose[5, row, step] * d
            out[1, traj, step] = pose[6, row, step] * d + pose[1, row, step]
            out[3, traj, step] = speed
