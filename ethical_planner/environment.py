"""The static road as the planner sees it: reference path, lanes, drivable area."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon

from ethical_planner.reference_path import ReferencePath


@dataclass(frozen=True, slots=True)
class StopLine:
    """A stop line on the reference path: a traffic light's or a stop sign's.

    Environment data for the planner (the scenario's ``[[stop_lines]]``); the world
    judges the ego's violations itself. The planner makes a candidate that crosses a
    binding line invalid (``ethical_planner.traffic_rules``).

    Attributes:
        s: arc length along the reference path [m].
        red: (start, end) times [s] of the run in which the light is red; empty for a
            stop sign.
        stop: a stop sign (stand still before crossing).
        stop_zone: a standstill with the front this far before the line or less counts
            as the stop at a stop sign [m].
    """

    s: float
    red: tuple[tuple[float, float], ...] = ()
    stop: bool = False
    stop_zone: float = 10.0

    def red_at(self, time: float) -> bool:
        """True if the light is red at ``time`` [s]."""
        return any(a <= time < b for a, b in self.red)


@dataclass(frozen=True, slots=True, eq=False)
class RoadEnvironment:
    """Road geometry around the ego's route.

    Attributes:
        reference_path: the route the Frenet frame follows (centre of the ego lane).
        drivable_area: polygon [m] the ego's footprint must stay inside (validity
            level 2); leaving it costs the harm of hitting a wall.
        lane_width: [m].
        lane_offsets: lateral offsets d of the lane centres from the reference path [m].
        speed_limit: [m/s].
        stop_lines: traffic lights and stop signs on the reference path, by arc length.
    """

    reference_path: ReferencePath
    drivable_area: Polygon
    lane_width: float = 3.5
    lane_offsets: tuple[float, ...] = (0.0,)
    speed_limit: float = 13.9
    stop_lines: tuple[StopLine, ...] = ()
    _prepared: bool = field(default=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.reference_path, ReferencePath):
            raise ValueError("reference_path must be a ReferencePath")
        if not isinstance(self.drivable_area, shapely.Polygon | shapely.MultiPolygon):
            raise ValueError("drivable_area must be a shapely Polygon or MultiPolygon")
        if self.drivable_area.is_empty or not self.drivable_area.is_valid:
            raise ValueError("drivable_area must be a non-empty, valid polygon")
        if not (math.isfinite(self.lane_width) and self.lane_width > 0):
            raise ValueError(f"lane_width must be > 0 m, got {self.lane_width}")
        if not (math.isfinite(self.speed_limit) and self.speed_limit > 0):
            raise ValueError(f"speed_limit must be > 0 m/s, got {self.speed_limit}")
        object.__setattr__(self, "lane_offsets", tuple(float(d) for d in self.lane_offsets))
        shapely.prepare(self.drivable_area)

    @classmethod
    def along_path(
        cls,
        points: np.ndarray | list,
        lanes_left: int = 1,
        lanes_right: int = 0,
        lane_width: float = 3.5,
        speed_limit: float = 13.9,
        margin: float = 0.0,
    ) -> RoadEnvironment:
        """A road of parallel lanes along a polyline; the ego lane is centred on it.

        Args:
            points: centre line of the ego lane [m], shape (n, 2).
            lanes_left: lanes to the left of the ego lane (e.g. the oncoming lane).
            lanes_right: lanes to the right of the ego lane.
            lane_width: [m].
            speed_limit: [m/s].
            margin: extra drivable width beyond the outer lane edges (shoulder) [m].
        """
        if lanes_left < 0 or lanes_right < 0:
            raise ValueError("lanes_left and lanes_right must be >= 0")
        path = ReferencePath.from_polyline(points)
        left = (lanes_left + 0.5) * lane_width + margin
        right = (lanes_right + 0.5) * lane_width + margin
        # Sample the path densely so the polygon follows curves.
        s = np.linspace(0.0, path.length, max(int(path.length / 1.0), 2) + 1)
        xl, yl = path.to_cartesian(s, np.full_like(s, left))
        xr, yr = path.to_cartesian(s, np.full_like(s, -right))
        ring = np.concatenate([np.column_stack([xr, yr]), np.column_stack([xl, yl])[::-1]])
        area = Polygon(ring).buffer(0)
        offsets = tuple(k * lane_width for k in range(-lanes_right, lanes_left + 1))
        return cls(path, area, lane_width, offsets, speed_limit)

    def road_edges(self) -> list[LineString]:
        """Boundary lines of the drivable area (for drawing)."""
        boundary = self.drivable_area.boundary
        return list(getattr(boundary, "geoms", [boundary]))
