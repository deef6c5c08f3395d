"""The physical world of one scenario: road, bodies, controllers, behaviours, impacts.

``World`` owns the MuJoCo scene and advances it one physics step at a time
(``step``). It knows nothing of the planner: the closed loop (``runner``) hands it the
ego's planned trajectory (``set_ego_plan``) and asks it for observations
(``observe``). Entity 0 is the ego, entity i >= 1 is ``scenario.road_users[i - 1]``.
"""

from __future__ import annotations

import copy
import math
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
import shapely

from ethical_planner.environment import NoOvertakingZone, RoadEnvironment
from ethical_planner.geometry import rectangle_overlap
from ethical_planner.reference_path import ReferencePath
from ethical_planner.road_users import VULNERABLE_TYPES, KinematicState, MotionHistory, RoadUser, Shape
from ethical_planner.validation import check_non_negative, parse_enum
from mujoco_world.agents.behaviour import Fleet, WorldView
from mujoco_world.agents.mobil import lane_layout
from mujoco_world.physics.control import (
    GRAVITY,
    ControlConfig,
    TrajectoryReference,
    brake_forces,
    tracking_forces,
)
from mujoco_world.physics.impact import ImpactMeasurement, ImpactRecorder
from mujoco_world.physics.scene import BodyProxy, Scene
from mujoco_world.physics.sight import Boxes, blocked, in_field_of_view, target_points
from mujoco_world.scenario.recorded_tracks import RECORDED_ACCEL_CAP, RecordedTracks
from mujoco_world.scenario.road import StaticBox, box_footprint, build_road, debris_boxes
from mujoco_world.scenario.spec import (
    BehaviourKind,
    Boundary,
    NoOvertakingSpec,
    PostCrashPolicy,
    RoadKind,
    RoadName,
    RouteSpec,
    Scenario,
)

#: Where bodies that are not in the world (yet, or any more) wait [m]: far from every
#: road and from each other, without contacts.
PARK_ORIGIN_M = 1.0e5
PARK_SPACING_M = 100.0


@dataclass(frozen=True, slots=True)
class ObservationNoise:
    """Gaussian noise on what the planner observes (standard deviations).

    Attributes:
        position: [m]. velocity: along the heading [m/s]. yaw: [rad].
        acceleration: along the heading [m/s^2]. yaw_rate: [rad/s].
        ego_position: noise on the ego's own localisation [m].
    """

    position: float = 0.0
    velocity: float = 0.0
    yaw: float = 0.0
    acceleration: float = 0.0
    yaw_rate: float = 0.0
    ego_position: float = 0.0

    def __post_init__(self) -> None:
        check_non_negative(
            "noise",
            position=self.position,
            velocity=self.velocity,
            yaw=self.yaw,
            acceleration=self.acceleration,
            yaw_rate=self.yaw_rate,
            ego_position=self.ego_position,
        )

    @property
    def enabled(self) -> bool:
        """True if any standard deviation is positive."""
        return (
            max(self.position, self.velocity, self.yaw, self.acceleration, self.yaw_rate, self.ego_position)
            > 0
        )


#: Window of the finite difference that measures accelerations [s].
ACCELERATION_WINDOW = 0.1
#: Velocities are kept at most this often for it [s].
_HISTORY_INTERVAL = ACCELERATION_WINDOW / 10


class World:
    """A scenario built in MuJoCo, stepped with controllers and behaviours.

    Args:
        scenario: what to build.
        control: tracking controller gains and limits.
        behaviour_tick: period of the road users' decisions [s].
        timestep: physics step [s].
        control_interval: physics steps between controller updates (held in between).
        history_step: period [s] at which the world samples every body's motion for
            the observed ``RoadUser.history`` (a multiple of ``timestep``).
        history_length: samples kept per body (the current one included).
        ego_present: False builds the world without its ego (the ego's body waits
            outside, without contacts): a replay of the road users alone.
        post_crash: what the ego's controller does after its first contact
            (``PostCrashPolicy``); None is the scenario's ``ego.post_crash``.

    Controllers after contact: inside an impact (``ImpactRecorder.in_impact``: a contact
    force above ``MeasurementWindow.impact_acceleration`` times the body's mass within
    the last ``impact_hold``) a body's controller force is zero. A scrape or a body pressed
    against a wall (forces of the order of the tyre force) does not cut it. The measured
    delta-v integrates contact forces only, so it is the contact's alone either way.
    Outside impacts a road user that has touched something brakes to rest
    (``brake_forces``: it is out of the traffic); the ego brakes too under the
    ``brake`` policy, or keeps tracking the planner's plans under ``continue``
    (``ego_on_plan``).

    Raises:
        ValueError: the scenario places bodies overlapping at the start or routes
            are degenerate.
    """

    def __init__(
        self,
        scenario: Scenario,
        control: ControlConfig | None = None,
        behaviour_tick: float = 0.05,
        timestep: float = 0.001,
        control_interval: int = 10,
        history_step: float = 0.1,
        history_length: int = 31,
        ego_present: bool = True,
        post_crash: PostCrashPolicy | str | None = None,
    ) -> None:
        if not (isinstance(control_interval, int) and control_interval >= 1):
            raise ValueError(f"control_interval must be an integer >= 1, got {control_interval!r}")
        if not (isinstance(history_length, int) and history_length >= 1):
            raise ValueError(f"history_length must be an integer >= 1, got {history_length!r}")
        history_interval = round(history_step / timestep) if history_step > 0 else 0
        if history_interval < 1 or abs(history_interval * timestep - history_step) > 1e-9:
            raise ValueError(
                f"history_step must be a positive multiple of the physics step {timestep} s, "
                f"got {history_step}"
            )
        self.scenario = scenario
        self.control = control or ControlConfig()
        #: What the ego's controller does after its first contact.
        self.post_crash = (
            scenario.ego.post_crash
            if post_crash is None
            else parse_enum(PostCrashPolicy, post_crash, "post-crash policy", "post_crash")
        )
        self.road = build_road(scenario.road)
        ego = scenario.ego
        if scenario.road.kind is RoadKind.MAP:
            ego_route = self.road.main_line
        elif scenario.road.kind is RoadKind.MERGE and ego.lane == 0:
            # A ramp start: the reference path merges into the main road's right lane.
            ego_route = self.road.merge_route(ego.s0)
        else:
            ego_route = self.road.route(RouteSpec(road=RoadName.MAIN, lane=ego.lane, turn=ego.turn))
        self.ego_path = ReferencePath.from_polyline(ego_route)
        self.goal_s = ego.goal_s if ego.goal_s is not None else self.ego_path.length - 20.0
        rings = ego.goal_region
        self.goal_area = shapely.union_all([shapely.Polygon(r) for r in rings]) if rings else None
        on_route = ego.s0 < self.goal_s <= self.ego_path.length + 1e-6
        if scenario.road.kind is not RoadKind.MAP and not rings and not on_route:
            raise ValueError(
                f"ego.goal_s: the goal at s = {self.goal_s:.1f} m must lie between the ego's start "
                f"({ego.s0:g} m) and the end of its route ({self.ego_path.length:.1f} m); the default is "
                "20 m before the end"
            )
        users = scenario.road_users
        on_merge = scenario.road.kind is RoadKind.MERGE
        recorded = [u.behaviour.kind is BehaviourKind.RECORDED for u in users]
        # A recorded body needs no route: it gets a short stand-in (shared by all of them).
        routes = [
            _STAND_IN_ROUTE if is_recorded else self.road.route(u.route)
            for u, is_recorded in zip(users, recorded, strict=True)
        ]
        self.fleet = Fleet(
            users,
            routes,
            scenario.road.speed_limit,
            behaviour_tick,
            scenario.road.lane_width,
            lanes=lane_layout(scenario) if any(u.behaviour.mobil for u in users) or on_merge else None,
            ego_desired_speed=ego.desired_speed,
        )
        proxies = [BodyProxy("ego", ego.type, ego.length, ego.width, ego.mass)]
        # A recorded body's recording already says where it went, and a mapped road's
        # parked bodies may stand on the kerb (pavement parking): kerbs do not stop them.
        on_map = scenario.road.kind is RoadKind.MAP
        proxies += [
            BodyProxy.of_type(
                u.name,
                u.type,
                *u.shape,
                u.body_mass,
                kerbs=False if is_recorded or (on_map and u.behaviour.kind is BehaviourKind.PARKED) else None,
                height=u.body_height,
            )
            for u, is_recorded in zip(users, recorded, strict=True)
        ]
        #: Static boxes of the scenario's debris (they also stop every body; the planner perceives them).
        self.debris = debris_boxes(self.road, scenario.debris)
        statics = (
            self.road.static_boxes()
            + tuple(
                StaticBox((o.x, o.y), 0.5 * o.length, 0.5 * o.width, 0.75, o.yaw, Boundary.WALL)
                for o in scenario.obstacles
            )
            + self.debris
        )
        _check_step_size(scenario, proxies, timestep)
        self.scene = Scene(proxies, statics, scenario.contact, timestep)
        self.accel_limit = self._acceleration_limits(users, recorded)
        self.recorder = ImpactRecorder(self.scene)
        self.lengths = np.array([p.length for p in proxies])
        self.widths = np.array([p.width for p in proxies])
        self.types = tuple(p.type for p in proxies)
        if ego.pose is not None:
            x0, y0, th0 = (np.array([value]) for value in ego.pose)
            s_start = float(self.ego_path.to_frenet(x0, y0)[0][0])
        else:
            x0, y0, th0, _, _ = self.ego_path.evaluate(np.array([ego.s0]))
            s_start = ego.s0
        ux, uy, uyaw, _ = self.fleet.initial_poses()
        user_velocity = self.fleet.initial_velocities()
        x = np.concatenate([x0, ux])
        y = np.concatenate([y0, uy])
        yaw = np.concatenate([th0, uyaw])
        vx = np.concatenate([[ego.speed * math.cos(th0[0])], user_velocity[:, 0]])
        vy = np.concatenate([[ego.speed * math.sin(th0[0])], user_velocity[:, 1]])
        self.n = len(proxies)
        #: (n,) bool: which bodies are in the world (recorded road users enter and leave).
        self.present = np.ones(self.n, dtype=bool)
        self.present[0] = bool(ego_present)
        self.present[1:] = self.fleet.presence(0.0)
        self._park = np.column_stack(
            [PARK_ORIGIN_M + PARK_SPACING_M * np.arange(self.n), np.full(self.n, PARK_ORIGIN_M)]
        )
        absent = ~self.present
        x[absent], y[absent] = self._park[absent, 0], self._park[absent, 1]
        vx[absent], vy[absent] = 0.0, 0.0
        self.scene.set_states(x, y, yaw, vx, vy)
        if absent.any():
            self.scene.set_contacts(np.flatnonzero(absent), False)
        self._check_no_overlap()
        #: Presence events, (time [s], entity, "enter" | "leave" | "enter_blocked").
        self.presence_events: list[tuple[float, int, str]] = []
        # Bodies whose entry is held back because they would appear inside another body.
        self._blocked = np.zeros(self.n, dtype=bool)
        # The ego keeps its heading and speed until the first plan arrives (on its route).
        s_grid = s_start + np.arange(0.0, 3.01, 0.1) * ego.speed
        px, py, pth, pk, _ = self.ego_path.evaluate(s_grid)
        if ego.pose is not None:
            t_grid = np.arange(0.0, 3.01, 0.1)
            px = x0[0] + t_grid * ego.speed * math.cos(th0[0])
            py = y0[0] + t_grid * ego.speed * math.sin(th0[0])
            pth, pk = np.full_like(t_grid, th0[0]), np.zeros_like(t_grid)
        n_grid = len(s_grid)
        self.ego_plan = TrajectoryReference(
            0.0,
            np.arange(n_grid) * 0.1,
            px,
            py,
            pth,
            np.full(n_grid, ego.speed),
            np.zeros(n_grid),
            pk,
        )
        self.crashed = np.zeros(self.n, dtype=bool)
        #: True after a step in which the ego came out of an impact (the loop replans then).
        self.ego_left_impact = False
        #: Pose (x, y, yaw) where each body last left the world, (n, 3) (nan if it never left).
        self.exit_pose = np.full((self.n, 3), math.nan)
        self.ego_crash_time: float | None = None
        self._track_sq = 0.0
        self._track_max = 0.0
        self._track_n = 0
        # Road users' distance to their references before their first contact.
        self._user_track_sq = np.zeros(self.n)
        self._user_track_max = np.zeros(self.n)
        self._user_track_n = np.zeros(self.n, dtype=int)
        self._dist_buf = np.zeros(6)
        # Geoms of road users, for distance queries from the ego.
        self._other_geoms = self.scene.geom_ids[1:]
        self.heights = np.array([p.height for p in proxies])
        # Road users that hide others: every one with sensor.occluders = "all", else
        # vehicles only (pedestrians and cyclists are seen around); never the ego.
        everyone = scenario.sensor.occluders == "all"
        self._occluders = np.array([everyone or t not in VULNERABLE_TYPES for t in self.types])
        self._occluders[0] = False
        #: Static boxes as sight sees them (walls, kerbs, debris, fixed obstacles).
        self._static_sight = Boxes.from_static(statics)
        #: Time each road user was first perceived by the planner [s] (nan: not yet), (n,).
        self.first_seen = np.full(self.n, math.nan)
        self.first_seen[0] = 0.0
        #: Wall-clock seconds spent in mj_step, in controllers and behaviours, in measurement.
        self.timing = {"mj_step": 0.0, "control": 0.0, "measurement": 0.0}
        self.control_interval = int(control_interval)
        self._control_countdown = 0
        self._any_crashed = False
        n = self.n
        self._p_ref, self._v_ref, self._a_ref = np.zeros((n, 2)), np.zeros((n, 2)), np.zeros((n, 2))
        self._yaw_ref, self._rate_ref = np.zeros(n), np.zeros(n)
        # Ring buffer of sampled motion (x, y, yaw, v along heading) for RoadUser.history.
        self._history_interval = history_interval
        self._history = np.zeros((history_length, n, 4))
        self._history_times = np.zeros(history_length)
        self._history_count = 0
        self._steps = 0
        self._sample_history()
        # Velocities at recent controller updates, for the measured accelerations.
        self._velocity_history: deque[tuple[float, np.ndarray]] = deque(maxlen=64)

    def __deepcopy__(self, memo: dict[int, object]) -> World:
        """An independent copy of the world in its current state, to branch a run from.

        What never changes during a run is shared, not copied: the scenario and its
        road-user specs and routes, the built road, the ego's route and the MuJoCo model
        (``Scene.__deepcopy__``). Everything that evolves (MuJoCo data, behaviours,
        controllers, contact episodes, histories) is copied; the copy and the original
        step to bit-identical states (tested).
        """
        fleet = self.fleet
        for shared in (
            self.scenario,
            self.scenario.road_users,
            self.road,
            self.ego_path,
            fleet.specs,
            fleet.routes,
        ):
            memo[id(shared)] = shared
        new = World.__new__(World)
        memo[id(self)] = new
        for name, value in self.__dict__.items():
            setattr(new, name, copy.deepcopy(value, memo))
        return new

    # ------------------------------------------------------------------ setup

    def _acceleration_limits(self, users: tuple, recorded: list[bool]) -> np.ndarray:
        """(n,) largest drive acceleration per body [m/s^2].

        Every body's tyres give at most ``friction_mu g``. A recorded road user must be
        where its recording says (the ego meets the traffic that was there), so its
        limit is raised to what its recording asks (plus 10 %), at most
        ``RECORDED_ACCEL_CAP``: noisy recordings (NGSIM) ask more than tyres can give.
        ``beyond_friction`` lists them with what they ask.
        """
        base = self.control.friction_mu * GRAVITY
        limit = np.full(len(users) + 1, base)
        rows = [i for i, is_recorded in enumerate(recorded) if is_recorded]
        #: Recorded road users whose recording asks more than the tyres give: entity -> [m/s^2].
        self.beyond_friction: dict[int, float] = {}
        #: What the world found in the scenario, for the run summary (jerky recordings).
        self.notes: list[str] = []
        if rows:
            peaks = RecordedTracks([users[i].behaviour.trajectory for i in rows]).peak_accelerations()
            for i, peak in zip(rows, peaks, strict=True):
                if peak.value > base:
                    limit[i + 1] = min(1.1 * peak.value, RECORDED_ACCEL_CAP)
                    self.beyond_friction[i + 1] = peak.value
                    self.notes.append(
                        f"recording of {users[i].name} asks {peak.value:.1f} m/s^2 at t = {peak.time:.1f} s, "
                        f"beyond tyre friction ({base:.1f} m/s^2): its body is given the force to follow it "
                        f"(at most {RECORDED_ACCEL_CAP:.0f} m/s^2)"
                    )
        return limit

    def _check_no_overlap(self) -> None:
        bad = self.scene.overlaps()
        if bad:
            names = [self._entity_name(e) for e in bad[0]]
            raise ValueError(
                f"scenario {self.scenario.name!r}: {names[0]} and {names[1]} overlap at the start"
            )

    def _entity_name(self, entity: int) -> str:
        return self.scene.names[entity] if entity >= 0 else f"a {self.scene.static_kind}"

    def environment(self) -> RoadEnvironment:
        """The road as the planner sees it: the ego route, lanes, drivable area (minus debris), stop lines."""
        spec = self.scenario.road
        centre = edges = None
        zones: tuple[NoOvertakingZone, ...] = ()
        if spec.map is not None:
            width, offsets = spec.map.lane_width, spec.map.lane_offsets
        else:
            lane = self.scenario.ego.lane
            on_ramp = spec.kind is RoadKind.MERGE and lane == 0
            if on_ramp:
                lane = 1  # its reference path ends in lane 1 (``RoadGeometry.merge_route``)
            width = spec.lane_width
            offsets = tuple((k - lane) * spec.lane_width for k in range(spec.lanes))
            # Markings relative to the ego's route (its start lane's centre line). A ramp
            # ego's route moves from lane 0 to lane 1, so no constant offset places the
            # edges on it: it gets no shoulder rule (planner) and no shoulder judge (world).
            d_ego = self.road.lane_offset(lane, 1)
            road_edges = self.road.lane_edges()
            if not on_ramp:
                edges = (float(road_edges[0] - d_ego), float(road_edges[-1] - d_ego))
            if self.road.centre_offset is not None:
                centre = self.road.centre_offset - d_ego
            zones = tuple(
                NoOvertakingZone(*self.zone_span(zone), zone.pass_below) for zone in spec.no_overtaking
            )
        area = self.road.drivable_area
        if self.debris:
            # Debris is a hole in the drivable area: the planner keeps off it as off the road's edges.
            area = area.difference(shapely.union_all([box_footprint(b) for b in self.debris]))
        return RoadEnvironment(
            reference_path=self.ego_path,
            drivable_area=area,
            lane_width=width,
            lane_offsets=offsets,
            speed_limit=spec.speed_limit,
            stop_lines=tuple(line.as_stop_line() for line in self.scenario.stop_lines),
            centre_line=centre,
            lane_edges=edges,
            no_overtaking=zones,
        )

    def zone_span(self, zone: NoOvertakingSpec) -> tuple[float, float]:
        """A no-overtaking zone's (start, end) as arc lengths along the ego's route [m].

        The zone is given along the main road's reference line; its ends are projected
        onto the ego's route (on a curve the ego's lane is longer or shorter than the
        reference line).
        """
        line = self.road.main_line
        arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(line, axis=0).T))])
        s = np.array([zone.start, zone.end])
        x, y = np.interp(s, arc, line[:, 0]), np.interp(s, arc, line[:, 1])
        s_ego, _ = self.ego_path.to_frenet(x, y)
        return float(s_ego[0]), float(s_ego[1])

    # ------------------------------------------------------------------ state

    @property
    def time(self) -> float:
        """Simulation time [s]."""
        return float(self.scene.data.time)

    @property
    def positions(self) -> np.ndarray:
        """(n, 2) centres [m] (a view; do not modify)."""
        return self.scene.qpos[:, :2]

    @property
    def velocities(self) -> np.ndarray:
        """(n, 2) velocities [m/s] (a view; do not modify)."""
        return self.scene.qvel[:, :2]

    @property
    def yaws(self) -> np.ndarray:
        """(n,) headings [rad] (a view; do not modify)."""
        return self.scene.qpos[:, 2]

    def speeds_along_heading(self) -> np.ndarray:
        """(n,) velocity projected on each body's heading [m/s]."""
        yaw = self.scene.qpos[:, 2]
        v = self.scene.qvel
        return v[:, 0] * np.cos(yaw) + v[:, 1] * np.sin(yaw)

    def ego_progress(self) -> float:
        """Arc length of the ego along its route [m]."""
        s, _ = self.ego_path.to_frenet(self.scene.qpos[0, 0], self.scene.qpos[0, 1])
        return float(s)

    def lane_extent(self) -> tuple[float, float, float, float]:
        """The ego across its route: (s, d, right, left) [m].

        s, d: its centre's Frenet coordinates along the route; right, left: the offsets
        of its footprint's outermost points, d -+ (L/2 |sin(yaw - theta)| + W/2
        |cos(yaw - theta)|) with theta the route's heading at s.
        """
        x, y, yaw = self.scene.qpos[0, 0], self.scene.qpos[0, 1], self.scene.qpos[0, 2]
        s, d = self.ego_path.to_frenet(x, y)
        s, d = float(np.asarray(s).reshape(-1)[0]), float(np.asarray(d).reshape(-1)[0])
        relative = float(yaw) - float(self.ego_path.heading(s))
        half = 0.5 * float(self.lengths[0]) * abs(math.sin(relative)) + 0.5 * float(self.widths[0]) * abs(
            math.cos(relative)
        )
        return s, d, d - half, d + half

    def goal_reached(self) -> bool:
        """True once the ego has reached its goal.

        The goal is, in this order: its goal region (the ego's centre inside it), a
        goal of time only (the run has lasted ``ego.goal_time``), or its arc length
        ``goal_s`` along the route.
        """
        ego = self.scenario.ego
        if self.goal_area is not None:
            return bool(self.goal_area.covers(shapely.Point(self.scene.qpos[0, 0], self.scene.qpos[0, 1])))
        if ego.goal_time is not None:
            return self.time >= ego.goal_time - 1e-9
        return self.ego_progress() >= self.goal_s

    def goal_description(self) -> str:
        """What reaching the goal means here (for a run's reason)."""
        ego = self.scenario.ego
        if self.goal_area is not None:
            return "ego reached its goal region"
        if ego.goal_time is not None:
            return f"ego drove until its goal time {ego.goal_time:g} s without a collision"
        return f"ego reached s = {self.goal_s:.1f} m on its route"

    def view(self) -> WorldView:
        """True states of all bodies for the behaviours."""
        return WorldView(
            time=self.time,
            position=self.scene.qpos[:, :2].copy(),
            velocity=self.scene.qvel[:, :2].copy(),
            yaw=self.scene.qpos[:, 2].copy(),
            length=self.lengths,
            width=self.widths,
            types=self.types,
            ego_s=self.ego_progress() if self.fleet.script.needs_ego_s else math.nan,
        )

    def _sample_history(self) -> None:
        k = self._history_count % len(self._history_times)
        qpos = self.scene.qpos
        row = self._history[k]
        row[:, 0:3] = qpos[:, 0:3]
        row[:, 3] = self.speeds_along_heading()
        self._history_times[k] = self.time
        self._history_count += 1

    def histories(self) -> tuple[np.ndarray, np.ndarray]:
        """Sampled true motion of every body, oldest first.

        Returns:
            (times [s] relative to now, shape (m,); samples (m, n, 4): x [m], y [m],
            yaw [rad], speed along the heading [m/s]), m <= history_length.
        """
        size = len(self._history_times)
        m = min(self._history_count, size)
        order = (self._history_count - m + np.arange(m)) % size
        return self._history_times[order] - self.time, self._history[order]

    def observe(
        self, rng: np.random.Generator | None = None, noise: ObservationNoise | None = None
    ) -> tuple[KinematicState, list[RoadUser]]:
        """The ego's state and the road users as the planner perceives them.

        Args:
            rng: generator for the observation noise (needed if ``noise`` is enabled).
            noise: standard deviations; None observes exactly.

        The ego's acceleration is the one its current plan commands. A road user's
        acceleration is measured from the physics: the change of its velocity over the
        last ``ACCELERATION_WINDOW`` seconds, projected on its heading; its yaw rate is
        the physics' angular velocity. Hidden road users (sensor range, occlusion) are
        left out. Each road user carries its ``history``: the world's samples of its true
        motion every ``history_step`` (a tracker's smoothed estimate; the observation
        noise applies to the current state only). The first time a road user is
        perceived is kept in ``first_seen``.

        Returns:
            (ego state, road users with ids = entity indices, shapes, masses and legal
            corridors).
        """
        qpos, qvel = self.scene.qpos, self.scene.qvel
        v_along = self.speeds_along_heading()
        x, y, yaw = qpos[:, 0].copy(), qpos[:, 1].copy(), qpos[:, 2].copy()
        v = v_along.copy()
        accel = self.accelerations_along_heading()
        yaw_rate = qvel[:, 2].copy()
        if noise is not None and noise.enabled:
            if rng is None:
                raise ValueError("observe: observation noise needs a numpy Generator (rng)")
            sigma_p = np.full(self.n, noise.position)
            sigma_p[0] = noise.ego_position
            x += rng.normal(0.0, 1.0, self.n) * sigma_p
            y += rng.normal(0.0, 1.0, self.n) * sigma_p
            yaw[1:] += rng.normal(0.0, noise.yaw, self.n - 1)
            v[1:] += rng.normal(0.0, noise.velocity, self.n - 1)
            if noise.acceleration > 0 or noise.yaw_rate > 0:
                accel[1:] += rng.normal(0.0, noise.acceleration, self.n - 1)
                yaw_rate[1:] += rng.normal(0.0, noise.yaw_rate, self.n - 1)
        t = self.time
        visible = self.visible()
        self.first_seen[visible & np.isnan(self.first_seen)] = t
        a_plan = float(self.ego_plan.sample(t)[2] @ np.array([math.cos(yaw[0]), math.sin(yaw[0])]))
        ego_state = KinematicState(
            float(x[0]), float(y[0]), float(yaw[0]), float(v[0]), a_plan, float(qvel[0, 2])
        )
        legal = self.fleet.legal_corridors(t)
        h_times, h_rows = self.histories()
        users = [
            RoadUser(
                id=i,
                type=self.types[i],
                state=KinematicState(
                    float(x[i]), float(y[i]), float(yaw[i]), float(v[i]), float(accel[i]), float(yaw_rate[i])
                ),
                shape=Shape(float(self.lengths[i]), float(self.widths[i])),
                mass=float(self.scene.masses[i]),
                legal=legal[i - 1],
                history=MotionHistory(h_times, h_rows[:, i, 0:2], h_rows[:, i, 2], h_rows[:, i, 3]),
            )
            for i in range(1, self.n)
            if visible[i]
        ]
        return ego_state, users

    def accelerations_along_heading(self) -> np.ndarray:
        """(n,) accelerations along each body's heading [m/s^2], by finite differences.

        The velocity change since the controller update closest to
        ``ACCELERATION_WINDOW`` seconds ago, divided by the time between; 0 before
        the first update.
        """
        history = self._velocity_history
        now = self.time
        if not history:
            return np.zeros(self.n)
        times = np.fromiter((entry[0] for entry in history), float, len(history))
        k = int(np.argmin(np.abs(times - (now - ACCELERATION_WINDOW))))
        then, velocity = history[k]
        if now - then < 0.25 * ACCELERATION_WINDOW:
            return np.zeros(self.n)
        dv = (self.scene.qvel[:, :2] - velocity) / (now - then)
        yaw = self.scene.qpos[:, 2]
        return dv[:, 0] * np.cos(yaw) + dv[:, 1] * np.sin(yaw)

    def visible(self) -> np.ndarray:
        """(n,) bool: which bodies the ego's sensor perceives (the ego itself always).

        Bodies out of the world are never perceived. With a limited sensor
        (``SensorSpec``: range, field of view, occlusion) a road user is perceived if one
        of its five sample points (centre, corners) is in range, in the field of view
        and, with occlusion, no other occluding road user (``sensor.occluders``) and no
        static box (wall, kerb, debris, fixed obstacle) rises above the sight line from
        the sensor to the point at half the road user's height (``physics.sight``).
        """
        sensor = self.scenario.sensor
        visible = self.present.copy()
        visible[0] = True
        others = np.flatnonzero(visible[1:]) + 1
        if not sensor.limited or others.size == 0:
            return visible
        qpos = self.scene.qpos
        heading = float(qpos[0, 2])
        eye = qpos[0, :2] + sensor.offset * np.array([math.cos(heading), math.sin(heading)])
        px, py = target_points(
            qpos[others, 0], qpos[others, 1], qpos[others, 2], self.lengths[others], self.widths[others]
        )
        seen = in_field_of_view(eye, heading, px, py, sensor.range, sensor.fov)
        if sensor.occlusion:
            look = seen.any(axis=1)
            if look.any():
                rows = others[look]
                boxes, ignore = self._sight_boxes(eye, rows, px[look], py[look])
                seen[look] &= ~blocked(
                    eye, sensor.height, px[look], py[look], 0.5 * self.heights[rows], boxes, ignore
                )
        visible[others] = seen.any(axis=1)
        return visible

    def _sight_boxes(
        self, eye: np.ndarray, rows: np.ndarray, px: np.ndarray, py: np.ndarray
    ) -> tuple[Boxes, np.ndarray]:
        """Boxes that may hide road users ``rows`` from ``eye``, and which to ignore for whom.

        Returns:
            (boxes: the occluding road users in the world, then the static boxes near enough
            and tall enough to cross a sight line; ignore: (len(rows), k) bool, a road
            user's own body).
        """
        qpos = self.scene.qpos
        bodies = np.flatnonzero(self.present & self._occluders)
        moving = Boxes(
            qpos[bodies, 0],
            qpos[bodies, 1],
            qpos[bodies, 2],
            0.5 * self.lengths[bodies],
            0.5 * self.widths[bodies],
            self.heights[bodies],
        )
        static = self._static_sight
        if static.size:
            # A box lower than the sensor and every target's middle is under every sight
            # line; one farther than every target point cannot be crossed.
            lowest = min(self.scenario.sensor.height, 0.5 * float(self.heights[rows].min()))
            reach = float(np.hypot(px - eye[0], py - eye[1]).max())
            radius = np.hypot(static.half_length, static.half_width)
            near = np.hypot(static.x - eye[0], static.y - eye[1]) - radius
            static = static.take((static.height > lowest) & (near <= reach))
        ignore = np.zeros((len(rows), bodies.size + static.size), dtype=bool)
        ignore[:, : bodies.size] = rows[:, None] == bodies[None, :]
        return Boxes.concatenate(moving, static), ignore

    # ------------------------------------------------------------------ stepping

    @property
    def ego_on_plan(self) -> bool:
        """True while the ego's controller tracks the planner's plans.

        Before the ego's first contact, and after it under the ``continue`` policy
        (outside impacts the plan is tracked, inside them the force is zero).
        """
        return bool(self.present[0]) and (not self.crashed[0] or self.post_crash is PostCrashPolicy.CONTINUE)

    def set_ego_plan(self, plan: TrajectoryReference) -> None:
        """Track ``plan`` from now on (while ``ego_on_plan``)."""
        self.ego_plan = plan

    def _update_controls(self, t: float) -> None:
        """Behaviours and controllers of all bodies at time ``t`` [s] (one vectorised call)."""
        scene, fleet = self.scene, self.fleet
        history = self._velocity_history
        if not history or t - history[-1][0] >= _HISTORY_INTERVAL - 1e-9:
            history.append((t, scene.qvel[:, :2].copy()))
        if fleet.k and fleet.due(t):
            fleet.decide(self.view())
        p_ref, v_ref, a_ref = self._p_ref, self._v_ref, self._a_ref
        yaw_ref, rate_ref = self._yaw_ref, self._rate_ref
        if fleet.k:
            p, v, a, yaw, rate = fleet.references(t)
            p_ref[1:], v_ref[1:], a_ref[1:], yaw_ref[1:], rate_ref[1:] = p, v, a, yaw, rate
            self._update_presence(t)
            following = self.present & ~self.crashed & ~self._blocked
            following[0] = False
            if following.any():
                err = np.hypot(*(scene.qpos[following, :2] - p_ref[following]).T)
                self._user_track_sq[following] += err * err
                self._user_track_n[following] += 1
                np.maximum.at(self._user_track_max, np.flatnonzero(following), err)
        ego_on_plan = self.ego_on_plan
        if ego_on_plan:
            p, v, a, yaw, rate = self.ego_plan.sample(t)
            if not self.crashed[0]:
                err = math.hypot(scene.qpos[0, 0] - p[0], scene.qpos[0, 1] - p[1])
                self._track_sq += err * err
                self._track_n += 1
                self._track_max = max(self._track_max, err)
            p_ref[0], v_ref[0], a_ref[0], yaw_ref[0], rate_ref[0] = p, v, a, yaw, rate
        ctrl = tracking_forces(
            self.control,
            scene.masses,
            scene.yaw_inertia,
            scene.qpos,
            scene.qvel,
            p_ref,
            v_ref,
            a_ref,
            yaw_ref,
            rate_ref,
            self.accel_limit,
        )
        if self.crashed.any():
            braking = self.crashed.copy()
            braking[0] &= not ego_on_plan
            rows = np.flatnonzero(braking)
            if rows.size:
                ctrl[rows] = brake_forces(
                    self.control, scene.masses[rows], scene.yaw_inertia[rows], scene.qvel[rows]
                )
            # No controller force inside an impact (a body in one has touched something,
            # so it is crashed): a driver or automation has no control in a pulse of tens
            # of g. Scraping or pressed against a wall, it keeps braking and steering.
            ctrl[self.recorder.in_impact] = 0.0
        if not self.present.all():
            ctrl[~self.present] = 0.0
        scene.ctrl[:] = ctrl

    def _update_presence(self, t: float) -> None:
        """Let road users enter and leave the world at ``t`` [s].

        Recorded road users exist while their recording lasts; route-following road
        users leave once their body has passed their route's end (``Fleet.presence``).
        A body enters at its reference state (position, heading, velocity) with its
        contacts on, unless it would appear inside another body: then it waits as a
        ghost (no contacts, following its reference) until it is clear, and the
        presence events say so. A body leaves by losing its contacts and being parked
        far away (its pose when it left is kept in ``exit_pose``); a crashed body stays
        (a wreck does not vanish).
        """
        want = np.ones(self.n, dtype=bool)
        want[1:] = self.fleet.presence(t)
        want |= self.crashed
        want[0] = self.present[0]
        scene = self.scene
        leave = self.present & ~want
        if leave.any():
            rows = np.flatnonzero(leave)
            self.exit_pose[rows] = scene.qpos[rows]
            scene.set_contacts(rows, False)
            scene.qpos[rows, :2] = self._park[rows]
            scene.qvel[rows] = 0.0
            self.present[rows] = False
            self._blocked[rows] = False
            self.presence_events += [(t, int(i), "leave") for i in rows]
        enter = ~self.present & want
        if enter.any():
            rows = np.flatnonzero(enter)
            scene.qpos[rows, :2] = self._p_ref[rows]
            scene.qpos[rows, 2] = self._yaw_ref[rows]
            scene.qvel[rows, :2] = self._v_ref[rows]
            scene.qvel[rows, 2] = self._rate_ref[rows]
            self.present[rows] = True
            self._blocked[rows] = True
            self.presence_events += [(t, int(i), "enter") for i in rows]
            held = rows[~self._release_blocked(rows)]
            self.presence_events += [(t, int(i), "enter_blocked") for i in held]
        if self._blocked.any():
            self._release_blocked(np.flatnonzero(self._blocked))

    def _release_blocked(self, rows: np.ndarray) -> np.ndarray:
        """Turn on the contacts of entering bodies ``rows`` that overlap no other body.

        Returns:
            (len(rows),) bool: which were released.
        """
        qpos = self.scene.qpos
        others = np.flatnonzero(self.present & ~self._blocked)
        clear = np.ones(rows.size, dtype=bool)
        if others.size:
            depth = rectangle_overlap(
                qpos[rows, 0, None],
                qpos[rows, 1, None],
                qpos[rows, 2, None],
                self.lengths[rows, None],
                self.widths[rows, None],
                qpos[others, 0],
                qpos[others, 1],
                qpos[others, 2],
                self.lengths[others],
                self.widths[others],
            )
            clear = ~(depth > 0.0).any(axis=1)
        if clear.any():
            self.scene.set_contacts(rows[clear], True)
            self._blocked[rows[clear]] = False
        return clear

    def step(self) -> list[ImpactMeasurement]:
        """One physics step: behaviours, controllers, ``mj_step``, impact measurement.

        Controls are recomputed every ``control_interval`` steps (held in between),
        and every step once a body has crashed. ``ego_left_impact`` says whether the ego
        came out of an impact in this step.

        Returns:
            The collision episodes that ended in this step.
        """
        clock = time.perf_counter
        t_start = clock()
        scene = self.scene
        if self._control_countdown <= 0 or self._any_crashed:
            self._update_controls(float(scene.data.time))
            self._control_countdown = self.control_interval
        self._control_countdown -= 1
        recorder = self.recorder
        t_physics = clock()
        was_in_impact = bool(recorder.in_impact[0])
        done = scene.step(recorder)  # physics and impact measurement, sub-stepped in impacts
        self.ego_left_impact = was_in_impact and not recorder.in_impact[0]
        self._steps += 1
        if self._steps % self._history_interval == 0:
            self._sample_history()
        t_measure = clock()
        if scene.contact_possible:
            new = recorder.touched & ~self.crashed
            if new.any():
                self.crashed |= new
                self._any_crashed = True
                if new[0]:
                    self.ego_crash_time = float(scene.data.time) - scene.dt
                self.fleet.deactivate(new[1:])
                scene.ctrl[np.flatnonzero(new)] = 0.0
        t_end = clock()
        timing = self.timing
        timing["control"] += t_physics - t_start
        timing["mj_step"] += t_measure - t_physics
        timing["measurement"] += t_end - t_measure
        return done

    def finish(self, complete: bool = False) -> list[ImpactMeasurement]:
        """Close open collision episodes at the end of a run.

        Args:
            complete: mark them complete (the bodies have come to rest).
        """
        return self.recorder.finish(complete)

    # ------------------------------------------------------------------ diagnostics

    def tracking_error(self) -> tuple[float, float]:
        """RMS and maximum distance [m] between the ego and its plan before any contact."""
        if self._track_n == 0:
            return 0.0, 0.0
        return math.sqrt(self._track_sq / self._track_n), self._track_max

    def road_user_tracking(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each road user's distance to its reference while in the world, before its first contact.

        Returns:
            (rms [m], max [m], samples), each (n,) with entity 0 (the ego) zero; rms is
            nan for a body never sampled.
        """
        n = self._user_track_n
        with np.errstate(invalid="ignore", divide="ignore"):
            rms = np.where(n > 0, np.sqrt(self._user_track_sq / np.maximum(n, 1)), np.nan)
        rms[0] = 0.0
        return rms, self._user_track_max.copy(), n.copy()

    def ego_distances(self, distmax: float = 50.0) -> np.ndarray:
        """(n - 1,) distances [m] from the ego's geom to every road user's (capped at distmax).

        Road users not in the world are at ``distmax``.
        """
        scene = self.scene
        ego_geom = int(scene.geom_ids[0])
        out = np.full(len(self._other_geoms), float(distmax))
        for k, g in enumerate(self._other_geoms):
            if self.present[k + 1]:
                out[k] = mujoco.mj_geomDistance(scene.model, scene.data, ego_geom, int(g), distmax, None)
        return out

    def diverged(self, max_penetration: float) -> str | None:
        """Why the simulation cannot be trusted any more, or None.

        Args:
            max_penetration: largest acceptable geom overlap [m].
        """
        scene = self.scene
        if not (np.isfinite(scene.data.qpos).all() and np.isfinite(scene.data.qvel).all()):
            return "non-finite state (NaN or Inf in qpos/qvel)"
        warnings = scene.data.warning
        for kind, what in _UNSTABLE_WARNINGS:
            if warnings[kind].number:
                return f"MuJoCo warned: {what} ({kind.name})"
        speed = float(scene.speeds().max(initial=0.0))
        if speed > MAX_BODY_SPEED:
            return f"a body moves at {speed:.0f} m/s (more than {MAX_BODY_SPEED:g} m/s)"
        if self.recorder.max_penetration > max_penetration:
            return f"penetration {self.recorder.max_penetration:.3f} m exceeds the bound {max_penetration} m"
        return None


#: The route a recorded road user is given (it follows its recording, not a route).
_STAND_IN_ROUTE = np.array([[0.0, 0.0], [10.0, 0.0]])


#: MuJoCo warnings after which a run's physics is not trusted: (warning, meaning).
_UNSTABLE_WARNINGS = (
    (mujoco.mjtWarning.mjWARN_BADQACC, "bad acceleration, the state was reset"),
    (mujoco.mjtWarning.mjWARN_BADQPOS, "bad position, the state was reset"),
    (mujoco.mjtWarning.mjWARN_BADQVEL, "bad velocity, the state was reset"),
    (mujoco.mjtWarning.mjWARN_CONTACTFULL, "too many contacts, some were dropped"),
    (mujoco.mjtWarning.mjWARN_CNSTRFULL, "too many constraints, some were dropped"),
)
#: A body faster than this [m/s] means the physics has blown up (scenario speeds are <= 70 m/s).
MAX_BODY_SPEED = 200.0
#: Largest share of its smallest dimension a body may move in one physics step.
MAX_STEP_FRACTION = 0.25


def _check_step_size(scenario: Scenario, proxies: Sequence[BodyProxy], timestep: float) -> None:
    """Refuse speeds at which a body moves more than ``MAX_STEP_FRACTION`` of its size per step.

    A body that jumps a good part of its own width between two physics steps can pass
    through another without a contact being found. The speeds checked are every
    speed a body is given (initial, profile, desired) and, for the ego, the road's
    speed limit it may drive at.

    Raises:
        ValueError: naming the body, its speed, the distance per step and the limit.
    """
    ego = scenario.ego
    speeds = [max(ego.speed, ego.desired_speed or 0.0, scenario.road.speed_limit)]
    for user in scenario.road_users:
        behaviour = user.behaviour
        speeds.append(max([behaviour.speed, *(v for _, v in behaviour.speed_profile)]))
    for proxy, speed in zip(proxies, speeds, strict=True):
        size = 2.0 * proxy.radius if proxy.is_round else min(proxy.length, proxy.width)
        step = speed * timestep
        if step > MAX_STEP_FRACTION * size:
            raise ValueError(
                f"{proxy.name}: at {speed:g} m/s it moves {step * 100:.1f} cm per {timestep * 1000:g} ms "
                f"physics step, more than {MAX_STEP_FRACTION:.0%} of its size {size:g} m; lower the "
                "speed or the physics time step"
            )
