"""Risk without the integrals that cannot matter, checked against evaluating every triple.

``risk_maximum`` skips octagon integrals whose upper bound shows they cannot change Eq. 3's
maximum, maximin's set or the onset; the planner assesses only candidates of the best
level that the integral-free tests leave possible. Both must give exactly what the full
evaluation gives: here the full evaluation is written out with the exhaustive
``collision_probability``, ``collision_harm`` and the cost functions.
"""

from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ethical_planner import collision_probability as cp
from ethical_planner.boundary import edge_impact_speed, physical_view
from ethical_planner.collision_probability import (
    collision_probability,
    gate,
    octagon_tables,
    polygon_gaussian_mass,
    risk_maximum,
)
from ethical_planner.config import preset
from ethical_planner.cost import path_deviation, risk_set, total_cost
from ethical_planner.environment import RoadEnvironment
from ethical_planner.harm import HarmModel, boundary_harm, collision_harm
from ethical_planner.planner import Planner
from ethical_planner.responsibility import LegalCorridors, collision_onset, responsibilities
from ethical_planner.risk import outside_drivable_area, prediction_collision_probability
from ethical_planner.road_users import DEFAULT_SHAPES, EGO_MASS_KG, EGO_SHAPE, KinematicState, RoadUser, Shape
from ethical_planner.road_users import RoadUserType as T
from ethical_planner.terminal import terminally_unsafe
from ethical_planner.validity import UNASSESSED, Validity, physically_invalid, validity_levels
from ethical_planner.workers import Workers


def _cov(sigma_major: float, sigma_minor: float, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    return rot @ np.diag([sigma_major**2, sigma_minor**2]) @ rot.T


def _scene(seed: int, n_traj: int = 40, n_obs: int = 6, n_t: int = 21):
    """Candidates fanning out ahead and road users around them with growing covariances."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 2.0, n_t)
    speed = rng.uniform(5, 15, (n_traj, 1))
    lateral = rng.uniform(-4, 4, (n_traj, 1))
    x = speed * t
    y = lateral * (t / 2.0) ** 2
    yaw = np.arctan2(lateral * t / 2.0, speed) * np.ones_like(t)
    start = rng.uniform(5, 30, (n_obs, 1))
    vel = rng.uniform(-8, 8, (n_obs, 1))
    lane = rng.uniform(-4, 4, (n_obs, 1))
    mean = np.stack([start + vel * t, lane + 0.0 * t], axis=-1)
    heading = np.where(vel < 0, math.pi, 0.0) * np.ones_like(t)
    scale = rng.uniform(0.2, 1.5, n_obs)
    cov = np.array(
        [
            [_cov(s * (0.3 + tt), s * (0.2 + 0.5 * tt), h) for tt, h in zip(t, hs, strict=True)]
            for s, hs in zip(scale, heading, strict=True)
        ]
    )
    length, width = rng.uniform(0.5, 12, n_obs), rng.uniform(0.5, 2.6, n_obs)
    return (x, y, yaw, 4.508, 1.61, mean, cov, heading, length, width)


def _brute_force(args, harm_obs, harm_ego, epsilon):
    """Eq. 3, maximin harms, peak and onset from p at every triple (dense arrays)."""
    p = collision_probability(*args).probability
    risk_obs = (p * harm_obs).max(axis=2, initial=0.0)
    risk_ego = (p * harm_ego).max(axis=2, initial=0.0)
    counted = p > epsilon
    worst_obs = np.where(counted, harm_obs, 0.0).max(axis=2, initial=0.0)
    worst_ego = np.where(counted, harm_ego, 0.0).max(axis=2, initial=0.0)
    peak, onset = collision_onset(p)
    return risk_obs, risk_ego, worst_obs, worst_ego, peak, onset


def _assert_equals_brute_force(result, expected, onset):
    """``risk_maximum``'s result equals ``_brute_force``'s (every triple evaluated), bit for bit."""
    names = ("risk_obs", "risk_ego", "maximin_harm_obs", "maximin_harm_ego")
    for name, reference in zip(names, expected[:4], strict=True):
        np.testing.assert_array_equal(getattr(result, name), reference, err_msg=name)
    if onset:
        np.testing.assert_array_equal(result.peak_probability, expected[4])
        np.testing.assert_array_equal(result.onset_step, expected[5])


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("onset", [False, True])
def test_risk_maximum_equals_evaluating_every_triple(seed, onset):
    args = _scene(seed)
    rng = np.random.default_rng(50 + seed)
    n_traj, n_obs, n_t = args[0].shape[0], args[5].shape[0], args[0].shape[1]
    # Harms that vary along the horizon, some pairs near 1, some tiny.
    harm_obs = rng.uniform(0.0, 1.0, (n_traj, n_obs, n_t)) ** rng.uniform(0.5, 4, (1, n_obs, 1))
    harm_ego = rng.uniform(0.0, 0.3, (n_traj, n_obs, n_t))
    epsilon = 0.01
    expected = _brute_force(args, harm_obs, harm_ego, epsilon)
    tables = octagon_tables(*args)
    rows = np.arange(n_traj)
    flat = gate(tables, rows)
    result = risk_maximum(tables, rows, flat, harm_obs.ravel()[flat], harm_ego.ravel()[flat], epsilon, onset)
    assert 0 < result.integrals < result.triples == flat.size  # something skipped, something not
    assert expected[0].max() > 1e-3 and (expected[4] > epsilon).any()  # informative scenes
    _assert_equals_brute_force(result, expected, onset)
    # Two threads split the pairs; the numbers stay the same.
    threaded = risk_maximum(
        tables, rows, flat, harm_obs.ravel()[flat], harm_ego.ravel()[flat], epsilon, onset, Workers(2)
    )
    np.testing.assert_array_equal(threaded.risk_obs, result.risk_obs)


def _mixture_scene(seed: int):
    """``_scene`` with each road user a two-component scale mixture (narrow and wide).

    Returns the arguments of ``collision_probability`` with the components as road users
    of their own (road user o's component c at o * 2 + c) and the weights (n_obs, n_t, 2).
    """
    x, y, yaw, length, width, mean, cov, heading, olen, owid = _scene(seed)
    rng = np.random.default_rng(80 + seed)
    n_obs, n_t = mean.shape[:2]
    narrow = rng.uniform(0.1, 0.6, (n_obs, n_t, 1))
    wide = rng.uniform(2.0, 6.0, (n_obs, n_t, 1))
    factors = np.concatenate([narrow, wide], axis=-1)  # (n_obs, n_t, 2)
    first = rng.uniform(0.5, 0.95, (n_obs, n_t, 1))
    weights = np.concatenate([first, 1.0 - first], axis=-1)
    components = factors[..., None, None] * cov[:, :, None]  # (n_obs, n_t, 2, 2, 2)
    gaussians = (
        np.repeat(mean, 2, axis=0),
        np.moveaxis(components, 2, 1).reshape(2 * n_obs, n_t, 2, 2),
        np.repeat(heading, 2, axis=0),
        np.repeat(olen, 2),
        np.repeat(owid, 2),
    )
    return (x, y, yaw, length, width, *gaussians), weights


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("onset", [False, True])
def test_risk_maximum_of_a_mixture_equals_evaluating_every_triple(seed, onset):
    """A mixture's p is sum_c w_c p_c: every component integrated, weighted, then Eq. 3."""
    args, weights = _mixture_scene(seed)
    rng = np.random.default_rng(60 + seed)
    n_traj, n_t = args[0].shape
    n_obs = weights.shape[0]
    harm_obs = rng.uniform(0.0, 1.0, (n_traj, n_obs, n_t)) ** rng.uniform(0.5, 4, (1, n_obs, 1))
    harm_ego = rng.uniform(0.0, 0.3, (n_traj, n_obs, n_t))
    epsilon = 0.01
    per_component = collision_probability(*args).probability.reshape(n_traj, n_obs, 2, n_t)
    p = np.clip(np.einsum("nokt,otk->not", per_component, weights), 0.0, 1.0)
    expected = (
        (p * harm_obs).max(axis=2, initial=0.0),
        (p * harm_ego).max(axis=2, initial=0.0),
        np.where(p > epsilon, harm_obs, 0.0).max(axis=2, initial=0.0),
        np.where(p > epsilon, harm_ego, 0.0).max(axis=2, initial=0.0),
        *collision_onset(p),
    )
    tables = octagon_tables(*args, component_weight=weights)
    rows = np.arange(n_traj)
    flat = gate(tables, rows)
    kept = np.zeros(p.size, dtype=bool)
    kept[flat] = True
    assert not (p.ravel()[~kept] > 0).any()  # the gate keeps every triple with p > 0
    result = risk_maximum(tables, rows, flat, harm_obs.ravel()[flat], harm_ego.ravel()[flat], epsilon, onset)
    assert 0 < result.integrals < result.triples == flat.size
    assert expected[0].max() > 1e-3 and (expected[4] > epsilon).any()
    _assert_equals_brute_force(result, expected, onset)


def test_mixture_tables_refuse_weights_that_do_not_match_the_gaussians():
    args, weights = _mixture_scene(0)
    with pytest.raises(ValueError, match="component_weight"):
        octagon_tables(*args, component_weight=weights[:-1])


def test_gate_keeps_exactly_the_triples_with_a_nonzero_probability_or_more():
    args = _scene(11)
    p = collision_probability(*args).probability
    tables = octagon_tables(*args)
    flat = gate(tables, np.arange(p.shape[0]))
    kept = np.zeros(p.size, dtype=bool)
    kept[flat] = True
    assert not (p.ravel()[~kept] > 0).any()  # everything outside the gate is exactly 0
    assert np.all(np.diff(flat) > 0)


@numba.njit
def _bounds(obs_rows, ego_rows, degenerate, far, out):
    edges = np.empty((6, 8))
    for j in range(obs_rows.shape[1]):
        cp._octagon_edges(obs_rows, j, ego_rows, j, degenerate, edges)
        out[0, j] = cp._octagon_mass(edges, far)
        out[1, j] = cp._disc_bound(obs_rows, j, ego_rows, j)
        out[2, j] = cp._rectangle_bound(edges)


_size = st.tuples(st.floats(0.3, 12.0), st.floats(0.3, 3.0))


@settings(max_examples=300, deadline=None)
@given(
    ego=st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(-4, 4)),
    ego_size=_size,
    obs_size=_size,
    obs_yaw=st.floats(-4, 4),
    sigmas=st.tuples(st.floats(0.05, 4.0), st.floats(0.05, 4.0), st.floats(0, 3.2)),
)
def test_bounds_hold_for_the_exact_mass(ego, ego_size, obs_size, obs_yaw, sigmas):
    # Both upper bounds against polygon_gaussian_mass (SciPy's owens_t): the true mass
    # never exceeds them (beyond the tail table's 2e-9), and the computed p never exceeds
    # them by more than the slack the kernel adds.
    cov = _cov(*sigmas)
    pose = tuple(np.array([[value]]) for value in ego)
    obs = (np.zeros((1, 1, 2)), cov.reshape(1, 1, 2, 2), np.array([[obs_yaw]]))
    tables = octagon_tables(*pose, *ego_size, *obs, np.array(obs_size[:1]), np.array(obs_size[1:]), math.inf)
    out = np.empty((3, 1))
    _bounds(tables.obs_rows, tables.ego_rows, tables.degenerate, tables.far, out)
    computed, disc, rectangle = out[:, 0]

    def corners(x, y, yaw, size):
        c, s = math.cos(yaw), math.sin(yaw)
        half_l, half_w = size[0] / 2, size[1] / 2
        signs = ((1, 1), (-1, 1), (-1, -1), (1, -1))
        return [(x + a * half_l * c - b * half_w * s, y + a * half_l * s + b * half_w * c) for a, b in signs]

    import shapely

    points = [
        (ex + ox, ey + oy)
        for ex, ey in corners(*ego, ego_size)
        for ox, oy in corners(0, 0, obs_yaw, obs_size)
    ]
    hull = shapely.orient_polygons(shapely.MultiPoint(points).convex_hull)
    exact = float(polygon_gaussian_mass(np.array(hull.exterior.coords)[:-1], np.zeros(2), cov))
    assert exact <= disc + 1e-8 and exact <= rectangle + 1e-8
    assert computed <= min(disc, rectangle) + cp._BOUND_SLACK


def _brute_force_decision(planner, situation):
    """The cycle written out without shortcuts: every candidate, every triple."""
    from ethical_planner.sampling import frenet_state, sample_candidates

    config, env, weights = planner.config, planner.environment, planner.config.weights
    start = frenet_state(situation.ego, env.reference_path)
    cand = sample_candidates(start, env.reference_path, config.sampling, config.vehicle)
    pred = planner.predictor.predict(situation.road_users, cand.t)
    pred = pred.with_covariance_floor(config.prediction.covariance_floor)
    plan = cand
    # Road users meet the plans pressed against the road edge (tested in test_boundary.py).
    cand, pressed = physical_view(plan, np.arange(plan.n_traj), EGO_SHAPE, env)
    assert pressed.any()  # some candidates cross the road edge: the test covers them
    full = prediction_collision_probability(cand, pred, EGO_SHAPE, config.risk.gate_sigmas)
    p = full.probability
    n = p.shape[0]
    ego_vel = np.stack([cand.v * np.cos(cand.yaw), cand.v * np.sin(cand.yaw)], -1)[:, None]
    obs_vel = np.stack([pred.speed * np.cos(pred.heading), pred.speed * np.sin(pred.heading)], -1)[None]
    ego_pos = np.stack([cand.x, cand.y], -1)[:, None]
    models = (HarmModel(config.risk.harm_model), HarmModel(config.risk.pedestrian_model))
    unprotected = pred.vulnerable[None, :, None]
    ego_state = (ego_vel, ego_pos, cand.yaw[:, None])
    obs_state = (pred.mass[None, :, None], obs_vel, pred.mean[None], pred.heading[None], unprotected)
    harm = collision_harm(
        EGO_MASS_KG,
        *ego_state,
        *obs_state,
        *models,
        delta_v_model=config.risk.delta_v_model,
        restitution=config.risk.restitution_law,
        impulse_ratio=config.risk.impulse_ratio,
        obs_round=np.array([t is T.PEDESTRIAN for t in pred.types])[None, :, None],
        ego_shape=(EGO_SHAPE.length, EGO_SHAPE.width),
        obs_shape=(pred.length[None, :, None], pred.width[None, :, None]),
    )
    risk_obs = (p * harm.harm_obs).max(axis=2, initial=0.0)
    risk_ego = (p * harm.harm_ego).max(axis=2, initial=0.0)
    margin = config.risk.road_edge_margin
    outside = outside_drivable_area(plan, EGO_SHAPE, env, margin)
    leaves = outside.any(axis=1)
    impact = edge_impact_speed(plan, np.arange(n), outside, EGO_SHAPE, env, margin)
    boundary = np.where(leaves, boundary_harm(impact), 0.0)
    ego_combined = 1.0 - np.prod(1.0 - risk_ego, axis=1) * (1.0 - boundary)
    invalid = physically_invalid(plan, config.vehicle)
    max_risk = config.risk.max_acceptable_risk
    # Terminal safety (tested by hand in test_terminal.py) is part of level 1.
    terminal = terminally_unsafe(plan, pred, env, EGO_SHAPE, config.terminal)
    overlap = full.mean_overlap | terminal[:, None, None]
    levels = validity_levels(invalid, overlap, outside, risk_obs, ego_combined, max_risk)
    corridors = LegalCorridors.of(situation.road_users, env)
    peak, onset = collision_onset(p)
    r_obs, r_ego = responsibilities(
        cand, np.arange(n), peak, onset, pred, corridors, EGO_MASS_KG, config.responsibility
    )
    counted = p > weights.maximin_epsilon
    worst_obs = np.where(counted, harm.harm_obs, 0).max(axis=2, initial=0)
    worst_ego = np.where(counted, harm.harm_ego, 0).max(axis=2, initial=0)
    harms = np.concatenate([worst_obs, worst_ego, boundary[:, None]], axis=1)
    pairs = counted.any(axis=2)
    counted_set = np.concatenate([pairs, pairs, leaves[:, None]], axis=1)
    risks, present = risk_set(risk_obs, risk_ego, boundary, leaves)
    r = np.concatenate([r_obs, r_ego, np.zeros((n, 1))], axis=1)
    speed = np.abs(plan.v - planner.desired_speed).mean(axis=1)
    path = path_deviation(plan.d, env.lane_offsets, env.lane_width, weights.path_reference)
    risk_terms = (risks, present, r, harms, counted_set, ego_combined)
    costs = total_cost(*risk_terms, plan.jerk_lon, plan.jerk_lat, speed, *path, levels, weights)
    in_level = np.flatnonzero(levels == levels.max())
    order = np.lexsort((costs.comfort[in_level] + costs.mobility[in_level], costs.total[in_level]))
    return levels, in_level[order[0]], costs


def _assert_levels(decision, levels, costs, weights):
    """The decision's levels are the brute force's, but for candidates left unassessed.

    Those (``UNASSESSED``) are valid or above R_max (or break a rule) in the brute force,
    and cost more by Eq. 5 than the chosen plan.
    """
    left_out = decision.candidate_levels == UNASSESSED
    np.testing.assert_array_equal(decision.candidate_levels[~left_out], levels[~left_out])
    possible = [Validity.VALID, Validity.ABOVE_MAX_RISK, Validity.BREAKS_TRAFFIC_RULE]
    assert np.isin(levels[left_out], possible).all()
    eq5 = weights.risk * costs.risk + costs.comfort + costs.mobility
    assert (eq5[left_out] > decision.costs["total"]).all()


def _street(seed: int):
    """A two-lane street with cars, a cyclist and pedestrians around the ego."""
    rng = np.random.default_rng(seed)
    env = RoadEnvironment.along_path([[-20, 0], [200, 0]], lanes_left=1, lanes_right=0, margin=0.5)

    class Situation:
        pass

    situation = Situation()
    situation.ego = KinematicState(0.0, 0.0, 0.0, rng.uniform(6, 14))
    users = []
    for i, kind in enumerate((T.CAR, T.CAR, T.BICYCLE, T.PEDESTRIAN, T.TRUCK, T.CAR)):
        x = rng.uniform(6, 50)
        y = rng.choice([0.0, 3.5]) if kind is not T.PEDESTRIAN else rng.uniform(-2.5, 5.5)
        yaw = math.pi if y > 2 and kind is not T.PEDESTRIAN else rng.uniform(-0.3, 0.3)
        speed = {T.CAR: 8.0, T.TRUCK: 6.0, T.BICYCLE: 4.0, T.PEDESTRIAN: 1.3}[kind] * rng.uniform(0.3, 1.1)
        users.append(RoadUser(i + 1, kind, KinematicState(x, y, yaw, speed), DEFAULT_SHAPES[kind]))
    situation.road_users = tuple(users)
    situation.environment = env
    return situation


@pytest.mark.parametrize("preset_name", ["ethical", "ethical_responsible", "selfish", "standard"])
@pytest.mark.parametrize("seed", range(3))
def test_planner_decides_as_evaluating_every_candidate_and_triple(preset_name, seed):
    situation = _street(seed)
    planner = Planner(
        preset(preset_name).with_overrides({"commitment": {"enabled": False}}), situation.environment
    )
    decision = planner.plan(situation.ego, situation.road_users)
    levels, index, costs = _brute_force_decision(planner, situation)
    _assert_levels(decision, levels, costs, planner.config.weights)
    assert decision.chosen_index == index
    for name, value in decision.costs.items():
        assert value == getattr(costs, name)[index], name  # the same numbers, to the bit


class _MixturePredictor:
    """The planner's own predictor with each prediction made a narrow/wide scale mixture."""

    def __init__(self, base):
        self.base = base
        self.name = base.name

    def predict(self, road_users, t):
        prediction = self.base.predict(road_users, t)
        n_obs, n_t = prediction.mean.shape[:2]
        steps = np.linspace(0.0, 1.0, n_t)
        weights = np.stack(np.broadcast_arrays(0.7 - 0.2 * steps, 0.3 + 0.2 * steps), axis=-1)
        weights = np.broadcast_to(weights, (n_obs, n_t, 2)).copy()
        components = np.stack([0.4 * prediction.cov, 3.0 * prediction.cov], axis=2)
        cov = np.einsum("otk,otkij->otij", weights, components)
        return dataclasses.replace(prediction, cov=cov, component_weight=weights, component_cov=components)


@pytest.mark.parametrize("preset_name", ["ethical", "ethical_responsible"])
@pytest.mark.parametrize("seed", range(3))
def test_planner_with_a_mixture_prediction_decides_as_evaluating_every_candidate(preset_name, seed):
    situation = _street(seed)
    planner = Planner(
        preset(preset_name).with_overrides({"commitment": {"enabled": False}}), situation.environment
    )
    planner.predictor = _MixturePredictor(planner.predictor)
    decision = planner.plan(situation.ego, situation.road_users)
    levels, index, costs = _brute_force_decision(planner, situation)
    _assert_levels(decision, levels, costs, planner.config.weights)
    assert decision.chosen_index == index
    for name, value in decision.costs.items():
        assert value == getattr(costs, name)[index], name


@pytest.mark.parametrize("case", ["curved_road", "debris", "large_map"])
def test_inside_grid_fast_path_equals_shapely_contains(case):
    """The road-edge test's grid of interior cells gives shapely's answer at every point.

    Points: random ones over the bounds and beyond, the polygons' own vertices (on the
    boundary: not contained), points on the grid's cell edges and corners, and points
    just inside and outside those edges.
    """
    import shapely

    from ethical_planner.risk import _contains, _InsideGrid

    env = RoadEnvironment.along_path(
        [[0, 0], [20, 2], [40, 10], [55, 25], [60, 45]], lanes_left=1, lanes_right=1, margin=0.3
    )
    polygon = env.drivable_area
    if case == "debris":
        holes = shapely.union_all([shapely.box(10, -1, 12, 1), shapely.Point(45, 15).buffer(0.8)])
        polygon = polygon.difference(holes)
    elif case == "large_map":
        # A long thin polygon over a large box: cells coarser than the minimum.
        polygon = shapely.union_all([polygon, shapely.box(0, 300, 900, 304), shapely.box(896, 0, 900, 304)])
    polygon = polygon.buffer(-0.7)
    shapely.prepare(polygon)
    grid = _InsideGrid.of(polygon)
    assert grid is not None and grid.inside.any() and not grid.inside.all()
    if case == "large_map":
        assert grid.cell > 0.5 and grid.inside.size <= 41_000  # 40,000 cells, rounded up per axis
    rng = np.random.default_rng(7)
    x0, y0, x1, y1 = polygon.bounds
    x = rng.uniform(x0 - 5, x1 + 5, 200_000)
    y = rng.uniform(y0 - 5, y1 + 5, 200_000)
    ny, nx = grid.inside.shape
    ex = grid.x0 + grid.cell * rng.integers(0, nx + 1, 50_000)
    ey = grid.y0 + grid.cell * rng.integers(0, ny + 1, 50_000)
    vx, vy = shapely.get_coordinates(polygon).T
    tiny = 1e-9
    x = np.concatenate([x, ex, ex + tiny, ex - tiny, rng.uniform(x0, x1, 50_000), vx])
    y = np.concatenate([y, ey, ey - tiny, ey + tiny, ey, vy])
    expected = shapely.contains_xy(polygon, x, y)
    np.testing.assert_array_equal(_contains(polygon, grid, x, y), expected)
    # The fast path decides most points inside (on a large map with coarse cells, fewer)
    # and most points outside (outside cells and beyond the bounds), never wrongly.
    state = grid.state(x, y)
    assert expected[state == 1].all() and not expected[state == 0].any()
    share = grid.contains(x, y).sum() / expected.sum()
    assert share > (0.05 if case == "large_map" else 0.5)
    assert (state == 0).sum() / (~expected).sum() > 0.5
    assert not shapely.contains_xy(polygon, vx, vy).any()


@pytest.mark.parametrize("case", ["curved_road", "debris"])
def test_footprint_corners_kernel_equals_rectangle_corners_and_shapely(case):
    """The road-edge test's fused corner pass: the corners of ``rectangle_corners`` to the
    bit, and "all four inside" as shapely says, for footprints across the road's edges."""
    import shapely

    from ethical_planner.geometry import rectangle_corners
    from ethical_planner.risk import _corners_inside

    env = RoadEnvironment.along_path(
        [[0, 0], [20, 2], [40, 10], [55, 25], [60, 45]], lanes_left=1, lanes_right=1, margin=0.3
    )
    area = env.drivable_area
    if case == "debris":
        area = area.difference(
            shapely.union_all([shapely.box(10, -1, 12, 1), shapely.Point(45, 15).buffer(0.8)])
        )
    shapely.prepare(area)
    rng = np.random.default_rng(11)
    x0, y0, x1, y1 = area.bounds
    m = 60_000
    x, y = rng.uniform(x0 - 3, x1 + 3, m), rng.uniform(y0 - 3, y1 + 3, m)
    yaw = rng.uniform(-np.pi, np.pi, m)
    shape = Shape(5.5, 2.8)
    cx, cy, inside = _corners_inside(area, x, y, yaw, shape)
    ex, ey = rectangle_corners(x, y, yaw, shape.length, shape.width)
    np.testing.assert_array_equal(cx, ex)
    np.testing.assert_array_equal(cy, ey)
    expected = shapely.contains_xy(area, ex, ey).all(axis=1)
    np.testing.assert_array_equal(inside, expected)
    assert 0.05 < expected.mean() < 0.95
