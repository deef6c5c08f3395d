"""What a sensor sees: 2D visibility with heights, sensor range and field of view.

The world is planar, but sight is not: a 1.0 m wall hides a car from a sensor 1.2 m
above the road, a 0.15 m kerb does not. Each target is sampled at five points (its
centre and its four corners pulled 10 % inwards) at half its height; a sight line runs
from the sensor (``eye``, at ``eye_height``) to each point. A box (a road user's body,
a wall, a kerb, debris, a fixed obstacle) blocks a sight line if the line crosses its
footprint while below its top: the line's height is linear along it, so it suffices
to compare the heights where it enters and leaves the footprint with the box's height.
A target is seen if one of its points is in range, in the field of view and
unblocked.

Everything is one vectorised slab test of (targets x points x boxes); no Python loop
over sight lines.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ethical_planner.geometry import rectangle_corners, wrap_angle
from mujoco_world.scenario.road import StaticBox

#: Fraction of a target's length and width at which its corner points are sampled.
CORNER_FRACTION = 0.9


@dataclass(frozen=True, slots=True)
class Boxes:
    """Rectangular boxes standing on the road, as a struct of arrays, each (k,).

    Attributes:
        x, y: centres [m]. yaw: headings [rad].
        half_length, half_width: half extents along and across the heading [m].
        height: heights above the road [m].
    """

    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    half_length: np.ndarray
    half_width: np.ndarray
    height: np.ndarray

    @property
    def size(self) -> int:
        """Number of boxes."""
        return len(self.x)

    def take(self, rows: np.ndarray) -> Boxes:
        """The boxes ``rows`` (an index or bool array)."""
        return Boxes(*(getattr(self, f)[rows] for f in _FIELDS))

    @staticmethod
    def from_static(boxes: Sequence[StaticBox]) -> Boxes:
        """Walls, kerbs, debris and fixed obstacles of a scene."""
        rows = [(*b.center, b.yaw, b.half_length, b.half_width, 2.0 * b.half_height) for b in boxes]
        return Boxes(*np.array(rows, dtype=float).reshape(-1, 6).T)

    @staticmethod
    def concatenate(*parts: Boxes) -> Boxes:
        """All boxes of ``parts`` in order."""
        return Boxes(*(np.concatenate([getattr(p, f) for p in parts]) for f in _FIELDS))


_FIELDS = ("x", "y", "yaw", "half_length", "half_width", "height")


def target_points(
    x: np.ndarray, y: np.ndarray, yaw: np.ndarray, length: np.ndarray, width: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Sample points of targets: centre and corners at ``CORNER_FRACTION`` of the footprint.

    Args:
        x, y, yaw, length, width: (m,) poses [m, rad] and footprints [m].

    Returns:
        (px, py), each (m, 5) [m].
    """
    cx, cy = rectangle_corners(x, y, yaw, CORNER_FRACTION * length, CORNER_FRACTION * width)
    return np.concatenate([x[:, None], cx], axis=1), np.concatenate([y[:, None], cy], axis=1)


def blocked(
    eye: np.ndarray,
    eye_height: float,
    px: np.ndarray,
    py: np.ndarray,
    target_height: np.ndarray,
    boxes: Boxes,
    ignore: np.ndarray | None = None,
) -> np.ndarray:
    """Which sight lines from the eye to target points some box blocks.

    Args:
        eye: (2,) sensor position [m].
        eye_height: sensor height above the road [m].
        px, py: (m, p) target points [m].
        target_height: (m,) height of each target's points above the road [m].
        boxes: k boxes that may block.
        ignore: (m, k) bool, box j never blocks target i (its own body), or None.

    Returns:
        (m, p) bool: the line from the eye to point (i, q) crosses a box while below its top.
    """
    m, p = px.shape
    if boxes.size == 0 or m == 0:
        return np.zeros((m, p), dtype=bool)
    c, s = np.cos(boxes.yaw), np.sin(boxes.yaw)
    # The segment eye -> point in each box's frame: a (k,) at u = 0, b (m, p, k) at u = 1.
    ex, ey = eye[0] - boxes.x, eye[1] - boxes.y
    a_x, a_y = ex * c + ey * s, -ex * s + ey * c
    dx, dy = px[..., None] - boxes.x, py[..., None] - boxes.y
    b_x, b_y = dx * c + dy * s, -dx * s + dy * c
    u0 = np.zeros(b_x.shape)
    u1 = np.ones(b_x.shape)
    for a, b, half in ((a_x, b_x, boxes.half_length), (a_y, b_y, boxes.half_width)):
        d = b - a
        inside = np.abs(a) <= half
        with np.errstate(divide="ignore", invalid="ignore"):
            lo = (-half - a) / d
            hi = (half - a) / d
        u0 = np.maximum(u0, np.where(d != 0, np.minimum(lo, hi), np.where(inside, -np.inf, np.inf)))
        u1 = np.minimum(u1, np.where(d != 0, np.maximum(lo, hi), np.where(inside, np.inf, -np.inf)))
    crosses = u0 < u1
    # Height of the line where it enters and leaves the footprint; it is lowest at one of them.
    rise = (np.asarray(target_height, dtype=float) - eye_height)[:, None, None]
    lowest = eye_height + np.minimum(u0 * rise, u1 * rise)
    hit = crosses & (lowest < boxes.height)
    if ignore is not None:
        hit &= ~ignore[:, None, :]
    return hit.any(axis=2)


def in_field_of_view(
    eye: np.ndarray, heading: float, px: np.ndarray, py: np.ndarray, range_m: float | None, fov_deg: float
) -> np.ndarray:
    """(m, p) bool: target points within the sensor's range and field of view.

    Args:
        eye: (2,) sensor position [m]. heading: sensor axis [rad].
        px, py: (m, p) target points [m].
        range_m: sensor range [m], or None for unlimited.
        fov_deg: full opening angle centred on the heading [deg] (360: all around).
    """
    ok = np.ones(px.shape, dtype=bool)
    dx, dy = px - eye[0], py - eye[1]
    if range_m is not None:
        ok &= np.hypot(dx, dy) <= range_m
    if fov_deg < 360.0:
        off = np.abs(wrap_angle(np.arctan2(dy, dx) - heading))
        ok &= off <= 0.5 * np.radians(fov_deg)
    return ok


__all__ = ["CORNER_FRACTION", "Boxes", "blocked", "in_field_of_view", "target_points"]
