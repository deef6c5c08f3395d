"""The paper's evaluation over a study's runs: Fig. 5 risks, Fig. 6 harm, statistics, table.

Definitions follow the paper's reference evaluation (``analyze_risk_dist.py``,
``boxplots_risks.py``; SPEC section 8):

* **Groups.** Ego AV; 3rd party = every other road user (the vulnerable ones
  included, as in the paper: "all other road users except the AV", and as its script
  ``analyze_risk_dist.py``, which adds every obstacle's risk to the 3rd-party list and
  the VRUs' to the VRU list as well); VRU = the vulnerable subgroup, pedestrians,
  cyclists and motorcyclists (``GroupDefinition``; motorcycles can be left out with
  ``motorcycles=False``). Since VRU is a subset of 3rd party, the k-th highest VRU risk
  never exceeds the k-th highest 3rd-party risk: the paper's "VRUs carry higher risk"
  can only be judged against the *other* 3rd parties (``OTHERS``: every road user but
  the ego and the VRUs), which ``vru_against_others`` does; it is not a group of Fig. 5.
* **Fig. 5** (risk): the 100 highest risk values per group and planner over all
  scenarios, along the executed (chosen) plans. Ego: the chosen plan's ego risk per
  collision partner (R_ego,k, as the reference); 3rd party and VRU: the road users'
  risks R_k of the chosen plan. Each run keeps its 100 highest values per road-user
  type, so any grouping can be formed afterwards.
* **Fig. 6** (harm): measured harm summed over the collisions of all scenarios, per
  group and planner, apart for ego-involved collisions and collisions between other
  road users. Where we differ from the paper: our harm is the CRSS model evaluated at
  the delta-v and impact area the physics measured, not the model's harm at a
  kinematic overlap; summing over repeated contacts counts expected MAIS3+ injuries.
* **Crash attribution** (``attribution``): each run's crash is the class of its first
  ego-involved collision; "excluding" figures, tests and rates leave out the ego-involved
  collisions of runs whose crash is ``struck_from_behind_by_replay`` (a replayed
  recording, blind to the ego, drove into its rear), which say little about the planner.
* **Statistics.** Cluster bootstrap over scenarios for each figure's summary (median of
  the top 100 risks; summed harm), Wilcoxon signed-rank tests between planners on
  per-scenario maxima (risk) and sums (harm), rank-biserial effect sizes, Holm over
  the family of tests; crashes per 1000 km with exact Poisson intervals.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from itertools import combinations
from typing import Any

import numpy as np

from ethical_planner.road_users import RoadUserType
from harm_calibration.study.attribution import ATTRIBUTIONS, STRUCK_FROM_BEHIND_BY_REPLAY
from harm_calibration.study.statistics import (
    Interval,
    PairedTest,
    cluster_bootstrap,
    holm,
    paired_test,
    poisson_rate_ci,
)
from mujoco_world.loop.summary import OUTCOMES

#: Groups of the paper's Figs. 5 and 6.
GROUPS = ("ego", "third_party", "vulnerable")
#: The 3rd parties that are not VRUs (for the claim "VRUs carry higher risk"; not in the figures).
OTHERS = "other_third_party"
GROUP_LABELS = {
    "ego": "Ego AV",
    "third_party": "3rd party",
    "vulnerable": "VRU",
    OTHERS: "3rd party without VRUs",
}
#: Values per group and planner in Fig. 5.
TOP_N = 100
#: A goal reached within this time of the start [s] is counted apart in the runs table: the
#: planning problem put the ego at (or a step from) its goal region (in the shared CommonRoad
#: files 171 of 792 runs that did not fail: SinD, NGSIM US101 and highD above all).
QUICK_GOAL_S = 1.0


@dataclass(frozen=True, slots=True)
class GroupDefinition:
    """Which road-user types are vulnerable (the VRU group).

    Attributes:
        motorcycles: count motorcyclists as VRUs (the reference evaluation does).
    """

    motorcycles: bool = True

    @property
    def vulnerable(self) -> frozenset[str]:
        """Road-user type values of the VRU group."""
        kinds = {RoadUserType.PEDESTRIAN.value, RoadUserType.BICYCLE.value}
        if self.motorcycles:
            kinds.add(RoadUserType.MOTORCYCLE.value)
        return frozenset(kinds)

    def describe(self) -> str:
        """One line for reports."""
        names = "pedestrians, cyclists" + (" and motorcyclists" if self.motorcycles else "")
        return f"VRUs: {names}"


@dataclass(frozen=True, slots=True)
class BodyHarm:
    """One body's measured harm in one collision.

    Attributes:
        kind: "ego", a road-user type value, or "static" (a wall: no harm).
        harm: measured harm (probability of MAIS3+ injury).
        ego_collision: the collision involved the ego.
        avoidable: the avoidability search's verdict for the run's ego collision
            (None: not searched).
    """

    kind: str
    harm: float
    ego_collision: bool
    avoidable: bool | None = None


@dataclass(frozen=True, slots=True)
class StudyRun:
    """What the study needs of one run (read from its run record).

    Attributes:
        run_id, scenario, planner, seed, outcome, reason: the run.
        rejected: the reason key of a scenario that could not be imported, else None.
        distance: ego path length driven [m].
        duration: simulated time [s]. wall_time: [s].
        risks: highest road-user risks R_k along the chosen plans, per road-user type.
        ego_risks: highest ego risks R_ego,k, per partner type.
        ego_collided: the ego took part in a collision.
        crash: class (``attribution.ATTRIBUTIONS``) of the run's first ego-involved
            collision, None without one.
        harms: measured harm per body and collision.
        avoidable: the avoidability verdict of the run's ego collision, or None.
    """

    run_id: str
    scenario: str
    planner: str
    seed: int
    outcome: str
    reason: str
    rejected: str | None = None
    distance: float = 0.0
    duration: float = 0.0
    wall_time: float = math.nan
    risks: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    ego_risks: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    ego_collided: bool = False
    crash: str | None = None
    harms: tuple[BodyHarm, ...] = ()
    avoidable: bool | None = None

    def group_risks(self, group: str, groups: GroupDefinition) -> list[float]:
        """The run's kept risk values of ``group``."""
        if group == "ego":
            return [v for values in self.ego_risks.values() for v in values]
        return [v for k, values in self.risks.items() if _in_group(k, group, groups) for v in values]

    @property
    def struck_from_behind_by_replay(self) -> bool:
        """The run's crash is a replayed recording driving into the ego's rear."""
        return self.crash == STRUCK_FROM_BEHIND_BY_REPLAY

    def group_harm(
        self,
        group: str,
        groups: GroupDefinition,
        ego_collisions: bool | None = None,
        excluding: bool = False,
    ) -> float:
        """Summed measured harm of ``group``.

        Args:
            group, groups: which bodies count.
            ego_collisions: only ego-involved (True) or other (False) collisions; None: all.
            excluding: leave out the ego-involved collisions if the run's crash is
                ``struck_from_behind_by_replay``.
        """
        skip_ego = excluding and self.struck_from_behind_by_replay
        total = 0.0
        for body in self.harms:
            if ego_collisions is not None and body.ego_collision != ego_collisions:
                continue
            if skip_ego and body.ego_collision:
                continue
            if _in_group(body.kind, group, groups) and math.isfinite(body.harm):
                total += body.harm
        return total


def _in_group(kind: str, group: str, groups: GroupDefinition) -> bool:
    if kind == "static":
        return False
    if group == "ego":
        return kind == "ego"
    if group == "third_party":
        return kind != "ego"
    if group == OTHERS:
        return kind != "ego" and kind not in groups.vulnerable
    if group == "vulnerable":
        return kind in groups.vulnerable
    raise ValueError(f"unknown group {group!r}; allowed: {', '.join((*GROUPS, OTHERS))}")


# --------------------------------------------------------------------------- figures' data


def top_risks(runs: Iterable[StudyRun], group: str, groups: GroupDefinition, n: int = TOP_N) -> np.ndarray:
    """The ``n`` highest risk values of ``group`` over ``runs``, descending."""
    values = [v for run in runs for v in run.group_risks(group, groups)]
    return np.sort(np.asarray(values, dtype=float))[::-1][:n]


def summed_harm(
    runs: Iterable[StudyRun],
    group: str,
    groups: GroupDefinition,
    ego: bool | None = None,
    excluding: bool = False,
) -> float:
    """Measured harm of ``group`` summed over ``runs`` (``StudyRun.group_harm``'s options)."""
    return float(sum(run.group_harm(group, groups, ego, excluding) for run in runs))


@dataclass(frozen=True, slots=True)
class GroupSummary:
    """One group and planner.

    Attributes:
        top: Fig. 5's values (up to 100, descending).
        top_median: median of ``top`` with a cluster-bootstrap interval.
        harm: measured harm summed over all collisions with a bootstrap interval.
        harm_ego_collisions, harm_other_collisions: the same split by whether the
            ego took part.
        harm_avoidable, harm_unavoidable: ego-involved harm by the avoidability
            verdict (0 where no run was searched).
        harm_excluding: ``harm`` without the ego-involved collisions of runs struck
            from behind by a replay, with a bootstrap interval.
        harm_ego_collisions_excluding: ``harm_ego_collisions`` without them.
    """

    top: tuple[float, ...]
    top_median: Interval
    harm: Interval
    harm_ego_collisions: float
    harm_other_collisions: float
    harm_avoidable: float
    harm_unavoidable: float
    harm_excluding: Interval
    harm_ego_collisions_excluding: float


@dataclass(frozen=True, slots=True)
class VruAgainstOthers:
    """Fig. 5's VRU risks against those of the 3rd parties that are not VRUs, one planner.

    Attributes:
        vru, others: median of the group's ``TOP_N`` highest risks (bootstrap interval).
        difference: vru - others, with a cluster-bootstrap interval over scenarios (nan
            where a resample lacks either group).
    """

    vru: Interval
    others: Interval
    difference: Interval


@dataclass(frozen=True, slots=True)
class PlannerTable:
    """Runs, outcomes and crash rates of one planner.

    Attributes:
        runs: runs of scenarios that could be imported. outcomes: per outcome.
        rejected: runs of scenarios refused at import.
        ego_crashes: runs with an ego-involved collision.
        avoidable, unavoidable: of those, with an avoidability verdict.
        km: distance driven [km].
        crashes_per_1000km: ego-involved crashes per 1000 km with an exact interval.
        crash_classes: ego crashes per class (``attribution.ATTRIBUTIONS``, every class).
        ego_crashes_excluding: ego crashes not struck from behind by a replay.
        crashes_per_1000km_excluding: those per 1000 km with an exact interval.
        quick_goals: goal runs that ended within ``QUICK_GOAL_S`` of the start (the planning
            problem places the ego at or next to its goal region; they test little).
    """

    runs: int
    outcomes: dict[str, int]
    rejected: int
    ego_crashes: int
    avoidable: int
    unavoidable: int
    km: float
    crashes_per_1000km: Interval
    crash_classes: dict[str, int]
    ego_crashes_excluding: int
    crashes_per_1000km_excluding: Interval
    quick_goals: int = 0


@dataclass(frozen=True, slots=True)
class StudyAnalysis:
    """Everything the figures and the report show.

    Attributes:
        planners: in the study's order.
        groups: the VRU definition.
        summaries: (group, planner) -> GroupSummary.
        vru_against_others: planner -> VRU risks against the other 3rd parties'.
        risk_tests, harm_tests: group -> paired tests.
        harm_tests_excluding: the harm tests without the ego-involved collisions of runs
            struck from behind by a replay (Holm over the three families together).
        table: planner -> PlannerTable.
        scenarios: scenarios with at least one run that was not rejected.
        rejected: scenario -> rejection reason key.
        avoidability_searched: runs with an avoidability verdict.
    """

    planners: tuple[str, ...]
    groups: GroupDefinition
    summaries: dict[tuple[str, str], GroupSummary]
    vru_against_others: dict[str, VruAgainstOthers]
    risk_tests: dict[str, list[PairedTest]]
    harm_tests: dict[str, list[PairedTest]]
    harm_tests_excluding: dict[str, list[PairedTest]]
    table: dict[str, PlannerTable]
    scenarios: tuple[str, ...]
    rejected: dict[str, str]
    avoidability_searched: int


def _by_scenario(runs: Sequence[StudyRun]) -> dict[str, list[StudyRun]]:
    out: dict[str, list[StudyRun]] = defaultdict(list)
    for run in runs:
        out[run.scenario].append(run)
    return dict(out)


def _per_scenario(runs: Sequence[StudyRun], planner: str, value) -> dict[str, float]:
    """Scenario -> ``value(runs of the scenario and planner)`` (mean over seeds)."""
    per: dict[str, list[float]] = defaultdict(list)
    for run in runs:
        if run.planner == planner:
            per[run.scenario].append(value(run))
    return {s: float(np.mean(v)) for s, v in per.items()}


def analyse(
    runs: Sequence[StudyRun],
    planners: Sequence[str],
    groups: GroupDefinition | None = None,
    resamples: int = 2000,
    seed: int = 0,
) -> StudyAnalysis:
    """The study's figures' data, statistics and table from its runs.

    Runs of rejected scenarios and failed runs count in the table only; figures and
    tests use the runs that produced a result (goal, timeout, crash). Paired tests
    compare planners over the scenarios where both have such a run.
    """
    groups = groups or GroupDefinition()
    planners = tuple(planners)
    usable = [r for r in runs if r.rejected is None and r.outcome != "failed"]
    rejected = {r.scenario: r.rejected for r in runs if r.rejected is not None}
    summaries = {}
    for group in GROUPS:
        for planner in planners:
            mine = [r for r in usable if r.planner == planner]
            clusters = list(_by_scenario(mine).values())
            # Per scenario: its top values of the group (the pooled top 100 of any set of
            # scenarios lies among them) and its summed harm.
            tops = [top_risks(c, group, groups) for c in clusters]
            harms = [summed_harm(c, group, groups) for c in clusters]
            harms_excluding = [summed_harm(c, group, groups, excluding=True) for c in clusters]
            searched = [r for r in mine if r.avoidable is not None]
            summaries[(group, planner)] = GroupSummary(
                top=tuple(top_risks(mine, group, groups)),
                top_median=cluster_bootstrap(tops, _median_of_top, resamples, seed),
                harm=cluster_bootstrap(harms, _total, resamples, seed),
                harm_ego_collisions=summed_harm(mine, group, groups, ego=True),
                harm_other_collisions=summed_harm(mine, group, groups, ego=False),
                harm_avoidable=summed_harm([r for r in searched if r.avoidable], group, groups, ego=True),
                harm_unavoidable=summed_harm(
                    [r for r in searched if not r.avoidable], group, groups, ego=True
                ),
                harm_excluding=cluster_bootstrap(harms_excluding, _total, resamples, seed),
                harm_ego_collisions_excluding=summed_harm(mine, group, groups, ego=True, excluding=True),
            )
    risk_tests, harm_tests, harm_tests_excluding = _tests(usable, planners, groups)
    return StudyAnalysis(
        planners=planners,
        groups=groups,
        summaries=summaries,
        vru_against_others={
            p: _vru_against_others([r for r in usable if r.planner == p], groups, resamples, seed)
            for p in planners
        },
        risk_tests=risk_tests,
        harm_tests=harm_tests,
        harm_tests_excluding=harm_tests_excluding,
        table={p: _table([r for r in runs if r.planner == p]) for p in planners},
        scenarios=tuple(sorted({r.scenario for r in usable})),
        rejected=rejected,
        avoidability_searched=sum(1 for r in usable if r.avoidable is not None),
    )


def _vru_against_others(
    runs: Sequence[StudyRun], groups: GroupDefinition, resamples: int, seed: int
) -> VruAgainstOthers:
    """Median of the top risks of the VRUs and of the other 3rd parties, and their difference."""
    clusters = [
        (top_risks(c, "vulnerable", groups), top_risks(c, OTHERS, groups))
        for c in _by_scenario(runs).values()
    ]

    def difference(drawn):
        return _median_of_top([v for v, _ in drawn]) - _median_of_top([o for _, o in drawn])

    return VruAgainstOthers(
        vru=cluster_bootstrap([v for v, _ in clusters], _median_of_top, resamples, seed),
        others=cluster_bootstrap([o for _, o in clusters], _median_of_top, resamples, seed),
        difference=cluster_bootstrap(clusters, difference, resamples, seed),
    )


def _median_of_top(tops: Sequence[np.ndarray]) -> float:
    values = np.concatenate(tops) if len(tops) else np.zeros(0)
    if values.size == 0:
        return math.nan
    if values.size > TOP_N:
        values = np.partition(values, values.size - TOP_N)[-TOP_N:]
    return float(np.median(values))


def _total(values: Sequence[float]) -> float:
    return float(np.sum(values))


def _tests(
    runs: Sequence[StudyRun], planners: tuple[str, ...], groups: GroupDefinition
) -> tuple[dict[str, list[PairedTest]], dict[str, list[PairedTest]], dict[str, list[PairedTest]]]:
    risk_tests: dict[str, list[PairedTest]] = {}
    harm_tests: dict[str, list[PairedTest]] = {}
    harm_tests_excluding: dict[str, list[PairedTest]] = {}
    families = (risk_tests, harm_tests, harm_tests_excluding)
    for group in GROUPS:

        def max_risk(run, group=group):
            values = run.group_risks(group, groups)
            return max(values) if values else math.nan

        def harm(run, group=group):
            return run.group_harm(group, groups)

        def harm_excluding(run, group=group):
            return run.group_harm(group, groups, excluding=True)

        for family, value in zip(families, (max_risk, harm, harm_excluding), strict=True):
            family[group] = []
            per = {p: _per_scenario(runs, p, value) for p in planners}
            for a, b in combinations(planners, 2):
                common = sorted(set(per[a]) & set(per[b]))
                family[group].append(
                    paired_test(a, b, [per[a][s] for s in common], [per[b][s] for s in common])
                )
    everything = [t for family in families for tests in family.values() for t in tests]
    adjusted = iter(holm([t.p for t in everything]))
    for family in families:
        for group, tests in family.items():
            family[group] = [_with_holm(t, next(adjusted)) for t in tests]
    return risk_tests, harm_tests, harm_tests_excluding


def _with_holm(test: PairedTest, p_holm: float) -> PairedTest:
    from dataclasses import replace

    return replace(test, p_holm=p_holm)


def _table(runs: Sequence[StudyRun]) -> PlannerTable:
    imported = [r for r in runs if r.rejected is None]
    ego = [r for r in imported if r.ego_collided]
    excluding = [r for r in ego if not r.struck_from_behind_by_replay]
    km = sum(r.distance for r in imported) / 1000.0
    return PlannerTable(
        runs=len(imported),
        outcomes={o: sum(1 for r in imported if r.outcome == o) for o in OUTCOMES},
        rejected=len(runs) - len(imported),
        ego_crashes=len(ego),
        avoidable=sum(1 for r in ego if r.avoidable is True),
        unavoidable=sum(1 for r in ego if r.avoidable is False),
        km=km,
        crashes_per_1000km=poisson_rate_ci(len(ego), km, per=1000.0),
        crash_classes={c: sum(1 for r in ego if r.crash == c) for c in ATTRIBUTIONS},
        ego_crashes_excluding=len(excluding),
        crashes_per_1000km_excluding=poisson_rate_ci(len(excluding), km, per=1000.0),
        quick_goals=sum(1 for r in imported if r.outcome == "goal" and r.duration <= QUICK_GOAL_S),
    )


def to_plain_analysis(analysis: StudyAnalysis) -> dict[str, Any]:
    """JSON-able form of the analysis (``statistics.json``)."""
    from ethical_planner.records import to_plain

    return {
        "planners": list(analysis.planners),
        "vulnerable_types": sorted(analysis.groups.vulnerable),
        "scenarios": len(analysis.scenarios),
        "rejected": analysis.rejected,
        "avoidability_searched": analysis.avoidability_searched,
        "groups": {
            group: {planner: to_plain(analysis.summaries[(group, planner)]) for planner in analysis.planners}
            for group in GROUPS
        },
        "vru_against_others": {p: to_plain(c) for p, c in analysis.vru_against_others.items()},
        "risk_tests": {g: [to_plain(t) for t in tests] for g, tests in analysis.risk_tests.items()},
        "harm_tests": {g: [to_plain(t) for t in tests] for g, tests in analysis.harm_tests.items()},
        "harm_tests_excluding_struck_from_behind_by_replay": {
            g: [to_plain(t) for t in tests] for g, tests in analysis.harm_tests_excluding.items()
        },
        "table": {p: to_plain(t) for p, t in analysis.table.items()},
    }


__all__ = [
    "GROUPS",
    "GROUP_LABELS",
    "OTHERS",
    "QUICK_GOAL_S",
    "TOP_N",
    "BodyHarm",
    "GroupDefinition",
    "GroupSummary",
    "PlannerTable",
    "StudyAnalysis",
    "StudyRun",
    "VruAgainstOthers",
    "analyse",
    "summed_harm",
    "to_plain_analysis",
    "top_risks",
]
