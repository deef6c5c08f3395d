"""Correction of the planner's delta-v (Eq. 1) towards the measured one.

``CalibratedDeltaV`` multiplies the perfectly plastic delta-v by a factor per bin of
the angle between the two velocity directions (0 = rear-end, 90 deg = T-bone,
180 deg = head-on). The factor of a bin is the median of measured / predicted over
the training impacts in it (it minimises the absolute relative error). Both bodies
of an impact share one factor, since both delta-v come from one impulse.

Planner use::

    cal = CalibratedDeltaV.load(path)
    dv_ego = cal(dv_ego_eq1, alpha)  # arrays of any broadcastable shape
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

#: Default bin edges of the angle between velocity directions [deg].
DEFAULT_EDGES_DEG = (0.0, 7.5, 22.5, 37.5, 52.5, 67.5, 82.5, 97.5, 112.5, 127.5, 142.5, 157.5, 172.5, 180.0)
#: Impacts with a predicted delta-v below this are left out of fits and errors [m/s].
MIN_DV_MS = 0.05


@dataclass(frozen=True, slots=True)
class CalibratedDeltaV:
    """Delta-v correction factor per bin of the angle between the velocity directions.

    Attributes:
        edges_deg: increasing bin edges [deg], from 0 to 180, length n_bins + 1.
        factors: measured / Eq. 1 factor per bin, length n_bins, > 0.
        n_train: training impacts per bin (0: factor defaulted to 1).
    """

    edges_deg: tuple[float, ...]
    factors: tuple[float, ...]
    n_train: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        edges = np.asarray(self.edges_deg, dtype=float)
        if edges.ndim != 1 or edges.size < 2 or not np.all(np.isfinite(edges)):
            raise ValueError(f"CalibratedDeltaV.edges_deg needs >= 2 finite values, got {self.edges_deg}")
        if edges[0] != 0.0 or edges[-1] != 180.0 or np.any(np.diff(edges) <= 0):
            raise ValueError(f"CalibratedDeltaV.edges_deg must increase from 0 to 180, got {self.edges_deg}")
        if len(self.factors) != edges.size - 1:
            raise ValueError(
                f"CalibratedDeltaV.factors needs {edges.size - 1} values (one per bin), "
                f"got {len(self.factors)}"
            )
        if not all(math.isfinite(f) and f > 0 for f in self.factors):
            raise ValueError(f"CalibratedDeltaV.factors must be finite and > 0, got {self.factors}")
        if self.n_train and len(self.n_train) != len(self.factors):
            raise ValueError("CalibratedDeltaV.n_train must have one count per bin")
        object.__setattr__(self, "edges_deg", tuple(float(e) for e in edges))
        object.__setattr__(self, "factors", tuple(float(f) for f in self.factors))
        object.__setattr__(self, "n_train", tuple(int(n) for n in self.n_train))

    def factor(self, angle: ArrayLike) -> np.ndarray:
        """Correction factor for angles between velocity directions [rad], any shape.

        The angle is folded into [0, pi] (its sign and full turns do not matter).
        """
        a = np.asarray(angle, dtype=float)
        folded = np.degrees(np.abs(np.remainder(a + np.pi, 2 * np.pi) - np.pi))
        index = np.clip(np.searchsorted(self.edges_deg, folded, side="right") - 1, 0, len(self.factors) - 1)
        return np.asarray(self.factors)[index]

    def __call__(self, dv_eq1: ArrayLike, angle: ArrayLike) -> np.ndarray:
        """Corrected delta-v.

        Args:
            dv_eq1: delta-v of paper Eq. 1 [m/s], any shape.
            angle: angle between the two velocity directions [rad] (the alpha of
                Eq. 1), broadcastable against ``dv_eq1``.

        Returns:
            Calibrated delta-v [m/s], the broadcast shape.
        """
        return np.asarray(dv_eq1, dtype=float) * self.factor(angle)

    def to_dict(self) -> dict:
        """JSON-able dict."""
        return {
            "edges_deg": list(self.edges_deg),
            "factors": list(self.factors),
            "n_train": list(self.n_train),
        }

    @classmethod
    def from_dict(cls, data: dict) -> CalibratedDeltaV:
        """Inverse of ``to_dict``; a ValueError names unknown or missing keys."""
        unknown = sorted(set(data) - {"edges_deg", "factors", "n_train"})
        if unknown:
            raise ValueError(f"CalibratedDeltaV: unknown keys {unknown}")
        missing = sorted({"edges_deg", "factors"} - set(data))
        if missing:
            raise ValueError(f"CalibratedDeltaV: missing keys {missing}")
        return cls(tuple(data["edges_deg"]), tuple(data["factors"]), tuple(data.get("n_train", ())))

    def save(self, path: Path) -> None:
        """Write the JSON file."""
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n", encoding="utf-8")

    @classmethod
    def load(cls, path: Path) -> CalibratedDeltaV:
        """Read a JSON file written by ``save``."""
        return cls.from_dict(json.loads(Path(path).read_text(encoding="utf-8")))


def fit_calibrated_delta_v(
    dv_predicted: ArrayLike,
    dv_measured: ArrayLike,
    angle_deg: ArrayLike,
    edges_deg: Sequence[float] = DEFAULT_EDGES_DEG,
) -> CalibratedDeltaV:
    """Fit the factor per angle bin as the median of measured / predicted delta-v.

    Args:
        dv_predicted: Eq. 1 delta-v [m/s], shape (n,).
        dv_measured: measured delta-v [m/s], shape (n,).
        angle_deg: angle between the velocity directions [deg], shape (n,).
        edges_deg: bin edges [deg].

    Returns:
        The fitted correction; empty bins keep factor 1.
    """
    pred, meas, ang = (np.asarray(x, dtype=float) for x in (dv_predicted, dv_measured, angle_deg))
    if not pred.shape == meas.shape == ang.shape:
        raise ValueError(
            f"shapes differ: dv_predicted {pred.shape}, dv_measured {meas.shape}, angle {ang.shape}"
        )
    keep = np.isfinite(pred) & np.isfinite(meas) & np.isfinite(ang) & (pred > MIN_DV_MS)
    ratio = meas[keep] / pred[keep]
    edges = np.asarray(edges_deg, dtype=float)
    index = np.clip(np.searchsorted(edges, ang[keep], side="right") - 1, 0, edges.size - 2)
    factors, counts = [], []
    for k in range(edges.size - 1):
        r = ratio[index == k]
        counts.append(int(r.size))
        factors.append(float(np.median(r)) if r.size and np.median(r) > 0 else 1.0)
    return CalibratedDeltaV(tuple(edges), tuple(factors), tuple(counts))


def error_stats(relative_error: np.ndarray) -> dict[str, float]:
    """Median and 95th percentile of |relative error|, and the count (finite entries only)."""
    e = np.abs(relative_error[np.isfinite(relative_error)])
    if e.size == 0:
        return {"n": 0, "median_abs": math.nan, "p95_abs": math.nan}
    return {"n": int(e.size), "median_abs": float(np.median(e)), "p95_abs": float(np.percentile(e, 95))}


@dataclass(frozen=True, slots=True)
class CalibrationResult:
    """A fitted correction and its error on held-back impacts.

    Attributes:
        correction: the fit on the training impacts.
        seed: seed of the split. test_fraction: share of impacts held back.
        before: error stats of Eq. 1 on the test impacts (per class and "all").
        after: the same with the correction.
    """

    correction: CalibratedDeltaV
    seed: int
    test_fraction: float
    before: dict[str, dict[str, float]]
    after: dict[str, dict[str, float]]

    def to_dict(self) -> dict:
        """JSON-able dict."""
        return {
            "correction": self.correction.to_dict(),
            "seed": self.seed,
            "test_fraction": self.test_fraction,
            "test_error_eq1": self.before,
            "test_error_calibrated": self.after,
        }


def calibrate(
    dv_predicted: ArrayLike,
    dv_measured: ArrayLike,
    angle_deg: ArrayLike,
    classes: Sequence[str],
    rng: np.random.Generator,
    test_fraction: float = 0.3,
    edges_deg: Sequence[float] = DEFAULT_EDGES_DEG,
) -> CalibrationResult:
    """Fit on a random training share, report the error before and after on the rest.

    Args:
        dv_predicted: Eq. 1 delta-v [m/s], shape (n,).
        dv_measured: measured delta-v [m/s], shape (n,).
        angle_deg: angle between velocities [deg], shape (n,).
        classes: impact class per impact, length n.
        rng: random generator of the split (pass a seeded one).
        test_fraction: share held back, in (0, 1).
        edges_deg: bin edges [deg].
    """
    if not 0.0 < test_fraction < 1.0:
        raise ValueError(f"test_fraction must lie in (0, 1), got {test_fraction}")
    pred, meas, ang = (np.asarray(x, dtype=float) for x in (dv_predicted, dv_measured, angle_deg))
    cls = np.asarray(classes, dtype=object)
    n = pred.size
    test = np.zeros(n, dtype=bool)
    test[rng.permutation(n)[: int(round(test_fraction * n))]] = True
    correction = fit_calibrated_delta_v(pred[~test], meas[~test], ang[~test], edges_deg)
    valid = test & (pred > MIN_DV_MS) & np.isfinite(meas)
    corrected = correction(pred, np.radians(ang))
    err_before = (meas - pred) / np.where(pred > 0, pred, np.nan)
    err_after = (meas - corrected) / np.where(corrected > 0, corrected, np.nan)
    before, after = {}, {}
    for name in ["all", *sorted(set(cls[valid]))]:
        mask = valid if name == "all" else valid & (cls == name)
        before[name] = error_stats(err_before[mask])
        after[name] = error_stats(err_after[mask])
    seed = int(rng.bit_generator.seed_seq.entropy) if hasattr(rng.bit_generator, "seed_seq") else -1
    return CalibrationResult(correction, seed, float(test_fraction), before, after)
