"""Risk of candidates for every road user (paper Eqs. 3 and 4).

Shapes: m assessed candidates, k road users, t time steps. The collision probability
is integrated only where it can change a result: at triples that pass the distance gate,
and among those only where an upper bound of p H does not show that the maximum over
time (Eq. 3), maximin's set (p > epsilon) or the responsibility's onset stays as it is
(``collision_probability.risk_maximum``). Harm is evaluated at the gated triples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from ethical_planner.collision_probability import (
    CollisionProbability,
    OctagonTables,
    RiskMaximum,
    collision_probability,
    empty_tables,
    gate,
    octagon_tables,
    risk_maximum,
)
from ethical_planner.config import RiskConfig
from ethical_planner.environment import RoadEnvironment
from ethical_planner.geometry import CORNER_ACROSS, CORNER_ALONG, rectangle_corners
from ethical_planner.harm import HarmModel, boundary_harm, collision_harm, collision_harm_at
from ethical_planner.impulse import DeltaVModel
from ethical_planner.jit import kernel
from ethical_planner.prediction.base import Prediction
from ethical_planner.road_users import RoadUserType, Shape
from ethical_planner.sampling import Candidates, every_row
from ethical_planner.workers import Workers


@dataclass(frozen=True, slots=True, eq=False)
class RiskAssessment:
    """Risk of the assessed candidates, per (candidate, road user) pair and per candidate.

    Attributes:
        rows: the assessed candidates' indices in the cycle's candidate set, shape (m,).
        risk_obs: R_k = max_t p H_obs, shape (m, k) (Eq. 3).
        risk_ego: R_ego,k = max_t p H_ego, shape (m, k).
        maximin_harm_obs: highest harm of road user k at a step where its collision
            probability exceeds maximin's epsilon, 0 if none, shape (m, k) (Eq. 10).
        maximin_harm_ego: the ego's harm in those collisions, shape (m, k).
        peak_probability: highest p_k(t), shape (m, k); exact with ``onset``.
        onset_step: first step at which p_k reaches half its peak, shape (m, k) (with
            ``onset``; 0 otherwise and where p is 0 throughout).
        leaves_road: the footprint leaves the drivable area at some step, shape (m,).
        boundary_risk: harm of hitting a wall where the candidate leaves the road (p = 1),
            at its speed into the edge there (``boundary.edge_impact_speed``), shape (m,).
        ego_combined: R_ego(u) = 1 - prod(1 - R_ego,k) incl. the boundary, shape (m,) (Eq. 4).
        triples: (candidate, road user, step) triples that passed the distance gate.
        integrals: collision-probability integrals evaluated among them.
    """

    rows: np.ndarray
    risk_obs: np.ndarray
    risk_ego: np.ndarray
    maximin_harm_obs: np.ndarray
    maximin_harm_ego: np.ndarray
    peak_probability: np.ndarray
    onset_step: np.ndarray
    leaves_road: np.ndarray
    boundary_risk: np.ndarray
    ego_combined: np.ndarray
    triples: int
    integrals: int


@dataclass(frozen=True, slots=True, eq=False)
class RiskDetail:
    """Every step of one candidate: what the decision record shows of the chosen plan.

    Attributes:
        probability: p_k(t), shape (k, t), evaluated at every step that passes the gate.
        harm_obs: harm of road user k if it collides at t, shape (k, t) (0 where p = 0).
        harm_ego: the ego's harm in that collision, shape (k, t).
    """

    probability: np.ndarray
    harm_obs: np.ndarray
    harm_ego: np.ndarray


#: Extra inward margin [m] of the eroded drivable area, above the sagitta of shapely's
#: arc approximation (r (1 - cos(pi / 32)) < 0.5 % of r at quad_segs = 8) and rounding.
_ERODE_MARGIN = 0.05
_ERODED: dict[tuple[int, float], tuple[object, object, _InsideGrid | None]] = {}
#: The drivable areas' own grids (``_area_grid``), by id, with the area kept alive.
_AREA_GRIDS: dict[int, tuple[object, _InsideGrid | None]] = {}
#: Cells of an ``_InsideGrid`` (about: rounded up per axis), and their smallest edge [m].
_GRID_CELLS = 40_000
_GRID_MIN_CELL = 0.5
#: Slack [m] of a grid cell's box beyond the cell: more than the rounding of the cell index.
_GRID_SLACK = 1e-6


@dataclass(frozen=True, slots=True, eq=False)
class _InsideGrid:
    """Square cells over a polygon's bounds, marked where the whole cell lies in its interior or outside it.

    A fast path for ``shapely.contains_xy``: a point in an inside cell is contained, a
    point in an outside cell is not; the others (cells the boundary crosses, points off
    the grid inside the polygon's bounds) need the exact test. A cell is inside if
    its box, grown by _GRID_SLACK, lies in the polygon's interior (``contains_properly``:
    no boundary contact), and outside if that grown box is disjoint from the polygon
    (no contact either), so rounding of a point's cell index cannot put a point in a
    cell of the wrong kind. A point beyond the polygon's bounds (compared exactly, not
    through a cell index) is outside.

    Attributes:
        x0, y0: the grid's lower-left corner, the polygon's lower bounds [m].
        x1, y1: the polygon's upper bounds [m]. cell: cell edge [m].
        inside: cells in the interior, shape (ny, nx).
        outside: cells disjoint from the polygon, shape (ny, nx).
    """

    x0: float
    y0: float
    x1: float
    y1: float
    cell: float
    inside: np.ndarray
    outside: np.ndarray

    @classmethod
    def of(cls, polygon: shapely.Geometry) -> _InsideGrid | None:
        """The grid of a prepared polygon (None if it is empty)."""
        if polygon.is_empty:
            return None
        x0, y0, x1, y1 = polygon.bounds
        cell = max(_GRID_MIN_CELL, math.sqrt((x1 - x0) * (y1 - y0) / _GRID_CELLS))
        nx, ny = max(1, math.ceil((x1 - x0) / cell)), max(1, math.ceil((y1 - y0) / cell))
        ix, iy = np.meshgrid(np.arange(nx), np.arange(ny))
        left, bottom = x0 + ix * cell - _GRID_SLACK, y0 + iy * cell - _GRID_SLACK
        boxes = shapely.box(left, bottom, left + cell + 2 * _GRID_SLACK, bottom + cell + 2 * _GRID_SLACK)
        inside = shapely.contains_properly(polygon, boxes)
        return cls(x0, y0, x1, y1, cell, inside, shapely.disjoint(polygon, boxes))

    def state(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """1 where the point lies in an inside cell, 0 in an outside cell, -1 elsewhere, shape of ``x``."""
        result = np.empty(x.shape, dtype=np.int8)
        _cell_state(
            np.ascontiguousarray(x, dtype=float).reshape(-1),
            np.ascontiguousarray(y, dtype=float).reshape(-1),
            np.array([self.x0, self.y0, self.x1, self.y1]),
            self.cell,
            self.inside,
            self.outside,
            result.reshape(-1),
        )
        return result

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """True where the point lies in an inside cell (so in the polygon), shape of ``x``."""
        return self.state(x, y) == 1


@kernel
def _cell_state(
    x: np.ndarray,
    y: np.ndarray,
    bounds: np.ndarray,
    cell: float,
    inside: np.ndarray,
    outside: np.ndarray,
    out: np.ndarray,
) -> None:
    """Kernel of ``_InsideGrid.state``: out (m,) 1, 0 or -1 (inside, outside, undecided).

    1 in an inside cell, 0 in an outside one or beyond ``bounds`` (x0, y0, x1, y1). The
    cell indices are floor((x - x0) / cell) and floor((y - y0) / cell); a point off the
    grid within the bounds (or NaN) is in no cell.
    """
    ny, nx = inside.shape
    x0, y0, x1, y1 = bounds[0], bounds[1], bounds[2], bounds[3]
    for i in range(x.size):
        if x[i] < x0 or x[i] > x1 or y[i] < y0 or y[i] > y1:
            out[i] = 0
            continue
        ix = np.floor((x[i] - x0) / cell)
        iy = np.floor((y[i] - y0) / cell)
        out[i] = -1
        if ix >= 0 and ix < nx and iy >= 0 and iy < ny:
            if inside[int(iy), int(ix)]:
                out[i] = 1
            elif outside[int(iy), int(ix)]:
                out[i] = 0


def _eroded_area(area: shapely.Geometry, radius: float) -> tuple[shapely.Geometry, _InsideGrid | None]:
    """``area`` shrunk by ``radius`` [m] plus a margin, prepared, and its grid; cached per area object."""
    key = (id(area), radius)
    cached = _ERODED.get(key)
    if cached is None or cached[0] is not area:
        if len(_ERODED) >= 8:
            _ERODED.clear()
        inner = area.buffer(-(radius * 1.01 + _ERODE_MARGIN))
        shapely.prepare(inner)
        # The entry keeps ``area`` alive, so its id cannot be reused while cached.
        cached = _ERODED[key] = (area, inner, _InsideGrid.of(inner))
    return cached[1], cached[2]


def _area_grid(area: shapely.Geometry) -> _InsideGrid | None:
    """The grid of ``area`` itself (``_InsideGrid``), cached per area object."""
    cached = _AREA_GRIDS.get(id(area))
    if cached is None or cached[0] is not area:
        if len(_AREA_GRIDS) >= 8:
            _AREA_GRIDS.clear()
        # The entry keeps ``area`` alive, so its id cannot be reused while cached.
        cached = _AREA_GRIDS[id(area)] = (area, _InsideGrid.of(area))
    return cached[1]


def _contains(
    polygon: shapely.Geometry, grid: _InsideGrid | None, x: np.ndarray, y: np.ndarray
) -> np.ndarray:
    """``shapely.contains_xy(polygon, x, y)``; the exact test only for points ``grid`` leaves undecided."""
    if grid is None:
        return shapely.contains_xy(polygon, x, y)
    state = grid.state(x, y)
    result = state == 1
    rest = np.flatnonzero(state < 0)
    if rest.size:
        result.ravel()[rest] = shapely.contains_xy(polygon, x.ravel()[rest], y.ravel()[rest])
    return result


def _corners_inside(
    area: shapely.Geometry, x: np.ndarray, y: np.ndarray, yaw: np.ndarray, shape: Shape
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The footprints' corners (``rectangle_corners``) and whether all four lie in ``area``.

    The corners and their cells (``_InsideGrid.state`` of the area's grid) in one
    compiled pass; shapely tests only the undecided corners of footprints that have no
    corner in an outside cell (one such corner already puts the footprint outside).

    Args:
        area: the drivable area. x, y, yaw: centres [m] and headings [rad], shape (m,).
        shape: the footprint.

    Returns:
        (cx, cy, inside): corners [m], shape (m, 4) each, as ``rectangle_corners`` gives
        them; whether every corner lies in ``area`` (``shapely.contains_xy``), shape (m,).
    """
    grid = _area_grid(area)
    if grid is None:
        cx, cy = rectangle_corners(x, y, yaw, shape.length, shape.width)
        return cx, cy, np.all(shapely.contains_xy(area, cx, cy), axis=-1)
    cx = np.empty((x.size, 4))
    cy = np.empty((x.size, 4))
    state = np.empty((x.size, 4), dtype=np.int8)
    _corner_states(
        np.ascontiguousarray(x, dtype=float),
        np.ascontiguousarray(y, dtype=float),
        np.cos(yaw),
        np.sin(yaw),
        0.5 * float(shape.length) * CORNER_ALONG,
        0.5 * float(shape.width) * CORNER_ACROSS,
        np.array([grid.x0, grid.y0, grid.x1, grid.y1]),
        grid.cell,
        grid.inside,
        grid.outside,
        cx,
        cy,
        state,
    )
    open_rows = ~(state == 0).any(axis=1)
    rest = np.flatnonzero((state < 0) & open_rows[:, None])
    if rest.size:
        state.ravel()[rest] = shapely.contains_xy(area, cx.ravel()[rest], cy.ravel()[rest])
    return cx, cy, (state == 1).all(axis=1)


@kernel
def _corner_states(
    x: np.ndarray,
    y: np.ndarray,
    cos_yaw: np.ndarray,
    sin_yaw: np.ndarray,
    half_l: np.ndarray,
    half_w: np.ndarray,
    bounds: np.ndarray,
    cell: float,
    inside: np.ndarray,
    outside: np.ndarray,
    cx: np.ndarray,
    cy: np.ndarray,
    state: np.ndarray,
) -> None:
    """Kernel of ``_corners_inside``: the corners (m, 4) and their ``_cell_state`` (m, 4).

    The corners as ``rectangle_corners`` computes them: x + c l - s w and y + s l + c w,
    in that order.
    """
    for i in range(x.size):
        c, s = cos_yaw[i], sin_yaw[i]
        for j in range(4):
            cx[i, j] = x[i] + c * half_l[j] - s * half_w[j]
            cy[i, j] = y[i] + s * half_l[j] + c * half_w[j]
        _cell_state(cx[i], cy[i], bounds, cell, inside, outside, state[i])


def outside_drivable_area(
    candidates: Candidates,
    shape: Shape,
    environment: RoadEnvironment,
    margin: float = 0.0,
    rows: np.ndarray | None = None,
) -> np.ndarray:
    """True where the ego footprint comes within ``margin`` [m] of the edge, shape (n, t).

    The footprint grown by ``margin`` on every side must lie inside the drivable area:
    a plan that skims the kerb is not executable by a controller with a tracking error
    and a body that yaws. A centre inside the area shrunk by the grown footprint's
    half-diagonal has all corners inside, so only the other centres (near the road
    edge) get the corner test; if the area has holes (debris on the road), footprints
    with all corners inside then get the exact polygon containment test.

    Args:
        candidates: anything with x, y, yaw arrays of shape (n, t) [m, rad].
        shape: the ego's footprint.
        environment: the road.
        margin: [m].
        rows: only these candidates (the result then has shape (len(rows), t)).
    """
    area = environment.drivable_area
    shape = Shape(shape.length + 2.0 * margin, shape.width + 2.0 * margin)
    half_diagonal = 0.5 * float(np.hypot(shape.length, shape.width))
    x, y, yaw = candidates.x, candidates.y, candidates.yaw
    if rows is not None and not every_row(np.asarray(rows), x.shape[0]):
        x, y, yaw = x[rows], y[rows], yaw[rows]
    deep = _contains(*_eroded_area(area, half_diagonal), x, y)
    outside = np.zeros(x.shape, dtype=bool)
    edge = np.flatnonzero(~deep)
    if edge.size:
        poses = (x.ravel()[edge], y.ravel()[edge], yaw.ravel()[edge])
        cx, cy, corners_in = _corners_inside(area, *poses, shape)
        holes = _holes(area)
        if holes is not None and corners_in.any():
            # A hole (debris) smaller than the footprint can lie between its corners:
            # footprints with all corners inside and near a hole get the exact test.
            near = np.flatnonzero(corners_in)
            px, py = x.ravel()[edge[near]], y.ravel()[edge[near]]
            near = near[shapely.dwithin(holes, shapely.points(px, py), half_diagonal)]
            if near.size:
                ring = np.stack([cx[near], cy[near]], axis=-1)
                footprints = shapely.polygons(np.concatenate([ring, ring[:, :1]], axis=1))
                corners_in[near] = ~shapely.intersects(holes, footprints)
        outside.ravel()[edge] = ~corners_in
    return outside


def _components(prediction: Prediction) -> tuple[np.ndarray, ...]:
    """The prediction's Gaussians as road users of their own: (mean, cov, heading, length, width).

    A mixture's road user o's component c becomes virtual road user o * K + c (K = 1:
    the prediction's own arrays).
    """
    k = prediction.n_components
    if k == 1:
        return prediction.mean, prediction.cov, prediction.heading, prediction.length, prediction.width
    n_obs, n_t = prediction.mean.shape[:2]
    return (
        np.repeat(prediction.mean, k, axis=0),
        np.moveaxis(prediction.component_cov, 2, 1).reshape(n_obs * k, n_t, 2, 2),
        np.repeat(prediction.heading, k, axis=0),
        np.repeat(prediction.length, k),
        np.repeat(prediction.width, k),
    )


def prediction_collision_probability(
    candidates: Candidates,
    prediction: Prediction,
    ego_shape: Shape,
    gate_sigmas: float,
    workers: Workers | None = None,
    rows: np.ndarray | None = None,
) -> CollisionProbability:
    """Collision probabilities of every candidate with every predicted road user, every triple.

    A Gaussian-mixture prediction (K components with a shared mean) is integrated in
    one call with each component as a road user of its own; its probability is the
    weighted sum sum_k w_k(t) p_k(u, t), and the mean overlap that of the shared mean.

    Args:
        candidates: the cycle's candidates.
        prediction: the road users.
        ego_shape: the ego's footprint.
        gate_sigmas: see ``collision_probability``.
        workers: threads for large problems.
        rows: only these candidates (default all).

    Returns:
        Probabilities and mean overlaps, shape (n, n_obs, n_t) (n = len(rows) if given).
    """
    x, y, yaw = candidates.x, candidates.y, candidates.yaw
    if rows is not None:
        x, y, yaw = x[rows], y[rows], yaw[rows]
    k = prediction.n_components
    cp = collision_probability(
        x,
        y,
        yaw,
        ego_shape.length,
        ego_shape.width,
        *_components(prediction),
        gate_sigmas=gate_sigmas,
        workers=workers,
    )
    if k == 1:
        return cp
    n = x.shape[0]
    n_obs, n_t = prediction.mean.shape[:2]
    per_component = cp.probability.reshape(n, n_obs, k, n_t)
    probability = np.einsum("nokt,otk->not", per_component, prediction.component_weight)
    return CollisionProbability(np.clip(probability, 0.0, 1.0), cp.mean_overlap[:, ::k])


def _holes(area: shapely.Geometry) -> shapely.Geometry | None:
    """The interior rings of the drivable area (obstacles inside the road) as polygons, or None."""
    parts = getattr(area, "geoms", (area,))
    rings = [shapely.Polygon(r) for p in parts for r in p.interiors]
    if not rings:
        return None
    holes = shapely.union_all(rings)
    shapely.prepare(holes)
    return holes


def static_obstacles(environment: RoadEnvironment) -> shapely.Geometry | None:
    """The obstacles inside the road (debris): the drivable area's holes as polygons, or None."""
    return _holes(environment.drivable_area)


def prediction_tables(
    candidates: Candidates,
    rows: np.ndarray,
    prediction: Prediction,
    ego_shape: Shape,
    gate_sigmas: float,
) -> OctagonTables:
    """The octagon tables (``octagon_tables``) of candidates ``rows`` and the prediction.

    A mixture's components are the tables' components (``component_weight``): its p is
    the weighted sum of theirs, as in ``prediction_collision_probability``.
    """
    weight = prediction.component_weight if prediction.n_components > 1 else None
    if prediction.n_obs == 0 and weight is None:
        # The candidates' states are not read: spare gathering and checking them.
        return empty_tables(rows.size, candidates.t.size, gate_sigmas)
    x, y, yaw = candidates.x[rows], candidates.y[rows], candidates.yaw[rows]
    return octagon_tables(
        x,
        y,
        yaw,
        ego_shape.length,
        ego_shape.width,
        *_components(prediction),
        gate_sigmas=gate_sigmas,
        component_weight=weight,
    )


def assess_risk(
    candidates: Candidates,
    rows: np.ndarray,
    tables: OctagonTables,
    table_rows: np.ndarray,
    prediction: Prediction,
    ego_shape: Shape,
    ego_mass: float,
    outside: np.ndarray,
    config: RiskConfig,
    epsilon: float,
    onset: bool = False,
    workers: Workers | None = None,
    impact_speed: np.ndarray | None = None,
    cap: int = 0,
    triples: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> RiskAssessment:
    """Risk of candidates ``rows`` for every road user (Eqs. 3, 4) and maximin's harms.

    Delta-v by ``config.delta_v_model``: paper Eq. 1 or the planar impulse model
    (``ethical_planner.impulse``), whose contact comes from the two footprints.

    Args:
        candidates: the cycle's candidates.
        rows: the candidates to assess, indices into ``candidates``, shape (m,).
        tables: the octagon tables of the cycle for the prediction (``prediction_tables``).
        table_rows: the same candidates' rows in ``tables``, shape (m,).
        prediction: the k road users.
        ego_shape: the ego's footprint [m].
        ego_mass: [kg].
        outside: the ego footprint leaves the drivable area, shape (m, t)
            (``outside_drivable_area``).
        config: harm models, boundary harm.
        epsilon: maximin's collision-probability threshold (``CostWeights.maximin_epsilon``).
        onset: also find each pair's highest p and its onset exactly (responsibility).
        workers: threads for large problems (a planner passes its own).
        impact_speed: each candidate's speed into the road edge where it leaves the
            road [m/s], shape (m,) (``boundary.edge_impact_speed``); None: its speed
            at the first step off the road (the paper's head-on wall).
        cap: if > 0, at most this many integrals per (candidate, road user) pair
            (``collision_probability.risk_maximum``): R_k, R_ego,k, maximin's harms and R_ego
            are then lower bounds of the exact ones (the boundary risk stays exact).
        triples: the gated triples of ``rows`` and their harms, (flat, harm_obs,
            harm_ego) as ``gate`` and ``_triple_harms`` give them, if already known
            (``gated_triples``).
    """
    workers = Workers() if workers is None else workers
    rows = np.asarray(rows, dtype=np.int64)
    m = rows.size
    if tables.n_obs:
        if triples is None:
            triples = gated_triples(
                candidates, rows, tables, table_rows, prediction, ego_shape, ego_mass, config, workers
            )
        flat, harm_obs, harm_ego = triples
        maximum = risk_maximum(tables, table_rows, flat, harm_obs, harm_ego, epsilon, onset, workers, cap)
    else:  # no road user: no pair to integrate (what ``risk_maximum`` returns for none)
        none = np.zeros((m, 0))
        maximum = RiskMaximum(none, none, none, none, none, np.zeros((m, 0), dtype=np.int64), 0, 0)
    boundary = np.zeros(m)
    leaves = outside.any(axis=1)
    if config.boundary_harm and leaves.any():
        if impact_speed is None:
            impact_speed = candidates.v[rows, outside.argmax(axis=1)]
        boundary = np.where(leaves, boundary_harm(impact_speed), 0.0)
    survive = np.prod(1.0 - maximum.risk_ego, axis=1) * (1.0 - boundary)
    return RiskAssessment(
        rows=rows,
        risk_obs=maximum.risk_obs,
        risk_ego=maximum.risk_ego,
        maximin_harm_obs=maximum.maximin_harm_obs,
        maximin_harm_ego=maximum.maximin_harm_ego,
        peak_probability=maximum.peak_probability,
        onset_step=maximum.onset_step,
        leaves_road=leaves,
        boundary_risk=boundary,
        ego_combined=1.0 - survive,
        triples=maximum.triples,
        integrals=maximum.integrals,
    )


def gated_triples(
    candidates: Candidates,
    rows: np.ndarray,
    tables: OctagonTables,
    table_rows: np.ndarray,
    prediction: Prediction,
    ego_shape: Shape,
    ego_mass: float,
    config: RiskConfig,
    workers: Workers | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The triples of candidates ``rows`` that pass the gate and their harms (``assess_risk``).

    Returns:
        (flat, harm_obs, harm_ego): flat indices (i * k + obs) * n_t + step, i the
        position in ``rows``, ascending; the road user's and the ego's harm of each.
    """
    workers = Workers() if workers is None else workers
    rows = np.asarray(rows, dtype=np.int64)
    flat = gate(tables, table_rows)
    harm_obs, harm_ego = _triple_harms(
        candidates, rows, prediction, ego_mass, ego_shape, config, flat, workers
    )
    return flat, harm_obs, harm_ego


def subset_triples(
    triples: tuple[np.ndarray, np.ndarray, np.ndarray], positions: np.ndarray, m: int, per_row: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ``gated_triples`` of some of the m rows they were found for, renumbered.

    Args:
        triples: (flat, harm_obs, harm_ego) of m rows.
        positions: the rows kept, ascending positions in 0..m-1, shape (q,).
        m: rows of ``triples``.
        per_row: k * n_t, the flat indices per row.

    Returns:
        (flat, harm_obs, harm_ego) as ``gated_triples`` of the rows kept would give them.
    """
    flat, harm_obs, harm_ego = triples
    row = flat // per_row
    kept = np.zeros(m, dtype=bool)
    kept[positions] = True
    renumber = np.full(m, -1, dtype=np.int64)
    renumber[positions] = np.arange(positions.size)
    keep = kept[row]
    return renumber[row[keep]] * per_row + flat[keep] % per_row, harm_obs[keep], harm_ego[keep]


def risk_detail(
    candidates: Candidates,
    index: int,
    prediction: Prediction,
    ego_shape: Shape,
    ego_mass: float,
    config: RiskConfig,
) -> RiskDetail:
    """Collision probability and harm of candidate ``index`` at every step (the record).

    Every triple that passes the gate is integrated (``prediction_collision_probability``);
    the harms are those of ``assess_risk``, so the maximum over t of p H equals its R.
    """
    if prediction.n_obs == 0:
        empty = np.zeros((0, candidates.t.size))
        return RiskDetail(empty, empty.copy(), empty.copy())
    rows = np.array([index])
    p = prediction_collision_probability(
        candidates, prediction, ego_shape, config.gate_sigmas, Workers(1), rows
    )
    p = p.probability[0]
    harm_obs = np.zeros(p.shape)
    harm_ego = np.zeros(p.shape)
    flat = np.flatnonzero(p > 0.0)
    if flat.size:
        harm_obs.ravel()[flat], harm_ego.ravel()[flat] = _triple_harms(
            candidates, rows, prediction, ego_mass, ego_shape, config, flat, Workers(1)
        )
    return RiskDetail(p, harm_obs, harm_ego)


#: Triples per harm evaluation: the temporaries of ``collision_harm`` then stay small and
#: are reused instead of page-faulting. With two threads (from _HARM_PARALLEL_MIN triples
#: on) the chunks are a quarter of the work each: numpy must run long loops between
#: Python statements for two threads to pay off.
_HARM_CHUNK = 16384
_HARM_PARALLEL_MIN = 100_000


def _triple_harms(
    candidates: Candidates,
    rows: np.ndarray,
    prediction: Prediction,
    ego_mass: float,
    ego_shape: Shape,
    config: RiskConfig,
    flat: np.ndarray,
    workers: Workers,
) -> tuple[np.ndarray, np.ndarray]:
    """Harm of the road user and of the ego at triples (i, obs, step), in chunks.

    Args:
        candidates: the cycle's candidates.
        rows: candidate of each i, indices into ``candidates``, shape (m,).
        prediction: the k road users.
        ego_mass: [kg].
        ego_shape: the ego's footprint (used by the planar delta-v model).
        config: harm models.
        flat: flat triple indices (i * k + obs) * n_t + step, shape (q,).
        workers: threads for large problems.

    Returns:
        (harm_obs, harm_ego), shape (q,) each.
    """
    n_t = candidates.t.size
    k = prediction.n_obs
    if flat.size == 0:
        return np.zeros(0), np.zeros(0)
    if config.delta_v_model is DeltaVModel.EQ1:
        yaw, speed = candidates.yaw[rows], candidates.v[rows]
        ego = np.stack(
            [candidates.x[rows], candidates.y[rows], yaw, speed * np.cos(yaw), speed * np.sin(yaw)]
        )
        obs_states = np.stack(
            [
                prediction.mean[..., 0],
                prediction.mean[..., 1],
                prediction.heading,
                prediction.speed * np.cos(prediction.heading),
                prediction.speed * np.sin(prediction.heading),
            ]
        )
        harm_ego, harm_obs = collision_harm_at(
            ego,
            ego_mass,
            obs_states,
            prediction.mass,
            prediction.vulnerable,
            flat,
            HarmModel(config.harm_model),
            HarmModel(config.pedestrian_model),
        )
        return harm_obs, harm_ego
    harm_obs = np.empty(flat.size)
    harm_ego = np.empty(flat.size)
    obs_yaw = prediction.heading.ravel()
    obs_speed = prediction.speed.ravel()
    obs_table = np.stack(
        [
            prediction.mean[..., 0].ravel(),
            prediction.mean[..., 1].ravel(),
            obs_yaw,
            obs_speed * np.cos(obs_yaw),
            obs_speed * np.sin(obs_yaw),
        ]
    )
    ego_x, ego_y, ego_yaw, ego_v = (getattr(candidates, name).ravel() for name in ("x", "y", "yaw", "v"))
    obs_round = np.array([t is RoadUserType.PEDESTRIAN for t in prediction.types], dtype=bool)
    model = HarmModel(config.harm_model)
    pedestrian_model = HarmModel(config.pedestrian_model)
    size = _HARM_CHUNK
    if flat.size >= _HARM_PARALLEL_MIN and workers.threads > 1:
        size = max(size, -(-flat.size // 4))
    cuts = list(range(0, flat.size, size)) + [flat.size]

    def run(part: tuple[int, int]) -> None:
        f = flat[part[0] : part[1]]
        pair, step = np.divmod(f, n_t)
        i, obs = np.divmod(pair, k)
        point = rows.take(i) * n_t + step
        yaw, speed = ego_yaw.take(point), ego_v.take(point)
        obs_now = obs_table.take(obs * n_t + step, axis=1)
        result = collision_harm(
            ego_mass=ego_mass,
            ego_vel=np.stack([speed * np.cos(yaw), speed * np.sin(yaw)], axis=-1),
            ego_pos=np.stack([ego_x.take(point), ego_y.take(point)], axis=-1),
            ego_yaw=yaw,
            obs_mass=prediction.mass.take(obs),
            obs_vel=obs_now[3:5].T,
            obs_pos=obs_now[0:2].T,
            obs_yaw=obs_now[2],
            obs_unprotected=prediction.vulnerable.take(obs),
            model=model,
            pedestrian_model=pedestrian_model,
            delta_v_model=config.delta_v_model,
            restitution=config.restitution_law,
            impulse_ratio=config.impulse_ratio,
            obs_round=obs_round.take(obs),
            ego_shape=(ego_shape.length, ego_shape.width),
            obs_shape=(prediction.length.take(obs), prediction.width.take(obs)),
        )
        harm_obs[part[0] : part[1]] = result.harm_obs
        harm_ego[part[0] : part[1]] = result.harm_ego

    # Elementwise per triple and disjoint per chunk: any split gives the same numbers.
    workers.parallel_for(list(zip(cuts[:-1], cuts[1:], strict=True)), run)
    return harm_obs, harm_ego
