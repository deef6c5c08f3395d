"""Launch geometry of controlled two-body impacts and classification of impacts.

An impact is set up in the frame of body a (heading 0 along +x, at the origin).
Body b has heading ``alpha`` (the angle between the two velocity directions:
0 = same direction / rear-end, 90 deg = T-bone, 180 deg = head-on). The relative
velocity w = v_b - v_a fixes the line along which b's centre approaches a's centre;
the lateral offset moves that line sideways by a fraction of the largest offset at
which the footprints still touch (0 = central, 1 = grazing edge).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from ethical_planner.geometry import rectangle_corners

#: Gap between the footprints at launch, along the approach line [m].
LAUNCH_GAP_M = 0.05
#: Vertices of the polygon circumscribing a round (pedestrian) proxy.
_ROUND_VERTICES = 16

CENTRAL_COLLINEAR = "central_collinear"
OBLIQUE = "oblique"
OFFSET = "offset"
STATIC = "static"
#: Impact classes of the summary tables.
CLASSES = (CENTRAL_COLLINEAR, OBLIQUE, OFFSET)
#: Offset fraction below which an impact counts as central.
CENTRAL_OFFSET_MAX = 0.15
#: Angle from 0 or 180 deg below which a central impact counts as collinear [deg].
COLLINEAR_ANGLE_MAX_DEG = 7.5


@dataclass(frozen=True, slots=True)
class Footprint:
    """Planar footprint of a body.

    Attributes:
        length: [m]. width: [m].
        round: True for capsule (pedestrian) proxies, diameter min(length, width).
    """

    length: float
    width: float
    round: bool = False

    def __post_init__(self) -> None:
        for name in ("length", "width"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"Footprint.{name} must be finite and > 0 [m], got {value!r}")

    def corners(self, yaw: float) -> np.ndarray:
        """Vertices of the footprint centred at the origin, rotated by ``yaw`` [rad]; shape (k, 2) [m]."""
        if self.round:
            r = 0.5 * min(self.length, self.width) / math.cos(math.pi / _ROUND_VERTICES)
            t = np.linspace(0.0, 2 * math.pi, _ROUND_VERTICES, endpoint=False)
            pts = r * np.column_stack([np.cos(t), np.sin(t)])
            c, s = math.cos(yaw), math.sin(yaw)
            return pts @ np.array([[c, s], [-s, c]])
        x, y = rectangle_corners(0.0, 0.0, yaw, self.length, self.width)
        return np.column_stack([x, y])


def configuration_space(a: Footprint, yaw_a: float, b: Footprint, yaw_b: float) -> np.ndarray:
    """Minkowski sum of a and -b: b's centre relative to a's centre is in contact inside it.

    Returns:
        Convex hull vertices, shape (k, 2) [m], counter-clockwise.
    """
    pa, pb = a.corners(yaw_a), b.corners(yaw_b)
    sums = (pa[:, None, :] - pb[None, :, :]).reshape(-1, 2)
    hull = shapely.MultiPoint(sums).convex_hull
    return np.asarray(hull.exterior.coords)[:-1]


def edge_offset(hull: np.ndarray, direction: np.ndarray) -> float:
    """Largest perpendicular offset [m] of an approach line along ``direction`` that still hits ``hull``."""
    n = np.array([-direction[1], direction[0]])
    return float(np.max(hull @ n))


def classify(angle_deg: float, offset: float) -> str:
    """Impact class from the angle between velocities [deg] and the offset fraction.

    Returns:
        "offset" if the offset fraction exceeds ``CENTRAL_OFFSET_MAX``, else
        "central_collinear" within ``COLLINEAR_ANGLE_MAX_DEG`` of 0 or 180 deg, else "oblique".
    """
    if not math.isfinite(offset) or offset > CENTRAL_OFFSET_MAX:
        return OFFSET
    if min(abs(angle_deg), abs(180.0 - angle_deg)) <= COLLINEAR_ANGLE_MAX_DEG:
        return CENTRAL_COLLINEAR
    return OBLIQUE


def speeds_for_closing(closing: float, alpha: float, partner_speed: float) -> tuple[float, float]:
    """Speeds of a and b [m/s] giving relative speed ``closing`` at angle ``alpha`` [rad].

    b's speed is ``partner_speed`` (must be <= closing / 2 so a real solution with
    a moving forward exists); a's speed solves |v_a - v_b| = closing.
    """
    if not 0.0 <= partner_speed <= 0.5 * closing + 1e-12:
        raise ValueError(f"partner_speed must lie in [0, closing/2], got {partner_speed} for {closing}")
    s_b = partner_speed
    s_a = s_b * math.cos(alpha) + math.sqrt(closing**2 - (s_b * math.sin(alpha)) ** 2)
    return s_a, s_b


@dataclass(frozen=True, slots=True)
class Launch:
    """Initial states of a controlled impact (a at the origin with heading 0).

    Attributes:
        velocity_a: [m/s], (vx, vy). position_b: [m], (x, y). yaw_b: [rad].
        velocity_b: [m/s], (vx, vy). time_to_contact: [s].
    """

    velocity_a: tuple[float, float]
    position_b: tuple[float, float]
    yaw_b: float
    velocity_b: tuple[float, float]
    time_to_contact: float


def launch_geometry(
    a: Footprint, b: Footprint, speed_a: float, speed_b: float, alpha: float, offset: float
) -> Launch:
    """Place b so that it meets a along a line offset by ``offset`` of the edge offset.

    Args:
        a: footprint of a (heading 0, at the origin).
        b: footprint of b.
        speed_a: speed of a [m/s] along +x.
        speed_b: speed of b [m/s] along heading ``alpha``.
        alpha: heading of b [rad].
        offset: lateral offset, fraction of the edge offset in [0, 1).

    Returns:
        The launch states; the footprints are ``LAUNCH_GAP_M`` apart along the approach.

    Raises:
        ValueError: offset outside [0, 1) or zero relative speed.
    """
    if not 0.0 <= offset < 1.0:
        raise ValueError(f"offset must lie in [0, 1), got {offset}")
    va = np.array([speed_a, 0.0])
    vb = speed_b * np.array([math.cos(alpha), math.sin(alpha)])
    w = vb - va
    speed = float(np.hypot(*w))
    if speed < 1e-9:
        raise ValueError("the bodies have no relative velocity")
    w_hat = w / speed
    n = np.array([-w_hat[1], w_hat[0]])
    hull = configuration_space(a, 0.0, b, alpha)
    reach = float(np.max(np.hypot(hull[:, 0], hull[:, 1]))) + 1.0
    start = -w_hat * reach + n * offset * edge_offset(hull, w_hat)
    line = shapely.LineString([start, start + 2.0 * reach * w_hat])
    cut = shapely.Polygon(hull).intersection(line)
    s_entry = min(float(np.dot(np.asarray(p) - start, w_hat)) for p in np.asarray(cut.coords))
    p0 = start + w_hat * (s_entry - LAUNCH_GAP_M)
    return Launch(
        velocity_a=(float(va[0]), float(va[1])),
        position_b=(float(p0[0]), float(p0[1])),
        yaw_b=float(alpha),
        velocity_b=(float(vb[0]), float(vb[1])),
        time_to_contact=LAUNCH_GAP_M / speed,
    )
