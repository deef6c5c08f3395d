"""Figures of an impact table, written as PNG and PDF (matplotlib, Agg backend).

Every figure states its quantities and units on the axes, compares one model per panel
where two are shown, tells partner types apart by colour (Okabe-Ito, colour-blind safe)
and impact classes by marker, and keeps legends outside the data.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from harm_calibration.analysis import AREAS, DV_MODELS, confusion, dv_errors, harm_errors
from harm_calibration.geometry import CLASSES
from harm_calibration.rows import Row, column

#: Okabe-Ito colours per partner type.
PARTNER_COLOURS = {
    "car": "#0072B2",
    "truck": "#D55E00",
    "bus": "#E69F00",
    "motorcycle": "#CC79A7",
    "bicycle": "#009E73",
    "pedestrian": "#56B4E9",
}
CLASS_MARKERS = {"central_collinear": "o", "oblique": "^", "offset": "s", "static": "D"}
MODEL_COLOURS = {
    "Eq. 1": "#7f7f7f",
    "planar": "#0072B2",
    "planar sequence": "#009E73",
    "correction": "#D55E00",
}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update(
        {"font.size": 9, "axes.titlesize": 10, "axes.labelsize": 9, "legend.fontsize": 8, "figure.dpi": 100}
    )
    return plt


def _save(fig: Any, out_dir: Path, stem: str) -> str:
    """Save ``stem``.png (200 dpi) and ``stem``.pdf; return the PNG name."""
    plt = _pyplot()
    fig.savefig(out_dir / f"{stem}.png", dpi=200, bbox_inches="tight")
    fig.savefig(out_dir / f"{stem}.pdf", bbox_inches="tight")
    plt.close(fig)
    return f"{stem}.png"


def _colour(partner: str) -> str:
    return PARTNER_COLOURS.get(partner, "#000000")


def dv_scatter(out_dir: Path, rows: Sequence[Row]) -> str:
    """Measured against predicted delta-v of the partner, one panel per model."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(DV_MODELS), figsize=(3.6 * len(DV_MODELS), 3.6), sharex=True, sharey=True)
    meas = column(rows, "dv_measured_b")
    finite = meas[np.isfinite(meas) & (meas > 0)]
    lo, hi = max(0.05, float(finite.min()) * 0.8), float(finite.max()) * 1.25
    partners = [p for p in PARTNER_COLOURS if any(r["partner"] == p for r in rows)]
    for ax, (model, (dv_key, _)) in zip(axes, DV_MODELS.items(), strict=True):
        pred = column(rows, f"{dv_key}_b")
        for partner in partners:
            for cls, marker in CLASS_MARKERS.items():
                mask = np.array([r["partner"] == partner and r["class"] == cls for r in rows])
                mask &= np.isfinite(pred) & (pred > 0) & np.isfinite(meas) & (meas > 0)
                if mask.any():
                    ax.scatter(pred[mask], meas[mask], s=7, marker=marker, color=_colour(partner),
                               alpha=0.55, linewidths=0, rasterized=True)  # fmt: skip
        grid = np.array([lo, hi])
        ax.plot(grid, grid, color="black", lw=0.9, label="measured = model")
        ax.fill_between(grid, grid / 1.2, grid * 1.2, color="black", alpha=0.08, lw=0, label="within 20 %")
        ax.set(xscale="log", yscale="log", xlim=(lo, hi), ylim=(lo, hi), title=f"{model}",
               xlabel=f"{model} delta-v of the partner [m/s]")  # fmt: skip
        ax.set_aspect("equal")
        ax.grid(True, which="major", lw=0.3, alpha=0.5)
    axes[0].set_ylabel("measured delta-v of the partner [m/s]")
    handles = [
        plt.Line2D([], [], ls="", marker="o", color=_colour(p), label=p) for p in partners
    ] + [plt.Line2D([], [], ls="", marker=m, color="black", mfc="none", label=c.replace("_", " "))
         for c, m in CLASS_MARKERS.items() if any(r["class"] == c for r in rows)]  # fmt: skip
    handles += axes[1].get_legend_handles_labels()[0]
    fig.legend(handles=handles, loc="center left", bbox_to_anchor=(1.0, 0.5), frameon=False)
    fig.suptitle("Delta-v: measured (rigid contact, whole impact sequence) against each model", y=1.02)
    return _save(fig, out_dir, "dv_measured_vs_model")


def dv_error_by_angle(out_dir: Path, rows: Sequence[Row]) -> str:
    """Median and interquartile range of the relative error per angle and partner.

    Models by column, measured references (whole sequence, first impulse) by row.
    """
    plt = _pyplot()
    references = (("sequence", "whole sequence"), ("first impulse", "first impulse"))
    fig, axes = plt.subplots(2, len(DV_MODELS), figsize=(3.6 * len(DV_MODELS), 5.6), sharex=True)
    angle = column(rows, "angle_deg")
    partners = [p for p in PARTNER_COLOURS if any(r["partner"] == p for r in rows)]
    for row_axes, (reference, label) in zip(axes, references, strict=True):
        errors = {m: 100 * dv_errors(rows, m, reference) for m in DV_MODELS}
        pooled = np.concatenate(list(errors.values()))
        pooled = pooled[np.isfinite(pooled)]
        y_lo, y_hi = np.percentile(pooled, [2, 98]) if pooled.size else (-100, 100)
        for ax, model in zip(row_axes, DV_MODELS, strict=True):
            err = errors[model]
            for partner in partners:
                in_p = np.array([r["partner"] == partner for r in rows]) & np.isfinite(err)
                angles = np.unique(angle[in_p])
                quartiles = np.array([np.percentile(err[in_p & (angle == a)], [25, 50, 75]) for a in angles])
                if not angles.size:
                    continue
                ax.plot(angles, quartiles[:, 1], color=_colour(partner), lw=1.2, marker="o", ms=2.5,
                        label=partner)  # fmt: skip
                ax.fill_between(angles, quartiles[:, 0], quartiles[:, 2], color=_colour(partner), alpha=0.15,
                                lw=0)  # fmt: skip
            ax.axhline(0, color="black", lw=0.8)
            ax.set(xlim=(0, 180), ylim=(min(y_lo, -10) * 1.1, max(y_hi, 10) * 1.1), xticks=range(0, 181, 30))
            ax.set_title(f"{model} against the {label}")
            ax.grid(True, lw=0.3, alpha=0.5)
        row_axes[0].set_ylabel("(measured - model) / model [%]")
    for ax in axes[-1]:
        ax.set_xlabel("angle between the velocity directions [deg]")
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="center left", bbox_to_anchor=(1.0, 0.5),
               frameon=False, title="partner\n(line: median,\nband: 25-75 %)")  # fmt: skip
    fig.suptitle("Relative delta-v error of the ego against the impact angle (all offsets and speeds)", y=1.0)
    fig.tight_layout()
    return _save(fig, out_dir, "dv_error_vs_angle")


def area_confusion(out_dir: Path, rows: Sequence[Row]) -> str:
    """Row-normalised confusion of the predicted and measured impact areas."""
    plt = _pyplot()
    matrix = confusion(rows).astype(float)
    totals = matrix.sum(axis=1, keepdims=True)
    share = matrix / np.maximum(totals, 1.0)
    fig, ax = plt.subplots(figsize=(4.6, 3.8))
    image = ax.imshow(100 * share, cmap="viridis", vmin=0, vmax=100)
    for i in range(len(AREAS)):
        for j in range(len(AREAS)):
            colour = "black" if share[i, j] > 0.6 else "white"
            ax.text(j, i, f"{100 * share[i, j]:.0f}%\n({int(matrix[i, j])})", ha="center", va="center",
                    color=colour, fontsize=8)  # fmt: skip
    labels = [a.replace("_", " ") for a in AREAS]
    ax.set_xticks(range(len(AREAS)), labels, rotation=20)
    ax.set_yticks(
        range(len(AREAS)), [f"{lab} (n={int(t)})" for lab, t in zip(labels, totals[:, 0], strict=True)]
    )
    ax.set(
        xlabel="measured area (force-weighted contact point)",
        ylabel="predicted area (direction of the partner)",
    )
    fig.colorbar(image, ax=ax, label="share of the predicted row [%]", fraction=0.046, pad=0.04)
    ax.set_title("Impact area, both bodies of every impact")
    return _save(fig, out_dir, "area_confusion")


def harm_error(out_dir: Path, rows: Sequence[Row]) -> str:
    """Exceedance of the partner's harm error per partner type, one line per model."""
    plt = _pyplot()
    partners = [p for p in PARTNER_COLOURS if any(r["partner"] == p for r in rows)]
    n_cols = 3
    n_rows = max(1, math.ceil(len(partners) / n_cols))
    fig, axes = plt.subplots(
        n_rows, n_cols, figsize=(7.2, 2.4 * n_rows), sharex=True, sharey=True, squeeze=False
    )
    for ax, partner in zip(axes.ravel(), partners, strict=False):
        in_p = [r for r in rows if r["partner"] == partner]
        for model in DV_MODELS:
            diff = np.sort(np.abs(harm_errors(in_p, model, "b")))
            if not diff.size:
                continue
            exceed = 1.0 - np.arange(diff.size) / diff.size
            ax.step(
                np.maximum(diff, 1e-5), exceed, where="post", color=MODEL_COLOURS[model], lw=1.2, label=model
            )
        ax.set(xscale="log", yscale="log", xlim=(1e-4, 1), ylim=(1.0 / max(len(in_p), 10), 1.05))
        ax.set_title(f"{partner} (n = {len(in_p)})", color=_colour(partner))
        ax.grid(True, which="major", lw=0.3, alpha=0.5)
    for ax in axes.ravel()[len(partners) :]:
        ax.set_visible(False)
    fig.supxlabel("|H(measured) - H(model)| of the partner (MAIS3+ probability)", fontsize=9)
    fig.supylabel("share of impacts exceeding", fontsize=9)
    fig.legend(
        *axes[0, 0].get_legend_handles_labels(), loc="center left", bbox_to_anchor=(1.0, 0.5), frameon=False
    )
    fig.suptitle("Harm error of the partner per partner type (delta-v of each model, whole sequence)", y=1.01)
    return _save(fig, out_dir, "harm_error")


def held_back(out_dir: Path, summary: dict[str, Any], which: str = "held_back") -> str:
    """Held-back median and p95 |error| per group and model, with the range over the splits.

    ``which``: ``held_back`` (error against the whole sequence) or ``held_back_first_impulse``.
    """
    plt = _pyplot()
    from harm_calibration.calibration import PARTNER_SEQUENCE

    groups = summary[which]["groups"]
    names = [g for g in groups if not g.startswith(PARTNER_SEQUENCE)]  # those are in report.md
    models = (
        ("eq1", "Eq. 1"),
        ("planar", "planar"),
        ("planar_seq", "planar sequence"),
        ("correction", "correction"),
    )
    legend = {"Eq. 1": "Eq. 1", "planar": "planar impulse model (first impulse)",
              "planar sequence": "planar sequence model (every impulse)",
              "correction": "Eq. 1 x angle-offset factor (retired)"}  # fmt: skip
    fig, axes = plt.subplots(2, 1, figsize=(7.2, 4.8), sharex=True)
    x = np.arange(len(names))
    width = 0.8 / len(models)
    for ax, stat, label in zip(axes, ("median_abs", "p95_abs"), ("median", "95th percentile"), strict=True):
        for k, (key, name) in enumerate(models):
            floor = 0.01  # [%]: the log axis shows the planar model's small errors
            mid = np.maximum(np.array([groups[g][key][stat]["median"] for g in names]) * 100, floor)
            low = np.maximum(np.array([groups[g][key][stat]["min"] for g in names]) * 100, floor)
            high = np.maximum(np.array([groups[g][key][stat]["max"] for g in names]) * 100, floor)
            shift = (k - 0.5 * (len(models) - 1)) * width
            ax.bar(x + shift, mid - floor, width, bottom=floor, color=MODEL_COLOURS[name],
                   label=legend[name])  # fmt: skip
            ax.errorbar(x + shift, mid, yerr=[mid - low, high - mid], fmt="none", ecolor="black",
                        lw=0.7, capsize=1.5)  # fmt: skip
        ax.set_yscale("log")
        ax.set_ylim(floor, None)
        ax.yaxis.set_major_formatter(plt.FuncFormatter(lambda v, _: f"{v:g}"))
        ax.set_ylabel(f"{label} of |error| [%]")
        ax.grid(True, axis="y", lw=0.3, alpha=0.5)
    labels = [n.split(":", 1)[-1].replace("_", " ") for n in names]
    axes[1].set_xticks(x, labels, rotation=30, ha="right")
    axes[0].legend(loc="center left", bbox_to_anchor=(1.0, 0.5), frameon=False)
    n = len(summary[which]["seeds"])
    reference = {"sequence": "whole sequence"}.get(summary[which]["reference"], summary[which]["reference"])
    fig.suptitle(
        f"Held-back geometry cells, error against the {reference}: bars = median over {n} splits, "
        "whiskers = range",
        y=1.0,
    )
    return _save(fig, out_dir, which)


#: Line style of a cell in the speed figure, per ``calibration.SPEED_VERDICTS`` verdict.
_VERDICT_STYLE = {
    "steady": {"lw": 0.7, "alpha": 0.8, "zorder": 2},
    "multi-impact": {"color": "#999999", "lw": 0.6, "ls": "--", "alpha": 0.7, "zorder": 1},
    "restitution law": {"color": "#555555", "lw": 1.0, "ls": ":", "zorder": 2},
    "sequence model": {"color": "#009E73", "lw": 1.0, "ls": "-.", "zorder": 2},
    "unexplained": {"color": "black", "lw": 1.4, "zorder": 3},
}


def speed_ratio(out_dir: Path, check: dict[str, Any]) -> str:
    """Measured / Eq. 1 against the closing speed for every vehicle cell, a panel per partner.

    Args:
        out_dir: output folder.
        check: ``calibration.speed_independence`` result (cells with ratios and verdicts).
    """
    plt = _pyplot()
    cells = check["cells"]
    partners = [p for p in check["partners"] if any(c["cell"].split("|")[0] == p for c in cells)]
    sets = sorted({c["restitution_set"] for c in cells})
    fig, axes = plt.subplots(len(sets), len(partners), figsize=(2.6 * len(partners), 2.6 * len(sets)),
                             sharex=True, sharey=True, squeeze=False)  # fmt: skip
    for row_axes, rset in zip(axes, sets, strict=True):
        for ax, partner in zip(row_axes, partners, strict=True):
            for c in cells:
                if c["restitution_set"] != rset or c["cell"].split("|")[0] != partner:
                    continue
                speed = np.array([float(v) for v in c["ratio"]])
                ratio = np.array(list(c["ratio"].values()), dtype=float)
                order = np.argsort(speed)
                style = {"color": _colour(partner)} | _VERDICT_STYLE[c["verdict"]]
                ax.plot(speed[order], ratio[order], **style)
            title = partner + (f", restitution {rset}" if len(sets) > 1 else "")
            ax.set_title(title, color=_colour(partner))
            ax.grid(True, lw=0.3, alpha=0.5)
            ax.set_xlim(0, 32)
    for ax in axes[-1]:
        ax.set_xlabel("closing speed [m/s]")
    for ax in axes[:, 0]:
        ax.set_ylabel("measured / Eq. 1 delta-v\nof the ego (whole sequence)")
    labels = {
        "steady": f"steady: spread below {check['limit']:.0%} (partner colour)",
        "multi-impact": "multi-impact: single-impulse speeds and first impulse / planar steady",
        "restitution law": "restitution law: measured / planar model steady",
        "sequence model": "sequence model: measured / planar sequence model steady",
        "unexplained": "unexplained",
    }
    handles = [
        plt.Line2D([], [], **({"color": "#555555"} | style), label=labels[verdict])
        for verdict, style in _VERDICT_STYLE.items()
    ]
    fig.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 0.0), frameon=False, ncol=1,
               fontsize="small")  # fmt: skip
    fig.suptitle(
        f"Speed independence: one line per geometry cell (angle, offset); flagged at "
        f"{check['limit']:.0%} spread" + (f"; restitution {sets[0]}" if len(sets) == 1 else ""),
        y=1.0,
    )
    fig.tight_layout()
    return _save(fig, out_dir, "speed_ratio")


def write_figures(out_dir: Path, rows: Sequence[Row], summary: dict[str, Any]) -> list[str]:
    """Write every figure that the rows support; return the PNG names ([] without matplotlib)."""
    try:
        _pyplot()
    except ImportError:
        return []
    good = [r for r in rows if r["class"] in CLASSES]
    if not good:
        return []
    names = [dv_scatter(out_dir, good), dv_error_by_angle(out_dir, good), area_confusion(out_dir, rows),
             harm_error(out_dir, good)]  # fmt: skip
    for key in ("held_back", "held_back_first_impulse"):
        if key in summary:
            names.append(held_back(out_dir, summary, key))
    if summary.get("speed_independence", {}).get("cells"):
        names.append(speed_ratio(out_dir, summary["speed_independence"]))
    return names


__all__ = ["write_figures"]
