"""Surrogate safety measures of a moment of a run (no collision needed).

``time_to_collision``: constant-velocity time until two oriented rectangles first
overlap, solved exactly with the separating-axis test (four axes, each gives an
interval of times; their intersection is the overlap). The loop's
``metrics.TimeToCollision`` keeps its minimum over a run.
"""

from __future__ import annotations

import numpy as np


def time_to_collision(
    ego: np.ndarray,
    others: np.ndarray,
    horizon: float = 10.0,
) -> np.ndarray:
    """Constant-velocity time to first overlap of oriented rectangles (separating axes).

    Args:
        ego: (x [m], y [m], yaw [rad], vx [m/s], vy [m/s], length [m], width [m]), shape (7,).
        others: the same per road user, shape (k, 7).
        horizon: longest time looked ahead [s].

    Returns:
        (k,) first time of overlap in [0, horizon] [s]; 0 if overlapping now; inf if none.
    """
    others = np.atleast_2d(np.asarray(others, dtype=float))
    ego = np.asarray(ego, dtype=float)
    k = len(others)
    if k == 0:
        return np.zeros(0)
    d0 = others[:, :2] - ego[:2]  # (k, 2)
    dv = others[:, 3:5] - ego[3:5]

    def frame(yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u = np.stack([np.cos(yaw), np.sin(yaw)], axis=-1)
        return u, np.stack([-u[..., 1], u[..., 0]], axis=-1)

    ue, ne = frame(np.full(k, ego[2]))
    uk, nk = frame(others[:, 2])
    lo = np.zeros(k)
    hi = np.full(k, float(horizon))
    for axis in (ue, ne, uk, nk):
        reach = (
            0.5 * ego[5] * np.abs((ue * axis).sum(1))
            + 0.5 * ego[6] * np.abs((ne * axis).sum(1))
            + 0.5 * others[:, 5] * np.abs((uk * axis).sum(1))
            + 0.5 * others[:, 6] * np.abs((nk * axis).sum(1))
        )
        p = (d0 * axis).sum(1)
        q = (dv * axis).sum(1)
        moving = np.abs(q) > 1e-12
        safe_q = np.where(moving, q, 1.0)
        t1 = (-reach - p) / safe_q
        t2 = (reach - p) / safe_q
        inside = np.abs(p) <= reach
        a_lo = np.where(moving, np.minimum(t1, t2), np.where(inside, -np.inf, np.inf))
        a_hi = np.where(moving, np.maximum(t1, t2), np.where(inside, np.inf, -np.inf))
        lo = np.maximum(lo, a_lo)
        hi = np.minimum(hi, a_hi)
    return np.where(lo <= hi, lo, np.inf)
