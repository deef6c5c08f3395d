"""Tests of the Gaussian collision probability (SPEC section 3).

The Monte-Carlo reference samples obstacle centres and tests rectangle overlap with
a separating-axis test of its own, so it checks the Minkowski-sum geometry as well
as the Owen's T integral.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import ndtr

from ethical_planner.collision_probability import (
    CollisionProbability,
    collision_probability,
    polygon_gaussian_mass,
)
from ethical_planner.workers import Workers

# Documented accuracy of collision_probability against the closed form (its module
# docstring: float32 Gauss-Legendre Owen's T within 3e-8 per term, a tabulated normal
# tail within 2e-9, dropped far edges below 7.6e-9 each, 16 terms per octagon; measured
# at most 5e-8). polygon_gaussian_mass stays exact (SciPy's owens_t): its tests keep 1e-12.
P_TOL = 1e-6

# (length, width) [m]: pedestrian, bicycle, car, van, bus, truck.
SHAPES = [(0.5, 0.5), (1.8, 0.7), (4.5, 1.8), (5.5, 2.1), (12.0, 2.55), (10.0, 2.5)]


def _cov(sigma_major: float, sigma_minor: float, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    return rot @ np.diag([sigma_major**2, sigma_minor**2]) @ rot.T


def _single(ego, ego_size, mean, cov, obs_yaw, obs_size, gate_sigmas=6.0):
    """Collision probability of one (traj, obs, t) triple as a float plus mean overlap."""
    (x, y, yaw), (length, width) = ego, ego_size
    result = collision_probability(
        np.array([[x]]),
        np.array([[y]]),
        np.array([[yaw]]),
        length,
        width,
        np.asarray(mean, dtype=float).reshape(1, 1, 2),
        np.asarray(cov, dtype=float).reshape(1, 1, 2, 2),
        np.array([[obs_yaw]]),
        np.array([obs_size[0]]),
        np.array([obs_size[1]]),
        gate_sigmas=gate_sigmas,
    )
    return float(result.probability[0, 0, 0]), bool(result.mean_overlap[0, 0, 0])


def _sat_overlap(ego, ego_size, centres, obs_yaw, obs_size):
    """Separating-axis test: does the obstacle at each of ``centres`` (n, 2) touch the ego?"""
    x, y, yaw = ego
    rel = np.asarray(centres, dtype=float).reshape(-1, 2) - np.array([x, y])
    overlap = np.ones(len(rel), dtype=bool)
    ego_axes = [(math.cos(yaw), math.sin(yaw)), (-math.sin(yaw), math.cos(yaw))]
    obs_axes = [(math.cos(obs_yaw), math.sin(obs_yaw)), (-math.sin(obs_yaw), math.cos(obs_yaw))]
    for ax, ay in ego_axes + obs_axes:
        # Half-extent of each rectangle projected on the axis.
        ego_r = 0.5 * ego_size[0] * abs(ego_axes[0][0] * ax + ego_axes[0][1] * ay) + 0.5 * (
            ego_size[1] * abs(ego_axes[1][0] * ax + ego_axes[1][1] * ay)
        )
        obs_r = 0.5 * obs_size[0] * abs(obs_axes[0][0] * ax + obs_axes[0][1] * ay) + 0.5 * (
            obs_size[1] * abs(obs_axes[1][0] * ax + obs_axes[1][1] * ay)
        )
        overlap &= np.abs(rel[:, 0] * ax + rel[:, 1] * ay) <= ego_r + obs_r
    return overlap


def _reference_probability_mc(ego, ego_size, mean, cov, obs_yaw, obs_size, n_samples, rng):
    """Monte-Carlo P(overlap): sample obstacle centres, separating-axis test each."""
    centres = rng.multivariate_normal(np.asarray(mean, dtype=float), cov, size=n_samples)
    return float(np.mean(_sat_overlap(ego, ego_size, centres, obs_yaw, obs_size)))


def _random_case(rng):
    """A random pose pair, shapes and covariance placed so that p is often not trivial."""
    ego_size = SHAPES[rng.integers(len(SHAPES))]
    obs_size = SHAPES[rng.integers(len(SHAPES))]
    ego = (rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(-math.pi, math.pi))
    obs_yaw = rng.uniform(-math.pi, math.pi)
    reach = 0.5 * (math.hypot(*ego_size) + math.hypot(*obs_size))
    direction = np.array([math.cos(d := rng.uniform(-math.pi, math.pi)), math.sin(d)])
    dist = reach * rng.uniform(0.2, 1.2)
    kind = rng.integers(4)
    if kind == 0:  # correlation 0.95 and more
        sx, sy = rng.uniform(0.3, 4.0, 2)
        rho = rng.choice([-1.0, 1.0]) * rng.uniform(0.95, 0.995)
        cov = np.array([[sx * sx, rho * sx * sy], [rho * sx * sy, sy * sy]])
    elif kind == 1:  # very anisotropic, any orientation
        cov = _cov(rng.uniform(1.0, 4.0), rng.uniform(0.05, 0.2), rng.uniform(0, math.pi))
    elif kind == 2:  # tiny, 0.01 m^2: put the mean within ~0.1 m of the contact boundary
        cov = _cov(0.1, 0.1, 0.0) if rng.random() < 0.5 else _cov(0.1, 0.05, rng.uniform(0, 3))
        lo, hi = 0.0, 2.0 * reach
        for _ in range(60):  # bisection on the separating-axis test along the direction
            mid = 0.5 * (lo + hi)
            centre = np.array(ego[:2]) + mid * direction
            lo, hi = (mid, hi) if _sat_overlap(ego, ego_size, centre, obs_yaw, obs_size)[0] else (lo, mid)
        dist = lo + rng.normal(0.0, 0.1)
    else:
        cov = _cov(rng.uniform(0.3, 3.0), rng.uniform(0.3, 3.0), rng.uniform(0, math.pi))
    mean = tuple(np.array(ego[:2]) + dist * direction)
    return ego, ego_size, mean, cov, obs_yaw, obs_size


MC_CASES = [_random_case(np.random.default_rng(1000 + i)) for i in range(20)]


@pytest.mark.parametrize("case", MC_CASES)
def test_matches_monte_carlo(case):
    ego, ego_size, mean, cov, obs_yaw, obs_size = case
    rng = np.random.default_rng(7)
    p, _ = _single(ego, ego_size, mean, cov, obs_yaw, obs_size)
    p_mc = _reference_probability_mc(ego, ego_size, mean, cov, obs_yaw, obs_size, 10**6, rng)
    assert abs(p - p_mc) <= 0.005


def test_monte_carlo_cases_are_informative():
    # A check against MC is only meaningful if many cases are neither 0 nor 1, and
    # includes correlations of 0.95 and more.
    values = [_single(*case)[0] for case in MC_CASES]
    assert sum(0.05 < v < 0.95 for v in values) >= 10
    corr = [abs(c[3][0, 1]) / math.sqrt(c[3][0, 0] * c[3][1, 1]) for c in MC_CASES]
    assert max(corr) >= 0.95
    tiny = [v for v, c in zip(values, MC_CASES, strict=True) if np.trace(c[3]) <= 0.021]
    assert sum(0.02 < v < 0.98 for v in tiny) >= 3


@pytest.mark.parametrize(
    ("yaw", "obs_quarter_turns", "mean_offset", "sigmas"),
    [
        (0.0, 0, (3.0, 0.5), (2.0, 0.5)),
        (0.0, 1, (-1.0, 2.5), (0.1, 0.1)),
        (0.7, 2, (0.0, 0.0), (5.0, 0.2)),
        (-2.1, 3, (4.0, -1.5), (1.0, 3.0)),
        (1.3, 0, (6.65, 0.0), (0.5, 0.5)),  # mean exactly on an edge of the octagon
        (0.0, 0, (6.65, 1.9), (0.5, 0.5)),  # mean exactly at a vertex of the octagon
        (2.0, 1, (-6.65, -1.9), (0.3, 2.0)),  # the same, rotated
    ],
)
def test_aligned_rectangles_match_ndtr_product(yaw, obs_quarter_turns, mean_offset, sigmas):
    # Aligned rectangles and a covariance aligned with them: the octagon is a rectangle
    # and the mass factorises into two 1-D normal intervals in the ego frame.
    ego_size, obs_size = (4.5, 1.8), (8.8, 2.0)
    ego = (10.0, -3.0, yaw)
    c, s = math.cos(yaw), math.sin(yaw)
    mean = (
        ego[0] + c * mean_offset[0] - s * mean_offset[1],
        ego[1] + s * mean_offset[0] + c * mean_offset[1],
    )
    cov = _cov(sigmas[0], sigmas[1], yaw)
    obs_yaw = yaw + obs_quarter_turns * 0.5 * math.pi
    obs_along, obs_across = obs_size if obs_quarter_turns % 2 == 0 else obs_size[::-1]
    half_x = 0.5 * (ego_size[0] + obs_along)
    half_y = 0.5 * (ego_size[1] + obs_across)
    mx, my = mean_offset
    expected = (ndtr((half_x - mx) / sigmas[0]) - ndtr((-half_x - mx) / sigmas[0])) * (
        ndtr((half_y - my) / sigmas[1]) - ndtr((-half_y - my) / sigmas[1])
    )
    p, overlap = _single(ego, ego_size, mean, cov, obs_yaw, obs_size)
    assert p == pytest.approx(expected, abs=P_TOL)
    # The closed octagon: touching counts as overlap.
    assert overlap == (abs(mx) <= half_x and abs(my) <= half_y)


def test_mean_at_a_vertex_of_aligned_squares():
    # Exactly representable: the octagon is the square [-1, 1]^2, the mean its corner.
    p, overlap = _single((0.0, 0.0, 0.0), (1.0, 1.0), (1.0, 1.0), np.eye(2), 0.0, (1.0, 1.0))
    assert p == pytest.approx((ndtr(0.0) - ndtr(-2.0)) ** 2, abs=P_TOL)
    assert overlap


def test_mean_next_to_tiny_edges_of_a_nearly_square_octagon():
    # A slightly turned ego makes the square octagon [-1, 1]^2 an octagon with edges of
    # length ~yaw, and a mean on the top edge lies ~1e-11 from their vertices, where h and
    # t of those edges are both tiny and their ratio ill-conditioned (found by hypothesis:
    # p was up to 4e-6 off for 15 % of such yaws). Independent value: the mass of the
    # square, (Phi(1) - Phi(-1)) (Phi(0) - Phi(-2)), within the area the turn adds or
    # removes (|yaw| * 4 m^2 * phi(0) < 1e-8).
    rng = np.random.default_rng(0)
    yaws = 10 ** rng.uniform(-13, -8, 200) * rng.choice([-1.0, 1.0], 200)
    expected = (ndtr(1.0) - ndtr(-1.0)) * (ndtr(0.0) - ndtr(-2.0))
    for yaw in [1.6082374532830978e-11, *yaws]:
        p, _ = _single((0.0, 0.0, yaw), (1.0, 1.0), (0.0, 1.0), np.eye(2), 0.0, (1.0, 1.0))
        assert p == pytest.approx(expected, abs=P_TOL / 4)


@pytest.mark.parametrize("seed", range(4))
def test_continuous_at_vertices_and_edge_lines(seed):
    # With the mean exactly at an octagon vertex, on an edge, or on an edge's extension,
    # p must equal p at a mean moved by 1e-7 m (the wedge angles are then not a
    # winding number). The octagon comes from shapely here, not from the module.
    rng = np.random.default_rng(seed)
    ego_yaw, obs_yaw = rng.uniform(-math.pi, math.pi, 2)
    ego_size, obs_size = (4.5, 1.8), (1.8, 0.7)
    cov = _cov(rng.uniform(0.5, 2.0), rng.uniform(0.5, 2.0), rng.uniform(0, math.pi))

    def corners(yaw, size):
        c, s = math.cos(yaw), math.sin(yaw)
        local = np.array([[sx * size[0], sy * size[1]] for sx in (-0.5, 0.5) for sy in (-0.5, 0.5)])
        return local @ np.array([[c, s], [-s, c]])

    points = (corners(ego_yaw, ego_size)[:, None] + corners(obs_yaw, obs_size)[None]).reshape(-1, 2)
    hull = np.array(shapely.MultiPoint(points).convex_hull.exterior.coords)[:-1]
    assert len(hull) == 8
    edges = np.roll(hull, -1, axis=0) - hull
    targets = np.concatenate([hull, hull + 0.5 * edges, hull - 0.5 * edges, hull + 1.5 * edges])
    for target in targets:
        step = 1e-7 * rng.standard_normal(2)
        p, _ = _single((0.0, 0.0, ego_yaw), ego_size, target, cov, obs_yaw, obs_size)
        p_moved, _ = _single((0.0, 0.0, ego_yaw), ego_size, target + step, cov, obs_yaw, obs_size)
        assert p == pytest.approx(p_moved, abs=1e-6)


def test_far_obstacle_is_exactly_zero():
    p, overlap = _single((0.0, 0.0, 0.3), (4.5, 1.8), (200.0, 5.0), _cov(3.0, 1.0, 0.2), 1.0, (4.5, 1.8))
    assert p == 0.0
    assert not overlap


def test_gate_never_cuts_more_than_1e_6():
    # Many obstacles around the gate radius, anisotropic covariances pointing anywhere.
    rng = np.random.default_rng(3)
    n_traj, n_obs, n_t = 40, 30, 5
    ego_x = rng.uniform(-5, 5, (n_traj, n_t))
    ego_y = rng.uniform(-5, 5, (n_traj, n_t))
    ego_yaw = rng.uniform(-math.pi, math.pi, (n_traj, n_t))
    covs = np.array(
        [
            [_cov(rng.uniform(0.2, 3), rng.uniform(0.05, 1), rng.uniform(0, 4)) for _ in range(n_t)]
            for _ in range(n_obs)
        ]
    )
    sigma = np.sqrt(np.linalg.eigvalsh(covs)[..., -1])
    direction = rng.uniform(-math.pi, math.pi, (n_obs, n_t))
    dist = 8.0 + 6.0 * sigma * rng.uniform(0.2, 1.3, (n_obs, n_t))
    mean = np.stack([dist * np.cos(direction), dist * np.sin(direction)], axis=-1)
    heading = rng.uniform(-math.pi, math.pi, (n_obs, n_t))
    length = rng.uniform(0.5, 10.0, n_obs)
    width = rng.uniform(0.5, 2.5, n_obs)
    args = (ego_x, ego_y, ego_yaw, 4.5, 1.8, mean, covs, heading, length, width)
    gated = collision_probability(*args, gate_sigmas=6.0)
    full = collision_probability(*args, gate_sigmas=math.inf)
    cut = (gated.probability == 0.0) & (full.probability > 0.0)
    assert cut.sum() > 100  # the gate is exercised
    assert np.max(np.abs(gated.probability - full.probability)) <= 1e-6
    np.testing.assert_array_equal(gated.mean_overlap, full.mean_overlap)


def test_batched_call_matches_single_calls():
    # Checks the gather/scatter of survivors: every triple of a batched call equals the
    # single-triple call, which the Monte-Carlo tests verify.
    rng = np.random.default_rng(11)
    n_traj, n_obs, n_t = 4, 3, 6
    ego_x = rng.uniform(-3, 3, (n_traj, n_t))
    ego_y = rng.uniform(-3, 3, (n_traj, n_t))
    ego_yaw = rng.uniform(-math.pi, math.pi, (n_traj, n_t))
    mean = rng.uniform(-6, 6, (n_obs, n_t, 2))
    cov = np.array(
        [
            [_cov(rng.uniform(0.2, 2), rng.uniform(0.1, 2), rng.uniform(0, 4)) for _ in range(n_t)]
            for _ in range(n_obs)
        ]
    )
    heading = rng.uniform(-math.pi, math.pi, (n_obs, n_t))
    length = np.array([0.5, 4.5, 10.0])
    width = np.array([0.5, 1.8, 2.5])
    result = collision_probability(ego_x, ego_y, ego_yaw, 4.5, 1.8, mean, cov, heading, length, width)
    assert 0.0 < result.probability.mean() < 1.0
    for i in range(n_traj):
        for k in range(n_obs):
            for t in range(n_t):
                p, overlap = _single(
                    (ego_x[i, t], ego_y[i, t], ego_yaw[i, t]),
                    (4.5, 1.8),
                    mean[k, t],
                    cov[k, t],
                    heading[k, t],
                    (length[k], width[k]),
                )
                assert result.probability[i, k, t] == pytest.approx(p, abs=1e-14)
                assert result.mean_overlap[i, k, t] == overlap


# --- properties -----------------------------------------------------------------------

_angle = st.floats(-2 * math.pi, 2 * math.pi)
_size = st.tuples(st.floats(0.3, 12.0), st.floats(0.3, 3.0))
_pose = st.tuples(st.floats(-20, 20), st.floats(-20, 20), _angle)
_cov_st = st.builds(_cov, st.floats(0.05, 5.0), st.floats(0.05, 5.0), _angle)
_offset = st.tuples(st.floats(-12, 12), st.floats(-12, 12))


@settings(max_examples=200, deadline=None)
@given(_pose, _size, _offset, _cov_st, _angle, _size)
def test_probability_in_unit_interval(ego, ego_size, offset, cov, obs_yaw, obs_size):
    mean = (ego[0] + offset[0], ego[1] + offset[1])
    p, overlap = _single(ego, ego_size, mean, cov, obs_yaw, obs_size)
    assert 0.0 <= p <= 1.0
    if overlap:  # the mean is inside the octagon, so a positive mass surrounds it
        assert p > 0.0


@settings(max_examples=200, deadline=None)
@given(
    _pose,
    _size,
    _offset,
    _cov_st,
    _angle,
    _size,
    _angle,
    st.tuples(st.floats(-50, 50), st.floats(-50, 50)),
)
def test_invariant_under_rigid_motion(ego, ego_size, offset, cov, obs_yaw, obs_size, theta, shift):
    mean = np.array([ego[0] + offset[0], ego[1] + offset[1]])
    c, s = math.cos(theta), math.sin(theta)
    rot = np.array([[c, -s], [s, c]])
    ego_moved = (*(rot @ np.array(ego[:2]) + shift), ego[2] + theta)
    mean_moved = rot @ mean + shift
    p, overlap = _single(ego, ego_size, mean, cov, obs_yaw, obs_size)
    p_moved, overlap_moved = _single(
        ego_moved, ego_size, mean_moved, rot @ cov @ rot.T, obs_yaw + theta, obs_size
    )
    # Rigid motions change the whitened edges only by rounding; the approximation is
    # continuous up to P_TOL where it switches branch (|t| = |h|) or drops an edge.
    assert p_moved == pytest.approx(p, abs=P_TOL)


@settings(max_examples=200, deadline=None)
@given(_pose, _size, _offset, _cov_st, _angle, _size)
def test_symmetric_in_ego_and_obstacle(ego, ego_size, offset, cov, obs_yaw, obs_size):
    # Overlap depends only on the relative position, and the octagon is centrally
    # symmetric: swapping the bodies (the other one uncertain, same covariance) keeps p.
    mean = (ego[0] + offset[0], ego[1] + offset[1])
    p, _ = _single(ego, ego_size, mean, cov, obs_yaw, obs_size)
    p_swapped, _ = _single((*mean, obs_yaw), obs_size, ego[:2], cov, ego[2], ego_size)
    assert p_swapped == pytest.approx(p, abs=P_TOL)


@settings(max_examples=200, deadline=None)
@given(_pose, _size, _offset, _cov_st, _angle, _size, st.floats(1.0, 3.0), st.integers(0, 3))
def test_growing_a_footprint_never_lowers_p(ego, ego_size, offset, cov, obs_yaw, obs_size, factor, which):
    mean = (ego[0] + offset[0], ego[1] + offset[1])
    p, _ = _single(ego, ego_size, mean, cov, obs_yaw, obs_size)
    sizes = [*ego_size, *obs_size]
    sizes[which] *= factor
    p_grown, _ = _single(ego, tuple(sizes[:2]), mean, cov, obs_yaw, tuple(sizes[2:]))
    assert p_grown >= p - 2 * P_TOL


# --- polygon_gaussian_mass ----------------------------------------------------------------


def test_polygon_mass_of_axis_aligned_rectangles():
    rng = np.random.default_rng(5)
    lo = rng.uniform(-3, 0, (50, 2))
    hi = lo + rng.uniform(0.01, 4, (50, 2))
    vertices = np.stack([lo, np.c_[hi[:, 0], lo[:, 1]], hi, np.c_[lo[:, 0], hi[:, 1]]], axis=1)
    mean = rng.uniform(-2, 2, (50, 2))
    sig = rng.uniform(0.1, 2, (50, 2))
    cov = np.zeros((50, 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = sig[:, 0] ** 2, sig[:, 1] ** 2
    expected = np.prod(ndtr((hi - mean) / sig) - ndtr((lo - mean) / sig), axis=1)
    np.testing.assert_allclose(polygon_gaussian_mass(vertices, mean, cov), expected, rtol=0, atol=1e-12)


def test_polygon_mass_is_additive_over_a_split():
    # A convex hexagon cut along a chord into two convex pieces: masses add up.
    rng = np.random.default_rng(9)
    angles = np.sort(rng.uniform(0, 2 * math.pi, (100, 6)), axis=1)
    radius = rng.uniform(0.5, 3, (100, 1))
    hexagon = np.stack([radius * np.cos(angles), radius * np.sin(angles)], axis=-1)
    mean = rng.uniform(-2, 2, (100, 2))
    cov = np.array([_cov(rng.uniform(0.2, 2), rng.uniform(0.05, 1), rng.uniform(0, 4)) for _ in range(100)])
    whole = polygon_gaussian_mass(hexagon, mean, cov)
    first = polygon_gaussian_mass(hexagon[:, [0, 1, 2, 3]], mean, cov)
    second = polygon_gaussian_mass(hexagon[:, [3, 4, 5, 0]], mean, cov)
    np.testing.assert_allclose(first + second, whole, rtol=0, atol=1e-12)
    assert np.all((whole > 0) & (whole < 1))


def test_polygon_mass_rejects_clockwise_and_bad_cov():
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    assert polygon_gaussian_mass(square, [0.5, 0.5], np.eye(2)).shape == ()
    with pytest.raises(ValueError, match="counter-clockwise"):
        polygon_gaussian_mass(square[::-1], [0.5, 0.5], np.eye(2))
    with pytest.raises(ValueError, match="positive definite"):
        polygon_gaussian_mass(square, [0.5, 0.5], np.diag([1.0, -1.0]))
    with pytest.raises(ValueError, match="mean"):
        polygon_gaussian_mass(square, [0.5, 0.5, 0.5], np.eye(2))


# --- shapes, validation, purity -------------------------------------------------------------


def _scene(n_traj=3, n_obs=2, n_t=4):
    rng = np.random.default_rng(2)
    return {
        "ego_x": rng.uniform(-2, 2, (n_traj, n_t)),
        "ego_y": rng.uniform(-2, 2, (n_traj, n_t)),
        "ego_yaw": rng.uniform(-3, 3, (n_traj, n_t)),
        "ego_length": 4.5,
        "ego_width": 1.8,
        "obs_mean": rng.uniform(-5, 5, (n_obs, n_t, 2)),
        "obs_cov": np.broadcast_to(np.diag([1.0, 0.3]), (n_obs, n_t, 2, 2)).copy(),
        "obs_heading": rng.uniform(-3, 3, (n_obs, n_t)),
        "obs_length": np.full(n_obs, 4.0),
        "obs_width": np.full(n_obs, 2.0),
    }


@pytest.mark.parametrize(("n_traj", "n_obs", "n_t"), [(3, 2, 4), (1, 1, 1), (5, 0, 7), (0, 2, 3)])
def test_output_shapes(n_traj, n_obs, n_t):
    result = collision_probability(**_scene(n_traj, n_obs, n_t))
    assert isinstance(result, CollisionProbability)
    assert result.probability.shape == (n_traj, n_obs, n_t)
    assert result.probability.dtype == np.float64
    assert result.mean_overlap.shape == (n_traj, n_obs, n_t)
    assert result.mean_overlap.dtype == np.bool_


@pytest.mark.parametrize(
    ("name", "bad"),
    [
        ("ego_x", np.zeros(12)),
        ("ego_y", np.zeros((3, 5))),
        ("ego_y", np.zeros(4)),
        ("ego_yaw", np.zeros((2, 4))),
        ("obs_mean", np.zeros((2, 4, 3))),
        ("obs_mean", np.zeros((2, 5, 2))),
        ("obs_cov", np.zeros((2, 4, 2))),
        ("obs_heading", np.zeros((3, 4))),
        ("obs_length", np.zeros(3)),
        ("obs_width", np.zeros((2, 1))),
    ],
)
def test_bad_shapes_raise_naming_the_argument(name, bad):
    scene = _scene()
    scene[name] = bad
    with pytest.raises(ValueError, match=name):
        collision_probability(**scene)


@pytest.mark.parametrize(
    ("name", "bad", "message"),
    [
        ("obs_cov", np.zeros((2, 4, 2, 2)), "positive definite"),
        ("obs_cov", np.broadcast_to([[1.0, 0.5], [0.0, 1.0]], (2, 4, 2, 2)), "symmetric"),
        ("ego_length", -1.0, "ego_length"),
        ("obs_width", np.array([2.0, -0.1]), "obs_width"),
        ("ego_x", np.full((3, 4), np.nan), "ego_x"),
    ],
)
def test_bad_values_raise(name, bad, message):
    scene = _scene()
    scene[name] = bad
    with pytest.raises(ValueError, match=message):
        collision_probability(**scene)


def test_inputs_not_mutated():
    scene = _scene(4, 3, 5)
    copies = {k: np.copy(v) for k, v in scene.items()}
    for value in scene.values():
        if isinstance(value, np.ndarray):
            value.setflags(write=False)  # any in-place write would raise
    result = collision_probability(**scene)
    assert result.probability.flags.writeable
    for key, value in scene.items():
        np.testing.assert_array_equal(value, copies[key])


# --- the fast path against the exact evaluation ----------------------------------------------


def _octagon(ego, ego_size, obs_yaw, obs_size):
    """Minkowski octagon around the ego centre from shapely's convex hull, CCW, (k, 2)."""

    def corners(yaw, size):
        c, s = math.cos(yaw), math.sin(yaw)
        local = np.array([[sx * size[0], sy * size[1]] for sx in (-0.5, 0.5) for sy in (-0.5, 0.5)])
        return local @ np.array([[c, s], [-s, c]])

    points = (corners(ego[2], ego_size)[:, None] + corners(obs_yaw, obs_size)[None]).reshape(-1, 2)
    hull = shapely.MultiPoint(points + np.array(ego[:2])).convex_hull
    if hull.geom_type != "Polygon":  # a zero-size footprint pair: a segment or a point
        return None
    return np.array(shapely.orient_polygons(hull).exterior.coords)[:-1]


@pytest.mark.parametrize("seed", range(6))
def test_fast_path_matches_exact_polygon_mass(seed):
    # Batched scenes with all kinds of covariances (tiny, huge, needle-like) against
    # polygon_gaussian_mass (SciPy's owens_t) on shapely's octagon: within P_TOL.
    rng = np.random.default_rng(100 + seed)
    n_traj, n_obs, n_t = 12, 6, 4
    ego_x = rng.uniform(-3, 3, (n_traj, n_t))
    ego_y = rng.uniform(-3, 3, (n_traj, n_t))
    ego_yaw = rng.uniform(-4, 4, (n_traj, n_t))
    scale = [0.05, 0.5, 2.0, 6.0, 1.0, 0.2][seed]
    cov = np.array(
        [
            [
                _cov(scale * rng.uniform(0.3, 1.5), scale * rng.uniform(0.05, 1.0), rng.uniform(0, 4))
                for _ in range(n_t)
            ]
            for _ in range(n_obs)
        ]
    )
    mean = rng.uniform(-7, 7, (n_obs, n_t, 2))
    heading = rng.uniform(-4, 4, (n_obs, n_t))
    size = SHAPES[seed % len(SHAPES)]
    length, width = rng.uniform(0.3, 12, n_obs), rng.uniform(0.3, 3, n_obs)
    p = collision_probability(
        ego_x, ego_y, ego_yaw, *size, mean, cov, heading, length, width, gate_sigmas=math.inf
    ).probability
    assert 0.05 < np.mean(p > 1e-3)  # informative: not all zero
    for i in range(n_traj):
        for k in range(n_obs):
            for t in range(n_t):
                poly = _octagon(
                    (ego_x[i, t], ego_y[i, t], ego_yaw[i, t]),
                    size,
                    heading[k, t],
                    (length[k], width[k]),
                )
                exact = polygon_gaussian_mass(poly, mean[k, t], cov[k, t])
                assert p[i, k, t] == pytest.approx(exact, abs=P_TOL)


@pytest.mark.parametrize(("ego_size", "obs_size"), [((4.5, 0.0), (1.8, 0.7)), ((4.5, 1.8), (0.0, 2.0))])
def test_zero_width_footprints_match_exact(ego_size, obs_size):
    # A zero-length edge pair (a footprint that is a segment) goes through the degenerate
    # branch of the fast path; the octagon is then a hexagon.
    rng = np.random.default_rng(4)
    for _ in range(40):
        ego = (rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-4, 4))
        obs_yaw = rng.uniform(-4, 4)
        mean = np.array(ego[:2]) + rng.uniform(-4, 4, 2)
        cov = _cov(rng.uniform(0.3, 2), rng.uniform(0.2, 1), rng.uniform(0, 4))
        p, _ = _single(ego, ego_size, mean, cov, obs_yaw, obs_size)
        exact = polygon_gaussian_mass(_octagon(ego, ego_size, obs_yaw, obs_size), mean, cov)
        assert p == pytest.approx(exact, abs=P_TOL)


def test_owens_t_kernel_and_tail_table_against_scipy():
    # The scalar kernels, called from a compiled loop over a grid, against SciPy.
    import numba
    from scipy.special import owens_t

    from ethical_planner.collision_probability import _FAR_MAX, _owens_t_unit, _upper_tail

    @numba.njit
    def grid(h, a, x):
        t = np.empty(h.shape)
        for i in range(h.shape[0]):
            for j in range(h.shape[1]):
                t[i, j] = _owens_t_unit(np.float32(h[i, j]), np.float32(a[i, j]))
        q = np.empty(x.size)
        for i in range(x.size):
            q[i] = _upper_tail(x[i])
        return t, q

    h = np.linspace(0.0, _FAR_MAX, 801)[:, None] * np.ones((1, 401))
    a = np.linspace(0.0, 1.0, 401)[None, :] * np.ones((801, 1))
    x = np.linspace(0.0, _FAR_MAX, 100_001)
    t32, q = grid(h, a, x)
    assert np.max(np.abs(t32 - owens_t(h, a))) < 3e-8
    assert np.max(np.abs(q - ndtr(-x))) < 2e-9


def test_threads_do_not_change_results():
    # Large enough for the threaded path; every triple is computed elementwise, so the
    # split over threads must not change a single bit.
    rng = np.random.default_rng(8)
    n_traj, n_obs, n_t = 600, 20, 21
    t = np.linspace(0, 2, n_t)
    ego_x = 10 * t[None, :] + rng.uniform(-1, 1, (n_traj, 1))
    ego_y = rng.uniform(-3, 3, (n_traj, 1)) * t[None, :]
    ego_yaw = rng.uniform(-0.2, 0.2, (n_traj, n_t))
    mean = np.stack(
        [rng.uniform(5, 40, (n_obs, 1)) + 5 * t, np.repeat(rng.uniform(-4, 4, (n_obs, 1)), n_t, 1)],
        axis=-1,
    )
    cov = np.array([[_cov(0.3 + 0.5 * tt, 0.2 + 0.3 * tt, 0.0) for tt in t] for _ in range(n_obs)])
    heading = np.zeros((n_obs, n_t))
    args = (ego_x, ego_y, ego_yaw, 4.5, 1.8, mean, cov, heading, np.full(n_obs, 4.5), np.full(n_obs, 1.8))
    results = [collision_probability(*args, workers=Workers(threads)) for threads in (1, 2, 3)]
    assert results[0].probability.size >= 200_000 and results[0].probability.max() > 0.5
    for other in results[1:]:
        np.testing.assert_array_equal(results[0].probability, other.probability)
        np.testing.assert_array_equal(results[0].mean_overlap, other.mean_overlap)


def test_drivable_area_shortcut_matches_the_corner_test():
    # risk.outside_drivable_area tests only candidates near the road edge corner by
    # corner (the others lie deep inside the eroded area); it must agree with testing
    # every corner, on a curved road with candidates hugging and crossing its edges.
    # The corners are written out here (centre +- half length along the heading +- half
    # width across it), independent of the planner's geometry helpers.
    from ethical_planner.environment import RoadEnvironment
    from ethical_planner.risk import outside_drivable_area
    from ethical_planner.road_users import Shape

    env = RoadEnvironment.along_path(
        [[0, 0], [20, 2], [40, 10], [55, 25], [60, 45]], lanes_left=1, lanes_right=0, margin=0.3
    )
    path = env.reference_path
    rng = np.random.default_rng(2)
    s = rng.uniform(0, path.length, (400, 30))
    d = rng.uniform(-3.5, 7.0, (400, 30))
    x, y = path.to_cartesian(s, d)
    yaw = path.heading(s) + rng.uniform(-0.6, 0.6, s.shape)

    class _Poses:
        pass

    poses = _Poses()
    poses.x, poses.y, poses.yaw = x, y, yaw
    half_l, half_w = 4.5 / 2, 1.8 / 2
    outside = np.zeros(s.shape, dtype=bool)
    for along, across in ((1, 1), (1, -1), (-1, -1), (-1, 1)):
        cx = x + along * half_l * np.cos(yaw) - across * half_w * np.sin(yaw)
        cy = y + along * half_l * np.sin(yaw) + across * half_w * np.cos(yaw)
        outside |= ~shapely.contains_xy(env.drivable_area, cx, cy)
    fast = outside_drivable_area(poses, Shape(4.5, 1.8), env)
    assert 0.1 < outside.mean() < 0.9
    np.testing.assert_array_equal(fast, outside)
