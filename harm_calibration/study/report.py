"""``report.md``: the study's numbers and which of the paper's claims they support.

Each claim of the paper's evaluation (section "Evaluation", Figs. 5 and 6) is judged by
a stated rule on the paired tests (Holm-adjusted p < ``ALPHA``, rank-biserial effect
sizes; ``SMALL_EFFECT`` is the bound under which a difference counts as negligible):
supported, partly supported, not supported, or inconclusive (too few scenarios).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from harm_calibration.study.analysis import (
    GROUP_LABELS,
    GROUPS,
    OTHERS,
    OUTCOMES,
    QUICK_GOAL_S,
    TOP_N,
    StudyAnalysis,
)
from harm_calibration.study.attribution import ATTRIBUTIONS, STRUCK_FROM_BEHIND_BY_REPLAY
from harm_calibration.study.statistics import Interval, PairedTest

#: Significance level (after Holm's adjustment).
ALPHA = 0.05
#: |rank-biserial| below this is a negligible difference.
SMALL_EFFECT = 0.2
#: Fewer scenarios with a difference than this make a claim inconclusive.
MIN_PAIRS = 6


@dataclass(frozen=True, slots=True)
class Verdict:
    """A claim of the paper and what the study says of it.

    Attributes:
        claim: the claim in the paper's words. verdict: supported, partly supported,
            not supported or inconclusive. evidence: the numbers behind it.
    """

    claim: str
    verdict: str
    evidence: str


def _find(tests: Sequence[PairedTest], a: str, b: str) -> tuple[PairedTest | None, int]:
    """The test of a against b (sign +1) or b against a (sign -1)."""
    for t in tests:
        if (t.a, t.b) == (a, b):
            return t, 1
        if (t.a, t.b) == (b, a):
            return t, -1
    return None, 1


def _lower(test: PairedTest | None, sign: int) -> str:
    """'lower', 'higher', 'similar' or 'unclear' for the first planner against the second."""
    if test is None or test.n_nonzero < MIN_PAIRS or not math.isfinite(test.p_holm):
        return "unclear"
    effect = sign * test.rank_biserial
    if test.p_holm < ALPHA:
        return "lower" if effect < 0 else "higher"
    return "similar" if abs(effect) < SMALL_EFFECT else "unclear"


def _describe(test: PairedTest | None, sign: int, a: str, b: str) -> str:
    if test is None or test.n == 0:
        return f"{a} vs {b}: no scenario with a value for both"
    if test.n_nonzero == 0:
        return f"{a} vs {b}: equal in all {test.n} scenarios"
    return (
        f"{a} vs {b}: r = {sign * test.rank_biserial:+.2f}, p(Holm) = {test.p_holm:.3g}, "
        f"n = {test.n} ({test.n_nonzero} differ)"
    )


def _against_standard(tests: Mapping[str, Sequence[PairedTest]]) -> tuple[list[str], list[str]]:
    """Ethical and selfish against standard in every group: the looks and the evidence lines."""
    looks, lines = [], []
    for group in GROUPS:
        for planner in ("ethical", "selfish"):
            test, sign = _find(tests[group], planner, "standard")
            looks.append(_lower(test, sign))
            lines.append(f"{GROUP_LABELS[group]}, {_describe(test, sign, planner, 'standard')}")
    return looks, lines


def judge(analysis: StudyAnalysis) -> list[Verdict]:
    """The paper's claims with the study's verdicts (needs planners ethical, selfish, standard)."""
    needed = {"ethical", "selfish", "standard"}
    if not needed <= set(analysis.planners):
        return [
            Verdict(
                "the paper's claims compare ethical, selfish and standard",
                "inconclusive",
                f"this study ran {', '.join(analysis.planners)}",
            )
        ]
    risk = analysis.risk_tests
    verdicts = []
    # 1. Considering risk lowers risk for all groups.
    looks, lines = _against_standard(risk)
    verdicts.append(
        Verdict(
            "Considering risk in planning (ethical, selfish) lowers the risk of every group "
            "compared with the standard planner (Fig. 5).",
            _tally(looks, "lower"),
            "; ".join(lines),
        )
    )
    # 2. Ethical vs selfish: ego risk similar.
    test, sign = _find(risk["ego"], "ethical", "selfish")
    look = _lower(test, sign)
    verdicts.append(
        Verdict(
            "The ethical planner keeps the ego's risk similar to the selfish planner's (Fig. 5).",
            {"similar": "supported", "unclear": "inconclusive"}.get(look, "not supported"),
            _describe(test, sign, "ethical", "selfish")
            + f" (similar: p(Holm) >= {ALPHA} and |r| < {SMALL_EFFECT})",
        )
    )
    # 3. Ethical vs selfish: third-party and especially VRU risks lower.
    third, s3 = _find(risk["third_party"], "ethical", "selfish")
    vru, sv = _find(risk["vulnerable"], "ethical", "selfish")
    looks = [_lower(third, s3), _lower(vru, sv)]
    verdict = _tally(looks, "lower")
    if verdict == "supported" and abs(vru.rank_biserial) < abs(third.rank_biserial):
        verdict = "partly supported"
    verdicts.append(
        Verdict(
            "The ethical planner lowers the risk of 3rd parties, and especially of VRUs, "
            "compared with the selfish planner (Fig. 5).",
            verdict,
            f"3rd party, {_describe(third, s3, 'ethical', 'selfish')}; "
            f"VRU, {_describe(vru, sv, 'ethical', 'selfish')}"
            " (especially: the VRU effect at least the 3rd-party effect)",
        )
    )
    # 4. VRUs carry higher risk than the other 3rd parties. VRU is a subset of 3rd party
    # (the paper's groups), so its top values can never exceed the 3rd party's: the claim
    # compares the VRUs with the 3rd parties that are not VRUs.
    looks = [_higher(analysis.vru_against_others[p].difference) for p in analysis.planners]
    verdicts.append(
        Verdict(
            "VRUs carry higher risk than the other road users, for every planner (Fig. 5: "
            '"the VRUs have to carry higher risk").',
            _tally(looks, "higher"),
            ", ".join(
                f"{p}: VRU {c.vru.text(3)} vs 3rd party without VRUs {c.others.text(3)}, "
                f"difference {c.difference.text(3)}"
                for p, c in analysis.vru_against_others.items()
            )
            + f" (median of the top {TOP_N}, bootstrap 95 % interval over scenarios; higher: the "
            "difference's interval above 0. 3rd party as in the paper includes the VRUs, so VRU "
            "against 3rd party as a whole cannot come out higher)",
        )
    )
    # 5. The accidents confirm the risks: standard causes the most harm. Judged on all
    # crashes and again without the runs a replayed recording drove into from behind.
    for tests, which in (
        (analysis.harm_tests, "all crashes"),
        (analysis.harm_tests_excluding, "excluding crashes struck from behind by a replay"),
    ):
        looks, lines = _against_standard(tests)
        verdicts.append(
            Verdict(
                "The simulated accidents confirm the risk distribution: considering risk lowers the "
                f"harm of every group (Fig. 6; {which}).",
                _tally(looks, "lower"),
                "; ".join(lines) + " (per-scenario summed measured harm)",
            )
        )
    return verdicts


def _higher(difference: Interval) -> str:
    """'higher' or 'lower' where the interval of a difference excludes 0, else 'unclear'."""
    if not (math.isfinite(difference.low) and math.isfinite(difference.high)):
        return "unclear"
    if difference.low > 0:
        return "higher"
    return "lower" if difference.high < 0 else "unclear"


def _tally(looks: Sequence[str], wanted: str) -> str:
    if all(v == "unclear" for v in looks):
        return "inconclusive"
    if all(v == wanted for v in looks):
        return "supported"
    if any(v == wanted for v in looks):
        return "partly supported"
    return "not supported"


def _families(analysis: StudyAnalysis) -> tuple[dict[str, list[PairedTest]], ...]:
    return (analysis.risk_tests, analysis.harm_tests, analysis.harm_tests_excluding)


def _fmt_p(p: float) -> str:
    return "-" if not math.isfinite(p) else f"{p:.3g}"


def _runs_section(analysis: StudyAnalysis, rejected_by_reason: dict[str, list[str]]) -> list[str]:
    """The table of runs, outcomes and crash rates, the crash attribution and the refusals."""
    out: list[str] = []
    out += ["", "## Runs, outcomes, crashes", ""]
    out += [
        "| planner | runs | "
        + " | ".join(OUTCOMES)
        + " | ego crashes | avoidable | unavoidable | km | ego crashes per 1000 km (95 %) "
        "| ego crashes excl. struck from behind by a replay | per 1000 km (95 %) |",
        "| --- |" + " --- |" * (len(OUTCOMES) + 8),
    ]
    for p, t in analysis.table.items():
        o = t.outcomes
        out.append(
            f"| {p} | {t.runs} | " + " | ".join(str(o[name]) for name in OUTCOMES) + f" | {t.ego_crashes} | "
            f"{t.avoidable} | {t.unavoidable} | {t.km:.1f} | {t.crashes_per_1000km.text(3)} | "
            f"{t.ego_crashes_excluding} | {t.crashes_per_1000km_excluding.text(3)} |"
        )
    quick = ", ".join(f"{p} {t.quick_goals}" for p, t in analysis.table.items())
    out += [
        "",
        "`left_map`: the ego's centre left an imported map beyond its end along its route (it missed "
        "its goal region, or had none) before any crash; the run ends there, as a recorded road user "
        "leaves where its recording ends, and its distance and risks count up to that moment.",
    ]
    out += [
        "",
        f"Goals reached within {QUICK_GOAL_S:g} s of the start (the planning problem places the ego "
        f"at or next to its goal region, so the run tests little; counted in `goal` above): {quick}.",
        "",
        "Crash attribution: each run's crash is classified by its first ego-involved collision, from "
        "the record (the bodies' approach speeds to the contact point, where the ego was hit, and "
        "whether the other body replays a recording, blind to the ego):",
        "",
        "| class | what | " + " | ".join(analysis.planners) + " |",
        "| --- | --- |" + " --- |" * len(analysis.planners),
    ]
    for name, what in ATTRIBUTIONS.items():
        cells = [str(analysis.table[p].crash_classes.get(name, 0)) for p in analysis.planners]
        out.append(f"| `{name}` | {what} | " + " | ".join(cells) + " |")
    if rejected_by_reason:
        out += ["", "Scenarios refused at import (not counted above), by reason:", ""]
        for reason, files in sorted(rejected_by_reason.items()):
            out.append(f"- {reason}: {len(files)}")
            out += [f"  - {f}" for f in sorted(files)]
    return out


def render(
    analysis: StudyAnalysis,
    spec_lines: Sequence[str],
    speed_lines: Sequence[str],
    rejected_by_reason: dict[str, list[str]],
    notes: Sequence[str] = (),
) -> str:
    """The whole ``report.md``."""
    out = ["# Study report", "", *spec_lines, ""]
    out += ["## Claims of the paper", ""]
    out += ["| claim | verdict | evidence |", "| --- | --- | --- |"]
    for v in judge(analysis):
        out.append(f"| {v.claim} | **{v.verdict}** | {v.evidence} |")
    out += [
        "",
        f"Rule: a difference counts where Holm-adjusted p < {ALPHA} over all "
        f"{sum(len(t) for f in _families(analysis) for t in f.values())} paired tests "
        f"(Wilcoxon signed-rank on per-scenario maxima of risk and sums of harm, the latter with all "
        "crashes and excluding those struck from behind by a replay); 'similar' needs "
        f"p >= {ALPHA} and |rank-biserial r| < {SMALL_EFFECT}; fewer than {MIN_PAIRS} scenarios "
        "that differ is inconclusive. r < 0: the first planner is lower.",
        "",
    ]
    out += ["## Fig. 5: risk", "", "![Fig. 5](fig5_risks.png)", ""]
    out += [
        f"Median of the {TOP_N} highest risks (cluster bootstrap 95 % interval over scenarios):",
        "",
        "| group | " + " | ".join(analysis.planners) + " |",
        "| --- |" + " --- |" * len(analysis.planners),
    ]
    for group in GROUPS:
        cells = [analysis.summaries[(group, p)].top_median.text(3) for p in analysis.planners]
        out.append(f"| {GROUP_LABELS[group]} | " + " | ".join(cells) + " |")
    cells = [analysis.vru_against_others[p].others.text(3) for p in analysis.planners]
    out.append(f"| ({GROUP_LABELS[OTHERS]}) | " + " | ".join(cells) + " |")
    out += [
        "",
        "Groups as in the paper and its reference scripts: 3rd party is every road user but the "
        "ego, the VRUs included; VRU is their vulnerable subgroup. Where the highest 3rd-party "
        "risks all belong to VRUs the two rows are equal. The last row (not a group of Fig. 5) "
        'is the 3rd parties without the VRUs, which the claim "VRUs carry higher risk" is '
        "judged against.",
    ]
    out += ["", "## Fig. 6: harm", "", "![Fig. 6](fig6_harm.png)", ""]
    out += [
        "Summed measured harm (expected MAIS3+ injuries; 95 % interval), its split by whether "
        "the ego was in the collision, and the same without the ego collisions of runs a replayed "
        f"recording drove into from behind (`{STRUCK_FROM_BEHIND_BY_REPLAY}`, the right panel of "
        "Fig. 6; see the crash attribution below):",
        "",
        "| group | planner | total | ego collisions | other collisions | avoidable | unavoidable "
        "| total excl. struck from behind by a replay | ego collisions excl. |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for group in GROUPS:
        for p in analysis.planners:
            s = analysis.summaries[(group, p)]
            out.append(
                f"| {GROUP_LABELS[group]} | {p} | {s.harm.text(3)} | {s.harm_ego_collisions:.3f} | "
                f"{s.harm_other_collisions:.3f} | {s.harm_avoidable:.3f} | {s.harm_unavoidable:.3f} | "
                f"{s.harm_excluding.text(3)} | {s.harm_ego_collisions_excluding:.3f} |"
            )
    if analysis.avoidability_searched == 0:
        out += ["", "The avoidability search has not run on these runs: no crash is marked avoidable."]
    out += ["", "## Paired tests", ""]
    out += [
        "| family | group | a | b | n | differ | median a - b | r (rank-biserial) | p | p (Holm) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for family, tests in zip(("max risk", "harm", "harm excl."), _families(analysis), strict=True):
        for group in GROUPS:
            for t in tests[group]:
                out.append(
                    f"| {family} | {GROUP_LABELS[group]} | {t.a} | {t.b} | {t.n} | {t.n_nonzero} | "
                    f"{t.median_difference:.3g} | {t.rank_biserial:+.2f} | {_fmt_p(t.p)} | "
                    f"{_fmt_p(t.p_holm)} |"
                )
    out += _runs_section(analysis, rejected_by_reason)
    out += ["", "## Speed", "", *speed_lines, ""]
    out += ["## Where this study differs from the paper's", "", *notes, ""]
    return "\n".join(out)


__all__ = ["ALPHA", "MIN_PAIRS", "SMALL_EFFECT", "Verdict", "judge", "render"]
