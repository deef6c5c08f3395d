"""Scenarios given by data: a mapped road, recorded trajectories, fixed obstacles.

An importer (``scenario/commonroad.py`` for CommonRoad files) fills them; a TOML
scenario can use them too (``road.kind = "map"`` with a ``[road.map]`` table, road users
with ``behaviour.kind = "recorded"`` and a ``[road_users.behaviour.trajectory]`` table,
``[[obstacles]]``). Points are ``(x, y)`` pairs [m] in the world frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ethical_planner.validation import check, check_finite, check_non_negative, check_positive

#: A polyline or a polygon's ring: (x [m], y [m]) points.
Points = tuple[tuple[float, float], ...]


def points(owner: str, value: Any, minimum: int) -> Points:
    """Validate a sequence of (x, y) points [m]: finite, at least ``minimum`` of them."""
    try:
        pairs = tuple((float(x), float(y)) for x, y in value)
    except (TypeError, ValueError):
        raise ValueError(f"{owner} must be a list of [x, y] pairs, got {value!r:.80}") from None
    check(
        all(math.isfinite(x) and math.isfinite(y) for x, y in pairs),
        f"{owner} must hold finite numbers",
    )
    check(len(pairs) >= minimum, f"{owner} needs at least {minimum} points, got {len(pairs)}")
    return pairs


def numbers(owner: str, value: Any) -> tuple[float, ...]:
    """Validate a sequence of finite numbers."""
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{owner} must be a list of numbers, got {value!r:.80}") from None
    check(all(math.isfinite(v) for v in out), f"{owner} must hold finite numbers")
    return out


@dataclass(frozen=True, slots=True)
class MapSpec:
    """A road given by its geometry (``road.kind = "map"``), e.g. a CommonRoad lanelet network.

    Attributes:
        area: polygons (rings of at least three points) whose union is the drivable
            area (e.g. every lanelet) [m].
        reference_path: the ego's route, a polyline of at least two points [m].
        lanes: lane centre lines (for pictures and recordings) [m].
        boundaries: polylines lined with the road's boundary bodies (``road.boundary``) [m].
        lane_offsets: lateral offsets of the lane centres from the reference path, positive
            left [m] (the planner's lane model; 0 is the ego's lane).
        lane_width: [m].
    """

    area: tuple[Points, ...]
    reference_path: Points
    lanes: tuple[Points, ...] = ()
    boundaries: tuple[Points, ...] = ()
    lane_offsets: tuple[float, ...] = (0.0,)
    lane_width: float = 3.5

    def __post_init__(self) -> None:
        check(len(self.area) >= 1, "map.area needs at least one polygon")
        object.__setattr__(
            self, "area", tuple(points(f"map.area[{i}]", ring, 3) for i, ring in enumerate(self.area))
        )
        object.__setattr__(self, "reference_path", points("map.reference_path", self.reference_path, 2))
        object.__setattr__(
            self, "lanes", tuple(points(f"map.lanes[{i}]", line, 2) for i, line in enumerate(self.lanes))
        )
        object.__setattr__(
            self,
            "boundaries",
            tuple(points(f"map.boundaries[{i}]", line, 2) for i, line in enumerate(self.boundaries)),
        )
        offsets = numbers("map.lane_offsets", self.lane_offsets)
        check(0.0 in offsets, f"map.lane_offsets must contain 0 (the ego's lane), got {offsets}")
        object.__setattr__(self, "lane_offsets", offsets)
        check_positive("map", lane_width=self.lane_width)


@dataclass(frozen=True, slots=True)
class RecordedTrajectory:
    """A recorded trajectory at a fixed step (``behaviour.kind = "recorded"``).

    The road user exists in the world from ``start`` to the time of its last state: it
    enters at its first recorded state and leaves after its last one. In between its
    body follows a cubic Hermite spline through the recorded positions (velocities by
    central differences) through the tracking controller, so contacts stay physical.

    Attributes:
        start: time of the first state [s] (>= 0, in world time).
        dt: time between states [s].
        x, y: recorded centre positions [m], at least two.
        yaw: recorded headings [rad].
        source_id: the obstacle's id in its source file (for messages), or "".
    """

    start: float
    dt: float
    x: tuple[float, ...]
    y: tuple[float, ...]
    yaw: tuple[float, ...]
    source_id: str = ""

    def __post_init__(self) -> None:
        check_non_negative("trajectory", start=self.start)
        check_positive("trajectory", dt=self.dt)
        for name in ("x", "y", "yaw"):
            object.__setattr__(self, name, numbers(f"trajectory.{name}", getattr(self, name)))
        n = len(self.x)
        check(n >= 2, f"trajectory needs at least two states, got {n}")
        check(
            len(self.y) == n and len(self.yaw) == n,
            f"trajectory.x, y and yaw must have one value per state, got {n}, {len(self.y)}, {len(self.yaw)}",
        )

    @property
    def end(self) -> float:
        """Time of the last state [s]."""
        return self.start + (len(self.x) - 1) * self.dt

    @property
    def states(self) -> int:
        """Number of recorded states."""
        return len(self.x)


@dataclass(frozen=True, slots=True)
class ObstacleSpec:
    """A fixed obstacle: a rectangular body that never moves (construction site, debris...).

    Attributes:
        name: identifier (for messages).
        x, y: centre [m]. yaw: heading [rad].
        length, width: footprint [m].
    """

    name: str
    x: float
    y: float
    yaw: float
    length: float
    width: float

    def __post_init__(self) -> None:
        check(
            isinstance(self.name, str) and self.name.isidentifier(),
            f"obstacle name must be an identifier (letters, digits, _), got {self.name!r}",
        )
        check_finite("obstacle", x=self.x, y=self.y, yaw=self.yaw)
        check_positive("obstacle", length=self.length, width=self.width)


__all__ = ["MapSpec", "ObstacleSpec", "Points", "RecordedTrajectory", "numbers", "points"]
