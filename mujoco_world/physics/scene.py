"""MuJoCo scene of planar road-user proxies and static walls.

Every body moves on three joints (slide x, slide y, hinge z) in the plane; the slide
axes stay world-aligned because the hinge comes last, and the yaw is the hinge's
qpos. There is no floor and no gravity: tyre forces come from the controllers
(``control``). Bodies are boxes, pedestrians are vertical capsules. Names, ids and
addresses are looked up once here; the rest of the package works on the (n, 3)
views ``qpos``, ``qvel`` and ``ctrl`` (columns x, y, yaw).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
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

# Measured restitution of two 1475 kg boxes against solref damping ratio
# (timeconst 0.05 s, 3 and 10 m/s head-on, mean); used to map e to a damping ratio.
_RESTITUTION_TABLE = np.array(
    [
        (0.1, 0.7501),
        (0.15, 0.6512),
        (0.2, 0.5708),
        (0.3, 0.4477),
        (0.4, 0.3591),
        (0.5, 0.2937),
        (0.7, 0.2057),
        (1.0, 0.1315),
        (1.5, 0.0730),
        (2.0, 0.0460),
        (3.0, 0.0228),
        (4.0, 0.0135),
        (6.0, 0.0063),
    ]
)


def dampratio_for_restitution(e: float) -> float:
    """MuJoCo solref damping ratio giving a coefficient of restitution ``e``.

    Interpolated (in log e) in a table measured for box-box impacts with a time
    constant of 0.05 s; other shapes and time constants differ by a few percent, and
    the measured restitution is reported with every impact anyway.

    Args:
        e: restitution in [0.0063, 0.75].
    """
    table_dr, table_e = _RESTITUTION_TABLE[::-1, 0], _RESTITUTION_TABLE[::-1, 1]
    check(
        table_e[0] <= e <= table_e[-1],
        f"restitution must lie in [{table_e[0]}, {table_e[-1]}], got {e}",
    )
    return float(np.interp(math.log(e), np.log(table_e), table_dr))


@dataclass(frozen=True, slots=True)
class BodyProxy:
    """A road user's physical proxy.

    Attributes:
        name: unique body name.
        type: road-user type.
        length: footprint length [m] (pedestrians: diameter is the smaller side).
        width: footprint width [m].
        mass: [kg].
    """

    name: str
    type: RoadUserType
    length: float
    width: float
    mass: float

    def __post_init__(self) -> None:
        check(
            isinstance(self.name, str) and self.name.isidentifier(),
            f"BodyProxy.name must be an identifier, got {self.name!r}",
        )
        object.__setattr__(self, "type", RoadUserType.parse(self.type))
        check_positive("BodyProxy", length=self.length, width=self.width, mass=self.mass)

    @classmethod
    def of_type(
        cls,
        name: str,
        kind: RoadUserType | str,
        length: float | None = None,
        width: float | None = None,
        mass: float | None = None,
    ) -> BodyProxy:
        """A proxy with the type's default shape and SPEC mass unless given."""
        kind = RoadUserType.parse(kind)
        shape = DEFAULT_SHAPES[kind]
        length = shape.length if length is None else length
        width = shape.width if width is None else width
        mass = mass_of(kind, length, width) if mass is None else mass
        return cls(name, kind, float(length), float(width), float(mass))

    @property
    def height(self) -> float:
        """Body height [m]."""
        return PROXY_HEIGHT_M[self.type]

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
    """MJCF text of a planar scene (see the module docstring)."""
    contact = contact or ContactSpec()
    friction = _fmt(contact.friction, 0.005, 0.0001)
    lines = [
        '<mujoco model="mujoco_world">',
        '  <compiler angle="radian"/>',
        f'  <option timestep="{timestep:.9g}" integrator="implicitfast" gravity="0 0 0"/>',
        "  <default>",
        f'    <geom solref="{_fmt(contact.timeconst, contact.dampratio)}" friction="{friction}" condim="3"/>',
        '    <joint damping="0" armature="0" limited="false"/>',
        "  </default>",
        "  <worldbody>",
    ]
    for k, wall in enumerate(static_boxes):
        bit = _WALL_BIT if wall.kind is Boundary.WALL else _KERB_BIT
        lines.append(
            f'    <geom name="static_{k}" type="box" '
            f'pos="{_fmt(wall.center[0], wall.center[1], wall.half_height)}" '
            f'size="{_fmt(wall.half_length, wall.half_width, wall.half_height)}" '
            f'euler="0 0 {wall.yaw:.9g}" contype="{bit}" conaffinity="0" rgba="0.6 0.6 0.6 1"/>'
        )
    for body in bodies:
        name = body.name
        half_h = 0.5 * body.height
        affinity = _BODY_BIT | _WALL_BIT | (_KERB_BIT if body.type in MOTORISED_TYPES else 0)
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
            f'contype="{_BODY_BIT}" conaffinity="{affinity}"/>',
            "    </body>",
        ]
    lines.append("  </worldbody>")
    pairs = _restitution_pairs(bodies, contact)
    if pairs:
        lines += ["  <contact>", *pairs, "  </contact>"]
    lines.append("  <actuator>")
    for body in bodies:
        for axis in ("x", "y", "yaw"):
            lines.append(f'    <motor name="{body.name}_{axis}_motor" joint="{body.name}_{axis}"/>')
    lines += ["  </actuator>", "</mujoco>"]
    return "\n".join(lines)


def _restitution_pairs(bodies: Sequence[BodyProxy], contact: ContactSpec) -> list[str]:
    if not contact.restitution:
        return []
    table = {frozenset((r.a, r.b)): dampratio_for_restitution(r.e) for r in contact.restitution}
    friction = _fmt(contact.friction, contact.friction, 0.005, 0.0001, 0.0001)
    pairs = []
    for i, a in enumerate(bodies):
        for b in bodies[i + 1 :]:
            dampratio = table.get(frozenset((a.type, b.type)))
            if dampratio is None:
                continue
            pairs.append(
                f'    <pair geom1="{a.name}_geom" geom2="{b.name}_geom" condim="3" '
                f'solref="{_fmt(contact.timeconst, dampratio)}" friction="{friction}"/>'
            )
    return pairs


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

    def reset(self) -> None:
        """Reset time, states and controls to zero."""
        mujoco.mj_resetData(self.model, self.data)
        # The views stay valid: mj_resetData keeps the buffers.

    def step(self) -> None:
        """Advance the physics by one time step."""
        mujoco.mj_step(self.model, self.data)

    def speeds(self) -> np.ndarray:
        """Planar speed of every body [m/s], shape (n,)."""
        return np.hypot(self.qvel[:, 0], self.qvel[:, 1])
