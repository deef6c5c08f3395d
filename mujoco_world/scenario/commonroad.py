"""CommonRoad scenario files (``*.xml``, formats 2018b and 2020a) as MuJoCo-world scenarios.

``import_commonroad(path)`` reads a file with ``commonroad-io`` (2024.3; imported here,
lazily) and builds a ``Scenario``:

* **Road** (``road.kind = "map"``): the drivable area is the union of the lanelets near
  the ego's way (``ImportOptions.corridor``), lane centre lines are the lanelets'
  centre vertices, the road's boundary bodies (kerbs by default) line the outline of
  the lanelets except where a road begins or ends, and the ego's reference path comes
  from ``commonroad-route-planner`` (initial lanelet to the goal, with lane changes
  where the route needs them), continued along successors. The planner's lanes are
  the lanelets beside the initial one (offsets measured at the ego's start).
  Speed limit: the ``MAX_SPEED`` sign of the lanelet the ego starts on, else the first
  on its route; without one, the 85th percentile of the recorded motor vehicles'
  median speeds (the operating speed of traffic engineering), at least the ego's start
  speed.
* **Road users:** every dynamic obstacle becomes a body of its type and shape (a
  circle of radius r a round proxy of diameter 2r) following its recorded trajectory
  through the tracking controller (``behaviour.kind = "recorded"``); it enters the
  world at its first recorded state and leaves after its last. Its times use the time
  step checked against the recorded velocities (``commonroad_tracks.check_step``;
  highD and SinD files declare a step 2x and 5x too short). Pairs whose recorded
  footprints overlap get no contact (``contact.exclude``) and the notes say so.
  Recordings that ask more acceleration than the friction limit are named by the
  world in the run summary's notes. Static obstacles: parked vehicles and obstacles of unknown type (the
  hand-crafted files' blocked lanes) become parked bodies, which the planner perceives
  as road users; every other kind (construction zones, buildings...) a fixed body, which
  only the physics sees (the notes say so).
* **Ego:** the planning problem's initial state (the lowest planning-problem id unless
  ``ImportOptions.planning_problem`` or a ``FILE.xml#ID`` reference names one); the
  default ego's shape and mass (BMW 320i). World time 0 is the planning problem's
  initial time step.
* **Goal:** the goal region's shapes (velocity, orientation and time intervals of the
  goal are not checked; the notes say so); a goal of time only is reached when the
  run has lasted until the end of its interval.
* **Time limit:** the end of the goal's time interval, but not beyond the end of the
  recorded traffic (files whose goal intervals reach far beyond their recording,
  like highD and SinD, end with the traffic); a file without recorded traffic stops
  at the goal time, at most ``ImportOptions.max_duration``.

A file that cannot become a scenario raises ``CommonRoadImportError`` (a
``ValueError``) with a short ``reason`` key (``REJECTION_REASONS``) and a message
naming the file: unreadable, no planning problem, set-based occupancies, an obstacle
type the world does not simulate, no route to the goal, an ego that starts inside a
road user.

Everything the importer decided or found is in ``Scenario.notes``.
"""

from __future__ import annotations

import functools
import math
import os
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import shapely
import shapely.ops
from shapely.geometry import LineString, Polygon

from ethical_planner.geometry import rectangle_corners, rectangle_overlap
from ethical_planner.road_users import EGO_MASS_KG, EGO_SHAPE, MOTORISED_TYPES, RoadUserType
from ethical_planner.validation import check, parse_enum
from mujoco_world.scenario.commonroad_tracks import (
    COMMONROAD_TYPES,
    ScenarioTracks,
    Track,
    UnusableScenarioError,
    open_commonroad,
    scenario_tracks,
)
from mujoco_world.scenario.imported import MapSpec, ObstacleSpec, RecordedTrajectory
from mujoco_world.scenario.recorded_tracks import RecordedTracks
from mujoco_world.scenario.road import close_union
from mujoco_world.scenario.spec import (
    BehaviourKind,
    BehaviourSpec,
    Boundary,
    ContactSpec,
    EgoSpec,
    RoadKind,
    RoadSpec,
    RoadUserSpec,
    Scenario,
)

#: Why a file is refused: reason key -> what it means.
REJECTION_REASONS = {
    "unreadable": "commonroad-io cannot parse the file",
    "no_planning_problem": "the file has no planning problem, so there is no ego",
    "set_based": "obstacles are given as set-based occupancies, not trajectories",
    "unknown_obstacle_type": "an obstacle type the world does not simulate",
    "no_route": "the route planner finds no route from the initial lanelet to the goal",
    "invalid": "the file's content does not make a valid scenario",
    "ego_overlaps": "the planning problem's initial state overlaps a road user present at the start",
}
#: Step policies (``commonroad_tracks.STEP_POLICIES``).
STEP_POLICIES = ("velocity", "declared")
#: Reference path sample spacing [m].
PATH_STEP_M = 1.0
#: How far the reference path is continued past the route's end [m].
PATH_EXTENSION_M = 150.0
#: No road boundary this close to the ego's start footprint [m] (kerbs are 0.3 m wide).
EGO_START_CLEARANCE_M = 1.0
#: Boundary simplification tolerance [m].
BOUNDARY_TOLERANCE_M = 0.1
#: Recorded footprints that come closer than this get no contact between them [m].
CONTACT_MARGIN_M = 0.02
#: Time step of the overlap check of recorded footprints [s].
OVERLAP_CHECK_STEP_S = 0.02
#: A track's first or last step may differ this much (relative) from its recorded velocity.
END_STEP_TOLERANCE = 0.1
#: Below this mean speed [m/s] a track's end step is not checked.
MIN_END_SPEED = 2.0
#: Static obstacle types that become parked bodies (the planner perceives them).
_PARKED_TYPES = {"parkedVehicle", "unknown"}
_REFERENCE = re.compile(r"^(?P<path>.+\.xml)(?:#(?P<pp>-?\d+))?$", re.IGNORECASE)


#: Marks the reason key at the end of a rejection's message (a failed run's stored reason).
REJECTED_TAG = "rejected: "
_REJECTED_KEY = re.compile(r"\[" + re.escape(REJECTED_TAG) + r"(?P<key>[a-z_]+)\]$")


def rejection_reason(message: str) -> str | None:
    """The ``REJECTION_REASONS`` key at the end of a rejection's message, else None."""
    match = _REJECTED_KEY.search(message.strip())
    return match["key"] if match else None


class CommonRoadImportError(ValueError):
    """A CommonRoad file that cannot become a scenario.

    Attributes:
        path: the file.
        reason: a key of ``REJECTION_REASONS``.
    """

    def __init__(self, path: str | Path, reason: str, message: str) -> None:
        super().__init__(f"{path}: {message} [{REJECTED_TAG}{reason}]")
        self.path = str(path)
        self.reason = reason


@dataclass(frozen=True, slots=True)
class ImportOptions:
    """How a CommonRoad file is imported.

    Attributes:
        planning_problem: id of the planning problem that defines the ego; None takes
            the lowest id.
        step: ``"velocity"`` corrects a declared time step the recorded velocities
            contradict; ``"declared"`` keeps it.
        boundary: what lines the road (kerbs stop motor vehicles, walls everything,
            none).
        corridor: half width of the region around the ego's reachable route whose
            lanelets make the road [m].
        max_duration: time limit of a file without recorded traffic [s].
        ego_length, ego_width: the ego's footprint [m]. ego_mass: [kg].
    """

    planning_problem: int | None = None
    step: str = "velocity"
    boundary: Boundary = Boundary.KERB
    corridor: float = 40.0
    max_duration: float = 60.0
    ego_length: float = EGO_SHAPE.length
    ego_width: float = EGO_SHAPE.width
    ego_mass: float = EGO_MASS_KG

    def __post_init__(self) -> None:
        check(
            self.step in STEP_POLICIES, f"step must be one of {', '.join(STEP_POLICIES)}, got {self.step!r}"
        )
        object.__setattr__(self, "boundary", parse_enum(Boundary, self.boundary, "boundary", "boundary"))
        check(self.corridor > 0 and self.max_duration > 0, "corridor and max_duration must be > 0")


def is_commonroad_reference(reference: str) -> bool:
    """True for ``FILE.xml`` or ``FILE.xml#PLANNING_PROBLEM_ID``."""
    return _REFERENCE.match(reference) is not None


def split_reference(reference: str) -> tuple[Path, int | None]:
    """(file, planning-problem id or None) of ``FILE.xml[#ID]``.

    Raises:
        ValueError: not such a reference.
    """
    match = _REFERENCE.match(reference)
    if match is None:
        raise ValueError(f"not a CommonRoad reference FILE.xml[#PLANNING_PROBLEM_ID]: {reference!r}")
    pp = match.group("pp")
    return Path(match.group("path")), (int(pp) if pp is not None else None)


def import_commonroad(path: str | Path, options: ImportOptions | None = None) -> Scenario:
    """The scenario of a CommonRoad file (see the module docstring).

    Raises:
        CommonRoadImportError: the file cannot become a scenario (``reason`` says why).
    """
    options = options or ImportOptions()
    path = Path(path)
    try:
        cr_scenario, problems = open_commonroad(path)
    except UnusableScenarioError as error:
        raise CommonRoadImportError(path, "unreadable", str(error).removeprefix(f"{path}: ")) from None
    try:
        return _Importer(path, cr_scenario, problems, options).build()
    except CommonRoadImportError:
        raise
    except ValueError as error:
        raise CommonRoadImportError(path, "invalid", f"does not make a valid scenario: {error}") from None


@functools.lru_cache(maxsize=8)
def _cached_import(path: str, mtime: float, size: int, options: ImportOptions) -> Scenario:
    return import_commonroad(path, options)


def load_commonroad(reference: str, options: ImportOptions | None = None) -> Scenario:
    """The scenario of ``FILE.xml[#PLANNING_PROBLEM_ID]``, cached per process.

    A study runs each file with several planners; the import (parsing, route
    planning) is done once per process as long as the file is unchanged.
    """
    path, pp = split_reference(reference)
    options = options or ImportOptions()
    if pp is not None:
        options = replace(options, planning_problem=pp)
    try:
        stat = os.stat(path)
    except OSError as error:
        raise CommonRoadImportError(path, "unreadable", f"cannot read the file ({error.strerror})") from None
    return _cached_import(str(Path(path).resolve()), stat.st_mtime, stat.st_size, options)


# --------------------------------------------------------------------------- the importer


def _shape_polygon(shape: Any) -> Polygon:
    """A commonroad shape (Rectangle, Circle, Polygon, ShapeGroup) as one shapely polygon."""
    shapes = getattr(shape, "shapes", None)
    if shapes is not None:
        return shapely.union_all([_shape_polygon(s) for s in shapes])
    return shapely.make_valid(shape.shapely_object)


def _rings(area: Any) -> list[list[tuple[float, float]]]:
    polygons = getattr(area, "geoms", [area])
    out = []
    for p in polygons:
        if isinstance(p, Polygon) and not p.is_empty and p.area > 1e-6:
            out.append([(float(x), float(y)) for x, y in np.asarray(p.exterior.coords)[:-1]])
    return out


def _resample(points: np.ndarray, step: float) -> np.ndarray:
    """A polyline resampled every ``step`` metres by arc length, shape (m, 2)."""
    keep = np.concatenate([[True], np.hypot(*np.diff(points, axis=0).T) > 1e-6])
    points = points[keep]
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])
    n = max(int(math.ceil(s[-1] / step)), 1)
    grid = np.linspace(0.0, s[-1], n + 1)
    return np.column_stack([np.interp(grid, s, points[:, 0]), np.interp(grid, s, points[:, 1])])


def _at_fractions(line: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Points of a polyline at arc-length fractions ``f`` in [0, 1], shape (len(f), 2)."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(line, axis=0).T))])
    target = f * s[-1]
    return np.column_stack([np.interp(target, s, line[:, 0]), np.interp(target, s, line[:, 1])])


def _blend(centres: list[np.ndarray], f_start: float) -> np.ndarray:
    """A path from the first centre line to the last through the ones between.

    Lane change j (from ``centres[j]`` to ``centres[j + 1]``) happens over the j-th of
    equal parts of the fraction range [f_start, 1], weighted by a quintic smoothstep;
    before ``f_start`` the path follows the first centre line.
    """
    length = max(float(np.sum(np.hypot(*np.diff(c, axis=0).T))) for c in centres)
    f = np.linspace(0.0, 1.0, max(int(length / 0.5), 8) + 1)
    lines = np.stack([_at_fractions(c, f) for c in centres])  # (k + 1, m, 2)
    changes = len(centres) - 1
    u = np.clip((f - f_start) / max(1.0 - f_start, 1e-9), 0.0, 1.0) * changes
    j = np.minimum(np.floor(u).astype(int), changes - 1)
    w = np.clip(u - j, 0.0, 1.0)
    w = w**3 * (10 - 15 * w + 6 * w**2)
    rows = np.arange(len(f))
    return (1 - w)[:, None] * lines[j, rows] + w[:, None] * lines[j + 1, rows]


def _trim_ends(track: Track) -> tuple[Track, bool]:
    """``track`` without a first or last state whose step disagrees with the recorded velocity.

    highD tracks that begin or end mid-recording have a first (or last) step of 0.2 to
    0.6 times the distance their velocity covers in one step: that state lies between
    the file's frames. Following it would ask the body to jump from a crawl to highway
    speed in one step. Such an end state is dropped (only when the mean speed over the
    step exceeds ``MIN_END_SPEED``; at most one state per end).
    """
    n = len(track)
    if n < 4:
        return track, False
    step = np.hypot(*np.diff(track.positions, axis=0).T)
    dt = np.diff(track.times)
    expected = 0.5 * (np.abs(track.speeds[1:]) + np.abs(track.speeds[:-1])) * dt
    bad = (expected > MIN_END_SPEED * dt) & (
        np.abs(step / np.maximum(expected, 1e-9) - 1.0) > END_STEP_TOLERANCE
    )
    first, last = (1 if bad[0] else 0), (n - 1 if bad[-1] else n)
    if first == 0 and last == n:
        return track, False
    keep = slice(first, last)
    return (
        replace(
            track,
            time_steps=track.time_steps[keep],
            times=track.times[keep],
            positions=track.positions[keep],
            headings=track.headings[keep],
            speeds=track.speeds[keep],
        ),
        True,
    )


def _name(kind: RoadUserType, obstacle_id: int) -> str:
    return f"{kind.value}_{obstacle_id}"


class _Importer:
    """One file's import: each step a method, the notes collected on the way."""

    def __init__(self, path: Path, cr: Any, problems: Any, options: ImportOptions) -> None:
        self.path, self.cr, self.problems, self.options = path, cr, problems, options
        self.notes: list[str] = []
        self.network = cr.lanelet_network

    def fail(self, reason: str, message: str) -> CommonRoadImportError:
        return CommonRoadImportError(self.path, reason, message)

    # ------------------------------------------------------------------ steps

    def build(self) -> Scenario:
        problem = self._planning_problem()
        self._check_obstacles()
        tracks = scenario_tracks(self.cr, self.path, self.options.step, allow_empty=True)
        self.dt = tracks.dt
        self.notes.append(tracks.step_check.message)
        for oid, why in tracks.skipped:
            self.notes.append(f"obstacle {oid} left out: {why}")
        initial = problem.initial_state
        self.t0 = int(initial.time_step) * self.dt
        ego_xy = np.asarray(initial.position, dtype=float)
        ego_yaw, ego_v = float(initial.orientation), float(getattr(initial, "velocity", 0.0) or 0.0)
        route_ids, path = self._route(problem)
        goal_region, duration, goal_time = self._goal_and_duration(problem, tracks)
        reach = max(ego_v, 14.0) * 1.5 * duration + 50.0
        corridor = self._corridor(path, ego_xy, reach)
        road_map = self._map(path, ego_xy, corridor, ego_yaw)
        users, excluded = self._road_users(tracks, duration)
        users += self._parked_users()
        self._check_ego_start(users, ego_xy, ego_yaw)
        speed_limit = self._speed_limit(route_ids, ego_xy, tracks, ego_v)
        s_start = float(LineString(road_map.reference_path).project(shapely.Point(*ego_xy)))
        length = float(LineString(road_map.reference_path).length)
        ego = EgoSpec(
            length=self.options.ego_length,
            width=self.options.ego_width,
            mass=self.options.ego_mass,
            s0=min(max(s_start, 0.0), length - 1.0),
            speed=max(ego_v, 0.0),
            goal_s=length - 1.0 if not goal_region and goal_time is None else None,
            pose=(float(ego_xy[0]), float(ego_xy[1]), ego_yaw),
            goal_region=tuple(tuple(r) for r in goal_region),
            goal_time=goal_time,
        )
        road = RoadSpec(
            kind=RoadKind.MAP,
            length=max(length, 10.0),
            speed_limit=speed_limit,
            boundary=self.options.boundary,
            map=road_map,
        )
        name = str(self.cr.scenario_id)
        if self.options.planning_problem is not None:
            name += f"-pp{self.options.planning_problem}"
        if initial.time_step and int(initial.time_step) > 0:
            self.notes.append(f"world time 0 is the planning problem's initial time step {initial.time_step}")
        return Scenario(
            name=re.sub(r"[^A-Za-z0-9_.-]", "_", name),
            description=f"CommonRoad {name} ({self.path.name}), planning problem {self.problem_id}",
            road=road,
            ego=ego,
            road_users=tuple(users),
            duration=duration,
            contact=ContactSpec(exclude=tuple(excluded)),
            obstacles=tuple(self._fixed_obstacles()),
            notes=tuple(self.notes),
        )

    def _planning_problem(self) -> Any:
        problems = dict(self.problems.planning_problem_dict) if self.problems is not None else {}
        if not problems:
            raise self.fail("no_planning_problem", "no planning problem, so no ego to simulate")
        wanted = self.options.planning_problem
        if wanted is None:
            self.problem_id = min(problems)
            if len(problems) > 1:
                self.notes.append(
                    f"planning problem {self.problem_id} of {sorted(problems)} defines the ego "
                    f"(FILE.xml#ID chooses another)"
                )
        elif wanted not in problems:
            raise self.fail(
                "no_planning_problem", f"no planning problem {wanted}; the file has {sorted(problems)}"
            )
        else:
            self.problem_id = wanted
        return problems[self.problem_id]

    def _check_obstacles(self) -> None:
        from commonroad.prediction.prediction import SetBasedPrediction

        for obstacle in self.cr.dynamic_obstacles:
            kind = obstacle.obstacle_type.value
            if isinstance(obstacle.prediction, SetBasedPrediction):
                raise self.fail(
                    "set_based",
                    f"obstacle {obstacle.obstacle_id} is given as set-based occupancies, not a "
                    "trajectory: there is no motion to replay",
                )
            if kind not in COMMONROAD_TYPES or COMMONROAD_TYPES[kind] is RoadUserType.TRAIN:
                allowed = ", ".join(k for k, v in COMMONROAD_TYPES.items() if v is not RoadUserType.TRAIN)
                raise self.fail(
                    "unknown_obstacle_type",
                    f"dynamic obstacle {obstacle.obstacle_id} has type {kind!r}, which the world does "
                    f"not simulate (allowed: {allowed})",
                )

    def _route(self, problem: Any) -> tuple[list[int], np.ndarray]:
        """(route lanelet ids, reference path (m, 2)) continued along successors.

        ``commonroad-route-planner`` finds the lanelet sequences from the initial lanelet
        to the goal; of them the one that starts along the ego's heading, then with the
        fewest lane changes, then the shortest, is taken. Its path follows the
        lanelets' centre lines; a lane change blends one centre line into the next
        (quintic smoothstep) over the part of the lanelet ahead of the ego.
        (commonroad-route-planner's own reference-path builder took up to 50 s per file
        resampling long highway lanelets in Python.)
        """
        import logging

        from commonroad_route_planner.route_planner import RoutePlanner

        logging.getLogger("commonroad_route_planner").setLevel(logging.ERROR)
        try:
            routes = RoutePlanner(self.network, problem, logging_level=logging.ERROR).plan_routes()
        except Exception as error:  # noqa: BLE001 - the route planner raises several kinds
            detail = re.sub(r"<[^>]*>", "the route planner", str(error))
            raise self.fail(
                "no_route",
                f"commonroad-route-planner finds no route from the initial lanelet to the goal ({detail})",
            ) from None
        initial = problem.initial_state
        ego_xy = np.asarray(initial.position, dtype=float)
        ranked = sorted(
            (self._route_cost([int(i) for i in r.lanelet_ids], ego_xy, float(initial.orientation)), k)
            for k, r in enumerate(routes)
            if len(r.lanelet_ids)
        )
        if not ranked:
            raise self.fail("no_route", "commonroad-route-planner returns only empty routes")
        ids = [int(i) for i in routes[ranked[0][1]].lanelet_ids]
        path, changes = self._route_path(ids, ego_xy)
        what = f"{changes} lane change(s)" if changes else "no lane change"
        self.notes.append(f"route: {len(ids)} lanelet(s) from commonroad-route-planner, {what}")
        path = self._extend(path, ids[-1])
        return ids, _resample(path, PATH_STEP_M)

    def _lane_change(self, a: int, b: int) -> bool:
        lanelet = self.network.find_lanelet_by_id(a)
        return (lanelet.adj_left == b and lanelet.adj_left_same_direction) or (
            lanelet.adj_right == b and lanelet.adj_right_same_direction
        )

    def _route_cost(self, ids: list[int], ego_xy: np.ndarray, yaw: float) -> tuple[int, int, float]:
        first = self.network.find_lanelet_by_id(ids[0])
        centre = np.asarray(first.center_vertices, dtype=float)
        k = int(np.argmin(np.hypot(*(centre - ego_xy).T)))
        k = min(k, len(centre) - 2)
        heading = math.atan2(*(centre[k + 1] - centre[k])[::-1])
        against = int(abs(math.remainder(heading - yaw, 2 * math.pi)) > math.pi / 4)
        changes = sum(self._lane_change(a, b) for a, b in zip(ids, ids[1:], strict=False))
        length = sum(float(self.network.find_lanelet_by_id(i).distance[-1]) for i in ids)
        return against, changes, length

    def _route_path(self, ids: list[int], ego_xy: np.ndarray) -> tuple[np.ndarray, int]:
        """The centre-line path of a lanelet sequence with blended lane changes, and their number."""
        groups = [[ids[0]]]
        for a, b in zip(ids, ids[1:], strict=False):
            if self._lane_change(a, b):
                groups[-1].append(b)
            else:
                groups.append([b])
        pieces = []
        for g, group in enumerate(groups):
            centres = [
                np.asarray(self.network.find_lanelet_by_id(i).center_vertices, dtype=float) for i in group
            ]
            if len(group) == 1:
                pieces.append(centres[0])
                continue
            first = LineString(centres[0])
            f0 = first.project(shapely.Point(*ego_xy), normalized=True) if g == 0 else 0.0
            pieces.append(_blend(centres, min(f0, 0.9)))
        return np.concatenate(pieces), sum(len(group) - 1 for group in groups)

    def _extend(self, path: np.ndarray, last: int | None) -> np.ndarray:
        """``path`` continued along first successors, then straight, by ``PATH_EXTENSION_M``."""
        pieces = [path]
        added = 0.0
        seen = set()
        lanelet = self.network.find_lanelet_by_id(last) if last is not None else None
        while lanelet is not None and added < PATH_EXTENSION_M and lanelet.successor:
            nxt = self.network.find_lanelet_by_id(lanelet.successor[0])
            if nxt is None or nxt.lanelet_id in seen:
                break
            seen.add(nxt.lanelet_id)
            centre = np.asarray(nxt.center_vertices, dtype=float)
            pieces.append(centre)
            added += float(np.sum(np.hypot(*np.diff(centre, axis=0).T)))
            lanelet = nxt
        joined = np.concatenate(pieces)
        if added < PATH_EXTENSION_M:
            end, before = joined[-1], joined[max(len(joined) - 5, 0)]
            heading = end - before
            norm = float(np.hypot(*heading))
            if norm > 1e-6:
                extra = PATH_EXTENSION_M - added
                joined = np.concatenate([joined, end + np.outer([extra], heading / norm)])
        # Drop points that fold back (successor joints can repeat a vertex).
        keep = [0]
        for k in range(1, len(joined)):
            if np.hypot(*(joined[k] - joined[keep[-1]])) > 0.05:
                keep.append(k)
        return joined[keep]

    def _goal_and_duration(
        self, problem: Any, tracks: ScenarioTracks
    ) -> tuple[list[list[tuple[float, float]]], float, float | None]:
        goal = problem.goal
        shapes, ends, checked = [], [], set()
        for state in goal.state_list:
            position = getattr(state, "position", None)
            if position is not None:
                shapes.append(_shape_polygon(position))
            time = getattr(state, "time_step", None)
            if time is not None:
                ends.append(float(getattr(time, "end", time)) * self.dt - self.t0)
                opens = float(getattr(time, "start", time)) * self.dt - self.t0
                if opens > 0.0 and position is not None:
                    self.notes.append(
                        f"goal: its time interval opens at {opens:.1f} s; entering the goal region "
                        "earlier already counts (the interval's start is not checked)"
                    )
            for name in ("velocity", "orientation"):
                if getattr(state, name, None) is not None:
                    checked.add(name)
        if checked:
            self.notes.append(f"goal: its {' and '.join(sorted(checked))} interval(s) are not checked")
        traffic_end = max((float(t.times[-1]) for t in tracks.tracks), default=0.0) - self.t0
        goal_end = max(ends) if ends else math.inf
        if traffic_end > 0:
            duration = min(goal_end, traffic_end)
            if goal_end > traffic_end + 1e-9:
                self.notes.append(
                    f"time limit {duration:.1f} s: the end of the recorded traffic (the goal allows "
                    f"{goal_end:.1f} s)"
                )
            else:
                self.notes.append(f"time limit {duration:.1f} s: the end of the goal's time interval")
        else:
            duration = min(goal_end, self.options.max_duration)
            self.notes.append(f"time limit {duration:.1f} s: no recorded traffic")
        duration = max(duration, self.dt)
        region = _rings(shapely.union_all(shapes)) if shapes else []
        goal_time = None
        if not region:
            goal_time = duration
            self.notes.append(f"goal of time only: reached after {goal_time:.1f} s without a collision")
        return region, duration, goal_time

    def _corridor(self, path: np.ndarray, ego_xy: np.ndarray, reach: float) -> Any:
        line = LineString(path)
        s0 = line.project(shapely.Point(*ego_xy))
        start, end = max(s0 - 30.0, 0.0), min(s0 + reach, line.length)
        piece = shapely.ops.substring(line, start, end) if end > start else line
        return piece.buffer(self.options.corridor)

    def _map(self, path: np.ndarray, ego_xy: np.ndarray, corridor: Any, ego_yaw: float) -> MapSpec:
        lanelets = [ll for ll in self.network.lanelets if ll.polygon.shapely_object.intersects(corridor)]
        check(bool(lanelets), "no lanelet near the ego's route")
        area = [np.asarray(ll.polygon.vertices, dtype=float) for ll in lanelets]
        union = close_union([shapely.make_valid(Polygon(a)) for a in area])
        ends = []
        for ll in lanelets:
            left, right = np.asarray(ll.left_vertices), np.asarray(ll.right_vertices)
            if not ll.predecessor:
                ends.append(LineString([left[0], right[0]]))
            if not ll.successor:
                ends.append(LineString([left[-1], right[-1]]))
        outline = union.boundary
        if ends:
            outline = outline.difference(shapely.union_all(ends).buffer(0.05))
        outline = outline.intersection(corridor)
        # An ego that starts across the lanelets' outline (a planning problem on a lanelet's
        # edge) would start inside a kerb: the boundary around its start is left out.
        xs, ys = rectangle_corners(
            ego_xy[0], ego_xy[1], ego_yaw, self.options.ego_length, self.options.ego_width
        )
        start_box = Polygon(np.column_stack([xs, ys])).buffer(EGO_START_CLEARANCE_M)
        if outline.intersects(start_box):
            outline = outline.difference(start_box)
            self.notes.append(
                f"the ego starts across the lanelets' outline: no road boundary within "
                f"{EGO_START_CLEARANCE_M:g} m of its start"
            )
        outline = shapely.line_merge(outline) if not outline.is_empty else outline
        parts = getattr(outline, "geoms", [outline]) if not outline.is_empty else []
        boundaries = []
        for part in parts:
            if isinstance(part, LineString) and part.length > 0.5:
                simple = part.simplify(BOUNDARY_TOLERANCE_M)
                boundaries.append(tuple((float(x), float(y)) for x, y in simple.coords))
        lanes = tuple(
            tuple(
                (float(x), float(y)) for x, y in _resample(np.asarray(ll.center_vertices, dtype=float), 2.0)
            )
            for ll in lanelets
        )
        offsets, width = self._lanes(path, ego_xy)
        return MapSpec(
            area=tuple(tuple((float(x), float(y)) for x, y in a) for a in area),
            reference_path=tuple((float(x), float(y)) for x, y in path),
            lanes=lanes,
            boundaries=tuple(boundaries),
            lane_offsets=offsets,
            lane_width=width,
        )

    def _lanes(self, path: np.ndarray, ego_xy: np.ndarray) -> tuple[tuple[float, ...], float]:
        """Offsets of the lanes beside the ego's start from its reference path, and the lane width."""
        found = self.network.find_lanelet_by_position([ego_xy])[0]
        if not found:
            self.notes.append("the ego starts outside every lanelet: one lane of 3.5 m")
            return (0.0,), 3.5
        start = self.network.find_lanelet_by_id(found[0])
        line = LineString(path)
        s = line.project(shapely.Point(*ego_xy))
        here = np.asarray(line.interpolate(s).coords[0])
        ahead = np.asarray(line.interpolate(min(s + 1.0, line.length)).coords[0])
        tangent = (ahead - here) / max(float(np.hypot(*(ahead - here))), 1e-9)
        normal = np.array([-tangent[1], tangent[0]])
        offsets = set()
        widths = []
        for lanelet in self._neighbours(start):
            centre = LineString(np.asarray(lanelet.center_vertices, dtype=float))
            foot = np.asarray(centre.interpolate(centre.project(shapely.Point(*here))).coords[0])
            offsets.add(round(float((foot - here) @ normal), 2))
            left = LineString(np.asarray(lanelet.left_vertices, dtype=float))
            right = LineString(np.asarray(lanelet.right_vertices, dtype=float))
            widths.append(left.distance(right.interpolate(right.project(shapely.Point(*foot)))))
        # The ego's own lane is the reference path: offset 0 (the route may differ from
        # the lanelet's centre by a few centimetres).
        nearest = min(offsets, key=abs)
        offsets = sorted({0.0} | {d for d in offsets if d != nearest})
        width = float(np.median(widths)) if widths else 3.5
        return tuple(offsets), float(min(max(width, 2.0), 6.0))

    def _neighbours(self, lanelet: Any) -> list[Any]:
        """The lanelet and every lanelet beside it (left and right chains, either direction)."""
        out, seen = [lanelet], {lanelet.lanelet_id}
        for side in ("adj_left", "adj_right"):
            current = lanelet
            while True:
                nxt_id = getattr(current, side)
                if nxt_id is None or nxt_id in seen:
                    break
                nxt = self.network.find_lanelet_by_id(nxt_id)
                if nxt is None:
                    break
                seen.add(nxt_id)
                out.append(nxt)
                # Past an opposite-direction neighbour, "left" and "right" swap.
                same = getattr(current, f"{side}_same_direction")
                if not same:
                    side = "adj_right" if side == "adj_left" else "adj_left"
                current = nxt
        return out

    def _speed_limit(
        self, route_ids: list[int], ego_xy: np.ndarray, tracks: ScenarioTracks, ego_v: float
    ) -> float:
        from commonroad.scenario.traffic_sign import SupportedTrafficSignCountry
        from commonroad.scenario.traffic_sign_interpreter import TrafficSignInterpreter

        try:
            country = SupportedTrafficSignCountry(self.cr.scenario_id.country_id)
        except ValueError:
            country = SupportedTrafficSignCountry.ZAMUNDA
        interpreter = TrafficSignInterpreter(country, self.network)
        start = self.network.find_lanelet_by_position([ego_xy])[0]
        for ids, where in (
            (start, "the lanelet the ego starts on"),
            *(([i], "its route") for i in route_ids),
        ):
            limit = interpreter.speed_limit(frozenset(ids)) if ids else None
            if limit is not None and limit > 0:
                self.notes.append(f"speed limit {limit:.1f} m/s from a MAX_SPEED sign on {where}")
                return float(limit)
        speeds = [float(np.median(t.speeds)) for t in tracks.tracks if t.type in MOTORISED_TYPES]
        if speeds:
            value = float(np.percentile(speeds, 85))
            limit = max(value, ego_v, 1.0)
            self.notes.append(
                f"speed limit {limit:.1f} m/s: no MAX_SPEED sign; 85th percentile of the recorded motor "
                f"vehicles' median speeds ({value:.1f} m/s), at least the ego's start speed"
            )
            return limit
        limit = max(ego_v, 13.9)
        self.notes.append(f"speed limit {limit:.1f} m/s: no sign and no recorded motor vehicle")
        return limit

    def _road_users(self, tracks: ScenarioTracks, duration: float) -> tuple[list[RoadUserSpec], list]:
        """Recorded road users within the run's time, and the pairs whose footprints overlap."""
        users, kept = [], []
        t_end = duration + 1e-9
        trimmed = []
        for track in tracks.tracks:
            track, cut = _trim_ends(track)
            if cut:
                trimmed.append(track.obstacle_id)
            times = track.times - self.t0
            inside = (times >= -1e-9) & (times <= t_end)
            if inside.sum() < 2:
                if (times <= t_end).any() and (times >= -1e-9).any():
                    self.notes.append(f"obstacle {track.obstacle_id} left out: one recorded state in the run")
                continue
            idx = np.flatnonzero(inside)
            trajectory = RecordedTrajectory(
                start=max(float(times[idx[0]]), 0.0),
                dt=self.dt,
                x=tuple(track.positions[idx, 0]),
                y=tuple(track.positions[idx, 1]),
                yaw=tuple(track.headings[idx]),
                source_id=str(track.obstacle_id),
            )
            users.append(
                RoadUserSpec(
                    name=_name(track.type, track.obstacle_id),
                    type=track.type,
                    length=track.length,
                    width=track.width,
                    behaviour=BehaviourSpec(kind=BehaviourKind.RECORDED, trajectory=trajectory),
                )
            )
            kept.append(track)
        if trimmed:
            self.notes.append(
                f"{len(trimmed)} recording(s) lost a first or last state whose step disagrees with the "
                f"recorded velocity by more than {END_STEP_TOLERANCE:.0%} (a track end between frames): "
                + ", ".join(str(i) for i in trimmed[:10])
                + (" ..." if len(trimmed) > 10 else "")
            )
        return users, self._overlapping_pairs(users, kept)

    def _overlapping_pairs(self, users: list[RoadUserSpec], tracks: list[Track]) -> list[tuple[str, str]]:
        """Pairs of recorded road users whose footprints overlap (or touch) while both exist.

        Checked on the splines the bodies follow (``RecordedTracks``), every
        ``OVERLAP_CHECK_STEP_S``: a car and a cyclist recorded every 0.5 s can overlap
        between two recorded states.
        """
        if len(users) < 2:
            return []
        tracks_ = RecordedTracks([u.behaviour.trajectory for u in users])
        times = np.arange(float(tracks_.start.min()), float(tracks_.end.max()) + 1e-9, OVERLAP_CHECK_STEP_S)
        k, m = len(users), len(times)
        pose = np.full((k, m, 3), np.nan)
        for c, t in enumerate(times):
            present = tracks_.present(t)
            p, _, _, yaw, _ = tracks_.sample(t)
            pose[present, c, 0:2], pose[present, c, 2] = p[present], yaw[present]
        length = np.array([u.shape[0] for u in users])
        width = np.array([u.shape[1] for u in users])
        radius = 0.5 * np.hypot(length, width)
        pairs, lines = [], []
        for i in range(k - 1):
            j = np.arange(i + 1, k)
            dx = pose[j, :, 0] - pose[i, None, :, 0]
            dy = pose[j, :, 1] - pose[i, None, :, 1]
            near = np.hypot(dx, dy) < (radius[i] + radius[j] + CONTACT_MARGIN_M)[:, None]  # nan: False
            if not near.any():
                continue
            jj, tt = np.nonzero(near)
            depth = rectangle_overlap(
                pose[i, tt, 0], pose[i, tt, 1], pose[i, tt, 2], length[i], width[i],
                pose[j[jj], tt, 0], pose[j[jj], tt, 1], pose[j[jj], tt, 2], length[j[jj]], width[j[jj]],
            )  # fmt: skip
            touching = depth > -CONTACT_MARGIN_M
            for other in np.unique(j[jj][touching]):
                mine = j[jj] == other
                worst = float(depth[mine].max())
                span = float(np.sum(mine & touching)) * OVERLAP_CHECK_STEP_S
                a, b = users[i].name, users[int(other)].name
                pairs.append((a, b))
                what = (
                    f"overlap by up to {worst:.2f} m" if worst > 0 else f"come within {-worst * 100:.0f} cm"
                )
                lines.append(
                    f"the file's shapes of {a} and {b} {what} ({span:.1f} s): no contact between them"
                )
        self.notes += lines[:10]
        if len(lines) > 10:
            self.notes.append(f"... and {len(lines) - 10} more pairs without contact between them")
        return pairs

    def _check_ego_start(self, users: list[RoadUserSpec], ego_xy: np.ndarray, ego_yaw: float) -> None:
        """Refuse a file whose ego starts inside a road user that is there at the start.

        (SinD planning problems place the ego in queues of recorded vehicles, overlapping
        them by up to a metre; no collision-free start exists.)
        """
        poses = []
        for u in users:
            if u.behaviour.kind is BehaviourKind.RECORDED:
                t = u.behaviour.trajectory
                if t.start <= 0.0:
                    poses.append((u.name, t.x[0], t.y[0], t.yaw[0], u.length, u.width))
            elif u.route.waypoints:
                (x0, y0), (x1, y1) = u.route.waypoints[:2]
                poses.append((u.name, x0, y0, math.atan2(y1 - y0, x1 - x0), u.length, u.width))
        if not poses:
            return
        names = [p[0] for p in poses]
        x, y, yaw, length, width = np.array([p[1:] for p in poses], dtype=float).T
        depth = rectangle_overlap(
            ego_xy[0],
            ego_xy[1],
            ego_yaw,
            self.options.ego_length,
            self.options.ego_width,
            x,
            y,
            yaw,
            length,
            width,
        )
        worst = int(np.argmax(depth))
        if depth[worst] > CONTACT_MARGIN_M:
            raise self.fail(
                "ego_overlaps",
                f"the planning problem's initial state overlaps {names[worst]} by {depth[worst]:.2f} m "
                "at the start: no collision-free start",
            )

    def _parked_users(self) -> list[RoadUserSpec]:
        out = []
        for obstacle in self.cr.static_obstacles:
            if obstacle.obstacle_type.value not in _PARKED_TYPES:
                continue
            x, y, yaw, length, width = self._static_pose(obstacle)
            if obstacle.obstacle_type.value != "parkedVehicle":
                self.notes.append(
                    f"static obstacle {obstacle.obstacle_id} ({obstacle.obstacle_type.value}) is a parked "
                    "vehicle, so that the planner perceives it"
                )
            out.append(
                RoadUserSpec(
                    name=_name(RoadUserType.PARKED_VEHICLE, obstacle.obstacle_id),
                    type=RoadUserType.PARKED_VEHICLE,
                    length=length,
                    width=width,
                    route=_waypoints_at(x, y, yaw),
                    behaviour=BehaviourSpec(kind=BehaviourKind.PARKED),
                )
            )
        return out

    def _fixed_obstacles(self) -> list[ObstacleSpec]:
        out = []
        for obstacle in self.cr.static_obstacles:
            kind = obstacle.obstacle_type.value
            if kind in _PARKED_TYPES:
                continue
            x, y, yaw, length, width = self._static_pose(obstacle)
            out.append(ObstacleSpec(f"{kind}_{obstacle.obstacle_id}", x, y, yaw, length, width))
            self.notes.append(
                f"static obstacle {obstacle.obstacle_id} ({kind}) is a fixed body: the physics has it, "
                "the planner does not perceive it"
            )
        return out

    @staticmethod
    def _static_pose(obstacle: Any) -> tuple[float, float, float, float, float]:
        shape = obstacle.obstacle_shape
        state = obstacle.initial_state
        if hasattr(shape, "length") and hasattr(shape, "width"):
            x, y = (np.asarray(state.position, dtype=float) + np.asarray(shape.center)).tolist()
            yaw = float(state.orientation) + float(getattr(shape, "orientation", 0.0))
            return x, y, yaw, float(shape.length), float(shape.width)
        polygon = _shape_polygon(shape.rotate_translate_local(np.asarray(state.position), state.orientation))
        box = polygon.minimum_rotated_rectangle
        corners = np.asarray(box.exterior.coords)[:4]
        edges = np.diff(np.vstack([corners, corners[:1]]), axis=0)
        lengths = np.hypot(*edges.T)
        k = int(np.argmax(lengths))
        centre = corners.mean(axis=0)
        return (
            float(centre[0]),
            float(centre[1]),
            float(math.atan2(edges[k, 1], edges[k, 0])),
            float(max(lengths[k], 0.2)),
            float(max(lengths[(k + 1) % 4], 0.2)),
        )


def _waypoints_at(x: float, y: float, yaw: float):
    """A two-point route starting at (x, y) along ``yaw`` (a parked body's pose)."""
    from mujoco_world.scenario.spec import RoadName, RouteSpec

    c, s = math.cos(yaw), math.sin(yaw)
    return RouteSpec(road=RoadName.WAYPOINTS, waypoints=((x, y), (x + 5.0 * c, y + 5.0 * s)))


__all__ = [
    "REJECTED_TAG",
    "REJECTION_REASONS",
    "CommonRoadImportError",
    "ImportOptions",
    "import_commonroad",
    "rejection_reason",
    "is_commonroad_reference",
    "load_commonroad",
    "split_reference",
]
