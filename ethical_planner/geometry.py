"""Planar geometry shared by every layer: angle wrapping, rectangles, impact geometry.

Conventions (SPEC section 3): angles counter-clockwise from the x axis [rad], wrapped
into (-pi, pi]; a rectangle is centred at its geometric centre with its length along
its heading. All functions are vectorised and broadcast their arguments.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ethical_planner.validation import positive_array, vector_array

_TWO_PI = 2.0 * math.pi

#: Relative speed below which the approach direction is undefined [m/s].
MIN_RELATIVE_SPEED = 1e-9
#: Speed below which a body's heading replaces its velocity direction [m/s].
MIN_SPEED = 1e-6

# Corner signs (along, across) of a rectangle, counter-clockwise from the front right.
CORNER_ALONG = np.array([1.0, 1.0, -1.0, -1.0])
CORNER_ACROSS = np.array([-1.0, 1.0, 1.0, -1.0])


def wrap_angle(angle: ArrayLike) -> np.ndarray:
    """Wrap angles into (-pi, pi]: pi stays pi, -pi becomes pi.

    Angles already inside are returned unchanged to the bit.

    Args:
        angle: angles [rad], any shape; NaN stays NaN.

    Returns:
        Wrapped angles [rad], a new array of the same shape.
    """
    return wrap_angle_in_place(np.array(angle, dtype=float))


def wrap_angle_in_place(angle: np.ndarray) -> np.ndarray:
    """Wrap a float array into (-pi, pi], in place where possible (see ``wrap_angle``).

    Hot-path variant: pass only arrays the caller owns (it may overwrite them).

    Args:
        angle: angles [rad], float array, any shape.

    Returns:
        The wrapped angles [rad] (``angle`` itself when it is a writeable array).
    """
    angle = np.asarray(angle)
    turns = np.multiply(angle, 1.0 / _TWO_PI, out=np.empty_like(angle))
    np.rint(turns, out=turns)
    turns *= _TWO_PI
    angle -= turns  # now in [-pi, pi] up to rounding; unchanged if already inside
    low = angle <= -np.pi
    if low.any():
        angle[low] += _TWO_PI
    high = angle > np.pi
    if high.any():
        angle[high] -= _TWO_PI
    return angle


def rectangle_corners(
    x: ArrayLike, y: ArrayLike, yaw: ArrayLike, length: ArrayLike, width: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Corners of rectangles centred at (x, y), counter-clockwise from the front right.

    Args:
        x, y: centres [m], any shape S (broadcast with the others).
        yaw: headings [rad], broadcastable to S.
        length: lengths along the heading [m], broadcastable to S.
        width: widths across the heading [m], broadcastable to S.

    Returns:
        Corner x and y [m], each of shape S + (4,): front right, front left, rear left,
        rear right.
    """
    yaw = np.asarray(yaw, dtype=float)
    c, s = np.cos(yaw)[..., None], np.sin(yaw)[..., None]
    half_l = 0.5 * np.asarray(length, dtype=float)[..., None] * CORNER_ALONG
    half_w = 0.5 * np.asarray(width, dtype=float)[..., None] * CORNER_ACROSS
    x = np.asarray(x, dtype=float)[..., None]
    y = np.asarray(y, dtype=float)[..., None]
    return x + c * half_l - s * half_w, y + s * half_l + c * half_w


def rectangle_half_extent(
    yaw: ArrayLike, length: ArrayLike, width: ArrayLike, nx: ArrayLike, ny: ArrayLike
) -> np.ndarray:
    """Half-extent [m] of rectangles along the unit directions (nx, ny).

    The largest distance of a corner from the centre measured along (nx, ny): the
    support function of the rectangle.

    Args:
        yaw: headings [rad]. length, width: sizes [m]. nx, ny: unit direction; all broadcast.

    Returns:
        Half-extent [m], the broadcast shape.
    """
    c, s = np.cos(yaw), np.sin(yaw)
    return 0.5 * length * np.abs(c * nx + s * ny) + 0.5 * width * np.abs(c * ny - s * nx)


def rectangle_overlap(
    xa: ArrayLike,
    ya: ArrayLike,
    yaw_a: ArrayLike,
    length_a: ArrayLike,
    width_a: ArrayLike,
    xb: ArrayLike,
    yb: ArrayLike,
    yaw_b: ArrayLike,
    length_b: ArrayLike,
    width_b: ArrayLike,
) -> np.ndarray:
    """Penetration depth of two rectangles by the separating-axis test [m].

    The smallest, over the four edge normals of both rectangles, of the sum of the
    half-extents along the axis minus the distance of the centres along it: positive
    where the rectangles overlap (by that much along the axis that separates them
    best), zero or negative where they do not (minus the gap along that axis, a lower
    bound of the distance).

    Args:
        xa, ya: centres of the first rectangles [m]. yaw_a: headings [rad].
        length_a, width_a: sizes [m]. xb, yb, yaw_b, length_b, width_b: the second
            rectangles; all broadcast.

    Returns:
        Depth [m], the broadcast shape.
    """
    dx = np.asarray(xb, dtype=float) - np.asarray(xa, dtype=float)
    dy = np.asarray(yb, dtype=float) - np.asarray(ya, dtype=float)
    yaw_a, yaw_b = np.asarray(yaw_a, dtype=float), np.asarray(yaw_b, dtype=float)
    depth = None
    for yaw in (yaw_a, yaw_b):
        for nx, ny in ((np.cos(yaw), np.sin(yaw)), (-np.sin(yaw), np.cos(yaw))):
            reach = rectangle_half_extent(yaw_a, length_a, width_a, nx, ny) + rectangle_half_extent(
                yaw_b, length_b, width_b, nx, ny
            )
            along = reach - np.abs(dx * nx + dy * ny)
            depth = along if depth is None else np.minimum(depth, along)
    return depth


def impact_offset_fraction(
    ego_pos: ArrayLike,
    ego_vel: ArrayLike,
    ego_yaw: ArrayLike,
    ego_length: ArrayLike,
    ego_width: ArrayLike,
    obs_pos: ArrayLike,
    obs_vel: ArrayLike,
    obs_yaw: ArrayLike,
    obs_length: ArrayLike,
    obs_width: ArrayLike,
) -> np.ndarray:
    """Lateral offset of an impact as a fraction of the largest offset that still touches.

    The other body's centre approaches the ego's centre along the relative velocity
    w = obs_vel - ego_vel. The offset is the perpendicular distance of the other
    centre from the line through the ego's centre along w; it is divided by the
    largest such distance at which the two rectangular footprints can touch, the sum
    of their half-extents perpendicular to w (the edge offset of their Minkowski
    sum). The result is clipped to [0, 1]: 0 = central impact, 1 = grazing (or
    missing). Under constant velocities the distance does not change along the
    approach, so states at any step before or at contact give the same value.

    Args:
        ego_pos: ego centre [m], shape (..., 2).
        ego_vel: ego velocity [m/s], shape (..., 2).
        ego_yaw: ego heading [rad], shape (...).
        ego_length: ego length [m], > 0, shape (...).
        ego_width: ego width [m], > 0, shape (...).
        obs_pos: other road user's centre [m], shape (..., 2).
        obs_vel: its velocity [m/s], shape (..., 2).
        obs_yaw: its heading [rad], shape (...).
        obs_length: its length [m], > 0, shape (...).
        obs_width: its width [m], > 0, shape (...).

    Returns:
        Offset fraction in [0, 1], the broadcast shape of the arguments (vectors
        without their last axis); 0 where the relative speed is below
        ``MIN_RELATIVE_SPEED`` (no approach, Eq. 1 gives dv = 0 there anyway).

    Raises:
        ValueError: vectors without a last axis of 2 or not finite, or lengths not
            finite and > 0.
    """
    ep, ev = vector_array("ego_pos", ego_pos, "[m]"), vector_array("ego_vel", ego_vel, "[m/s]")
    op, ov = vector_array("obs_pos", obs_pos, "[m]"), vector_array("obs_vel", obs_vel, "[m/s]")
    el, ew = positive_array("ego_length", ego_length, "[m]"), positive_array("ego_width", ego_width, "[m]")
    ol, ow = positive_array("obs_length", obs_length, "[m]"), positive_array("obs_width", obs_width, "[m]")
    wx, wy = ov[..., 0] - ev[..., 0], ov[..., 1] - ev[..., 1]
    speed = np.hypot(wx, wy)
    moving = speed > MIN_RELATIVE_SPEED
    safe = np.where(moving, speed, 1.0)
    # unit normal of the approach line (any unit vector where there is no approach)
    nx, ny = np.where(moving, -wy / safe, 1.0), np.where(moving, wx / safe, 0.0)
    dist = np.abs((op[..., 0] - ep[..., 0]) * nx + (op[..., 1] - ep[..., 1]) * ny)
    reach = rectangle_half_extent(np.asarray(ego_yaw, dtype=float), el, ew, nx, ny) + rectangle_half_extent(
        np.asarray(obs_yaw, dtype=float), ol, ow, nx, ny
    )
    return np.where(moving, np.clip(dist / reach, 0.0, 1.0), 0.0)


def velocity_angle(
    ego_vel: ArrayLike, obs_vel: ArrayLike, ego_yaw: ArrayLike, obs_yaw: ArrayLike
) -> np.ndarray:
    """Angle between the two velocity directions (the alpha of Eq. 1) [rad], in [0, pi].

    A body slower than ``MIN_SPEED`` has no velocity direction; its heading is used
    instead.

    Args:
        ego_vel: ego velocity [m/s], shape (..., 2).
        obs_vel: other road user's velocity [m/s], shape (..., 2).
        ego_yaw: ego heading [rad], shape (...).
        obs_yaw: other heading [rad], shape (...).

    Returns:
        Angle [rad] in [0, pi], the broadcast shape (vectors without their last axis).
    """
    ev, ov = vector_array("ego_vel", ego_vel, "[m/s]"), vector_array("obs_vel", obs_vel, "[m/s]")
    directions = []
    for v, yaw in ((ev, ego_yaw), (ov, obs_yaw)):
        yaw = np.asarray(yaw, dtype=float)
        still = np.hypot(v[..., 0], v[..., 1]) < MIN_SPEED
        directions.append((np.where(still, np.cos(yaw), v[..., 0]), np.where(still, np.sin(yaw), v[..., 1])))
    (ax, ay), (bx, by) = directions
    return np.abs(np.arctan2(ax * by - ay * bx, ax * bx + ay * by))


__all__ = [
    "MIN_RELATIVE_SPEED",
    "MIN_SPEED",
    "impact_offset_fraction",
    "rectangle_corners",
    "rectangle_half_extent",
    "rectangle_overlap",
    "velocity_angle",
    "wrap_angle",
    "wrap_angle_in_place",
]
