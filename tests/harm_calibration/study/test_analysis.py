"""The study's analysis on hand-made runs: groups, pairing by scenario, harm split, verdicts."""

import pytest

from harm_calibration.study.analysis import BodyHarm, GroupDefinition, StudyRun, analyse, top_risks
from harm_calibration.study.report import judge


def _run(scenario, planner, risk=0.1, ego=0.01, moto=0.0, harms=(), distance=100.0):
    risks = {"car": (risk,), "pedestrian": (risk * 2,)}
    if moto:
        risks["motorcycle"] = (moto,)
    return StudyRun(
        run_id=f"{scenario}__{planner}__s0",
        scenario=scenario,
        planner=planner,
        seed=0,
        outcome="crash" if harms else "goal",
        reason="",
        distance=distance,
        risks=risks,
        ego_risks={"car": (ego,)},
        ego_collided=any(h.ego_collision for h in harms),
        harms=tuple(harms),
    )


def test_motorcyclists_are_vrus_only_when_asked():
    run = _run("a", "ethical", risk=0.1, moto=0.9)
    with_moto, without = GroupDefinition(True), GroupDefinition(False)
    assert top_risks([run], "vulnerable", with_moto).tolist() == [0.9, 0.2]
    assert top_risks([run], "vulnerable", without).tolist() == [0.2]
    # 3rd party: every road user but the ego, the VRUs included (the paper's definition).
    assert top_risks([run], "third_party", without).tolist() == [0.9, 0.2, 0.1]
    assert top_risks([run], "ego", without).tolist() == [0.01]


def test_top_100_pools_all_scenarios_and_keeps_the_highest():
    runs = [_run(f"s{k}", "ethical", risk=k / 1000) for k in range(150)]
    top = top_risks(runs, "third_party", GroupDefinition())
    every = sorted([k / 1000 for k in range(150)] + [k / 500 for k in range(150)], reverse=True)
    assert top.tolist() == pytest.approx(every[:100])


def test_paired_tests_pair_by_scenario_and_the_claims_follow():
    runs = []
    for k in range(12):  # ethical and selfish lower than standard in every scenario, by distinct amounts
        scenario = f"s{k}"
        runs += [
            _run(scenario, "standard", risk=0.5 + k / 100, ego=0.05 + k / 1000),
            _run(scenario, "ethical", risk=0.2 + k / 200, ego=0.02 + k / 1500),
            _run(scenario, "selfish", risk=0.3 + k / 150, ego=0.02 + k / 1400),
        ]
    runs.reverse()  # order of the runs must not matter, only the scenario
    analysis = analyse(runs, ["ethical", "selfish", "standard"], resamples=200)
    test = next(t for t in analysis.risk_tests["third_party"] if (t.a, t.b) == ("ethical", "standard"))
    assert test.n == 12 and test.n_nonzero == 12
    assert test.rank_biserial == pytest.approx(-1.0)
    assert test.p == pytest.approx(2 / 2**12)  # exact: only the all-negative sign pattern and its mirror
    verdicts = {v.claim.split(" (")[0]: v.verdict for v in judge(analysis)}
    first = next(k for k in verdicts if k.startswith("Considering risk"))
    assert verdicts[first] == "supported"


def test_harm_is_split_by_ego_involvement_and_walls_carry_none():
    harms = (
        BodyHarm("ego", 0.3, True),
        BodyHarm("pedestrian", 0.6, True),
        BodyHarm("car", 0.2, False),
        BodyHarm("bicycle", 0.1, False),
        BodyHarm("static", float("nan"), True),
    )
    analysis = analyse([_run("a", "ethical", harms=harms)], ["ethical"], resamples=200)
    vru = analysis.summaries[("vulnerable", "ethical")]
    third = analysis.summaries[("third_party", "ethical")]
    ego = analysis.summaries[("ego", "ethical")]
    assert (vru.harm_ego_collisions, vru.harm_other_collisions) == pytest.approx((0.6, 0.1))
    assert (third.harm_ego_collisions, third.harm_other_collisions) == pytest.approx((0.6, 0.3))
    assert ego.harm.value == pytest.approx(0.3)
    table = analysis.table["ethical"]
    assert table.ego_crashes == 1 and table.km == pytest.approx(0.1)
    assert table.crashes_per_1000km.value == pytest.approx(10_000.0)


def _typed_run(scenario, planner, pedestrian, car, n=20):
    """A run that kept ``n`` risk values of each type (more than TOP_N over a few scenarios)."""
    risks = {"car": (car,) * n}
    if pedestrian is not None:
        risks["pedestrian"] = (pedestrian,) * n
    return StudyRun(
        run_id=f"{scenario}__{planner}__s0",
        scenario=scenario,
        planner=planner,
        seed=0,
        outcome="goal",
        reason="",
        distance=100.0,
        risks=risks,
        ego_risks={"car": (0.01,)},
    )


def _claim(analysis, start):
    return next(v for v in judge(analysis) if v.claim.startswith(start))


def test_vrus_are_judged_against_the_other_third_parties_not_against_a_superset():
    # 8 scenarios x 20 pedestrian values of 0.4 and 20 car values of 0.1 per run (one scenario
    # without pedestrians): the 100 highest 3rd-party risks are all pedestrians', so 3rd party
    # and VRU have the same median (0.4) and a VRU-vs-3rd-party comparison can never say
    # "higher". By hand: VRU median 0.4, non-VRU 3rd parties 0.1, difference +0.3 in every
    # bootstrap resample -> "higher" for each planner -> supported.
    planners = ["ethical", "selfish", "standard"]
    runs = [_typed_run(f"s{k}", p, None if k == 7 else 0.4, 0.1) for k in range(8) for p in planners]
    analysis = analyse(runs, planners, resamples=200)
    for p in planners:
        assert analysis.summaries[("third_party", p)].top_median.value == pytest.approx(0.4)
        assert analysis.summaries[("vulnerable", p)].top_median.value == pytest.approx(0.4)
        c = analysis.vru_against_others[p]
        assert (c.vru.value, c.others.value) == pytest.approx((0.4, 0.1))
        assert (c.difference.value, c.difference.low, c.difference.high) == pytest.approx((0.3, 0.3, 0.3))
    claim = _claim(analysis, "VRUs carry higher risk")
    assert claim.verdict == "supported"
    assert "3rd party without VRUs 0.1" in claim.evidence

    # Standard's cars carry 0.5 > 0.4: by hand, difference -0.1 there -> "lower" for one
    # planner of three -> partly supported; every planner lower -> not supported.
    runs = [_typed_run(f"s{k}", p, 0.4, 0.5 if p == "standard" else 0.1) for k in range(8) for p in planners]
    analysis = analyse(runs, planners, resamples=200)
    assert analysis.vru_against_others["standard"].difference.value == pytest.approx(-0.1)
    assert _claim(analysis, "VRUs carry higher risk").verdict == "partly supported"
    runs = [_typed_run(f"s{k}", p, 0.4, 0.5) for k in range(8) for p in planners]
    assert _claim(analyse(runs, planners, resamples=200), "VRUs carry higher risk").verdict == "not supported"

    # No VRU in any scenario: nothing to compare.
    runs = [_typed_run(f"s{k}", p, None, 0.5) for k in range(8) for p in planners]
    assert _claim(analyse(runs, planners, resamples=200), "VRUs carry higher risk").verdict == "inconclusive"


def test_an_unknown_group_is_refused():
    with pytest.raises(ValueError, match="unknown group 'cyclists'; allowed: ego, third_party"):
        top_risks([_run("a", "ethical")], "cyclists", GroupDefinition())


def test_goals_within_a_second_are_counted_apart_in_the_table_and_the_report():
    from dataclasses import replace

    from harm_calibration.study.report import render

    # 0.1 s and exactly 1.0 s count (the SinD egos that start at their goal region's edge);
    # 1.1 s and a crash at 0.5 s do not.
    runs = [
        replace(_run("a", "ethical"), duration=0.1),
        replace(_run("b", "ethical"), duration=1.0),
        replace(_run("c", "ethical"), duration=1.1),
        replace(_run("d", "ethical", harms=(BodyHarm("ego", 0.1, True),)), duration=0.5),
    ]
    analysis = analyse(runs, ["ethical"], resamples=50)
    assert analysis.table["ethical"].quick_goals == 2
    assert analysis.table["ethical"].outcomes["goal"] == 3
    report = render(analysis, [], [], {})
    assert "Goals reached within 1 s of the start" in report and "ethical 2." in report
