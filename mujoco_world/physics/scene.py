"""MuJoCo scene of planar road-user proxies and static walls.

Every body moves on three joints (slide x, slide y, hinge z) in the plane; the slide
axes stay world-aligned because the hinge comes last, and the yaw is the hinge's
qpos. There is no floor and no gravity: tyre forces come from the controllers
(``control``). Bodies are boxes, pedestrians are vertical capsules. Names, ids and
addresses are looked up once here; the rest of the package works on the (n, 3)
views ``qpos``, ``qvel`` and ``ctrl`` (columns x, y, yaw).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol
from xml.sax.saxutils import quoteattr

import mujoco
import numpy as np

from ethical_planner.road_users import (
    DEFAULT_SHAPES,
    MOTORISED_TYPES,
    RoadUserType,
    mass_of,
)
from ethical_planner.validation import check, check_positive
from mujoco_world.physics.contact import (
    MODES,
    ContactDynamics,
    dampratio_for_restitution,
    step_with_substeps,
)
from mujoco_world.scenario.road import StaticBox
from mujoco_world.scenario.spec import Boundary, ContactSpec

#: Body height per type [m] (planar world: only for pictures and capsule length).
PROXY_HEIGHT_M = {
    RoadUserType.CAR: 1.45,
    RoadUserType.TAXI: 1.45,
    RoadUserType.PARKED_VEHICLE: 1.45,
    RoadUserType.PRIORITY_VEHICLE: 1.8,
    RoadUserType.TRUCK: 3.6,
    RoadUserType.BUS: 3.2,
    RoadUserType.MOTORCYCLE: 1.3,
    RoadUserType.BICYCLE: 1.75,
    RoadUserType.PEDESTRIAN: 1.75,
    RoadUserType.TRAIN: 4.0,
}
#: Default physics time step [s].
TIMESTEP_S = 0.001
#: Entity index of static geoms (walls, kerbs) in ``Scene.geom_entity``.
STATIC = -1
#: Entity index of geoms that belong to nothing measured.
NO_ENTITY = -2

# Collision bits: bodies collide with bodies; kerbs stop motor vehicles only, walls all.
_BODY_BIT, _KERB_BIT, _WALL_BIT = 1, 2, 4


@dataclass(frozen=True, slots=True)
class BodyProxy:
    """A road user's physical proxy.

    Attributes:
        name: unique body name.
        type: road-user type.
        length: footprint length [m] (pedestrians: diameter is the smaller side).
        width: footprint width [m].
        mass: [kg].
        kerbs: whether kerbs stop it; None: motor vehicles only (a body that follows a
            recording ignores kerbs: the recording already says where it went).
        height: [m]; None: the type's (``PROXY_HEIGHT_M``). The world is planar: the
            height is for pictures, capsule lengths and sight (``physics.sight``).
    """

    name: str
    type: RoadUserType
    length: float
    width: float
    mass: float
    kerbs: bool | None = None
    height: float | None = None

    def __post_init__(self) -> None:
        check(
            isinstance(self.name, str) and self.name.isidentifier(),
            f"BodyProxy.name must be an identifier, got {self.name!r}",
        )
        object.__setattr__(self, "type", RoadUserType.parse(self.type))
        check_positive("BodyProxy", length=self.length, width=self.width, mass=self.mass)
        if self.kerbs is None:
            object.__setattr__(self, "kerbs", self.type in MOTORISED_TYPES)
        if self.height is None:
            object.__setattr__(self, "height", PROXY_HEIGHT_M[self.type])
        check_positive("BodyProxy", height=self.height)

    @classmethod
    def of_type(
        cls,
        name: str,
        kind: RoadUserType | str,
        length: float | None = None,
        width: float | None = None,
        mass: float | None = None,
        kerbs: bool | None = None,
        height: float | None = None,
    ) -> BodyProxy:
        """A proxy with the type's default shape, height and SPEC mass unless given."""
        kind = RoadUserType.parse(kind)
        shape = DEFAULT_SHAPES[kind]
        length = shape.length if length is None else length
        width = shape.width if width is None else width
        mass = mass_of(kind, length, width) if mass is None else mass
        return cls(name, kind, float(length), float(width), float(mass), kerbs, height)

    @property
    def is_round(self) -> bool:
        """True for pedestrians (capsule proxies)."""
        return self.type is RoadUserType.PEDESTRIAN

    @property
    def radius(self) -> float:
        """Capsule radius of a round proxy [m]."""
        return 0.5 * min(self.length, self.width)


def _fmt(*values: float) -> str:
    return " ".join(f"{v:.9g}" for v in values)


def scene_xml(
    bodies: Sequence[BodyProxy],
    static_boxes: Sequence[StaticBox] = (),
    contact: ContactSpec | None = None,
    timestep: float = TIMESTEP_S,
) -> str:
    """MJCF text of a planar scene (see the module docstring and ``physics.contact``)."""
    contact = contact or ContactSpec()
    params = MODES[contact.mode]
    friction = _fmt(contact.friction, 0.005, 0.0001)
    if params.forces:
        # MuJoCo only integrates: ContactDynamics finds the contacts (collide2d) and forces.
        geom_default = 'contype="0" conaffinity="0"'
    else:
        geom_default = (
            f'solref="{_fmt(contact.timeconst, contact.dampratio)}" solimp="{_fmt(*params.solimp)}" '
            f'friction="{friction}" condim="3"'
        )
    lines = [
        '<mujoco model="mujoco_world">',
        '  <compiler angle="radian"/>',
        f'  <option timestep="{timestep:.9g}" integrator="implicitfast" gravity="0 0 0"/>',
        "  <default>",
        f"    <geom {geom_default}/>",
        '    <joint damping="0" armature="0" limited="false"/>',
        "  </default>",
        "  <worldbody>",
    ]
    for k, wall in enumerate(static_boxes):
        bit = _WALL_BIT if wall.kind is Boundary.WALL else _KERB_BIT
        half_h = wall.half_height
        bit, affinity = (0, 0) if params.forces else (bit, 0)
        lines.append(
            f'    <geom name="static_{k}" type="box" '
            f'pos="{_fmt(wall.center[0], wall.center[1], half_h)}" '
            f'size="{_fmt(wall.half_length, wall.half_width, half_h)}" '
            f'euler="0 0 {wall.yaw:.9g}" contype="{bit}" conaffinity="{affinity}" rgba="0.6 0.6 0.6 1"/>'
        )
    for body in bodies:
        name = body.name
        half_h = 0.5 * body.height
        affinity = _BODY_BIT | _WALL_BIT | (_KERB_BIT if body.kerbs else 0)
        contype = _BODY_BIT
        if params.forces:
            contype = affinity = 0
        if body.is_round:
            r = body.radius
            geom = f'type="capsule" fromto="0 0 {-half_h + r:.9g} 0 0 {half_h - r:.9g}" size="{r:.9g}"'
        else:
            geom = f'type="box" size="{_fmt(0.5 * body.length, 0.5 * body.width, half_h)}"'
        lines += [
            f'    <body name={quoteattr(name)} pos="0 0 {half_h:.9g}">',
            f'      <joint name="{name}_x" type="slide" axis="1 0 0"/>',
            f'      <joint name="{name}_y" type="slide" axis="0 1 0"/>',
            f'      <joint name="{name}_yaw" type="hinge" axis="0 0 1"/>',
            f'      <geom name="{name}_geom" {geom} mass="{body.mass:.9g}" '
            f'contype="{contype}" conaffinity="{affinity}"/>',
            "    </body>",
        ]
    lines.append("  </worldbody>")
    pairs = [] if params.forces else _restitution_pairs(bodies, contact)
    excludes = [f"    <exclude body1={quoteattr(a)} body2={quoteattr(b)}/>" for a, b in contact.exclude]
    if pairs or excludes:
        lines += ["  <contact>", *pairs, *excludes, "  </contact>"]
    lines.append("  <actuator>")
    for body in bodies:
        for axis in ("x", "y", "yaw"):
            lines.append(f'    <motor name="{body.name}_{axis}_motor" joint="{body.name}_{axis}"/>')
    lines += ["  </actuator>", "</mujoco>"]
    return "\n".join(lines)


def _restitution_pairs(bodies: Sequence[BodyProxy], contact: ContactSpec) -> list[str]:
    """``<pair>`` elements of the soft mode's constant restitution per pair of types."""
    if not contact.restitution:
        return []
    table = {
        frozenset((r.a, r.b)): dampratio_for_restitution(
            r.e if r.e is not None else r.law(contact.restitution_law).e_high
        )
        for r in contact.restitution
    }
    friction = _fmt(contact.friction, contact.friction, 0.005, 0.0001, 0.0001)
    pairs = []
    excluded = {frozenset(pair) for pair in contact.exclude}
    for i, a in enumerate(bodies):
        for b in bodies[i + 1 :]:
            dampratio = table.get(frozenset((a.type, b.type)))
            if dampratio is None or frozenset((a.name, b.name)) in excluded:
                continue
            pairs.append(
                f'    <pair geom1="{a.name}_geom" geom2="{b.name}_geom" condim="3" '
                f'solref="{_fmt(contact.timeconst, dampratio)}" friction="{friction}"/>'
            )
    return pairs


class StepObserver(Protocol):
    """Something that watches every physics (sub-)step, like ``impact.ImpactRecorder``."""

    def before_step(self) -> None:
        """Called before each ``mj_step``."""

    def after_step(self) -> list:
        """Called after each ``mj_step``; returns what ended in it."""


class Scene:
    """A compiled planar scene with ids and addresses looked up once.

    Attributes:
        bodies: the proxies, in entity order (entity i is ``bodies[i]``).
        model: ``mujoco.MjModel``. data: ``mujoco.MjData``.
        qpos: (n, 3) view of the joint positions: x [m], y [m], yaw [rad].
        qvel: (n, 3) view of the joint velocities: vx, vy [m/s], yaw rate [rad/s].
        ctrl: (n, 3) view of the motor inputs: Fx, Fy [N], torque [N m].
        masses: (n,) [kg]. yaw_inertia: (n,) [kg m^2].
        geom_entity: (ngeom,) entity index of every geom, ``STATIC`` for walls and kerbs.
        static_kind: "wall", "kerb" or "static" (no static geoms).
        static_boxes: the walls and kerbs.
        dt: physics time step [s].
    """

    def __init__(
        self,
        bodies: Sequence[BodyProxy],
        static_boxes: Sequence[StaticBox] = (),
        contact: ContactSpec | None = None,
        timestep: float = TIMESTEP_S,
    ) -> None:
        check(len(bodies) >= 1, "a scene needs at least one body")
        names = [b.name for b in bodies]
        check(len(set(names)) == len(names), f"body names must be unique, got {names}")
        check_positive("Scene", timestep=timestep)
        self.bodies = tuple(bodies)
        self.contact = contact or ContactSpec()
        self.xml = scene_xml(self.bodies, static_boxes, self.contact, timestep)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        self.n = len(self.bodies)
        self.dt = float(self.model.opt.timestep)
        m = self.model
        obj = mujoco.mjtObj
        joints = np.array(
            [
                [mujoco.mj_name2id(m, obj.mjOBJ_JOINT, f"{b.name}_{axis}") for axis in ("x", "y", "yaw")]
                for b in self.bodies
            ]
        )
        actuators = np.array(
            [
                [
                    mujoco.mj_name2id(m, obj.mjOBJ_ACTUATOR, f"{b.name}_{axis}_motor")
                    for axis in ("x", "y", "yaw")
                ]
                for b in self.bodies
            ]
        )
        self.body_ids = np.array([mujoco.mj_name2id(m, obj.mjOBJ_BODY, n) for n in names])
        self.geom_ids = np.array([mujoco.mj_name2id(m, obj.mjOBJ_GEOM, f"{n}_geom") for n in names])
        qpos_adr = m.jnt_qposadr[joints]
        dof_adr = m.jnt_dofadr[joints]
        expected = np.arange(3 * self.n).reshape(self.n, 3)
        if not (
            np.array_equal(qpos_adr, expected)
            and np.array_equal(dof_adr, expected)
            and np.array_equal(actuators, expected)
        ):
            raise RuntimeError("unexpected MuJoCo joint layout: planar joints are not contiguous")
        self.qpos = self.data.qpos.reshape(self.n, 3)
        self.qvel = self.data.qvel.reshape(self.n, 3)
        self.ctrl = self.data.ctrl.reshape(self.n, 3)
        self.masses = m.body_mass[self.body_ids].copy()
        self.yaw_inertia = m.body_inertia[self.body_ids, 2].copy()
        entity = np.full(m.ngeom, NO_ENTITY, dtype=np.int64)
        entity[m.geom_bodyid == 0] = STATIC
        entity[self.geom_ids] = np.arange(self.n)
        self.geom_entity = entity
        self.types = tuple(b.type for b in self.bodies)
        self.names = tuple(names)
        self.static_kind = static_boxes[0].kind.value if static_boxes else "static"
        self.static_boxes = tuple(static_boxes)
        self._contype = m.geom_contype[self.geom_ids].copy()
        self._conaffinity = m.geom_conaffinity[self.geom_ids].copy()
        self.dynamics = ContactDynamics(self)

    @property
    def contact_possible(self) -> bool:
        """Whether a contact could have pressed during the last step.

        Force modes: some pair was within the look-ahead before it; soft mode: MuJoCo
        reported contacts. False means no body touched anything in that step.
        """
        if self.dynamics.parameters.forces:
            return self.dynamics.near
        return self.data.ncon > 0

    def overlaps(self, tolerance: float = 1e-6) -> list[tuple[int, int]]:
        """Pairs of entities (``STATIC`` for walls and kerbs) overlapping deeper than ``tolerance`` [m]."""
        if self.dynamics.parameters.forces:
            found = self.dynamics.contacts()
            bad = found.dist < -tolerance
            pairs = zip(found.a[bad].tolist(), found.b[bad].tolist(), strict=True)
        else:
            data = self.data
            if not data.ncon:
                return []
            e1 = self.geom_entity[data.contact.geom1]
            e2 = self.geom_entity[data.contact.geom2]
            bad = (e1 != NO_ENTITY) & (e2 != NO_ENTITY) & (e1 != e2) & (data.contact.dist < -tolerance)
            pairs = zip(e1[bad].tolist(), e2[bad].tolist(), strict=True)
        return list(dict.fromkeys((int(a), int(b)) for a, b in pairs))

    def __deepcopy__(self, memo: dict[int, object]) -> Scene:
        """An independent copy of the scene in its current state (``data`` copied).

        The ``model`` is shared: nothing changes it in place after the scene is built
        (``set_contacts`` changes a copy of its own). ``qpos``,
        ``qvel`` and ``ctrl`` are views into ``data``; a plain deep copy would detach them
        from the copied ``data``, so they are made again from it. Stepping the copy and
        the original gives bit-identical states (tested).
        """
        new = Scene.__new__(Scene)
        memo[id(self)] = new
        memo[id(self.model)] = self.model
        for name, value in self.__dict__.items():
            if name not in ("qpos", "qvel", "ctrl"):
                setattr(new, name, copy.deepcopy(value, memo))
        new.qpos = new.data.qpos.reshape(new.n, 3)
        new.qvel = new.data.qvel.reshape(new.n, 3)
        new.ctrl = new.data.ctrl.reshape(new.n, 3)
        return new

    def set_contacts(self, rows: np.ndarray, enabled: bool) -> None:
        """Let bodies ``rows`` (entity indices) take part in contacts, or not.

        A body without contacts passes through everything (a road user that has not
        entered the world yet, or has left it): in the soft mode through MuJoCo's
        contact bits (explicit ``<pair>`` contacts are not filtered), in the force modes
        through the collider. Bodies out of the world are also parked far apart. (The soft
        mode changes the contact bits in a copy of the ``model``: forks of a run share the
        model, and one branch's bodies entering or leaving must not reach the others.)
        """
        geoms = self.geom_ids[rows]
        contype = self._contype[rows] if enabled else 0
        conaffinity = self._conaffinity[rows] if enabled else 0
        m = self.model
        if np.any(m.geom_contype[geoms] != contype) or np.any(m.geom_conaffinity[geoms] != conaffinity):
            self.model = m = copy.copy(m)  # copy on write (see __deepcopy__)
            m.geom_contype[geoms] = contype
            m.geom_conaffinity[geoms] = conaffinity
        self.dynamics.collider.enabled[rows] = enabled
        self.dynamics.invalidate()

    @property
    def time(self) -> float:
        """Simulation time [s]."""
        return float(self.data.time)

    def set_states(
        self,
        x: np.ndarray,
        y: np.ndarray,
        yaw: np.ndarray,
        vx: np.ndarray,
        vy: np.ndarray,
        yaw_rate: np.ndarray | float = 0.0,
    ) -> None:
        """Set positions [m], headings [rad] and velocities [m/s] of all bodies, shape (n,)."""
        values = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (x, y, yaw, vx, vy, yaw_rate)))
        for value in values:
            check(value.shape in ((self.n,), ()), f"states must have shape ({self.n},)")
            check(bool(np.all(np.isfinite(value))), "Scene.set_states: states must be finite")
        self.qpos[:, 0], self.qpos[:, 1], self.qpos[:, 2] = values[0], values[1], values[2]
        self.qvel[:, 0], self.qvel[:, 1], self.qvel[:, 2] = values[3], values[4], values[5]
        mujoco.mj_forward(self.model, self.data)
        self.dynamics.invalidate()

    def reset(self) -> None:
        """Reset time, states, controls and contact states to zero."""
        mujoco.mj_resetData(self.model, self.data)
        self.dynamics.reset()
        # The views stay valid: mj_resetData keeps the buffers.

    def step(self, observer: StepObserver | None = None) -> list:
        """Advance the physics by one time step ``dt`` (in sub-steps during an impact).

        Args:
            observer: gets ``before_step()`` / ``after_step()`` around every ``mj_step``
                (e.g. an ``ImpactRecorder``); ``after_step`` results are returned.

        Returns:
            The concatenated results of ``observer.after_step()`` (empty without one).
        """
        return step_with_substeps(self, self.dynamics.prepare(), observer)

    def speeds(self) -> np.ndarray:
        """Planar speed of every body [m/s], shape (n,)."""
        return np.hypot(self.qvel[:, 0], self.qvel[:, 1])
