"""Summary figures, plots and the report of an impact table.

Per partner type and impact class (central collinear, oblique, offset): median and
95th percentile of |relative delta-v error| of Eq. 1, agreement of the geometric
(centre-direction) impact area with the measured (contact-point) one, and the mean
absolute difference of the harm from measured and from predicted inputs. Both bodies
of an impact share one relative delta-v error (one impulse), so the error is taken
from body a; areas and harms pool both bodies.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from harm_calibration.calibration import (
    MIN_DV_MS,
    CalibrationResult,
    DeltaVCorrection,
    calibrate,
    error_stats,
    row_offset_fractions,
)
from harm_calibration.geometry import CLASSES
from harm_calibration.literature import literature_markdown, literature_table
from harm_calibration.rows import Row, column

AREAS = ("front", "driver_side", "right_side", "rear")
MEASURED_STATUS = ("ok", "incomplete")


def measured(rows: Sequence[Row]) -> list[Row]:
    """Rows with a measurement (status ok or incomplete)."""
    return [r for r in rows if r["status"] in MEASURED_STATUS]


def _body_pairs(rows: Sequence[Row], key: str) -> list[tuple[Any, Any]]:
    return [(r[f"{key}_measured_{s}"], r[f"{key}_predicted_{s}"]) for r in rows for s in ("a", "b")]


def _area_agreement(rows: Sequence[Row]) -> float:
    pairs = [(m, p) for m, p in _body_pairs(rows, "area") if m and p]
    return float(np.mean([m == p for m, p in pairs])) if pairs else math.nan


def _harm_error(rows: Sequence[Row]) -> float:
    diff = [abs(m - p) for m, p in _body_pairs(rows, "harm") if math.isfinite(m) and math.isfinite(p)]
    return float(np.mean(diff)) if diff else math.nan


def _dv_error(rows: Sequence[Row]) -> np.ndarray:
    pred = column(rows, "dv_predicted_a")
    err = column(rows, "dv_error_a")
    return np.where(pred > MIN_DV_MS, err, np.nan)


def group_stats(rows: Sequence[Row]) -> dict[str, Any]:
    """Error statistics of a group of measured rows."""
    stats = error_stats(_dv_error(rows)) if rows else error_stats(np.array([]))
    err = _dv_error(rows) if rows else np.array([])
    finite = err[np.isfinite(err)]
    return {
        "n": len(rows),
        "dv_median_abs_rel_error": stats["median_abs"],
        "dv_p95_abs_rel_error": stats["p95_abs"],
        "dv_median_rel_error": float(np.median(finite)) if finite.size else math.nan,
        "area_agreement": _area_agreement(rows),
        "harm_mean_abs_error": _harm_error(rows),
    }


def confusion(rows: Sequence[Row]) -> np.ndarray:
    """Reduced-area confusion matrix, rows predicted, columns measured, shape (4, 4), both bodies."""
    matrix = np.zeros((len(AREAS), len(AREAS)), dtype=int)
    for m, p in _body_pairs(rows, "area"):
        if m in AREAS and p in AREAS:
            matrix[AREAS.index(p), AREAS.index(m)] += 1
    return matrix


def summarize(rows: Sequence[Row], rng: np.random.Generator | None = None) -> dict[str, Any]:
    """Summary of a table of impacts (the content of ``summary.json``).

    Args:
        rows: impact rows (any status).
        rng: generator of the calibration split; no calibration if None or too few rows.
    """
    good = measured(rows)
    partners = sorted({r["partner"] for r in good})
    classes = [c for c in (*CLASSES, "static") if any(r["class"] == c for r in good)]
    by_partner = {}
    for p in partners:
        in_p = [r for r in good if r["partner"] == p]
        entry = {"all": group_stats(in_p)}
        for c in classes:
            in_pc = [r for r in in_p if r["class"] == c]
            if in_pc:
                entry[c] = group_stats(in_pc)
        by_partner[p] = entry
    status: dict[str, int] = {}
    for r in rows:
        key = r["status"] if r["status"] in (*MEASURED_STATUS, "miss") else "error"
        status[key] = status.get(key, 0) + 1
    summary: dict[str, Any] = {
        "n_impacts": len(rows),
        "status": status,
        "overall": group_stats(good),
        "by_class": {c: group_stats([r for r in good if r["class"] == c]) for c in classes},
        "by_partner": by_partner,
        "area_confusion": {"areas": list(AREAS), "rows_predicted_cols_measured": confusion(good).tolist()},
        "literature": [
            {
                "source": c.anchor.source,
                "case": c.anchor.case,
                "outcome": c.anchor.outcome,
                "speed_kmh": c.anchor.speed_kmh,
                "reported": c.anchor.risk,
                "model": c.model,
                "model_risk": c.predicted,
                "passed": c.passed,
            }
            for c in literature_table()
        ],
    }
    vehicle = [r for r in good if r["class"] != "static" and math.isfinite(r["angle_deg"])]
    if rng is not None and len(vehicle) >= 20:
        result = calibrate(
            column(vehicle, "dv_predicted_a"),
            column(vehicle, "dv_measured_a"),
            column(vehicle, "angle_deg"),
            row_offset_fractions(vehicle),
            [r["class"] for r in vehicle],
            rng,
        )
        summary["calibration"] = result.to_dict()
    return summary


def _fmt(x: float, pct: bool = False) -> str:
    if not isinstance(x, float | int) or not math.isfinite(x):
        return "-"
    return f"{100 * x:.1f}%" if pct else f"{x:.3f}"


def headline_markdown(summary: dict[str, Any]) -> str:
    """Markdown table: per partner and class, dv errors, area agreement, harm error."""
    lines = [
        "| partner | class | n | median abs dv error | p95 abs dv error | median signed dv error "
        "| area agreement | mean abs harm error |",
        "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for partner, entry in summary["by_partner"].items():
        for cls, s in entry.items():
            lines.append(
                f"| {partner} | {cls} | {s['n']} | {_fmt(s['dv_median_abs_rel_error'], True)} | "
                f"{_fmt(s['dv_p95_abs_rel_error'], True)} | {_fmt(s['dv_median_rel_error'], True)} | "
                f"{_fmt(s['area_agreement'], True)} | {_fmt(s['harm_mean_abs_error'])} |"
            )
    return "\n".join(lines)


_CALIBRATION_KEYS = ("test_error_eq1", "test_error_angle_only", "test_error_calibrated")
_CALIBRATION_NAMES = ("Eq. 1", "angle-only", "angle x offset")


def _calibration_markdown(cal: dict[str, Any]) -> str:
    corr = cal["correction"]
    lines = [
        "Correction (`ethical_planner.dv_correction.DeltaVCorrection`): Eq. 1 delta-v times a "
        "factor per bin of the angle between the velocity directions and the impact offset "
        "fraction (perpendicular distance of the partner's centre from the approach line through "
        "the ego's centre, over the sum of the footprints' half-extents; 0 central, 1 grazing), "
        "the median of measured / Eq. 1 over the training impacts of the bin. Bins with fewer "
        f"than {cal.get('min_count', '?')} training impacts take the angle-only factor (or 1). "
        f"Fitted on {100 * (1 - cal['test_fraction']):.0f}% of the impacts (seed {cal['seed']}); "
        "errors |(measured - model) / model| on the held-back rest.",
        "",
        "| class | n test | Eq. 1 median | Eq. 1 p95 | angle-only median | angle-only p95 "
        "| angle x offset median | angle x offset p95 |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    angle_only = cal.get("test_error_angle_only", {})
    for cls, before in cal["test_error_eq1"].items():
        mid = angle_only.get(cls, {})
        after = cal["test_error_calibrated"][cls]
        lines.append(
            f"| {cls} | {before['n']} | {_fmt(before['median_abs'], True)} | "
            f"{_fmt(before['p95_abs'], True)} | {_fmt(mid.get('median_abs'), True)} | "
            f"{_fmt(mid.get('p95_abs'), True)} | "
            f"{_fmt(after['median_abs'], True)} | {_fmt(after['p95_abs'], True)} |"
        )
    overall = [cal.get(k, {}).get("all", {}).get("p95_abs_log") for k in _CALIBRATION_KEYS]
    lines += [
        "",
        "p95 of |ln(measured / model)| (weighs under- and overestimates alike), all classes: "
        + ", ".join(f"{name} {_fmt(v)}" for name, v in zip(_CALIBRATION_NAMES, overall, strict=True))
        + ".",
    ]
    angle_edges, offset_edges = corr["angle_edges_deg"], corr["offset_edges"]
    counts = corr["n_train"]
    header = [f"{offset_edges[j]:g}-{offset_edges[j + 1]:g}" for j in range(len(offset_edges) - 1)]
    lines += [
        "",
        "Factor (training impacts) per angle bin [deg] (rows) and offset-fraction bin (columns):",
        "",
        "| angle \\ offset | " + " | ".join(header) + " |",
        "| --- |" + " ---: |" * len(header),
    ]
    for i, row in enumerate(corr["factors"]):
        cells = [f"{f:.3f} ({counts[i][j]})" if counts else f"{f:.3f}" for j, f in enumerate(row)]
        lines.append(f"| {angle_edges[i]:g}-{angle_edges[i + 1]:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_report(out_dir: Path, summary: dict[str, Any], title: str, plots: Sequence[str]) -> Path:
    """Write ``report.md`` from a summary; return its path."""
    conf = summary["area_confusion"]
    conf_lines = ["| predicted \\ measured | " + " | ".join(conf["areas"]) + " |", "| --- |" + " ---: |" * 4]
    for name, row in zip(conf["areas"], conf["rows_predicted_cols_measured"], strict=True):
        conf_lines.append(f"| {name} | " + " | ".join(str(v) for v in row) + " |")
    o = summary["overall"]
    parts = [
        f"# {title}",
        "",
        f"{summary['n_impacts']} impacts; status counts: {summary['status']}.",
        "",
        "Delta-v error = (measured - Eq. 1) / Eq. 1, measured = |contact impulse| / mass. "
        "Area agreement: reduced area (front / driver side / right side / rear) from the "
        "direction of the partner's centre (the planner's geometry) against the area of the "
        "force-weighted contact point, both bodies pooled. Harm error: |H(measured dv, "
        "measured angle) - H(Eq. 1 dv, geometric angle)| with the planner's models.",
        "",
        f"Overall: median |dv error| {_fmt(o['dv_median_abs_rel_error'], True)}, "
        f"p95 {_fmt(o['dv_p95_abs_rel_error'], True)}, area agreement {_fmt(o['area_agreement'], True)}, "
        f"mean |harm error| {_fmt(o['harm_mean_abs_error'])}.",
        "",
        "## By partner and impact class",
        "",
        headline_markdown(summary),
        "",
        "## Impact-area confusion (both bodies)",
        "",
        *conf_lines,
        "",
    ]
    if "calibration" in summary:
        parts += [
            "## Delta-v calibration (held-back impacts)",
            "",
            _calibration_markdown(summary["calibration"]),
            "",
        ]
    parts += [
        "## Literature check",
        "",
        "Car occupants: closing speed between equal-mass cars gives dv = closing / 2; "
        "reduced symmetric model, accepted within a factor of 2.5. Pedestrians: Tefft's "
        "AIS4+ and death risks are subsets of MAIS3+, so the pedestrian MAIS3+ model must lie "
        "at or above them (dv = m_ego / (m_ego + 75 kg) x impact speed).",
        "",
        literature_markdown(literature_table()),
        "",
    ]
    if plots:
        parts += ["## Plots", "", *[f"![{p}]({p})" for p in plots], ""]
    path = out_dir / "report.md"
    path.write_text("\n".join(parts), encoding="utf-8")
    return path


def write_summary(out_dir: Path, summary: dict[str, Any]) -> Path:
    """Write ``summary.json`` (NaN written as null)."""

    def clean(x: Any) -> Any:
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, list | tuple):
            return [clean(v) for v in x]
        return x

    path = out_dir / "summary.json"
    path.write_text(json.dumps(clean(summary), indent=2) + "\n", encoding="utf-8")
    return path


def write_plots(out_dir: Path, rows: Sequence[Row]) -> list[str]:
    """Write the PNG plots (matplotlib, Agg backend); return their file names ([] without matplotlib)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return []
    good = [r for r in measured(rows) if math.isfinite(r["angle_deg"])]
    if not good:
        return []
    names = []
    pred, meas = column(good, "dv_predicted_a"), column(good, "dv_measured_a")
    pred_b, meas_b = column(good, "dv_predicted_b"), column(good, "dv_measured_b")
    angle = column(good, "angle_deg")

    fig, ax = plt.subplots(figsize=(6, 5))
    sc = ax.scatter(
        np.r_[pred, pred_b], np.r_[meas, meas_b], c=np.r_[angle, angle], cmap="viridis", s=8, vmin=0, vmax=180
    )
    top = float(np.nanmax(np.r_[pred, meas, pred_b, meas_b])) * 1.05
    ax.plot([0, top], [0, top], "k--", lw=0.8)
    ax.set(xlabel="Eq. 1 delta-v [m/s]", ylabel="measured delta-v [m/s]", title="Delta-v, both bodies")
    fig.colorbar(sc, ax=ax, label="angle between velocities [deg]")
    names.append(_save(fig, out_dir, "dv_measured_vs_predicted.png"))

    fig, ax = plt.subplots(figsize=(7, 4))
    err = _dv_error(good)
    classes = [r["class"] for r in good]
    for cls, marker in zip(CLASSES, "o^s", strict=True):
        mask = np.array([c == cls for c in classes])
        if mask.any():
            jitter = (np.arange(mask.sum()) % 7 - 3) * 0.6
            ax.scatter(angle[mask] + jitter, 100 * err[mask], s=8, marker=marker, label=cls, alpha=0.7)
    ax.axhline(0, color="k", lw=0.8)
    ax.set(
        xlabel="angle between velocities [deg]", ylabel="delta-v error [%]", title="Eq. 1 error against angle"
    )
    ax.legend()
    names.append(_save(fig, out_dir, "dv_error_vs_angle.png"))

    fig, ax = plt.subplots(figsize=(5, 4.5))
    matrix = confusion(good)
    ax.imshow(matrix, cmap="Blues")
    for i in range(len(AREAS)):
        for j in range(len(AREAS)):
            ax.text(j, i, str(matrix[i, j]), ha="center", va="center")
    ax.set_xticks(range(len(AREAS)), AREAS, rotation=30)
    ax.set_yticks(range(len(AREAS)), AREAS)
    ax.set(xlabel="measured (contact point)", ylabel="predicted (centre direction)", title="Impact area")
    names.append(_save(fig, out_dir, "area_confusion.png"))

    fig, ax = plt.subplots(figsize=(6, 4))
    diff = np.array(
        [m - p for m, p in _body_pairs(good, "harm") if math.isfinite(m) and math.isfinite(p)], dtype=float
    )
    ax.hist(diff, bins=50)
    ax.set(xlabel="harm(measured) - harm(predicted)", ylabel="bodies", title="Harm error distribution")
    names.append(_save(fig, out_dir, "harm_error_hist.png"))
    return names


def _save(fig: Any, out_dir: Path, name: str) -> str:
    fig.tight_layout()
    fig.savefig(out_dir / name, dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return name


def analyse(
    out_dir: Path, rows: Sequence[Row], title: str, seed: int = 0, plots: bool = True
) -> dict[str, Any]:
    """Summary, plots, ``summary.json``, ``report.md`` (and ``calibration.json``) in ``out_dir``."""
    summary = summarize(rows, np.random.default_rng(seed))
    if "calibration" in summary:
        DeltaVCorrection.from_dict(summary["calibration"]["correction"]).save(out_dir / "calibration.json")
    names = write_plots(out_dir, rows) if plots else []
    write_summary(out_dir, summary)
    write_report(out_dir, summary, title, names)
    return summary


__all__ = ["CalibrationResult", "analyse", "summarize", "write_report", "write_summary", "write_plots"]
