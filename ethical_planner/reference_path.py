"""Arc-length parameterised, smooth reference path and Frenet <-> Cartesian conversion."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial import cKDTree

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
        s_clipped = np.clip(s, 0.0, self.s[-1])
        beyond = s - s_clipped  # non-zero only outside [0, length]
        theta = np.interp(s_clipped, self.s, self.theta)
        x = np.interp(s_clipped, self.s, self.x) + beyond * np.cos(theta)
        y = np.interp(s_clipped, self.s, self.y) + beyond * np.sin(theta)
        inside = beyond == 0.0
        kappa = np.where(inside, np.interp(s_clipped, self.s, self.kappa), 0.0)
        dkappa = np.where(inside, np.interp(s_clipped, self.s, self.dkappa), 0.0)
        return x, y, theta, kappa, dkappa

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
        _, nearest = self._tree.query(np.column_stack([px, py]))
        # Project onto the segment after (or, at the end, before) the nearest sample.
        best_s = np.empty_like(px)
        best_d = np.full_like(px, np.inf)
        last = len(self.s) - 1
        for start in (np.minimum(nearest, last - 1), np.maximum(nearest - 1, 0)):
            ax, ay = self.x[start], self.y[start]
            ex, ey = self.x[start + 1] - ax, self.y[start + 1] - ay
            seg = np.hypot(ex, ey)
            ux, uy = ex / seg, ey / seg
            along = (px - ax) * ux + (py - ay) * uy
            # Only the first and the last segment extend beyond the path's ends.
            lo = np.where(start == 0, -np.inf, 0.0)
            hi = np.where(start == last - 1, np.inf, seg)
            along = np.clip(along, lo, hi)
            lateral = -(px - ax) * uy + (py - ay) * ux
            dist = np.hypot(px - (ax + along * ux), py - (ay + along * uy))
            better = dist < np.abs(best_d) - 1e-12
            best_s = np.where(better, self.s[start] + along, best_s)
            best_d = np.where(better, np.copysign(dist, lateral), best_d)
        return best_s.reshape(shape), best_d.reshape(shape)
