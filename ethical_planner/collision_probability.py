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
The work runs in chunks on reused scratch buffers (no allocation in the loop) and,
for large inputs, on the threads of the caller's ``ethical_planner.workers.Workers``
(``ETHICAL_PLANNER_THREADS``, default min(2, CPU count), 1 inside a worker process);
results do not depend on the number of threads.

Everything is a pure function over struct-of-arrays inputs; nothing is mutated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import ndtr, owens_t

from ethical_planner.validation import check_shape, shaped_array
from ethical_planner.workers import Scratch, Workers

__all__ = ["CollisionProbability", "collision_probability", "polygon_gaussian_mass"]

#: An origin closer than this (whitened units) to an edge's line is "on" that line:
#: the edge's triangle (origin, a, b) then has mass below 0.4 * 1e-12 and counts 0.
_H_TOL = 1e-12
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

#: Owen's T on the hot path is evaluated in float32 (twice the SIMD width): rounding adds
#: at most 2.6e-8 to the Gauss-Legendre error (measured against SciPy on a 1601 x 801 grid).
_OWENS_DTYPE = np.float32

#: Survivor triples per kernel call on one thread: large enough to amortise numpy's
#: per-call cost, small enough that the scratch buffers stay in cache.
_CHUNK = 4096
#: Triples gated per block (a block of trajectories against all road users and steps).
_GATE_BLOCK = 32768
#: With two threads numpy must run long loops between Python statements: each thread
#: switch hands the GIL over (a wake-up of the other core, tens of us on a VM), so the
#: threaded path uses 4x larger chunks and blocks, and only from this many triples on.
_CHUNK_THREADED = 16384
_GATE_BLOCK_THREADED = 131072
_PARALLEL_MIN = 200_000


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
    """Probability that the ego footprint overlaps each road user's footprint.

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
        workers: helper threads and scratch buffers; large inputs (from
            ``_PARALLEL_MIN`` triples) use its threads. None makes a fresh one for this
            call (threads from ``ETHICAL_PLANNER_THREADS``); pass one to reuse buffers.

    Returns:
        Probabilities and mean-position overlaps, both of shape (n_traj, n_obs, n_t).

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

    probability = np.zeros((n_traj, n_obs, n_t))
    mean_overlap = np.zeros((n_traj, n_obs, n_t), dtype=bool)
    if probability.size == 0:
        return CollisionProbability(probability, mean_overlap)

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
    reach = 0.5 * math.hypot(ego_length, ego_width) + r_obs[:, None] + gate_sigmas * sigma_max

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
        ]
    ).reshape(_O_ROWS, n_obs * n_t)
    # Ego rows, (_E_ROWS, n_traj * n_t): centre and the raw ego segments, ordered so
    # that whitening is two broadcast products (see _octagon_edges).
    ce, se = np.cos(eyaw), np.sin(eyaw)
    ego_rows = np.stack([ex, ey, ego_length * ce, -ego_width * se, ego_length * se, ego_width * ce]).reshape(
        _E_ROWS, n_traj * n_t
    )
    degenerate = min(ego_length, ego_width, float(olen.min()), float(owid.min())) <= 0.0

    # Edges dropped beyond gate_sigmas whitened units, the gate's own scale (_FAR_MIN).
    far = min(max(gate_sigmas, _FAR_MIN), _FAR_MAX)
    problem = _Problem(n_traj, n_obs, n_t, obs_rows, ego_rows, degenerate, far)
    # Blocks of trajectories: small enough for the cache, at least two per thread so that
    # the threads finish together.
    workers = Workers() if workers is None else workers
    threads = workers.threads if probability.size >= _PARALLEL_MIN else 1
    chunk, gate_block = (_CHUNK, _GATE_BLOCK) if threads == 1 else (_CHUNK_THREADED, _GATE_BLOCK_THREADED)
    block = max(1, min(gate_block // (n_obs * n_t), -(-n_traj // (2 * threads))))
    jobs = [(start, min(start + block, n_traj)) for start in range(0, n_traj, block)]

    def run(job: tuple[int, int]) -> None:
        start, stop = job
        _gate_and_integrate(
            problem, start, stop, chunk, probability[start:stop], mean_overlap[start:stop], workers.scratch
        )

    # Each block writes its own rows of the outputs, so the result does not depend on
    # which thread runs which block.
    if threads > 1:
        workers.parallel_for(jobs, run)
    else:
        for job in jobs:
            run(job)
    return CollisionProbability(probability, mean_overlap)


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


# --- fast path: gate, octagon edges, Owen's T ---------------------------------------------

# Rows of the per-(obs, t) table built in collision_probability.
_O_MX, _O_MY, _O_W, _O_SX, _O_SY, _O_LEN, _O_C, _O_D, _O_CEGO, _O_REACH2 = (
    0,
    1,
    slice(2, 5),
    slice(5, 7),
    slice(7, 9),
    slice(9, 11),
    11,
    12,
    13,
    14,
)
_O_ROWS = 15
_E_ROWS = 6


@dataclass(frozen=True, slots=True, eq=False)
class _Problem:
    """Inputs of one ``collision_probability`` call, flattened for gathers.

    Attributes:
        n_traj: number of candidates.
        n_obs: number of road users.
        n_t: number of steps.
        obs_rows: per-(obs, t) rows (see collision_probability), shape (15, n_obs * n_t).
        ego_rows: per-(traj, t) rows x, y, L cos, -W sin, L sin, W cos, shape (6, n_traj * n_t).
        degenerate: a footprint has a zero length or width (zero-length edges).
        far: edges farther than this from the mean are dropped [whitened units] (_FAR_MIN).
    """

    n_traj: int
    n_obs: int
    n_t: int
    obs_rows: np.ndarray
    ego_rows: np.ndarray
    degenerate: bool
    far: float


def _gate_and_integrate(
    problem: _Problem,
    start: int,
    stop: int,
    chunk: int,
    probability: np.ndarray,
    mean_overlap: np.ndarray,
    scratch: Scratch,
) -> None:
    """Gate trajectories ``start:stop`` against every (obs, t) and integrate the survivors.

    Args:
        problem: the flattened inputs.
        start: first trajectory of the block.
        stop: one past its last trajectory.
        chunk: survivors per kernel call.
        probability: output rows ``start:stop``, shape (stop - start, n_obs, n_t), written.
        mean_overlap: output rows, same shape, written.
        scratch: the calling thread's scratch buffers.

    """
    n_obs, n_t = problem.n_obs, problem.n_t
    b = stop - start
    obs, ego = problem.obs_rows, problem.ego_rows
    # Squared centre distance of every triple of the block, compared with reach^2.
    ex = ego[0, start * n_t : stop * n_t].reshape(b, 1, n_t)
    ey = ego[1, start * n_t : stop * n_t].reshape(b, 1, n_t)
    dx = scratch.get("gate_dx", (b, n_obs, n_t))
    dy = scratch.get("gate_dy", (b, n_obs, n_t))
    np.subtract(ex, obs[_O_MX].reshape(n_obs, n_t), out=dx)
    np.subtract(ey, obs[_O_MY].reshape(n_obs, n_t), out=dy)
    dx *= dx
    dy *= dy
    dx += dy
    keep = scratch.get("gate_keep", (b, n_obs, n_t), np.bool_)
    # reach^2 is inf without a gate, which keeps every triple.
    np.less_equal(dx, obs[_O_REACH2].reshape(n_obs, n_t), out=keep)
    survivors = np.flatnonzero(keep)
    if survivors.size == 0:
        return
    p_flat = probability.reshape(-1)
    overlap_flat = mean_overlap.reshape(-1)
    per_traj = n_obs * n_t
    for first in range(0, survivors.size, chunk):
        flat = survivors[first : first + chunk]
        m = flat.size
        # Flat triple index (traj, obs, t) -> (obs, t) and (traj, t) row indices.
        o = scratch.get("idx_o", (m,), np.intp)
        e = scratch.get("idx_e", (m,), np.intp)
        step = scratch.get("idx_t", (m,), np.intp)
        np.remainder(flat, n_t, out=step)
        np.remainder(flat, per_traj, out=o)
        np.floor_divide(flat, per_traj, out=e)
        e *= n_t
        e += step
        e += start * n_t
        mass, inside = _octagon_mass(problem, o, e, scratch)
        p_flat[flat] = mass
        overlap_flat[flat] = inside


def _octagon_mass(
    problem: _Problem, o: np.ndarray, e: np.ndarray, scratch: Scratch
) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian mass of the Minkowski octagons of ``m`` surviving triples.

    Args:
        problem: the flattened inputs.
        o: (obs, t) row of each triple, shape (m,).
        e: (traj, t) row of each triple, shape (m,).

    Returns:
        Mass in [0, 1] and whether the mean lies in the closed octagon, shape (m,) each;
        views into scratch buffers, valid until the next call on this thread.

    """
    h, t1, t2 = _octagon_edges(problem, o, e, scratch)
    m = o.size
    get = scratch.get
    # The mean lies in the closed octagon (touching counts) when it is on the inner side
    # of every edge line, and strictly inside (winding number 1) when strictly so.
    lowest = get("lowest_h", (m,))
    np.minimum.reduce(h, axis=0, out=lowest)
    inside = get("inside", (m,), np.bool_)
    np.greater(lowest, -_H_TOL, out=inside)
    winding = get("winding", (m,))
    np.greater(lowest, 0.0, out=winding, casting="unsafe")
    # An edge's term is the mass of the part of its wedge beyond the edge, all at least
    # r_min (the edge's distance from the origin) away: below exp(-r_min^2 / 2) / 2.
    # Keep edges with r_min < far and off the origin's line (|h| >= _H_TOL, see
    # _winding); typically about half of them. Compress those, integrate, add back.
    h2 = get("h2", (8, m))
    np.multiply(h, h, out=h2)
    np.minimum.reduce(h2, axis=0, out=lowest)
    on_line = np.flatnonzero(lowest < _H_TOL * _H_TOL)
    if on_line.size:
        rows = (slice(None), on_line)
        winding[on_line] = _winding(h[rows], t1[rows], t2[rows], h2[rows] < _H_TOL * _H_TOL)
    r2 = get("r2", (8, m))
    np.minimum(t2, 0.0, out=r2)
    np.maximum(r2, t1, out=r2)  # the edge point nearest to the foot of h, along u
    r2 *= r2
    r2 += h2
    active = get("active", (8, m), np.bool_)
    test = get("active_test", (8, m), np.bool_)
    np.less(r2, problem.far * problem.far, out=active)
    np.greater_equal(h2, _H_TOL * _H_TOL, out=test)
    active &= test
    where = np.flatnonzero(active)
    n = where.size
    mass = get("mass", (m,))
    if n:
        hs = get("h_active", (n,))
        ts = get("t_active", (2, n))
        h.take(where, out=hs)
        t1.take(where, out=ts[0])
        t2.take(where, out=ts[1])
        terms = _edge_terms(hs, ts, problem.far, scratch)
        np.remainder(where, m, out=where)  # flat (edge, triple) -> triple
        np.subtract(winding, np.bincount(where, weights=terms, minlength=m), out=mass)
    else:
        mass[...] = winding
    np.clip(mass, 0.0, 1.0, out=mass)
    return mass, inside


def _octagon_edges(
    problem: _Problem, o: np.ndarray, e: np.ndarray, scratch: Scratch
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Whitened edges of the Minkowski octagons, as distances and spans from the origin.

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
        problem: the flattened inputs.
        o: (obs, t) row of each triple, shape (m,).
        e: (traj, t) row of each triple, shape (m,).

    Returns:
        h, t1, t2 of the eight edges, shape (8, m) each (whitened units; degenerate
        edges have h = t1 = t2 = 0). Views into scratch buffers.

    """
    m = o.size
    get = scratch.get
    obs, ego = problem.obs_rows, problem.ego_rows
    p = get("obs_mean_w", (5, m))  # mean x, y and w11, w21, w22
    np.take(obs[:5], o, axis=1, out=p)
    seg_x = get("seg_x", (4, m))
    seg_y = get("seg_y", (4, m))
    seg_len = get("seg_len", (4, m))
    np.take(obs[_O_SX], o, axis=1, out=seg_x[:2])
    np.take(obs[_O_SY], o, axis=1, out=seg_y[:2])
    np.take(obs[_O_LEN], o, axis=1, out=seg_len[:2])
    k = get("obs_cross", (3, m))  # obs cross, obs dot, det W * ego length * width
    np.take(obs[_O_C : _O_CEGO + 1], o, axis=1, out=k)
    q = get("ego", (_E_ROWS, m))
    np.take(ego, e, axis=1, out=q)
    w11, w21, w22 = p[2], p[3], p[4]

    # Whitened ego centre relative to the mean: z = W (ego - mean).
    z = get("z", (2, m))
    np.subtract(q[:2], p[:2], out=z)
    tmp = get("tmp", (4, m))
    np.multiply(w21, z[0], out=tmp[0])
    z[1] *= w22
    z[1] += tmp[0]
    z[0] *= w11
    # Whitened ego segments: W (L cos, L sin) and W (-Wd sin, Wd cos).
    np.multiply(w11, q[2:4], out=seg_x[2:])
    np.multiply(w21, q[2:4], out=seg_y[2:])
    np.multiply(w22, q[4:6], out=tmp[:2])
    seg_y[2:] += tmp[:2]
    np.multiply(seg_x[2:], seg_x[2:], out=seg_len[2:])
    np.multiply(seg_y[2:], seg_y[2:], out=tmp[:2])
    seg_len[2:] += tmp[:2]
    np.sqrt(seg_len[2:], out=seg_len[2:])
    half_inv = get("half_inv", (4, m))
    if problem.degenerate:
        half_inv.fill(0.0)
        np.divide(0.5, seg_len, out=half_inv, where=seg_len > _MIN_EDGE)
    else:
        np.divide(0.5, seg_len, out=half_inv)

    # Road-user x ego cross and dot products, (2, 2, m): [obs segment, ego segment].
    cross = get("cross", (2, 2, m))
    dot = get("dot", (2, 2, m))
    tmp22 = get("tmp22", (2, 2, m))
    np.multiply(seg_x[:2, None], seg_y[None, 2:], out=cross)
    np.multiply(seg_y[:2, None], seg_x[None, 2:], out=tmp22)
    cross -= tmp22
    np.multiply(seg_x[:2, None], seg_x[None, 2:], out=dot)
    np.multiply(seg_y[:2, None], seg_y[None, 2:], out=tmp22)
    dot += tmp22
    ego_dot = get("ego_dot", (m,))
    np.multiply(seg_x[2], seg_x[3], out=ego_dot)
    np.multiply(seg_y[2], seg_y[3], out=tmp[0])
    ego_dot += tmp[0]

    # 2 |g_k| rho_k: the two same-body cross products are det W * length * width >= 0.
    rho = get("rho", (4, m))
    np.abs(cross, out=tmp22)
    np.add(tmp22[:, 0], tmp22[:, 1], out=rho[:2])
    np.add(tmp22[0], tmp22[1], out=rho[2:])
    rho[:2] += k[0]
    rho[2:] += k[2]
    # 2 |g_k| tau_k + |g_k|^2 = sum_i s_ki (g_k . g_i). For a mixed pair (k road user,
    # i ego) s_ki (g_k . g_i) = -copysign(1, cross) * dot; for a same-body pair
    # (cross >= 0, the second segment taking s = +1) it is -dot for the first, +dot
    # for the second segment.
    np.copysign(1.0, cross, out=tmp22)
    tmp22 *= dot
    tau = get("tau", (4, m))
    np.add(tmp22[:, 0], tmp22[:, 1], out=tau[:2])
    np.negative(tau[:2], out=tau[:2])
    tau[0] -= k[1]
    tau[1] += k[1]
    np.add(tmp22[0], tmp22[1], out=tau[2:])
    tau[2] -= ego_dot
    tau[3] += ego_dot

    # 2 |g_k| (z . n_k) = 2 (z x g_k) and 2 |g_k| (z . u_k) = 2 (z . g_k): everything
    # is scaled by 2 |g_k| until the one multiplication by 1 / (2 |g_k|) below.
    across_z = get("across_z", (4, m))
    along_z = get("along_z", (4, m))
    z *= 2.0
    np.multiply(seg_y, z[0], out=across_z)
    np.multiply(seg_x, z[1], out=tmp)
    across_z -= tmp
    np.multiply(seg_x, z[0], out=along_z)
    np.multiply(seg_y, z[1], out=tmp)
    along_z += tmp

    h = get("h", (8, m))
    t1 = get("t1", (8, m))
    t2 = get("t2", (8, m))
    np.add(rho, across_z, out=h[:4])
    np.subtract(rho, across_z, out=h[4:])
    np.add(tau, along_z, out=t1[:4])
    np.subtract(tau, along_z, out=t1[4:])
    # Edges k and k + 4 share |g_k|: view (8, m) as (2, 4, m) to scale both at once.
    h_pairs = h.reshape(2, 4, m)
    h_pairs *= half_inv
    t1_pairs = t1.reshape(2, 4, m)
    t1_pairs *= half_inv
    np.multiply(seg_len, 0.5, out=tmp)
    t1_pairs -= tmp
    np.add(t1_pairs, seg_len, out=t2.reshape(2, 4, m))

    return h, t1, t2


def _edge_terms(h: np.ndarray, t: np.ndarray, far: float, scratch: Scratch) -> np.ndarray:
    """sign(h) [E(|h|, t2) - E(|h|, t1)] of edges with _H_TOL <= |h| < far.

    E(h, t) = T(h, t / h) is the standard normal mass of {X > h, 0 < Y < t X / h}
    (negative for t < 0). For |t| <= h, T(h, |t| / h) has a <= 1; otherwise Owen's
    reflection T(h, a) = Q(h) / 2 + Q(ah) / 2 - Q(h) Q(ah) - T(ah, 1 / a) (a > 1, h >= 0)
    does, with ah = |t|. |t| is clamped to ``far`` (see _FAR_MIN).

    Args:
        h: Signed edge distances, shape (n,).
        t: Edge start and end coordinates t1, t2, shape (2, n).
        far: clamp for |t| [whitened units], <= _FAR_MAX.

    Returns:
        The terms, shape (n,), a scratch view.

    """
    n = h.size
    get = scratch.get
    # x rows: |h|, then |t1|, |t2| clamped; their upper normal tails in one call.
    x = get("tail_x", (3, n))
    np.abs(h, out=x[0])
    np.abs(t, out=x[1:])
    np.minimum(x[1:], far, out=x[1:])
    tail = _upper_tail(x, scratch)
    ah, at = x[0], x[1:]
    big = get("owens_h", (2, n), _OWENS_DTYPE)
    small = get("owens_a", (2, n), _OWENS_DTYPE)
    np.maximum(at, ah, out=big, casting="same_kind")
    np.minimum(at, ah, out=small, casting="same_kind")
    small /= big
    owens = get("owens", (2, n))
    owens[...] = _owens_t_unit(big, small, scratch)
    # Reflected value Q(h) / 2 + Q(t) (1/2 - Q(h)) - T(t, h / t) where |t| > |h|.
    reflected = get("reflected", (2, n))
    half_minus = get("half_minus", (n,))
    np.subtract(0.5, tail[0], out=half_minus)
    np.multiply(tail[1:], half_minus, out=reflected)
    np.multiply(tail[0], 0.5, out=half_minus)
    reflected += half_minus
    reflected -= owens
    flip = get("flip", (2, n), np.bool_)
    np.greater(at, ah, out=flip)
    np.copyto(owens, reflected, where=flip)
    np.copysign(owens, t, out=owens)
    terms = get("terms", (n,))
    np.subtract(owens[1], owens[0], out=terms)
    np.copysign(terms, h, out=terms)
    return terms


def _owens_t_unit(h: np.ndarray, a: np.ndarray, scratch: Scratch) -> np.ndarray:
    """Owen's T(h, a) for h >= 0 and 0 <= a <= 1 (see _GL_S2), in the dtype of ``h``.

    Args:
        h: shape (2, n).
        a: shape (2, n).

    Returns:
        T, shape (2, n), a scratch view.

    """
    shape, dtype = h.shape, h.dtype.type
    get = scratch.get
    a2 = get("owens_a2", shape, dtype)
    half_h2 = get("owens_q", shape, dtype)
    y = get("owens_y", shape, dtype)
    term = get("owens_term", shape, dtype)
    total = get("owens_total", shape, dtype)
    np.multiply(a, a, out=a2)
    np.multiply(h, h, out=half_h2)
    half_h2 *= -0.5
    total.fill(0.0)
    for s2, weight in zip(_GL_S2, _GL_W, strict=True):
        # exp(-h^2 (1 + a^2 s^2) / 2) / (1 + a^2 s^2), weighted.
        np.multiply(a2, s2, out=y)
        y += 1.0
        np.multiply(half_h2, y, out=term)
        np.exp(term, out=term)
        term /= y
        term *= weight
        total += term
    total *= a
    return total


def _upper_tail(x: np.ndarray, scratch: Scratch) -> np.ndarray:
    """Q(x) = P(Z > x) for 0 <= x <= _FAR_MAX by linear interpolation (see _Q_STEP); a scratch view."""
    get = scratch.get
    node = get("tail_node", x.shape)
    index = get("tail_index", x.shape, np.intp)
    out = get("tail_out", x.shape)
    np.multiply(x, 1.0 / _Q_STEP, out=node)
    index[...] = node  # truncation = floor for x >= 0
    node -= index
    np.take(_Q_SLOPE, index, out=out)
    node *= out
    np.take(_Q_TABLE, index, out=out)
    out += node
    return out
