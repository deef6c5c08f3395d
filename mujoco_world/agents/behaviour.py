"""Behaviour of the road users: scripted, car following (IDM), crossing pedestrians, parked.

Each behaviour is a ``BehaviourModel`` registered in ``BEHAVIOURS`` under its
``BehaviourKind`` value; the ``Fleet`` looks the models up once and holds the states.

Every road user follows its route with an *intended* longitudinal state (arc length
``s`` [m], speed ``v`` [m/s]) and a lateral offset ``d`` [m] from the route. The
behaviours decide an acceleration and a lateral motion at a behaviour rate (default
20 Hz, ``tick``); the intended state is integrated every physics step, vectorised
over all road users, and turned into position, velocity and acceleration references
for the tracking controller (``Fleet.references``). The bodies are physical, so they
lag their references slightly and respond to impacts.
"""

from __future__ import annotations

import functools
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ethical_planner.geometry import rectangle_half_extent
from ethical_planner.reference_path import ReferencePath
from ethical_planner.registry import Registry
from ethical_planner.road_users import LegalCorridor, RoadUserType
from mujoco_world.agents.mobil import (
    LOOK_BACK_M,
    SIDES,
    IdmParameters,
    LaneLayout,
    Neighbours,
    lane_neighbours,
    mobil_accelerations,
    mobil_decide,
)
from mujoco_world.physics.safety import time_to_collision
from mujoco_world.scenario.recorded_tracks import RecordedTracks
from mujoco_world.scenario.spec import (
    ActionSpec,
    BehaviourKind,
    ConditionSpec,
    IdmSpec,
    RoadUserSpec,
)

#: Resampling step of the routes [m].
ROUTE_STEP_M = 0.25
#: Straight continuation of every route beyond its end [m].
ROUTE_EXTENSION_M = 300.0
#: Largest acceleration magnitude a scripted profile may command [m/s^2].
SCRIPTED_ACCEL_LIMIT = 10.0


def smoothstep_profile(knots: Sequence[tuple[float, float]], t: float) -> tuple[float, float, float]:
    """Value, first and second time derivative of a knot profile at ``t``.

    Between knots the value follows a quintic smoothstep (zero velocity and
    acceleration at the knots); before the first knot it is 0 (moving to the first
    value), after the last it holds.

    Args:
        knots: (time [s], value) pairs, strictly increasing times.
        t: time [s].
    """
    if not knots:
        return 0.0, 0.0, 0.0
    pts = [(0.0, 0.0), *knots] if knots[0][0] > 0 else list(knots)
    if t <= pts[0][0]:
        return pts[0][1], 0.0, 0.0
    for (t0, v0), (t1, v1) in zip(pts[:-1], pts[1:], strict=True):
        if t <= t1:
            h = t1 - t0
            u = (t - t0) / h
            dv = v1 - v0
            value = v0 + dv * (10 * u**3 - 15 * u**4 + 6 * u**5)
            rate = dv * (30 * u**2 - 60 * u**3 + 30 * u**4) / h
            accel = dv * (60 * u - 180 * u**2 + 120 * u**3) / (h * h)
            return value, rate, accel
    return pts[-1][1], 0.0, 0.0


def linear_profile(knots: Sequence[tuple[float, float]], t: float, default: float) -> float:
    """Piecewise-linear profile value at ``t`` (``default`` without knots; holds at the ends)."""
    if not knots:
        return default
    times = [k[0] for k in knots]
    values = [k[1] for k in knots]
    if t <= times[0]:
        return default if times[0] > 0 else values[0]
    return float(np.interp(t, times, values))


class RouteTable:
    """Routes of several bodies, resampled by arc length into padded arrays.

    Beyond its end a route continues straight (``ReferencePath`` semantics); before
    its start it is clamped. Bodies on the same route (equal polylines, e.g. every car
    of one lane) share one smoothed path and one table row, so building the table
    costs one path per distinct route, not one per body.

    Attributes:
        paths: the smoothed ``ReferencePath`` of each body's route (shared objects).
        length: (k,) route lengths [m].
        x, y, theta, kappa: (m, n) samples every ``ROUTE_STEP_M`` of the m distinct routes.
    """

    def __init__(self, polylines: Sequence[np.ndarray]) -> None:
        distinct: dict[bytes, int] = {}
        unique: list[np.ndarray] = []
        row_of = []
        for polyline in polylines:
            points = np.ascontiguousarray(polyline, dtype=float)
            key = points.shape[0].to_bytes(8, "little") + points.tobytes()
            if key not in distinct:
                distinct[key] = len(unique)
                unique.append(points)
            row_of.append(distinct[key])
        self._row_of = np.array(row_of, dtype=np.int64)
        shared = [ReferencePath.from_polyline(p) for p in unique]
        self.paths = tuple(shared[i] for i in row_of)
        self.length = np.array([p.length for p in self.paths])
        longest = max((p.length for p in shared), default=0.0)
        n = int(math.ceil((float(longest) + ROUTE_EXTENSION_M) / ROUTE_STEP_M)) + 2
        s = np.arange(n) * ROUTE_STEP_M
        self._table = np.zeros((len(shared), n, 4))  # x, y, theta, kappa
        for i, path in enumerate(shared):
            x, y, theta, kappa, _ = path.evaluate(s)
            self._table[i] = np.column_stack([x, y, theta, kappa])
        self.x, self.y, self.theta, self.kappa = (self._table[:, :, j] for j in range(4))
        self._n = n

    def lookup(self, rows: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, ...]:
        """Pose of the routes of bodies ``rows`` at arc lengths ``s`` (same shape, any).

        Returns:
            (x, y, theta, kappa), each of the shape of ``s``.
        """
        u = np.clip(s, 0.0, (self._n - 1.001) * ROUTE_STEP_M) / ROUTE_STEP_M
        i = u.astype(np.int64)
        f = (u - i)[..., None]
        table_rows = self._row_of[rows]
        lo = self._table[table_rows, i]
        out = lo + f * (self._table[table_rows, i + 1] - lo)
        return out[..., 0], out[..., 1], out[..., 2], out[..., 3]


@dataclass(frozen=True, slots=True)
class WorldView:
    """What a behaviour may look at: the true states of all bodies (entity 0 is the ego).

    Attributes:
        time: [s].
        position: (n, 2) [m]. velocity: (n, 2) [m/s]. yaw: (n,) [rad].
        length: (n,) [m]. width: (n,) [m]. types: road-user types, length n.
        ego_s: the ego's arc length along its route [m] (nan unless a script reads it).
    """

    time: float
    position: np.ndarray
    velocity: np.ndarray
    yaw: np.ndarray
    length: np.ndarray
    width: np.ndarray
    types: tuple[RoadUserType, ...]
    ego_s: float = math.nan


class Fleet:
    """The road users' behaviours and intended states, vectorised.

    Args:
        specs: road users (entity i + 1 is ``specs[i]``; the ego is entity 0).
        routes: route polylines in the same order, each (n_i, 2) [m].
        road_speed_limit: [m/s], for legal corridors without their own limit.
        tick: behaviour period [s].
        lane_width: [m], for scripted lane changes.
        lanes: the lanes MOBIL road users may change into and where lanes end (None:
            every lane of the road is theirs, none ends).
        ego_desired_speed: [m/s], the ego's desired speed when MOBIL weighs the ego as a
            follower (None: the road's speed limit).
    """

    def __init__(
        self,
        specs: Sequence[RoadUserSpec],
        routes: Sequence[np.ndarray],
        road_speed_limit: float,
        tick: float = 0.05,
        lane_width: float = 3.5,
        lanes: LaneLayout | None = None,
        ego_desired_speed: float | None = None,
    ) -> None:
        self.specs = tuple(specs)
        self.k = len(self.specs)
        self.tick = float(tick)
        self.road_speed_limit = float(road_speed_limit)
        self.routes = RouteTable(routes) if self.k else None
        self.rows = np.arange(self.k)
        self.s = np.array([u.s0 for u in self.specs], dtype=float)
        self.v = np.array([u.behaviour.speed for u in self.specs], dtype=float)
        self.a = np.zeros(self.k)
        self.d = np.zeros(self.k)
        self.d_rate = np.zeros(self.k)
        self.d_accel = np.zeros(self.k)
        self.activated_at = np.full(self.k, math.inf)
        self.active = np.ones(self.k, dtype=bool)  # False once crashed or gone
        #: Road users that have left the world past their route's end, (k,) bool.
        self.left = np.zeros(self.k, dtype=bool)
        #: Arc length past which a road user leaves: route end + half its length [m], (k,)
        #: (its rear has crossed the road's end; inf for bodies whose motion a model gives).
        self.exit_s = (
            self.routes.length + 0.5 * np.array([u.shape[0] for u in self.specs]) if self.k else np.zeros(0)
        )
        self._next_tick = 0.0
        self._time = 0.0
        #: Pedestrians that have started to cross, (k,) bool.
        self.crossing = np.zeros(self.k, dtype=bool)
        #: Reaction-time queues of decided accelerations (None without a delay).
        self.delay: list[deque[float] | None] = []
        for u in self.specs:
            idm = u.behaviour.idm
            ticks = int(round(idm.reaction_time / self.tick)) if idm is not None else 0
            self.delay.append(deque([0.0] * ticks) if ticks > 0 else None)
        self.lane_width = float(lane_width)
        self.script = Script(self.specs)
        self._setup_lanes(lanes, ego_desired_speed)
        self._kind = [u.behaviour.kind for u in self.specs]
        self._models_by_kind = {kind: BEHAVIOURS.get(kind.value) for kind in dict.fromkeys(self._kind)}
        self._kind_mask = {kind: np.array([k is kind for k in self._kind]) for kind in self._models_by_kind}
        # Models that give the motion of their bodies themselves (recordings): their rows
        # and the state their ``setup`` built.
        self._given: list[tuple[GivenMotion, np.ndarray, Any]] = []
        for kind, model in self._models_by_kind.items():
            if isinstance(model, GivenMotion):
                rows = np.flatnonzero(self._kind_mask[kind])
                self._given.append((model, rows, model.setup(self, rows)))
                self.exit_s[rows] = math.inf

    def _setup_lanes(self, lanes: LaneLayout | None, ego_desired_speed: float | None) -> None:
        """Per road user: route lane and direction, whom it sees, MOBIL parameters and state."""
        specs = self.specs
        self.lanes = lanes
        self.route_lane = np.array([u.route.lane for u in specs], dtype=np.int64)
        self.direction = np.array([u.route.direction for u in specs], dtype=np.int64)
        #: (k,) reaction level to the ego in [0, 1] (``behaviour.ego_reaction``; 0 for
        #: road users of other kinds, which are blind to it).
        self.ego_reaction = np.array(
            [u.behaviour.ego_reaction if u.behaviour.ego_reaction is not None else 0.0 for u in specs],
            dtype=float,
        )
        #: (k,) bool: road users that change lanes with MOBIL.
        self.mobil = np.array([u.behaviour.mobil is not None for u in specs], dtype=bool)
        mobil = [u.behaviour.mobil for u in specs]
        self._mobil_params = {
            name: np.array([getattr(p, name) if p is not None else 0.0 for p in mobil])
            for name in ("politeness", "threshold", "b_safe", "bias_right", "duration", "cooldown")
        }
        # v_crit of the passing rule (``mobil.no_passing_right``); inf: the rule is off.
        self._mobil_params["pass_right_below"] = np.array(
            [p.pass_right_below if p is not None and p.no_passing_right else math.inf for p in mobil]
        )
        #: (k,) time before which a MOBIL road user does not decide (changing lane, cooldown) [s].
        self.mobil_busy_until = np.full(self.k, -math.inf)
        #: Lane changes MOBIL made: (time [s], road user index, from lane, to lane), lanes
        #: from the right in its direction.
        self.lane_changes: list[tuple[float, int, int, int]] = []
        # The lane end on each road user's route lane (a standing obstacle), along the main road [m].
        self.route_lane_end = (
            lanes.end_of(self.route_lane, self.direction) if lanes is not None else np.full(self.k, np.inf)
        )
        # IDM parameters of every body (entity 0 the ego), for the accelerations MOBIL weighs:
        # an idm road user's own, the defaults for the others (desired speed: the ego's, or
        # the larger of the body's speed and the road's limit).
        default = IdmSpec()
        idms = [default, *(u.behaviour.idm or default for u in specs)]
        self._idm_static = {
            "a_max": np.array([p.max_acceleration for p in idms]),
            "b_comf": np.array([p.comfort_deceleration for p in idms]),
            "headway": np.array([p.time_headway for p in idms]),
            "min_gap": np.array([p.min_gap for p in idms]),
        }
        self._is_idm = np.array([False, *(u.behaviour.kind is BehaviourKind.IDM for u in specs)])
        self._v0 = np.array(
            [
                ego_desired_speed if ego_desired_speed is not None else self.road_speed_limit,
                *(u.behaviour.speed for u in specs),
            ],
            dtype=float,
        )

    def idm_parameters(self, speeds: np.ndarray, v0_rows: np.ndarray, rows: np.ndarray) -> IdmParameters:
        """IDM parameters of every body (n = k + 1), with desired speeds ``v0_rows`` for ``rows``.

        Args:
            speeds: (n,) body speeds [m/s]. v0_rows: desired speeds of road users ``rows``.
        """
        v0 = np.where(self._is_idm, self._v0, np.maximum(speeds, self.road_speed_limit))
        v0[0] = self._v0[0]
        v0[rows + 1] = v0_rows
        return IdmParameters(v0=v0, **self._idm_static)

    # ------------------------------------------------------------------ states

    def initial_poses(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(x, y, yaw, speed along the heading) of every road user at the start, each (k,)."""
        if not self.k:
            empty = np.zeros(0)
            return empty, empty, empty, empty
        x, y, theta, _ = self.routes.lookup(self.rows, self.s)
        speed = self.v.copy()
        for model, rows, state in self._given:
            p, v, _, yaw, _ = model.references(state, 0.0)
            x[rows], y[rows], theta[rows] = p[:, 0], p[:, 1], yaw
            speed[rows] = v[:, 0] * np.cos(yaw) + v[:, 1] * np.sin(yaw)
        return x, y, theta, speed

    def initial_velocities(self) -> np.ndarray:
        """(k, 2) velocities [m/s] of every road user at the start."""
        x, y, theta, speed = self.initial_poses()
        vel = np.column_stack([speed * np.cos(theta), speed * np.sin(theta)])
        for model, rows, state in self._given:
            vel[rows] = model.references(state, 0.0)[1]
        return vel

    def presence(self, time: float) -> np.ndarray:
        """(k,) bool: which road users exist in the world at ``time`` [s].

        Route-following road users do until their body has passed their route's end
        (``left``, set by ``references``); a model giving its bodies' motion decides
        for its rows (a recording exists while it lasts).
        """
        present = ~self.left
        for model, rows, state in self._given:
            present[rows] = model.presence(state, time)
        return present

    @property
    def given_rows(self) -> np.ndarray:
        """Rows whose motion a model gives (recordings), sorted."""
        if not self._given:
            return np.zeros(0, dtype=int)
        return np.sort(np.concatenate([rows for _, rows, _ in self._given]))

    def references(self, time: float) -> tuple[np.ndarray, ...]:
        """Advance the intended states to ``time`` [s] and return controller references.

        Returns:
            (p_ref (k, 2), v_ref (k, 2), a_ref (k, 2), yaw_ref (k,), yaw_rate_ref (k,)).
        """
        dt = time - self._time
        self._time = time
        a = np.where((self.v > 0.0) | (self.a > 0.0), self.a, 0.0)
        v_new = np.maximum(self.v + a * dt, 0.0)
        self.s = self.s + 0.5 * (self.v + v_new) * dt
        self.v = v_new
        self.d = self.d + self.d_rate * dt
        gone = self.active & ~self.left & (self.s > self.exit_s)
        if gone.any():
            # Past the route's end: the road user leaves the world (crashed ones, not
            # active, stay), and its behaviour stops.
            self.left |= gone
            self.deactivate(gone)
        x, y, theta, kappa = self.routes.lookup(self.rows, self.s)
        c, s = np.cos(theta), np.sin(theta)
        p = np.column_stack([x - self.d * s, y + self.d * c])
        v = self.v
        vel = np.column_stack([v * c - self.d_rate * s, v * s + self.d_rate * c])
        lat = v * v * kappa + self.d_accel
        acc = np.column_stack([a * c - lat * s, a * s + lat * c])
        yaw = theta + np.arctan2(self.d_rate, np.maximum(v, 0.5))
        rate = v * kappa
        for model, rows, state in self._given:
            p[rows], vel[rows], acc[rows], yaw[rows], rate[rows] = model.references(state, time)
        return p, vel, acc, yaw, rate

    def deactivate(self, mask: np.ndarray) -> None:
        """Stop the behaviours of crashed or departed road users (``mask`` (k,) bool)."""
        self.active &= ~mask
        self.v[mask] = 0.0
        self.a[mask] = 0.0
        self.d_rate[mask] = 0.0
        self.d_accel[mask] = 0.0

    # ------------------------------------------------------------------ decisions

    def due(self, time: float) -> bool:
        """True if the behaviours should decide again at ``time`` [s]."""
        return time >= self._next_tick - 1e-9

    def decide(self, view: WorldView) -> None:
        """Update accelerations and lateral motions of all active road users.

        Each road user's behaviour model (``BEHAVIOURS``, by ``behaviour.kind``) first
        sees all its active road users at once (``prepare``), then decides for each.
        """
        t = view.time
        self._next_tick = t + self.tick
        ego_pos = view.position[0]
        contexts = {}
        for kind, model in self._models_by_kind.items():
            rows = np.flatnonzero(self._kind_mask[kind] & self.active)
            contexts[kind] = model.prepare(self, rows, view) if rows.size else None
        for i, spec in enumerate(self.specs):
            if not self.active[i]:
                continue
            b = spec.behaviour
            if math.isinf(self.activated_at[i]) and t >= b.start_time - 1e-9:
                trigger = b.trigger_distance
                me = view.position[i + 1]
                if trigger is None or math.hypot(*(ego_pos - me)) <= trigger:
                    self.activated_at[i] = t
                    self.script.armed_at[i] = t
            since = t - self.activated_at[i]
            kind = self._kind[i]
            model = self._models_by_kind[kind]
            if math.isfinite(since) and self.script.pending(i):
                self.script.advance(self, i, view)
            lateral = self.script.lateral[i]
            if model.moves and lateral is not None:
                t0, lateral_knots = lateral
                d_next, _, _ = smoothstep_profile(lateral_knots, t - t0 + self.tick)
                _, _, accel = smoothstep_profile(lateral_knots, t - t0)
                self.d_rate[i] = (d_next - self.d[i]) / self.tick
                self.d_accel[i] = accel
            elif model.moves and math.isfinite(since) and b.lateral:
                d_next, _, _ = smoothstep_profile(b.lateral, since + self.tick)
                _, _, accel = smoothstep_profile(b.lateral, since)
                self.d_rate[i] = (d_next - self.d[i]) / self.tick
                self.d_accel[i] = accel
            self.a[i] = model.acceleration(self, i, since, view, contexts[kind])
            if not model.moves:
                self.v[i] = 0.0

    def target_speed(self, i: int, since: float) -> float:
        """Speed road user ``i`` wants [m/s], ``since`` [s] after its behaviour started."""
        b = self.specs[i].behaviour
        if not math.isfinite(since):
            return b.speed
        program = self.script.longitudinal[i]
        if program is not None:
            t0, speed_knots = program
            return linear_profile(speed_knots, self.activated_at[i] + since - t0, b.speed)
        return linear_profile(b.speed_profile, since, b.speed)

    # ------------------------------------------------------------------ legal corridors

    def legal_corridors(self, time: float) -> list[LegalCorridor | None]:
        """Legal corridor of every road user for the planner (None where not given)."""
        out: list[LegalCorridor | None] = []
        for i, spec in enumerate(self.specs):
            legal = spec.legal
            if legal is None:
                out.append(None)
                continue
            stop = None
            if legal.stop_line is not None and time < legal.stop_until:
                stop = float(legal.stop_line - self.s[i])
                if stop < -0.5 * (spec.shape[0]):
                    stop = None  # already past the line
            limit = legal.speed_limit if legal.speed_limit is not None else self.road_speed_limit
            out.append(LegalCorridor(limit, legal.lateral_half_width, stop))
        return out


class Script:
    """The road users' scripts (``BehaviourSpec.events``): conditions checked in order.

    Event k of a road user is armed once event k - 1 has fired (the first at the road
    user's activation) and fires once, at the first behaviour tick where every
    condition of its ``when`` holds. Its ``do`` then replaces the road user's speed
    program (``longitudinal``: (t0, knots)) and/or its lateral program (``lateral``:
    (t0, knots)), both starting from the state at the event.

    Attributes:
        next: (k,) index of each road user's next event.
        armed_at: (k,) time the next event was armed [s] (inf before activation).
        fired: per road user, the times its events fired [s].
        longitudinal: per road user, the speed program set by its last speed action.
        lateral: per road user, the offset program set by its last lateral action.
    """

    def __init__(self, specs: Sequence[RoadUserSpec]) -> None:
        self.events = [u.behaviour.events for u in specs]
        k = len(self.events)
        self.next = np.zeros(k, dtype=np.int64)
        self.armed_at = np.full(k, math.inf)
        self.fired: list[list[float]] = [[] for _ in range(k)]
        self.longitudinal: list[tuple[float, tuple[tuple[float, float], ...]] | None] = [None] * k
        self.lateral: list[tuple[float, tuple[tuple[float, float], ...]] | None] = [None] * k
        self.index = {"ego": 0, **{u.name: i + 1 for i, u in enumerate(specs)}}
        self.needs_ego_s = any(e.when.needs_ego_s for events in self.events for e in events)

    def pending(self, i: int) -> bool:
        """True if road user ``i`` has an event left."""
        return self.next[i] < len(self.events[i])

    def advance(self, fleet: Fleet, i: int, view: WorldView) -> None:
        """Fire road user ``i``'s next event if its conditions hold at ``view.time``."""
        event = self.events[i][self.next[i]]
        if not self._holds(event.when, fleet, i, view):
            return
        t = view.time
        self._apply(event.do, fleet, i, t)
        self.fired[i].append(t)
        self.next[i] += 1
        self.armed_at[i] = t

    def _holds(self, when: ConditionSpec, fleet: Fleet, i: int, view: WorldView) -> bool:
        t = view.time
        if when.time is not None and t < when.time - 1e-9:
            return False
        if when.delay is not None and t - self.armed_at[i] < when.delay - 1e-9:
            return False
        me = i + 1
        if when.distance_below is not None or when.distance_above is not None or when.ttc_below is not None:
            j = self.index[when.to]
            distance = float(np.hypot(*(view.position[me] - view.position[j])))
            if when.distance_below is not None and not distance < when.distance_below:
                return False
            if when.distance_above is not None and not distance > when.distance_above:
                return False
            if when.ttc_below is not None and not _ttc(view, me, j, when.ttc_below) < when.ttc_below:
                return False
        j = me if when.of == "self" else self.index[when.of]
        s = view.ego_s if j == 0 else float(fleet.s[j - 1])
        if when.s_above is not None and not s > when.s_above:
            return False
        if when.s_below is not None and not s < when.s_below:
            return False
        speed = float(np.hypot(*view.velocity[j]))
        if when.speed_above is not None and not speed > when.speed_above:
            return False
        return when.speed_below is None or speed < when.speed_below

    def _apply(self, do: ActionSpec, fleet: Fleet, i: int, t: float) -> None:
        v0 = float(fleet.v[i])
        if do.speed is not None:
            target = do.speed
        elif do.stop:
            target = 0.0
        elif do.start:
            target = fleet.specs[i].behaviour.speed
        else:
            target = None
        if target is not None:
            ramp = abs(target - v0) / do.acceleration
            knots = ((0.0, v0), (ramp, target)) if ramp > 0 else ((0.0, target),)
            self.longitudinal[i] = (t, knots)
        elif do.speed_profile:
            profile = do.speed_profile
            self.longitudinal[i] = (t, profile if profile[0][0] == 0 else ((0.0, v0), *profile))
        d0 = float(fleet.d[i])
        if do.change_lane:
            self.lateral[i] = (t, ((0.0, d0), (do.duration, d0 + do.change_lane * fleet.lane_width)))
        elif do.lateral:
            lateral = do.lateral
            self.lateral[i] = (t, lateral if lateral[0][0] == 0 else ((0.0, d0), *lateral))


def _ttc(view: WorldView, a: int, b: int, horizon: float) -> float:
    """Constant-velocity time-to-collision [s] of bodies ``a`` and ``b`` (inf: none within horizon)."""
    states = np.column_stack([view.position, view.yaw, view.velocity, view.length, view.width])
    return float(time_to_collision(states[a], states[b][None, :], horizon + 1e-6)[0])


class BehaviourModel(Protocol):
    """How road users of one ``BehaviourKind`` decide their longitudinal acceleration.

    A new behaviour is one class registered in ``BEHAVIOURS`` under its kind's value
    (and its parameters in ``BehaviourSpec``). Models keep no state of their own: the
    ``Fleet`` holds the road users' states.

    Attributes:
        moves: False for a body that holds still (its speed is set to 0, no lateral
            profile).
    """

    moves: bool

    def prepare(self, fleet: Fleet, rows: np.ndarray, view: WorldView) -> Any:
        """Work shared by the active road users ``rows`` (k,) of this kind, vectorised."""
        ...

    def acceleration(self, fleet: Fleet, i: int, since: float, view: WorldView, context: Any) -> float:
        """Longitudinal acceleration [m/s^2] of road user ``i`` (``context`` from ``prepare``)."""
        ...


@runtime_checkable
class GivenMotion(Protocol):
    """A behaviour whose bodies' motion is given in advance (a recording), not decided.

    Besides ``BehaviourModel`` it builds, once per fleet, the state of its rows
    (``setup``) and answers, for all of them at once, where they should be
    (``references``, the tracking controller's references) and whether they exist
    (``presence``). The Fleet uses these instead of the route for its rows.
    """

    def setup(self, fleet: Fleet, rows: np.ndarray) -> Any:
        """The state of rows ``rows`` (m,) of this kind."""
        ...

    def references(self, state: Any, time: float) -> tuple[np.ndarray, ...]:
        """(p (m, 2), v (m, 2), a (m, 2), yaw (m,), yaw rate (m,)) at ``time`` [s]."""
        ...

    def presence(self, state: Any, time: float) -> np.ndarray:
        """(m,) bool: which of the rows exist at ``time`` [s]."""
        ...


#: Behaviour models by ``BehaviourKind`` value.
BEHAVIOURS: Registry[BehaviourModel] = Registry("behaviour")


class _Parked:
    """Holds its start pose with its brakes."""

    moves = False

    def prepare(self, fleet: Fleet, rows: np.ndarray, view: WorldView) -> None:
        return None

    def acceleration(self, fleet: Fleet, i: int, since: float, view: WorldView, context: Any) -> float:
        return 0.0


class _Scripted:
    """Follows its speed profile, blind to everything."""

    moves = True

    def prepare(self, fleet: Fleet, rows: np.ndarray, view: WorldView) -> None:
        return None

    def acceleration(self, fleet: Fleet, i: int, since: float, view: WorldView, context: Any) -> float:
        target = fleet.target_speed(i, since + fleet.tick if math.isfinite(since) else since)
        return float(np.clip((target - fleet.v[i]) / fleet.tick, -SCRIPTED_ACCEL_LIMIT, SCRIPTED_ACCEL_LIMIT))


class _IntelligentDriver:
    """Car following (intelligent driver model) behind the nearest body on its route."""

    moves = True

    def prepare(self, fleet: Fleet, rows: np.ndarray, view: WorldView) -> dict[int, _Leaders]:
        out: dict[int, _Leaders] = {}
        mobil = fleet.mobil[rows]
        keep = rows[~mobil]
        if keep.size:
            found = _leaders(fleet, keep, view)
            # A lane that ends (merge roads) is a standing obstacle for a road user in it.
            end_gap = fleet.route_lane_end[keep] - fleet.s[keep] - 0.5 * view.length[keep + 1]
            in_lane = np.abs(fleet.d[keep]) < 0.5 * fleet.lane_width
            lanes = []
            for gaps, speeds in found:
                end_first = in_lane & (end_gap < gaps)
                lanes += [np.where(end_first, end_gap, gaps), np.where(end_first, 0.0, speeds)]
            out.update(_leaders_by_row(keep, *lanes))
        if mobil.any():
            out.update(_leaders_by_row(rows[mobil], *_change_lanes(fleet, rows[mobil], view)))
        return out

    def acceleration(
        self, fleet: Fleet, i: int, since: float, view: WorldView, context: dict[int, _Leaders]
    ) -> float:
        """IDM acceleration behind its leader, blended over its reaction level r to the ego.

        ``(1 - r) a_blind + r a_seeing`` (``spec.reaction_level``): r = 0 and r = 1 give
        exactly the acceleration behind the nearest body other than the ego and behind
        the nearest body, the ego included; both clipped to the IDM's limits, the blend
        then delayed by ``idm.reaction_time``.
        """
        leaders = context[i]
        p = fleet.specs[i].behaviour.idm
        v = float(fleet.v[i])
        v0 = max(fleet.target_speed(i, since), 0.1)
        r = float(fleet.ego_reaction[i])
        if r == 0.0:
            acc = _idm_behind(p, v, v0, fleet.s[i], view, i, leaders.gap_blind, leaders.speed_blind)
        elif r == 1.0:
            acc = _idm_behind(p, v, v0, fleet.s[i], view, i, leaders.gap, leaders.speed)
        else:
            blind = _idm_behind(p, v, v0, fleet.s[i], view, i, leaders.gap_blind, leaders.speed_blind)
            seeing = _idm_behind(p, v, v0, fleet.s[i], view, i, leaders.gap, leaders.speed)
            acc = (1.0 - r) * blind + r * seeing
        queue = fleet.delay[i]
        if queue is not None:
            queue.append(acc)
            acc = queue.popleft()
        return acc


@dataclass(frozen=True, slots=True)
class _Leaders:
    """An idm road user's leader: seeing the ego (``gap``, ``speed``) and blind to it.

    Attributes:
        gap: [m] to the nearest body ahead, the ego included (inf: none).
        speed: its speed along the route [m/s].
        gap_blind, speed_blind: the same without the ego.
    """

    gap: float
    speed: float
    gap_blind: float
    speed_blind: float


def _leaders_by_row(
    rows: np.ndarray, gap_blind: np.ndarray, speed_blind: np.ndarray, gap: np.ndarray, speed: np.ndarray
) -> dict[int, _Leaders]:
    """``_Leaders`` of road users ``rows`` (m,) from (m,) arrays."""
    return {
        int(i): _Leaders(float(g), float(v), float(gb), float(vb))
        for i, gb, vb, g, v in zip(rows, gap_blind, speed_blind, gap, speed, strict=True)
    }


def _idm_behind(
    p: IdmSpec, v: float, v0: float, s: float, view: WorldView, i: int, gap: float, v_lead: float
) -> float:
    """IDM acceleration [m/s^2] of road user ``i`` at speed ``v`` behind a leader, clipped.

    Its stop line (``idm.stop_at``, while red and still stoppable) replaces the leader
    when nearer.
    """
    if p.stop_at is not None and view.time < p.stop_until:
        line_gap = p.stop_at - s - 0.5 * view.length[i + 1]
        if line_gap > v * v / (2.0 * p.max_deceleration) - 0.5 and line_gap < gap:
            gap, v_lead = max(line_gap, 0.0), 0.0
    free = 1.0 - (v / v0) ** 4
    if math.isfinite(gap):
        brake_term = v * (v - v_lead) / (2.0 * math.sqrt(p.max_acceleration * p.comfort_deceleration))
        s_star = p.min_gap + max(0.0, v * p.time_headway + brake_term)
        acc = p.max_acceleration * (free - (s_star / max(gap, 0.1)) ** 2)
    else:
        acc = p.max_acceleration * free
    return float(np.clip(acc, -p.max_deceleration, p.max_acceleration))


class _Pedestrian:
    """Walks to ``crossing.wait_at``, waits for a gap in the traffic, then crosses."""

    moves = True

    def prepare(self, fleet: Fleet, rows: np.ndarray, view: WorldView) -> None:
        return None

    def acceleration(self, fleet: Fleet, i: int, since: float, view: WorldView, context: Any) -> float:
        crossing = fleet.specs[i].behaviour.crossing
        v, s = float(fleet.v[i]), float(fleet.s[i])
        speed = fleet.target_speed(i, since)
        if not fleet.crossing[i] and s < crossing.wait_at + 0.05:
            if _gap_clear(i, view, crossing.gap_time, crossing.corridor) and s >= crossing.wait_at - 0.3:
                fleet.crossing[i] = True
            else:
                remaining = max(crossing.wait_at - s, 0.0)
                speed = min(speed, math.sqrt(2.0 * 1.0 * remaining))
        elif not fleet.crossing[i]:
            fleet.crossing[i] = True
        return float(np.clip((speed - v) / fleet.tick, -3.0, 1.5))


class _Recorded:
    """Follows its recorded trajectory (``behaviour.trajectory``), blind to everything."""

    moves = True

    def prepare(self, fleet: Fleet, rows: np.ndarray, view: WorldView) -> None:
        return None

    def acceleration(self, fleet: Fleet, i: int, since: float, view: WorldView, context: Any) -> float:
        return 0.0

    def setup(self, fleet: Fleet, rows: np.ndarray) -> RecordedTracks:
        return RecordedTracks([fleet.specs[i].behaviour.trajectory for i in rows])

    def references(self, state: RecordedTracks, time: float) -> tuple[np.ndarray, ...]:
        return state.sample(time)

    def presence(self, state: RecordedTracks, time: float) -> np.ndarray:
        return state.present(time)


BEHAVIOURS.register(BehaviourKind.SCRIPTED.value, _Scripted())
BEHAVIOURS.register(BehaviourKind.IDM.value, _IntelligentDriver())
BEHAVIOURS.register(BehaviourKind.PEDESTRIAN.value, _Pedestrian())
BEHAVIOURS.register(BehaviourKind.PARKED.value, _Parked())
BEHAVIOURS.register(BehaviourKind.RECORDED.value, _Recorded())


def _leaders(
    fleet: Fleet, rows: np.ndarray, view: WorldView
) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Gap [m] to and speed [m/s] of the nearest body ahead on the routes of ``rows``.

    Every other body is projected onto the first ``look_ahead`` metres of each
    route (sampled every metre, refined along the tangent); it leads if it
    overlaps the route's lane laterally. Vectorised over rows and bodies. Found
    twice: blind to the ego and seeing it (``Fleet.ego_reaction`` weighs the two).

    Returns:
        ((gap, speed) blind to the ego, (gap, speed) seeing it), each (m,); inf and
        0 where nothing is ahead.
    """
    m = len(rows)
    horizon = max(fleet.specs[i].behaviour.idm.look_ahead for i in rows)
    samples = np.arange(0.0, horizon + 1e-9, 1.0)
    n_s = samples.size
    x, y, theta, _ = fleet.routes.lookup(rows[:, None], fleet.s[rows, None] + samples[None, :])
    pos = view.position
    dx = pos[None, :, 0, None] - x[:, None, :]  # (m, n, n_s)
    dy = pos[None, :, 1, None] - y[:, None, :]
    nearest = np.argmin(dx * dx + dy * dy, axis=2)  # (m, n)
    dxn = np.take_along_axis(dx, nearest[..., None], axis=2)[..., 0]
    dyn = np.take_along_axis(dy, nearest[..., None], axis=2)[..., 0]
    heading = np.take_along_axis(theta, nearest, axis=1)
    c, s = np.cos(heading), np.sin(heading)
    lateral = np.abs(-dxn * s + dyn * c)
    rel = view.yaw[None, :] - heading
    length, width = view.length[None, :], view.width[None, :]
    # the footprints' half-extents along and across the route (in the route's frame)
    half_along = rectangle_half_extent(rel, length, width, 1.0, 0.0)
    half_across = rectangle_half_extent(rel, length, width, 0.0, 1.0)
    me = rows + 1
    along = samples[nearest] + dxn * c + dyn * s
    gap = along - 0.5 * view.length[me, None] - half_along
    limit = np.array([fleet.specs[i].behaviour.idm.look_ahead for i in rows])
    valid = (
        (lateral < 0.5 * view.width[me, None] + half_across + 0.3)
        & (nearest > 0)
        & (nearest < n_s - 1)
        & (samples[nearest] <= limit[:, None])
    )
    valid[np.arange(m), me] = False
    gap = np.where(valid, gap, np.inf)
    seeing = _nearest(gap, heading, view.velocity)
    gap[:, 0] = np.inf
    return _nearest(gap, heading, view.velocity), seeing


def _nearest(gap: np.ndarray, heading: np.ndarray, velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(gap [m], speed along the route [m/s]) of the nearest of n bodies for m road users.

    Args:
        gap: (m, n) gaps [m] (inf: not a leader). heading: (m, n) route heading at each
            body [rad]. velocity: (n, 2) [m/s].

    Returns:
        (gap, speed), each (m,); inf and 0 where no body leads.
    """
    m = gap.shape[0]
    j = np.argmin(gap, axis=1)
    best = gap[np.arange(m), j]
    vel = velocity[j]
    hj = heading[np.arange(m), j]
    speed = np.where(np.isfinite(best), vel[:, 0] * np.cos(hj) + vel[:, 1] * np.sin(hj), 0.0)
    return best, speed


@functools.lru_cache(maxsize=16)
def _followers(types: tuple[RoadUserType, ...]) -> np.ndarray:
    """(n,) bool: bodies that can be a MOBIL follower (every road user but pedestrians)."""
    mask = np.array([ty is not RoadUserType.PEDESTRIAN for ty in types], dtype=bool)
    mask.setflags(write=False)
    return mask


def _change_lanes(fleet: Fleet, rows: np.ndarray, view: WorldView) -> tuple[np.ndarray, ...]:
    """MOBIL for the road users ``rows`` (m,): start the lane changes it decides, return their leaders.

    Leaders and followers are read in the lanes the road user occupies and in those on
    either side (``mobil.lane_neighbours``: the ego is a body like any other); a
    road user that is not changing lane and whose cooldown is over changes if MOBIL
    says so (``mobil.mobil_decide``), with
    the scripts' smooth lateral move over ``mobil.duration``. Its IDM leader is the
    nearest one in any lane its footprint occupies: during a change the old and the
    target lane's, after it the target lane's.

    A road user's reaction level r to the ego (``Fleet.ego_reaction``) weighs the
    accelerations MOBIL compares: ``(1 - r)`` times those blind to the ego plus ``r``
    times those seeing it (``MobilAccelerations.blend``; neighbours found once if
    every r is 0 or 1).

    Returns:
        (gap_blind, speed_blind, gap, speed): each road user's leader blind to the ego
        and seeing it [m, m/s], each (m,); inf and 0: none.
    """
    t = view.time
    m = rows.size
    me = rows + 1
    w = fleet.lane_width
    look_ahead = np.array([fleet.specs[i].behaviour.idm.look_ahead for i in rows])
    samples = np.arange(-LOOK_BACK_M, float(look_ahead.max()) + 1e-9, 1.0)
    s_abs = np.maximum(fleet.s[rows, None] + samples[None, :], 0.0)
    x, y, theta, _ = fleet.routes.lookup(rows[:, None], s_abs)
    s_rel = s_abs - fleet.s[rows, None]
    n = view.position.shape[0]
    weight = fleet.ego_reaction[rows]
    sees = np.ones((m, n), dtype=bool)
    sees[:, 0] = weight > 0.0
    can_follow = _followers(view.types)
    current = np.rint(fleet.d[rows] / w).astype(np.int64)
    lane = fleet.route_lane[rows, None] + current[:, None] + SIDES[None, :]
    direction = fleet.direction[rows, None]
    half = 0.5 * view.length[me]
    lanes = fleet.lanes
    if lanes is not None:
        end_gap = lanes.end_of(lane, direction) - fleet.s[rows, None] - half[:, None]
        allowed = lanes.allowed(lane, direction)
    else:
        end_gap = np.full((m, 3), np.inf)
        allowed = np.ones((m, 3), dtype=bool)
    left_runs = allowed[:, 2].copy()
    nb = lane_neighbours(
        x, y, theta, s_rel, me, fleet.d[rows], w,
        view.position, view.velocity, view.yaw, view.length, view.width,
        can_follow, sees, end_gap,
    )  # fmt: skip
    partial = bool(np.any((weight > 0.0) & (weight < 1.0)))
    if partial:
        sees[:, 0] = False
        nb_blind = lane_neighbours(
            x, y, theta, s_rel, me, fleet.d[rows], w,
            view.position, view.velocity, view.yaw, view.length, view.width,
            can_follow, sees, end_gap,
        )  # fmt: skip
    params = fleet._mobil_params
    p = {name: values[rows] for name, values in params.items()}
    v = fleet.v[rows]
    # A lane is a target only if it runs the road user's way and does not end before the change is done.
    allowed &= end_gap > v[:, None] * p["duration"][:, None] + 5.0
    since = t - fleet.activated_at[rows]
    v0 = np.array([max(fleet.target_speed(int(i), float(a)), 0.1) for i, a in zip(rows, since, strict=True)])
    speeds = np.hypot(view.velocity[:, 0], view.velocity[:, 1])
    idm = fleet.idm_parameters(speeds, v0, rows)
    ready = (t >= fleet.mobil_busy_until[rows]) & np.isfinite(since) & fleet.active[rows]
    v_crit = p["pass_right_below"]
    rule = (left_runs, v_crit) if np.isfinite(v_crit).any() else (None, None)
    accelerations = mobil_accelerations(nb, me, v, idm, *rule)
    if partial:
        accelerations = mobil_accelerations(nb_blind, me, v, idm, *rule).blend(accelerations, weight)
    decision = mobil_decide(accelerations, allowed, p["politeness"], p["threshold"], p["b_safe"],
                            p["bias_right"], ready)  # fmt: skip
    for r in np.flatnonzero(decision.change):
        i = int(rows[r])
        d0 = float(fleet.d[i])
        target = float((current[r] + decision.change[r]) * w)
        duration = float(p["duration"][r])
        fleet.script.lateral[i] = (t, ((0.0, d0), (duration, target)))
        fleet.mobil_busy_until[i] = t + duration + float(p["cooldown"][r])
        start = int(fleet.route_lane[i] + current[r])
        fleet.lane_changes.append((t, i, start, start + int(decision.change[r])))
    # The leader: the nearest in any lane the road user's footprint occupies (both during a change).
    changing = decision.change != 0
    occupied = nb.occupied.copy()
    occupied[changing, 1 + decision.change[changing]] = True
    passing_rule = (idm, me, v, left_runs, v_crit) if rule[0] is not None else None
    seeing = _lane_leader(nb, occupied, passing_rule)
    return (*(_lane_leader(nb_blind, occupied, passing_rule) if partial else seeing), *seeing)


def _lane_leader(
    nb: Neighbours, occupied: np.ndarray, passing_rule: tuple | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(gap [m], speed [m/s]) of the leader m road users follow, each (m,).

    The nearest leader in the lanes ``occupied`` (m, 3); under the European passing rule
    (``passing_rule``: IDM parameters, body indices, speeds, whether the lane to the left
    runs its way, v_crit) the left lane's leader instead where it moves faster than
    v_crit and following it gives the lower IDM acceleration (``mobil.no_passing_on_the_right``).
    """
    m = occupied.shape[0]
    rows = np.arange(m)
    gaps = np.where(occupied, nb.lead_gap, np.inf)
    k = np.argmin(gaps, axis=1)
    gap = gaps[rows, k]
    speed = np.where(np.isfinite(gap), nb.lead_speed[rows, k], 0.0)
    if passing_rule is None:
        return gap, speed
    idm, me, v, left_runs, v_crit = passing_rule
    left_gap, left_speed = nb.lead_gap[:, 2], nb.lead_speed[:, 2]
    binds = (
        left_runs
        & (left_speed > v_crit)
        & (idm.acceleration(me, v, left_gap, left_speed) < idm.acceleration(me, v, gap, speed))
    )
    return np.where(binds, left_gap, gap), np.where(binds, left_speed, speed)


def _gap_clear(i: int, view: WorldView, gap_time: float, corridor: float) -> bool:
    me = i + 1
    pos = view.position
    rel = pos[me] - pos
    c, s = np.cos(view.yaw), np.sin(view.yaw)
    along = rel[:, 0] * c + rel[:, 1] * s
    across = -rel[:, 0] * s + rel[:, 1] * c
    speed = view.velocity[:, 0] * c + view.velocity[:, 1] * s
    vehicle = np.array([t is not RoadUserType.PEDESTRIAN for t in view.types])
    vehicle[me] = False
    approaching = vehicle & (speed > 0.5) & (along > -0.5 * view.length) & (np.abs(across) < corridor)
    time_to_arrive = (along - 0.5 * view.length) / np.maximum(speed, 0.5)
    return not bool(np.any(approaching & (time_to_arrive < gap_time)))
