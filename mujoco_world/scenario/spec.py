"""Scenario descriptions: road, ego, road users and their behaviour, contact settings.

A scenario is a tree of frozen dataclasses, validated at construction. It can be
written in TOML (see ``data/example_scenario.toml``) and loaded with
``load_scenario``; unknown keys are rejected by their dotted name.

Conventions: lanes are counted from the right edge of the road *in the direction of
travel* (lane 0 is the right-hand lane of a road user's own direction), lateral
offsets are positive to the left of the direction of travel, and arc lengths ``s``
are measured along a road user's own route from its start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from ethical_planner.environment import StopLine
from ethical_planner.geometry import rectangle_corners
from ethical_planner.impulse import RestitutionLaw
from ethical_planner.records import errors_in, from_mapping, read_toml
from ethical_planner.road_users import DEFAULT_SHAPES, EGO_MASS_KG, EGO_SHAPE, RoadUserType
from ethical_planner.validation import check, check_finite, check_non_negative, check_positive, parse_enum
from mujoco_world.scenario.imported import MapSpec, ObstacleSpec, Points, RecordedTrajectory, points

#: Run outcomes the closed loop gives (``loop.summary``; here so that ``[expect]`` can
#: name them).
OUTCOMES = ("goal", "timeout", "stopped_safely", "no_progress", "left_map", "crash", "failed")


def knots(owner: str, name: str, value: Any) -> tuple[tuple[float, float], ...]:
    """Validate a sequence of (time [s], value) knots with strictly increasing times."""
    try:
        pairs = tuple((float(t), float(v)) for t, v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}.{name} must be a list of [time, value] pairs, got {value!r}") from None
    for t, v in pairs:
        if not (math.isfinite(t) and math.isfinite(v)):
            raise ValueError(f"{owner}.{name} must hold finite numbers, got {value!r}")
    times = [t for t, _ in pairs]
    if any(b <= a for a, b in zip(times, times[1:], strict=False)) or (times and times[0] < 0):
        raise ValueError(f"{owner}.{name} times must be >= 0 and strictly increasing, got {times}")
    return pairs


#: Plausible range of every physical quantity of a scenario: (low, high, unit). A value
#: outside is rejected by name (``check_plausible``); the table is the documentation
#: (``mujoco_world/README.md`` lists it, a test keeps the two equal).
RANGES: dict[str, tuple[float, float, str]] = {
    "scenario.duration": (0.1, 3600.0, "s"),
    "road.length": (10.0, 20000.0, "m"),
    "road.lane_width": (2.0, 6.0, "m"),
    "road.speed_limit": (1.0, 70.0, "m/s"),
    "road.parking_width": (0.0, 5.0, "m"),
    "road.shoulder": (0.0, 10.0, "m"),
    "road.radius": (5.0, 10000.0, "m"),
    "road.lead_in": (0.0, 20000.0, "m"),
    "road.corner_radius": (0.0, 50.0, "m"),
    "road.lane_drop": (10.0, 20000.0, "m"),
    "road.taper": (1.0, 1000.0, "m"),
    "route.offset": (-20.0, 20.0, "m"),
    "idm.time_headway": (0.0, 10.0, "s"),
    "idm.min_gap": (0.0, 50.0, "m"),
    "idm.max_acceleration": (0.1, 10.0, "m/s^2"),
    "idm.comfort_deceleration": (0.1, 10.0, "m/s^2"),
    "idm.max_deceleration": (0.1, 15.0, "m/s^2"),
    "idm.reaction_time": (0.0, 3.0, "s"),
    "idm.look_ahead": (1.0, 1000.0, "m"),
    "mobil.politeness": (-1.0, 5.0, "-"),
    "mobil.threshold": (0.0, 5.0, "m/s^2"),
    "mobil.b_safe": (0.5, 15.0, "m/s^2"),
    "mobil.bias_right": (0.0, 5.0, "m/s^2"),
    "mobil.duration": (1.0, 15.0, "s"),
    "mobil.cooldown": (0.0, 60.0, "s"),
    "mobil.pass_right_below": (0.0, 70.0, "m/s"),
    "crossing.wait_at": (0.0, 20000.0, "m"),
    "crossing.gap_time": (0.0, 60.0, "s"),
    "crossing.corridor": (0.5, 100.0, "m"),
    "behaviour.speed": (0.0, 70.0, "m/s"),
    "behaviour.start_time": (0.0, 3600.0, "s"),
    "behaviour.trigger_distance": (0.1, 1000.0, "m"),
    "behaviour.speed_profile": (0.0, 70.0, "m/s"),
    "behaviour.lateral": (-20.0, 20.0, "m"),
    "behaviour.ego_reaction": (0.0, 1.0, "-"),
    "when.time": (0.0, 3600.0, "s"),
    "when.delay": (0.0, 3600.0, "s"),
    "when.distance_below": (0.1, 1000.0, "m"),
    "when.distance_above": (0.1, 1000.0, "m"),
    "when.ttc_below": (0.01, 60.0, "s"),
    "when.s_above": (0.0, 20000.0, "m"),
    "when.s_below": (0.0, 20000.0, "m"),
    "when.speed_above": (0.0, 70.0, "m/s"),
    "when.speed_below": (0.0, 70.0, "m/s"),
    "do.speed": (0.0, 70.0, "m/s"),
    "do.acceleration": (0.1, 15.0, "m/s^2"),
    "do.speed_profile": (0.0, 70.0, "m/s"),
    "do.lateral": (-20.0, 20.0, "m"),
    "do.duration": (0.1, 30.0, "s"),
    "legal.speed_limit": (0.0, 70.0, "m/s"),
    "legal.lateral_half_width": (0.0, 20.0, "m"),
    "road_user.s0": (0.0, 20000.0, "m"),
    "road_user.length": (0.2, 25.0, "m"),
    "road_user.width": (0.2, 4.0, "m"),
    "road_user.mass": (20.0, 60000.0, "kg"),
    "ego.length": (1.0, 25.0, "m"),
    "ego.width": (0.5, 4.0, "m"),
    "ego.mass": (100.0, 60000.0, "kg"),
    "ego.s0": (0.0, 20000.0, "m"),
    "ego.speed": (0.0, 70.0, "m/s"),
    "ego.desired_speed": (0.0, 70.0, "m/s"),
    "contact.timeconst": (0.002, 1.0, "s"),
    "contact.dampratio": (0.1, 100.0, "-"),
    "contact.friction": (0.0, 2.0, "-"),
    "restitution.speed_scale": (0.1, 100.0, "m/s"),
    "sensor.range": (1.0, 2000.0, "m"),
    "sensor.fov": (1.0, 360.0, "deg"),
    "sensor.height": (0.1, 5.0, "m"),
    "sensor.offset": (-15.0, 15.0, "m"),
    "debris.s": (0.0, 20000.0, "m"),
    "stop_line.s": (0.0, 20000.0, "m"),
    "no_overtaking.start": (0.0, 20000.0, "m"),
    "no_overtaking.end": (0.0, 20000.0, "m"),
    "no_overtaking.pass_below": (0.0, 70.0, "m/s"),
    "stop_line.stop_zone": (0.5, 100.0, "m"),
    "debris.offset": (-20.0, 20.0, "m"),
    "debris.length": (0.1, 20.0, "m"),
    "debris.width": (0.1, 10.0, "m"),
    "debris.yaw": (-180.0, 180.0, "deg"),
    "expect.max_ego_harm": (0.0, 1000.0, "-"),
    "expect.max_third_party_harm": (0.0, 1000.0, "-"),
    "expect.max_vulnerable_harm": (0.0, 1000.0, "-"),
    "expect.min_distance": (-10.0, 1000.0, "m"),
    "expect.min_distance_vulnerable": (-10.0, 1000.0, "m"),
    "expect.min_ttc": (0.0, 100.0, "s"),
    "expect.min_progress": (0.0, 20000.0, "m"),
}
#: Most road users of one scenario (``Scenario.road_users``).
MAX_ROAD_USERS = 2000


def check_plausible(owner: str, record: object) -> None:
    """Raise a ValueError naming ``owner.field`` for a value outside its ``RANGES`` entry.

    Knot lists (``speed_profile``, ``lateral``) are checked value by value; None passes.
    """
    for key, (low, high, unit) in RANGES.items():
        prefix, name = key.split(".")
        if prefix != owner:
            continue
        value = getattr(record, name)
        values = [v for _, v in value] if isinstance(value, tuple) else [value]
        for v in values:
            if v is not None and not low <= v <= high:
                raise ValueError(f"{key} must lie in [{low:g}, {high:g}] {unit}, got {v!r}")


#: A merge road's default lane drop and taper [m] (``RoadSpec.lane_drop``, ``taper``).
MERGE_LANE_DROP_M = 150.0
MERGE_TAPER_M = 50.0


class RoadKind(StrEnum):
    """Road layout."""

    STRAIGHT = "straight"
    CURVED = "curved"
    INTERSECTION = "intersection"
    MAP = "map"
    MERGE = "merge"


class Boundary(StrEnum):
    """What lines the drivable area: walls stop every body, kerbs only motor vehicles."""

    WALL = "wall"
    KERB = "kerb"
    NONE = "none"


class PostCrashPolicy(StrEnum):
    """What the ego's controller does after its first contact (``[ego] post_crash``).

    Inside an impact (``ImpactRecorder.in_impact``: the high-force part of a contact
    pulse, above ``MeasurementWindow.impact_acceleration`` times the body's mass) every
    body's controller force is zero under either policy; a scrape or a body pressed
    against a wall keeps its controller. A measured delta-v integrates contact forces
    only, so it is the contact's alone. Outside impacts:

    ``brake``: the ego stops following plans and brakes to rest at up to mu g, as a
    multi-collision brake does (the default: it keeps the catalog's outcomes as they
    were, and a crashed ego coming to rest ends the run as ``crash`` at rest).
    ``continue``: the ego's planner keeps replanning from the measured state and the
    ego keeps tracking its plans (an automated vehicle that scrapes a wall keeps
    braking and steering). Other road users brake to rest after their first contact
    under both policies.
    """

    BRAKE = "brake"
    CONTINUE = "continue"


class RoadName(StrEnum):
    """Which road a route follows; ``waypoints`` gives it explicitly."""

    MAIN = "main"
    CROSS = "cross"
    WAYPOINTS = "waypoints"


class Turn(StrEnum):
    """Manoeuvre at an intersection."""

    STRAIGHT = "straight"
    LEFT = "left"
    RIGHT = "right"


class BehaviourKind(StrEnum):
    """How a road user moves.

    scripted: follows its speed profile and lateral profile, blind to everything.
    idm: car following (intelligent driver model) with braking for obstacles ahead.
    pedestrian: walks to ``crossing.wait_at``, waits for a gap, then crosses.
    parked: holds its start pose with its brakes.
    recorded: follows ``trajectory`` (a recording), blind to everything; it exists in
        the world only while its recording lasts.
    """

    SCRIPTED = "scripted"
    IDM = "idm"
    PEDESTRIAN = "pedestrian"
    PARKED = "parked"
    RECORDED = "recorded"


@dataclass(frozen=True, slots=True)
class NoOvertakingSpec:
    """A no-overtaking zone of the main road (``[[road.no_overtaking]]``).

    Inside it the ego keeps out of the lanes of the other direction: the planner makes
    a candidate whose footprint moves further across the centre line invalid (level 4,
    ``ethical_planner.traffic_rules.breaks_lane_rules``), and the world counts each time
    the ego's footprint enters the other direction's lanes inside the zone as a
    ``no_overtaking`` violation (``loop.metrics.RuleViolations``). Passing debris, or a
    road user slower than ``pass_below``, that blocks the ego's lane is not overtaking
    (the UK Highway Code, rule 129: a solid centre line may be crossed to pass a
    stationary vehicle, or a cyclist, horse or road works vehicle at 10 mph or less).

    Attributes:
        start, end: arc lengths along the main road's reference line [m], start < end.
        name: identifier for the summary (default ``no_overtaking_<i>``).
        pass_below: [m/s]; 4.47 is 10 mph; 0 allows no exception.
    """

    start: float
    end: float
    name: str = ""
    pass_below: float = 4.47

    def __post_init__(self) -> None:
        check_finite("no_overtaking", start=self.start, end=self.end, pass_below=self.pass_below)
        check_non_negative("no_overtaking", start=self.start, pass_below=self.pass_below)
        check(
            self.start < self.end,
            f"no_overtaking.end must lie beyond no_overtaking.start ({self.start:g} m), got {self.end:g}",
        )
        check(
            isinstance(self.name, str) and (not self.name or self.name.isidentifier()),
            f"no_overtaking.name must be an identifier (letters, digits, _), got {self.name!r}",
        )
        check_plausible("no_overtaking", self)


@dataclass(frozen=True, slots=True)
class RoadSpec:
    """Road geometry.

    Attributes:
        kind: straight, curved (lead-in, arc, straight remainder), a four-way
            intersection of the main road (along x) and a cross road (along y), or a
            map (``map`` gives the geometry; ``length`` is the length of its reference
            path, the lane and curve fields are not used), or a merge: a straight
            one-way carriageway (every lane runs along +x) whose right-most lane 0 is an
            acceleration lane that narrows over ``taper`` and ends at ``lane_drop``.
        length: centre-line length of the main road [m] (and of the cross road).
        lanes: number of lanes of each road, both directions together.
        lanes_forward: how many of them run along the road's reference direction
            (main: +x, cross: +y); the others run against it. None (the default) is
            half of them, rounded up: ``lanes = 2`` is one lane each way, ``lanes = 1``
            one lane along the reference, ``lanes = 3`` two along and one against. A
            one-way road has ``lanes_forward = lanes``. Lanes are numbered across the
            whole road from the right edge of a direction of travel, so the lanes of
            direction +1 are 0 .. lanes_forward - 1 and those of direction -1 are
            0 .. lanes - lanes_forward - 1 (``RoadGeometry.lanes_in``).
        lane_width: [m].
        speed_limit: [m/s].
        parking_width: drivable parking strip right of the main road's reference
            direction [m] (parked vehicles stand in it).
        shoulder: extra drivable width beyond the outer lanes [m].
        boundary: what lines the drivable area.
        radius: curve radius of the centre line [m] (curved only).
        curve_angle: turning angle of the arc [deg], positive to the left (curved only).
        lead_in: straight before the arc [m] (curved only).
        corner_radius: kerb radius at the intersection corners [m].
        map: the road's geometry (``kind = "map"`` only).
        lane_drop: merge roads only: arc length along the main road where the
            acceleration lane (lane 0, the right-most) has ended [m] (default 150).
        taper: merge roads only: length of the taper before ``lane_drop`` over which
            the acceleration lane narrows from full width to nothing [m] (default 50).
            Either on another kind of road is refused by name (None there).
        no_overtaking: no-overtaking zones of the main road (``NoOvertakingSpec``); they
            need lanes in both directions. Unnamed zones are named ``no_overtaking_<i>``.
    """

    kind: RoadKind = RoadKind.STRAIGHT
    length: float = 200.0
    lanes: int = 2
    lanes_forward: int | None = None
    lane_width: float = 3.5
    speed_limit: float = 13.9
    parking_width: float = 0.0
    shoulder: float = 0.5
    boundary: Boundary = Boundary.KERB
    radius: float = 80.0
    curve_angle: float = 60.0
    lead_in: float = 40.0
    corner_radius: float = 8.0
    map: MapSpec | None = None
    lane_drop: float | None = None
    taper: float | None = None
    no_overtaking: tuple[NoOvertakingSpec, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", parse_enum(RoadKind, self.kind, "road kind", "road.kind"))
        check(
            (self.map is not None) == (self.kind is RoadKind.MAP),
            "road.map is required with road.kind = 'map' and allowed only with it",
        )
        object.__setattr__(self, "boundary", parse_enum(Boundary, self.boundary, "boundary", "road.boundary"))
        check_positive(
            "road",
            length=self.length,
            lane_width=self.lane_width,
            speed_limit=self.speed_limit,
            radius=self.radius,
        )
        check_non_negative(
            "road",
            parking_width=self.parking_width,
            shoulder=self.shoulder,
            lead_in=self.lead_in,
            corner_radius=self.corner_radius,
        )
        check_finite("road", curve_angle=self.curve_angle)
        check_plausible("road", self)
        check(
            isinstance(self.lanes, int) and 1 <= self.lanes <= 8,
            f"road.lanes must be an integer in 1..8, got {self.lanes!r}",
        )
        forward = self.lanes_forward if self.lanes_forward is not None else (self.lanes + 1) // 2
        if self.kind is RoadKind.MERGE:
            # A merge road is one way: every lane runs along the reference direction.
            forward = self.lanes if self.lanes_forward is None else self.lanes_forward
            check(
                forward == self.lanes,
                f"road.lanes_forward of a merge road must be road.lanes ({self.lanes}: it is one way), "
                f"got {forward!r}",
            )
        check(
            isinstance(forward, int) and not isinstance(forward, bool) and 0 <= forward <= self.lanes,
            f"road.lanes_forward must be an integer in 0..road.lanes ({self.lanes}), got {forward!r}",
        )
        object.__setattr__(self, "lanes_forward", forward)
        zones = tuple(
            zone
            if zone.name
            else NoOvertakingSpec(zone.start, zone.end, f"no_overtaking_{i}", zone.pass_below)
            for i, zone in enumerate(self.no_overtaking)
        )
        object.__setattr__(self, "no_overtaking", zones)
        if zones:
            check(
                self.kind is not RoadKind.MAP and 0 < forward < self.lanes,
                "road.no_overtaking needs a centre line: lanes in both directions "
                f"(road.lanes = {self.lanes}, road.lanes_forward = {forward}) on a straight, curved or "
                "intersection road",
            )
        for i, zone in enumerate(zones):
            check(
                zone.end <= self.length,
                f"road.no_overtaking[{i}] ({zone.name}).end must lie on the road (<= road.length "
                f"{self.length:g} m), got {zone.end:g}",
            )
        names = [zone.name for zone in zones]
        twice = sorted({n for n in names if names.count(n) > 1})
        check(not twice, f"road.no_overtaking: duplicate names {twice}")
        if self.kind is RoadKind.CURVED:
            check(
                0 < abs(self.curve_angle) <= 180,
                f"road.curve_angle must lie in (0, 180] deg in magnitude, got {self.curve_angle}",
            )
            check(
                self.radius > self.half_width + 1.0,
                f"road.radius must exceed the road's half width + 1 m "
                f"({self.half_width + 1.0:.1f} m), got {self.radius}",
            )
            check(
                self.lead_in + self.arc_length <= self.length,
                f"road.length ({self.length} m) must cover lead_in + arc "
                f"({self.lead_in + self.arc_length:.1f} m)",
            )
        if self.kind is RoadKind.MERGE:
            if self.lane_drop is None:
                object.__setattr__(self, "lane_drop", MERGE_LANE_DROP_M)
            if self.taper is None:
                object.__setattr__(self, "taper", MERGE_TAPER_M)
            check(
                self.lanes >= 2,
                f"road.lanes of a merge road counts the acceleration lane and the main road's lanes "
                f"(at least 2), got {self.lanes}",
            )
            check(
                self.taper < self.lane_drop <= self.length - 10.0,
                f"road.lane_drop ({self.lane_drop:g} m) must lie after road.taper ({self.taper:g} m) and "
                f"at least 10 m before the road's end ({self.length:g} m)",
            )
        else:
            given = [name for name in ("lane_drop", "taper") if getattr(self, name) is not None]
            check(
                not given,
                f"road.{given[0] if given else ''} is only allowed with road.kind = 'merge' (an on-ramp's "
                f"acceleration lane), not {self.kind.value!r}",
            )
        if self.kind is RoadKind.INTERSECTION:
            check(
                self.length > 4 * (self.half_width + self.corner_radius),
                "road.length of an intersection must exceed 4 x (half width + corner_radius)",
            )

    @property
    def half_width(self) -> float:
        """Half the width of the lanes [m]."""
        return 0.5 * self.lanes * self.lane_width

    @property
    def lanes_backward(self) -> int:
        """Lanes that run against the reference direction (``lanes - lanes_forward``)."""
        return self.lanes - self.lanes_forward  # type: ignore[operator]

    def lanes_of(self, direction: int) -> int:
        """Number of lanes that run in ``direction`` (+1 along the reference, -1 against)."""
        return self.lanes_forward if direction > 0 else self.lanes_backward  # type: ignore[return-value]

    @property
    def arc_length(self) -> float:
        """Arc length of the curve of a curved road [m]."""
        return self.radius * math.radians(abs(self.curve_angle))


@dataclass(frozen=True, slots=True)
class RouteSpec:
    """The path a road user follows.

    Attributes:
        road: ``main``, ``cross`` (intersections only) or ``waypoints``.
        lane: lane index from the right in the direction of travel.
        direction: +1 along the road's reference direction (main: +x, cross: +y), -1 against.
        offset: lateral offset from the lane centre [m], positive left of travel.
        turn: manoeuvre at an intersection.
        waypoints: world positions [m] (``road = "waypoints"``), at least two.
        wrong_way: a wrong-way driver: its lane runs the other way. A route in a lane
            of the other direction is refused without it, and it is refused on a lane
            of the route's own direction (``Scenario`` checks both against
            ``road.lanes_forward``; pedestrians and parked road users are exempt).
    """

    road: RoadName = RoadName.MAIN
    lane: int = 0
    direction: int = 1
    offset: float = 0.0
    turn: Turn = Turn.STRAIGHT
    waypoints: tuple[tuple[float, float], ...] = ()
    wrong_way: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "road", parse_enum(RoadName, self.road, "road name", "route.road"))
        object.__setattr__(self, "turn", parse_enum(Turn, self.turn, "turn", "route.turn"))
        check(
            isinstance(self.lane, int) and self.lane >= 0,
            f"route.lane must be an integer >= 0, got {self.lane!r}",
        )
        check(self.direction in (1, -1), f"route.direction must be 1 or -1, got {self.direction!r}")
        check(
            isinstance(self.wrong_way, bool), f"route.wrong_way must be true or false, got {self.wrong_way!r}"
        )
        check_finite("route", offset=self.offset)
        check_plausible("route", self)
        try:
            points = tuple((float(x), float(y)) for x, y in self.waypoints)
        except (TypeError, ValueError):
            raise ValueError(
                f"route.waypoints must be a list of [x, y] pairs, got {self.waypoints!r}"
            ) from None
        check(
            all(math.isfinite(x) and math.isfinite(y) for x, y in points),
            "route.waypoints must be finite",
        )
        object.__setattr__(self, "waypoints", points)
        if self.road is RoadName.WAYPOINTS:
            check(len(points) >= 2, "route.waypoints needs at least two points for road = waypoints")
        else:
            check(not points, "route.waypoints is only allowed with road = 'waypoints'")


@dataclass(frozen=True, slots=True)
class IdmSpec:
    """Intelligent driver model (Treiber) with a reaction delay.

    Attributes:
        time_headway: desired time gap T [s].
        min_gap: standstill gap s0 [m].
        max_acceleration: a [m/s^2].
        comfort_deceleration: b [m/s^2].
        max_deceleration: braking limit [m/s^2].
        reaction_time: delay between perception and action [s].
        look_ahead: range of leader detection [m].
        stop_at: arc length of a stop line it obeys [m] (red light), or None.
        stop_until: time the stop line releases [s].
    """

    time_headway: float = 1.5
    min_gap: float = 2.0
    max_acceleration: float = 1.5
    comfort_deceleration: float = 2.0
    max_deceleration: float = 8.0
    reaction_time: float = 0.0
    look_ahead: float = 80.0
    stop_at: float | None = None
    stop_until: float = math.inf

    def __post_init__(self) -> None:
        check_non_negative(
            "idm",
            time_headway=self.time_headway,
            min_gap=self.min_gap,
            reaction_time=self.reaction_time,
        )
        check_positive(
            "idm",
            max_acceleration=self.max_acceleration,
            comfort_deceleration=self.comfort_deceleration,
            max_deceleration=self.max_deceleration,
            look_ahead=self.look_ahead,
        )
        check_finite("idm", stop_at=self.stop_at)
        check_plausible("idm", self)
        check(
            not math.isnan(self.stop_until) and self.stop_until >= 0,
            f"idm.stop_until must be >= 0 s (inf allowed), got {self.stop_until}",
        )


class EgoReaction(StrEnum):
    """Named levels of an idm road user's reaction to the ego (``behaviour.ego_reaction``).

    none: level 0, blind to the ego (a scripted hazard): it neither follows nor brakes
        for it, and its lane changes ignore it.
    idm: level 1, the ego is a vehicle like any other: followed and braked for as a
        leader, and counted as leader and follower by MOBIL (its safety criterion
        protects the ego when it would be the new follower).
    """

    NONE = "none"
    IDM = "idm"

    @property
    def level(self) -> float:
        """The reaction level of the name (0 or 1)."""
        return 0.0 if self is EgoReaction.NONE else 1.0


def reaction_level(value: Any) -> float:
    """``behaviour.ego_reaction`` as a level in [0, 1]: a number, or ``"none"`` (0) / ``"idm"`` (1).

    The level r weighs the ego in the road user's decisions: its acceleration (and each
    acceleration MOBIL weighs) is ``(1 - r) a_blind + r a_seeing``, the convex blend of
    what it would do blind to the ego and seeing it as a vehicle like any other (the
    form of the enhanced IDM's coolness factor, Kesting, Treiber, Helbing 2010).
    Between the ends it reacts weakly: it brakes for the ego ahead r times as much as
    an attentive driver would beyond what it does anyway (``mujoco_world/README.md``).

    Raises:
        ValueError: naming ``behaviour.ego_reaction``: an unknown name, a non-number or
            a level outside [0, 1].
    """
    if isinstance(value, str | EgoReaction):
        return parse_enum(EgoReaction, value, "ego reaction", "behaviour.ego_reaction").level
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(
            f"behaviour.ego_reaction must be a level in [0, 1] or one of none, idm, got {value!r}"
        )
    level = float(value)
    check(math.isfinite(level), f"behaviour.ego_reaction must be finite, got {value!r}")
    return level


@dataclass(frozen=True, slots=True)
class MobilSpec:
    """Reactive lane changes with MOBIL (Kesting, Treiber, Helbing 2007) for an idm road user.

    At each behaviour tick a road user not already changing lane weighs a change to
    each neighbouring lane of its own direction, with IDM accelerations computed in
    the current and the target lane (``agents.mobil``):
    ``(a~_c - a_c) + politeness ((a~_n - a_n) + (a~_o - a_o)) +- bias_right > threshold``
    (``+`` for a change to the right, ``-`` to the left: European keep-right rule), and
    changes if also the new follower and itself stay above ``-b_safe`` (safety).

    Attributes:
        politeness: p, weight of the followers' acceleration changes [-] (0 selfish).
        threshold: incentive threshold Delta a_th [m/s^2].
        b_safe: safe braking limit of the new follower and of itself [m/s^2].
        bias_right: keep-right bias Delta a_bias [m/s^2].
        duration: time of the lateral move [s].
        cooldown: time after a lane change ends before the next decision [s].
        no_passing_right: the European passing rule of MOBIL's asymmetric variant:
            its acceleration in a lane is at most the one behind the leader of the lane
            to its left, while that leader moves faster than ``pass_right_below``
            (``agents.mobil.no_passing_on_the_right``), in its decisions and its motion.
        pass_right_below: below this speed of the left lane's leader (congestion)
            passing on the right is allowed [m/s] (60 km/h, Kesting et al.'s v_crit).
    """

    politeness: float = 0.3
    threshold: float = 0.1
    b_safe: float = 4.0
    bias_right: float = 0.2
    duration: float = 4.0
    cooldown: float = 2.0
    no_passing_right: bool = False
    pass_right_below: float = 60.0 / 3.6

    def __post_init__(self) -> None:
        check_finite(
            "mobil",
            politeness=self.politeness,
            threshold=self.threshold,
            b_safe=self.b_safe,
            bias_right=self.bias_right,
            duration=self.duration,
            cooldown=self.cooldown,
            pass_right_below=self.pass_right_below,
        )
        check(
            isinstance(self.no_passing_right, bool),
            f"mobil.no_passing_right must be true or false, got {self.no_passing_right!r}",
        )
        check_plausible("mobil", self)


@dataclass(frozen=True, slots=True)
class CrossingSpec:
    """A pedestrian that waits at the kerb for a gap in the traffic.

    Attributes:
        wait_at: arc length along its route of the kerb where it waits [m].
        gap_time: smallest time gap [s] to an approaching vehicle it accepts.
        corridor: half width of the road strip a vehicle must be in to count [m].
    """

    wait_at: float = 2.0
    gap_time: float = 4.0
    corridor: float = 8.0

    def __post_init__(self) -> None:
        check_non_negative("crossing", wait_at=self.wait_at, gap_time=self.gap_time)
        check_positive("crossing", corridor=self.corridor)
        check_plausible("crossing", self)


@dataclass(frozen=True, slots=True)
class ConditionSpec:
    """When a scripted event fires: every condition given must hold (at a behaviour tick).

    Attributes:
        time: the run's time is at least this [s].
        delay: at least this long since the previous event of the script fired (or
            since the road user's activation for the first event) [s].
        to: whom ``distance_*`` and ``ttc_below`` measure to: ``ego`` or a road user's name.
        distance_below: centre distance to ``to`` is below this [m].
        distance_above: centre distance to ``to`` is above this [m].
        ttc_below: constant-velocity time-to-collision with ``to`` (footprints,
            ``physics.safety.time_to_collision``) is below this [s].
        of: whose position and speed ``s_*`` and ``speed_*`` read: ``self`` (default),
            ``ego`` or a road user's name.
        s_above, s_below: its arc length along its own route is above / below this [m]
            (the ego: along its route).
        speed_above, speed_below: its speed is above / below this [m/s].
    """

    time: float | None = None
    delay: float | None = None
    to: str = "ego"
    distance_below: float | None = None
    distance_above: float | None = None
    ttc_below: float | None = None
    of: str = "self"
    s_above: float | None = None
    s_below: float | None = None
    speed_above: float | None = None
    speed_below: float | None = None

    def __post_init__(self) -> None:
        check_finite(
            "when",
            **{name: getattr(self, name) for name in _CONDITION_VALUES},
        )
        check_plausible("when", self)
        check(
            any(getattr(self, name) is not None for name in _CONDITION_VALUES),
            f"needs at least one condition of {', '.join(_CONDITION_VALUES)}",
        )
        for name in ("to", "of"):
            value = getattr(self, name)
            check(
                isinstance(value, str) and value.isidentifier(),
                f"when.{name} must be 'ego', 'self' or a road user's name, got {value!r}",
            )
        check(self.to != "self", "when.to must be 'ego' or another road user's name, not 'self'")
        for quantity in ("distance", "s", "speed"):
            above, below = getattr(self, f"{quantity}_above"), getattr(self, f"{quantity}_below")
            if above is not None and below is not None:
                check(
                    above < below,
                    f"when.{quantity}_above ({above:g}) must be below when.{quantity}_below ({below:g}): "
                    "otherwise the event can never fire",
                )

    @property
    def needs_ego_s(self) -> bool:
        """True if it reads the ego's arc length along its route."""
        return self.of == "ego" and (self.s_above is not None or self.s_below is not None)


#: Conditions of ``ConditionSpec`` that take a value.
_CONDITION_VALUES = (
    "time",
    "delay",
    "distance_below",
    "distance_above",
    "ttc_below",
    "s_above",
    "s_below",
    "speed_above",
    "speed_below",
)


@dataclass(frozen=True, slots=True)
class ActionSpec:
    """What a scripted event does: at most one longitudinal and one lateral action.

    Times of knot lists count from the moment the event fires.

    Attributes:
        speed: go to this speed [m/s] at ``acceleration``.
        acceleration: rate of the speed change of ``speed``, ``stop`` and ``start``
            [m/s^2] (default 3).
        stop: brake to a standstill at ``acceleration``.
        start: go (back) to the behaviour's ``speed`` at ``acceleration``.
        speed_profile: (time [s], speed [m/s]) knots, linear between, from the speed
            at the event.
        lateral: (time [s], offset [m], positive left of travel) knots, smooth
            between, from the offset at the event.
        change_lane: move this many lanes (+ left, - right) over ``duration``.
        duration: time of a lane change [s] (default 3).
    """

    speed: float | None = None
    acceleration: float = 3.0
    stop: bool = False
    start: bool = False
    speed_profile: tuple[tuple[float, float], ...] = ()
    lateral: tuple[tuple[float, float], ...] = ()
    change_lane: int = 0
    duration: float = 3.0

    def __post_init__(self) -> None:
        for name in ("stop", "start"):
            check(isinstance(getattr(self, name), bool), f"do.{name} must be true or false")
        check(
            isinstance(self.change_lane, int) and not isinstance(self.change_lane, bool),
            f"do.change_lane must be an integer number of lanes, got {self.change_lane!r}",
        )
        check(abs(self.change_lane) <= 4, f"do.change_lane must lie in -4..4, got {self.change_lane}")
        check_finite("do", speed=self.speed, acceleration=self.acceleration, duration=self.duration)
        profile = knots("do", "speed_profile", self.speed_profile)
        check(all(v >= 0 for _, v in profile), "do.speed_profile speeds must be >= 0 m/s")
        object.__setattr__(self, "speed_profile", profile)
        object.__setattr__(self, "lateral", knots("do", "lateral", self.lateral))
        check_plausible("do", self)
        longitudinal = [
            name
            for name, given in (
                ("speed", self.speed is not None),
                ("stop", self.stop),
                ("start", self.start),
                ("speed_profile", bool(self.speed_profile)),
            )
            if given
        ]
        lateral = [
            name
            for name, given in (("lateral", bool(self.lateral)), ("change_lane", self.change_lane != 0))
            if given
        ]
        check(len(longitudinal) <= 1, f"takes one of speed, stop, start, speed_profile; got {longitudinal}")
        check(len(lateral) <= 1, f"takes one of lateral, change_lane; got {lateral}")
        check(
            longitudinal or lateral,
            "needs an action: speed, stop, start, speed_profile, lateral or change_lane",
        )


@dataclass(frozen=True, slots=True)
class EventSpec:
    """One step of a road user's script: when ``when`` holds, do ``do``.

    A road user's events run in order: event k is armed once event k - 1 has fired
    (the first once the road user is activated); each fires once.

    Attributes:
        when: the condition.
        do: the action.
    """

    when: ConditionSpec
    do: ActionSpec


@dataclass(frozen=True, slots=True)
class BehaviourSpec:
    """How a road user moves (see ``BehaviourKind``).

    Until it is activated (``start_time`` passed and, if set, the ego within
    ``trigger_distance``) a road user keeps ``speed`` and its route offset; then it
    follows ``speed_profile`` and ``lateral``, whose times count from activation.

    Attributes:
        kind: behaviour model.
        speed: initial (and, for idm, desired) speed [m/s].
        start_time: earliest activation [s].
        trigger_distance: activate once the ego's centre is this close [m], or None.
        speed_profile: (time [s], speed [m/s]) knots after activation, linear between.
        lateral: (time [s], offset [m], positive left of travel) knots after
            activation, smooth (cubic smoothstep) between.
        idm: car-following parameters (kind idm; defaults if omitted).
        crossing: gap acceptance (kind pedestrian; defaults if omitted).
        trajectory: the recording to follow (kind recorded only, required there).
        events: a script of triggered actions, run in order (``EventSpec``).
        mobil: reactive lane changes (kind idm only; None: it keeps its lane).
        ego_reaction: how much it reacts to the ego, a level in [0, 1] (kind idm
            only; default 1): 0 blind to it, 1 the ego is a vehicle like any other,
            between a convex blend of both (``reaction_level``). The names ``"none"``
            and ``"idm"`` stand for 0 and 1.
    """

    kind: BehaviourKind = BehaviourKind.SCRIPTED
    speed: float = 0.0
    start_time: float = 0.0
    trigger_distance: float | None = None
    speed_profile: tuple[tuple[float, float], ...] = ()
    lateral: tuple[tuple[float, float], ...] = ()
    idm: IdmSpec | None = None
    crossing: CrossingSpec | None = None
    trajectory: RecordedTrajectory | None = None
    events: tuple[EventSpec, ...] = ()
    mobil: MobilSpec | None = None
    ego_reaction: float | str | None = None

    def __post_init__(self) -> None:
        kind = parse_enum(BehaviourKind, self.kind, "behaviour kind", "behaviour.kind")
        if self.ego_reaction is not None:
            object.__setattr__(self, "ego_reaction", reaction_level(self.ego_reaction))
        check(
            (self.trajectory is not None) == (kind is BehaviourKind.RECORDED),
            "behaviour.trajectory is required with kind 'recorded' and allowed only with it",
        )
        object.__setattr__(self, "events", tuple(self.events))
        object.__setattr__(self, "kind", kind)
        check_non_negative("behaviour", speed=self.speed, start_time=self.start_time)
        check_positive("behaviour", trigger_distance=self.trigger_distance)
        profile = knots("behaviour", "speed_profile", self.speed_profile)
        check(
            all(v >= 0 for _, v in profile),
            "behaviour.speed_profile speeds must be >= 0 m/s",
        )
        object.__setattr__(self, "speed_profile", profile)
        object.__setattr__(self, "lateral", knots("behaviour", "lateral", self.lateral))
        check_plausible("behaviour", self)
        if kind is BehaviourKind.IDM:
            if self.idm is None:
                object.__setattr__(self, "idm", IdmSpec())
            if self.ego_reaction is None:
                object.__setattr__(self, "ego_reaction", EgoReaction.IDM.level)
        else:
            check(self.idm is None, f"behaviour.idm is only allowed with kind 'idm', not {kind.value!r}")
            check(
                self.mobil is None,
                f"behaviour.mobil (lane changes) is only allowed with kind 'idm', not {kind.value!r}",
            )
            check(
                self.ego_reaction is None,
                f"behaviour.ego_reaction is only allowed with kind 'idm', not {kind.value!r} "
                "(scripted and recorded road users are blind to the ego)",
            )
        if kind is BehaviourKind.PEDESTRIAN:
            if self.crossing is None:
                object.__setattr__(self, "crossing", CrossingSpec())
        else:
            check(
                self.crossing is None,
                f"behaviour.crossing is only allowed with kind 'pedestrian', not {kind.value!r}",
            )
        if kind is BehaviourKind.PARKED:
            check(
                self.speed == 0 and not self.speed_profile and not self.lateral and not self.events,
                "behaviour of kind 'parked' takes no speed, speed_profile, lateral or events",
            )
        if kind is BehaviourKind.RECORDED:
            check(
                self.speed == 0
                and self.start_time == 0
                and self.trigger_distance is None
                and not self.speed_profile
                and not self.lateral
                and not self.events,
                "behaviour of kind 'recorded' takes its motion from its trajectory only "
                "(no speed, start_time, trigger_distance, speed_profile, lateral or events)",
            )


@dataclass(frozen=True, slots=True)
class LegalSpec:
    """What a road user may legally do; handed to the planner as its LegalCorridor.

    Attributes:
        speed_limit: its legal speed [m/s]; None uses the road's.
        lateral_half_width: allowed sideways excursion of its centre [m].
        stop_line: arc length along its route of a stop line it must respect
            (red light) [m], or None.
        stop_until: time the stop line releases [s].
    """

    speed_limit: float | None = None
    lateral_half_width: float = 0.5
    stop_line: float | None = None
    stop_until: float = math.inf

    def __post_init__(self) -> None:
        check_non_negative("legal", speed_limit=self.speed_limit, lateral_half_width=self.lateral_half_width)
        check_finite("legal", stop_line=self.stop_line)
        check_plausible("legal", self)
        check(
            not math.isnan(self.stop_until) and self.stop_until >= 0,
            f"legal.stop_until must be >= 0 s (inf allowed), got {self.stop_until}",
        )


#: Road-user kinds a scenario may name beyond ``RoadUserType``: name -> (the type the
#: planner, the physics and the harm model see, default (length, width) [m], default
#: mass [kg], height [m]). A child is a pedestrian for the CRSS harm model (the model
#: has no age term); only its body is smaller, lighter and lower (a 6-7 year old: 23 kg,
#: 0.3 m wide, 1.2 m tall; the height matters for sight, ``physics.sight``).
SCENARIO_KINDS: dict[str, tuple[RoadUserType, tuple[float, float], float, float]] = {
    "child": (RoadUserType.PEDESTRIAN, (0.3, 0.3), 23.0, 1.2),
}


@dataclass(frozen=True, slots=True)
class RoadUserSpec:
    """One road user: its proxy body, route, behaviour and legal corridor.

    Attributes:
        name: unique name (MuJoCo body name).
        type: road-user type (car, truck, bus, motorcycle, bicycle, pedestrian...).
        route: the path it follows.
        s0: start arc length along the route [m].
        length: footprint length [m]; None uses the type's default shape.
        width: footprint width [m]; None uses the type's default shape.
        mass: [kg]; None uses ``mass_of`` (SPEC masses).
        behaviour: how it moves.
        legal: its legal corridor (rule violations become visible against it), or
            None to let the planner derive one.
        kind: a finer kind of its type from ``SCENARIO_KINDS`` ("child"), or None.
            ``type = "child"`` in a file sets ``type = "pedestrian", kind = "child"``.
    """

    name: str
    type: RoadUserType
    route: RouteSpec = field(default_factory=RouteSpec)
    s0: float = 0.0
    length: float | None = None
    width: float | None = None
    mass: float | None = None
    behaviour: BehaviourSpec = field(default_factory=BehaviourSpec)
    legal: LegalSpec | None = None
    kind: str | None = None

    def __post_init__(self) -> None:
        check(
            isinstance(self.name, str) and self.name.isidentifier(),
            f"road user name must be an identifier (letters, digits, _), got {self.name!r}",
        )
        if isinstance(self.type, str) and self.type in SCENARIO_KINDS:
            check(
                self.kind in (None, self.type),
                f"road_user.kind: type {self.type!r} cannot have kind {self.kind!r}",
            )
            object.__setattr__(self, "kind", str(self.type))
            object.__setattr__(self, "type", SCENARIO_KINDS[self.type][0])
        types = [t.value for t in RoadUserType if t is not RoadUserType.TRAIN]
        allowed = ", ".join([*types, *SCENARIO_KINDS])
        try:
            kind = parse_enum(RoadUserType, self.type, "road-user type", "type")
        except ValueError:
            raise ValueError(f"type: unknown road-user type {self.type!r}; allowed: {allowed}") from None
        object.__setattr__(self, "type", kind)
        if self.kind is not None:
            check(
                self.kind in SCENARIO_KINDS and SCENARIO_KINDS[self.kind][0] is kind,
                f"road_user.kind must be one of {sorted(SCENARIO_KINDS)} with its type, got {self.kind!r} "
                f"for type {kind.value!r}",
            )
        check_finite("road_user", s0=self.s0)
        check_positive("road_user", length=self.length, width=self.width, mass=self.mass)
        check_plausible("road_user", self)
        if self.type is RoadUserType.TRAIN:
            raise ValueError("type: trains are not supported as road users in mujoco_world")

    @property
    def shape(self) -> tuple[float, float]:
        """(length, width) of the footprint [m] (the kind's or the type's default unless given)."""
        if self.kind is not None:
            default_length, default_width = SCENARIO_KINDS[self.kind][1]
        else:
            default_length, default_width = DEFAULT_SHAPES[self.type].length, DEFAULT_SHAPES[self.type].width
        return (
            self.length if self.length is not None else default_length,
            self.width if self.width is not None else default_width,
        )

    @property
    def body_mass(self) -> float | None:
        """The mass given, else the kind's default mass [kg], else None (the type's mass)."""
        if self.mass is not None:
            return self.mass
        return SCENARIO_KINDS[self.kind][2] if self.kind is not None else None

    @property
    def body_height(self) -> float | None:
        """The kind's height [m], else None (the type's height)."""
        return SCENARIO_KINDS[self.kind][3] if self.kind is not None else None


@dataclass(frozen=True, slots=True)
class EgoSpec:
    """The ego vehicle, driven by the planner.

    Attributes:
        type: road-user type of the ego.
        length: [m]. width: [m]. mass: [kg].
        lane: start lane (from the right in its direction of travel) on the main road.
        s0: start arc length along its route [m].
        speed: initial speed [m/s].
        turn: manoeuvre at an intersection.
        goal_s: arc length along the route where the goal is reached [m]; None is
            20 m before the route's end.
        desired_speed: [m/s]; None uses the road's speed limit.
        pose: start pose (x [m], y [m], yaw [rad]) in the world; None starts on the
            route at ``s0`` (a map road's route is ``road.map.reference_path``).
        goal_region: polygons [m]; the goal is reached when the ego's centre is inside
            one of them (instead of at ``goal_s``).
        goal_time: a goal of time only: reached when the run has lasted this long [s]
            (not with ``goal_region``).
        post_crash: what the ego does after its first contact (``PostCrashPolicy``:
            "brake" or "continue").
    """

    type: RoadUserType = RoadUserType.CAR
    length: float = EGO_SHAPE.length
    width: float = EGO_SHAPE.width
    mass: float = EGO_MASS_KG
    lane: int = 0
    s0: float = 10.0
    speed: float = 10.0
    turn: Turn = Turn.STRAIGHT
    goal_s: float | None = None
    desired_speed: float | None = None
    pose: tuple[float, float, float] | None = None
    goal_region: tuple[Points, ...] = ()
    goal_time: float | None = None
    post_crash: PostCrashPolicy = PostCrashPolicy.BRAKE

    def __post_init__(self) -> None:
        object.__setattr__(self, "type", parse_enum(RoadUserType, self.type, "road-user type", "ego.type"))
        object.__setattr__(
            self,
            "post_crash",
            parse_enum(PostCrashPolicy, self.post_crash, "post-crash policy", "ego.post_crash"),
        )
        if self.pose is not None:
            try:
                x, y, yaw = (float(v) for v in self.pose)
            except (TypeError, ValueError):
                raise ValueError(f"ego.pose must be [x, y, yaw], got {self.pose!r}") from None
            check_finite("ego", pose_x=x, pose_y=y, pose_yaw=yaw)
            object.__setattr__(self, "pose", (x, y, yaw))
        object.__setattr__(
            self,
            "goal_region",
            tuple(points(f"ego.goal_region[{i}]", ring, 3) for i, ring in enumerate(self.goal_region)),
        )
        check_positive("ego", goal_time=self.goal_time)
        check(
            self.goal_time is None or not self.goal_region,
            "ego.goal_time (a goal of time only) is not allowed with ego.goal_region",
        )
        object.__setattr__(self, "turn", parse_enum(Turn, self.turn, "turn", "ego.turn"))
        check_positive("ego", length=self.length, width=self.width, mass=self.mass)
        check_non_negative("ego", speed=self.speed, desired_speed=self.desired_speed)
        check_finite("ego", s0=self.s0, goal_s=self.goal_s)
        check_plausible("ego", self)
        check(
            isinstance(self.lane, int) and self.lane >= 0,
            f"ego.lane must be an integer >= 0, got {self.lane!r}",
        )


class ContactMode(StrEnum):
    """How bodies touch (see ``mujoco_world.physics.contact``).

    ``rigid``: stiff contacts resolved with sub-steps during impacts; restitution follows
    the contact's ``RestitutionLaw`` at the contact point. The mode for validating
    harm-model inputs (rigid-body impulse mechanics within a few percent).
    ``crush``: deformable fronts, sides and rears (force-deflection per body region,
    softer pedestrians and cyclists); crash pulses of ~0.1 s with the peak force
    mid-pulse and 0.5-0.7 m of crush at 56 km/h into a wall.
    ``soft``: the near-plastic ``solref`` contact of wave 1 (``timeconst``, ``dampratio``);
    bodies sink into each other and it under-measures offset impacts: kept for comparison only.
    """

    RIGID = "rigid"
    CRUSH = "crush"
    SOFT = "soft"


# Measured restitution of two 1475 kg boxes head-on against the solref damping ratio at
# time constant 0.05 s (soft mode; regenerate with ``python benchmarks/restitution_table.py``).
SOFT_RESTITUTION_TABLE = (
    (0.1, 0.7501), (0.15, 0.6512), (0.2, 0.5708), (0.3, 0.4477), (0.4, 0.3591), (0.5, 0.2937),
    (0.7, 0.2057), (1.0, 0.1315), (1.5, 0.0730), (2.0, 0.0460), (3.0, 0.0228), (4.0, 0.0135),
    (6.0, 0.0063),
)  # fmt: skip
#: Restitution the force modes (rigid, crush) can produce.
FORCE_RESTITUTION = (0.01, 0.9)


def restitution_range(mode: ContactMode | str) -> tuple[float, float]:
    """Smallest and largest restitution a contact mode can produce."""
    if ContactMode(mode) is ContactMode.SOFT:
        return SOFT_RESTITUTION_TABLE[-1][1], SOFT_RESTITUTION_TABLE[0][1]
    return FORCE_RESTITUTION


@dataclass(frozen=True, slots=True)
class RestitutionSpec:
    """Restitution between two road-user types, overriding the contact's default law.

    Either a constant ``e``, or any of ``e_high``, ``e_low``, ``speed_scale`` (the
    others from the default law); see ``ethical_planner.impulse.RestitutionLaw``.

    Attributes:
        a: first type. b: second type (order does not matter).
        e: constant restitution in [0, 1], or None.
        e_high: restitution at high closing speed, or None.
        e_low: restitution at low closing speed, or None.
        speed_scale: [m/s], or None.
    """

    a: RoadUserType
    b: RoadUserType
    e: float | None = None
    e_high: float | None = None
    e_low: float | None = None
    speed_scale: float | None = None

    def __post_init__(self) -> None:
        for name in ("a", "b"):
            kind = parse_enum(RoadUserType, getattr(self, name), "road-user type", f"restitution.{name}")
            object.__setattr__(self, name, kind)
        check_finite(
            "restitution", e=self.e, e_high=self.e_high, e_low=self.e_low, speed_scale=self.speed_scale
        )
        law = (self.e_high, self.e_low, self.speed_scale)
        check(
            (self.e is None) != all(v is None for v in law),
            "restitution: give either e (a constant) or some of e_high, e_low, speed_scale",
        )
        for name in ("e", "e_high", "e_low"):
            value = getattr(self, name)
            check(value is None or 0.0 <= value <= 1.0, f"restitution.{name} must lie in [0, 1], got {value}")
        check_positive("restitution", speed_scale=self.speed_scale)
        check_plausible("restitution", self)

    def law(self, default: RestitutionLaw) -> RestitutionLaw:
        """The pair's restitution law, filling unset fields from ``default``."""
        if self.e is not None:
            return RestitutionLaw.constant(self.e)
        return RestitutionLaw(
            default.e_high if self.e_high is None else self.e_high,
            default.e_low if self.e_low is None else self.e_low,
            default.speed_scale if self.speed_scale is None else self.speed_scale,
        )


@dataclass(frozen=True, slots=True)
class ContactSpec:
    """Contact model between bodies (and between bodies and walls).

    Attributes:
        mode: ``rigid`` (default), ``crush`` or ``soft`` (see ``ContactMode``).
        friction: sliding friction between bodies (Coulomb); the planner's planar impulse
            model uses the same value as its largest impulse ratio.
        restitution_law: restitution against the normal closing speed at the contact
            point, for every pair without an entry in ``restitution`` (rigid and crush).
        restitution: per pair of types.
        timeconst: ``soft`` mode only: solref time constant [s] (pulse length, sinking depth).
        dampratio: ``soft`` mode only: solref damping ratio; >= 4 gives e ~ 0.01. In soft
            mode ``restitution`` entries give a constant e per pair (their ``e`` or
            ``e_high``) and the law is not used.
        exclude: pairs of road-user names that never touch (e.g. recorded bodies whose
            recorded footprints overlap).
    """

    mode: ContactMode = ContactMode.RIGID
    friction: float = 0.3
    restitution_law: RestitutionLaw = field(default_factory=RestitutionLaw)
    restitution: tuple[RestitutionSpec, ...] = ()
    timeconst: float = 0.05
    dampratio: float = 4.0

    exclude: tuple[tuple[str, str], ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode", parse_enum(ContactMode, self.mode, "contact mode", "contact.mode"))
        try:
            pairs = tuple((str(a), str(b)) for a, b in self.exclude)
        except (TypeError, ValueError):
            raise ValueError(
                f"contact.exclude must be a list of [name, name] pairs, got {self.exclude!r}"
            ) from None
        object.__setattr__(self, "exclude", pairs)
        check_positive("contact", timeconst=self.timeconst, dampratio=self.dampratio)
        check_non_negative("contact", friction=self.friction)
        check_plausible("contact", self)
        check(self.timeconst >= 0.002, "contact.timeconst must be >= 0.002 s (2 time steps)")
        check(
            isinstance(self.restitution_law, RestitutionLaw),
            "contact.restitution_law must be a table with e_high, e_low, speed_scale",
        )
        object.__setattr__(self, "restitution", tuple(self.restitution))
        seen = set()
        for r in self.restitution:
            key = frozenset((r.a, r.b))
            check(key not in seen, f"contact.restitution lists {r.a.value}-{r.b.value} twice")
            seen.add(key)
        # Every restitution must be reachable in this mode (its table of measured values).
        low, high = restitution_range(self.mode)
        laws = [("restitution_law", self.restitution_law)]
        laws += [(f"restitution[{k}]", r.law(self.restitution_law)) for k, r in enumerate(self.restitution)]
        for name, law in laws:
            for value in (law.e_high, law.e_low):
                check(
                    low <= value <= high,
                    f"contact.{name}.e must lie in [{low:g}, {high:g}] in {self.mode.value} mode, "
                    f"got {value:g}",
                )

    def law_for(self, a: RoadUserType | str, b: RoadUserType | str) -> RestitutionLaw:
        """Restitution law between types ``a`` and ``b`` (a wall or kerb: ``b = "static"``)."""
        key = {a, b}
        for r in self.restitution:
            if {r.a, r.b} == key:
                return r.law(self.restitution_law)
        return self.restitution_law


@dataclass(frozen=True, slots=True)
class SensorSpec:
    """What the ego can perceive (``physics.sight``).

    A road user is perceived if one of its five sample points (centre, corners) is
    within ``range``, within the field of view and, with ``occlusion``, not hidden
    behind a road user (``occluders``) or a static box (walls, kerbs, debris, fixed
    obstacles) that rises above the sight line from the sensor to the point at half the
    road user's height.

    Attributes:
        occlusion: bodies and static boxes hide what is behind them.
        occluders: which road users hide others: ``vehicles`` (the default:
            pedestrians and cyclists are seen around) or ``all``.
        range: perception range [m] around the sensor, or None for unlimited.
        fov: full opening angle of the field of view [deg], centred on the ego's
            heading (360: all around).
        height: sensor height above the road [m] (a roof camera: 1.2 m).
        offset: sensor position ahead of the ego's centre along its heading [m].
    """

    occlusion: bool = False
    occluders: str = "vehicles"
    range: float | None = None
    fov: float = 360.0
    height: float = 1.2
    offset: float = 0.0

    def __post_init__(self) -> None:
        check(
            isinstance(self.occlusion, bool),
            f"sensor.occlusion must be true or false, got {self.occlusion!r}",
        )
        check(
            self.occluders in ("vehicles", "all"),
            f"sensor.occluders must be 'vehicles' or 'all', got {self.occluders!r}",
        )
        check_positive("sensor", range=self.range, fov=self.fov, height=self.height)
        check_finite("sensor", offset=self.offset)
        check_plausible("sensor", self)

    @property
    def limited(self) -> bool:
        """True if the sensor misses anything (range, field of view or occlusion)."""
        return self.occlusion or self.range is not None or self.fov < 360.0


@dataclass(frozen=True, slots=True)
class DebrisSpec:
    """A static obstacle lying on the road (a fallen load, a rock): immovable.

    Debris is part of the road, not a road user: the physics holds it fixed like a
    wall (infinite mass, it stops every body), the planner sees it as a hole in the
    drivable area (as it sees the road's edges), and a collision with it is a
    collision with a static obstacle (the ego's harm as for a wall; debris has no
    harm of its own).

    Attributes:
        name: identifier (unique among debris).
        s: arc length of its centre along the main road's reference line [m].
        offset: lateral position of its centre from the reference line [m], positive
            left of the reference direction.
        length: along the road [m]. width: across the road [m].
        yaw: heading relative to the road [deg].
    """

    name: str
    s: float
    offset: float = 0.0
    length: float = 0.8
    width: float = 0.6
    yaw: float = 0.0

    def __post_init__(self) -> None:
        check(
            isinstance(self.name, str) and self.name.isidentifier(),
            f"debris name must be an identifier (letters, digits, _), got {self.name!r}",
        )
        check_finite("debris", s=self.s, offset=self.offset, yaw=self.yaw)
        check_positive("debris", length=self.length, width=self.width)
        check_plausible("debris", self)


@dataclass(frozen=True, slots=True)
class StopLineSpec:
    """A stop line on the ego's route: a traffic light's, or a stop sign's.

    The world checks the ego against it (``loop.metrics.RuleViolations``): crossing the
    line (the ego's front passing ``s``) while the light is red is a ``red_light``
    violation; crossing a stop sign's line without having stood still (below
    ``traffic_rules.STANDSTILL_MPS``) within ``stop_zone`` before it is a ``stop_sign`` violation. The
    planner receives the line as environment data (``RoadEnvironment.stop_lines``).

    Attributes:
        name: identifier (unique among stop lines).
        s: arc length of the line along the ego's route [m].
        red: time windows [s] (start, end) in which the light is red (amber counts as
            red); empty for a stop sign.
        stop: a stop sign: the ego must stand still before crossing.
        stop_zone: how far before the line the standstill counts [m] (stop signs).
    """

    name: str
    s: float
    red: tuple[tuple[float, float], ...] = ()
    stop: bool = False
    stop_zone: float = 10.0

    def __post_init__(self) -> None:
        check(
            isinstance(self.name, str) and self.name.isidentifier(),
            f"stop line name must be an identifier (letters, digits, _), got {self.name!r}",
        )
        check_finite("stop_line", s=self.s)
        check_positive("stop_line", stop_zone=self.stop_zone)
        check(isinstance(self.stop, bool), f"stop_line.stop must be true or false, got {self.stop!r}")
        try:
            red = tuple((float(a), float(b)) for a, b in self.red)
        except (TypeError, ValueError):
            raise ValueError(
                f"stop_line.red must be a list of [start, end] times [s], got {self.red!r:.80}"
            ) from None
        check(
            all(math.isfinite(a) and math.isfinite(b) and 0.0 <= a < b for a, b in red),
            f"stop_line.red: each window needs 0 <= start < end [s], got {red}",
        )
        check(
            all(b1 <= a2 for (_, b1), (a2, _) in zip(red, red[1:], strict=False)),
            f"stop_line.red: windows must be in order and not overlap, got {red}",
        )
        check(
            bool(red) != self.stop,
            "stop_line: give red windows (a traffic light) or stop = true (a stop sign), not both",
        )
        object.__setattr__(self, "red", red)
        check_plausible("stop_line", self)

    def as_stop_line(self) -> StopLine:
        """The line as the planner's environment data."""
        return StopLine(self.s, self.red, self.stop, self.stop_zone)


@dataclass(frozen=True, slots=True)
class ExpectSpec:
    """What a scenario expects of a run: each given item is checked and reported pass/fail.

    Items left out (None, or an empty ``outcome``) are not checked. See
    ``mujoco_world.loop.expectations`` for how each is measured.

    Attributes:
        outcome: accepted run outcomes (one name or a list).
        reach_goal: the ego reaches its goal (outcome ``goal``).
        ego_collision: the ego takes part in a collision.
        ego_strikes: the ego drives into something itself in one of its collisions: a
            fixed body (wall, kerb, debris, obstacle), or a road user whose approach
            speed to the contact is not above the ego's
            (``mujoco_world.evaluation.compare.ego_strikes``). ``false`` with
            ``ego_collision = true``: the ego was hit, and hit nobody itself.
        collision: any collision happens (the ego's or others').
        max_collisions: at most this many measured collisions.
        max_ego_collisions: at most this many measured collisions the ego takes part
            in (1: no second impact after being hit).
        max_ego_harm, max_third_party_harm, max_vulnerable_harm: at most this much
            measured harm in the group (the summary's ``harm``).
        min_distance: the ego keeps at least this distance to every road user [m].
        min_distance_vulnerable: the same to vulnerable road users [m].
        min_ttc: the ego's time-to-collision stays at least this long [s].
        min_progress: the ego gets at least this far along its route [m].
        max_rule_violations: at most this many traffic-rule violations of the ego
            (red lights, stop signs: ``StopLineSpec``).
    """

    outcome: str | tuple[str, ...] = ()
    reach_goal: bool | None = None
    ego_collision: bool | None = None
    ego_strikes: bool | None = None
    collision: bool | None = None
    max_collisions: int | None = None
    max_ego_collisions: int | None = None
    max_ego_harm: float | None = None
    max_third_party_harm: float | None = None
    max_vulnerable_harm: float | None = None
    min_distance: float | None = None
    min_distance_vulnerable: float | None = None
    min_ttc: float | None = None
    min_progress: float | None = None
    max_rule_violations: int | None = None

    def __post_init__(self) -> None:
        check(
            isinstance(self.outcome, str | list | tuple),
            f"expect.outcome must be an outcome name or a list of them, got {self.outcome!r}",
        )
        outcome = (self.outcome,) if isinstance(self.outcome, str) else tuple(self.outcome)
        bad = [o for o in outcome if o not in OUTCOMES]
        check(not bad, f"expect.outcome must name outcomes among {', '.join(OUTCOMES)}, got {bad}")
        object.__setattr__(self, "outcome", outcome)
        for name in ("reach_goal", "ego_collision", "ego_strikes", "collision"):
            value = getattr(self, name)
            check(
                value is None or isinstance(value, bool),
                f"expect.{name} must be true or false, got {value!r}",
            )
        for name in ("max_collisions", "max_ego_collisions", "max_rule_violations"):
            value = getattr(self, name)
            check(
                value is None or (isinstance(value, int) and not isinstance(value, bool)) and value >= 0,
                f"expect.{name} must be an integer >= 0, got {value!r}",
            )
        check_finite(
            "expect",
            max_ego_harm=self.max_ego_harm,
            max_third_party_harm=self.max_third_party_harm,
            max_vulnerable_harm=self.max_vulnerable_harm,
            min_distance=self.min_distance,
            min_distance_vulnerable=self.min_distance_vulnerable,
            min_ttc=self.min_ttc,
            min_progress=self.min_progress,
        )
        check_plausible("expect", self)

    @property
    def empty(self) -> bool:
        """True if nothing is expected."""
        return not self.outcome and all(
            getattr(self, f.name) is None for f in fields(self) if f.name != "outcome"
        )


@dataclass(frozen=True, slots=True)
class Scenario:
    """A complete scenario.

    Attributes:
        name: identifier (used for output folders).
        description: one line.
        road: road geometry.
        ego: the planner's vehicle.
        road_users: everyone else.
        duration: time limit [s].
        contact: contact model.
        sensor: what the ego perceives (occlusion, range).
        obstacles: fixed obstacles (bodies that never move; the planner does not perceive them).
        notes: what made the scenario (an importer's decisions and findings), for
            summaries and reports.
        debris: static obstacles placed along the road (the planner perceives them).
        stop_lines: traffic lights and stop signs on the ego's route (``StopLineSpec``).
        expect: what a run should give (checked and reported pass/fail), or None.
    """

    name: str
    description: str = ""
    road: RoadSpec = field(default_factory=RoadSpec)
    ego: EgoSpec = field(default_factory=EgoSpec)
    road_users: tuple[RoadUserSpec, ...] = ()
    duration: float = 20.0
    contact: ContactSpec = field(default_factory=ContactSpec)
    sensor: SensorSpec = field(default_factory=SensorSpec)
    obstacles: tuple[ObstacleSpec, ...] = ()
    notes: tuple[str, ...] = ()
    debris: tuple[DebrisSpec, ...] = ()
    stop_lines: tuple[StopLineSpec, ...] = ()
    expect: ExpectSpec | None = None

    def __post_init__(self) -> None:
        check(
            isinstance(self.name, str)
            and bool(self.name)
            and all(c.isalnum() or c in "_-." for c in self.name),
            f"name must be a non-empty string of letters, digits, _ - ., got {self.name!r}",
        )
        check_positive("scenario", duration=self.duration)
        check_plausible("scenario", self)
        check(
            len(self.road_users) <= MAX_ROAD_USERS,
            f"road_users: at most {MAX_ROAD_USERS} road users per scenario, got {len(self.road_users)}",
        )
        length = self.road.length
        check(
            self.ego.s0 < length,
            f"ego.s0 must lie on the road (< road.length {length:g} m), got {self.ego.s0}",
        )
        if self.ego.goal_s is not None:
            check(
                self.ego.s0 < self.ego.goal_s <= length,
                f"ego.goal_s must lie between ego.s0 ({self.ego.s0:g} m) and road.length ({length:g} m), "
                f"got {self.ego.goal_s}",
            )
        object.__setattr__(self, "road_users", tuple(self.road_users))
        names = [u.name for u in self.road_users]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        check(not duplicates, f"road_users: duplicate names {duplicates}")
        check("ego" not in names, "road_users: the name 'ego' is reserved")
        known = set(names)
        for a, b in self.contact.exclude:
            check(
                a in known and b in known and a != b,
                f"contact.exclude: {a!r} and {b!r} must be two different road users of the scenario",
            )
        object.__setattr__(self, "obstacles", tuple(self.obstacles))
        object.__setattr__(self, "notes", tuple(str(n) for n in self.notes))
        if self.road.kind is RoadKind.MAP:
            for i, user in enumerate(self.road_users):
                check(
                    user.route.road is RoadName.WAYPOINTS or user.route.lane == 0,
                    f"road_users[{i}] ({user.name}).route.lane must be 0 on a map road "
                    "(its main route is the reference path shifted by route.offset)",
                )
        object.__setattr__(self, "debris", tuple(self.debris))
        self._check_debris()
        object.__setattr__(self, "stop_lines", tuple(self.stop_lines))
        lines = [line.name for line in self.stop_lines]
        twice = sorted({n for n in lines if lines.count(n) > 1})
        check(not twice, f"stop_lines: duplicate names {twice}")
        front = self.ego.s0 + 0.5 * self.ego.length
        for i, line in enumerate(self.stop_lines):
            # A line the ego's front has passed at the start would count as crossed at
            # once; one beyond the road would never be checked.
            check(
                line.s > front,
                f"stop_lines[{i}] ({line.name}).s must lie ahead of the ego's front at the start "
                f"(> ego.s0 + ego.length / 2 = {front:g} m), got {line.s:g}",
            )
            check(
                self.road.kind is RoadKind.MAP or line.s <= length,
                f"stop_lines[{i}] ({line.name}).s must lie on the road (<= road.length {length:g} m), "
                f"got {line.s:g}",
            )
        lanes = self.road.lanes
        check(self.ego.lane < lanes, f"ego.lane must be < road.lanes ({lanes}), got {self.ego.lane}")
        forward = self.road.lanes_forward
        check(
            self.road.kind is RoadKind.MAP or self.ego.lane < forward,
            f"ego.lane must be a lane that runs the ego's way (along the reference direction: lanes "
            f"0..{forward - 1} of road.lanes_forward = {forward}), got {self.ego.lane}"
            if forward
            else "road.lanes_forward = 0 leaves the ego (which drives along the reference direction) no lane",
        )
        if self.road.kind is not RoadKind.INTERSECTION:
            check(
                self.ego.turn is Turn.STRAIGHT,
                "ego.turn is only allowed on an intersection road",
            )
        self._check_events()
        self._check_lane_changes()
        for i, user in enumerate(self.road_users):
            where = f"road_users[{i}] ({user.name})"
            route = user.route
            if route.road is not RoadName.WAYPOINTS:
                check(
                    user.s0 <= length,
                    f"{where}.s0 must lie on its road (<= road.length {length:g} m), got {user.s0}",
                )
            if route.road is not RoadName.WAYPOINTS:
                check(
                    route.lane < lanes,
                    f"{where}.route.lane must be < road.lanes ({lanes}), got {route.lane}",
                )
                self._check_lane_direction(where, user)
            if self.road.kind is not RoadKind.INTERSECTION:
                check(
                    route.road is not RoadName.CROSS,
                    f"{where}.route.road 'cross' needs road.kind = 'intersection'",
                )
                check(
                    route.turn is Turn.STRAIGHT,
                    f"{where}.route.turn is only allowed on an intersection road",
                )

    def _check_lane_direction(self, where: str, user: RoadUserSpec) -> None:
        """A driver's route lane runs its way, or the route says ``wrong_way`` and it does not.

        Pedestrians and parked road users are exempt (they do not drive a lane), and so
        are map roads (their lanes have no numbers).
        """
        route, road = user.route, self.road
        if (
            road.kind is RoadKind.MAP
            or user.type is RoadUserType.PEDESTRIAN
            or user.behaviour.kind is BehaviourKind.PARKED
        ):
            check(
                not route.wrong_way or road.kind is not RoadKind.MAP,
                f"{where}.route.wrong_way needs numbered lanes (not a map road)",
            )
            return
        own = road.lanes_of(route.direction)
        runs_its_way = route.lane < own
        way = "along" if route.direction > 0 else "against"
        lanes = f"lanes 0..{own - 1}" if own else "none"
        check(
            runs_its_way != route.wrong_way,
            f"{where}.route.lane = {route.lane} with direction = {route.direction} is a lane of the other "
            f"direction: the lanes that run {way} the reference direction are {lanes} (road.lanes = "
            f"{road.lanes}, road.lanes_forward = {road.lanes_forward}); use one of them, set "
            f"road.lanes_forward, or say route.wrong_way = true for a wrong-way driver"
            if not route.wrong_way
            else f"{where}.route.wrong_way = true, but lane {route.lane} with direction = {route.direction} "
            f"runs its way ({lanes} run {way} the reference direction); remove wrong_way or pick a lane "
            f"of the other direction",
        )

    def _check_debris(self) -> None:
        """Debris names are unique and every piece lies on the road."""
        length = self.road.length
        names = [d.name for d in self.debris]
        twice = sorted({n for n in names if names.count(n) > 1})
        check(not twice, f"debris: duplicate names {twice}")
        road = self.road
        left = road.half_width + road.shoulder
        right = road.half_width + road.parking_width + road.shoulder
        for i, piece in enumerate(self.debris):
            check(
                piece.s <= length,
                f"debris[{i}] ({piece.name}).s must lie on the road (<= road.length {length:g} m), "
                f"got {piece.s}",
            )
            # Off the drivable area it would be neither a hole for the planner nor in anyone's way.
            reach = 0.5 * math.hypot(piece.length, piece.width)
            check(
                road.kind is RoadKind.MAP or -right < piece.offset + reach and piece.offset - reach < left,
                f"debris[{i}] ({piece.name}).offset must put it on the road ({-right:g} to {left:g} m "
                f"from the reference line), got {piece.offset:g}",
            )
        self._check_debris_clear_of_ego()

    def _check_debris_clear_of_ego(self) -> None:
        """No debris lies under the ego at the start (the world would refuse the overlap later).

        Both footprints in the road's (s, offset) frame: the ego at ``s0`` in the centre
        of its lane, along the road; the debris at its ``s``, ``offset`` and ``yaw``.
        """
        ego, road = self.ego, self.road
        if not self.debris or ego.pose is not None or road.kind is RoadKind.MAP:
            return
        d_ego = -road.half_width + (ego.lane + 0.5) * road.lane_width
        pieces = self.debris
        xs, ys = rectangle_corners(
            np.array([ego.s0, *(p.s for p in pieces)]),
            np.array([d_ego, *(p.offset for p in pieces)]),
            np.radians([0.0, *(p.yaw for p in pieces)]),
            np.array([ego.length, *(p.length for p in pieces)]),
            np.array([ego.width, *(p.width for p in pieces)]),
        )
        boxes = shapely.polygons(np.stack([xs, ys], axis=-1))
        overlap = shapely.area(shapely.intersection(boxes[0], boxes[1:])) > 0.0
        for i in np.flatnonzero(overlap):
            piece = pieces[i]
            raise ValueError(
                f"debris[{i}] ({piece.name}) lies under the ego at the start: the ego covers s "
                f"{ego.s0 - 0.5 * ego.length:g} to {ego.s0 + 0.5 * ego.length:g} m and offset "
                f"{d_ego - 0.5 * ego.width:g} to {d_ego + 0.5 * ego.width:g} m (lane {ego.lane}); "
                f"move debris[{i}].s or .offset (or ego.s0) so that they do not overlap"
            )

    def _check_events(self) -> None:
        """Every road user a script's condition names exists (``to`` never the road user itself).

        A script's lane changes, run in order from the road user's start lane, keep it on
        the road's lanes (not checked on map roads and waypoint routes, which have no
        lane numbers to change between).
        """
        known = {"ego", *(u.name for u in self.road_users)}
        lanes = self.road.lanes
        for i, user in enumerate(self.road_users):
            lane = user.route.lane
            numbered = (
                self.road.kind is not RoadKind.MAP
                and user.route.road is not RoadName.WAYPOINTS
                and user.route.lane < lanes
            )
            for k, event in enumerate(user.behaviour.events):
                lane += event.do.change_lane
                check(
                    not numbered or 0 <= lane < lanes,
                    f"road_users[{i}] ({user.name}).behaviour.events[{k}].do.change_lane = "
                    f"{event.do.change_lane} takes it to lane {lane}, off the road: its lanes are 0 to "
                    f"{lanes - 1} (from the right in its direction), it starts in lane {user.route.lane}",
                )
            for k, event in enumerate(user.behaviour.events):
                for key in ("to", "of"):
                    other = getattr(event.when, key)
                    check(
                        other in known or (key == "of" and other == "self"),
                        f"road_users[{i}] ({user.name}).behaviour.events[{k}].when.{key}: unknown road user "
                        f"{other!r}; allowed: {', '.join(sorted(known))}",
                    )
                    check(
                        key == "of" or other != user.name,
                        f"road_users[{i}] ({user.name}).behaviour.events[{k}].when.{key}: a road user "
                        f"measures to others (use of = 'self' for its own state)",
                    )

    def _check_lane_changes(self) -> None:
        """MOBIL road users drive on numbered lanes of a straight, curved or merge road.

        A map road's or waypoint route's lanes have no numbers to change between, and
        an intersection's turns leave the lanes they start in.
        """
        road = self.road
        if road.kind is RoadKind.MERGE and self.ego.lane == 0 and self.ego.pose is None:
            merge_at = road.lane_drop - road.taper
            check(
                self.ego.s0 <= merge_at - 20.0,
                f"ego.s0 ({self.ego.s0:g} m) on the acceleration lane (ego.lane = 0) must lie at least 20 m "
                f"before its taper starts (road.lane_drop - road.taper = {merge_at:g} m) to merge",
            )
        for i, user in enumerate(self.road_users):
            if user.behaviour.mobil is None:
                continue
            where = f"road_users[{i}] ({user.name}).behaviour.mobil"
            check(
                self.road.kind in (RoadKind.STRAIGHT, RoadKind.CURVED, RoadKind.MERGE),
                f"{where}: lane changes need a straight, curved or merge road, not road.kind = "
                f"{self.road.kind.value!r}",
            )
            check(
                user.route.road is RoadName.MAIN,
                f"{where}: lane changes need a route on the main road's lanes, not route.road = "
                f"{user.route.road.value!r}",
            )
            check(
                not user.route.wrong_way,
                f"{where}: a wrong-way driver (route.wrong_way) does not change lanes by MOBIL",
            )


#: Road fields only one road kind reads: written for another kind they would be ignored.
ROAD_FIELDS_OF_ONE_KIND: dict[str, RoadKind] = {
    "radius": RoadKind.CURVED,
    "curve_angle": RoadKind.CURVED,
    "lead_in": RoadKind.CURVED,
    "corner_radius": RoadKind.INTERSECTION,
}


def _check_road_fields_of_kind(data: dict[str, Any]) -> None:
    """Refuse a ``[road]`` field written for a road kind that ignores it (e.g. a radius on a straight road).

    Only fields the file sets are checked (the dataclass defaults apply to every kind);
    an unknown kind is left to the field parser, which names what is allowed.
    """
    road = data.get("road")
    if not isinstance(road, dict):
        return
    kind = road.get("kind", RoadKind.STRAIGHT.value)
    if kind not in {k.value for k in RoadKind}:
        return
    for name, only in ROAD_FIELDS_OF_ONE_KIND.items():
        check(
            name not in road or kind == only.value,
            f"road.{name} is only used by road.kind = {only.value!r}, not {kind!r}: remove it or "
            f"set road.kind = {only.value!r}",
        )


def scenario_from_dict(data: dict[str, Any]) -> Scenario:
    """Build a scenario from nested dicts (as read from TOML).

    Raises:
        ValueError: unknown keys or invalid values, naming the field (e.g.
            ``road_users[2].behaviour.speed``), and road fields written for another road
            kind (``ROAD_FIELDS_OF_ONE_KIND``).
    """
    if isinstance(data, dict):
        _check_road_fields_of_kind(data)
    return from_mapping(Scenario, data, "")


def load_scenario(path: str | Path) -> Scenario:
    """Load a scenario from a TOML file.

    Raises:
        ValueError: unreadable TOML, unknown keys or invalid values; the message names
            the file and the field.
    """
    data = read_toml(path, "scenario")
    with errors_in(path):
        return scenario_from_dict(data)
