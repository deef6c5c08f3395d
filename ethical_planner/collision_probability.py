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
2. The octagon is built by merging the edge directions of both rectangles.
3. Whitening with the Cholesky factor of Sigma turns the Gaussian into a
   standard one and the octagon into another convex, counter-clockwise polygon.
4. The standard bivariate normal mass of a convex polygon is a sum of Owen's T
   functions, one pair per edge (see :func:`polygon_gaussian_mass`).

Everything is a pure function over struct-of-arrays inputs; nothing is mutated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import owens_t

__all__ = ["CollisionProbability", "collision_probability", "polygon_gaussian_mass"]

#: An origin closer than this (whitened units) to an edge's line is "on" that line:
#: the edge's triangle (origin, a, b) then has mass below 0.4 * 1e-12 and counts 0.
_H_TOL = 1e-12
#: Edges farther than this (whitened units) from the origin contribute
#: |T(h, a)| <= Phi(-8.5) / 2 < 1e-17 and are skipped.
_H_SKIP = 8.5
#: An edge whose closest point is farther than sqrt(_D2_SKIP) from the origin
#: contributes at most P(|Z| > d) = exp(-d^2 / 2) < 6e-17 and is skipped too.
_D2_SKIP = 75.0
#: Whitened edges shorter than this are degenerate (a zero footprint dimension).
_MIN_EDGE = 1e-12
_HALF_PI = 0.5 * math.pi


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
) -> CollisionProbability:
    """Probability that the ego footprint overlaps each road user's footprint.

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

    Returns:
        Probabilities and mean-position overlaps, both of shape (n_traj, n_obs, n_t).

    Raises:
        ValueError: If an argument has the wrong shape, is not finite, a size is negative,
            or a covariance is not symmetric positive definite.

    """
    ex = _float_array(ego_x, "ego_x", 2, "(n_traj, n_t)")
    n_traj, n_t = ex.shape
    ey = _float_array(ego_y, "ego_y", 2, "(n_traj, n_t)", (n_traj, n_t))
    eyaw = _float_array(ego_yaw, "ego_yaw", 2, "(n_traj, n_t)", (n_traj, n_t))
    mean = _float_array(obs_mean, "obs_mean", 3, "(n_obs, n_t, 2)")
    n_obs = mean.shape[0]
    _check_shape(mean, "obs_mean", "(n_obs, n_t, 2)", (n_obs, n_t, 2))
    cov = _float_array(obs_cov, "obs_cov", 4, "(n_obs, n_t, 2, 2)", (n_obs, n_t, 2, 2))
    oyaw = _float_array(obs_heading, "obs_heading", 2, "(n_obs, n_t)", (n_obs, n_t))
    olen = _float_array(obs_length, "obs_length", 1, "(n_obs,)", (n_obs,))
    owid = _float_array(obs_width, "obs_width", 1, "(n_obs,)", (n_obs,))
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

    # 1. Distance gate. The octagon lies in the disc of radius r_ego + r_obs around the
    # ego centre, so outside the gate its mass is below the 1-D tail Phi(-gate_sigmas).
    sigma_max = np.sqrt(0.5 * (c11 + c22) + np.sqrt(0.25 * (c11 - c22) ** 2 + c12 * c12))
    r_obs = 0.5 * np.hypot(olen, owid)
    reach = 0.5 * math.hypot(ego_length, ego_width) + r_obs[:, None] + gate_sigmas * sigma_max
    dx = ex[:, None, :] - mean[None, :, :, 0]
    dy = ey[:, None, :] - mean[None, :, :, 1]
    # Comparing squares avoids a sqrt over all triples; inf reach keeps every triple.
    i_traj, i_obs, i_t = np.nonzero(dx * dx + dy * dy <= reach * reach)
    if i_traj.size == 0:
        return CollisionProbability(probability, mean_overlap)

    # 2. Minkowski octagon relative to the ego centre, (m, 8) per coordinate.
    ego_edges = _rectangle_edges(eyaw, ego_length, ego_width)
    obs_edges = _rectangle_edges(oyaw, olen[:, None], owid[:, None])
    vx, vy = _minkowski_octagon(
        tuple(e[i_traj, i_t] for e in ego_edges),
        tuple(e[i_obs, i_t] for e in obs_edges),
    )

    # 3. Whiten: z = W (ego + v - mean) = W (ego - mean) + W v.
    a11, a21, a22 = w11[i_obs, i_t], w21[i_obs, i_t], w22[i_obs, i_t]
    sdx, sdy = dx[i_traj, i_obs, i_t], dy[i_traj, i_obs, i_t]
    zx = (a11 * sdx)[:, None] + a11[:, None] * vx
    zy = (a21 * sdx + a22 * sdy)[:, None] + a21[:, None] * vx + a22[:, None] * vy

    # 4. Standard normal mass of the whitened octagon; the origin is the mean.
    mass, inside = _standard_polygon_mass(zx, zy)
    probability[i_traj, i_obs, i_t] = mass
    mean_overlap[i_traj, i_obs, i_t] = inside
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
    verts = _float_array(vertices, "vertices", None, "(..., k, 2)")
    if verts.ndim < 2 or verts.shape[-1] != 2 or verts.shape[-2] < 3:
        raise ValueError(f"vertices must have shape (..., k, 2) with k >= 3, got {verts.shape}")
    batch = verts.shape[:-2]
    mu = _float_array(mean, "mean", len(batch) + 1, "(..., 2)", (*batch, 2))
    sig = _float_array(cov, "cov", len(batch) + 2, "(..., 2, 2)", (*batch, 2, 2))
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
    """Return the standard normal mass of convex CCW polygons (see polygon_gaussian_mass).

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
    on_line = valid & (np.abs(h) < _H_TOL)
    inside = np.all((h > -_H_TOL) | ~valid, axis=1)

    # With the origin off every edge line the wedge angles add up to the winding
    # number, 1 inside and 0 outside. On an edge line (the mean on the boundary, or
    # on the extension of an edge) the winding number is not an integer: sum the
    # wedge angles of the other edges instead; the degenerate triangles count 0.
    winding = np.all((h > 0.0) | ~valid, axis=1).astype(np.float64)
    rows = np.flatnonzero(np.any(on_line, axis=1))
    if rows.size:
        hr = h[rows]
        keep = valid[rows] & ~on_line[rows]
        har = np.where(keep, np.abs(hr), 1.0)
        wedge = np.copysign(np.arctan(t2[rows] / har) - np.arctan(t1[rows] / har), hr)
        winding[rows] = np.sum(np.where(keep, wedge, 0.0), axis=1) / (2.0 * math.pi)

    # Closest distance^2 from the origin to the edge segment bounds the edge's term.
    d2 = h * h + np.where(t1 > 0.0, t1 * t1, np.where(t2 < 0.0, t2 * t2, 0.0))
    need = valid & ~on_line & (np.abs(h) <= _H_SKIP) & (d2 <= _D2_SKIP)
    # owens_t costs ~100 ns a call: evaluate it only where it can matter.
    hn = h[need]
    ha = np.abs(hn)
    term = owens_t(ha, t2[need] / ha) - owens_t(ha, t1[need] / ha)
    contrib = np.zeros_like(h)
    contrib[need] = np.copysign(term, hn)
    mass = winding - contrib.sum(axis=1)
    return np.clip(mass, 0.0, 1.0), inside


def _rectangle_edges(
    yaw: np.ndarray, length: float | np.ndarray, width: float | np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """First two CCW edges of a rectangle, starting at the first direction in [0, pi/2).

    A rectangle's edges point along yaw + j pi/2, j = 0..3. Reducing yaw modulo pi/2
    to alpha in [0, pi/2) gives the edge directions alpha + j pi/2 in increasing angle;
    edges 2 and 3 are the negatives of edges 0 and 1.

    Args:
        yaw: Heading [rad], any shape.
        length: Length [m], broadcastable to ``yaw``.
        width: Width [m], broadcastable to ``yaw``.

    Returns:
        alpha [rad], edge 0 (x, y) [m] and edge 1 (x, y) [m], each shaped like ``yaw``.

    """
    quarter = np.floor(yaw / _HALF_PI)
    alpha = yaw - quarter * _HALF_PI
    # Along the heading after an even number of quarter turns, across it otherwise.
    odd = np.mod(quarter, 2.0) == 1.0
    first = np.where(odd, width, length)
    second = np.where(odd, length, width)
    c, s = np.cos(alpha), np.sin(alpha)
    return alpha, first * c, first * s, -second * s, second * c


def _minkowski_octagon(
    ego: tuple[np.ndarray, ...], obs: tuple[np.ndarray, ...]
) -> tuple[np.ndarray, np.ndarray]:
    """Vertices of the Minkowski sum of two centred rectangles, counter-clockwise.

    Both rectangles contribute one edge per quarter turn, so merging the edges by
    angle only needs, per quarter, the order of the two alphas. The chain starts at
    the sum of the start vertices of both edge-0s, -(e0 + e1)/2 for a centred
    rectangle, and the second half of the octagon is the point reflection of the first.

    Args:
        ego: (alpha, e0x, e0y, e1x, e1y) of the ego rectangle, each shape (m,).
        obs: The same for the road user, each shape (m,).

    Returns:
        Vertex x and y relative to the common centre [m], each shape (m, 8).

    """
    ego_alpha, ego0x, ego0y, ego1x, ego1y = ego
    obs_alpha, obs0x, obs0y, obs1x, obs1y = obs
    ego_first = ego_alpha <= obs_alpha
    f0x = np.where(ego_first, ego0x, obs0x)
    f0y = np.where(ego_first, ego0y, obs0y)
    s0x = np.where(ego_first, obs0x, ego0x)
    s0y = np.where(ego_first, obs0y, ego0y)
    f1x = np.where(ego_first, ego1x, obs1x)
    f1y = np.where(ego_first, ego1y, obs1y)
    v0x = -0.5 * (ego0x + ego1x + obs0x + obs1x)
    v0y = -0.5 * (ego0y + ego1y + obs0y + obs1y)
    v1x, v1y = v0x + f0x, v0y + f0y
    v2x, v2y = v1x + s0x, v1y + s0y
    v3x, v3y = v2x + f1x, v2y + f1y
    vx = np.stack([v0x, v1x, v2x, v3x, -v0x, -v1x, -v2x, -v3x], axis=1)
    vy = np.stack([v0y, v1y, v2y, v3y, -v0y, -v1y, -v2y, -v3y], axis=1)
    return vx, vy


def _float_array(
    value: ArrayLike,
    name: str,
    ndim: int | None,
    expected: str,
    shape: tuple[int, ...] | None = None,
) -> np.ndarray:
    """Return ``value`` as a finite float64 array, checking its rank and shape."""
    array = np.asarray(value, dtype=np.float64)
    if ndim is not None and array.ndim != ndim:
        raise ValueError(f"{name} must have shape {expected}, got {array.shape}")
    if shape is not None:
        _check_shape(array, name, expected, shape)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite")
    return array


def _check_shape(array: np.ndarray, name: str, expected: str, shape: tuple[int, ...]) -> None:
    """Raise a ValueError naming ``name`` unless ``array`` has ``shape``."""
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {expected} = {shape}, got {array.shape}")
