"""The road edge as a body: where a plan that leaves the road would be, and how hard it hits.

The planner treats every edge of the drivable area as a wall (the world lines its roads
with wall or kerb boxes just outside the drivable area; both stop a car in its planar
physics). A candidate's positions beyond the edge are not where the car would be, so:

- **Pressed positions** (``physical_view``): at every step at which a candidate's
  footprint crosses the edge, the footprint is pushed back inside along the edge's
  normal, keeping the plan's heading: the car presses against the wall, turned as its
  tracking controller turns it, and its tangential progress is the plan's. Its speed
  there is the plan's speed along the wall, v |sin(heading, normal)| (the normal
  component is what the wall takes). The risk of every other road user, the predicted
  collisions (validity level 1) and the responsibilities are evaluated on these
  positions; the comfort and mobility costs, the road-edge test (level 2) and the
  executed plan stay the plan's own.
- **Impact speed** (``edge_impact_speed``): the boundary harm is the harm of a plastic
  impact on a rigid wall at the plan's speed *into* the edge, v max(0, -(heading .
  normal)), at the first step at which the plan leaves the road (a head-on plan: its
  full speed, as the paper prices every exit; a plan grazing the wall: the harm
  curve's floor at zero speed, 0.010 with the default coefficients).

Both come from one push-back: the deepest footprint corner beyond the edge is moved to
its nearest point on the edge, and that vector is the centre's shift (exact for a
straight edge; a second pass handles a footprint across two edges, e.g. a corner).
Approximations: the wall's friction is ignored (the car keeps its plan's tangential
speed, which overstates the risk it carries along the wall), the impact's spin is
ignored, and each step is pushed back on its own (a plan that returns to the road is
back on its own positions at once).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import shapely

from ethical_planner.environment import RoadEnvironment
from ethical_planner.geometry import rectangle_corners
from ethical_planner.jit import kernel
from ethical_planner.risk import outside_drivable_area
from ethical_planner.road_users import Shape
from ethical_planner.sampling import Candidates

#: Push-back passes: the second one takes a footprint out of a second edge (a corner).
_PASSES = 2
#: Shifts below this are none [m] (a corner on the edge).
_MIN_SHIFT = 1e-9
#: A pushed-back corner goes this much further than the edge, to lie inside [m].
_NUDGE = 1e-9
#: The edge's polyline is simplified within this tolerance [m] before the nearest-point
#: search: a road's edge sampled every metre along a straight line becomes one segment.
_EDGE_TOLERANCE = 0.005
_EDGES: dict[int, tuple[object, np.ndarray]] = {}


def _edge_segments(area: shapely.Geometry) -> np.ndarray:
    """The area's boundary (holes included) as segments (x0, y0, x1, y1), shape (m, 4), cached per area."""
    cached = _EDGES.get(id(area))
    if cached is None or cached[0] is not area:
        if len(_EDGES) >= 8:
            _EDGES.clear()
        simple = shapely.simplify(area, _EDGE_TOLERANCE)
        rings = [r for part in getattr(simple, "geoms", (simple,)) for r in (part.exterior, *part.interiors)]
        segments = np.concatenate(
            [np.concatenate([c[:-1], c[1:]], axis=1) for c in (np.asarray(r.coords) for r in rings)]
        )
        # The entry keeps ``area`` alive, so its id cannot be reused while cached.
        cached = _EDGES[id(area)] = (area, np.ascontiguousarray(segments))
    return cached[1]


@kernel
def _nearest_on_segments(
    px: np.ndarray, py: np.ndarray, segments: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest point on any segment of each point: a scan of every segment per point.

    Args:
        px, py: points [m], shape (q,).
        segments: (x0, y0, x1, y1) [m], shape (m, 4), m >= 1, no segment of zero length.

    Returns:
        (qx, qy) [m], shape (q,) each.
    """
    q = px.size
    qx, qy = np.empty(q), np.empty(q)
    for i in range(q):
        best = np.inf
        for j in range(segments.shape[0]):
            ax, ay = segments[j, 0], segments[j, 1]
            ux, uy = segments[j, 2] - ax, segments[j, 3] - ay
            t = ((px[i] - ax) * ux + (py[i] - ay) * uy) / (ux * ux + uy * uy)
            t = min(max(t, 0.0), 1.0)
            nx, ny = ax + t * ux, ay + t * uy
            d = (px[i] - nx) ** 2 + (py[i] - ny) ** 2
            if d < best:
                best, qx[i], qy[i] = d, nx, ny
    return qx, qy


def push_back(
    x: np.ndarray, y: np.ndarray, yaw: np.ndarray, shape: Shape, environment: RoadEnvironment
) -> tuple[np.ndarray, np.ndarray]:
    """Shift of each footprint's centre that brings it inside the drivable area.

    Per pass, the corner deepest beyond the edge is moved to its nearest point on the
    edge (the drivable area's boundary, holes included, simplified within 5 mm); that
    vector shifts the centre.

    Args:
        x, y, yaw: footprint poses [m, m, rad], shape (q,).
        shape: the footprint [m].
        environment: the road.

    Returns:
        (dx, dy) [m], shape (q,) each; 0 for a footprint inside the area.
    """
    area = environment.drivable_area
    dx, dy = np.zeros(x.shape), np.zeros(x.shape)
    active = np.arange(x.size)
    for _ in range(_PASSES):
        cx, cy = rectangle_corners(
            x[active] + dx[active], y[active] + dy[active], yaw[active], shape.length, shape.width
        )
        out = ~shapely.contains_xy(area, cx, cy)  # (q, 4)
        hit = out.any(axis=1)
        if not hit.any():
            break
        active, cx, cy, out = active[hit], cx[hit], cy[hit], out[hit]
        px, py = _nearest_on_segments(cx[out], cy[out], _edge_segments(area))
        ex, ey = np.zeros(cx.shape), np.zeros(cx.shape)
        ex[out], ey[out] = px - cx[out], py - cy[out]
        deepest = np.argmax(ex * ex + ey * ey, axis=1)[:, None]
        sx = np.take_along_axis(ex, deepest, axis=1)[:, 0]
        sy = np.take_along_axis(ey, deepest, axis=1)[:, 0]
        # A hair further, so that the corner lies inside rather than on the edge (where
        # the point-in-polygon test is slow and says "outside").
        scale = 1.0 + _NUDGE / np.maximum(np.hypot(sx, sy), _NUDGE)
        dx[active] += sx * scale
        dy[active] += sy * scale
    return dx, dy


def _inward_normal(dx: np.ndarray, dy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit vector of each shift and whether there is one (shift > _MIN_SHIFT)."""
    length = np.hypot(dx, dy)
    pushed = length > _MIN_SHIFT
    safe = np.where(pushed, length, 1.0)
    return dx / safe, dy / safe, pushed


def physical_view(
    candidates: Candidates, rows: np.ndarray, shape: Shape, environment: RoadEnvironment
) -> tuple[Candidates, np.ndarray]:
    """The candidates as the car would drive them: pressed against the edge where they cross it.

    Only ``rows`` are looked at, from step 1 on (step 0 is the ego's present state,
    shared by every candidate). At each step at which a footprint crosses the edge, its
    centre is shifted by ``push_back`` (heading kept) and its speed becomes the plan's
    speed along the wall, v |t x n| (t the heading, n the edge normal), where the plan
    moves into the edge (v t . n < 0, n pointing into the road); a plan moving back
    out keeps its speed.

    Args:
        candidates: the cycle's candidates (plans).
        rows: candidates to look at, indices, shape (m,).
        shape: the ego's footprint [m].
        environment: the road.

    Returns:
        (view, pressed): the candidates with x, y, v replaced where pressed (the same
        object if no footprint crosses the edge), and the pressed steps, shape (n, n_t).
    """
    rows = np.asarray(rows, dtype=np.int64)
    pressed = np.zeros(candidates.x.shape, dtype=bool)
    if rows.size == 0:
        return candidates, pressed
    crossing = outside_drivable_area(candidates, shape, environment, 0.0, rows)
    crossing[:, 0] = False
    i, step = np.nonzero(crossing)
    if i.size == 0:
        return candidates, pressed
    row = rows[i]
    x, y = candidates.x[row, step], candidates.y[row, step]
    yaw, v = candidates.yaw[row, step], candidates.v[row, step]
    dx, dy = push_back(x, y, yaw, shape, environment)
    nx, ny, pushed = _inward_normal(dx, dy)
    along_normal = np.cos(yaw) * nx + np.sin(yaw) * ny
    into = pushed & (v * along_normal < 0.0)
    kept = np.where(into, v * np.sqrt(np.clip(1.0 - along_normal**2, 0.0, 1.0)), v)
    new_x, new_y, new_v = candidates.x.copy(), candidates.y.copy(), candidates.v.copy()
    new_x[row, step] = x + dx
    new_y[row, step] = y + dy
    new_v[row, step] = kept
    pressed[row, step] = pushed
    return replace(candidates, x=new_x, y=new_y, v=new_v), pressed


def edge_impact_speed(
    candidates: Candidates,
    rows: np.ndarray,
    outside: np.ndarray,
    shape: Shape,
    environment: RoadEnvironment,
    margin: float,
) -> np.ndarray:
    """Speed into the edge of each candidate at the first step it leaves the road [m/s].

    The normal is that of the push-back of the footprint grown by ``margin`` (the
    footprint the road-edge test judges, ``risk.outside_drivable_area``); the speed is
    v max(0, -(t . n)), t the heading and n the normal pointing into the road. Where
    no edge is crossed at that step (a plan that ends crowding debris,
    ``terminal.crowds_static_obstacle``, marks its last step without leaving), the
    full speed: a head-on impact.

    Args:
        candidates: the cycle's candidates (plans).
        rows: candidates, indices, shape (m,).
        outside: their steps off the road, shape (m, n_t) (``outside_drivable_area``
            with ``margin``, as the planner judges it).
        shape: the ego's footprint [m].
        environment: the road.
        margin: the road-edge margin [m] of ``outside``.

    Returns:
        Shape (m,), 0 for a candidate that stays on the road.
    """
    rows = np.asarray(rows, dtype=np.int64)
    speed = np.zeros(rows.size)
    leaves = np.flatnonzero(outside.any(axis=1))
    if leaves.size == 0:
        return speed
    row = rows[leaves]
    first = outside[leaves].argmax(axis=1)
    yaw, v = candidates.yaw[row, first], np.abs(candidates.v[row, first])
    grown = Shape(shape.length + 2.0 * margin, shape.width + 2.0 * margin)
    dx, dy = push_back(candidates.x[row, first], candidates.y[row, first], yaw, grown, environment)
    nx, ny, pushed = _inward_normal(dx, dy)
    into = np.maximum(0.0, -(np.cos(yaw) * nx + np.sin(yaw) * ny))
    speed[leaves] = np.where(pushed, v * into, v)
    return speed
