"""Summary, report and figures of an impact table (controlled sweep or closed-loop runs).

The delta-v error of a model is e = (measured - model) / model, measured = |J| / m over the
impact sequence; both bodies of an impact share it (one impulse), so it is taken from body
a. Three models are compared everywhere: paper Eq. 1, the planar impulse model
(``ethical_planner.impulse``, the first impulse) and the sequence-aware planar model (every
impulse of the sequence, ``harm_calibration.sequence``). Per partner type and impact class (central collinear,
oblique, offset): median and 95th percentile of |e|, the share of multi-impact sequences,
agreement of the geometric impact area with the measured one and the harm error
|H(measured) - H(model)| per body. Sweeps add the held-back evaluation by geometry cell
(``calibration.held_back_evaluation``) and the speed check.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from harm_calibration.calibration import (
    MIN_IMPACT_DV_MS,
    REFERENCES,
    SPEED_TABLE_SPEEDS,
    SPEED_VERDICTS,
    done_checks,
    error_stats,
    held_back_evaluation,
    relative_error,
    scored,
    speed_independence,
)
from harm_calibration.geometry import CLASSES
from harm_calibration.literature import literature_markdown, literature_table
from harm_calibration.rows import Row, column

AREAS = ("front", "driver_side", "right_side", "rear")
MEASURED_STATUS = ("ok", "incomplete")
#: Delta-v models compared: label -> (delta-v column prefix, harm column prefix).
DV_MODELS = {
    "Eq. 1": ("dv_predicted", "harm_predicted"),
    "planar": ("dv_planar", "harm_planar"),
    "planar sequence": ("dv_planar_seq", "harm_planar_seq"),
}


def measured(rows: Sequence[Row]) -> list[Row]:
    """Rows with a measurement (status ok or incomplete)."""
    return [r for r in rows if r["status"] in MEASURED_STATUS]


def _body_pairs(rows: Sequence[Row], key: str) -> list[tuple[Any, Any]]:
    return [(r[f"{key}_measured_{s}"], r[f"{key}_predicted_{s}"]) for r in rows for s in ("a", "b")]


def _area_agreement(rows: Sequence[Row]) -> float:
    pairs = [(m, p) for m, p in _body_pairs(rows, "area") if m and p]
    return float(np.mean([m == p for m, p in pairs])) if pairs else math.nan


def dv_errors(rows: Sequence[Row], model: str, reference: str = "sequence") -> np.ndarray:
    """Relative delta-v error of body a for a model of ``DV_MODELS``, shape (n,).

    Against the measured ``reference`` (``calibration.REFERENCES``); nan for touches
    (``calibration.scored``).
    """
    if not rows:
        return np.array([])
    err = relative_error(column(rows, REFERENCES[reference]), column(rows, f"{DV_MODELS[model][0]}_a"))
    return np.where(scored(rows), err, np.nan)


def harm_errors(rows: Sequence[Row], model: str, side: str) -> np.ndarray:
    """H(measured) - H(model) of body ``side`` ("a" or "b"), finite entries, shape (k,)."""
    if not rows:
        return np.array([])
    diff = column(rows, f"harm_measured_{side}") - column(rows, f"{DV_MODELS[model][1]}_{side}")
    return diff[np.isfinite(diff)]


def group_stats(rows: Sequence[Row], reference: str = "sequence") -> dict[str, Any]:
    """Error statistics of a group of measured rows, per model, against a measured reference."""
    out: dict[str, Any] = {"n": len(rows)}
    for model in DV_MODELS:
        out[model] = error_stats(dv_errors(rows, model, reference))
        both = np.concatenate([harm_errors(rows, model, "a"), harm_errors(rows, model, "b")])
        out[model]["harm_mean_abs"] = float(np.mean(np.abs(both))) if both.size else math.nan
    out["multi_impact_share"] = (
        float(np.mean([r.get("multi_impact") == "yes" for r in rows])) if rows else math.nan
    )
    out["area_agreement"] = _area_agreement(rows)
    return out


def confusion(rows: Sequence[Row]) -> np.ndarray:
    """Reduced-area confusion matrix, rows predicted, columns measured, shape (4, 4), both bodies."""
    matrix = np.zeros((len(AREAS), len(AREAS)), dtype=int)
    for m, p in _body_pairs(rows, "area"):
        if m in AREAS and p in AREAS:
            matrix[AREAS.index(p), AREAS.index(m)] += 1
    return matrix


def harm_by_partner(rows: Sequence[Row]) -> dict[str, Any]:
    """Harm error per partner type and body (a: the ego, b: the partner), per model."""
    out: dict[str, Any] = {}
    for partner in sorted({r["partner"] for r in rows}):
        in_p = [r for r in rows if r["partner"] == partner]
        out[partner] = {}
        for side, body in (("b", "partner"), ("a", "ego")):
            entry = {}
            for model in DV_MODELS:
                diff = harm_errors(in_p, model, side)
                entry[model] = {
                    "n": int(diff.size),
                    "mean_abs": float(np.mean(np.abs(diff))) if diff.size else math.nan,
                    "p95_abs": float(np.percentile(np.abs(diff), 95)) if diff.size else math.nan,
                    "mean": float(np.mean(diff)) if diff.size else math.nan,
                }
            out[partner][body] = entry
    return out


def summarize(rows: Sequence[Row], seeds: Sequence[int] | None = None) -> dict[str, Any]:
    """Summary of a table of impacts (the content of ``summary.json``).

    Args:
        rows: impact rows (any status).
        seeds: splits of the held-back evaluation (sweep rows with geometry cells only);
            None skips it.
    """
    good = measured(rows)
    partners = sorted({r["partner"] for r in good})
    classes = [c for c in (*CLASSES, "static") if any(r["class"] == c for r in good)]

    def by_partner_table(reference: str) -> dict[str, Any]:
        table = {}
        for p in partners:
            in_p = [r for r in good if r["partner"] == p]
            entry = {"all": group_stats(in_p, reference)}
            for c in classes:
                in_pc = [r for r in in_p if r["class"] == c]
                if in_pc:
                    entry[c] = group_stats(in_pc, reference)
            table[p] = entry
        return table

    status: dict[str, int] = {}
    for r in rows:
        key = r["status"] if r["status"] in (*MEASURED_STATUS, "miss") else "error"
        status[key] = status.get(key, 0) + 1
    summary: dict[str, Any] = {
        "n_impacts": len(rows),
        "status": status,
        "modes": sorted({r.get("mode", "") for r in good}),
        "restitution_sets": sorted({r.get("restitution_set", "") for r in good}),
        "overall": group_stats(good),
        "overall_first_impulse": group_stats(good, "first impulse"),
        "by_class": {c: group_stats([r for r in good if r["class"] == c]) for c in classes},
        "by_partner": by_partner_table("sequence"),
        "by_partner_first_impulse": by_partner_table("first impulse"),
        "harm_by_partner": harm_by_partner(good),
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
    swept = [r for r in good if r.get("cell")]
    if seeds is not None and len({r["cell"] for r in swept}) >= 10:
        for key, reference in (("held_back", "sequence"), ("held_back_first_impulse", "first impulse")):
            evaluation = held_back_evaluation(swept, seeds, reference=reference)
            summary[key] = evaluation
            summary[f"{key}_checks"] = done_checks(evaluation)
            summary[f"{key}_seq_checks"] = done_checks(evaluation, "planar_seq")
    if swept:
        summary["speed_independence"] = speed_independence(swept)
    return summary


def _fmt(x: Any, pct: bool = False) -> str:
    if not isinstance(x, float | int) or isinstance(x, bool) or not math.isfinite(x):
        return "-"
    return f"{100 * x:.1f}%" if pct else f"{x:.3f}"


def headline_markdown(summary: dict[str, Any], key: str = "by_partner") -> str:
    """Markdown table: per partner and class, |dv error| of every model, multi-impact share."""
    lines = [
        "| partner | class | n | Eq. 1 median | Eq. 1 p95 | planar median | planar p95 "
        "| planar sequence median | planar sequence p95 | multi-impact |",
        "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for partner, entry in summary[key].items():
        for cls, s in entry.items():
            cells = " | ".join(
                f"{_fmt(s[m]['median_abs'], True)} | {_fmt(s[m]['p95_abs'], True)}" for m in DV_MODELS
            )
            lines.append(
                f"| {partner} | {cls} | {s['n']} | {cells} | {_fmt(s['multi_impact_share'], True)} |"
            )
    return "\n".join(lines)


def _range(stat: dict[str, float], pct: bool = True) -> str:
    """'median (min-max)' over the splits; '-' without a value."""
    if not math.isfinite(stat["median"]):
        return "-"
    if not pct:
        return f"{stat['median']:.0f} ({stat['min']:.0f}-{stat['max']:.0f})"
    return f"{_fmt(stat['median'], True)} ({_fmt(stat['min'], True)}-{_fmt(stat['max'], True)})"


def held_back_markdown(evaluation: dict[str, Any]) -> str:
    """Markdown of the held-back evaluation: per group, median and p95 |error| per model."""
    lines = [
        f"Measured reference: {evaluation['reference']}. "
        f"{len(evaluation['seeds'])} splits (seeds {evaluation['seeds'][0]}-{evaluation['seeds'][-1]}), "
        f"{100 * evaluation['test_fraction']:.0f}% of {evaluation['n_cells']} geometry cells held back each; "
        "median over the splits (range in brackets) of the median and 95th percentile of |error| on the "
        "held-back impacts. Correction: Eq. 1 times the median measured / Eq. 1 of the training impacts in "
        f"the same angle x offset bin (bins with fewer than {evaluation['min_count']} training impacts have "
        "no factor; their test impacts are counted below, not scored).",
        "",
        "| group | n test (range) | Eq. 1 median | Eq. 1 p95 | planar median | planar p95 "
        "| planar sequence median | planar sequence p95 | correction median | correction p95 |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for group, models in evaluation["groups"].items():
        cells = " | ".join(
            f"{_range(models[m]['median_abs'])} | {_range(models[m]['p95_abs'])}"
            for m in ("eq1", "planar", "planar_seq", "correction")
        )
        lines.append(f"| {group} | {_range(models['eq1']['n'], pct=False)} | {cells} |")
    unseen = evaluation["unseen"]
    counts = [u["unseen_impacts"] for u in unseen]
    tests = [u["test_impacts"] for u in unseen]
    bins = sorted({b for u in unseen for b in u["unseen_bins"]})
    lines += [
        "",
        f"Unseen bins: {min(counts)}-{max(counts)} of {min(tests)}-{max(tests)} held-back impacts per split "
        f"fell in bins without training impacts ({len(bins)} distinct bins"
        + (": " + "; ".join(bins[:12]) + (" ..." if len(bins) > 12 else "") if bins else "")
        + ").",
        "",
        "Decision: "
        + (
            "the correction beats the planar model on held-back cells."
            if evaluation["decision"]["correction_beats_planar"]
            else "the correction does not beat the planar model on held-back cells; it is retired."
        ),
    ]
    return "\n".join(lines)


def done_markdown(checks: Sequence[dict[str, Any]], label: str = "planar") -> str:
    """Markdown of the acceptance checks (the model's median <= Eq. 1 / 2, p95 no worse)."""
    lines = [
        f"| group | Eq. 1 median | {label} median | median halved | Eq. 1 p95 | {label} p95 | p95 no worse |",
        "| --- | ---: | ---: | :---: | ---: | ---: | :---: |",
    ]
    for c in checks:
        lines.append(
            f"| {c['group']} | {_fmt(c['eq1_median'], True)} | {_fmt(c['planar_median'], True)} | "
            f"{'yes' if c['median_halved'] else 'NO'} | {_fmt(c['eq1_p95'], True)} | "
            f"{_fmt(c['planar_p95'], True)} | {'yes' if c['p95_no_worse'] else 'NO'} |"
        )
    return "\n".join(lines)


def harm_markdown(harm: dict[str, Any]) -> str:
    """Markdown of the harm error per partner and body."""
    lines = [
        "| partner | body | n | Eq. 1 mean abs | Eq. 1 p95 abs | planar mean abs | planar p95 abs "
        "| planar sequence mean abs | planar sequence p95 abs |",
        "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for partner, bodies in harm.items():
        for body, models in bodies.items():
            cells = " | ".join(
                f"{_fmt(models[m]['mean_abs'])} | {_fmt(models[m]['p95_abs'])}" for m in DV_MODELS
            )
            lines.append(f"| {partner} | {body} | {models['Eq. 1']['n']} | {cells} |")
    return "\n".join(lines)


def speed_markdown(check: dict[str, Any], only_flagged: bool = False) -> str:
    """Markdown of the speed check: counts per restitution setting, then a row per cell.

    Args:
        check: ``calibration.speed_independence`` result.
        only_flagged: list only the cells whose ratio varies by the limit or more.
    """
    speeds = [f"{v:g}" for v in SPEED_TABLE_SPEEDS]
    lines = [
        f"Ratio measured / Eq. 1 (the ego's delta-v over the whole sequence) across closing speeds "
        f"{check['speeds'][0]:g}-{check['speeds'][1]:g} m/s per geometry cell "
        f"({', '.join(check['partners'])}); spread = max / min - 1 over the speeds, flagged at "
        f"{100 * check['limit']:.0f}% or more. Verdicts: "
        + "; ".join(f"*{v}*: {text}" for v, text in SPEED_VERDICTS.items())
        + ".",
        "",
        "| restitution | cells | " + " | ".join(SPEED_VERDICTS) + " | largest spread |",
        "| --- | ---: |" + " ---: |" * (len(SPEED_VERDICTS) + 1),
    ]
    for rset, s in check["by_restitution_set"].items():
        counts = " | ".join(str(s[v]) for v in SPEED_VERDICTS)
        lines.append(f"| {rset} | {s['n_cells']} | {counts} | {_fmt(s['max_variation'], True)} |")
    cells = check["flagged"] if only_flagged else check["cells"]
    if not cells:
        return "\n".join(lines)
    lines += [
        "",
        "| cell | restitution | " + " | ".join(f"{v} m/s" for v in speeds)
        + " | spread | spread, single impulses | spread of measured / planar "
        "| spread of first impulse / planar | spread of measured / planar sequence | impulses | verdict |",
        "| --- | --- |" + " ---: |" * (len(speeds) + 5) + " --- | --- |",
    ]  # fmt: skip
    for c in cells:
        ratios = " | ".join(_fmt(c["ratio"].get(v)) for v in speeds)
        impulses = "/".join(
            "-" if not isinstance(n, float | int) or not math.isfinite(n) else f"{n:.0f}"
            for n in (c["impulses"].get(v) for v in speeds)
        )
        lines.append(
            f"| {c['cell']} | {c['restitution_set']} | {ratios} | {_fmt(c['variation'], True)} "
            f"| {_fmt(c['variation_single'], True)} | {_fmt(c['variation_planar'], True)} "
            f"| {_fmt(c['variation_first'], True)} | {_fmt(c.get('variation_seq'), True)} | {impulses} "
            f"| {c['verdict']} |"
        )
    return "\n".join(lines)


def collisions_markdown(rows: Sequence[Row]) -> str:
    """One line per collision of a batch: measured delta-v and harm against both models."""
    lines = [
        "| run | bodies | closing [m/s] | class | dv measured a / b | Eq. 1 a / b | planar a / b "
        "| planar sequence a / b | harm measured a / b | harm Eq. 1 a / b | harm planar a / b "
        "| harm planar sequence a / b | impulses |",
        "| --- | --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]

    def pair(r: Row, key: str, digits: int = 2) -> str:
        values = [r[f"{key}_{s}"] for s in ("a", "b")]
        return " / ".join("-" if not math.isfinite(v) else f"{v:.{digits}f}" for v in values)

    for r in rows:
        lines.append(
            f"| {r['source']} | {r['type_a']}-{r['type_b']} | {r['closing_speed']:.1f} | {r['class']} | "
            f"{pair(r, 'dv_measured')} | {pair(r, 'dv_predicted')} | {pair(r, 'dv_planar')} | "
            f"{pair(r, 'dv_planar_seq')} | {pair(r, 'harm_measured', 3)} | {pair(r, 'harm_predicted', 3)} | "
            f"{pair(r, 'harm_planar', 3)} | {pair(r, 'harm_planar_seq', 3)} | "
            f"{r['n_impulses']:.0f} |"
        )
    return "\n".join(lines)


def write_report(
    out_dir: Path, summary: dict[str, Any], title: str, figures: Sequence[str], rows: Sequence[Row] = ()
) -> Path:
    """Write ``report.md`` from a summary; return its path."""
    conf = np.array(summary["area_confusion"]["rows_predicted_cols_measured"], dtype=float)
    share = conf / np.maximum(conf.sum(axis=1, keepdims=True), 1.0)
    conf_lines = ["| predicted \\ measured | " + " | ".join(AREAS) + " | n |", "| --- |" + " ---: |" * 5]
    for i, name in enumerate(AREAS):
        cells = " | ".join(f"{100 * share[i, j]:.0f}%" for j in range(len(AREAS)))
        conf_lines.append(f"| {name} | {cells} | {int(conf[i].sum())} |")
    o = summary["overall"]
    f = summary["overall_first_impulse"]
    parts = [
        f"# {title}",
        "",
        f"{summary['n_impacts']} impacts; status counts: {summary['status']}; contact mode(s): "
        f"{', '.join(summary['modes'])}; restitution: {', '.join(summary['restitution_sets'])}.",
        "",
        "Delta-v error e = (measured - model) / model, measured = |J| / m over the impact sequence "
        "(from the first contact until the bodies have stayed apart for 0.5 s) or of its first impulse; "
        "models: paper Eq. 1 (perfectly plastic, common velocity), the planar impulse model "
        "(`ethical_planner.impulse`: impulse at the first contact of the footprints, restitution law, "
        "Coulomb impulse ratio 0.3) and the planar sequence model (`planar_impulse_sequence`: that impulse, "
        "then the bodies moved on with their new velocities and yaw rates, skidding at the tyre limit as the "
        "world's crashed bodies do, every later contact's impulse; |sum of the impulses| / m). "
        f"Touches (larger measured delta-v below {MIN_IMPACT_DV_MS} m/s) are "
        "not scored. Harm error: |H(measured dv, measured angle) - H(model dv, geometric angle)| with the "
        "planner's harm models.",
        "",
        "Overall |dv error| against the whole sequence: Eq. 1 median "
        f"{_fmt(o['Eq. 1']['median_abs'], True)}, "
        f"p95 {_fmt(o['Eq. 1']['p95_abs'], True)}; planar median {_fmt(o['planar']['median_abs'], True)}, "
        f"p95 {_fmt(o['planar']['p95_abs'], True)}. Against the first impulse: Eq. 1 median "
        f"{_fmt(f['Eq. 1']['median_abs'], True)}, p95 {_fmt(f['Eq. 1']['p95_abs'], True)}; planar median "
        f"{_fmt(f['planar']['median_abs'], True)}, p95 {_fmt(f['planar']['p95_abs'], True)}. "
        "Planar sequence model against the whole sequence: median "
        f"{_fmt(o['planar sequence']['median_abs'], True)}, "
        f"p95 {_fmt(o['planar sequence']['p95_abs'], True)}. "
        f"Multi-impact sequences: {_fmt(o['multi_impact_share'], True)}. "
        f"Impact-area agreement: {_fmt(o['area_agreement'], True)}.",
        "",
        "## Delta-v error by partner and impact class (all impacts, whole sequence)",
        "",
        headline_markdown(summary),
        "",
        "## The same against the first impulse",
        "",
        headline_markdown(summary, "by_partner_first_impulse"),
        "",
    ]
    for key, name in (("held_back", "whole sequence"), ("held_back_first_impulse", "first impulse")):
        if key in summary:
            parts += [
                f"## Held-back geometry cells ({name})",
                "",
                held_back_markdown(summary[key]),
                "",
                "Acceptance (held back): planar median at most half of Eq. 1's, planar p95 no worse:",
                "",
                done_markdown(summary[f"{key}_checks"]),
                "",
                "The same for the planar sequence model:",
                "",
                done_markdown(summary[f"{key}_seq_checks"], "planar sequence"),
                "",
            ]
    parts += ["## Harm error per partner", "", harm_markdown(summary["harm_by_partner"]), ""]
    if "speed_independence" in summary:
        parts += ["## Speed independence (vehicles)", "", speed_markdown(summary["speed_independence"]), ""]
    if rows and not any(r.get("cell") for r in rows):
        parts += ["## Collisions", "", collisions_markdown(measured(rows)), ""]
    parts += [
        "## Impact area: predicted (centre direction) against measured (contact point), both bodies",
        "",
        *conf_lines,
        "",
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
    if figures:
        parts += ["## Figures", "", *[f"![{f}]({f})" for f in figures], ""]
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


def analyse(
    out_dir: Path,
    rows: Sequence[Row],
    title: str,
    seeds: Sequence[int] = tuple(range(10)),
    plots: bool = True,
) -> dict[str, Any]:
    """Summary, figures (PNG and PDF), ``summary.json`` and ``report.md`` in ``out_dir``."""
    from harm_calibration.figures import write_figures

    summary = summarize(rows, seeds)
    names = write_figures(out_dir, measured(rows), summary) if plots else []
    write_summary(out_dir, summary)
    write_report(out_dir, summary, title, names, rows)
    return summary


__all__ = ["analyse", "summarize", "write_report", "write_summary"]
