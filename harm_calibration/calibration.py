"""Held-back evaluation of the delta-v models by geometry cell, and the speed check.

Four predictions of the measured delta-v are compared on impacts a model has not
seen: paper Eq. 1, the planar impulse model (``ethical_planner.impulse``; the first
impulse; nothing is fitted), the sequence-aware planar model (``planar_seq``: every
impulse of the sequence, ``harm_calibration.sequence``; nothing is fitted) and a
*correction* of Eq. 1 fitted to the other impacts, a factor per bin of
(angle between the velocity directions, impact offset fraction), the median of
measured / Eq. 1 over the bin's training impacts (the approach of the former
former ``ethical_planner.dv_correction``, retired because the planar model beats it).

Impacts are split by **geometry cell** (partner, angle, offset; its impacts differ only
in closing speed), never by row: a random row split puts almost every test impact in a
cell whose other speeds are in training. Each of ``seeds`` splits holds back
``test_fraction`` of the cells; the statistics are reported as the median over the
splits with their range. A bin without ``min_count`` training impacts has no factor: its
test impacts are reported as *unseen* and left out of the correction's error (never
silently predicted by Eq. 1).

``speed_independence`` checks the measurement itself: for a fixed geometry, rigid-body
mechanics gives a ratio measured / Eq. 1 that does not depend on the closing speed (at
constant restitution), so a cell whose ratio varies by 10 % or more over the closing
speeds is listed with its cause: a multi-impact sequence at some speeds, the
speed-dependent restitution law (then measured / planar model stays put), or none.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from harm_calibration.rows import Row, column

#: Impacts whose larger measured delta-v (of the two bodies) is below this are touches,
#: not crashes, and are left out of fits and errors (for every model alike) [m/s].
MIN_IMPACT_DV_MS = 0.5
#: Floor of a model's delta-v in the denominator of the relative error [m/s].
MIN_DV_MS = 0.05
#: Training impacts a bin needs for its own factor.
MIN_BIN_COUNT = 3
#: Bin edges of the angle between the velocity directions [deg] (15-deg bins centred on
#: multiples of 15 deg) and of the offset fraction (bins centred on 0, 0.25, 0.5, 0.75, 1).
ANGLE_EDGES_DEG = (0.0, 7.5, 22.5, 37.5, 52.5, 67.5, 82.5, 97.5, 112.5, 127.5, 142.5, 157.5, 172.5, 180.0)
OFFSET_EDGES = (0.0, 0.125, 0.375, 0.625, 0.875, 1.0)
#: Models compared: name -> column of the predicted delta-v of body a.
MODELS = {"eq1": "dv_predicted_a", "planar": "dv_planar_a", "planar_seq": "dv_planar_seq_a", "correction": ""}
#: Models held against Eq. 1 by the acceptance checks (``done_checks``).
CHECKED_MODELS = ("planar", "planar_seq")
#: Variation of measured / Eq. 1 across closing speeds that flags a cell.
SPEED_VARIATION_LIMIT = 0.10


def _optional(rows: Sequence[Row], key: str) -> np.ndarray:
    """A numeric column that older tables lack (``rows.OPTIONAL_COLUMNS``): nan where absent."""
    return np.array([float(r.get(key, math.nan)) for r in rows], dtype=float)


def error_stats(relative_error: np.ndarray) -> dict[str, float]:
    """Statistics of relative errors e = (measured - model) / model (finite entries only).

    Args:
        relative_error: shape (n,).

    Returns:
        ``n``; ``median_abs`` and ``p95_abs`` of |e|; ``median`` (signed).
    """
    e = relative_error[np.isfinite(relative_error)]
    if e.size == 0:
        return {"n": 0, "median_abs": math.nan, "p95_abs": math.nan, "median": math.nan}
    return {
        "n": int(e.size),
        "median_abs": float(np.median(np.abs(e))),
        "p95_abs": float(np.percentile(np.abs(e), 95)),
        "median": float(np.median(e)),
    }


def relative_error(measured: np.ndarray, model: np.ndarray) -> np.ndarray:
    """(measured - model) / max(model, ``MIN_DV_MS``); nan where either is not finite."""
    ok = np.isfinite(model) & np.isfinite(measured)
    return np.where(ok, (measured - model) / np.maximum(np.where(ok, model, 1.0), MIN_DV_MS), np.nan)


def scored(rows: Sequence[Row]) -> np.ndarray:
    """Impacts that count for delta-v errors: the larger measured delta-v >= ``MIN_IMPACT_DV_MS``."""
    if not rows:
        return np.zeros(0, dtype=bool)
    larger = np.fmax(column(rows, "dv_measured_a"), column(rows, "dv_measured_b"))
    return np.nan_to_num(larger) >= MIN_IMPACT_DV_MS


#: Measured references: name -> column of body a's measured delta-v.
REFERENCES = {"sequence": "dv_measured_a", "first impulse": "dv_first_a"}


def bin_index(angle_deg: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Flat (angle, offset) bin of each impact, shape (n,)."""
    ia = np.clip(np.searchsorted(ANGLE_EDGES_DEG, angle_deg, side="right") - 1, 0, len(ANGLE_EDGES_DEG) - 2)
    io = np.clip(
        np.searchsorted(OFFSET_EDGES, np.clip(offset, 0, 1), side="right") - 1, 0, len(OFFSET_EDGES) - 2
    )
    return ia * (len(OFFSET_EDGES) - 1) + io


def bin_label(index: int) -> str:
    """'angle lo-hi deg, offset lo-hi' of a flat bin index."""
    n_off = len(OFFSET_EDGES) - 1
    ia, io = divmod(int(index), n_off)
    return (
        f"angle {ANGLE_EDGES_DEG[ia]:g}-{ANGLE_EDGES_DEG[ia + 1]:g} deg, "
        f"offset {OFFSET_EDGES[io]:g}-{OFFSET_EDGES[io + 1]:g}"
    )


@dataclass(frozen=True, slots=True)
class BinCorrection:
    """Factor of measured / Eq. 1 per (angle, offset) bin, fitted on training impacts.

    Attributes:
        factors: per flat bin, nan where the bin is unseen.
        counts: training impacts per flat bin.
    """

    factors: np.ndarray
    counts: np.ndarray

    @classmethod
    def fit(cls, eq1: np.ndarray, measured: np.ndarray, bins: np.ndarray, min_count: int = MIN_BIN_COUNT):
        """Median of measured / Eq. 1 per bin over impacts with Eq. 1 above ``MIN_DV_MS``."""
        n_bins = (len(ANGLE_EDGES_DEG) - 1) * (len(OFFSET_EDGES) - 1)
        ok = np.isfinite(eq1) & np.isfinite(measured) & (eq1 > MIN_DV_MS)
        factors = np.full(n_bins, np.nan)
        counts = np.bincount(bins[ok], minlength=n_bins)
        ratio = measured[ok] / eq1[ok]
        for b in np.flatnonzero(counts >= min_count):
            factors[b] = float(np.median(ratio[bins[ok] == b]))
        return cls(factors, counts)

    def __call__(self, eq1: np.ndarray, bins: np.ndarray) -> np.ndarray:
        """Corrected delta-v [m/s]; nan in unseen bins."""
        return eq1 * self.factors[bins]


#: Prefix of the reporting groups that split a partner's impacts by sequence type.
PARTNER_SEQUENCE = "partner and sequence:"


def _groups(rows: Sequence[Row]) -> dict[str, np.ndarray]:
    """Masks of the reporting groups.

    All; per class; per partner; per sequence type (single impulse or multi-impact); per
    partner and sequence type.
    """
    classes = np.array([r["class"] for r in rows], dtype=object)
    partners = np.array([r["partner"] for r in rows], dtype=object)
    multi = np.array([r.get("multi_impact") == "yes" for r in rows])
    out = {"all": np.ones(len(rows), dtype=bool)}
    for c in sorted(set(classes)):
        out[f"class:{c}"] = classes == c
    for p in sorted(set(partners)):
        out[f"partner:{p}"] = partners == p
    out["sequence:single impulse"] = ~multi
    out["sequence:multi-impact"] = multi
    for p in sorted(set(partners)):
        out[f"{PARTNER_SEQUENCE}{p}, single impulse"] = (partners == p) & ~multi
        out[f"{PARTNER_SEQUENCE}{p}, multi-impact"] = (partners == p) & multi
    return out


def held_back_evaluation(
    rows: Sequence[Row],
    seeds: Sequence[int] = tuple(range(10)),
    test_fraction: float = 0.3,
    reference: str = "sequence",
) -> dict[str, Any]:
    """Errors of Eq. 1, the planar model and the fitted correction on held-back cells.

    Args:
        rows: measured sweep rows with a ``cell`` (others are ignored).
        seeds: one split per seed (``numpy.random.default_rng(seed)``).
        test_fraction: share of cells held back, in (0, 1).
        reference: measured delta-v compared with (``REFERENCES``): the whole impact
            sequence, or its first impulse (the event a single-impulse model describes).

    Returns:
        ``groups``: group -> model -> stat -> {"median", "min", "max"} over the splits;
        ``unseen``: per split, the test impacts in bins without a factor and the bins;
        ``decision``: whether the correction beats the planar model (median and p95, all).

    Raises:
        ValueError: fewer than 2 cells, or ``test_fraction`` outside (0, 1).
    """
    if not 0.0 < test_fraction < 1.0:
        raise ValueError(f"test_fraction must lie in (0, 1), got {test_fraction}")
    if reference not in REFERENCES:
        raise ValueError(f"reference must be one of {list(REFERENCES)}, got {reference!r}")
    rows = [r for r in rows if r.get("cell")]
    rows = [r for r, ok in zip(rows, scored(rows), strict=True) if ok]
    cells = np.array([r["cell"] for r in rows], dtype=object)
    unique = np.array(sorted(set(cells)), dtype=object)
    if unique.size < 2:
        raise ValueError(f"held-back evaluation needs >= 2 geometry cells, got {unique.size}")
    measured = column(rows, REFERENCES[reference])
    eq1 = column(rows, "dv_predicted_a")
    planar = column(rows, "dv_planar_a")
    planar_seq = _optional(rows, "dv_planar_seq_a")
    bins = bin_index(column(rows, "angle_deg"), column(rows, "offset"))
    groups = _groups(rows)
    per_split: dict[str, dict[str, dict[str, list[float]]]] = {
        g: {m: {"median_abs": [], "p95_abs": [], "n": []} for m in MODELS} for g in groups
    }
    unseen = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        n_test = max(1, int(round(test_fraction * unique.size)))
        test_cells = set(rng.permutation(unique)[:n_test])
        test = np.array([c in test_cells for c in cells])
        correction = BinCorrection.fit(eq1[~test], measured[~test], bins[~test])
        corrected = correction(eq1, bins)
        missing = test & ~np.isfinite(corrected)
        unseen.append(
            {
                "seed": int(seed),
                "test_impacts": int(test.sum()),
                "unseen_impacts": int(missing.sum()),
                "unseen_bins": [bin_label(b) for b in sorted(set(bins[missing].tolist()))],
            }
        )
        errors = {
            "eq1": relative_error(measured, eq1),
            "planar": relative_error(measured, planar),
            "planar_seq": relative_error(measured, planar_seq),
            "correction": relative_error(measured, corrected),
        }
        for g, mask in groups.items():
            for m, err in errors.items():
                stats = error_stats(err[test & mask])
                for key in ("median_abs", "p95_abs", "n"):
                    per_split[g][m][key].append(stats[key])
    summary: dict[str, Any] = {}
    for g, models in per_split.items():
        summary[g] = {}
        for m, stats in models.items():
            summary[g][m] = {}
            for key, values in stats.items():
                array = np.array(values, dtype=float)
                finite = array[np.isfinite(array)]
                summary[g][m][key] = {
                    "median": float(np.median(finite)) if finite.size else math.nan,
                    "min": float(finite.min()) if finite.size else math.nan,
                    "max": float(finite.max()) if finite.size else math.nan,
                }
    overall = summary["all"]
    keep = all(
        overall["correction"][k]["median"] < overall["planar"][k]["median"] for k in ("median_abs", "p95_abs")
    )
    return {
        "reference": reference,
        "seeds": [int(s) for s in seeds],
        "test_fraction": float(test_fraction),
        "n_cells": int(unique.size),
        "min_count": MIN_BIN_COUNT,
        "groups": summary,
        "unseen": unseen,
        "decision": {
            "correction_beats_planar": bool(keep),
            "rule": "the correction is kept only if its held-back median and p95 |error| "
            "(medians over the splits) are both below the planar model's",
        },
    }


def done_checks(evaluation: dict[str, Any], model: str = "planar") -> list[dict[str, Any]]:
    """Per group: ``model``'s median <= half of Eq. 1's and its p95 <= Eq. 1's (held back).

    Args:
        evaluation: ``held_back_evaluation`` result.
        model: one of ``CHECKED_MODELS`` (the keys keep the name ``planar_*`` for either).
    """
    if model not in CHECKED_MODELS:
        raise ValueError(f"model must be one of {list(CHECKED_MODELS)}, got {model!r}")
    out = []
    for group, models in evaluation["groups"].items():
        eq1, planar = models["eq1"], models[model]
        m_eq1, m_pl = eq1["median_abs"]["median"], planar["median_abs"]["median"]
        p_eq1, p_pl = eq1["p95_abs"]["median"], planar["p95_abs"]["median"]
        if not all(math.isfinite(x) for x in (m_eq1, m_pl, p_eq1, p_pl)):
            continue
        out.append(
            {
                "group": group,
                "model": model,
                "eq1_median": m_eq1,
                "planar_median": m_pl,
                "eq1_p95": p_eq1,
                "planar_p95": p_pl,
                "median_halved": bool(m_pl <= 0.5 * m_eq1),
                "p95_no_worse": bool(p_pl <= p_eq1),
            }
        )
    return out


#: Closing speeds [m/s] whose ratios the per-cell speed table shows.
SPEED_TABLE_SPEEDS = (5.0, 10.0, 20.0, 30.0)
#: Verdicts of a cell in the speed check, in the order they are tried.
SPEED_VERDICTS = {
    "steady": "measured / Eq. 1 varies by less than the limit",
    "multi-impact": "it varies, but not over the closing speeds whose sequence is a single impulse",
    "restitution law": "it varies, but measured / planar model (which takes the same e(v)) does not: "
    "the speed-dependent restitution, by design",
    "sequence model": "it varies, but measured / planar sequence model (every hit, the same e(v) and "
    "tyre forces) does not: the sequence's physics, predicted",
    "unexplained": "none of the above",
}


def _variation(ratio: np.ndarray) -> float:
    """Largest over smallest, minus 1, of the finite positive ratios; nan with fewer than two."""
    ratio = ratio[np.isfinite(ratio) & (ratio > 0)]
    return float(ratio.max() / ratio.min() - 1.0) if ratio.size >= 2 else math.nan


def speed_independence(
    rows: Sequence[Row],
    partners: Sequence[str] = ("car", "truck", "bus"),
    speeds: tuple[float, float] = (5.0, 30.0),
    limit: float = SPEED_VARIATION_LIMIT,
) -> dict[str, Any]:
    """Variation of measured / Eq. 1 across closing speeds, per geometry cell, and its cause.

    Rigid-body mechanics at a constant restitution gives a ratio that does not depend on
    the closing speed (velocities scale, the geometry does not). A cell whose ratio varies
    by ``limit`` or more gets a verdict (``SPEED_VERDICTS``): ``multi-impact`` if the
    closing speeds with a single-impulse sequence vary by less than the limit among
    themselves (or are fewer than two) and the first impulse / planar model varies by
    less than the limit across all speeds; ``restitution law`` if measured / planar model
    varies by less than the limit (the planar model takes the world's e(v) at the same
    normal closing speed, so its ratio to Eq. 1 moves with e(v) only); ``sequence model``
    if measured / planar sequence model varies by less than the limit (the sequence's
    later hits, with the same e(v) and tyre forces, account for it); otherwise
    ``unexplained``.

    Args:
        rows: measured sweep rows (with ``cell`` and ``closing_speed``).
        partners: partner types checked.
        speeds: closing-speed range [m/s] (inclusive).
        limit: variation (max / min - 1) that flags a cell.

    Returns:
        ``cells``: per (restitution setting, cell): ``ratio`` (measured / Eq. 1 of the whole
        sequence) and ``impulses`` per closing speed (keys as ``f"{v:g}"``), ``variation``,
        ``variation_single`` (single-impulse speeds only), ``variation_planar`` (measured /
        planar), ``variation_first`` (the first impulse / planar: where it is small, the
        later hits carry the variation), ``variation_seq`` (measured / planar sequence model),
        ``multi_impact``, ``verdict``; ``flagged`` and ``unexplained`` (those
        cells), the largest variation, and per restitution setting the counts per verdict.
    """
    by_cell: dict[tuple[str, str], list[Row]] = {}
    for r in rows:
        if r.get("cell") and r["partner"] in partners and speeds[0] <= r["closing_speed"] <= speeds[1]:
            by_cell.setdefault((r["restitution_set"], r["cell"]), []).append(r)
    cells = []
    for (rset, cell), group in sorted(by_cell.items()):
        group = sorted(group, key=lambda r: r["closing_speed"])
        measured = column(group, "dv_measured_a")
        ratio = measured / column(group, "dv_predicted_a")
        variation = _variation(ratio)
        if not math.isfinite(variation):
            continue
        single = np.array([r.get("multi_impact") != "yes" for r in group])
        variation_single = _variation(ratio[single])
        variation_planar = _variation(measured / column(group, "dv_planar_a"))
        variation_first = _variation(column(group, "dv_first_a") / column(group, "dv_planar_a"))
        variation_seq = _variation(measured / _optional(group, "dv_planar_seq_a"))
        if variation < limit:
            verdict = "steady"
        elif not (variation_single >= limit) and variation_first < limit:
            # The single-impulse speeds agree (or there are fewer than two of them) and the
            # first impulse agrees with the planar model at every speed: the variation is
            # in the later hits. Without the second condition a cell with fewer than two
            # single-impulse speeds would be "multi-impact" on no evidence.
            verdict = "multi-impact"
        elif variation_planar < limit:
            verdict = "restitution law"
        elif variation_seq < limit:
            verdict = "sequence model"
        else:
            verdict = "unexplained"
        cells.append(
            {
                "restitution_set": rset,
                "cell": cell,
                "ratio": {f"{r['closing_speed']:g}": float(x) for r, x in zip(group, ratio, strict=True)},
                "impulses": {f"{r['closing_speed']:g}": r.get("n_impulses") for r in group},
                "variation": variation,
                "variation_single": variation_single,
                "variation_planar": variation_planar,
                "variation_first": variation_first,
                "variation_seq": variation_seq,
                "multi_impact": bool(not single.all()),
                "verdict": verdict,
                "ratio_min": float(np.nanmin(ratio)),
                "ratio_max": float(np.nanmax(ratio)),
            }  # fmt: skip
        )
    flagged = [c for c in cells if c["verdict"] != "steady"]
    per_set = {}
    for rset in sorted({c["restitution_set"] for c in cells}):
        in_set = [c for c in cells if c["restitution_set"] == rset]
        per_set[rset] = {
            "n_cells": len(in_set),
            "flagged": sum(c["verdict"] != "steady" for c in in_set),
            **{v: sum(c["verdict"] == v for c in in_set) for v in SPEED_VERDICTS},
            "max_variation": max((c["variation"] for c in in_set), default=math.nan),
        }
    return {
        "limit": limit,
        "speeds": list(speeds),
        "partners": list(partners),
        "n_cells": len(cells),
        "cells": cells,
        "flagged": flagged,
        "unexplained": [c for c in flagged if c["verdict"] == "unexplained"],
        "max_variation": max((c["variation"] for c in cells), default=math.nan),
        "by_restitution_set": per_set,
    }


__all__ = [
    "ANGLE_EDGES_DEG",
    "CHECKED_MODELS",
    "MIN_BIN_COUNT",
    "MIN_DV_MS",
    "MIN_IMPACT_DV_MS",
    "MODELS",
    "REFERENCES",
    "OFFSET_EDGES",
    "PARTNER_SEQUENCE",
    "SPEED_TABLE_SPEEDS",
    "SPEED_VERDICTS",
    "BinCorrection",
    "bin_index",
    "done_checks",
    "error_stats",
    "held_back_evaluation",
    "relative_error",
    "scored",
    "speed_independence",
]
