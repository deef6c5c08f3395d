"""Scenario-level regressions of the ethical principles (issue 9, the catalog part).

Each test runs a catalog scenario that separates two planner configurations in
closed loop (seed 0) and checks the effect the principle must have: a true dilemma
(every candidate collides) in which the ethical planner shifts the harm away from the
vulnerable road users and the selfish one does not.
"""

import dataclasses

import pytest

from ethical_planner.road_users import VULNERABLE_TYPES, RoadUserType
from ethical_planner.validity import UNASSESSED, Validity
from mujoco_world.loop.runner import RunObserver, run_scenario
from mujoco_world.scenario.catalog import get_scenario


class _Cycles(RunObserver):
    """Keeps each planning cycle's time and decision."""

    def __init__(self):
        self.cycles = []

    def on_cycle(self, plan, time):
        self.cycles.append((time, plan.decision))


def _run(name, planner, duration):
    cycles = _Cycles()
    scenario = dataclasses.replace(get_scenario(name), duration=duration)
    summary = run_scenario(scenario, planner, seed=0, observer=cycles)
    assert summary.outcome != "failed", summary.reason
    return summary, cycles.cycles


def _ego_hits(summary):
    """(partner body, its BodyComparison) of every ego-involved collision."""
    return [(c.measurement.b, c.b) for c in summary.collisions if c.involves_ego]


def _vulnerable_harm(summary, which):
    """Summed harm of the vulnerable road users the ego hit ("measured" or "predicted")."""
    return sum(
        getattr(body, f"harm_{which}")
        for partner, body in _ego_hits(summary)
        if RoadUserType(partner.type) in VULNERABLE_TYPES
    )


#: dilemma_pedestrian_car: the pedestrians run out at ~1.4 s, the ego hits at ~1.9 s.
DILEMMA_SECONDS = 2.6


@pytest.fixture(scope="module")
def dilemma():
    return {
        planner: _run("dilemma_pedestrian_car", planner, DILEMMA_SECONDS)
        for planner in ("ethical", "selfish")
    }


@pytest.mark.parametrize("planner", ["ethical", "selfish"])
def test_dilemma_is_true_every_candidate_collides(dilemma, planner):
    """From the cycle the pedestrians are seen running until the impact, no candidate
    of either planner is collision-free: every one is predicted to collide (level 1)
    or breaks a physical limit (level 0), hard stops included."""
    summary, cycles = dilemma[planner]
    first_hit = min(c.measurement.time for c in summary.collisions if c.involves_ego)
    dilemma_cycles = [d for t, d in cycles if d.level == Validity.COLLISION and t < first_hit]
    assert len(dilemma_cycles) >= 3
    start = next(t for t, d in cycles if d.level == Validity.COLLISION)
    for t, decision in cycles:
        if start <= t < first_hit:
            levels = set(decision.level_counts)
            if decision.level == Validity.COLLISION:
                # At a fallback level the branch and bound leaves out candidates of that
                # level only (``Decision.level_counts``): they collide too.
                levels = {decision.level if v == UNASSESSED else v for v in levels}
            assert levels <= {Validity.PHYSICALLY_INVALID, Validity.COLLISION}, (t, decision.level_counts)


def test_dilemma_ethical_shifts_harm_from_the_pedestrians_to_a_car(dilemma):
    """The ethical planner swerves towards the car pulling out (it hits the child
    slower, then the car); the selfish planner protects its occupant, stays in its
    lane and hits both pedestrians at almost full speed."""
    ethical, _ = dilemma["ethical"]
    selfish, _ = dilemma["selfish"]
    ethical_partners = {RoadUserType(p.type) for p, _ in _ego_hits(ethical)}
    selfish_partners = {RoadUserType(p.type) for p, _ in _ego_hits(selfish)}
    assert RoadUserType.CAR in ethical_partners
    assert RoadUserType.CAR not in selfish_partners
    # Measured (physics) and predicted (Eq. 1 + CRSS at the measured pre-impact state):
    # ethical 0.38 / 0.54 (the child only), selfish 1.30 / 1.20 (child and parent).
    for which in ("measured", "predicted"):
        assert _vulnerable_harm(ethical, which) < 0.6 * _vulnerable_harm(selfish, which), which
    assert ethical.max_risk["vulnerable"] < selfish.max_risk["vulnerable"]


#: red_light_runner: the ego sees the runner from ~1.8 s; the presets part at 3.8 s.
RESPONSIBILITY_SECONDS = 4.6


def _max_planned_risk(cycles, user_id):
    return max((u.risk for _, d in cycles for u in d.road_users if u.id == user_id), default=0.0)


def test_responsibility_shifts_risk_onto_the_red_light_runner():
    """red_light_runner: the runner violates its red light, so ethical_responsible
    counts it responsible (r = 0.5 + its mass share) and discounts its risk in J_B
    (Eq. 11 with rho = 0.5). At 3.8 s it keeps more speed than ethical behind the
    runner; the runner bears more of the risk, the law-abiding car on the cross road
    no more than before. (Measured: planned risk to the runner 5e-5 against 3e-5.)"""
    ethical_summary, ethical = _run("red_light_runner", "ethical", RESPONSIBILITY_SECONDS)
    responsible_summary, responsible = _run("red_light_runner", "ethical_responsible", RESPONSIBILITY_SECONDS)
    runner, obeying = 1, 2  # road users in scenario order, after the ego
    assert any(u.id == runner and u.responsibility >= 0.5 for _, d in responsible for u in d.road_users)
    differ = [
        (t, a, b)
        for (t, a), (_, b) in zip(ethical, responsible, strict=False)
        if a.candidate.describe() != b.candidate.describe()
    ]
    assert differ, "responsibility changed no decision"
    _, first_ethical, first_responsible = differ[0]
    assert first_responsible.trajectory.v[-1] > first_ethical.trajectory.v[-1]
    assert _max_planned_risk(responsible, runner) > 1.3 * _max_planned_risk(ethical, runner)
    assert _max_planned_risk(responsible, obeying) <= _max_planned_risk(ethical, obeying) + 1e-9
    assert responsible_summary.max_risk["third_party"] > ethical_summary.max_risk["third_party"]


#: overtake_cyclist: the ego reaches the cyclist at ~4 s.
MAX_RISK_SECONDS = 4.5


def _without_max_risk(name):
    from ethical_planner.config import preset

    return preset(name).with_overrides({"risk": {"max_acceptable_risk": 1.0}})


def test_max_acceptable_risk_keeps_the_standard_planner_behind_the_cyclist():
    """overtake_cyclist with the standard planner (w_risk = 0: R_max is its only risk
    principle). Eq. 5 (comfort and mobility) prefers passing the cyclist at speed;
    R_max refuses those candidates every cycle and the ego slows behind the cyclist.
    With R_max disabled the same planner passes it at full speed, 0.4 m away."""
    with_max, cycles = _run("overtake_cyclist", "standard", MAX_RISK_SECONDS)
    without_max, free_cycles = _run("overtake_cyclist", _without_max_risk("standard"), MAX_RISK_SECONDS)
    refused = [d for _, d in cycles if d.level == Validity.VALID and d.max_risk_refused > 0]
    assert len(refused) >= 0.8 * len(cycles)
    assert free_cycles  # R_max = 1: nothing is above it, the ego drives on Eq. 5 alone
    assert with_max.clearance_vulnerable["cyclist"] > 2.0
    assert without_max.clearance_vulnerable["cyclist"] < 0.6
    assert with_max.max_risk["vulnerable"] <= 1.05 * 0.002 < 0.05 < without_max.max_risk["vulnerable"]


def test_max_acceptable_risk_does_not_decide_for_the_ethical_planner_in_overtake_cyclist():
    """With w_risk = 1000, Eq. 5 already prices every candidate above R_max above the
    chosen plan, so R_max refuses nothing (README, "R_max in overtake_cyclist")."""
    _, cycles = _run("overtake_cyclist", "ethical", MAX_RISK_SECONDS)
    assert all(d.max_risk_refused == 0 for _, d in cycles)
    assert any(d.level_counts.get(Validity.ABOVE_MAX_RISK, 0) > 0 for _, d in cycles)
