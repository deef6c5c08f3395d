"""Impact measurement from MuJoCo contact forces.

The physics is the ground truth the harm model only assumes. For every pair of bodies
(or a body and a wall) that touch, ``ImpactRecorder`` integrates the contact forces of
that pair (``mujoco.mj_contactForce`` in the contact frame, rotated to world with
``contact.frame``, and the rigid mode's Coulomb friction) over the pair's **impact sequence**.

The measurement window (``MeasurementWindow``; issue 15 keeps controllers on outside it):

* A **sequence** starts at the pair's first contact force and stays open until the pair
  has had no contact force for ``separation_time`` (0.5 s, long against a rigid pulse of
  ~4 ms and a crush pulse of ~0.1 s), so secondary hits of a spinning body (a glancing
  front hit followed by a side slap) belong to it. Bodies still pressed together
  ``max_duration`` (2 s) after the start close it as ``ended_in_contact``.
* An **impulse** (pulse) is a run of contact force without a gap of ``pulse_gap``
  (10 ms). ``ImpactRecorder.in_pulse`` marks the bodies inside one right now: outside
  it no contact force acts on a body, so its own controller does not touch the
  measured impulse.
* An **impact** is the high-force part of a pulse: ``ImpactRecorder.in_impact`` marks
  the bodies that received a contact force above ``impact_acceleration`` times their
  mass within the last ``impact_hold`` (2 ms). The world cuts the controllers there only: a rigid
  impact carries tens of g, a scrape along a wall or a car its controller presses
  against one carries about the tyre force (mu m g), and the controller keeps braking
  and steering through it. ``dv_impulse`` integrates contact forces only, so it excludes
  the controller's force whether the controller is on or not.

Per sequence and body:

* impulse J = sum F dt over the sequence (contact forces as measured by
  ``physics.contact.measure_contact_forces``, plus the Coulomb friction the rigid mode
  applies), delta-v = |J| / m (``dv_impulse``), and the first impulse's delta-v separately
  (``dv_first``); the centre-of-mass velocity change over the sequence (``dv_com``; equal to
  J / m while no other force acts, as in the rig);
* the principal direction of force: the sequence's impulse in the body frame at the
  impulse-weighted moment (the body's impulse-weighted yaw; a struck body may spin 90 deg
  during a sequence), with its clock position;
* the force-weighted contact point in the body frame (each step's point in that step's
  body frame) with its reduced and clock impact area.

Per sequence: peak force and when it came, the impulses' sizes and times (``multi_impact``
when later impulses carry more than ``MULTI_IMPACT_SHARE`` of the total), the deepest
penetration, and the first impulse's **restitution at the contact point along the contact
normal**: -(u_n after) / (u_n before), u the velocity of b's material point at the
force-weighted contact point relative to a's, n the force-weighted contact normal.

Usage without a planner: ``ImpactRig(body_a, body_b).launch(state_a, state_b)`` (or
``measure_impact``) launches two bodies at each other and returns one
``ImpactMeasurement``; the rig compiles its model once and is reused for sweeps. Inside a
scene, pass the recorder to ``Scene.step(recorder)``: it is called around every physics
(sub-)step and ``Scene.step`` returns the sequences that closed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ethical_planner.harm import ReducedArea, clock_area, reduced_area
from ethical_planner.impulse import SkidModel
from ethical_planner.records import to_plain
from ethical_planner.road_users import KinematicState
from ethical_planner.validation import check, check_positive
from mujoco_world.physics.control import GRAVITY, ControlConfig, brake_forces
from mujoco_world.physics.scene import STATIC, BodyProxy, Scene
from mujoco_world.scenario.spec import ContactSpec

#: Share of the summed impulse magnitudes carried by impulses after the first above
#: which a sequence is flagged ``multi_impact``.
MULTI_IMPACT_SHARE = 0.05

#: Contact acceleration [m/s^2] above which a body is in an impact (the controller cut):
#: 30 m/s^2, 3.4 mu g with the tyre friction mu = 0.9, held ``impact_hold`` (2 ms) to
#: bridge dips inside one pulse. Measured on the ego (seed 0, ``mujoco_world/README.md``,
#: "Control after contact"): rigid impacts peak at 53 mu m g (a child), 220 (the wall at
#: 10.9 m/s), 282 (a car); pushing a wreck or sliding along a wall carries 1-5 mu m g.
IMPACT_ACCELERATION = 30.0


@dataclass(frozen=True, slots=True)
class MeasurementWindow:
    """When an impact sequence and its impulses start and end (see the module docstring).

    Attributes:
        pulse_gap: contact-force-free time that ends an impulse [s].
        separation_time: contact-force-free time that closes a sequence [s].
        max_duration: longest sequence; bodies still pressed together then move on as one [s].
        new_impact_acceleration: after a sequence, a contact force above this times the
            lighter mass starts a new one; gentler touches of the resting pair are ignored [m/s^2].
        rest_memory: how long a closed pair counts as resting after its last contact [s].
        impact_acceleration: a contact force above this times a body's mass puts the
            body in an impact (``ImpactRecorder.in_impact``) [m/s^2].
        impact_hold: how long a body stays in an impact after such a force [s].
    """

    pulse_gap: float = 0.01
    separation_time: float = 0.5
    max_duration: float = 2.0
    new_impact_acceleration: float = 30.0
    rest_memory: float = 1.0
    impact_acceleration: float = IMPACT_ACCELERATION
    impact_hold: float = 0.002

    def __post_init__(self) -> None:
        check_positive(
            "window",
            pulse_gap=self.pulse_gap,
            separation_time=self.separation_time,
            max_duration=self.max_duration,
            new_impact_acceleration=self.new_impact_acceleration,
            rest_memory=self.rest_memory,
            impact_acceleration=self.impact_acceleration,
            impact_hold=self.impact_hold,
        )
        check(self.pulse_gap <= self.separation_time, "window.pulse_gap must be <= window.separation_time")
        check(self.impact_hold <= self.pulse_gap, "window.impact_hold must be <= window.pulse_gap")


def area_name(angle: float) -> str:
    """Reduced impact area of an angle in a body frame: front, driver_side, right_side, rear."""
    return ReducedArea(int(reduced_area(angle))).name.lower()


@dataclass(frozen=True, slots=True)
class BodyImpact:
    """What one body experienced in an impact sequence (world frame unless stated).

    Attributes:
        entity: index of the body in the scene, or ``STATIC`` (-1) for a wall or kerb.
        name: body name. type: road-user type or the static kind ("wall", "kerb").
        mass: [kg]; inf for a static obstacle.
        length: footprint length [m] (nan for a static obstacle).
        width: footprint width [m] (nan for a static obstacle).
        position: centre before the impact [m], (x, y).
        yaw: heading before the impact [rad].
        velocity: velocity before the impact [m/s], (vx, vy).
        velocity_after: velocity after the sequence's last contact [m/s].
        yaw_rate: yaw rate before the impact [rad/s].
        yaw_rate_after: yaw rate after the sequence's last contact [rad/s].
        impulse: contact impulse received over the sequence [N s], (Jx, Jy).
        delta_v_impulse: impulse / mass [m/s], (x, y).
        delta_v_first: the first impulse / mass [m/s], (x, y).
        delta_v_com: change of the centre-of-mass velocity from before the first to after the
            last contact [m/s], (x, y) (includes other forces acting meanwhile, e.g. braking).
        force_angle: principal direction of force in the body frame at the impulse-weighted
            moment [rad]: where the force comes from (0 = the front, +pi/2 = the left).
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
    length: float
    width: float
    position: tuple[float, float]
    yaw: float
    velocity: tuple[float, float]
    velocity_after: tuple[float, float]
    yaw_rate: float
    yaw_rate_after: float
    impulse: tuple[float, float]
    delta_v_impulse: tuple[float, float]
    delta_v_first: tuple[float, float]
    delta_v_com: tuple[float, float]
    force_angle: float
    force_clock: int
    contact_point: tuple[float, float]
    impact_angle: float
    reduced_area: str
    clock_area: int

    @property
    def dv_impulse(self) -> float:
        """|delta-v| over the whole sequence, from the impulse [m/s]."""
        return float(math.hypot(*self.delta_v_impulse))

    @property
    def dv_first(self) -> float:
        """|delta-v| of the first impulse [m/s]."""
        return float(math.hypot(*self.delta_v_first))

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
    """One impact sequence between two bodies, measured from the contact forces.

    Attributes:
        time: first contact [s].
        duration: first to last step with contact force [s].
        a: the first body (the lower entity index; the ego is entity 0).
        b: the second body, or the static obstacle.
        peak_force: largest magnitude of the pair's total contact force [N].
        peak_time: when it came, after ``time`` [s].
        impulse: |J| over the sequence [N s].
        impulses: |J| of every impulse of the sequence, in order [N s].
        impulse_times: (start, end) of every impulse, after ``time`` [s].
        max_penetration: deepest geom overlap during the sequence [m].
        restitution: of the first impulse, at the contact point along the contact normal
            (nan if the bodies did not approach there).
        contact_normal: force-weighted normal of the first impulse, from a to b (world).
        contact_position: force-weighted contact point of the first impulse [m] (world).
        complete: False if the run ended before the bodies separated.
        multi_body: a third body touched a or b during the sequence (the pair's
            prediction then misses forces).
        ended_in_contact: the bodies were still pressed together after ``max_duration``.
    """

    time: float
    duration: float
    a: BodyImpact
    b: BodyImpact
    peak_force: float
    peak_time: float
    impulse: float
    impulses: tuple[float, ...]
    impulse_times: tuple[tuple[float, float], ...]
    max_penetration: float
    restitution: float
    contact_normal: tuple[float, float]
    contact_position: tuple[float, float]
    complete: bool = True
    multi_body: bool = False
    ended_in_contact: bool = False

    @property
    def n_impulses(self) -> int:
        """Number of impulses in the sequence."""
        return len(self.impulses)

    @property
    def first_impulse_share(self) -> float:
        """|J| of the first impulse over the summed |J| of all impulses."""
        total = sum(self.impulses)
        return self.impulses[0] / total if total > 0 else 1.0

    @property
    def multi_impact(self) -> bool:
        """Later impulses carry more than ``MULTI_IMPACT_SHARE`` of the summed impulse."""
        return 1.0 - self.first_impulse_share > MULTI_IMPACT_SHARE

    def to_dict(self) -> dict:
        """JSON-able dict of every field (infinite masses become "inf"; see ``records.to_plain``)."""
        return to_plain(self)


class _Sequence:
    """Accumulators of one open impact sequence."""

    __slots__ = (
        "a", "b", "t_start", "t_last", "pre_qpos", "pre_qvel", "post_qpos", "post_qvel",
        "impulse_b", "impulses", "first_point", "first_normal", "first_weight", "first_post_qpos",
        "first_post_qvel", "point_sum", "yaw_sum", "weight", "force_weight", "peak", "peak_time",
        "penetration",
        "multi_body", "ended_in_contact",
    )  # fmt: skip

    def __init__(self, a: int, b: int, t: float, prev_qpos: np.ndarray, prev_qvel: np.ndarray):
        self.a, self.b, self.t_start, self.t_last = a, b, t, t
        static = b == STATIC
        self.pre_qpos = np.array([prev_qpos[a], np.zeros(3) if static else prev_qpos[b]])
        self.pre_qvel = np.array([prev_qvel[a], np.zeros(3) if static else prev_qvel[b]])
        self.post_qpos = self.pre_qpos.copy()
        self.post_qvel = self.pre_qvel.copy()
        self.impulse_b = np.zeros(2)
        # One row per impulse: Jx, Jy (on b), start, end.
        self.impulses: list[list[float]] = []
        self.first_point = np.zeros(2)
        self.first_normal = np.zeros(2)
        self.first_weight = 0.0
        self.first_post_qpos = self.pre_qpos.copy()
        self.first_post_qvel = self.pre_qvel.copy()
        self.point_sum = np.zeros((2, 2))  # per body, in the body frame
        self.yaw_sum = np.zeros(2)  # per body, yaw change since the start, force-weighted
        self.weight = 0.0
        self.force_weight = 0.0
        self.peak = 0.0
        self.peak_time = 0.0
        self.penetration = 0.0
        self.multi_body = False
        self.ended_in_contact = False


def _to_body_frame(point: np.ndarray, qpos: np.ndarray) -> np.ndarray:
    c, s = math.cos(qpos[2]), math.sin(qpos[2])
    dx, dy = point[0] - qpos[0], point[1] - qpos[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy])


def _rotate_into(vector: np.ndarray, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([c * vector[0] + s * vector[1], -s * vector[0] + c * vector[1]])


def _wrap(angle: float) -> float:
    return math.remainder(angle, 2.0 * math.pi)


def _point_velocity(qpos: np.ndarray, qvel: np.ndarray, point: np.ndarray) -> np.ndarray:
    rx, ry = point[0] - qpos[0], point[1] - qpos[1]
    return np.array([qvel[0] - qvel[2] * ry, qvel[1] + qvel[2] * rx])


class ImpactRecorder:
    """Tracks impact sequences in a ``Scene`` and measures each one.

    Pass it to ``Scene.step`` (or call ``before_step`` and ``after_step`` around every
    physics step yourself). Contacts are filtered by geom entity with numpy before
    ``mj_contactForce`` is called on the few that matter. After a sequence closes, its
    pair *rests* for ``window.rest_memory``: touches between braking bodies are ignored,
    only a contact force above ``window.new_impact_acceleration`` times the lighter mass
    starts a new sequence (a second hit, e.g. a chain collision).

    Attributes:
        scene: the scene observed.
        window: the measurement window.
        in_pulse: (n,) bool, bodies inside an impulse (contact force within ``pulse_gap``).
        in_impact: (n,) bool, bodies inside an impact: a contact force above
            ``window.impact_acceleration`` times their mass within ``window.impact_hold``
            (a subset of ``in_pulse`` while ``impact_hold <= pulse_gap``).
        in_sequence: (n,) bool, bodies in an open sequence.
        touched: (n,) bool, bodies that have had any contact force so far.
        max_penetration: deepest overlap seen so far [m].
        trace: if True, ``traces`` keeps every sequence's force history.
        traces: (a, b, start time) -> array of rows (t [s], Fx, Fy on b [N], depth [m],
            yaw of a, yaw of b [rad] after the step).
    """

    def __init__(self, scene: Scene, window: MeasurementWindow | None = None, trace: bool = False) -> None:
        self.scene = scene
        self.window = window or MeasurementWindow()
        self.trace = bool(trace)
        self.traces: dict[tuple[int, int, float], np.ndarray] = {}
        self._rows: dict[tuple[int, int], list[tuple[float, ...]]] = {}
        self._prev_qpos = scene.qpos.copy()
        self._prev_qvel = scene.qvel.copy()
        self._dt = scene.dt
        self._open: dict[tuple[int, int], _Sequence] = {}
        self._resting: dict[tuple[int, int], float] = {}
        self.in_pulse = np.zeros(scene.n, dtype=bool)
        self.in_impact = np.zeros(scene.n, dtype=bool)
        self._t_impact = np.full(scene.n, -np.inf)  # last time of an impact force per body [s]
        self._impacts = False  # some body may be in an impact
        self.in_sequence = np.zeros(scene.n, dtype=bool)
        self.touched = np.zeros(scene.n, dtype=bool)
        self.max_penetration = 0.0

    @property
    def has_open_episodes(self) -> bool:
        """True while some pair is in an open impact sequence."""
        return bool(self._open)

    @property
    def busy(self) -> bool:
        """True while a sequence is open or a pair rests after one."""
        return bool(self._open or self._resting)

    def reset(self) -> None:
        """Forget all sequences (after ``Scene.reset``)."""
        self._open.clear()
        self._resting.clear()
        self._rows.clear()
        self.traces.clear()
        self.in_pulse[:] = False
        self.in_sequence[:] = False
        self._clear_impacts()
        self.touched[:] = False
        self.max_penetration = 0.0

    def _clear_impacts(self) -> None:
        self.in_impact[:] = False
        self._t_impact[:] = -np.inf
        self._impacts = False

    def before_step(self) -> None:
        """Snapshot the state the coming step's contacts are computed from."""
        np.copyto(self._prev_qpos, self.scene.qpos)
        np.copyto(self._prev_qvel, self.scene.qvel)
        self._dt = float(self.scene.model.opt.timestep)

    def after_step(self) -> list[ImpactMeasurement]:
        """Integrate the step's contact forces; return the sequences that closed."""
        scene = self.scene
        data = scene.data
        t = float(data.time) - self._dt  # the forces acted during [t, t + dt]
        finished: list[ImpactMeasurement] = []
        if scene.dynamics.forces.size:
            self._accumulate(t, finished)
        if self._impacts:
            np.less(t - self._t_impact, self.window.impact_hold, out=self.in_impact)
            self._impacts = bool(self.in_impact.any())
        if not (self._open or self._resting):
            return finished
        window = self.window
        for key, seq in list(self._open.items()):
            if t - seq.t_last >= window.separation_time - 1e-12:
                finished.append(self._finish(seq, complete=True))
                del self._open[key]
                self._resting[key] = seq.t_last
        for key, last in list(self._resting.items()):
            if t - last >= window.rest_memory:
                del self._resting[key]
        self.in_pulse[:] = False
        self.in_sequence[:] = False
        for (a, b), seq in self._open.items():
            pulsing = t - seq.t_last < window.pulse_gap
            for x in (a, b):
                if x != STATIC:
                    self.in_sequence[x] = True
                    self.in_pulse[x] |= pulsing
        return finished

    def finish(self, complete: bool = False) -> list[ImpactMeasurement]:
        """Close every open sequence (end of a run).

        Args:
            complete: mark them complete (e.g. the bodies have come to rest).
        """
        finished = [self._finish(seq, complete=complete) for seq in self._open.values()]
        self._open.clear()
        self._resting.clear()
        self.in_pulse[:] = False
        self.in_sequence[:] = False
        self._clear_impacts()
        return finished

    def _accumulate(self, t: float, finished: list[ImpactMeasurement]) -> None:
        scene = self.scene
        forces = scene.dynamics.forces
        if forces.size == 0:
            return
        a, b = forces.a, forces.b
        force_b = forces.force_b
        magnitude = np.hypot(force_b[:, 0], force_b[:, 1])
        depth = forces.depth
        self.max_penetration = max(self.max_penetration, float(depth.max()))
        dt = self._dt
        pairs = sorted({(int(x), int(y)) for x, y in zip(a, b, strict=True)})
        partners = np.zeros(scene.n, dtype=np.int64)
        for pa, pb in pairs:
            partners[pa] += 1
            if pb != STATIC:
                partners[pb] += 1
        masses = scene.masses
        window = self.window
        for pair in pairs:
            rows = (a == pair[0]) & (b == pair[1])
            weights = magnitude[rows]
            weight_sum = float(weights.sum())
            if weight_sum <= 0.0:
                continue
            total = force_b[rows].sum(axis=0)
            force = float(np.hypot(*total))
            self._mark_impact(pair, force, t)
            seq = self._open.get(pair)
            if seq is None:
                if pair in self._resting:
                    lighter = masses[pair[0]] if pair[1] == STATIC else min(masses[pair[0]], masses[pair[1]])
                    if force < window.new_impact_acceleration * lighter:
                        self._resting[pair] = t
                        continue
                    del self._resting[pair]
                seq = _Sequence(pair[0], pair[1], t, self._prev_qpos, self._prev_qvel)
                self._open[pair] = seq
                if self.trace:
                    self._rows[pair] = []
            self._add(
                seq,
                t,
                dt,
                total,
                force,
                weights,
                weight_sum,
                forces.point[rows],
                forces.normal[rows],
                depth[rows],
            )
            seq.multi_body |= bool(partners[pair[0]] > 1) or (
                pair[1] != STATIC and bool(partners[pair[1]] > 1)
            )
            if self.trace:
                yaw_b = scene.qpos[pair[1], 2] if pair[1] != STATIC else 0.0
                self._rows[pair].append(
                    (
                        t,
                        float(total[0]),
                        float(total[1]),
                        float(depth[rows].max()),
                        scene.qpos[pair[0], 2],
                        yaw_b,
                    )
                )
            if t - seq.t_start >= window.max_duration - 1e-12:
                # Still pressed together: the sequence is over, the pair now rests in contact.
                seq.ended_in_contact = True
                finished.append(self._finish(seq, complete=True))
                del self._open[pair]
                self._resting[pair] = t

    def _mark_impact(self, pair: tuple[int, int], force: float, t: float) -> None:
        """Note the bodies of ``pair`` whose contact ``force`` [N] at ``t`` [s] is an impact's."""
        threshold = self.window.impact_acceleration
        for x in pair:
            if x != STATIC and force > threshold * self.scene.masses[x]:
                self._t_impact[x] = t
                self._impacts = True

    def _add(
        self,
        seq: _Sequence,
        t: float,
        dt: float,
        total: np.ndarray,
        force: float,
        weights: np.ndarray,
        weight_sum: float,
        points: np.ndarray,
        normals: np.ndarray,
        depth: np.ndarray,
    ) -> None:
        """Add one step's contact forces of a pair to its sequence."""
        scene = self.scene
        new_impulse = not seq.impulses or t - seq.t_last >= self.window.pulse_gap - 1e-12
        if new_impulse:
            seq.impulses.append([0.0, 0.0, t, t])
        current = seq.impulses[-1]
        current[0] += total[0] * dt
        current[1] += total[1] * dt
        current[3] = t
        seq.t_last = t
        seq.impulse_b += total * dt
        point = (weights[:, None] * points).sum(axis=0) / weight_sum
        w = weight_sum * dt
        bodies = (seq.a, seq.b)
        for k, entity in enumerate(bodies):
            if entity == STATIC:
                continue
            prev = self._prev_qpos[entity]
            seq.point_sum[k] += w * _to_body_frame(point, prev)
            # Yaw after the step, unwrapped from the pre-impact yaw, weighted by |F| dt.
            turned = seq.post_qpos[k, 2] + _wrap(scene.qpos[entity, 2] - seq.post_qpos[k, 2])
            seq.yaw_sum[k] += force * dt * (turned - seq.pre_qpos[k, 2])
            seq.post_qpos[k] = scene.qpos[entity]
            seq.post_qpos[k, 2] = turned
            seq.post_qvel[k] = scene.qvel[entity]
            self.touched[entity] = True
        seq.weight += w
        seq.force_weight += force * dt
        if len(seq.impulses) == 1:
            seq.first_point += w * point
            seq.first_normal += (weights[:, None] * normals).sum(axis=0) * dt
            seq.first_weight += w
            seq.first_post_qpos[:] = seq.post_qpos
            seq.first_post_qvel[:] = seq.post_qvel
        if force > seq.peak:
            seq.peak = force
            seq.peak_time = t - seq.t_start
        seq.penetration = max(seq.penetration, float(depth.max()))

    def _body(self, seq: _Sequence, k: int, impulse: np.ndarray, first: np.ndarray) -> BodyImpact:
        scene = self.scene
        entity = seq.a if k == 0 else seq.b
        qpos, qvel, qvel_after = seq.pre_qpos[k], seq.pre_qvel[k], seq.post_qvel[k]
        yaw = float(qpos[2])
        if entity == STATIC:
            name, kind, mass = "static", scene.static_kind, math.inf
            length = width = math.nan
            dv_impulse = dv_first = np.zeros(2)
        else:
            proxy = scene.bodies[entity]
            name, kind = proxy.name, proxy.type.value
            mass, length, width = float(scene.masses[entity]), proxy.length, proxy.width
            dv_impulse, dv_first = impulse / mass, first / mass
        weight = seq.weight
        mean_yaw = yaw + (seq.yaw_sum[k] / seq.force_weight if seq.force_weight > 0 else 0.0)
        # Direction the force comes from (opposite to the impulse), in the body frame.
        source = _rotate_into(-impulse, mean_yaw)
        force_angle = float(math.atan2(source[1], source[0])) if np.any(source) else 0.0
        point = seq.point_sum[k] / weight if weight > 0 else np.zeros(2)
        impact_angle = float(math.atan2(point[1], point[0]))
        return BodyImpact(
            entity=int(entity),
            name=name,
            type=kind,
            mass=mass,
            length=float(length),
            width=float(width),
            position=(float(qpos[0]), float(qpos[1])),
            yaw=yaw,
            velocity=(float(qvel[0]), float(qvel[1])),
            velocity_after=(float(qvel_after[0]), float(qvel_after[1])),
            yaw_rate=float(qvel[2]),
            yaw_rate_after=float(qvel_after[2]),
            impulse=(float(impulse[0]), float(impulse[1])),
            delta_v_impulse=(float(dv_impulse[0]), float(dv_impulse[1])),
            delta_v_first=(float(dv_first[0]), float(dv_first[1])),
            delta_v_com=(float(qvel_after[0] - qvel[0]), float(qvel_after[1] - qvel[1])),
            force_angle=force_angle,
            force_clock=int(clock_area(force_angle)),
            contact_point=(float(point[0]), float(point[1])),
            impact_angle=impact_angle,
            reduced_area=area_name(impact_angle),
            clock_area=int(clock_area(impact_angle)),
        )

    def _restitution(self, seq: _Sequence) -> tuple[float, np.ndarray, np.ndarray]:
        """First impulse: restitution at the contact point along the normal, normal, point."""
        norm = float(np.hypot(*seq.first_normal))
        if seq.first_weight <= 0 or norm <= 0:
            return math.nan, np.zeros(2), np.zeros(2)
        n = seq.first_normal / norm
        p = seq.first_point / seq.first_weight

        def relative(qpos: np.ndarray, qvel: np.ndarray) -> float:
            va = _point_velocity(qpos[0], qvel[0], p)
            vb = np.zeros(2) if seq.b == STATIC else _point_velocity(qpos[1], qvel[1], p)
            return float(np.dot(vb - va, n))

        before = relative(seq.pre_qpos, seq.pre_qvel)
        after = relative(seq.first_post_qpos, seq.first_post_qvel)
        e = -after / before if before < -1e-6 else math.nan
        return e, n, p

    def _finish(self, seq: _Sequence, complete: bool) -> ImpactMeasurement:
        impulse_b = seq.impulse_b
        first_b = np.array(seq.impulses[0][:2]) if seq.impulses else np.zeros(2)
        body_a = self._body(seq, 0, -impulse_b, -first_b)
        body_b = self._body(seq, 1, impulse_b, first_b)
        restitution, normal, point = self._restitution(seq)
        if self.trace and (seq.a, seq.b) in self._rows:
            self.traces[(seq.a, seq.b, seq.t_start)] = np.array(self._rows.pop((seq.a, seq.b)))
        return ImpactMeasurement(
            time=seq.t_start,
            duration=seq.t_last - seq.t_start + self._dt,
            a=body_a,
            b=body_b,
            peak_force=seq.peak,
            peak_time=seq.peak_time,
            impulse=float(np.hypot(*impulse_b)),
            impulses=tuple(float(math.hypot(j[0], j[1])) for j in seq.impulses),
            impulse_times=tuple((j[2] - seq.t_start, j[3] - seq.t_start + self._dt) for j in seq.impulses),
            max_penetration=seq.penetration,
            restitution=float(restitution),
            contact_normal=(float(normal[0]), float(normal[1])),
            contact_position=(float(point[0]), float(point[1])),
            complete=complete,
            multi_body=seq.multi_body,
            ended_in_contact=seq.ended_in_contact,
        )


def skid_model(control: ControlConfig | None = None, window: MeasurementWindow | None = None) -> SkidModel:
    """The tyre forces on crashed bodies of this world, for ``planar_impulse_sequence``.

    ``brake_forces`` with the controller's friction, yaw limit and time constant; no
    braking within ``window.pulse_gap`` of a contact force (as in ``ImpactRig`` with
    ``brake=True``, the sweeps' setting).
    """
    control = control or ControlConfig()
    window = window or MeasurementWindow()
    return SkidModel(
        deceleration=control.friction_mu * GRAVITY,
        yaw_deceleration=control.torque_limit_per_inertia,
        time_constant=control.brake_time_constant,
        delay=window.pulse_gap,
    )


def _state_velocity(state: KinematicState) -> tuple[float, float]:
    return state.v * math.cos(state.yaw), state.v * math.sin(state.yaw)


class ImpactRig:
    """Two bodies launched at each other in an empty scene.

    The model is compiled once; every ``launch`` resets the data, so one rig serves
    thousands of controlled impacts. The bodies coast until they touch; from then on,
    as in the closed-loop world, they brake (skid) at the tyre friction limit outside
    the impact pulses (``brake=False``: they coast throughout, and the centre-of-mass and
    impulse delta-v agree).

    Args:
        body_a: first proxy (``BodyProxy.of_type("car", "car")`` etc.).
        body_b: second proxy.
        contact: contact model (default: rigid).
        timestep: physics step [s].
        window: measurement window.
        trace: keep the force history of every launch (``last_trace``).
        brake: skid after the first contact, outside pulses (``control.brake_forces``).
    """

    def __init__(
        self,
        body_a: BodyProxy,
        body_b: BodyProxy,
        contact: ContactSpec | None = None,
        timestep: float = 0.001,
        window: MeasurementWindow | None = None,
        trace: bool = False,
        brake: bool = True,
    ) -> None:
        check(body_a.name != body_b.name, "ImpactRig bodies need different names")
        self.brake = bool(brake)
        self._control = ControlConfig()
        self.scene = Scene([body_a, body_b], contact=contact, timestep=timestep)
        self.recorder = ImpactRecorder(self.scene, window, trace=trace)
        # Bounding radii: coasting bodies whose bounding circles are apart and separating
        # can never touch again, so a launch ends there (the sequence is complete).
        self._reach = sum(0.5 * math.hypot(b.length, b.width) for b in (body_a, body_b)) + 0.05
        #: Force history of the last launch's measured sequence (see ``ImpactRecorder.traces``).
        self.last_trace: np.ndarray | None = None

    def launch(
        self,
        state_a: KinematicState,
        state_b: KinematicState,
        max_time: float = 3.0,
        velocity_a: tuple[float, float] | None = None,
        velocity_b: tuple[float, float] | None = None,
    ) -> ImpactMeasurement | None:
        """Place both bodies, let them coast and measure their first impact sequence.

        Args:
            state_a: pose and speed of body a (velocity along its heading unless
                ``velocity_a`` is given).
            state_b: pose and speed of body b.
            max_time: give up after this time [s] if they never touch; a sequence still
                open then is returned as incomplete.
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
        self.last_trace = None
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
        if scene.overlaps(0.0):
            raise ValueError("ImpactRig.launch: the bodies overlap at the start")
        n_steps = int(math.ceil(max_time / scene.dt))
        for _ in range(n_steps):
            if self.brake and recorder.touched.any():
                ctrl = brake_forces(self._control, scene.masses, scene.yaw_inertia, scene.qvel)
                ctrl[recorder.in_pulse] = 0.0
                scene.ctrl[:] = ctrl
            done = scene.step(recorder)
            if done:
                return self._result(done[0])
            if recorder.has_open_episodes and self._apart_for_good():
                return self._result(recorder.finish(complete=True)[0])
        leftover = recorder.finish()
        return self._result(leftover[0]) if leftover else None

    def _apart_for_good(self) -> bool:
        """The bounding circles are apart and moving apart.

        Coasting bodies then never meet again; braking only slows them to rest.
        """
        q, v = self.scene.qpos, self.scene.qvel
        rx, ry = q[1, 0] - q[0, 0], q[1, 1] - q[0, 1]
        wx, wy = v[1, 0] - v[0, 0], v[1, 1] - v[0, 1]
        return rx * rx + ry * ry > self._reach**2 and rx * wx + ry * wy > 0.0

    def _result(self, measurement: ImpactMeasurement) -> ImpactMeasurement:
        if self.recorder.trace:
            key = (measurement.a.entity, measurement.b.entity, measurement.time)
            self.last_trace = self.recorder.traces.get(key)
        return measurement


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
    brake: bool = True,
) -> ImpactMeasurement | None:
    """Launch two road-user proxies at each other once and measure the impact sequence.

    Convenience wrapper of ``ImpactRig``; build a rig yourself for sweeps.

    Args:
        type_a: road-user type of body a ("car", "pedestrian", ...).
        state_a: its pose and speed.
        type_b: type of body b.
        state_b: its pose and speed.
        contact: contact model (default: rigid).
        shape_a: (length, width) [m] of a; default shape of the type if None.
        shape_b: (length, width) [m] of b.
        mass_a: [kg]; SPEC mass if None.
        mass_b: [kg].
        brake: the bodies skid after their first contact (see ``ImpactRig``).
    """
    la, wa = shape_a if shape_a is not None else (None, None)
    lb, wb = shape_b if shape_b is not None else (None, None)
    rig = ImpactRig(
        BodyProxy.of_type("a", type_a, la, wa, mass_a),
        BodyProxy.of_type("b", type_b, lb, wb, mass_b),
        contact=contact,
        brake=brake,
    )
    return rig.launch(state_a, state_b)
