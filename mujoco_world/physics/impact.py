"""Impact measurement from MuJoCo contact forces.

The physics is the ground truth the harm model only assumes. For every pair of
bodies (or a body and a wall) that touch, ``ImpactRecorder`` integrates the contact
forces of that pair over the contact episode:

* impulse J = sum F dt on each body (``mujoco.mj_contactForce`` in the contact
  frame, rotated to world with ``contact.frame``); delta-v = J / m,
* the change of the centre-of-mass velocity from the step before the first contact
  to the step after the last one (equal to J / m while no other force acts),
* the principal direction of force (where the force comes from, in the body frame,
  and its clock position), the force-weighted contact point in the body frame (its
  angle gives the impact area: reduced front/side/rear and the 12 clock areas),
* peak force, duration, deepest penetration and the restitution.

Usage without a planner: ``ImpactRig(body_a, body_b).launch(state_a, state_b)``
(or ``measure_impact``) launches two bodies at each other and returns one
``ImpactMeasurement``; the rig compiles its model once and is reused for sweeps.

Inside a running scene call ``recorder.before_step()`` and
``recorder.after_step()`` around every ``mj_step``; ``after_step`` returns the
episodes that ended (no force for ``separation_time``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from ethical_planner.harm import ReducedArea, clock_area, reduced_area
from ethical_planner.records import to_plain
from ethical_planner.road_users import KinematicState
from ethical_planner.validation import check, check_positive
from mujoco_world.physics.scene import NO_ENTITY, STATIC, BodyProxy, Scene
from mujoco_world.scenario.spec import ContactSpec

#: Contact-free time after which an episode is closed [s].
SEPARATION_TIME_S = 0.03
#: Longest crash pulse: bodies still in contact after this move on together [s].
MAX_PULSE_S = 0.4


def area_name(angle: float) -> str:
    """Reduced impact area of an angle in a body frame: front, driver_side, right_side, rear."""
    return ReducedArea(int(reduced_area(angle))).name.lower()


@dataclass(frozen=True, slots=True)
class BodyImpact:
    """What one body experienced in a collision (world frame unless stated).

    Attributes:
        entity: index of the body in the scene, or ``STATIC`` (-1) for a wall or kerb.
        name: body name. type: road-user type or the static kind ("wall", "kerb").
        mass: [kg]; inf for a static obstacle.
        position: centre before the impact [m], (x, y).
        yaw: heading before the impact [rad].
        velocity: velocity before the impact [m/s], (vx, vy).
        velocity_after: velocity after the contact episode [m/s].
        yaw_rate: yaw rate before the impact [rad/s].
        yaw_rate_after: yaw rate after the contact episode [rad/s].
        impulse: contact impulse received [N s], (Jx, Jy).
        delta_v_impulse: impulse / mass [m/s], (x, y).
        delta_v_com: change of the centre-of-mass velocity [m/s], (x, y).
        force_angle: principal direction of force in the body frame [rad]: the
            direction the force comes from (0 = from the front, +pi/2 = from the left).
        force_clock: clock position 1..12 of ``force_angle``.
        contact_point: force-weighted contact point in the body frame [m], (x fwd, y left).
        impact_angle: angle of ``contact_point`` [rad] in (-pi, pi].
        reduced_area: front, driver_side, right_side or rear, from ``impact_angle``.
        clock_area: 1..12 from ``impact_angle``.
    """

    entity: int
    name: str
    type: str
    mass: float
    position: tuple[float, float]
    yaw: float
    velocity: tuple[float, float]
    velocity_after: tuple[float, float]
    yaw_rate: float
    yaw_rate_after: float
    impulse: tuple[float, float]
    delta_v_impulse: tuple[float, float]
    delta_v_com: tuple[float, float]
    force_angle: float
    force_clock: int
    contact_point: tuple[float, float]
    impact_angle: float
    reduced_area: str
    clock_area: int

    @property
    def dv_impulse(self) -> float:
        """|delta-v| from the impulse [m/s]."""
        return float(math.hypot(*self.delta_v_impulse))

    @property
    def dv_com(self) -> float:
        """|delta-v| from the centre-of-mass velocity change [m/s]."""
        return float(math.hypot(*self.delta_v_com))

    @property
    def speed(self) -> float:
        """Speed before the impact [m/s]."""
        return float(math.hypot(*self.velocity))

    @property
    def is_static(self) -> bool:
        """True for walls and kerbs."""
        return self.entity == STATIC

    def kinematic_state(self) -> KinematicState:
        """Pre-impact state as the planner would see it (speed signed along the heading)."""
        v = float(np.dot(self.velocity, (math.cos(self.yaw), math.sin(self.yaw))))
        return KinematicState(self.position[0], self.position[1], self.yaw, v)


@dataclass(frozen=True, slots=True)
class ImpactMeasurement:
    """One collision event between two bodies, measured from the contact forces.

    Attributes:
        time: first contact [s].
        duration: first to last step with contact force [s].
        a: the first body (the lower entity index; the ego is entity 0).
        b: the second body, or the static obstacle.
        peak_force: largest magnitude of the pair's total contact force [N].
        impulse: |J| [N s].
        max_penetration: deepest geom overlap during the episode [m].
        restitution: relative separation speed / closing speed along the impulse.
        complete: False if the run ended before the bodies separated.
        multi_body: a third body touched a or b during the episode (the pair's
            prediction then misses forces).
        ended_in_contact: the bodies were still pressed together after ``max_duration``.
    """

    time: float
    duration: float
    a: BodyImpact
    b: BodyImpact
    peak_force: float
    impulse: float
    max_penetration: float
    restitution: float
    complete: bool = True
    multi_body: bool = False
    ended_in_contact: bool = False

    def to_dict(self) -> dict:
        """JSON-able dict of every field (infinite masses become "inf"; see ``records.to_plain``)."""
        return to_plain(self)


class _Episode:
    """Accumulators of one open contact episode."""

    __slots__ = (
        "a",
        "b",
        "t_start",
        "t_last",
        "pre_qpos_a",
        "pre_qvel_a",
        "pre_qpos_b",
        "pre_qvel_b",
        "post_qvel_a",
        "post_qvel_b",
        "impulse_b",
        "point_sum_a",
        "point_sum_b",
        "weight",
        "peak",
        "penetration",
        "multi_body",
        "ended_in_contact",
    )

    def __init__(self, a: int, b: int, t: float, prev_qpos: np.ndarray, prev_qvel: np.ndarray):
        self.a, self.b, self.t_start, self.t_last = a, b, t, t
        self.pre_qpos_a = prev_qpos[a].copy()
        self.pre_qvel_a = prev_qvel[a].copy()
        static = b == STATIC
        self.pre_qpos_b = np.zeros(3) if static else prev_qpos[b].copy()
        self.pre_qvel_b = np.zeros(3) if static else prev_qvel[b].copy()
        self.post_qvel_a = self.pre_qvel_a.copy()
        self.post_qvel_b = self.pre_qvel_b.copy()
        self.impulse_b = np.zeros(2)
        self.point_sum_a = np.zeros(2)
        self.point_sum_b = np.zeros(2)
        self.weight = 0.0
        self.peak = 0.0
        self.penetration = 0.0
        self.multi_body = False
        self.ended_in_contact = False


def _to_body_frame(point: np.ndarray, qpos: np.ndarray) -> np.ndarray:
    c, s = math.cos(qpos[2]), math.sin(qpos[2])
    dx, dy = point[0] - qpos[0], point[1] - qpos[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy])


class ImpactRecorder:
    """Tracks contact episodes in a ``Scene`` and measures each one.

    Call ``before_step`` and ``after_step`` around every physics step. Contacts are
    filtered by geom entity with numpy before ``mj_contactForce`` is called on the
    few that matter.

    An episode (the crash pulse of one pair) starts at the pair's first contact
    force and ends when the pair has been apart for ``separation_time`` or, if the
    bodies stay pressed together (they move on as one), ``max_duration`` after its
    start. After its pulse a pair is *resting* for ``rest_memory``: touches between
    braking bodies are ignored, only a contact force above ``new_impact_acceleration``
    times the lighter mass starts a new episode (a second hit, e.g. a chain collision).

    Attributes:
        scene: the scene observed.
        separation_time: contact-free time that closes an episode [s].
        max_duration: longest crash pulse [s].
        new_impact_acceleration: force / lighter mass that counts as a new hit of a
            resting pair [m/s^2].
        rest_memory: how long a pair counts as resting after its last contact [s].
        in_pulse: (n,) bool, bodies in an open episode (their brakes stay off).
        touched: (n,) bool, bodies that have had any contact force so far.
        max_penetration: deepest overlap seen so far [m].
    """

    def __init__(
        self,
        scene: Scene,
        separation_time: float = SEPARATION_TIME_S,
        max_duration: float = MAX_PULSE_S,
        new_impact_acceleration: float = 30.0,
        rest_memory: float = 1.0,
    ) -> None:
        check_positive(
            "ImpactRecorder",
            separation_time=separation_time,
            max_duration=max_duration,
            new_impact_acceleration=new_impact_acceleration,
            rest_memory=rest_memory,
        )
        self.scene = scene
        self.rest_memory = float(rest_memory)
        self.separation_time = float(separation_time)
        self.max_duration = float(max_duration)
        self.new_impact_acceleration = float(new_impact_acceleration)
        self._prev_qpos = scene.qpos.copy()
        self._prev_qvel = scene.qvel.copy()
        self._open: dict[tuple[int, int], _Episode] = {}
        self._resting: dict[tuple[int, int], float] = {}
        self._force = np.zeros(6)
        self.in_pulse = np.zeros(scene.n, dtype=bool)
        self.touched = np.zeros(scene.n, dtype=bool)
        self.max_penetration = 0.0

    @property
    def has_open_episodes(self) -> bool:
        """True while some pair is in (or just after) a crash pulse."""
        return bool(self._open)

    @property
    def busy(self) -> bool:
        """True while an episode is open or a pair rests in contact."""
        return bool(self._open or self._resting)

    def reset(self) -> None:
        """Forget all episodes (after ``Scene.reset``)."""
        self._open.clear()
        self._resting.clear()
        self.in_pulse[:] = False
        self.touched[:] = False
        self.max_penetration = 0.0

    def before_step(self) -> None:
        """Snapshot the state the coming step's contacts are computed from."""
        np.copyto(self._prev_qpos, self.scene.qpos)
        np.copyto(self._prev_qvel, self.scene.qvel)

    def after_step(self) -> list[ImpactMeasurement]:
        """Integrate the step's contact forces; return the episodes that ended."""
        scene = self.scene
        data = scene.data
        t = float(data.time) - scene.dt  # the forces acted during [t, t + dt]
        finished: list[ImpactMeasurement] = []
        if data.ncon:
            self._accumulate(t, finished)
        if not (self._open or self._resting):
            return finished
        gap = self.separation_time - 1e-12
        for key, episode in list(self._open.items()):
            if t - episode.t_last >= gap:
                finished.append(self._finish(episode, complete=True))
                del self._open[key]
                self._resting[key] = episode.t_last
        for key, last in list(self._resting.items()):
            if t - last >= self.rest_memory:
                del self._resting[key]
        self.in_pulse[:] = False
        for a, b in self._open:
            self.in_pulse[a] = True
            if b != STATIC:
                self.in_pulse[b] = True
        return finished

    def finish(self, complete: bool = False) -> list[ImpactMeasurement]:
        """Close every open episode (end of a run).

        Args:
            complete: mark them complete (e.g. the bodies have come to rest).
        """
        finished = [self._finish(ep, complete=complete) for ep in self._open.values()]
        self._open.clear()
        self._resting.clear()
        self.in_pulse[:] = False
        return finished

    def _accumulate(self, t: float, finished: list[ImpactMeasurement]) -> None:
        scene, data = self.scene, self.scene.data
        contact = data.contact
        e1 = scene.geom_entity[contact.geom1]
        e2 = scene.geom_entity[contact.geom2]
        keep = (contact.efc_address >= 0) & (e1 != e2) & (e1 != NO_ENTITY) & (e2 != NO_ENTITY)
        index = np.flatnonzero(keep)
        if index.size == 0:
            return
        e1, e2 = e1[index], e2[index]
        forces = np.empty((index.size, 3))
        for k, i in enumerate(index):
            mujoco.mj_contactForce(scene.model, data, int(i), self._force)
            forces[k] = self._force[:3]
        frames = contact.frame[index].reshape(-1, 3, 3)
        # The contact frame's rows are its axes; the force acts on geom2 (normal from 1 to 2).
        world = np.einsum("ki,kij->kj", forces, frames)[:, :2]
        points = contact.pos[index, :2]
        depth = -contact.dist[index]
        # Order each pair as (body, higher body) or (body, STATIC); force on b.
        swap = (e1 == STATIC) | ((e2 != STATIC) & (e2 < e1))
        a = np.where(swap, e2, e1)
        b = np.where(swap, e1, e2)
        force_b = np.where(swap[:, None], -world, world)
        magnitude = np.hypot(world[:, 0], world[:, 1])
        self.max_penetration = max(self.max_penetration, float(depth.max()))
        dt = scene.dt
        pairs = sorted({(int(x), int(y)) for x, y in zip(a, b, strict=True)})
        partners = np.zeros(scene.n, dtype=np.int64)
        for pa, pb in pairs:
            partners[pa] += 1
            if pb != STATIC:
                partners[pb] += 1
        masses = scene.masses
        for pair in pairs:
            rows = (a == pair[0]) & (b == pair[1])
            weights = magnitude[rows]
            weight_sum = float(weights.sum())
            if weight_sum <= 0.0:
                continue
            total = force_b[rows].sum(axis=0)
            force = float(np.hypot(*total))
            episode = self._open.get(pair)
            if episode is None:
                if pair in self._resting:
                    lighter = masses[pair[0]] if pair[1] == STATIC else min(masses[pair[0]], masses[pair[1]])
                    if force < self.new_impact_acceleration * lighter:
                        self._resting[pair] = t
                        continue
                    del self._resting[pair]
                episode = _Episode(pair[0], pair[1], t, self._prev_qpos, self._prev_qvel)
                self._open[pair] = episode
            episode.t_last = t
            episode.impulse_b += total * dt
            point = (weights[:, None] * points[rows]).sum(axis=0) / weight_sum
            w = weight_sum * dt
            episode.point_sum_a += w * _to_body_frame(point, self._prev_qpos[pair[0]])
            if pair[1] != STATIC:
                episode.point_sum_b += w * _to_body_frame(point, self._prev_qpos[pair[1]])
                episode.post_qvel_b = scene.qvel[pair[1]].copy()
                self.touched[pair[1]] = True
                episode.multi_body |= bool(partners[pair[1]] > 1)
            episode.post_qvel_a = scene.qvel[pair[0]].copy()
            self.touched[pair[0]] = True
            episode.multi_body |= bool(partners[pair[0]] > 1)
            episode.weight += w
            episode.peak = max(episode.peak, force)
            episode.penetration = max(episode.penetration, float(depth[rows].max()))
            if t - episode.t_start >= self.max_duration - 1e-12:
                # Still pressed together: the pulse is over, the pair now rests in contact.
                episode.ended_in_contact = True
                finished.append(self._finish(episode, complete=True))
                del self._open[pair]
                self._resting[pair] = t

    def _body(
        self,
        entity: int,
        qpos: np.ndarray,
        qvel: np.ndarray,
        qvel_after: np.ndarray,
        impulse: np.ndarray,
        point_sum: np.ndarray,
        weight: float,
    ) -> BodyImpact:
        scene = self.scene
        yaw = float(qpos[2])
        if entity == STATIC:
            name, kind, mass = "static", scene.static_kind, math.inf
            dv_impulse = np.zeros(2)
        else:
            name, kind = scene.names[entity], scene.types[entity].value
            mass = float(scene.masses[entity])
            dv_impulse = impulse / mass
        # Direction the force comes from (opposite to the impulse), in the body frame.
        source = _to_body_frame(-impulse, np.array([0.0, 0.0, yaw]))
        force_angle = float(math.atan2(source[1], source[0])) if np.any(source) else 0.0
        point = point_sum / weight if weight > 0 else np.zeros(2)
        impact_angle = float(math.atan2(point[1], point[0]))
        return BodyImpact(
            entity=int(entity),
            name=name,
            type=kind,
            mass=mass,
            position=(float(qpos[0]), float(qpos[1])),
            yaw=yaw,
            velocity=(float(qvel[0]), float(qvel[1])),
            velocity_after=(float(qvel_after[0]), float(qvel_after[1])),
            yaw_rate=float(qvel[2]),
            yaw_rate_after=float(qvel_after[2]),
            impulse=(float(impulse[0]), float(impulse[1])),
            delta_v_impulse=(float(dv_impulse[0]), float(dv_impulse[1])),
            delta_v_com=(float(qvel_after[0] - qvel[0]), float(qvel_after[1] - qvel[1])),
            force_angle=force_angle,
            force_clock=int(clock_area(force_angle)),
            contact_point=(float(point[0]), float(point[1])),
            impact_angle=impact_angle,
            reduced_area=area_name(impact_angle),
            clock_area=int(clock_area(impact_angle)),
        )

    def _finish(self, ep: _Episode, complete: bool) -> ImpactMeasurement:
        impulse_b = ep.impulse_b
        body_a = self._body(
            ep.a, ep.pre_qpos_a, ep.pre_qvel_a, ep.post_qvel_a, -impulse_b, ep.point_sum_a, ep.weight
        )
        body_b = self._body(
            ep.b, ep.pre_qpos_b, ep.pre_qvel_b, ep.post_qvel_b, impulse_b, ep.point_sum_b, ep.weight
        )
        magnitude = float(np.hypot(*impulse_b))
        restitution = math.nan
        if magnitude > 0:
            n = impulse_b / magnitude  # pushes b away from a
            closing = float(np.dot(ep.pre_qvel_a[:2] - ep.pre_qvel_b[:2], n))
            separating = float(np.dot(ep.post_qvel_b[:2] - ep.post_qvel_a[:2], n))
            if closing > 1e-6:
                restitution = separating / closing
        return ImpactMeasurement(
            time=ep.t_start,
            duration=ep.t_last - ep.t_start + self.scene.dt,
            a=body_a,
            b=body_b,
            peak_force=ep.peak,
            impulse=magnitude,
            max_penetration=ep.penetration,
            restitution=restitution,
            complete=complete,
            multi_body=ep.multi_body,
            ended_in_contact=ep.ended_in_contact,
        )


def _state_velocity(state: KinematicState) -> tuple[float, float]:
    return state.v * math.cos(state.yaw), state.v * math.sin(state.yaw)


class ImpactRig:
    """Two free bodies launched at each other in an empty scene.

    The model is compiled once; every ``launch`` resets the data, so one rig serves
    thousands of controlled impacts. No actuator acts: the bodies coast, so the
    centre-of-mass and impulse delta-v agree.

    Args:
        body_a: first proxy (``BodyProxy.of_type("car", "car")`` etc.).
        body_b: second proxy.
        contact: contact model (defaults: near-plastic, solref "0.05 4").
        timestep: physics step [s].
    """

    def __init__(
        self,
        body_a: BodyProxy,
        body_b: BodyProxy,
        contact: ContactSpec | None = None,
        timestep: float = 0.001,
    ) -> None:
        check(body_a.name != body_b.name, "ImpactRig bodies need different names")
        self.scene = Scene([body_a, body_b], contact=contact, timestep=timestep)
        self.recorder = ImpactRecorder(self.scene)

    def launch(
        self,
        state_a: KinematicState,
        state_b: KinematicState,
        max_time: float = 3.0,
        velocity_a: tuple[float, float] | None = None,
        velocity_b: tuple[float, float] | None = None,
    ) -> ImpactMeasurement | None:
        """Place both bodies, let them coast and measure their first contact episode.

        Args:
            state_a: pose and speed of body a (velocity along its heading unless
                ``velocity_a`` is given).
            state_b: pose and speed of body b.
            max_time: give up after this time [s] if they never touch.
            velocity_a: explicit velocity of a [m/s], (vx, vy), e.g. a skidding car.
            velocity_b: explicit velocity of b [m/s].

        Returns:
            The measurement, or None if the bodies did not touch within ``max_time``.

        Raises:
            ValueError: the bodies overlap at the start.
        """
        scene, recorder = self.scene, self.recorder
        scene.reset()
        recorder.reset()
        va = velocity_a if velocity_a is not None else _state_velocity(state_a)
        vb = velocity_b if velocity_b is not None else _state_velocity(state_b)
        scene.set_states(
            np.array([state_a.x, state_b.x]),
            np.array([state_a.y, state_b.y]),
            np.array([state_a.yaw, state_b.yaw]),
            np.array([va[0], vb[0]]),
            np.array([va[1], vb[1]]),
            np.array([state_a.yaw_rate, state_b.yaw_rate]),
        )
        if scene.data.ncon:
            raise ValueError("ImpactRig.launch: the bodies overlap at the start")
        n_steps = int(math.ceil(max_time / scene.dt))
        for _ in range(n_steps):
            recorder.before_step()
            scene.step()
            done = recorder.after_step()
            if done:
                return done[0]
        leftover = recorder.finish()
        return leftover[0] if leftover else None


def measure_impact(
    type_a: str,
    state_a: KinematicState,
    type_b: str,
    state_b: KinematicState,
    contact: ContactSpec | None = None,
    shape_a: tuple[float, float] | None = None,
    shape_b: tuple[float, float] | None = None,
    mass_a: float | None = None,
    mass_b: float | None = None,
) -> ImpactMeasurement | None:
    """Launch two road-user proxies at each other once and measure the impact.

    Convenience wrapper of ``ImpactRig``; build a rig yourself for sweeps.

    Args:
        type_a: road-user type of body a ("car", "pedestrian", ...).
        state_a: its pose and speed.
        type_b: type of body b.
        state_b: its pose and speed.
        contact: contact model.
        shape_a: (length, width) [m] of a; default shape of the type if None.
        shape_b: (length, width) [m] of b.
        mass_a: [kg]; SPEC mass if None.
        mass_b: [kg].
    """
    la, wa = shape_a if shape_a is not None else (None, None)
    lb, wb = shape_b if shape_b is not None else (None, None)
    rig = ImpactRig(
        BodyProxy.of_type("a", type_a, la, wa, mass_a),
        BodyProxy.of_type("b", type_b, lb, wb, mass_b),
        contact=contact,
    )
    return rig.launch(state_a, state_b)
