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


@dataclass(frozen=True, slots=True)
class NoOvertakingZone:
    """A stretch of the reference path in which the ego keeps out of the oncoming lanes.

    Environment data for the planner (the scenario's ``[[road.no_overtaking]]``); the
    world judges the ego itself. A candidate whose footprint moves further across the
    centre line (``RoadEnvironment.centre_line``) while any part of it lies in the
    zone breaks the rule (``ethical_planner.traffic_rules.breaks_lane_rules``), unless
    the ego's lane ahead is blocked by something slower than ``pass_below``: passing a
    standing obstacle, or a road user crawling along, is not overtaking (the UK Highway
    Code, rule 129, allows crossing a solid centre line to pass a stationary vehicle or
    a cyclist, horse or road works vehicle at 10 mph or less).

    Attributes:
        start, end: arc lengths along the reference path [m], start < end.
        pass_below: road users slower than this may be passed, and debris [m/s]; 0 allows
            no exception (the ego then waits behind debris in the zone).
    """

    start: float
    end: float
    pass_below: float = 4.47

    def __post_init__(self) -> None:
        if not (math.isfinite(self.start) and math.isfinite(self.end) and self.start < self.end):
            raise ValueError(
                f"a no-overtaking zone needs finite start < end [m], got {self.start}, {self.end}"
            )
        if not (math.isfinite(self.pass_below) and self.pass_below >= 0.0):
            raise ValueError(f"no-overtaking pass_below must be >= 0 m/s, got {self.pass_below}")


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
        centre_line: offset d of the line between the ego's lanes and the oncoming
            lanes (left of it) from the reference path [m]; None on a one-way road or a
            road without lane markings.
        lane_edges: offsets d (right, left) of the outer lane edges from the reference
            path [m]; the drivable strips beyond them are the shoulders (and parking
            strips), drivable but not lanes. None: no markings, no shoulder rule.
        no_overtaking: the no-overtaking zones (they need a centre line).
    """

    reference_path: ReferencePath
    drivable_area: Polygon
    lane_width: float = 3.5
    lane_offsets: tuple[float, ...] = (0.0,)
    speed_limit: float = 13.9
    stop_lines: tuple[StopLine, ...] = ()
    centre_line: float | None = None
    lane_edges: tuple[float, float] | None = None
    no_overtaking: tuple[NoOvertakingZone, ...] = ()
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
        if self.centre_line is not None and not math.isfinite(self.centre_line):
            raise ValueError(f"centre_line must be a finite offset [m] or None, got {self.centre_line}")
        if self.lane_edges is not None:
            right, left = (float(d) for d in self.lane_edges)
            if not (math.isfinite(right) and math.isfinite(left) and right < left):
                raise ValueError(
                    f"lane_edges must be finite offsets (right, left), right < left, got {self.lane_edges}"
                )
            object.__setattr__(self, "lane_edges", (right, left))
        object.__setattr__(self, "no_overtaking", tuple(self.no_overtaking))
        if self.no_overtaking and self.centre_line is None:
            raise ValueError("no_overtaking zones need a centre_line (a road with lanes in both directions)")
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
