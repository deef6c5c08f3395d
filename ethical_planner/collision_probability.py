"""Collision probability of the ego footprint with Gaussian-predicted road users.

For every candidate trajectory u, road user k and step t this computes
p_k(u, t) = P(ego rectangle and k's rectangle overlap), with k's centre
distributed as N(mu_k(t), Sigma_k(t)) and k's heading held at its mean
(SPEC section 3). Overlap happens exactly when k's centre lies in the Minkowski
sum of the ego rectangle and k's rectangle (both are centrally symmetric, so no
reflection is needed), a convex octagon around the ego centre. Its Gaussian
mass is computed in closed form:

1. A vectorised distance gate sets p = 0 for triples whose circumscribed discs
   are more than ``gate_sigmas`` standard deviations (largest axis) apart, so
   the integral below runs on the few triples that matter.
2. Whitening with the Cholesky factor of Sigma turns the Gaussian into a
   standard one and the octagon into another convex polygon, the sum of four
   centred segments (two edges per rectangle). Each of its eight edges follows
   from the four whitened segments without sorting them by angle
   (:func:`_octagon_edges`).
3. The standard bivariate normal mass of a convex polygon is a sum of Owen's T
   functions, one pair per edge (see :func:`polygon_gaussian_mass`).

``polygon_gaussian_mass`` evaluates Owen's T with SciPy and is exact to rounding.
``collision_probability`` runs on the hot path and trades that for speed, within
a bound: Owen's T comes from a five-node Gauss-Legendre rule in float32 after the
reflection T(h, a) -> T(ah, 1/a) that keeps a <= 1 (each term within 3e-8,
:func:`_owens_t_unit`), the normal tail Q from a table (2e-9), and edges farther
than the gate radius from the mean are dropped (each below 7.6e-9, ``_FAR_MIN``).
With 16 terms per octagon, p is within 1e-6 of the closed form; measured against
the exact evaluation over 2.5 million triples, the largest difference was 5e-8.
It is a compiled kernel (``ethical_planner.jit``) that visits every triple once, with
no temporaries; for large inputs blocks of trajectories run on the threads of the
caller's ``ethical_planner.workers.Workers`` (``ETHICAL_PLANNER_THREADS``, default
min(2, CPU count), 1 inside a worker process); results do not depend on the number of
threads.

Everything is a pure function over struct-of-arrays inputs; nothing is mutated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import ndtr, owens_t

from ethical_planner.jit import kernel
from ethical_planner.validation import check_shape, shaped_array
from ethical_planner.workers import Workers

__all__ = [
    "CollisionProbability",
    "OctagonTables",
    "RiskMaximum",
    "collides",
    "collision_probability",
    "gate",
    "octagon_tables",
    "polygon_gaussian_mass",
    "risk_maximum",
]

#: An origin closer than this (whitened units) to an edge's line is "on" that line:
#: the edge's triangle (origin, a, b) then has mass below 0.4 * 1e-12 and counts 0.
_H_TOL = 1e-12
#: Fast path: h and t of an edge are sums of products of whitened quantities of order 10,
#: with absolute rounding errors near 1e-14; with the origin near a vertex (h and t both
#: tiny) their ratio, the wedge angle, is then ill-conditioned (an origin 1e-11 from a
#: vertex gave p 1e-6 off). An origin closer than this to an edge's line counts as on
#: that line: the edge's triangle (mass below h |ab| / (4 pi) < 1e-7 for |ab| < 40)
#: counts 0 and the winding number is the sum of the other edges' wedge angles, each
#: accurate to 1e-14 / _ON_LINE.
_ON_LINE = 3e-8
#: Exact path: edges farther than this (whitened units) from the origin contribute
#: |T(h, a)| <= Phi(-8.5) / 2 < 1e-17 and are skipped.
_H_SKIP = 8.5
#: Exact path: an edge whose closest point is farther than sqrt(_D2_SKIP) from the
#: origin contributes at most P(|Z| > d) = exp(-d^2 / 2) < 6e-17 and is skipped too.
_D2_SKIP = 75.0
#: Whitened edges shorter than this are degenerate (a zero footprint dimension).
_MIN_EDGE = 1e-12

#: Fast path: an edge whose closest point is r_min (whitened units) from the mean adds at
#: most exp(-r_min^2 / 2) / 2 to p (the part of its wedge beyond the edge, times the wedge
#: angle / 2 pi <= 1/2). Edges with r_min >= gate_sigmas, kept in [_FAR_MIN, _FAR_MAX],
#: are dropped (each below 7.6e-9 at the default 6 sigma, below 3e-17 as on the exact path
#: without a gate), and edge coordinates |t| are clamped to that radius (the mass beyond
#: the clamp, P(X > h, Y > t X / h) <= Q(h) Q(t), is smaller still).
_FAR_MIN = 6.0
_FAR_MAX = math.sqrt(_D2_SKIP)

#: Gauss-Legendre rule for T(h, a) = a / (2 pi) int_0^1 exp(-h^2 (1 + a^2 s^2) / 2) /
#: (1 + a^2 s^2) ds with 0 <= a <= 1: the integrand is even in s, so the positive half
#: of the 10-node rule on [-1, 1] is exact to 4.5e-9 (worst at h -> 0, a = 1, where
#: the poles s = +-i / a limit convergence). Stored as s_k^2 and w_k / (2 pi).
_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(10)
_GL_S2 = tuple(float(s * s) for s in _GL_NODES[5:])
_GL_W = tuple(float(w / (2.0 * math.pi)) for w in _GL_WEIGHTS[5:])

#: Upper normal tail Q(x) = P(Z > x) on [0, _FAR_MAX]: linear interpolation between nodes
#: every 1/4096, error below max|Q''| step^2 / 8 = 0.242 / 4096^2 / 8 < 2e-9.
_Q_STEP = 1.0 / 4096.0
_Q_TABLE = ndtr(-np.arange(int(_FAR_MAX / _Q_STEP) + 2) * _Q_STEP)
_Q_SLOPE = np.append(np.diff(_Q_TABLE), 0.0)

#: Owen's T on the hot path is evaluated in float32: rounding adds at most 2.6e-8 to the
#: Gauss-Legendre error (measured against SciPy on a 1601 x 801 grid).
#: From this many triples, ``collision_probability`` splits its work over the threads of
#: its ``Workers``.
_PARALLEL_MIN = 200_000
#: From this many gated triples, ``risk_maximum`` uses two threads.
_RISK_PARALLEL_MIN = 20_000


@dataclass(frozen=True, slots=True)
class CollisionProbability:
    """Collision probabilities of all candidates with all road users at all steps.

    Attributes:
        probability: P(footprints overlap), shape (n_traj, n_obs, n_t), float64 in [0, 1].
        mean_overlap: Whether the footprints overlap (touching counts) with the road
            user at its mean position, shape (n_traj, n_obs, n_t), bool.

    """

    probability: np.ndarray
    mean_overlap: np.ndarray


@dataclass(frozen=True, slots=True, eq=False)
class OctagonTables:
    """Per-step inputs of the octagon kernels, validated and flattened once per cycle.

    Attributes:
        obs_rows: per (road user, step), shape (_O_ROWS, n_obs * n_t): mean, whitening,
            the whitened road-user segments and their products, the covariance, the
            squared gate radius and the radius of the two footprints' discs.
            With K Gaussian components per road user (a mixture with a shared mean),
            column (obs * K + c) * n_t + step holds component c of road user obs.
        ego_rows: per (candidate, step), shape (_E_ROWS, n_traj * n_t): centre and the
            raw ego segments (L cos, -W sin) as x and (L sin, W cos) as y.
        weights: component weights per (road user, step), shape (n_obs * n_t, K) (ones
            for a single Gaussian); p of a triple is sum_c w_c p_c.
        n_traj, n_obs, n_t: sizes (n_obs road users, not components).
        degenerate: a footprint has a zero length or width (zero-length edges).
        far: edges farther than this from the mean are dropped [whitened units].
    """

    obs_rows: np.ndarray
    ego_rows: np.ndarray
    weights: np.ndarray
    n_traj: int
    n_obs: int
    n_t: int
    degenerate: bool
    far: float


def empty_tables(n_traj: int, n_t: int, gate_sigmas: float = 6.0) -> OctagonTables:
    """The ``octagon_tables`` of no road user: nothing to tabulate (no kernel reads a row without one).

    Args:
        n_traj: candidates. n_t: steps. gate_sigmas: as ``octagon_tables`` (>= 0).
    """
    far = min(max(gate_sigmas, _FAR_MIN), _FAR_MAX)
    empty = (np.zeros((_O_ROWS, 0)), np.zeros((_E_ROWS, 0)), np.ones((0, 1)))
    return OctagonTables(*empty, n_traj, 0, n_t, False, far)


def octagon_tables(
    ego_x: ArrayLike,
    ego_y: ArrayLike,
    ego_yaw: ArrayLike,
    ego_length: float,
    ego_width: float,
    obs_mean: ArrayLike,
    obs_cov: ArrayLike,
    obs_heading: ArrayLike,
    obs_length: ArrayLike,
    obs_width: ArrayLike,
    gate_sigmas: float = 6.0,
    component_weight: ArrayLike | None = None,
) -> OctagonTables:
    """Validate and flatten the inputs of the octagon kernels (see ``collision_probability``).

    Without ``component_weight`` each of the n_obs Gaussians is a road user. With it,
    shape (n_road_users, n_t, K), the n_obs = n_road_users * K Gaussians are the
    components of a mixture per road user, road user o's component c at o * K + c.

    Raises:
        ValueError: If an argument has the wrong shape, is not finite, a size is negative,
            or a covariance is not symmetric positive definite.
    """
    ex = shaped_array("ego_x", ego_x, "(n_traj, n_t)", 2)
    n_traj, n_t = ex.shape
    ey = shaped_array("ego_y", ego_y, "(n_traj, n_t)", 2, (n_traj, n_t))
    eyaw = shaped_array("ego_yaw", ego_yaw, "(n_traj, n_t)", 2, (n_traj, n_t))
    mean = shaped_array("obs_mean", obs_mean, "(n_obs, n_t, 2)", 3)
    n_obs = mean.shape[0]
    check_shape("obs_mean", mean, "(n_obs, n_t, 2)", (n_obs, n_t, 2))
    cov = shaped_array("obs_cov", obs_cov, "(n_obs, n_t, 2, 2)", 4, (n_obs, n_t, 2, 2))
    oyaw = shaped_array("obs_heading", obs_heading, "(n_obs, n_t)", 2, (n_obs, n_t))
    olen = shaped_array("obs_length", obs_length, "(n_obs,)", 1, (n_obs,))
    owid = shaped_array("obs_width", obs_width, "(n_obs,)", 1, (n_obs,))
    for name, size in (("ego_length", ego_length), ("ego_width", ego_width)):
        if not (math.isfinite(size) and size >= 0.0):
            raise ValueError(f"{name} must be a finite length >= 0 [m], got {size!r}")
    for name, sizes in (("obs_length", olen), ("obs_width", owid)):
        if np.any(sizes < 0.0):
            raise ValueError(f"{name} must be >= 0 [m], got {sizes}")
    if math.isnan(gate_sigmas) or gate_sigmas < 0.0:
        raise ValueError(f"gate_sigmas must be >= 0 (inf disables the gate), got {gate_sigmas!r}")

    # Edges dropped beyond gate_sigmas whitened units, the gate's own scale (_FAR_MIN).
    far = min(max(gate_sigmas, _FAR_MIN), _FAR_MAX)
    if n_obs == 0 and component_weight is None:
        return empty_tables(n_traj, n_t, gate_sigmas)

    # Per (obs, t), computed once and gathered for the survivors: whitening matrix
    # W = L^-1 = [[w11, 0], [w21, w22]] of the Cholesky factor L, closed form for 2x2.
    c11, c22 = cov[..., 0, 0], cov[..., 1, 1]
    c12 = 0.5 * (cov[..., 0, 1] + cov[..., 1, 0])
    asym = np.abs(cov[..., 0, 1] - cov[..., 1, 0])
    if np.any(asym > 1e-9 * (np.abs(c11) + np.abs(c22))):
        raise ValueError("obs_cov must be symmetric in its last two axes")
    det = c11 * c22 - c12 * c12
    if np.any(c11 <= 0.0) or np.any(det <= 0.0):
        raise ValueError("obs_cov must be positive definite (floor zero covariances first)")
    l11 = np.sqrt(c11)
    l21 = c12 / l11
    l22 = np.sqrt(det / c11)
    w11 = 1.0 / l11
    w22 = 1.0 / l22
    w21 = -l21 * w11 * w22

    # Gate radius per (obs, t): the octagon lies in the disc of radius r_ego + r_obs
    # around the ego centre, so outside the gate its mass is below Phi(-gate_sigmas).
    sigma_max = np.sqrt(0.5 * (c11 + c22) + np.sqrt(0.25 * (c11 - c22) ** 2 + c12 * c12))
    r_obs = 0.5 * np.hypot(olen, owid)
    discs = 0.5 * math.hypot(ego_length, ego_width) + r_obs[:, None]
    reach = discs + gate_sigmas * sigma_max

    # Road-user rows, (_O_ROWS, n_obs * n_t): mean, whitening, its two whitened edge
    # segments (along and across the heading), their lengths, cross and dot product,
    # and the cross product of the two whitened ego segments (det W * length * width).
    co, so = np.cos(oyaw), np.sin(oyaw)
    along = olen[:, None] * np.stack([co, so])  # (2, n_obs, n_t), raw [m]
    across = owid[:, None] * np.stack([-so, co])
    seg_x = np.stack([w11 * along[0], w11 * across[0]])
    seg_y = np.stack([w21 * along[0] + w22 * along[1], w21 * across[0] + w22 * across[1]])
    det_w = w11 * w22
    obs_rows = np.concatenate(
        [
            mean[..., 0][None],
            mean[..., 1][None],
            w11[None],
            w21[None],
            w22[None],
            seg_x,
            seg_y,
            np.sqrt(seg_x**2 + seg_y**2),
            (det_w * (olen * owid)[:, None])[None],
            (seg_x[0] * seg_x[1] + seg_y[0] * seg_y[1])[None],
            (det_w * (ego_length * ego_width))[None],
            (reach * reach)[None],
            c11[None],
            c12[None],
            c22[None],
            np.broadcast_to(discs, (n_obs, n_t))[None],
        ]
    ).reshape(_O_ROWS, n_obs * n_t)
    # Ego rows, (_E_ROWS, n_traj * n_t): centre and the raw ego segments, ordered so
    # that whitening is two broadcast products (see _octagon_edges).
    ce, se = np.cos(eyaw), np.sin(eyaw)
    ego_rows = np.stack([ex, ey, ego_length * ce, -ego_width * se, ego_length * se, ego_width * ce]).reshape(
        _E_ROWS, n_traj * n_t
    )
    degenerate = bool(n_obs) and min(ego_length, ego_width, float(olen.min()), float(owid.min())) <= 0.0
    if component_weight is None:
        weights = np.ones((n_obs * n_t, 1))
    else:
        weights = shaped_array("component_weight", component_weight, "(n_road_users, n_t, K)", 3)
        users, k = weights.shape[0], weights.shape[2]
        check_shape("component_weight", weights, "(n_road_users, n_t, K)", (users, n_t, k))
        if k == 0 or users * k != n_obs:
            raise ValueError(
                f"component_weight: {users} road users x {k} components must make the {n_obs} Gaussians"
            )
        n_obs = users
        weights = np.ascontiguousarray(weights.reshape(users * n_t, k))
    return OctagonTables(obs_rows, ego_rows, weights, n_traj, n_obs, n_t, degenerate, far)


def collision_probability(
    ego_x: ArrayLike,
    ego_y: ArrayLike,
    ego_yaw: ArrayLike,
    ego_length: float,
    ego_width: float,
    obs_mean: ArrayLike,
    obs_cov: ArrayLike,
    obs_heading: ArrayLike,
    obs_length: ArrayLike,
    obs_width: ArrayLike,
    gate_sigmas: float = 6.0,
    workers: Workers | None = None,
) -> CollisionProbability:
    """Probability that the ego footprint overlaps each road user's footprint, every triple.

    p is within 1e-6 of the closed-form Gaussian mass of the octagon (see the module
    docstring); triples cut by the gate are exactly 0.

    Args:
        ego_x: Ego centre x on each candidate [m], shape (n_traj, n_t).
        ego_y: Ego centre y [m], shape (n_traj, n_t).
        ego_yaw: Ego heading [rad], shape (n_traj, n_t).
        ego_length: Ego length [m], >= 0.
        ego_width: Ego width [m], >= 0.
        obs_mean: Predicted mean of each road user's centre [m], shape (n_obs, n_t, 2).
        obs_cov: Covariance of that centre [m^2], shape (n_obs, n_t, 2, 2), symmetric
            positive definite (the caller floors it, SPEC section 3).
        obs_heading: Road-user heading [rad], held at its mean, shape (n_obs, n_t).
        obs_length: Road-user lengths [m], shape (n_obs,), >= 0.
        obs_width: Road-user widths [m], shape (n_obs,), >= 0.
        gate_sigmas: Triples whose circumscribed discs are more than this many standard
            deviations (along the covariance's major axis) apart get p = 0 without an
            integral; the mass cut off is below Phi(-gate_sigmas) (1e-9 at 6).
            ``math.inf`` disables the gate.
        workers: helper threads; large inputs (from ``_PARALLEL_MIN`` triples) use them.
            None makes a fresh one for this call (threads from ``ETHICAL_PLANNER_THREADS``).

    Returns:
        Probabilities and mean-position overlaps, both of shape (n_traj, n_obs, n_t).

    Raises:
        ValueError: If an argument has the wrong shape, is not finite, a size is negative,
            or a covariance is not symmetric positive definite.

    """
    ego = (ego_x, ego_y, ego_yaw, ego_length, ego_width)
    tables = octagon_tables(*ego, obs_mean, obs_cov, obs_heading, obs_length, obs_width, gate_sigmas)
    n_traj, n_obs, n_t = tables.n_traj, tables.n_obs, tables.n_t
    probability = np.zeros((n_traj, n_obs, n_t))
    mean_overlap = np.zeros((n_traj, n_obs, n_t), dtype=bool)
    if probability.size == 0:
        return CollisionProbability(probability, mean_overlap)
    # Blocks of trajectories, at least two per thread so that the threads finish together;
    # each block writes its own rows of the outputs, so the result does not depend on
    # which thread runs which block.
    workers = Workers() if workers is None else workers
    threads = workers.threads if probability.size >= _PARALLEL_MIN else 1
    block = -(-n_traj // (2 * threads)) if threads > 1 else n_traj
    jobs = [(start, min(start + block, n_traj)) for start in range(0, n_traj, block)]

    def run(job: tuple[int, int]) -> None:
        rows = (tables.obs_rows, tables.ego_rows, n_obs, n_t, job[0], job[1])
        _gate_and_integrate(*rows, tables.degenerate, tables.far, probability, mean_overlap)

    workers.parallel_for(jobs, run)
    return CollisionProbability(probability, mean_overlap)


def collides(tables: OctagonTables, rows: np.ndarray, first_step: int = 0) -> np.ndarray:
    """Whether each candidate of ``rows`` meets a predicted mean occupancy at some step.

    The footprints overlap, touching counts, with a road user at its predicted mean
    (the ``mean_overlap`` of ``collision_probability``, any road user, any step from
    ``first_step`` on).

    Args:
        tables: the cycle's tables.
        rows: candidate indices, shape (m,).
        first_step: the first step tested (1 leaves out the present, t = 0).

    Returns:
        Shape (m,), bool.
    """
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    out = np.zeros(rows.size, dtype=bool)
    if rows.size and tables.n_obs:
        k = tables.weights.shape[1]
        _collides(
            tables.obs_rows,
            tables.ego_rows,
            tables.n_obs * k,
            k,
            tables.n_t,
            first_step,
            rows,
            tables.degenerate,
            out,
        )
    return out


def gate(tables: OctagonTables, rows: np.ndarray) -> np.ndarray:
    """The triples of candidates ``rows`` that pass the distance gate (see ``collision_probability``).

    Args:
        tables: the cycle's tables.
        rows: candidate indices, shape (m,).

    Returns:
        Flat indices (i * n_obs + obs) * n_t + step of the triples, i indexing ``rows``,
        ascending.
    """
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    flat = np.empty(rows.size * tables.n_obs * tables.n_t, dtype=np.int64)
    if not flat.size:
        return flat
    k = tables.weights.shape[1]
    return flat[: _gate_triples(tables.obs_rows, tables.ego_rows, tables.n_obs, k, tables.n_t, rows, flat)]


@dataclass(frozen=True, slots=True, eq=False)
class RiskMaximum:
    """Eq. 3 of (candidate, road user) pairs from their gated triples, shape (m, n_obs) each.

    Attributes:
        risk_obs: R_k = max_t p H_obs.
        risk_ego: R_ego,k = max_t p H_ego.
        maximin_harm_obs: highest harm of the road user at a step with p > epsilon (0 if none).
        maximin_harm_ego: the ego's harm, likewise.
        peak_probability: highest p (exact if ``onset`` was asked for; otherwise the
            highest of the integrals evaluated, a lower bound).
        onset_step: first step at which p reaches half its peak (0 without any p > 0);
            only if ``onset`` was asked for, else 0.
        triples: triples that passed the gate.
        integrals: octagon integrals evaluated (the rest were shown not to matter).
    """

    risk_obs: np.ndarray
    risk_ego: np.ndarray
    maximin_harm_obs: np.ndarray
    maximin_harm_ego: np.ndarray
    peak_probability: np.ndarray
    onset_step: np.ndarray
    triples: int
    integrals: int


def risk_maximum(
    tables: OctagonTables,
    rows: np.ndarray,
    flat: np.ndarray,
    harm_obs: np.ndarray,
    harm_ego: np.ndarray,
    epsilon: float,
    onset: bool = False,
    workers: Workers | None = None,
    cap: int = 0,
) -> RiskMaximum:
    """Eq. 3 and maximin's harms of every (candidate, road user) pair, integrals only where they matter.

    The results are those of evaluating p at every gated triple. Eq. 3 takes a maximum
    over time: a triple whose upper bound of p, times its harm, lies below the maximum
    found so far, below epsilon (or with harms below those already
    counted for maximin), and, with ``onset``, below half the highest p found so far,
    changes none of the results; its integral is skipped. The bounds (the footprints'
    discs, then the octagon's bounding rectangles, plus the 1e-6 accuracy of p) bound
    the computed p, so the results are those of the full evaluation to the bit. A
    mixture's bound is the weighted sum of its components' bounds (0 for a component
    the gate cuts: its p is 0), which bounds its p = sum_c w_c p_c.

    Args:
        tables: the cycle's tables.
        rows: candidate indices, shape (m,).
        flat: their gated triples (``gate``).
        harm_obs: the road user's harm of each triple's collision, shape like ``flat``.
        harm_ego: the ego's harm, likewise.
        epsilon: maximin's collision-probability threshold.
        onset: also find each pair's highest p and the step where p first reaches half
            of it (the responsibility's collision geometry), exactly.
        workers: threads for large inputs.
        cap: if > 0, at most this many integrals per pair, in the visiting order (highest
            bound x harm first): the results are then lower bounds of the exact ones
            (R and maximin's harms are maxima over the steps evaluated, a subset), each
            p computed as the full evaluation computes it. Not with ``onset``.

    Returns:
        The results per pair; pairs without gated triples have 0 everywhere.
    """
    if cap and onset:
        raise ValueError("risk_maximum: cap (lower bounds) cannot find the onset exactly; use cap=0")
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    m, n_obs, n_t = rows.size, tables.n_obs, tables.n_t
    out = np.zeros((5, m, n_obs))
    onset_step = np.zeros((m, n_obs), dtype=np.int64)
    counts = np.zeros((2, 2), dtype=np.int64)
    # Two halves split at a pair boundary for two threads: each writes its own pairs.
    cuts = [0, flat.size]
    workers = Workers() if workers is None else workers
    if workers.threads > 1 and flat.size >= _RISK_PARALLEL_MIN:
        middle = int(np.searchsorted(flat, (flat[flat.size // 2] // n_t) * n_t))
        cuts = [0, middle, flat.size] if 0 < middle < flat.size else cuts
    harm_obs = np.ascontiguousarray(harm_obs, dtype=float)
    harm_ego = np.ascontiguousarray(harm_ego, dtype=float)

    inputs = (tables.obs_rows, tables.ego_rows, tables.weights, n_obs, n_t, rows, flat, harm_obs, harm_ego)

    def run(job: int) -> None:
        settings = (epsilon, onset, tables.degenerate, tables.far, cap)
        _risk_maximum(*inputs, cuts[job], cuts[job + 1], *settings, out, onset_step, counts[job])

    workers.parallel_for(list(range(len(cuts) - 1)), run)
    total = counts.sum(axis=0)
    return RiskMaximum(*out, onset_step, int(total[0]), int(total[1]))


def polygon_gaussian_mass(vertices: ArrayLike, mean: ArrayLike, cov: ArrayLike) -> np.ndarray:
    """Probability mass of N(mean, cov) inside convex polygons.

    Whitening z = L^-1 (v - mean) with cov = L L^T maps the polygon to a convex
    counter-clockwise polygon under a standard normal. For an edge a -> b with unit
    direction u, outward normal n = (u_y, -u_x), signed distance h = a.n and
    t1 = a.u, t2 = b.u, the signed mass of the triangle (0, a, b) is the mass of
    its angular wedge minus the mass beyond the edge,
    sign(h) * ([atan(t2/|h|) - atan(t1/|h|)] / (2 pi) - [T(|h|, t2/|h|) - T(|h|, t1/|h|)]),
    with Owen's T(h, a) = P(X > h, 0 < Y < a X). The wedge terms add up to the
    winding number of the polygon around the origin, so
    mass = [origin inside] - sum over edges of sign(h) [T(|h|, t2/|h|) - T(|h|, t1/|h|)].
    When the mean lies on an edge's line (|h| < 1e-12 in whitened units) that edge's
    triangle is degenerate and counts 0, and the wedge angles of the other edges are
    summed explicitly: the winding number is then 1/2 on an edge and the interior
    angle / (2 pi) at a vertex, so p stays continuous there.

    Args:
        vertices: Polygon vertices [m], counter-clockwise, convex, shape (..., k, 2) with
            k >= 3; repeated vertices (zero-length edges) are allowed.
        mean: Gaussian means [m], shape (..., 2), same leading shape as ``vertices``.
        cov: Covariances [m^2], symmetric positive definite, shape (..., 2, 2).

    Returns:
        Masses in [0, 1], shape (...).

    Raises:
        ValueError: On mismatched shapes, non-finite values, a clockwise or non-convex
            polygon, or a covariance that is not symmetric positive definite.

    """
    verts = shaped_array("vertices", vertices, "(..., k, 2)")
    if verts.ndim < 2 or verts.shape[-1] != 2 or verts.shape[-2] < 3:
        raise ValueError(f"vertices must have shape (..., k, 2) with k >= 3, got {verts.shape}")
    batch = verts.shape[:-2]
    mu = shaped_array("mean", mean, "(..., 2)", len(batch) + 1, (*batch, 2))
    sig = shaped_array("cov", cov, "(..., 2, 2)", len(batch) + 2, (*batch, 2, 2))
    k = verts.shape[-2]
    verts = verts.reshape(-1, k, 2)
    mu = mu.reshape(-1, 2)
    sig = sig.reshape(-1, 2, 2)

    ex = np.roll(verts[..., 0], -1, axis=1) - verts[..., 0]
    ey = np.roll(verts[..., 1], -1, axis=1) - verts[..., 1]
    turn = ex * np.roll(ey, -1, axis=1) - ey * np.roll(ex, -1, axis=1)
    scale = np.max(np.abs(verts), axis=(1, 2), keepdims=False)[:, None] + 1.0
    if np.any(turn < -1e-12 * scale * scale):
        raise ValueError("vertices must describe convex polygons in counter-clockwise order")

    if np.any(np.abs(sig[:, 0, 1] - sig[:, 1, 0]) > 1e-9 * (np.abs(sig[:, 0, 0]) + 1.0)):
        raise ValueError("cov must be symmetric in its last two axes")
    try:
        chol = np.linalg.cholesky(sig)
    except np.linalg.LinAlgError:
        raise ValueError("cov must be positive definite") from None
    rel = verts - mu[:, None, :]
    # L is lower triangular, so L^-1 r is a forward substitution, two lines for 2x2.
    zx = rel[..., 0] / chol[:, 0, 0, None]
    zy = (rel[..., 1] - chol[:, 1, 0, None] * zx) / chol[:, 1, 1, None]
    mass, _ = _standard_polygon_mass(zx, zy)
    return mass.reshape(batch)


def _standard_polygon_mass(zx: np.ndarray, zy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the standard normal mass of convex CCW polygons, exactly (SciPy's owens_t).

    Args:
        zx: Whitened vertex x, shape (m, k).
        zy: Whitened vertex y, shape (m, k).

    Returns:
        Mass clipped to [0, 1], shape (m,), and whether the origin lies in the closed
        polygon, shape (m,).

    """
    bx = np.roll(zx, -1, axis=1)
    by = np.roll(zy, -1, axis=1)
    ex = bx - zx
    ey = by - zy
    length = np.hypot(ex, ey)
    valid = length > _MIN_EDGE
    inv_length = np.divide(1.0, length, out=np.zeros_like(length), where=valid)
    ux = ex * inv_length
    uy = ey * inv_length
    t1 = zx * ux + zy * uy
    t2 = bx * ux + by * uy
    # h from the endpoint nearer to the origin: near a vertex, h and t then carry
    # relative (not absolute) rounding errors and t/h stays accurate.
    a_nearer = zx * zx + zy * zy <= bx * bx + by * by
    h = np.where(a_nearer, zx * uy - zy * ux, bx * uy - by * ux)
    # Degenerate edges get h = +inf: never on a line, never outside, never integrated.
    h = np.where(valid, h, np.inf).T
    t1, t2 = t1.T, t2.T
    on_line = np.abs(h) < _H_TOL
    inside = np.all(h > -_H_TOL, axis=0)
    winding = _winding(h, t1, t2, on_line)

    # Closest distance^2 from the origin to the edge segment bounds the edge's term.
    d2 = h * h + np.where(t1 > 0.0, t1 * t1, np.where(t2 < 0.0, t2 * t2, 0.0))
    need = ~on_line & (np.abs(h) <= _H_SKIP) & (d2 <= _D2_SKIP)
    # owens_t costs ~100 ns a call: evaluate it only where it can matter.
    hn = h[need]
    ha = np.abs(hn)
    term = owens_t(ha, t2[need] / ha) - owens_t(ha, t1[need] / ha)
    contrib = np.zeros_like(h)
    contrib[need] = np.copysign(term, hn)
    mass = winding - contrib.sum(axis=0)
    return np.clip(mass, 0.0, 1.0), inside


def _winding(h: np.ndarray, t1: np.ndarray, t2: np.ndarray, on_line: np.ndarray) -> np.ndarray:
    """Sum of the wedge angles / (2 pi) of convex polygons seen from the origin.

    With the origin off every edge line the wedge angles add up to the winding number,
    1 inside and 0 outside. On an edge line (the mean on the boundary, or on the
    extension of an edge) the winding number is not an integer: the wedge angles of the
    other edges are summed explicitly; the degenerate triangles count 0.

    Args:
        h: Signed distance of each edge line from the origin, shape (k, m), +inf for a
            degenerate edge.
        t1: Coordinate of each edge's start along its direction, shape (k, m).
        t2: Coordinate of its end, shape (k, m).
        on_line: |h| < 1e-12, shape (k, m).

    Returns:
        Wedge-angle sums in [0, 1], shape (m,).

    """
    winding = np.all(h > 0.0, axis=0).astype(np.float64)
    rows = np.flatnonzero(np.any(on_line, axis=0))
    if rows.size:
        hr = h[:, rows]
        keep = ~on_line[:, rows] & np.isfinite(hr)
        har = np.where(keep, np.abs(hr), 1.0)
        wedge = np.copysign(np.arctan(t2[:, rows] / har) - np.arctan(t1[:, rows] / har), hr)
        winding[rows] = np.sum(np.where(keep, wedge, 0.0), axis=0) / (2.0 * math.pi)
    return winding


# --- fast path: compiled kernels (gate, octagon edges, Owen's T) ----------------------------

# Rows of the per-(obs, t) table built by octagon_tables: mean x, y; whitening
# w11, w21, w22; the whitened road-user segments (x of both, y of both, lengths of both);
# det W * length * width of the road user; the dot product of its two segments;
# det W * length * width of the ego; the squared gate radius; the covariance c11, c12,
# c22; the sum of the radii of the two footprints' circumscribed discs.
_O_MX, _O_MY, _O_W11, _O_W21, _O_W22 = 0, 1, 2, 3, 4
_O_SX, _O_SY, _O_LEN = 5, 7, 9
_O_C, _O_D, _O_CEGO, _O_REACH2 = 11, 12, 13, 14
_O_C11, _O_C12, _O_C22, _O_DISCS = 15, 16, 17, 18
_O_ROWS = 19
# Rows of the per-(traj, t) table: centre x, y and the raw ego segments
# (L cos, -W sin) as x and (L sin, W cos) as y.
_E_ROWS = 6

#: The Gauss-Legendre rule and the tail table as the kernels read them.
_GL_S2_32 = np.array(_GL_S2, dtype=np.float32)
_GL_W_32 = np.array(_GL_W, dtype=np.float32)
_Q_INV_STEP = 1.0 / _Q_STEP
_TWO_PI = 2.0 * math.pi


@kernel
def _upper_tail(x: float) -> float:
    """Q(x) = P(Z > x) for 0 <= x <= _FAR_MAX by linear interpolation (see _Q_STEP)."""
    node = x * _Q_INV_STEP
    index = int(node)  # truncation = floor for x >= 0
    return _Q_TABLE[index] + (node - index) * _Q_SLOPE[index]


@kernel
def _owens_t_unit(h: np.float32, a: np.float32) -> np.float32:
    """Owen's T(h, a) for h >= 0 and 0 <= a <= 1 (see _GL_S2), in float32.

    exp(-h^2 (1 + a^2 s^2) / 2) / (1 + a^2 s^2), weighted and summed over the nodes.
    """
    a2 = a * a
    half_h2 = (h * h) * np.float32(-0.5)
    total = np.float32(0.0)
    for node in range(_GL_S2_32.size):
        y = a2 * _GL_S2_32[node] + np.float32(1.0)
        total += math.exp(half_h2 * y) / y * _GL_W_32[node]
    return total * a


@kernel
def _edge_endpoint(abs_h: float, tail_h: float, t: float, far: float) -> float:
    """E(|h|, t) = T(|h|, t / |h|) of one edge end, |t| clamped to ``far`` (see _FAR_MIN).

    For |t| <= |h|, T(|h|, |t| / |h|) has a <= 1; otherwise Owen's reflection
    T(h, a) = Q(h) / 2 + Q(ah) / 2 - Q(h) Q(ah) - T(ah, 1 / a) (a > 1) does, with ah = |t|.
    """
    abs_t = min(abs(t), far)
    big = np.float32(max(abs_t, abs_h))
    small = np.float32(min(abs_t, abs_h)) / big
    owens = float(_owens_t_unit(big, small))
    if abs_t > abs_h:
        owens = _upper_tail(abs_t) * (0.5 - tail_h) + tail_h * 0.5 - owens
    return math.copysign(owens, t)


@kernel
def _octagon_edges(
    obs_rows: np.ndarray, o: int, ego_rows: np.ndarray, e: int, degenerate: bool, edges: np.ndarray
) -> None:
    """Whitened edges of one Minkowski octagon, as distances and spans from the origin.

    The octagon is the sum of four centred segments g_k (the road user's and the ego's
    whitened edge vectors, k = 0, 1 road user, 2, 3 ego), a zonotope. With
    u_k = g_k / |g_k| and n_k = (u_ky, -u_kx), its face with outward normal n_k lies
    rho_k = sum_{i != k} |g_k x g_i| / (2 |g_k|) from the centre z and runs along u_k
    from tau_k = sum_{i != k} s_ki (g_k . g_i) / (2 |g_k|) - |g_k| / 2 to tau_k + |g_k|
    (relative to z), s_ki = -sign(g_k x g_i), the side of n_k that g_i points to. The
    opposite face, direction -u_k, is its mirror image through z. Parallel segments
    (a zero cross product) may take either sign as long as s_ik = -s_ki: they split
    their common face in two. Seen from the origin (the road user's mean), edge k has
    h = rho_k + z . n_k and t1 = tau_k + z . u_k, edge k + 4 has h = rho_k - z . n_k and
    t1 = tau_k - z . u_k, both t2 = t1 + |g_k| (the conventions of polygon_gaussian_mass).

    Args:
        obs_rows: the per-(obs, t) table, shape (_O_ROWS, n_obs * n_t).
        o: column of the (obs, t) pair.
        ego_rows: the per-(traj, t) table, shape (_E_ROWS, n_traj * n_t).
        e: column of the (traj, t) pair.
        degenerate: a footprint has a zero length or width (zero-length edges).
        edges: shape (6, 8), written: h, t1, t2 and |g| of the eight edges (whitened
            units; degenerate edges have h = t1 = t2 = 0), and in rows 4 and 5 the
            octagon's extent along u_k, k = 0..3, [z . u_k - s_k, z . u_k + s_k] with the
            zonotope's support s_k = sum_i |g_i . u_k| / 2.
    """
    w11 = obs_rows[_O_W11, o]
    w21 = obs_rows[_O_W21, o]
    w22 = obs_rows[_O_W22, o]
    # Whitened ego centre relative to the mean, z = W (ego - mean), doubled below.
    z0 = ego_rows[0, e] - obs_rows[_O_MX, o]
    z1 = ego_rows[1, e] - obs_rows[_O_MY, o]
    z1 = z1 * w22 + w21 * z0
    z0 = z0 * w11
    sx0, sx1 = obs_rows[_O_SX, o], obs_rows[_O_SX + 1, o]
    sy0, sy1 = obs_rows[_O_SY, o], obs_rows[_O_SY + 1, o]
    # Whitened ego segments: W (L cos, L sin) and W (-Wd sin, Wd cos).
    sx2 = w11 * ego_rows[2, e]
    sx3 = w11 * ego_rows[3, e]
    sy2 = w21 * ego_rows[2, e] + w22 * ego_rows[4, e]
    sy3 = w21 * ego_rows[3, e] + w22 * ego_rows[5, e]
    length = edges[3]
    length[0] = obs_rows[_O_LEN, o]
    length[1] = obs_rows[_O_LEN + 1, o]
    length[2] = math.sqrt(sx2 * sx2 + sy2 * sy2)
    length[3] = math.sqrt(sx3 * sx3 + sy3 * sy3)
    # Road-user x ego cross and dot products [road-user segment][ego segment].
    c02 = sx0 * sy2 - sy0 * sx2
    c03 = sx0 * sy3 - sy0 * sx3
    c12 = sx1 * sy2 - sy1 * sx2
    c13 = sx1 * sy3 - sy1 * sx3
    d02 = sx0 * sx2 + sy0 * sy2
    d03 = sx0 * sx3 + sy0 * sy3
    d12 = sx1 * sx2 + sy1 * sy2
    d13 = sx1 * sx3 + sy1 * sy3
    ego_dot = sx2 * sx3 + sy2 * sy3
    obs_cross, obs_dot, ego_cross = obs_rows[_O_C, o], obs_rows[_O_D, o], obs_rows[_O_CEGO, o]
    # 2 |g_k| rho_k: the two same-body cross products are det W * length * width >= 0.
    rho0 = abs(c02) + abs(c03) + obs_cross
    rho1 = abs(c12) + abs(c13) + obs_cross
    rho2 = abs(c02) + abs(c12) + ego_cross
    rho3 = abs(c03) + abs(c13) + ego_cross
    # 2 |g_k| tau_k + |g_k|^2 = sum_i s_ki (g_k . g_i). For a mixed pair (k road user,
    # i ego) s_ki (g_k . g_i) = -copysign(1, cross) * dot; for a same-body pair
    # (cross >= 0, the second segment taking s = +1) it is -dot for the first, +dot
    # for the second segment.
    m02 = math.copysign(1.0, c02) * d02
    m03 = math.copysign(1.0, c03) * d03
    m12 = math.copysign(1.0, c12) * d12
    m13 = math.copysign(1.0, c13) * d13
    tau0 = -(m02 + m03) - obs_dot
    tau1 = -(m12 + m13) + obs_dot
    tau2 = (m02 + m12) - ego_dot
    tau3 = (m03 + m13) + ego_dot
    # 2 |g_k| (z . n_k) = 2 (z x g_k) and 2 |g_k| (z . u_k) = 2 (z . g_k): everything is
    # scaled by 2 |g_k| until the one multiplication by 1 / (2 |g_k|).
    z0 *= 2.0
    z1 *= 2.0
    h, t1, t2 = edges[0], edges[1], edges[2]
    for k in range(4):
        if k == 0:
            gx, gy, rho, tau = sx0, sy0, rho0, tau0
            dots = abs(obs_dot) + abs(d02) + abs(d03)
        elif k == 1:
            gx, gy, rho, tau = sx1, sy1, rho1, tau1
            dots = abs(obs_dot) + abs(d12) + abs(d13)
        elif k == 2:
            gx, gy, rho, tau = sx2, sy2, rho2, tau2
            dots = abs(d02) + abs(d12) + abs(ego_dot)
        else:
            gx, gy, rho, tau = sx3, sy3, rho3, tau3
            dots = abs(d03) + abs(d13) + abs(ego_dot)
        across = gy * z0 - gx * z1
        along = gx * z0 + gy * z1
        size = length[k]
        half_inv = 0.0 if degenerate and not size > _MIN_EDGE else 0.5 / size
        half = size * 0.5
        h[k] = (rho + across) * half_inv
        h[k + 4] = (rho - across) * half_inv
        t1[k] = (tau + along) * half_inv - half
        t1[k + 4] = (tau - along) * half_inv - half
        t2[k] = t1[k] + size
        t2[k + 4] = t1[k + 4] + size
        # 2 |g_k| (z . u_k) = along and 2 |g_k| s_k = |g_k|^2 + sum_{i != k} |g_k . g_i|.
        centre = along * half_inv
        support = (size * size + dots) * half_inv
        edges[4, k] = centre - support
        edges[5, k] = centre + support


@kernel
def _octagon_mass(edges: np.ndarray, far: float) -> float:
    """Gaussian mass in [0, 1] of an octagon from its edges (``_octagon_edges``).

    mass = winding number - sum of the edge terms sign(h) [E(|h|, t2) - E(|h|, t1)]
    (see polygon_gaussian_mass). An edge whose closest point is r_min from the origin
    adds at most exp(-r_min^2 / 2) / 2: edges with r_min >= ``far`` are dropped. An
    origin on an edge's line (|h| < _ON_LINE) makes that edge's triangle degenerate (it
    counts 0) and the winding number the sum of the other edges' wedge angles.
    """
    h, t1, t2 = edges[0], edges[1], edges[2]
    lowest = np.inf
    lowest_h2 = np.inf
    for k in range(8):
        lowest = min(lowest, h[k])
        lowest_h2 = min(lowest_h2, h[k] * h[k])
    tol2 = _ON_LINE * _ON_LINE
    if lowest_h2 < tol2:
        # Wedge angles of the edges off the origin's line (see _winding).
        winding = 0.0
        for k in range(8):
            if h[k] * h[k] >= tol2:
                wedge = math.atan(t2[k] / abs(h[k])) - math.atan(t1[k] / abs(h[k]))
                winding += math.copysign(wedge, h[k])
        winding /= _TWO_PI
    else:
        winding = 1.0 if lowest > 0.0 else 0.0
    total = 0.0
    far2 = far * far
    for k in range(8):
        h2 = h[k] * h[k]
        nearest = max(min(t2[k], 0.0), t1[k])  # the edge point nearest to the foot of h
        if nearest * nearest + h2 < far2 and h2 >= tol2:
            abs_h = abs(h[k])
            tail_h = _upper_tail(abs_h)
            term = _edge_endpoint(abs_h, tail_h, t2[k], far) - _edge_endpoint(abs_h, tail_h, t1[k], far)
            total += math.copysign(term, h[k])
    return min(max(winding - total, 0.0), 1.0)


@kernel
def _gate_and_integrate(
    obs_rows: np.ndarray,
    ego_rows: np.ndarray,
    n_obs: int,
    n_t: int,
    start: int,
    stop: int,
    degenerate: bool,
    far: float,
    probability: np.ndarray,
    mean_overlap: np.ndarray,
) -> None:
    """Gate trajectories ``start:stop`` against every (obs, t) and integrate the survivors.

    Args:
        obs_rows: the per-(obs, t) table, shape (_O_ROWS, n_obs * n_t).
        ego_rows: the per-(traj, t) table, shape (_E_ROWS, n_traj * n_t).
        n_obs: number of road users.
        n_t: number of steps.
        start: first trajectory of the block.
        stop: one past its last trajectory.
        degenerate: a footprint has a zero length or width.
        far: edges farther than this from the mean are dropped [whitened units].
        probability: output, shape (n_traj, n_obs, n_t), rows ``start:stop`` written
            where the gate lets a triple through (the rest stays 0).
        mean_overlap: output, same shape: the mean lies in the closed octagon.
    """
    edges = np.empty((6, 8))
    for traj in range(start, stop):
        for obs in range(n_obs):
            for step in range(n_t):
                o = obs * n_t + step
                e = traj * n_t + step
                dx = ego_rows[0, e] - obs_rows[_O_MX, o]
                dy = ego_rows[1, e] - obs_rows[_O_MY, o]
                # reach^2 is inf without a gate, which keeps every triple.
                if dx * dx + dy * dy <= obs_rows[_O_REACH2, o]:
                    _octagon_edges(obs_rows, o, ego_rows, e, degenerate, edges)
                    lowest = np.inf
                    for k in range(8):
                        lowest = min(lowest, edges[0, k])
                    # Touching counts: on the inner side of every edge line, within _H_TOL.
                    mean_overlap[traj, obs, step] = lowest > -_H_TOL
                    probability[traj, obs, step] = _octagon_mass(edges, far)


# --- bounds and the risk maximum (paper Eq. 3) without integrals that cannot matter ----------

#: Slack [1] added to every upper bound of p before it is compared: the computed p is
#: within 1e-6 of the true mass (module docstring), the bounds bound the true mass.
_BOUND_SLACK = 1e-6
#: Largest error of the tabulated tail (see _Q_STEP).
_Q_ERROR = 2e-9
#: The largest tail the table holds, an upper bound of Q beyond it.
_Q_FLOOR = float(_Q_TABLE[int(_FAR_MAX / _Q_STEP)])


@kernel
def _tail_bounds(x: float) -> tuple[float, float]:
    """Lower and upper bound of Q(x) = P(Z > x) for x >= 0.

    Linear interpolation of the convex Q overestimates it by at most _Q_ERROR.
    """
    if x >= _FAR_MAX:
        return 0.0, _Q_FLOOR
    upper = _upper_tail(x)
    return max(upper - _Q_ERROR, 0.0), upper


@kernel
def _slab_upper(low: float, high: float) -> float:
    """Upper bound of the standard normal mass of [low, high]."""
    if low >= 0.0:
        return _tail_bounds(low)[1] - _tail_bounds(high)[0]
    if high <= 0.0:
        return _tail_bounds(-high)[1] - _tail_bounds(-low)[0]
    return min(1.0 - _tail_bounds(-low)[0] - _tail_bounds(high)[0], 1.0)


@kernel
def _disc_bound(obs_rows: np.ndarray, o: int, ego_rows: np.ndarray, e: int) -> float:
    """Upper bound of the true p from the footprints' circumscribed discs.

    The octagon lies in the disc of radius r (both discs' radii) around the ego centre,
    at distance d from the mean; beyond d - r along that direction u lies a half-plane
    holding the disc, of mass Q((d - r) / sigma_u), sigma_u^2 = u^T Sigma u.
    """
    dx = ego_rows[0, e] - obs_rows[_O_MX, o]
    dy = ego_rows[1, e] - obs_rows[_O_MY, o]
    d2 = dx * dx + dy * dy
    radius = obs_rows[_O_DISCS, o]
    if d2 <= radius * radius:
        return 1.0
    c11, c12, c22 = obs_rows[_O_C11, o], obs_rows[_O_C12, o], obs_rows[_O_C22, o]
    variance = dx * dx * c11 + 2.0 * dx * dy * c12 + dy * dy * c22  # d^2 u^T Sigma u
    gap = math.sqrt(d2) - radius
    return _tail_bounds(gap * math.sqrt(d2 / variance))[1]


@kernel
def _rectangle_bound(edges: np.ndarray) -> float:
    """Upper bound of the true p from the octagon's bounding rectangles (``_octagon_edges``).

    In the frame (n_k, u_k) of each edge direction the octagon lies in the rectangle
    [-h_{k+4}, h_k] x [u extent]; the standard normal's coordinates along orthonormal
    directions are independent, so its mass is the product of two interval masses.
    The best of the four frames is returned.
    """
    best = 1.0
    for k in range(4):
        if edges[3, k] > _MIN_EDGE:
            across = _slab_upper(-edges[0, k + 4], edges[0, k])
            best = min(best, across * _slab_upper(edges[4, k], edges[5, k]))
    return best


@kernel
def _collides(
    obs_rows: np.ndarray,
    ego_rows: np.ndarray,
    n_gauss: int,
    n_components: int,
    n_t: int,
    first_step: int,
    rows: np.ndarray,
    degenerate: bool,
    out: np.ndarray,
) -> None:
    """Whether candidate ``rows[i]`` meets a predicted mean occupancy at a step >= ``first_step``, out[i].

    The footprints overlap (touching counts) when the mean lies in the closed octagon,
    which needs the discs to overlap first. A mixture's components share the mean:
    component 0 of each road user (every ``n_components``-th of the n_gauss) decides.
    """
    edges = np.empty((6, 8))
    for i in range(rows.size):
        traj = rows[i]
        found = False
        for obs in range(0, n_gauss, n_components):
            for step in range(first_step, n_t):
                o = obs * n_t + step
                e = traj * n_t + step
                dx = ego_rows[0, e] - obs_rows[_O_MX, o]
                dy = ego_rows[1, e] - obs_rows[_O_MY, o]
                radius = obs_rows[_O_DISCS, o]
                if dx * dx + dy * dy <= radius * radius:
                    _octagon_edges(obs_rows, o, ego_rows, e, degenerate, edges)
                    lowest = np.inf
                    for k in range(8):
                        lowest = min(lowest, edges[0, k])
                    if lowest > -_H_TOL:
                        found = True
                        break
            if found:
                break
        out[i] = found


@kernel
def _gate_triples(
    obs_rows: np.ndarray,
    ego_rows: np.ndarray,
    n_obs: int,
    n_components: int,
    n_t: int,
    rows: np.ndarray,
    flat: np.ndarray,
) -> int:
    """Triples (i, obs, step) of candidates ``rows[i]`` that pass the gate of some component.

    Writes their flat indices (i * n_obs + obs) * n_t + step, ascending, to ``flat``
    (capacity rows.size * n_obs * n_t) and returns how many.
    """
    count = 0
    for i in range(rows.size):
        traj = rows[i]
        for obs in range(n_obs):
            for step in range(n_t):
                e = traj * n_t + step
                for c in range(n_components):
                    o = (obs * n_components + c) * n_t + step
                    dx = ego_rows[0, e] - obs_rows[_O_MX, o]
                    dy = ego_rows[1, e] - obs_rows[_O_MY, o]
                    if dx * dx + dy * dy <= obs_rows[_O_REACH2, o]:
                        flat[count] = (i * n_obs + obs) * n_t + step
                        count += 1
                        break
    return count


@kernel
def _in_gate(obs_rows: np.ndarray, o: int, ego_rows: np.ndarray, e: int) -> bool:
    """Whether the (Gaussian, step) column o and the (candidate, step) column e pass the gate."""
    dx = ego_rows[0, e] - obs_rows[_O_MX, o]
    dy = ego_rows[1, e] - obs_rows[_O_MY, o]
    return dx * dx + dy * dy <= obs_rows[_O_REACH2, o]


@kernel
def _risk_maximum(
    obs_rows: np.ndarray,
    ego_rows: np.ndarray,
    weights: np.ndarray,
    n_obs: int,
    n_t: int,
    rows: np.ndarray,
    flat: np.ndarray,
    harm_obs: np.ndarray,
    harm_ego: np.ndarray,
    first: int,
    last: int,
    epsilon: float,
    onset: bool,
    degenerate: bool,
    far: float,
    cap: int,
    out: np.ndarray,
    onset_step: np.ndarray,
    counts: np.ndarray,
) -> None:
    """Eq. 3 and the maximin harms of the (candidate, road user) pairs of triples first:last.

    Per pair, over its triples that pass the gate (``_gate_triples``), the outputs equal
    those of evaluating p at every triple: R = max_t p H (road user and ego), the highest
    harms at steps with p > epsilon, and with ``onset`` the highest p and the first step
    where p reaches half of it. Triples are visited in decreasing order of an upper bound
    of p H; a triple whose upper bound of p (``_disc_bound``, then ``_rectangle_bound``,
    plus _BOUND_SLACK) shows it can change none of the outputs known so far keeps its
    integral unevaluated.

    Args:
        obs_rows, ego_rows, weights, n_obs, n_t: the tables (``OctagonTables``).
        rows: the candidates' rows in the tables, shape (m,).
        flat: the triples' flat indices (i * n_obs + obs) * n_t + step, ascending.
        harm_obs, harm_ego: harm of each triple's collision, same length as ``flat``.
        first: first triple to process; must start a pair.
        last: one past the last; must end a pair.
        epsilon: maximin's collision-probability threshold.
        onset: also find the highest p and its onset step exactly.
        degenerate, far: see ``OctagonTables``.
        cap: at most this many integrals per pair if > 0 (lower bounds, see ``risk_maximum``).
        out: shape (5, m, n_obs), written for the pairs processed (others untouched):
            R_obs, R_ego, maximin harm of the road user and of the ego (0 without a
            step above epsilon), highest p (with ``onset``; else of the evaluated steps).
        onset_step: shape (m, n_obs), written with ``onset`` (0 without any p > 0).
        counts: shape (2,), incremented: triples visited and integrals evaluated.
    """
    edges = np.empty((weights.shape[1], 6, 8))
    order = np.empty(n_t, dtype=np.int64)
    key = np.empty(n_t)
    bound = np.empty(n_t)
    probability = np.empty(n_t)
    pair_out = np.empty(5)
    start = first
    while start < last:
        pair = flat[start] // n_t
        stop = start + 1
        while stop < last and flat[stop] // n_t == pair:
            stop += 1
        i, obs = pair // n_obs, pair % n_obs
        _visiting_order(
            obs_rows,
            ego_rows,
            weights,
            n_t,
            obs,
            rows[i],
            flat,
            harm_obs,
            harm_ego,
            start,
            stop,
            bound,
            key,
            order,
        )
        counts[1] += _pair_maximum(
            obs_rows,
            ego_rows,
            weights,
            n_t,
            obs,
            rows[i],
            flat,
            harm_obs,
            harm_ego,
            start,
            stop,
            epsilon,
            onset,
            degenerate,
            far,
            cap if cap > 0 else -1,
            bound,
            order,
            probability,
            edges,
            pair_out,
        )
        counts[0] += stop - start
        for q in range(5):
            out[q, i, obs] = pair_out[q]
        if onset:
            onset_step[i, obs] = 0
            if pair_out[4] > 0.0:
                for j in range(stop - start):  # steps ascend within a pair
                    if probability[j] >= 0.5 * pair_out[4]:
                        onset_step[i, obs] = flat[start + j] % n_t
                        break
        start = stop


@kernel
def _visiting_order(
    obs_rows: np.ndarray,
    ego_rows: np.ndarray,
    weights: np.ndarray,
    n_t: int,
    obs: int,
    row: int,
    flat: np.ndarray,
    harm_obs: np.ndarray,
    harm_ego: np.ndarray,
    start: int,
    stop: int,
    bound: np.ndarray,
    key: np.ndarray,
    order: np.ndarray,
) -> None:
    """Upper bounds of p from the discs (``bound``) and the visiting order by bound x harm.

    For the triples start:stop of one pair (road user ``obs``, candidate table row
    ``row``): ``bound[j]`` is the disc bound plus _BOUND_SLACK (a mixture's: the
    weighted sum of its components' within the gate), ``order[:stop - start]`` sorts
    them by decreasing bound x max(harm of the road user, harm of the ego).
    """
    size = stop - start
    n_components = weights.shape[1]
    for j in range(size):
        step = flat[start + j] % n_t
        e = row * n_t + step
        total = 0.0
        for c in range(n_components):
            o = (obs * n_components + c) * n_t + step
            if n_components == 1 or _in_gate(obs_rows, o, ego_rows, e):
                total += weights[obs * n_t + step, c] * (_disc_bound(obs_rows, o, ego_rows, e) + _BOUND_SLACK)
        bound[j] = total
        key[j] = -bound[j] * max(harm_obs[start + j], harm_ego[start + j])
        order[j] = j
    for j in range(1, size):  # insertion sort: at most n_t elements
        value, k = order[j], j
        while k > 0 and key[order[k - 1]] > key[value]:
            order[k] = order[k - 1]
            k -= 1
        order[k] = value


@kernel
def _mixture_mass(
    obs_rows: np.ndarray,
    ego_rows: np.ndarray,
    weights: np.ndarray,
    n_t: int,
    obs: int,
    step: int,
    e: int,
    far: float,
    edges: np.ndarray,
) -> float:
    """The collision probability of one triple from its components' edge tables (``_pair_maximum``).

    sum_c w_c p_c over the components within the gate, clipped to [0, 1] for a mixture.
    """
    n_components = weights.shape[1]
    p = 0.0
    for c in range(n_components):
        o = (obs * n_components + c) * n_t + step
        if n_components == 1 or _in_gate(obs_rows, o, ego_rows, e):
            p += weights[obs * n_t + step, c] * _octagon_mass(edges[c], far)
    if n_components > 1:
        p = min(max(p, 0.0), 1.0)
    return p


@kernel
def _pair_maximum(
    obs_rows: np.ndarray,
    ego_rows: np.ndarray,
    weights: np.ndarray,
    n_t: int,
    obs: int,
    row: int,
    flat: np.ndarray,
    harm_obs: np.ndarray,
    harm_ego: np.ndarray,
    start: int,
    stop: int,
    epsilon: float,
    onset: bool,
    degenerate: bool,
    far: float,
    cap: int,
    bound: np.ndarray,
    order: np.ndarray,
    probability: np.ndarray,
    edges: np.ndarray,
    out: np.ndarray,
) -> int:
    """The outputs of one pair (see ``_risk_maximum``), visiting its triples in ``order``.

    Writes ``out`` (5,): R_obs, R_ego, maximin harms of the road user and of the ego,
    highest p; ``probability[j]`` is p of triple j where evaluated, else -1. Returns the
    number of integrals evaluated. A mixture's p is sum_c w_c p_c over the components
    within the gate (the others' p is 0), clipped to [0, 1] as in
    ``ethical_planner.risk.prediction_collision_probability``; ``edges`` holds one
    table per component, shape (K, 6, 8). It stops after ``cap`` integrals (the outputs
    are then maxima over a subset of the steps: lower bounds); -1 evaluates all needed.
    """
    n_components = weights.shape[1]
    risk_obs = risk_ego = 0.0
    worst_obs = worst_ego = -1.0
    peak = 0.0
    integrals = 0
    for j in range(stop - start):
        probability[j] = -1.0
    for rank in range(stop - start):
        if integrals == cap:
            break
        j = order[rank]
        h_obs, h_ego = harm_obs[start + j], harm_ego[start + j]
        upper = bound[j]
        for attempt in range(2):
            if (
                upper * h_obs <= risk_obs
                and upper * h_ego <= risk_ego
                and (upper <= epsilon or (h_obs <= worst_obs and h_ego <= worst_ego))
                and (not onset or upper < 0.5 * peak)
            ):
                break
            step = flat[start + j] % n_t
            e = row * n_t + step
            if attempt == 0:
                total = 0.0
                for c in range(n_components):
                    o = (obs * n_components + c) * n_t + step
                    if n_components == 1 or _in_gate(obs_rows, o, ego_rows, e):
                        _octagon_edges(obs_rows, o, ego_rows, e, degenerate, edges[c])
                        total += weights[obs * n_t + step, c] * (_rectangle_bound(edges[c]) + _BOUND_SLACK)
                upper = min(upper, total)
                continue
            p = _mixture_mass(obs_rows, ego_rows, weights, n_t, obs, step, e, far, edges)
            integrals += 1
            probability[j] = p
            risk_obs = max(risk_obs, p * h_obs)
            risk_ego = max(risk_ego, p * h_ego)
            peak = max(peak, p)
            if p > epsilon:
                worst_obs = max(worst_obs, h_obs)
                worst_ego = max(worst_ego, h_ego)
    out[0], out[1] = risk_obs, risk_ego
    out[2], out[3] = max(worst_obs, 0.0), max(worst_ego, 0.0)
    out[4] = peak
    return integrals
