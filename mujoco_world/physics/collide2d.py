"""Planar collision detection of the force modes: rectangles and discs in the plane.

The ``rigid`` and ``crush`` modes compute contact forces from penetration depths, so the
depths must be exact. MuJoCo 4.0's box-box collider is not a depth sensor: with a
positive margin it misses about 0.4 % of contacts a few centimetres ahead (an open
issue, google-deepmind/mujoco#2471), and for about 8 % of shallow penetrations of two
random boxes it reports a depth centimetres deeper than the true one (once 0.85 m for
5 cm; a box width, as in #3476). A stiff contact turns such a depth into a blow-up (a
car into a bus side at 30 m/s came out with e = 2.6). Every body here is a prism moving
in the plane, so the exact geometry is a few lines of 2D: separating axes of two
rectangles, the incident edge clipped against the reference face (two points for a
flat contact, one for a corner), closest points for discs (pedestrians). MuJoCo only
integrates in these modes; its geoms do not collide.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: Entity index of static boxes (walls, kerbs) in ``Contacts.b``.
STATIC = -1
#: Bound of the acceleration of any body's material point outside contacts [m/s^2]
#: (controllers clamp at 0.9 g; braking after a crash stays below the friction limit).
ACCEL_BOUND = 30.0


@dataclass(frozen=True, slots=True)
class Box2D:
    """A static rectangle (wall or kerb segment).

    Attributes:
        x, y: centre [m]. yaw: heading of the long side [rad].
        half_length, half_width: half extents [m].
        kerb: True for kerbs (only motor vehicles touch them).
    """

    x: float
    y: float
    yaw: float
    half_length: float
    half_width: float
    kerb: bool = False


@dataclass(frozen=True, slots=True, eq=False)
class Contacts:
    """Contact points within the look-ahead, one row each.

    Attributes:
        a: (k,) entity index of the first body (the lower index).
        b: (k,) entity index of the second body, or ``STATIC`` (-1).
        static: (k,) index of the static box touched (-1 for body pairs).
        dist: (k,) signed distance [m]: negative is penetration.
        point: (k, 2) contact point, midway between the two surfaces [m].
        normal: (k, 2) unit normal from a to b.
    """

    a: np.ndarray
    b: np.ndarray
    static: np.ndarray
    dist: np.ndarray
    point: np.ndarray
    normal: np.ndarray

    @property
    def size(self) -> int:
        """Number of contact points."""
        return len(self.a)

    @classmethod
    def from_rows(cls, rows: list[tuple[float, ...]]) -> Contacts:
        """From rows (a, b, static, dist, px, py, nx, ny)."""
        if not rows:
            return NO_CONTACTS
        t = np.array(rows, dtype=float)
        i = t[:, :3].astype(np.int64)
        return cls(i[:, 0], i[:, 1], i[:, 2], t[:, 3], t[:, 4:6], t[:, 6:8])


NO_CONTACTS = Contacts(
    np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 2)),
    np.zeros((0, 2)),
)  # fmt: skip


def rect_rect(
    ca: tuple[float, float], yaw_a: float, ha: tuple[float, float],
    cb: tuple[float, float], yaw_b: float, hb: tuple[float, float], margin: float,
) -> list[tuple[float, float, float, float, float]]:  # fmt: skip
    """Contact points of two rectangles closer than ``margin``.

    Separating axes: the axis of least penetration (or largest separation) is the
    normal; the face of the rectangle it belongs to is the reference face, the other
    rectangle's face most opposed to it is the incident face, clipped to the reference
    face's extent (Box2D's manifold). Separated rectangles get a conservative distance
    (the separation along that axis, at most the true distance).

    Args:
        ca, cb: centres [m]. yaw_a, yaw_b: headings [rad]. ha, hb: (half length, half width) [m].
        margin: report points with a distance below this [m].

    Returns:
        Rows (dist, px, py, nx, ny), normal from a to b; empty when farther than ``margin``.
    """
    dx, dy = cb[0] - ca[0], cb[1] - ca[1]
    a_axes = ((math.cos(yaw_a), math.sin(yaw_a)), (-math.sin(yaw_a), math.cos(yaw_a)))
    b_axes = ((math.cos(yaw_b), math.sin(yaw_b)), (-math.sin(yaw_b), math.cos(yaw_b)))
    best = None
    for owner, axes in ((0, a_axes), (1, b_axes)):
        for k, (nx, ny) in enumerate(axes):
            ra = _extent(ha, a_axes, nx, ny)
            rb = _extent(hb, b_axes, nx, ny)
            along = dx * nx + dy * ny
            separation = abs(along) - ra - rb
            if separation > margin:
                return []
            # Prefer a's faces unless b's separate clearly more (no flip-flop on ties).
            if best is None or separation > best[0] + (1e-6 if owner else 0.0):
                sign = 1.0 if along >= 0.0 else -1.0
                best = (separation, owner, k, sign * nx, sign * ny)  # normal from a to b
    separation, owner, k, nx, ny = best
    if owner == 0:
        rows = _clip(ca, a_axes, ha, k, (nx, ny), cb, b_axes, hb, separation, margin)
        return rows
    # b's face is the reference: normal from b to a, flipped back at the end.
    rows = _clip(cb, b_axes, hb, k, (-nx, -ny), ca, a_axes, ha, separation, margin)
    return [(d, px, py, -mx, -my) for d, px, py, mx, my in rows]


def _extent(h, axes, nx: float, ny: float) -> float:  # noqa: ANN001
    """Half extent of a rectangle along the unit direction (nx, ny)."""
    return h[0] * abs(nx * axes[0][0] + ny * axes[0][1]) + h[1] * abs(nx * axes[1][0] + ny * axes[1][1])


def _clip(rc, r_axes, rh, k, n, ic, i_axes, ih, separation, margin):  # noqa: ANN001, ANN202
    """Incident face of box I clipped against reference face k of box R (normal n, R -> I)."""
    nx, ny = n
    fx, fy = rc[0] + nx * rh[k], rc[1] + ny * rh[k]  # reference face centre
    tx, ty = r_axes[1 - k]
    ht = rh[1 - k]
    du = nx * i_axes[0][0] + ny * i_axes[0][1]
    dv = nx * i_axes[1][0] + ny * i_axes[1][1]
    if abs(du) >= abs(dv):  # incident face normal along I's length axis
        s = -1.0 if du > 0 else 1.0
        cx, cy = ic[0] + s * ih[0] * i_axes[0][0], ic[1] + s * ih[0] * i_axes[0][1]
        (ex, ey), he = i_axes[1], ih[1]
    else:
        s = -1.0 if dv > 0 else 1.0
        cx, cy = ic[0] + s * ih[1] * i_axes[1][0], ic[1] + s * ih[1] * i_axes[1][1]
        (ex, ey), he = i_axes[0], ih[0]
    p1 = (cx + ex * he, cy + ey * he)
    p2 = (cx - ex * he, cy - ey * he)
    t1 = (p1[0] - fx) * tx + (p1[1] - fy) * ty
    t2 = (p2[0] - fx) * tx + (p2[1] - fy) * ty
    lo, hi = 0.0, 1.0
    dt = t2 - t1
    if abs(dt) > 1e-12:
        l1, l2 = (-ht - t1) / dt, (ht - t1) / dt
        lo, hi = max(lo, min(l1, l2)), min(hi, max(l1, l2))
    elif abs(t1) > ht:
        lo, hi = 1.0, 0.0
    rows = []
    if lo <= hi:
        for lam in (lo, hi) if hi - lo > 1e-9 else (lo,):
            px, py = p1[0] + lam * (p2[0] - p1[0]), p1[1] + lam * (p2[1] - p1[1])
            d = (px - fx) * nx + (py - fy) * ny
            if d < margin:
                rows.append((d, px - 0.5 * d * nx, py - 0.5 * d * ny, nx, ny))
    if not rows:
        # Corner beyond the reference face's extent: I's support point against n.
        su = -1.0 if du > 0 else 1.0
        sv = -1.0 if dv > 0 else 1.0
        px = ic[0] + su * ih[0] * i_axes[0][0] + sv * ih[1] * i_axes[1][0]
        py = ic[1] + su * ih[0] * i_axes[0][1] + sv * ih[1] * i_axes[1][1]
        rows.append((separation, px - 0.5 * separation * nx, py - 0.5 * separation * ny, nx, ny))
    return rows


def rect_disc(
    c: tuple[float, float], yaw: float, h: tuple[float, float],
    p: tuple[float, float], r: float, margin: float,
) -> list[tuple[float, float, float, float, float]]:  # fmt: skip
    """Contact of a rectangle and a disc; rows (dist, px, py, nx, ny), normal from rectangle to disc."""
    cs, sn = math.cos(yaw), math.sin(yaw)
    rx, ry = p[0] - c[0], p[1] - c[1]
    u, v = cs * rx + sn * ry, -sn * rx + cs * ry  # disc centre in the rectangle's frame
    qu, qv = min(max(u, -h[0]), h[0]), min(max(v, -h[1]), h[1])
    if qu != u or qv != v:
        du, dv = u - qu, v - qv
        norm = math.hypot(du, dv)
        dist = norm - r
        if dist >= margin:
            return []
        mu, mv = du / norm, dv / norm
    else:  # centre inside: out through the nearest face
        gap_u, gap_v = h[0] - abs(u), h[1] - abs(v)
        if gap_u <= gap_v:
            mu, mv = (1.0 if u >= 0 else -1.0), 0.0
            qu, dist = mu * h[0], -gap_u - r
        else:
            mu, mv = 0.0, (1.0 if v >= 0 else -1.0)
            qv, dist = mv * h[1], -gap_v - r
    nx, ny = cs * mu - sn * mv, sn * mu + cs * mv
    sx, sy = c[0] + cs * qu - sn * qv, c[1] + sn * qu + cs * qv  # rectangle's surface point
    return [(dist, sx + 0.5 * dist * nx, sy + 0.5 * dist * ny, nx, ny)]


def disc_disc(
    pa: tuple[float, float], ra: float, pb: tuple[float, float], rb: float, margin: float
) -> list[tuple[float, float, float, float, float]]:
    """Contact of two discs; rows (dist, px, py, nx, ny), normal from a to b."""
    dx, dy = pb[0] - pa[0], pb[1] - pa[1]
    norm = math.hypot(dx, dy)
    dist = norm - ra - rb
    if dist >= margin:
        return []
    nx, ny = (dx / norm, dy / norm) if norm > 1e-12 else (1.0, 0.0)
    sx, sy = pa[0] + ra * nx, pa[1] + ra * ny
    return [(dist, sx + 0.5 * dist * nx, sy + 0.5 * dist * ny, nx, ny)]


class Collider:
    """Contacts between planar bodies and static boxes, broad phase in numpy.

    Args:
        half_extents: (n, 2) half length and half width of every body [m].
        round_: (n,) True for discs (radius: half the smaller extent).
        motorised: (n,) True for bodies that touch kerbs.
        statics: the static boxes.
    """

    def __init__(
        self, half_extents: np.ndarray, round_: np.ndarray, motorised: np.ndarray, statics: Sequence[Box2D]
    ) -> None:
        self.half = np.asarray(half_extents, dtype=float).reshape(-1, 2)
        self.round = np.asarray(round_, dtype=bool)
        self.radius = np.where(self.round, self.half.min(axis=1), np.hypot(self.half[:, 0], self.half[:, 1]))
        #: Half extents of the boxes of the separating-axis pre-check (a disc as its square).
        self.box_half = np.where(self.round[:, None], self.radius[:, None], self.half)
        self.motorised = np.asarray(motorised, dtype=bool)
        self.statics = tuple(statics)
        #: See ``contacts``.
        self.time_to_touch = math.inf
        n = len(self.half)
        self.pair_i, self.pair_j = np.triu_indices(n, 1)
        #: (n,) bodies that take part in contacts (a recorded road user out of the world does not).
        self.enabled = np.ones(n, dtype=bool)
        #: (pairs,) body pairs that may touch (``exclude`` removes some).
        self.pair_allowed = np.ones(self.pair_i.size, dtype=bool)
        if self.statics:
            s = self.statics
            self.s_center = np.array([[b.x, b.y] for b in s])
            self.s_cos = np.array([math.cos(b.yaw) for b in s])
            self.s_sin = np.array([math.sin(b.yaw) for b in s])
            self.s_half = np.array([[b.half_length, b.half_width] for b in s])
            self.s_pose = np.array([[b.x, b.y, b.yaw] for b in s])
            kerb = np.array([b.kerb for b in s])
            self.s_allowed = ~kerb[None, :] | self.motorised[:, None]  # (n, s)

    def exclude(self, pairs: Sequence[tuple[int, int]]) -> None:
        """Bodies of each pair (entity indices) never touch each other."""
        n = len(self.half)
        for a, b in pairs:
            i, j = min(a, b), max(a, b)
            k = i * n - i * (i + 1) // 2 + (j - i - 1)  # index of (i, j) in triu_indices(n, 1)
            self.pair_allowed[k] = False

    def contacts(
        self,
        qpos: np.ndarray,
        reach: np.ndarray | float = 0.0,
        base: float = 0.0,
        speed: np.ndarray | None = None,
    ) -> Contacts:
        """Contact points closer than a pair's margin (0: penetrating points only).

        Args:
            qpos: (n, 3) x, y, yaw of every body.
            reach: (n,) or scalar look-ahead of each body [m].
            base: look-ahead of every pair [m]; a pair's margin is ``base`` plus its
                bodies' ``reach`` (a static box adds none).
            speed: (n,) bound of the speed of each body's points [m/s]; with it,
                ``time_to_touch`` is set.

        ``time_to_touch``: a lower bound of the time before any two bodies (or a body and
        a box) can touch, from a lower bound of each pair's distance (bounding circles,
        then separating axes) and their speeds and ``ACCEL_BOUND`` [s].
        """
        n = len(self.half)
        reach = np.broadcast_to(np.asarray(reach, dtype=float), (n,))
        rows: list[tuple[float, ...]] = []
        soonest = math.inf
        if n > 1:
            i, j = self.pair_i, self.pair_j
            gap = np.hypot(qpos[j, 0] - qpos[i, 0], qpos[j, 1] - qpos[i, 1]) - self.radius[i] - self.radius[j]
            gap = np.where(self.pair_allowed & self.enabled[i] & self.enabled[j], gap, math.inf)
            margin = base + reach[i] + reach[j]
            near = np.flatnonzero(gap < margin)
            if near.size:
                # Separating axes of the boxes (discs as squares), all near pairs at once.
                a, b = i[near], j[near]
                gap[near] = _box_separation(qpos[a], self.box_half[a], qpos[b], self.box_half[b])
                for k in near[gap[near] < margin[near]].tolist():
                    self._body_pair(qpos, int(i[k]), int(j[k]), float(margin[k]), rows)
            if speed is not None:
                soonest = _time_to_close(gap, speed[i] + speed[j], 2.0 * ACCEL_BOUND)
        if self.statics:
            gap_s = self._statics(qpos, base + reach, rows)
            if speed is not None:
                soonest = min(soonest, _time_to_close(gap_s, speed[:, None], ACCEL_BOUND))
        self.time_to_touch = soonest
        return Contacts.from_rows(rows)

    def _body_pair(self, qpos: np.ndarray, a: int, b: int, margin: float, rows: list) -> None:
        pa, pb = (float(qpos[a, 0]), float(qpos[a, 1])), (float(qpos[b, 0]), float(qpos[b, 1]))
        if self.round[a] and self.round[b]:
            found = disc_disc(pa, self.radius[a], pb, self.radius[b], margin)
        elif self.round[b]:
            found = rect_disc(pa, float(qpos[a, 2]), self.half[a], pb, self.radius[b], margin)
        elif self.round[a]:
            flipped = rect_disc(pb, float(qpos[b, 2]), self.half[b], pa, self.radius[a], margin)
            found = [(d, px, py, -nx, -ny) for d, px, py, nx, ny in flipped]
        else:
            ya, yb = float(qpos[a, 2]), float(qpos[b, 2])
            found = rect_rect(pa, ya, self.half[a], pb, yb, self.half[b], margin)
        rows.extend((a, b, -1, d, px, py, nx, ny) for d, px, py, nx, ny in found)

    def _statics(self, qpos: np.ndarray, margin: np.ndarray, rows: list) -> np.ndarray:
        """Contacts of bodies with static boxes (appended to ``rows``); returns (n, s) distance bounds."""
        # Distance from each body's centre to each box, minus the body's bounding radius.
        rx = qpos[:, 0, None] - self.s_center[None, :, 0]
        ry = qpos[:, 1, None] - self.s_center[None, :, 1]
        u = np.abs(self.s_cos * rx + self.s_sin * ry) - self.s_half[:, 0]
        v = np.abs(-self.s_sin * rx + self.s_cos * ry) - self.s_half[:, 1]
        outside = np.hypot(np.maximum(u, 0.0), np.maximum(v, 0.0)) + np.minimum(np.maximum(u, v), 0.0)
        allowed = self.s_allowed & self.enabled[:, None]
        gap = np.where(allowed, outside - self.radius[:, None], math.inf)
        body, box = np.nonzero(gap < margin[:, None])
        if body.size:
            pose, half = self.s_pose[box], self.s_half[box]
            gap[body, box] = _box_separation(qpos[body], self.box_half[body], pose, half)
            keep = gap[body, box] < margin[body]
            for b_, s_ in zip(body[keep].tolist(), box[keep].tolist(), strict=True):
                self._static_pair(qpos, b_, s_, float(margin[b_]), rows)
        return gap

    def _static_pair(self, qpos: np.ndarray, body: int, box: int, margin: float, rows: list) -> None:
        s = self.statics[box]
        p = (float(qpos[body, 0]), float(qpos[body, 1]))
        centre, half = (s.x, s.y), (s.half_length, s.half_width)
        if self.round[body]:
            flipped = rect_disc(centre, s.yaw, half, p, self.radius[body], margin)
            found = [(d, px, py, -nx, -ny) for d, px, py, nx, ny in flipped]
        else:
            found = rect_rect(p, float(qpos[body, 2]), self.half[body], centre, s.yaw, half, margin)
        rows.extend((body, STATIC, box, d, px, py, nx, ny) for d, px, py, nx, ny in found)


def _time_to_close(gap: np.ndarray, speed: np.ndarray, accel: float) -> float:
    """Least time in which any pair can close its gap: gap = speed t + accel t^2 / 2 [s]."""
    gap = np.clip(gap, 0.0, 1e6)  # pairs that never touch have an infinite gap
    t = 2.0 * gap / (speed + np.sqrt(speed * speed + 2.0 * accel * gap) + 1e-300)
    return float(t.min()) if t.size else math.inf


def _box_separation(pa: np.ndarray, ha: np.ndarray, pb: np.ndarray, hb: np.ndarray) -> np.ndarray:
    """Largest separation over the four axes of pairs of boxes (poses (k, 3), halves (k, 2)) [m].

    Positive: apart by at least that much; negative: the penetration depth.
    """
    ca, sa = np.cos(pa[:, 2]), np.sin(pa[:, 2])
    cb, sb = np.cos(pb[:, 2]), np.sin(pb[:, 2])
    c = np.abs(ca * cb + sa * sb)  # |cos| of the relative heading
    s = np.abs(sa * cb - ca * sb)  # |sin|
    dx, dy = pb[:, 0] - pa[:, 0], pb[:, 1] - pa[:, 1]
    return np.maximum.reduce(
        [
            np.abs(ca * dx + sa * dy) - ha[:, 0] - hb[:, 0] * c - hb[:, 1] * s,
            np.abs(-sa * dx + ca * dy) - ha[:, 1] - hb[:, 0] * s - hb[:, 1] * c,
            np.abs(cb * dx + sb * dy) - hb[:, 0] - ha[:, 0] * c - ha[:, 1] * s,
            np.abs(-sb * dx + cb * dy) - hb[:, 1] - ha[:, 0] * s - ha[:, 1] * c,
        ]
    )


__all__ = [
    "ACCEL_BOUND",
    "NO_CONTACTS",
    "STATIC",
    "Box2D",
    "Collider",
    "Contacts",
    "disc_disc",
    "rect_disc",
    "rect_rect",
]
