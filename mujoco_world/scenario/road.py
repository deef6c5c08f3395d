"""Road geometry from a ``RoadSpec``: centre lines, routes, drivable area and boundaries.

Frames: the main road's reference line starts at the origin along +x (straight and
curved roads) or runs from x = -length/2 to +length/2 through the origin
(intersection, whose cross road runs along +y). Lateral offsets ``d`` are positive
to the left of a line's direction.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import shapely
from shapely.geometry import LineString, MultiLineString, MultiPolygon, Polygon, box

from ethical_planner.validation import check
from mujoco_world.scenario.spec import Boundary, DebrisSpec, RoadKind, RoadName, RoadSpec, RouteSpec, Turn

if TYPE_CHECKING:
    from ethical_planner.reference_path import ReferencePath

#: Spacing of sampled centre lines [m].
_SAMPLE_M = 1.0
#: Thickness of wall and kerb boxes [m].
BOUNDARY_THICKNESS_M = 0.4
#: Length of the probes either side of a boundary segment that tell which side is the road [m].
OUTWARD_PROBE_M = 1.0
#: How far the road may reach into a wall or kerb box [m]: a boundary is simplified twice
#: (an imported map's outline by 0.1 m, then by 0.05 m for its boxes), so a segment's chord
#: can lie up to 0.15 m inside the road.
BOX_ROAD_TOLERANCE_M = 0.15
#: Spacing along a boundary segment of the cross-sections that tell where its box may stand [m].
BOX_SAMPLE_M = 0.1
#: Height of walls and kerbs [m] (only for pictures: the world is planar).
BOUNDARY_HEIGHT_M = {Boundary.WALL: 1.0, Boundary.KERB: 0.15}


def polyline_frames(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents and left normals of a polyline, shape (n, 2) each."""
    diff = np.gradient(points, axis=0)
    tangent = diff / np.linalg.norm(diff, axis=1, keepdims=True)
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    return tangent, normal


def offset_polyline(points: np.ndarray, d: float) -> np.ndarray:
    """Polyline shifted by ``d`` [m] to its left, shape (n, 2)."""
    _, normal = polyline_frames(points)
    return points + d * normal


def _dedupe(points: np.ndarray) -> np.ndarray:
    keep = np.concatenate([[True], np.hypot(*np.diff(points, axis=0).T) > 1e-6])
    return points[keep]


def _bezier(p0: np.ndarray, h0: float, p1: np.ndarray, h1: float, n: int = 25) -> np.ndarray:
    """Cubic Bezier from p0 (heading h0) to p1 (heading h1), shape (n, 2)."""
    dist = float(np.hypot(*(p1 - p0)))
    k = 0.55 * dist
    c0 = p0 + k * np.array([math.cos(h0), math.sin(h0)])
    c1 = p1 - k * np.array([math.cos(h1), math.sin(h1)])
    t = np.linspace(0.0, 1.0, n)[:, None]
    return (1 - t) ** 3 * p0 + 3 * (1 - t) ** 2 * t * c0 + 3 * (1 - t) * t**2 * c1 + t**3 * p1


@dataclass(frozen=True, slots=True)
class StaticBox:
    """A static box obstacle (wall or kerb segment).

    Attributes:
        center: (x, y) [m]. half_length, half_width, half_height: [m].
        yaw: [rad]. kind: wall or kerb.
    """

    center: tuple[float, float]
    half_length: float
    half_width: float
    half_height: float
    yaw: float
    kind: Boundary


#: Painted length and gap of a dashed lane line [m] (a German rural road's 3 m / 6 m).
DASH_M = 3.0
GAP_M = 6.0
#: Half the distance between the two lines of a no-overtaking zone's double centre line [m].
ZONE_LINE_GAP_M = 0.15


def dashes(points: np.ndarray, dash: float, gap: float) -> list[np.ndarray]:
    """A polyline cut into dashes: ``dash`` painted, ``gap`` free, from its start [m].

    Args:
        points: the line [m], shape (n, 2).
        dash, gap: [m], > 0.

    Returns:
        One polyline per dash (the last may be shorter), each shape (k, 2), k >= 2.
    """
    seg = np.hypot(*np.diff(points, axis=0).T)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    starts = np.arange(0.0, arc[-1], dash + gap)
    out = []
    for a in starts:  # one dash each; drawing only
        b = min(a + dash, arc[-1])
        inner = (arc > a) & (arc < b)
        s = np.concatenate([[a], arc[inner], [b]])
        out.append(np.column_stack([np.interp(s, arc, points[:, 0]), np.interp(s, arc, points[:, 1])]))
    return [d for d in out if len(d) >= 2 and np.hypot(*(d[-1] - d[0])) > 1e-9]


@dataclass(frozen=True, slots=True)
class LaneMarkings:
    """Painted lines of a road (``RoadGeometry.lane_markings``).

    Attributes:
        solid: solid lines (outer lane edges, the centre line) [m], each shape (k, 2).
        dashed: the dashes of the lines between lanes of one direction [m], each shape (k, 2).
        no_overtaking: the no-overtaking zones' double line, two solid lines
            ``ZONE_LINE_GAP_M`` apart on either side of the centre line along each zone
            [m], each shape (k, 2).
    """

    solid: tuple[np.ndarray, ...]
    dashed: tuple[np.ndarray, ...]
    no_overtaking: tuple[np.ndarray, ...] = ()


@dataclass(frozen=True, slots=True, eq=False)
class RoadGeometry:
    """The built road.

    Attributes:
        spec: the road description.
        main_line: main road reference line [m], shape (n, 2).
        cross_line: cross road reference line [m], shape (m, 2), or None.
        drivable_area: polygon [m] (a map road's may be a MultiPolygon).
        boundaries: polylines [m] lined with walls or kerbs, each shape (k, 2).
    """

    spec: RoadSpec
    main_line: np.ndarray
    cross_line: np.ndarray | None
    drivable_area: Polygon | MultiPolygon
    boundaries: tuple[np.ndarray, ...]

    # ------------------------------------------------------------------ lanes

    def lane_offset(self, lane: int, direction: int) -> float:
        """Offset d of a lane centre from the reference line [m] (left of the reference).

        Args:
            lane: lane number from the right edge of the road in ``direction`` (across
                the whole road: the lanes of the other direction have the high numbers).
            direction: +1 along the reference direction, -1 against.
        """
        spec = self.spec
        check(0 <= lane < spec.lanes, f"lane must lie in 0..{spec.lanes - 1}, got {lane}")
        return direction * (-spec.half_width + (lane + 0.5) * spec.lane_width)

    def lanes_in(self, direction: int) -> tuple[int, ...]:
        """The lanes that run in ``direction``, numbered from the right in that direction.

        Args:
            direction: +1 along the reference direction, -1 against.

        Returns:
            ``0 .. n - 1`` with n = ``road.lanes_forward`` (+1) or ``road.lanes_backward``
            (-1); the other numbers of ``lane_offset(lane, direction)`` are the lanes of
            the other direction.
        """
        check(direction in (1, -1), f"direction must be 1 or -1, got {direction!r}")
        return tuple(range(self.spec.lanes_of(direction)))

    def lane_runs(self, lane: int, direction: int) -> int:
        """The direction of travel of lane ``lane`` (numbered from the right in ``direction``).

        Returns:
            ``direction`` if the lane runs that way, ``-direction`` if it belongs to the
            other direction (an overtaker's or a wrong-way driver's lane).
        """
        check(0 <= lane < self.spec.lanes, f"lane must lie in 0..{self.spec.lanes - 1}, got {lane}")
        return direction if lane in self.lanes_in(direction) else -direction

    def lane_edges(self) -> np.ndarray:
        """Offsets d of the lane boundaries from the reference line [m], right to left, shape (lanes + 1,).

        The first and last are the road's outer lane edges (the shoulders lie beyond).
        """
        spec = self.spec
        return -spec.half_width + spec.lane_width * np.arange(spec.lanes + 1)

    @property
    def centre_offset(self) -> float | None:
        """Offset d of the centre line between the two directions [m]; None on a one-way road.

        The lanes of direction +1 lie right of it (d below it), those of direction -1 left.
        """
        spec = self.spec
        if spec.kind is RoadKind.MAP or spec.lanes_forward in (0, spec.lanes):
            return None
        return float(self.lane_edges()[spec.lanes_forward])

    def lane_markings(self) -> LaneMarkings:
        """The painted lines of the main road (and the cross road): solid edges and centre, dashed lanes.

        The outer lane edges (between lanes and shoulder) and the centre line between
        the two directions are solid, the lines between lanes of one direction dashed
        (``DASH_M`` painted, ``GAP_M`` free). A merge road's acceleration lane has its
        outer edge along the taper up to ``lane_drop`` and a dashed line to the main
        road up to there. A map road has none (its lanes are not
        numbered).
        """
        spec = self.spec
        if spec.kind is RoadKind.MAP:
            return LaneMarkings((), ())
        edges = self.lane_edges()
        centre = spec.lanes_forward
        solid: list[np.ndarray] = []
        dashed: list[np.ndarray] = []
        for line in (self.main_line, self.cross_line):
            if line is None:
                continue
            for i, d in enumerate(edges):
                marking = offset_polyline(line, float(d))
                if spec.kind is RoadKind.MERGE and i < 2:
                    # The acceleration lane: its outer edge follows the taper to the lane
                    # drop; the line to the main road is dashed up to there, the road's edge after.
                    x = line[:, 0]
                    before = x <= spec.lane_drop
                    if i == 0:
                        solid.append(np.column_stack([x[before], _merge_edge(spec, x[before], shoulder=0.0)]))
                    else:
                        dashed.extend(dashes(marking[before], DASH_M, GAP_M))
                        solid.append(marking[x >= spec.lane_drop])
                elif i in (0, spec.lanes) or (i == centre and self.centre_offset is not None):
                    solid.append(marking)
                else:
                    dashed.extend(dashes(marking, DASH_M, GAP_M))
        zones: list[np.ndarray] = []
        line = self.main_line
        arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(line, axis=0).T))])
        for zone in spec.no_overtaking:  # a few zones
            inner = (arc > zone.start) & (arc < zone.end)
            s = np.concatenate([[zone.start], arc[inner], [zone.end]])
            piece = np.column_stack([np.interp(s, arc, line[:, 0]), np.interp(s, arc, line[:, 1])])
            for side in (-1.0, 1.0):
                zones.append(offset_polyline(piece, float(self.centre_offset) + side * ZONE_LINE_GAP_M))
        return LaneMarkings(tuple(solid), tuple(dashed), tuple(zones))

    def _line(self, road: RoadName) -> np.ndarray:
        if road is RoadName.CROSS:
            check(self.cross_line is not None, "route.road 'cross' needs an intersection")
            return self.cross_line  # type: ignore[return-value]
        return self.main_line

    def route(self, spec: RouteSpec) -> np.ndarray:
        """Polyline of a route in its direction of travel [m], shape (n, 2)."""
        if spec.road is RoadName.WAYPOINTS:
            return _dedupe(np.asarray(spec.waypoints, dtype=float))
        if self.spec.kind is RoadKind.MAP:
            # A map road's main route is its reference path, shifted by the offset.
            line = offset_polyline(self.main_line, spec.direction * spec.offset)
            return line if spec.direction > 0 else line[::-1].copy()
        d = self.lane_offset(spec.lane, spec.direction) + spec.direction * spec.offset
        if spec.turn is Turn.STRAIGHT or self.spec.kind is not RoadKind.INTERSECTION:
            line = offset_polyline(self._line(spec.road), d)
            return line if spec.direction > 0 else line[::-1].copy()
        return self._turn_route(spec)

    def _turn_route(self, spec: RouteSpec) -> np.ndarray:
        half = 0.5 * self.spec.length
        edge = self.spec.half_width + 0.5 * self.spec.shoulder
        heading_in = {
            (RoadName.MAIN, 1): 0.0,
            (RoadName.MAIN, -1): math.pi,
            (RoadName.CROSS, 1): 0.5 * math.pi,
            (RoadName.CROSS, -1): -0.5 * math.pi,
        }[(spec.road, spec.direction)]
        heading_out = heading_in + (0.5 * math.pi if spec.turn is Turn.LEFT else -0.5 * math.pi)
        exit_road, exit_dir = _arm_of_heading(heading_out)
        d_in = self.lane_offset(spec.lane, spec.direction) + spec.direction * spec.offset
        # The same lane of the exit's own lanes (a wrong-way driver keeps to the other side).
        own_out = self.spec.lanes_of(exit_dir)
        lane_out = spec.lane if spec.wrong_way else min(spec.lane, max(own_out - 1, 0))
        d_out = self.lane_offset(lane_out, exit_dir) + exit_dir * spec.offset

        def point(road: RoadName, u: float, d: float) -> np.ndarray:
            return np.array([u, d]) if road is RoadName.MAIN else np.array([-d, u])

        n_arm = max(int((half - edge) / _SAMPLE_M), 2)
        u_in = np.linspace(-half, -edge, n_arm) * spec.direction
        entry = np.array([point(spec.road, u, d_in) for u in u_in])
        u_out = np.linspace(edge, half, n_arm) * exit_dir
        exit_ = np.array([point(exit_road, u, d_out) for u in u_out])
        bend = _bezier(entry[-1], heading_in, exit_[0], heading_out)
        return _dedupe(np.concatenate([entry, bend[1:-1], exit_]))

    def merge_route(self, s_start: float) -> np.ndarray:
        """The route from the acceleration lane into the main road's right lane [m], (n, 2).

        The offset moves from lane 0's centre to lane 1's along a quintic smoothstep
        (zero slope and curvature at both ends) over the 80 m (at most; from 10 m past
        ``s_start``) before the taper starts: the ego's reference path for a ramp start,
        which its planner's Frenet frame follows.

        Args:
            s_start: the ego's start along the main road [m].
        """
        spec = self.spec
        check(spec.kind is RoadKind.MERGE, "merge_route needs road.kind = 'merge'")
        s2 = spec.lane_drop - spec.taper
        s1 = max(s_start + 10.0, s2 - 80.0)
        x = self.main_line[:, 0]
        u = np.clip((x - s1) / max(s2 - s1, 1.0), 0.0, 1.0)
        d0 = -spec.half_width + 0.5 * spec.lane_width
        d = d0 + spec.lane_width * (10 * u**3 - 15 * u**4 + 6 * u**5)
        return np.column_stack([x, d])

    # ------------------------------------------------------------------ obstacles

    def _outward(self, mid: np.ndarray, normal: np.ndarray) -> np.ndarray:
        """``normal`` or its opposite: the one pointing away from the drivable area at ``mid``.

        The side with less road on a probe of ``OUTWARD_PROBE_M`` is outside. A point a few
        centimetres off the line does not tell: a simplified boundary (an imported map's
        outline is simplified by 0.1 m) can lie that far inside the road, which put a
        100 m kerb 0.3 m into DEU_A9-3_1's left lane.
        """
        ahead = LineString([mid, mid + OUTWARD_PROBE_M * normal])
        behind = LineString([mid, mid - OUTWARD_PROBE_M * normal])
        road_ahead = self.drivable_area.intersection(ahead).length
        road_behind = self.drivable_area.intersection(behind).length
        if road_ahead == road_behind:  # no road on either side, or on both: the closest look
            return -normal if self.drivable_area.contains(shapely.Point(*(mid + 0.05 * normal))) else normal
        return -normal if road_ahead > road_behind else normal

    def static_boxes(self) -> tuple[StaticBox, ...]:
        """Wall or kerb boxes along the boundaries, just outside the drivable area.

        Each boundary segment gets a box of thickness ``BOUNDARY_THICKNESS_M`` on its side
        away from the road, or pieces of it where the road would reach into it
        (``_off_road_spans``).
        """
        kind = self.spec.boundary
        if kind is Boundary.NONE:
            return ()
        t = BOUNDARY_THICKNESS_M
        height = BOUNDARY_HEIGHT_M[kind]
        shapely.prepare(self.drivable_area)
        boxes = []
        for line in self.boundaries:
            simple = np.asarray(LineString(line).simplify(0.05).coords)
            for a, b in zip(simple[:-1], simple[1:], strict=True):
                seg = b - a
                length = float(np.hypot(*seg))
                if length < 1e-3:
                    continue
                tangent = seg / length
                mid = 0.5 * (a + b)
                normal = self._outward(mid, np.array([-tangent[1], tangent[0]]))
                spans = self._off_road_spans(a, tangent, normal, length)
                for span in [None] if spans is None else spans:
                    if span is None:
                        center, half_length = mid + 0.5 * t * normal, 0.5 * length + 0.5 * t
                    else:
                        u0, u1 = span
                        center = a + 0.5 * (u0 + u1) * tangent + 0.5 * t * normal
                        half_length = 0.5 * (u1 - u0)
                    boxes.append(
                        StaticBox(
                            center=(float(center[0]), float(center[1])),
                            half_length=half_length,
                            half_width=0.5 * t,
                            half_height=0.5 * height,
                            yaw=float(math.atan2(tangent[1], tangent[0])),
                            kind=kind,
                        )
                    )
        return tuple(boxes)

    def _off_road_spans(
        self, a: np.ndarray, tangent: np.ndarray, normal: np.ndarray, length: float
    ) -> list[tuple[float, float]] | None:
        """Where along a boundary segment its box may stand: spans (u0, u1) [m] from ``a``.

        A segment's box runs from ``t / 2`` before ``a`` to ``t / 2`` past its end (so
        that boxes close the corners between them) and ``t`` outward. It stands at a
        cross-section where the road reaches no sample point at the depths beyond
        ``BOX_ROAD_TOLERANCE_M`` (0.2, 0.3 and 0.4 m, every ``BOX_SAMPLE_M`` along it; so
        road up to 0.2 m deep, or a bump narrower than the spacing, can go unseen): not in a
        crack between lanelets narrower than the box (the tip of the gap between two
        lanelets that part at an angle, where there is road on the box's far side), nor
        with its end past a sharp inner corner of the road, where it stood in the lane.

        Returns:
            None where the whole box stands (almost everywhere), else the spans.
        """
        t = BOUNDARY_THICKNESS_M
        n = max(math.ceil((length + t) / BOX_SAMPLE_M), 1) + 1
        u = np.linspace(-0.5 * t, length + 0.5 * t, n)
        depths = np.arange(BOX_ROAD_TOLERANCE_M + 0.05, t + 1e-9, 0.1)
        points = a + u[:, None, None] * tangent + depths[None, :, None] * normal  # (n, k, 2)
        free = ~shapely.contains_xy(self.drivable_area, points[..., 0], points[..., 1]).any(axis=1)
        if free.all():
            return None
        edges = np.flatnonzero(np.diff(np.concatenate([[0], free.astype(np.int8), [0]])))
        spans = [(float(u[i]), float(u[j - 1])) for i, j in zip(edges[::2], edges[1::2], strict=True)]
        return [(u0, u1) for u0, u1 in spans if u1 - u0 >= BOX_SAMPLE_M - 1e-9]


#: Height of debris boxes [m]: what they hide from the ego's sensor (physics.sight) and their picture.
DEBRIS_HEIGHT_M = 0.5


def debris_boxes(road: RoadGeometry, debris: tuple[DebrisSpec, ...]) -> tuple[StaticBox, ...]:
    """Static boxes of debris placed along the main road's reference line.

    Args:
        road: the built road.
        debris: debris of the scenario (``s`` along the main line from its start,
            ``offset`` left of it).

    Returns:
        One ``StaticBox`` of kind wall per piece (it stops every body).
    """
    if not debris:
        return ()
    line = road.main_line
    seg = np.diff(line, axis=0)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))])
    s = np.array([d.s for d in debris])
    x = np.interp(s, arc, line[:, 0])
    y = np.interp(s, arc, line[:, 1])
    k = np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(seg) - 1)
    theta = np.arctan2(seg[k, 1], seg[k, 0])
    offset = np.array([d.offset for d in debris])
    cx, cy = x - offset * np.sin(theta), y + offset * np.cos(theta)
    return tuple(
        StaticBox(
            center=(float(cx[i]), float(cy[i])),
            half_length=0.5 * d.length,
            half_width=0.5 * d.width,
            half_height=0.5 * DEBRIS_HEIGHT_M,
            yaw=float(theta[i] + math.radians(d.yaw)),
            kind=Boundary.WALL,
        )
        for i, d in enumerate(debris)
    )


def box_footprint(b: StaticBox) -> Polygon:
    """The footprint of a static box as a polygon [m]."""
    c, s = math.cos(b.yaw), math.sin(b.yaw)
    corners = [(sx * b.half_length, sy * b.half_width) for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
    return Polygon([(b.center[0] + u * c - v * s, b.center[1] + u * s + v * c) for u, v in corners])


def _arm_of_heading(heading: float) -> tuple[RoadName, int]:
    c, s = round(math.cos(heading)), round(math.sin(heading))
    return {
        (1, 0): (RoadName.MAIN, 1),
        (-1, 0): (RoadName.MAIN, -1),
        (0, 1): (RoadName.CROSS, 1),
        (0, -1): (RoadName.CROSS, -1),
    }[(c, s)]


def _main_line(spec: RoadSpec) -> np.ndarray:
    if spec.kind is RoadKind.STRAIGHT:
        n = max(int(spec.length / _SAMPLE_M), 2)
        return np.column_stack([np.linspace(0.0, spec.length, n + 1), np.zeros(n + 1)])
    if spec.kind is RoadKind.INTERSECTION:
        half = 0.5 * spec.length
        n = max(int(spec.length / _SAMPLE_M), 2)
        return np.column_stack([np.linspace(-half, half, n + 1), np.zeros(n + 1)])
    # Curved: lead-in along +x, arc, straight remainder.
    sign = 1.0 if spec.curve_angle > 0 else -1.0
    angle = math.radians(abs(spec.curve_angle))
    lead = np.linspace(0.0, spec.lead_in, max(int(spec.lead_in / _SAMPLE_M), 1) + 1)
    points = [np.column_stack([lead, np.zeros_like(lead)])]
    n_arc = max(int(spec.arc_length / _SAMPLE_M), 8)
    phi = np.linspace(0.0, angle, n_arc + 1)[1:]
    cx, cy = spec.lead_in, sign * spec.radius
    arc = np.column_stack([cx + spec.radius * np.sin(phi), cy - sign * spec.radius * np.cos(phi)])
    points.append(arc)
    rest = spec.length - spec.lead_in - spec.arc_length
    if rest > 1e-6:
        heading = sign * angle
        u = np.linspace(0.0, rest, max(int(rest / _SAMPLE_M), 1) + 1)[1:]
        end = arc[-1]
        points.append(np.column_stack([end[0] + u * math.cos(heading), end[1] + u * math.sin(heading)]))
    return _dedupe(np.concatenate(points))


#: Gaps narrower than twice this between a map's area polygons are closed [m]: the shared
#: edges of neighbouring lanelets often miss each other by millimetres (NGSIM), and the
#: slivers between them would become holes lined with kerbs inside the road.
AREA_GAP_M = 0.05


def close_union(polygons: Sequence[Polygon], gap: float = AREA_GAP_M):  # noqa: ANN201 - a shapely geometry
    """Union of ``polygons`` with gaps narrower than ``2 gap`` closed [m].

    Each polygon grows by ``gap`` (mitred, so corners stay corners), the union shrinks
    by ``gap`` again: wider gaps and real holes (traffic islands) stay.
    """
    grown = [p.buffer(gap, join_style="mitre") for p in polygons if not p.is_empty and p.area > 0]
    return shapely.union_all(grown).buffer(-gap, join_style="mitre")


#: Spacing of the samples along a route that find where its mapped road ends [m].
MAP_END_STEP_M = 0.1


def map_end(area: Polygon | MultiPolygon, path: ReferencePath, s_from: float) -> float:
    """Arc length along ``path`` where its mapped road ends [m], or ``inf``.

    The end is where the path, followed from ``s_from``, leaves ``area`` for good: an
    imported map's path runs on past its last lanelet (``commonroad.PATH_EXTENSION_M``).
    Every stretch outside after which the path comes back onto the area is bridged,
    whatever its length (a joint or sliver between lanelets, a junction or median the map
    leaves out): the map goes on there. A path that starts outside the area is followed
    until it enters. The result lies within ``MAP_END_STEP_M / 2`` of the crossing.

    Args:
        area: the drivable area [m].
        path: the ego's reference path.
        s_from: arc length to start from (the ego's start) [m].

    Returns:
        the arc length of the map's end [m]; ``inf`` if the path never leaves the area
        after entering it, or never enters it.
    """
    s = np.arange(max(s_from, 0.0), path.length + MAP_END_STEP_M, MAP_END_STEP_M)
    x, y = path.evaluate(s)[:2]
    inside = shapely.contains_xy(area, x, y)
    if not inside.any():
        return math.inf
    if inside[-1]:
        return math.inf  # the path ends on the map
    # The last sample on the area; the stretch after it runs outside to the path's end.
    last_inside = len(inside) - 1 - int(np.argmax(inside[::-1]))
    return float(s[last_inside + 1]) - 0.5 * MAP_END_STEP_M


def _map_road(spec: RoadSpec) -> RoadGeometry:
    """The geometry of a map road: the union of its area polygons, its own boundaries."""
    road_map = spec.map
    polygons = [shapely.make_valid(Polygon(ring)) for ring in road_map.area]
    area = close_union(polygons)
    if not isinstance(area, Polygon | MultiPolygon):
        parts = [g for g in getattr(area, "geoms", []) if isinstance(g, Polygon | MultiPolygon)]
        area = shapely.unary_union(parts)
    check(not area.is_empty, "road.map.area has no area")
    main = _dedupe(np.asarray(road_map.reference_path, dtype=float))
    check(len(main) >= 2, "road.map.reference_path needs two distinct points")
    boundaries = tuple(_dedupe(np.asarray(line, dtype=float)) for line in road_map.boundaries)
    return RoadGeometry(spec, main, None, area, tuple(b for b in boundaries if len(b) >= 2))


def _merge_edge(spec: RoadSpec, x: np.ndarray, shoulder: float) -> np.ndarray:
    """Right edge y [m] of a merge road at x [m]: the acceleration lane's, narrowing over the taper."""
    full = -(spec.half_width + spec.parking_width + shoulder)
    dropped = -(spec.half_width - spec.lane_width + shoulder)
    u = np.clip((x - (spec.lane_drop - spec.taper)) / spec.taper, 0.0, 1.0)
    return full + (dropped - full) * u


def _merge_road(spec: RoadSpec) -> RoadGeometry:
    """A straight one-way road whose right-most lane narrows over the taper and ends at ``lane_drop``."""
    main = _main_line(RoadSpec(length=spec.length))
    x = np.union1d(main[:, 0], [spec.lane_drop - spec.taper, spec.lane_drop])
    right = np.column_stack([x, _merge_edge(spec, x, spec.shoulder)])
    left = offset_polyline(main, spec.half_width + spec.shoulder)
    area = Polygon(np.concatenate([right, left[::-1]]))
    return RoadGeometry(spec, main, None, area, (left, right))


def build_road(spec: RoadSpec) -> RoadGeometry:
    """Build the road geometry of ``spec``."""
    if spec.kind is RoadKind.MAP:
        return _map_road(spec)
    if spec.kind is RoadKind.MERGE:
        return _merge_road(spec)
    main = _main_line(spec)
    right = spec.half_width + spec.parking_width + spec.shoulder
    left = spec.half_width + spec.shoulder
    if spec.kind is not RoadKind.INTERSECTION:
        left_line = offset_polyline(main, left)
        right_line = offset_polyline(main, -right)
        ring = np.concatenate([right_line, left_line[::-1]])
        area = shapely.make_valid(Polygon(ring))
        if not isinstance(area, Polygon):
            area = max(getattr(area, "geoms", [area]), key=lambda g: g.area)
        return RoadGeometry(spec, main, None, area, (left_line, right_line))
    half = 0.5 * spec.length
    cross = np.column_stack([np.zeros(len(main)), main[:, 0]])
    union = box(-half, -right, half, left).union(box(-left, -half, right, half))
    radius = spec.corner_radius
    area = union.buffer(radius, join_style="round").buffer(-radius, join_style="round")
    if radius == 0:
        area = union
    area = area.intersection(box(-half, -half, half, half))
    inner = box(-half + 1e-3, -half + 1e-3, half - 1e-3, half - 1e-3)
    edges = area.exterior.intersection(inner)
    parts = edges.geoms if isinstance(edges, MultiLineString) else [edges]
    boundaries = tuple(np.asarray(shapely.line_merge(p).coords) for p in parts if p.length > 0)
    return RoadGeometry(spec, main, cross, area, _merge_lines(boundaries))


def _merge_lines(lines: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
    merged = shapely.line_merge(MultiLineString([LineString(line) for line in lines]))
    parts = merged.geoms if isinstance(merged, MultiLineString) else [merged]
    return tuple(np.asarray(p.coords) for p in parts)
