"""The study's figures (PNG and PDF): the paper's Fig. 5 (risks) and Fig. 6 (harm)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from harm_calibration.study.analysis import GROUP_LABELS, GROUPS, TOP_N, StudyAnalysis

#: Colour per planner (others cycle through the rest).
PLANNER_COLORS = {"ethical": "#2a9d8f", "selfish": "#e9c46a", "standard": "#8d99ae"}
_CYCLE = ("#e76f51", "#264653", "#f4a261", "#6d597a")


def _color(planner: str, index: int) -> str:
    return PLANNER_COLORS.get(planner, _CYCLE[index % len(_CYCLE)])


def _save(fig, out: Path, stem: str) -> list[Path]:
    paths = []
    for suffix in (".png", ".pdf"):
        path = out / f"{stem}{suffix}"
        fig.savefig(path, dpi=150, bbox_inches="tight")
        paths.append(path)
    return paths


def figure_risks(analysis: StudyAnalysis, out: Path) -> list[Path]:
    """Fig. 5: box plots of the 100 highest risks per group and planner (log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    planners = analysis.planners
    fig, ax = plt.subplots(figsize=(8.0, 4.6))
    width = 0.8 / max(len(planners), 1)
    positive = [v for s in analysis.summaries.values() for v in s.top if v > 0]
    floor = min(positive) / 2 if positive else 1e-6
    for k, planner in enumerate(planners):
        data, places = [], []
        for g, group in enumerate(GROUPS):
            values = np.asarray(analysis.summaries[(group, planner)].top, dtype=float)
            data.append(np.maximum(values, floor) if values.size else np.array([np.nan]))
            places.append(g + (k - (len(planners) - 1) / 2) * width)
        parts = ax.boxplot(
            data,
            positions=places,
            widths=width * 0.85,
            patch_artist=True,
            showfliers=True,
            flierprops={"markersize": 3, "alpha": 0.5},
            medianprops={"color": "black"},
        )
        for box in parts["boxes"]:
            box.set_facecolor(_color(planner, k))
        ax.plot([], [], "s", color=_color(planner, k), markersize=10, label=planner)
    ax.set_yscale("log")
    ax.set_xticks(range(len(GROUPS)), [GROUP_LABELS[g] for g in GROUPS], fontsize=11)
    ax.set_ylabel(f"risk (the {TOP_N} highest values per group)", fontsize=11)
    ax.set_title(
        f"Fig. 5: risk along the executed plans, {len(analysis.scenarios)} scenarios "
        f"({analysis.groups.describe()})",
        fontsize=11,
    )
    ax.grid(axis="y", which="major", alpha=0.3)
    ax.legend(title="planner", fontsize=10)
    paths = _save(fig, out, "fig5_risks")
    plt.close(fig)
    return paths


def figure_harm(analysis: StudyAnalysis, out: Path) -> list[Path]:
    """Fig. 6: measured harm summed over the scenarios per group and planner, two panels.

    Left, all crashes; right, without the ego-involved collisions of runs a replayed
    recording drove into from behind (``attribution.STRUCK_FROM_BEHIND_BY_REPLAY``).
    Each bar stacks harm from ego-involved collisions (left: split into avoidable and
    unavoidable where the avoidability search has run) and from collisions between
    other road users (hatched); the whisker is the cluster-bootstrap interval of the
    total.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12.0, 4.6), sharey=True)
    _harm_panel(axes[0], analysis, excluding=False)
    _harm_panel(axes[1], analysis, excluding=True)
    axes[0].set_title("all crashes", fontsize=11)
    axes[1].set_title("excluding crashes struck from behind by a replay", fontsize=11)
    axes[0].set_ylabel("summed measured harm\n(expected MAIS3+ injuries)", fontsize=11)
    # Below the panels: inside, the legend covered the tallest whiskers.
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=len(labels), fontsize=9)
    fig.suptitle(f"Fig. 6: harm of the collisions in {len(analysis.scenarios)} scenarios", fontsize=12)
    paths = _save(fig, out, "fig6_harm")
    plt.close(fig)
    return paths


def _harm_panel(ax, analysis: StudyAnalysis, excluding: bool) -> None:
    planners = analysis.planners
    width = 0.8 / max(len(planners), 1)
    searched = analysis.avoidability_searched > 0 and not excluding
    for k, planner in enumerate(planners):
        color = _color(planner, k)
        for g, group in enumerate(GROUPS):
            s = analysis.summaries[(group, planner)]
            x = g + (k - (len(planners) - 1) / 2) * width
            bottom = 0.0
            if excluding:
                pieces = [(s.harm_ego_collisions_excluding, color, None)]
            elif searched:
                not_searched = max(s.harm_ego_collisions - s.harm_avoidable - s.harm_unavoidable, 0.0)
                pieces = [
                    (s.harm_unavoidable, color, None),
                    (s.harm_avoidable, color, "xx"),
                    (not_searched, color, ".."),
                ]
            else:
                pieces = [(s.harm_ego_collisions, color, None)]
            pieces.append((s.harm_other_collisions, "white", "//"))
            for height, face, hatch in pieces:
                if height > 0:
                    ax.bar(x, height, width * 0.9, bottom=bottom, color=face, hatch=hatch, edgecolor=color)
                    bottom += height
            interval = s.harm_excluding if excluding else s.harm
            if np.isfinite(interval.low):
                ax.errorbar(
                    x,
                    interval.value,
                    yerr=[[interval.value - interval.low], [interval.high - interval.value]],
                    color="black",
                    capsize=3,
                    linewidth=1,
                )
        ax.bar(np.nan, 0, color=color, label=planner)
    ax.bar(np.nan, 0, color="white", hatch="//", edgecolor="grey", label="collisions without the ego")
    if searched:
        ax.bar(np.nan, 0, color="white", hatch="xx", edgecolor="grey", label="avoidable (ego collisions)")
        ax.bar(np.nan, 0, color="white", hatch="..", edgecolor="grey", label="not searched")
    ax.set_xticks(range(len(GROUPS)), [GROUP_LABELS[g] for g in GROUPS], fontsize=11)
    ax.grid(axis="y", alpha=0.3)


__all__ = ["PLANNER_COLORS", "figure_harm", "figure_risks"]
