"""Closed loop with the planner: outcomes, determinism, failures, observer hooks."""

import dataclasses
import json

import numpy as np
import pytest

from ethical_planner.planner import Planner
from mujoco_world.loop.runner import RunConfig, RunObserver, run_scenario
from mujoco_world.loop.summary import OUTCOMES
from mujoco_world.loop.world import ObservationNoise
from mujoco_world.scenario.catalog import catalog_names, generate_scenarios, get_scenario
from mujoco_world.scenario.spec import scenario_from_dict


def third_party_crash(duration=6.0):
    """Two cars meet head-on in the oncoming lane at t ~ 1.8 s; the ego drives by."""
    return scenario_from_dict(
        {
            "name": "third_party_crash",
            "road": {"length": 300.0},
            "ego": {"s0": 10.0, "speed": 10.0},
            "duration": duration,
            "road_users": [
                {
                    "name": "east",
                    "type": "car",
                    "s0": 100.0,
                    "route": {"lane": 1, "wrong_way": True},
                    "behaviour": {"kind": "scripted", "speed": 10.0},
                },
                {
                    "name": "west",
                    "type": "car",
                    "s0": 160.0,
                    "route": {"lane": 0, "direction": -1},
                    "behaviour": {"kind": "scripted", "speed": 10.0},
                },
            ],
        }
    )


def assert_json_clean(summary):
    text = json.dumps(summary.to_dict(), allow_nan=False)
    assert json.loads(text)["outcome"] == summary.outcome


def _check_run(summary):
    assert summary.outcome in ("goal", "timeout", "stopped_safely", "no_progress", "crash"), summary.reason
    assert summary.cycles > 0 and summary.steps > 0
    assert summary.tracking_rms < 0.05
    assert (summary.outcome == "crash") == bool(summary.collisions)
    for record in summary.collisions:
        a, b = record.measurement.a, record.measurement.b
        if b.entity >= 0 and not record.measurement.multi_body:
            # Newton's third law: the two bodies received opposite impulses
            np.testing.assert_allclose(
                a.impulse, -np.asarray(b.impulse), atol=1e-6 * np.hypot(*a.impulse) + 1e-9
            )
    assert set(summary.max_risk) == {"ego", "third_party", "vulnerable"}
    assert_json_clean(summary)


#: Simulated seconds of the default catalog smoke test (the full length runs with -m slow).
SMOKE_SECONDS = 3.0


@pytest.mark.parametrize("name", catalog_names())
def test_catalog_scenario_runs_to_a_defined_outcome(name):
    scenario = get_scenario(name)
    summary = run_scenario(dataclasses.replace(scenario, duration=SMOKE_SECONDS), "ethical", seed=0)
    _check_run(summary)
    assert summary.duration <= SMOKE_SECONDS


@pytest.mark.slow
@pytest.mark.parametrize("name", catalog_names())
def test_catalog_scenario_runs_to_a_defined_outcome_full_length(name):
    _check_run(run_scenario(get_scenario(name), "ethical", seed=0))


def test_same_scenario_planner_and_seed_give_the_same_summary():
    config = RunConfig(noise=ObservationNoise(position=0.2, velocity=0.2, yaw=0.02))
    # two scripted cars crash head-on at ~1.8 s while the ego plans around them
    scenario = third_party_crash(duration=3.0)
    first = run_scenario(scenario, "ethical", seed=7, config=config)
    second = run_scenario(scenario, "ethical", seed=7, config=config)
    assert first.comparable_dict() == second.comparable_dict()
    assert first.collisions  # a crash is part of what must repeat
    other = run_scenario(scenario, "ethical", seed=8, config=config)
    assert other.comparable_dict() != first.comparable_dict()


def test_third_party_crash_is_measured_and_the_run_goes_on():
    summary = run_scenario(third_party_crash(), "standard", seed=0)
    assert summary.outcome != "crash", summary.reason  # not the ego's crash
    assert summary.duration > 2.5  # the run did not stop at the others' collision (~1.8 s)
    assert not summary.ego_collided and len(summary.third_party_collisions) == 1
    (record,) = summary.collisions
    assert {record.measurement.a.name, record.measurement.b.name} == {"east", "west"}
    assert record.a.group == record.b.group == "third_party"
    # Rigid contact: Eq. 1 times (1 + e) for this head-on, e at the contact point along the normal.
    e = record.measurement.restitution
    assert 0.05 < e < 0.15
    assert record.a.dv_measured == pytest.approx(record.a.dv_predicted * (1 + e), rel=0.01)
    assert record.a.dv_planar == pytest.approx(record.a.dv_measured, rel=0.02)
    assert summary.harm["third_party"] > 0


def test_planner_exception_fails_the_run_and_keeps_the_measurements(monkeypatch):
    original = Planner.plan
    calls = {"n": 0}

    def flaky(self, ego_state, road_users, prediction=None, now=0.0):
        calls["n"] += 1
        if calls["n"] > 30:  # t = 3 s, after the third-party crash
            raise RuntimeError("planner exploded")
        return original(self, ego_state, road_users, prediction, now)

    monkeypatch.setattr(Planner, "plan", flaky)
    summary = run_scenario(third_party_crash(duration=10.0), "standard", seed=0)
    assert summary.outcome == "failed"
    assert "planner raised RuntimeError" in summary.reason and "planner exploded" in summary.reason
    assert len(summary.collisions) == 1
    assert summary.cycles == 30
    assert_json_clean(summary)


def test_diverging_state_fails_the_run():
    class Poison(RunObserver):
        step_interval = 1000

        def on_step(self, world, time):
            if time > 1.5:
                world.scene.data.qvel[0] = np.nan

    summary = run_scenario(get_scenario("red_light_runner"), "standard", observer=Poison())
    assert summary.outcome == "failed"
    assert "non-finite" in summary.reason
    assert summary.duration == pytest.approx(2.0, abs=0.02)


def test_penetration_beyond_the_bound_fails_the_run():
    summary = run_scenario(third_party_crash(), "standard", config=RunConfig(max_penetration=0.001))
    assert summary.outcome == "failed"
    assert "penetration" in summary.reason


def test_observer_sees_cycles_steps_impacts_and_the_end():
    class Counter(RunObserver):
        step_interval = 100

        def __init__(self):
            self.started = self.cycles = self.steps = 0
            self.impacts = []
            self.summary = None

        def on_start(self, world, scenario, planner, seed):
            self.started += 1
            assert planner == "standard" and seed == 3

        def on_cycle(self, plan, time):
            self.cycles += 1
            assert plan.trajectory.t[0] == 0.0 and plan.decision.planner == "standard"

        def on_step(self, world, time):
            self.steps += 1

        def on_impact(self, record):
            self.impacts.append(record)

        def on_end(self, summary):
            self.summary = summary

    counter = Counter()
    summary = run_scenario(third_party_crash(), "standard", seed=3, observer=counter)
    assert counter.started == 1
    assert counter.cycles == summary.cycles
    assert counter.steps == summary.steps // 100
    assert tuple(counter.impacts) == summary.collisions
    assert counter.summary is summary


def test_replan_rate_sets_the_number_of_cycles():
    scenario = dataclasses.replace(get_scenario("highway_cut_in"), duration=2.0)
    summary = run_scenario(scenario, "standard", config=RunConfig(replan_rate=5.0))
    assert summary.cycles == 10
    assert summary.outcome in OUTCOMES


def test_run_config_is_validated():
    with pytest.raises(ValueError, match="run.replan_rate must be > 0"):
        RunConfig(replan_rate=0.0)
    with pytest.raises(ValueError, match="noise.position must be >= 0"):
        ObservationNoise(position=-1.0)
    with pytest.raises(ValueError, match="unknown planner 'reckless'; allowed: ethical, selfish"):
        run_scenario(get_scenario("red_light_runner"), "reckless")


@pytest.mark.slow
@pytest.mark.parametrize("planner", ["ethical", "selfish", "standard"])
def test_whole_catalog_with_every_planner(planner):
    for name in catalog_names():
        summary = run_scenario(get_scenario(name), planner, seed=1)
        assert summary.outcome in ("goal", "timeout", "stopped_safely", "no_progress", "crash"), (
            name,
            summary.reason,
        )


@pytest.mark.slow
def test_random_scenarios_never_fail():
    for scenario in generate_scenarios(45, seed=2024):
        summary = run_scenario(scenario, "ethical", seed=0)
        assert summary.outcome != "failed", (scenario.name, summary.reason)
        assert_json_clean(summary)


def test_run_scenario_plans_with_the_predictor_it_is_given():
    from ethical_planner.config import PredictionConfig
    from ethical_planner.prediction import make_predictor

    class Counting:
        name = "counting"

        def __init__(self):
            self.inner = make_predictor(PredictionConfig())
            self.calls = 0

        def predict(self, road_users, times):
            self.calls += 1
            return self.inner.predict(road_users, times)

    predictor = Counting()
    summary = run_scenario(third_party_crash(duration=1.0), "ethical", predictor=predictor)
    assert summary.cycles > 0 and predictor.calls == summary.cycles
