"""Contact modes and the contact forces between bodies (rigid, crush, soft).

MuJoCo's own contacts are soft constraints defined in *acceleration* space: a contact
is a damped spring with time constant and damping ratio (``solref``), so its force scales
with the effective mass of each contact row, and frictional contacts slide only by
gaining normal velocity (its convex model drops complementarity). Measured against
rigid-body mechanics that shows: pedestrians sunk into by 0.2-0.5 m at ``solref 0.05 4``,
restitution set by where in a 1 ms step two stiff bodies touch, sliding impacts with
20-30 % too much normal impulse, and flat contacts loaded at the end with the larger
effective mass.

So in the ``rigid`` and ``crush`` modes MuJoCo only integrates: its geoms do not collide,
contacts come from the exact planar geometry of ``physics.collide2d`` (MuJoCo's box-box
collider misreports depths, see there), and the forces are
computed here, per pair of bodies, in newtons:

* **Normal force.** From the pair's penetration D (its deepest contact point) and its
  rate, by the mode's force law; distributed over the pair's contact points in
  proportion to their depth (every point of a flat contact equally compliant).
  ``rigid``: a Hunt-Crossley contact F = k D (1 + lambda dD/dt) with k = m_red omega^2
  (omega = ``RIGID_OMEGA``: a pulse of ~4 ms, ~2.5 cm of penetration at 20 m/s) and
  lambda chosen at the first touch from the restitution law at the closing speed
  (``hunt_crossley_damping``: the exact one-degree-of-freedom relation), so restitution
  does not depend on the time step. ``crush``: elastic-plastic force-deflection curves
  per body region (``CRUSH_REGIONS``: front, side, rear; softer for pedestrians and
  cyclists), the two bodies' curves in series; unloading along a line whose slope returns
  e^2 of the absorbed energy.
* **Friction.** Coulomb friction at the pair's force-weighted contact point, opposing the
  tangential relative velocity there, at most ``friction`` times the normal force and at
  most what stops that velocity within the step (so contacts can stick).

Forces are applied as ``qfrc_applied`` between ``mj_step1`` and ``mj_step2``. Steps with a
contact pressing, or about to form, are split into ``substeps`` sub-steps (rigid: 0.1 ms).

``soft`` keeps wave 1's MuJoCo contact (``solref 0.05 4``, MuJoCo friction) for comparison.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np
import shapely

from ethical_planner.impulse import RestitutionLaw
from ethical_planner.road_users import UNPROTECTED_TYPES, RoadUserType
from mujoco_world.physics.collide2d import Box2D, Collider, Contacts
from mujoco_world.scenario.spec import FORCE_RESTITUTION as _FORCE_RESTITUTION
from mujoco_world.scenario.spec import SOFT_RESTITUTION_TABLE as _SOFT_TABLE
from mujoco_world.scenario.spec import Boundary, ContactMode, restitution_range

if TYPE_CHECKING:  # pragma: no cover
    from mujoco_world.physics.scene import Scene

#: Distance before touching at which contacts are reported (no force) [m]; a pair's
#: look-ahead also grows with the distance its bodies can close in ``_IMMINENT_STEPS`` steps.
LOOKAHEAD_GAP_M = 0.1
#: Normal speed of a contact about to form above which a step is sub-stepped [m/s].
SUBSTEP_SPEED = 0.3
#: Macro steps of travel within which an approaching contact counts as imminent.
_IMMINENT_STEPS = 2.5
#: Most macro steps between two contact searches.
_MAX_SKIP = 20
#: Natural frequency of a rigid-mode contact [rad/s].
RIGID_OMEGA = 800.0
#: Closing speed below which the Hunt-Crossley damping is computed as for this speed [m/s].
_MIN_ONSET_SPEED = 0.1
#: Entity indices of static geoms and of geoms of nothing measured (as in ``scene``).
_STATIC = -1
_NO_ENTITY = -2


@dataclass(frozen=True, slots=True)
class ModeParameters:
    """How a contact mode is modelled.

    Attributes:
        substeps: sub-steps of a macro step while a contact presses or is about to form.
        forces: contact forces are computed by ``ContactDynamics`` (detection-only geoms);
            otherwise MuJoCo's constraint contacts with ``solref`` and ``solimp``.
        solimp: MuJoCo solimp of constraint contacts (soft mode).
        table: (dampratio, restitution) pairs measured for constraint contacts (soft mode).
    """

    substeps: int
    forces: bool
    solimp: tuple[float, float, float, float, float] = (0.9, 0.95, 0.001, 0.5, 2.0)
    table: tuple[tuple[float, float], ...] = ()


MODES: dict[ContactMode, ModeParameters] = {
    ContactMode.SOFT: ModeParameters(substeps=1, forces=False, table=_SOFT_TABLE),
    ContactMode.RIGID: ModeParameters(substeps=10, forces=True),
    ContactMode.CRUSH: ModeParameters(substeps=4, forces=True),
}


@dataclass(frozen=True, slots=True)
class CrushRegion:
    """Elastic-plastic force-deflection of a body region, per kilogram of the body.

    The region deflects linearly up to ``yield_crush`` and then crushes at a constant
    force; masses scale the force, so bodies of one class crush alike at one speed.

    Attributes:
        yield_force: force at yield per kilogram of the body [N/kg] (= deceleration [m/s^2]).
        yield_crush: deflection at yield [m].
    """

    yield_force: float
    yield_crush: float

    @property
    def stiffness(self) -> float:
        """Elastic stiffness per kilogram [N/m/kg]."""
        return self.yield_force / self.yield_crush


#: Crush regions by (class, region). Vehicle fronts: 0.6 m of crush at 56 km/h into a
#: rigid wall with the force at yield (33 g) from 0.42 m on, a pulse of ~75 ms. Sides are
#: weaker with less crush space, rears a little softer than fronts. Pedestrians and
#: cyclists (with the striking bonnet and bumper) are far softer.
CRUSH_REGIONS: dict[tuple[str, str], CrushRegion] = {
    ("vehicle", "front"): CrushRegion(yield_force=324.0, yield_crush=0.42),
    ("vehicle", "side"): CrushRegion(yield_force=160.0, yield_crush=0.25),
    ("vehicle", "rear"): CrushRegion(yield_force=260.0, yield_crush=0.40),
    ("unprotected", "front"): CrushRegion(yield_force=300.0, yield_crush=0.75),
    ("unprotected", "side"): CrushRegion(yield_force=300.0, yield_crush=0.75),
    ("unprotected", "rear"): CrushRegion(yield_force=300.0, yield_crush=0.75),
}


def _hunt_crossley_table() -> tuple[np.ndarray, np.ndarray]:
    """Restitution e(u) of a Hunt-Crossley contact, u = lambda x closing speed.

    m x'' = -k x (1 + lambda x') has the first integral v / lambda - ln(1 + lambda v) /
    lambda^2 along the way in and out, so u - ln(1 + u) = -w - ln(1 - w) with w = lambda x
    rebound speed; e = w / u. Solved for w in (0, 1) by bisection.
    """
    u = np.geomspace(1e-4, 1e4, 2001)
    target = u - np.log1p(u)
    lo, hi = np.zeros_like(u), np.full_like(u, 1.0 - 1e-15)
    for _ in range(80):
        w = 0.5 * (lo + hi)
        value = -w - np.log1p(-w)
        lo = np.where(value < target, w, lo)
        hi = np.where(value < target, hi, w)
    return u, 0.5 * (lo + hi) / u


_HC_U, _HC_E = _hunt_crossley_table()


def hunt_crossley_damping(e: float, closing_speed: float) -> float:
    """Damping lambda [s/m] of a Hunt-Crossley contact giving restitution ``e`` at a closing speed.

    Args:
        e: restitution in [0.01, 0.9].
        closing_speed: normal closing speed at the first touch [m/s] (floored at 0.1 m/s).
    """
    e = min(max(float(e), _FORCE_RESTITUTION[0]), _FORCE_RESTITUTION[1])
    u = float(np.interp(math.log(e), np.log(_HC_E[::-1]), _HC_U[::-1]))
    return u / max(float(closing_speed), _MIN_ONSET_SPEED)


def restitution_dampratio(e: float | np.ndarray, mode: ContactMode = ContactMode.SOFT) -> np.ndarray:
    """MuJoCo damping ratio giving restitution ``e`` with constraint contacts (log-interpolated).

    Values outside the table's range are clamped to its ends.
    """
    table = np.array(MODES[mode].table)[::-1]
    log_e = np.log(np.clip(np.asarray(e, dtype=float), table[0, 1], table[-1, 1]))
    return np.interp(log_e, np.log(table[:, 1]), table[:, 0])


def dampratio_for_restitution(e: float, mode: ContactMode = ContactMode.SOFT) -> float:
    """Damping ratio of a constant restitution ``e``; raises if ``e`` is outside the table.

    Raises:
        ValueError: ``e`` outside ``restitution_range(mode)``.
    """
    low, high = restitution_range(mode)
    if not low <= e <= high:
        raise ValueError(f"restitution must lie in [{low}, {high}] in {mode.value} mode, got {e}")
    return float(restitution_dampratio(e, mode))


@dataclass(frozen=True, slots=True, eq=False)
class ContactForces:
    """Forces between entities during one physics step, one row per contact.

    Attributes:
        a: (k,) entity index of the first body (the lower index).
        b: (k,) entity index of the second body, or ``STATIC`` (-1) for walls and kerbs.
        force_b: (k, 2) force on b [N], world frame (on a: minus it).
        point: (k, 2) where it acts [m], world frame.
        normal: (k, 2) contact normal from a to b.
        depth: (k,) penetration [m] (0 for friction rows).
    """

    a: np.ndarray
    b: np.ndarray
    force_b: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    depth: np.ndarray

    @property
    def size(self) -> int:
        """Number of rows."""
        return len(self.a)

    @classmethod
    def from_rows(cls, rows: list[tuple[float, ...]]) -> ContactForces:
        """From rows (a, b, fx, fy, px, py, nx, ny, depth)."""
        if not rows:
            return NO_FORCES
        table = np.array(rows, dtype=float)
        return cls(
            table[:, 0].astype(np.int64), table[:, 1].astype(np.int64), table[:, 2:4], table[:, 4:6],
            table[:, 6:8], table[:, 8],
        )  # fmt: skip


NO_FORCES = ContactForces(
    np.zeros(0, np.int64),
    np.zeros(0, np.int64),
    np.zeros((0, 2)),
    np.zeros((0, 2)),
    np.zeros((0, 2)),
    np.zeros(0),
)


def measure_contact_forces(scene: Scene, buffer: np.ndarray | None = None) -> ContactForces:
    """Forces of MuJoCo's active constraint contacts between distinct entities (soft mode).

    Contacts are filtered by geom entity with numpy before ``mujoco.mj_contactForce`` is
    called on the few that matter; forces are rotated to world with ``contact.frame``.
    """
    data = scene.data
    if data.ncon == 0:
        return NO_FORCES
    contact = data.contact
    e1 = scene.geom_entity[contact.geom1]
    e2 = scene.geom_entity[contact.geom2]
    keep = (contact.efc_address >= 0) & (e1 != e2) & (e1 != _NO_ENTITY) & (e2 != _NO_ENTITY)
    index = np.flatnonzero(keep)
    if index.size == 0:
        return NO_FORCES
    e1, e2 = e1[index], e2[index]
    buffer = np.zeros(6) if buffer is None else buffer
    forces = np.empty((index.size, 3))
    for k, i in enumerate(index):
        mujoco.mj_contactForce(scene.model, data, int(i), buffer)
        forces[k] = buffer[:3]
    frames = contact.frame[index].reshape(-1, 3, 3)
    world = np.einsum("ki,kij->kj", forces, frames)[:, :2]
    swap = (e1 == _STATIC) | ((e2 != _STATIC) & (e2 < e1))
    flip = np.where(swap, -1.0, 1.0)[:, None]
    return ContactForces(
        a=np.where(swap, e2, e1),
        b=np.where(swap, e1, e2),
        force_b=world * flip,
        point=contact.pos[index, :2].copy(),
        normal=frames[:, 0, :2] * flip,
        depth=-contact.dist[index],
    )


class _Pair:
    """State of one pair in contact (from its first touch until it separates)."""

    __slots__ = (
        "e", "damping", "stiffness", "yield_force", "d_max", "f_max", "energy", "unload", "normal", "static",
        "depth", "last_dt", "speed", "law",
    )  # fmt: skip

    def __init__(self, e: float, damping: float, stiffness: float, yield_force: float) -> None:
        self.e, self.damping, self.stiffness, self.yield_force = e, damping, stiffness, yield_force
        self.normal = (1.0, 0.0)  # crush: contact normal at the first touch, in a's frame
        self.static = None  # crush: the static box of a wall contact
        self.d_max = 0.0
        self.f_max = 0.0
        self.energy = 0.0
        self.unload = 0.0
        self.depth: float | None = None  # crush: deflection, integrated from the closing rate [m]
        self.last_dt = 0.0
        self.speed = 0.0  # rigid: the fastest closing rate so far, which sets e and damping [m/s]
        self.law: RestitutionLaw | None = None  # rigid: the pair's restitution law


@dataclass(frozen=True, slots=True)
class _Footprint:
    """A rectangle (half extents) or a disc (radius) at a pose, for the crush geometry."""

    x: float
    y: float
    yaw: float
    half_length: float
    half_width: float
    radius: float = 0.0

    def support(self, dx: float, dy: float) -> float:
        """Extent along the unit direction (dx, dy) from the centre [m]."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return self.half_length * abs(c * dx + s * dy) + self.half_width * abs(c * dy - s * dx) + self.radius

    def polygon(self) -> shapely.Polygon:
        """The footprint as a polygon (a disc as a 16-gon)."""
        if self.radius > 0:
            return shapely.Point(self.x, self.y).buffer(self.radius, quad_segs=4)
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        corners = [(u, v) for u, v in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
        return shapely.Polygon(
            [
                (self.x + c * u * self.half_length - s * v * self.half_width,
                 self.y + s * u * self.half_length + c * v * self.half_width)
                for u, v in corners
            ]
        )  # fmt: skip


def _region(angle: float) -> str:
    a = abs(angle)
    return "front" if a < 0.25 * math.pi else ("side" if a < 0.75 * math.pi else "rear")


class ContactDynamics:
    """Per-scene logic of a contact mode around every physics step.

    ``prepare()`` before a macro step returns how many sub-steps it needs; in the force
    modes ``apply(dt)`` computes and applies the contact forces of a (sub-)step between
    ``mj_step1`` and ``mj_step2``; ``after_substep()`` keeps the forces of the step just
    taken in ``forces`` (for the impact recorder).

    Attributes:
        mode: the contact mode.
        parameters: how it is modelled.
        laws: restitution law per unordered pair of type names (``"static"`` for walls).
        friction: Coulomb friction coefficient between bodies.
        forces: contact forces of the last (sub-)step, friction rows included.
        onsets: (entity a, entity b, closing speed [m/s], e) of every first touch so far.
    """

    def __init__(self, scene: Scene) -> None:
        contact = scene.contact
        self.scene = scene
        self.mode = contact.mode
        self.parameters = MODES[self.mode]
        names = [t.value for t in scene.types]
        self.laws: dict[frozenset[str], RestitutionLaw] = {}
        for a in {*names, "static"}:
            for b in set(names):
                self.laws[frozenset((a, b))] = contact.law_for(a, b)
        self._type_names = names
        self._unprotected = [RoadUserType(t) in UNPROTECTED_TYPES for t in names]
        self._buffer = np.zeros(6)
        self._pairs: dict[tuple[int, int], _Pair] = {}
        self._applied = NO_FORCES
        self._static_index = np.zeros(0, dtype=np.int64)
        self.friction = float(contact.friction)
        self.forces = NO_FORCES
        self.onsets: list[tuple[int, int, float, float]] = []
        #: Some pair was within the look-ahead before the last macro step (force modes).
        self.near = False
        self._skip = 0
        bodies = scene.bodies
        self.collider = Collider(
            [(0.5 * b.length, 0.5 * b.width) for b in bodies],
            [b.is_round for b in bodies],
            [bool(b.kerbs) for b in bodies],
            [
                Box2D(*box.center, box.yaw, box.half_length, box.half_width, box.kind is Boundary.KERB)
                for box in scene.static_boxes
            ],
        )

        index = {name: k for k, name in enumerate(scene.names)}
        self.collider.exclude([(index[a], index[b]) for a, b in contact.exclude if a in index and b in index])

    def reset(self) -> None:
        """Forget every pair state (after ``Scene.reset``)."""
        self._pairs.clear()
        self._applied = NO_FORCES
        self.forces = NO_FORCES
        self.near = False
        self._skip = 0
        self.onsets.clear()
        self.scene.data.qfrc_applied[:] = 0.0

    # ------------------------------------------------------------------ sub-steps

    def prepare(self) -> int:
        """Sub-steps of the coming macro step (1 or ``parameters.substeps``).

        Force modes: sub-steps while a contact presses or is about to form (closing faster
        than ``SUBSTEP_SPEED`` and touching within ``_IMMINENT_STEPS`` steps); ``near``
        tells whether a contact could press in this step. While the collider's bound says
        nothing can touch for 1.5 steps or more, the searches are skipped (at most
        ``_MAX_SKIP`` steps).
        """
        params = self.parameters
        if not params.forces:
            return 1
        if self._skip > 0:
            self._skip -= 1
            self.near = False
            return 1
        found = self.contacts(lookahead=True)
        # Nothing can touch for a while: skip the searches (the bound's time, with 1.5 to spare).
        skip = min(_MAX_SKIP, int(self.collider.time_to_touch / (1.5 * self.scene.dt)))
        if skip >= 1:
            self._skip = skip - 1
            self.near = False
            return 1
        self.near = found.size > 0
        if not self.near:
            return 1
        if np.any(found.dist <= 0.0):
            return params.substeps  # a contact is pressing
        scene = self.scene
        u = _point_velocity(scene, found.b, found.point) - _point_velocity(scene, found.a, found.point)
        closing = -np.einsum("ij,ij->i", u, found.normal)
        imminent = (closing > SUBSTEP_SPEED) & (found.dist < closing * _IMMINENT_STEPS * scene.dt)
        return params.substeps if imminent.any() else 1

    def invalidate(self) -> None:
        """Search for contacts before the next step (bodies were moved by hand)."""
        self._skip = 0

    def contacts(self, lookahead: bool = False) -> Contacts:
        """Contact points at the current positions (``physics.collide2d``).

        Args:
            lookahead: also points not yet touching, within ``LOOKAHEAD_GAP_M`` plus the
                distance the pair can close in ``_IMMINENT_STEPS`` steps; otherwise only
                penetrating points.
        """
        scene = self.scene
        if not lookahead:
            return self.collider.contacts(scene.qpos, 0.0, 0.0)
        v = scene.qvel
        speed = np.hypot(v[:, 0], v[:, 1]) + np.abs(v[:, 2]) * self.collider.radius
        reach = speed * (_IMMINENT_STEPS * scene.dt)
        return self.collider.contacts(scene.qpos, reach, LOOKAHEAD_GAP_M, speed)

    # ------------------------------------------------------------------ forces

    def apply(self, dt: float) -> None:
        """Compute and apply the contact forces of the coming (sub-)step of ``dt`` [s].

        Call after ``mujoco.mj_step1`` (contacts at the current positions) and before
        ``mujoco.mj_step2``.
        """
        scene = self.scene
        qfrc = scene.data.qfrc_applied
        if self._applied.size:
            qfrc[:] = 0.0
        self._applied = NO_FORCES
        found = self.contacts()
        if found.size == 0:
            self._pairs.clear()
            return
        a_all, b_all = found.a, found.b
        depth = -found.dist
        point = found.point
        normal = found.normal
        self._static_index = found.static
        groups: dict[tuple[int, int], list[int]] = {}
        for k, (a, b) in enumerate(zip(a_all.tolist(), b_all.tolist(), strict=True)):
            groups.setdefault((a, b), []).append(k)
        for key in [k for k in self._pairs if k not in groups]:
            del self._pairs[key]
        rows: list[tuple[float, ...]] = []
        for (a, b), members in groups.items():
            self._pair_forces(a, b, members, depth, point, normal, dt, rows)
        for a, b, fx, fy, px, py, _, _, _ in rows:
            for entity, sign in ((int(b), 1.0), (int(a), -1.0)):
                if entity >= 0:
                    q = scene.qpos[entity]
                    base = 3 * entity
                    qfrc[base] += sign * fx
                    qfrc[base + 1] += sign * fy
                    qfrc[base + 2] += sign * ((px - q[0]) * fy - (py - q[1]) * fx)
        self._applied = ContactForces.from_rows(rows)

    def _pair_forces(self, a, b, members, depth, point, normal, dt, rows) -> None:  # noqa: ANN001
        """Normal forces of one pair's contact points and its friction force, appended to ``rows``."""
        scene = self.scene
        d = depth[members]
        deepest = members[int(np.argmax(d))]
        rates = []
        for k in members:
            px, py = float(point[k, 0]), float(point[k, 1])
            (vbx, vby), (vax, vay) = _velocity_at(scene, b, px, py), _velocity_at(scene, a, px, py)
            rates.append(-((vbx - vax) * normal[k, 0] + (vby - vay) * normal[k, 1]))  # > 0 approaching
        state = self._pairs.get((a, b))
        if state is None:
            state = self._onset(a, b, members, deepest, point, normal, rates[members.index(deepest)])
            self._pairs[(a, b)] = state
        if self.mode is ContactMode.CRUSH:
            self._crush_pair(a, b, state, dt, rows)
            return
        # A pair that touched gently and is then driven in faster (a spinning body swinging
        # into the other) is an impact at the faster rate: lambda and e are those of the
        # fastest closing rate of a pressing point so far. With lambda from the gentle
        # onset (up to 1 / 0.1 m/s), lambda * rate grew without bound and the explicit
        # damping force overshot: a bus's second hit on the ego multiplied the kinetic
        # energy by 10 (ego delta-v 103 m/s from 28 m/s).
        pressing = [r for k, r in zip(members, rates, strict=True) if depth[k] > 0.0]
        fastest = max(pressing, default=0.0)
        if fastest > state.speed:
            state.speed = fastest
            state.e = float(state.law(fastest))
            state.damping = hunt_crossley_damping(state.e, fastest)
        # Hunt-Crossley per contact point: a corner has the pair's stiffness, a flat
        # contact (two points) twice of it.
        k_pair = state.stiffness
        forces = [
            max(0.0, k_pair * float(depth[k]) * (1.0 + state.damping * r))
            for k, r in zip(members, rates, strict=True)
        ]
        total = wx = wy = wnx = wny = 0.0
        for k, f in zip(members, forces, strict=False):
            if f <= 0.0:
                continue
            fx, fy = f * normal[k, 0], f * normal[k, 1]
            rows.append((a, b, fx, fy, point[k, 0], point[k, 1], normal[k, 0], normal[k, 1], depth[k]))
            total += f
            wx += f * point[k, 0]
            wy += f * point[k, 1]
            wnx += f * normal[k, 0]
            wny += f * normal[k, 1]
        if total > 0.0 and self.friction > 0.0:
            self._friction(a, b, total, wx / total, wy / total, wnx, wny, dt, rows)

    def _onset(self, a, b, members, deepest, point, normal, rate) -> _Pair:  # noqa: ANN001
        """Pair state at its first touch: restitution from the law at the closing speed."""
        scene = self.scene
        type_b = "static" if b == _STATIC else self._type_names[b]
        law = self.laws[frozenset((self._type_names[a], type_b))]
        speed = max(rate, 0.0)
        e = float(law(speed))
        m_a = float(scene.masses[a])
        m_red = m_a if b == _STATIC else m_a * float(scene.masses[b]) / (m_a + float(scene.masses[b]))
        if self.mode is ContactMode.CRUSH:
            k = deepest
            px, py = float(point[k, 0]), float(point[k, 1])
            stiffness, yield_force = self._crush_curve(a, b, px, py)
            state = _Pair(e, 0.0, stiffness, yield_force)
            # Crush keeps the first touch's normal (turning with a): deep overlaps of boxes
            # would otherwise flip it to whichever face is least penetrated.
            yaw = float(scene.qpos[a, 2])
            c, s = math.cos(yaw), math.sin(yaw)
            nx, ny = float(normal[k, 0]), float(normal[k, 1])
            state.normal = (c * nx + s * ny, -s * nx + c * ny)
            if b == _STATIC:
                state.static = self._static_box_of(a, members)
        else:
            state = _Pair(e, hunt_crossley_damping(e, speed), m_red * RIGID_OMEGA**2, math.inf)
            state.speed, state.law = speed, law
        self.onsets.append((a, b, speed, e))
        return state

    def _static_box_of(self, a: int, members: list[int]):  # noqa: ANN202
        """The static box a crush contact of body a touches (the deepest one)."""
        index = int(self._static_index[members[0]])
        return self.scene.static_boxes[index] if index >= 0 else None

    def _crush_pair(self, a: int, b: int, state: _Pair, dt: float, rows: list) -> None:
        """Crush force of a pair along its first-touch normal, at the footprints' overlap centroid.

        The deflection is the geometric depth at the first touch and from then on the
        integral of the closing speed of the material points at the overlap centroid along
        the normal, so the force does work exactly as its force-deflection curve says. The
        geometric depth along the normal alone grows when a struck body spins (its
        diagonal turns into the normal) and then pushes the bodies apart with energy that
        no crush stored (a T-bone at the rear axle came out with e = 1.85).
        """
        scene = self.scene
        qa = scene.qpos[a]
        c, s = math.cos(qa[2]), math.sin(qa[2])
        nx = c * state.normal[0] - s * state.normal[1]
        ny = s * state.normal[0] + c * state.normal[1]
        shape_a = self._footprint(a)
        shape_b = self._footprint(b, state.static)
        if shape_b is None:
            return
        overlap = shape_a.polygon().intersection(shape_b.polygon())
        if overlap.is_empty:
            return
        centre = overlap.centroid
        px, py = float(centre.x), float(centre.y)
        if state.depth is None:
            depth = (
                shape_a.support(nx, ny)
                + shape_b.support(-nx, -ny)
                - ((shape_b.x - shape_a.x) * nx + (shape_b.y - shape_a.y) * ny)
            )
        else:
            (vbx, vby), (vax, vay) = _velocity_at(scene, b, px, py), _velocity_at(scene, a, px, py)
            depth = state.depth - ((vbx - vax) * nx + (vby - vay) * ny) * state.last_dt
        state.depth, state.last_dt = depth, dt
        force = self._crush_force(state, depth) if depth > 0 else 0.0
        if force <= 0.0:
            return
        rows.append((a, b, force * nx, force * ny, px, py, nx, ny, depth))
        if self.friction > 0.0:
            self._friction(a, b, force, px, py, nx, ny, dt, rows)

    def _footprint(self, entity: int, static=None) -> _Footprint | None:  # noqa: ANN001
        """Footprint of a body (from its proxy and pose) or of a static box."""
        scene = self.scene
        if entity == _STATIC:
            if static is None:
                return None
            return _Footprint(
                static.center[0], static.center[1], static.yaw, static.half_length, static.half_width
            )
        body = scene.bodies[entity]
        q = scene.qpos[entity]
        if body.is_round:
            return _Footprint(q[0], q[1], q[2], 0.0, 0.0, body.radius)
        return _Footprint(q[0], q[1], q[2], 0.5 * body.length, 0.5 * body.width)

    def _crush_curve(self, a: int, b: int, px: float, py: float) -> tuple[float, float]:
        """Stiffness [N/m] and yield force [N] of the pair's two regions in series."""
        scene = self.scene
        compliance, yields = 0.0, []
        for entity in (a, b):
            if entity == _STATIC:
                continue  # a wall does not crush
            q = scene.qpos[entity]
            c, s = math.cos(q[2]), math.sin(q[2])
            dx, dy = px - q[0], py - q[1]
            angle = math.atan2(-s * dx + c * dy, c * dx + s * dy)
            kind = "unprotected" if self._unprotected[entity] else "vehicle"
            region = CRUSH_REGIONS[(kind, _region(angle))]
            mass = float(scene.masses[entity])
            compliance += 1.0 / (region.stiffness * mass)
            yields.append(region.yield_force * mass)
        return 1.0 / compliance, min(yields)

    def _crush_force(self, state: _Pair, depth: float) -> float:
        """Elastic-plastic loading with an unloading line that returns e^2 of the absorbed energy."""
        if depth >= state.d_max:
            # Loading along the curve; the absorbed energy sets the unloading slope.
            force = min(state.stiffness * depth, state.yield_force)
            state.energy += (
                0.5 * (force + min(state.stiffness * state.d_max, state.yield_force)) * (depth - state.d_max)
            )
            state.d_max, state.f_max = depth, force
            e2 = max(state.e, _FORCE_RESTITUTION[0]) ** 2
            state.unload = max(force * force / (2.0 * e2 * max(state.energy, 1e-9)), state.stiffness)
            return force
        return max(0.0, state.f_max - state.unload * (state.d_max - depth))

    def _friction(self, a, b, normal_force, px, py, nx, ny, dt, rows) -> None:  # noqa: ANN001
        """Coulomb friction of a pair at its force-weighted point (appended to ``rows``)."""
        scene = self.scene
        norm = math.hypot(nx, ny)
        if norm <= 0.0:
            return
        nx, ny = nx / norm, ny / norm
        (vbx, vby), (vax, vay) = _velocity_at(scene, b, px, py), _velocity_at(scene, a, px, py)
        ux, uy = vbx - vax, vby - vay
        along = ux * nx + uy * ny
        tx, ty = ux - along * nx, uy - along * ny
        speed = math.hypot(tx, ty)
        if speed <= 1e-9:
            return
        tx, ty = tx / speed, ty / speed
        k_tt = 0.0
        for entity in (a, b):
            if entity >= 0:
                q = scene.qpos[entity]
                cross = (px - q[0]) * ty - (py - q[1]) * tx
                k_tt += 1.0 / scene.masses[entity] + cross * cross / scene.yaw_inertia[entity]
        magnitude = self.friction * normal_force
        if k_tt > 0.0:
            magnitude = min(magnitude, speed / (k_tt * dt))
        rows.append((a, b, -magnitude * tx, -magnitude * ty, px, py, nx, ny, 0.0))

    def after_substep(self) -> None:
        """Keep the forces of the step just taken (measured from MuJoCo in soft mode)."""
        if self.parameters.forces:
            self.forces = self._applied
        else:
            self.forces = measure_contact_forces(self.scene, self._buffer)


def _velocity_at(scene: Scene, entity: int, px: float, py: float) -> tuple[float, float]:
    """Velocity of an entity's material point at (px, py) [m/s]; 0 for static."""
    if entity < 0:
        return 0.0, 0.0
    q, v = scene.qpos[entity], scene.qvel[entity]
    return v[0] - v[2] * (py - q[1]), v[1] + v[2] * (px - q[0])


def _point_velocity(scene: Scene, entity: np.ndarray, point: np.ndarray) -> np.ndarray:
    """Velocity [m/s] of material points of entities (0 for static), shape (k, 2)."""
    out = np.zeros((len(entity), 2))
    moving = entity >= 0
    if moving.any():
        e = entity[moving]
        q, v = scene.qpos[e], scene.qvel[e]
        rx, ry = point[moving, 0] - q[:, 0], point[moving, 1] - q[:, 1]
        out[moving, 0] = v[:, 0] - v[:, 2] * ry
        out[moving, 1] = v[:, 1] + v[:, 2] * rx
    return out


def step_with_substeps(scene: Scene, substeps: int, observer) -> list:  # noqa: ANN001
    """Advance ``scene`` by one macro step of ``scene.dt`` in ``substeps`` equal parts.

    Force modes: ``mj_step1``, the contact forces (``ContactDynamics.apply``), ``mj_step2``;
    soft mode: ``mj_step``. ``observer`` (or None) gets ``before_step()`` and
    ``after_step()`` around every (sub-)step; the lists ``after_step`` returns are joined.
    """
    model, data = scene.model, scene.data
    dynamics = scene.dynamics
    forces = dynamics.parameters.forces
    if forces and substeps == 1 and not dynamics.near and (observer is None or not observer.busy):
        # Nothing within the look-ahead (which covers what the bodies can close in 2.5
        # steps): no contact can press during this step; nothing to compute or record.
        mujoco.mj_step(model, data)
        dynamics.forces = NO_FORCES
        return []
    done: list = []
    dt = scene.dt / substeps
    if substeps > 1:
        model.opt.timestep = dt
    try:
        for _ in range(substeps):
            if observer is not None:
                observer.before_step()
            if forces:
                mujoco.mj_step1(model, data)
                dynamics.apply(dt)
                mujoco.mj_step2(model, data)
            else:
                mujoco.mj_step(model, data)
            dynamics.after_substep()
            if observer is not None:
                done.extend(observer.after_step())
    finally:
        if substeps > 1:
            model.opt.timestep = scene.dt
    return done


__all__ = [
    "CRUSH_REGIONS",
    "LOOKAHEAD_GAP_M",
    "MODES",
    "NO_FORCES",
    "RIGID_OMEGA",
    "SUBSTEP_SPEED",
    "ContactDynamics",
    "ContactForces",
    "CrushRegion",
    "ModeParameters",
    "dampratio_for_restitution",
    "hunt_crossley_damping",
    "measure_contact_forces",
    "restitution_dampratio",
    "restitution_range",
    "step_with_substeps",
]
