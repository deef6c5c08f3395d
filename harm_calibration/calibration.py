"""Fitting the planner's delta-v correction (``ethical_planner.dv_correction``) to impacts.

The correction multiplies the perfectly plastic delta-v of Eq. 1 by a factor per bin
of (angle between the velocity directions, impact offset fraction). The factor of a
bin is the median of measured / Eq. 1 over the training impacts in it. A bin with
fewer than ``min_count`` training impacts takes the factor of its whole angle bin
(the angle-only fit), and an angle bin with too few impacts the factor 1.

The offset fraction must be the quantity the planner computes from pre-impact states
(``impact_offset_fraction``, rectangular footprints), not the sweep's design value:
``row_offset_fractions`` rebuilds each sweep impact's launch states and evaluates the
planner's function on them. (They agree for rectangular partners; the sweep's round
pedestrian proxy makes them differ by a few percent for pedestrians.)

``calibrate`` splits the impacts with a seeded generator, fits on the training share
and reports the error of Eq. 1, of the angle-only fit and of the angle-offset fit on
the held-back impacts.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ethical_planner.dv_correction import (
    DEFAULT_ANGLE_EDGES_DEG,
    DEFAULT_OFFSET_EDGES,
    DeltaVCorrection,
)
from ethical_planner.geometry import impact_offset_fraction
from ethical_planner.road_users import DEFAULT_SHAPES, EGO_SHAPE, RoadUserType
from harm_calibration.geometry import Footprint, launch_geometry

#: Impacts with an Eq. 1 delta-v below this are left out of fits and errors [m/s].
MIN_DV_MS = 0.05
#: Training impacts a bin needs for its own factor (else the fall-back factor).
MIN_BIN_COUNT = 5
#: Offset edges of the angle-only fit (one offset bin).
ANGLE_ONLY_OFFSET_EDGES = (0.0, 1.0)


def _bin_index(edges: Sequence[float], values: np.ndarray) -> np.ndarray:
    return np.clip(np.searchsorted(np.asarray(edges, float), values, side="right") - 1, 0, len(edges) - 2)


def fit_delta_v_correction(
    dv_predicted: ArrayLike,
    dv_measured: ArrayLike,
    angle_deg: ArrayLike,
    offset_fraction: ArrayLike,
    angle_edges_deg: Sequence[float] = DEFAULT_ANGLE_EDGES_DEG,
    offset_edges: Sequence[float] = DEFAULT_OFFSET_EDGES,
    min_count: int = MIN_BIN_COUNT,
) -> DeltaVCorrection:
    """Fit the factor per (angle, offset) bin as the median of measured / Eq. 1 delta-v.

    Impacts with an Eq. 1 delta-v <= ``MIN_DV_MS`` or a non-finite input are ignored.

    Args:
        dv_predicted: Eq. 1 delta-v [m/s], shape (n,).
        dv_measured: measured delta-v [m/s], shape (n,).
        angle_deg: angle between the velocity directions [deg], shape (n,).
        offset_fraction: impact offset fraction as the planner computes it [-], shape (n,).
        angle_edges_deg: angle bin edges [deg], 0 to 180.
        offset_edges: offset bin edges [-], 0 to 1.
        min_count: training impacts a bin needs for its own median, >= 1. Sparser
            (angle, offset) bins take their angle bin's median, sparser angle bins 1.

    Returns:
        The fitted correction, with the training count of every bin in ``n_train``.

    Raises:
        ValueError: shapes differ or ``min_count`` < 1.
    """
    arrays = [np.asarray(x, dtype=float) for x in (dv_predicted, dv_measured, angle_deg, offset_fraction)]
    if len({a.shape for a in arrays}) != 1:
        raise ValueError(
            "shapes differ: dv_predicted, dv_measured, angle_deg, offset_fraction have "
            f"{[a.shape for a in arrays]}"
        )
    if min_count < 1:
        raise ValueError(f"min_count must be >= 1, got {min_count}")
    pred, meas, ang, off = arrays
    keep = np.isfinite(pred) & np.isfinite(meas) & np.isfinite(ang) & np.isfinite(off) & (pred > MIN_DV_MS)
    ratio = meas[keep] / pred[keep]
    ia = _bin_index(angle_edges_deg, ang[keep])
    io = _bin_index(offset_edges, np.clip(off[keep], 0.0, 1.0))
    n_angle, n_offset = len(angle_edges_deg) - 1, len(offset_edges) - 1
    factors = np.ones((n_angle, n_offset))
    counts = np.zeros((n_angle, n_offset), dtype=int)
    for i in range(n_angle):
        in_angle = ia == i
        fallback = float(np.median(ratio[in_angle])) if in_angle.sum() >= min_count else 1.0
        for j in range(n_offset):
            r = ratio[in_angle & (io == j)]
            counts[i, j] = r.size
            factors[i, j] = float(np.median(r)) if r.size >= min_count else fallback
    factors = np.where(factors > 0.0, factors, 1.0)  # all-zero measurements: keep Eq. 1
    return DeltaVCorrection(
        tuple(float(e) for e in angle_edges_deg),
        tuple(float(e) for e in offset_edges),
        tuple(map(tuple, factors)),
        tuple(map(tuple, counts)),
    )


def error_stats(relative_error: np.ndarray) -> dict[str, float]:
    """Error statistics of relative errors e = (measured - model) / model (finite entries only).

    Args:
        relative_error: shape (n,).

    Returns:
        ``n``; ``median_abs`` and ``p95_abs``, the median and 95th percentile of |e|;
        ``p95_abs_log``, the 95th percentile of |ln(measured / model)| = |ln(1 + e)|,
        which weighs under- and overestimates alike (nan if some e <= -1).
    """
    e = relative_error[np.isfinite(relative_error)]
    if e.size == 0:
        return {"n": 0, "median_abs": math.nan, "p95_abs": math.nan, "p95_abs_log": math.nan}
    log = np.abs(np.log1p(e)) if np.all(e > -1.0) else np.full(e.shape, math.nan)
    return {
        "n": int(e.size),
        "median_abs": float(np.median(np.abs(e))),
        "p95_abs": float(np.percentile(np.abs(e), 95)),
        "p95_abs_log": float(np.percentile(log, 95)),
    }


@dataclass(frozen=True, slots=True)
class CalibrationResult:
    """A fitted correction and its error on held-back impacts.

    Relative error = (measured - model) / model, for Eq. 1 and for each correction.

    Attributes:
        correction: the (angle, offset) fit on the training impacts.
        angle_only: the fit with one offset bin (the former angle-only correction), for comparison.
        seed: seed of the split (-1 if unknown).
        test_fraction: share of impacts held back.
        min_count: training impacts a bin needed for its own factor.
        before: error stats of Eq. 1 on the test impacts (per class and "all").
        after_angle_only: the same with ``angle_only``.
        after: the same with ``correction``.
    """

    correction: DeltaVCorrection
    angle_only: DeltaVCorrection
    seed: int
    test_fraction: float
    min_count: int
    before: dict[str, dict[str, float]]
    after_angle_only: dict[str, dict[str, float]]
    after: dict[str, dict[str, float]]

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict."""
        return {
            "correction": self.correction.to_dict(),
            "angle_only_correction": self.angle_only.to_dict(),
            "seed": self.seed,
            "test_fraction": self.test_fraction,
            "min_count": self.min_count,
            "test_error_eq1": self.before,
            "test_error_angle_only": self.after_angle_only,
            "test_error_calibrated": self.after,
        }


def calibrate(
    dv_predicted: ArrayLike,
    dv_measured: ArrayLike,
    angle_deg: ArrayLike,
    offset_fraction: ArrayLike,
    classes: Sequence[str],
    rng: np.random.Generator,
    test_fraction: float = 0.3,
    angle_edges_deg: Sequence[float] = DEFAULT_ANGLE_EDGES_DEG,
    offset_edges: Sequence[float] = DEFAULT_OFFSET_EDGES,
    min_count: int = MIN_BIN_COUNT,
) -> CalibrationResult:
    """Fit on a random training share, report the error before and after on the rest.

    Args:
        dv_predicted: Eq. 1 delta-v [m/s], shape (n,).
        dv_measured: measured delta-v [m/s], shape (n,).
        angle_deg: angle between velocities [deg], shape (n,).
        offset_fraction: impact offset fraction as the planner computes it [-], shape (n,).
        classes: impact class per impact, length n.
        rng: random generator of the split (pass a seeded one).
        test_fraction: share held back, in (0, 1).
        angle_edges_deg: angle bin edges [deg].
        offset_edges: offset bin edges [-].
        min_count: training impacts a bin needs for its own factor.

    Returns:
        Both fits and the held-back error stats; test impacts with Eq. 1 delta-v <=
        ``MIN_DV_MS`` or a non-finite input are left out of all three.
    """
    if not 0.0 < test_fraction < 1.0:
        raise ValueError(f"test_fraction must lie in (0, 1), got {test_fraction}")
    pred, meas, ang, off = (
        np.asarray(x, dtype=float) for x in (dv_predicted, dv_measured, angle_deg, offset_fraction)
    )
    cls = np.asarray(classes, dtype=object)
    if not pred.shape == meas.shape == ang.shape == off.shape == cls.shape:
        raise ValueError(
            f"shapes differ: dv_predicted {pred.shape}, dv_measured {meas.shape}, angle_deg {ang.shape}, "
            f"offset_fraction {off.shape}, classes {cls.shape}"
        )
    n = pred.size
    test = np.zeros(n, dtype=bool)
    test[rng.permutation(n)[: int(round(test_fraction * n))]] = True
    train = ~test
    fit_args = (pred[train], meas[train], ang[train], off[train], angle_edges_deg)
    correction = fit_delta_v_correction(*fit_args, offset_edges, min_count)
    angle_only = fit_delta_v_correction(*fit_args, ANGLE_ONLY_OFFSET_EDGES, min_count)
    valid = test & (pred > MIN_DV_MS) & np.isfinite(meas) & np.isfinite(ang) & np.isfinite(off)

    def rel_error(model: np.ndarray) -> np.ndarray:
        return (meas - model) / np.where(model > 0, model, np.nan)

    angle_rad = np.radians(ang)
    errors = {
        "before": rel_error(pred),
        "angle_only": rel_error(angle_only(pred, angle_rad, off)),
        "after": rel_error(correction(pred, angle_rad, off)),
    }
    stats: dict[str, dict[str, dict[str, float]]] = {k: {} for k in errors}
    for name in ["all", *sorted(set(cls[valid]))]:
        mask = valid if name == "all" else valid & (cls == name)
        for key, err in errors.items():
            stats[key][name] = error_stats(err[mask])
    seed = int(rng.bit_generator.seed_seq.entropy) if hasattr(rng.bit_generator, "seed_seq") else -1
    return CalibrationResult(
        correction,
        angle_only,
        seed,
        float(test_fraction),
        int(min_count),
        stats["before"],
        stats["angle_only"],
        stats["after"],
    )


def _planner_shape(kind: str) -> tuple[float, float]:
    shape = DEFAULT_SHAPES[RoadUserType(kind)]
    return shape.length, shape.width


def row_offset_fractions(rows: Sequence[dict[str, Any]]) -> np.ndarray:
    """Impact offset fraction of each row as the planner computes it, shape (n_rows,).

    Sweep rows (``source == "sweep"``) are launched from design values; their launch
    states are rebuilt with ``geometry.launch_geometry`` (the same call as the sweep,
    with the rows' speeds) and ``impact_offset_fraction`` is evaluated on them with the
    planner's rectangular shapes (ego ``EGO_SHAPE``, partner ``DEFAULT_SHAPES``). Other
    rows (closed-loop runs) keep their ``offset`` column, which ``rows.row_from_impact``
    computed from the pre-impact states with the same function and the run's body shapes.

    Args:
        rows: impact rows with the columns of ``rows.COLUMNS``.

    Returns:
        Offset fractions [-] in [0, 1]; nan where neither is available.
    """
    out = np.full(len(rows), math.nan)
    ego_l, ego_w = EGO_SHAPE.length, EGO_SHAPE.width
    for k, r in enumerate(rows):
        design = float(r.get("offset", math.nan))
        if r.get("source") != "sweep":
            out[k] = design
            continue
        try:
            length, width = _planner_shape(r["partner"])
            launch = launch_geometry(
                Footprint(ego_l, ego_w),
                Footprint(length, width, r["partner"] == RoadUserType.PEDESTRIAN.value),
                float(r["speed_a"]),
                float(r["speed_b"]),
                math.radians(float(r["angle_deg"])),
                design,
            )
        except (KeyError, ValueError):
            out[k] = design
            continue
        out[k] = impact_offset_fraction(
            (0.0, 0.0), launch.velocity_a, 0.0, ego_l, ego_w,
            launch.position_b, launch.velocity_b, launch.yaw_b, length, width,
        )  # fmt: skip
    return out


__all__ = [
    "DEFAULT_ANGLE_EDGES_DEG",
    "DEFAULT_OFFSET_EDGES",
    "MIN_BIN_COUNT",
    "MIN_DV_MS",
    "CalibrationResult",
    "DeltaVCorrection",
    "calibrate",
    "error_stats",
    "fit_delta_v_correction",
    "row_offset_fractions",
]
