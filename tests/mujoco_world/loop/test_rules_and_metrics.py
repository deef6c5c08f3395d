"""Stop rules and metrics: each rule and metric alone, and new ones plugged into a run."""

from __future__ import annotations

import ast
import dataclasses
import inspect
import math
from types import SimpleNamespace

import numpy as np
import pytest

from ethical_planner.road_users import RoadUserType
from mujoco_world.loop import runner as runner_module
from mujoco_world.loop.config import RunConfig
from mujoco_world.loop.metrics import (
    TOP_RISKS,
    HarmPerGroup,
    LaneChanges,
    Metric,
    MinDistance,
    RiskByType,
    RiskLog,
    ValidityLevels,
    default_metrics,
)
from mujoco_world.loop.rules import (
    AnyContact,
    CrashAtRest,
    Diverged,
    EgoContact,
    Goal,
    LeftMap,
    PostCrashTime,
    Stop,
    StopRule,
    TimeLimit,
    default_rules,
    final_outcome,
)
from mujoco_world.loop.runner import run_scenario
from mujoco_world.loop.summary import build_summary
from mujoco_world.scenario.spec import scenario_from_dict


def head_on_beside_the_ego(duration=6.0):
    """Two cars meet head-on in the other lanes at t ~ 1.8 s; the ego drives by."""
    car = {"type": "car", "behaviour": {"kind": "scripted", "speed": 10.0}}
    return scenario_from_dict(
        {
            "name": "third_party_crash",
            "road": {"length": 300.0},
            "ego": {"s0": 10.0, "speed": 10.0, "goal_s": 60.0},
            "duration": duration,
            "road_users": [
                {"name": "east", "s0": 100.0, "route": {"lane": 1, "wrong_way": True}, **car},
                {"name": "west", "s0": 160.0, "route": {"lane": 0, "direction": -1}, **car},
            ],
        }
    )


class FakeWorld:
    """The few things the rules read from a world, set by hand."""

    def __init__(self, n=2):
        self.time = 0.0
        self.speeds = np.full(n, 5.0)
        self.crashed = np.zeros(n, dtype=bool)
        self.progress = 0.0
        self.goal_s = 100.0
        self.why = None
        self.ego_on_plan = True  # before a contact, or after it under the continue policy
        self.scene = SimpleNamespace(speeds=lambda: self.speeds, dt=0.001)
        self.recorder = SimpleNamespace(has_open_episodes=False, touched=np.zeros(n, dtype=bool))

    def ego_progress(self):
        return self.progress

    def goal_reached(self):
        # A road without a goal region or goal time: the route's arc length (World.goal_reached).
        return self.progress >= self.goal_s

    def goal_description(self):
        return f"ego reached s = {self.goal_s:.1f} m on its route"

    def diverged(self, max_penetration):
        return self.why


class FakeRun:
    """The run state a rule reads: its world, crash time, step and scenario duration."""

    def __init__(self, world, crash_time=None, step=0, duration=10.0):
        self.world, self.crash_time, self.step = world, crash_time, step
        self.scenario = SimpleNamespace(duration=duration)
        self.dt = 0.001

    @property
    def time(self):
        return self.world.time


fake_run = FakeRun


def test_crash_at_rest_waits_for_settle_time_without_open_episodes():
    world = FakeWorld()
    rule = CrashAtRest(rest_speed=0.1, settle_time=2.0, interval=10)
    run = fake_run(world, crash_time=0.5)
    rule.start(run)
    world.crashed[:] = True
    world.ego_on_plan = False  # the brake policy
    world.speeds[:] = 0.05
    world.time = 1.0
    assert rule.check(run) is None  # rest begins at 1.0 s
    world.time = 2.99
    assert rule.check(run) is None
    world.recorder.has_open_episodes = True  # still in contact: the rest starts over
    world.time = 3.0
    assert rule.check(run) is None
    world.recorder.has_open_episodes = False
    world.time = 3.5
    assert rule.check(run) is None  # rest begins again at 3.5 s
    world.time = 5.5
    stop = rule.check(run)
    assert stop == Stop("crash", "collision; the bodies involved have come to rest", at_rest=True)


def test_crash_at_rest_needs_a_crash_and_every_crashed_body_at_rest():
    world = FakeWorld()
    rule = CrashAtRest(0.1, 0.0, 10)
    rule.start(fake_run(world))
    world.speeds[:] = 0.0
    world.ego_on_plan = False
    assert rule.check(fake_run(world, crash_time=None)) is None
    world.crashed[:] = True
    world.speeds[1] = 0.2  # one crashed body still slides
    assert rule.check(fake_run(world, crash_time=0.0)) is None
    world.speeds[1] = 0.0
    assert rule.check(fake_run(world, crash_time=0.0)).outcome == "crash"


def test_crash_at_rest_waits_while_a_crashed_ego_drives_on_its_plans():
    # Under the continue policy a crashed ego at rest may be waiting (at a red light):
    # only PostCrashTime or the time limit end such a run.
    world = FakeWorld()
    rule = CrashAtRest(0.1, 0.0, 10)
    rule.start(fake_run(world))
    world.speeds[:] = 0.0
    world.crashed[:] = True
    assert world.ego_on_plan
    assert rule.check(fake_run(world, crash_time=0.0)) is None
    # A crash between two other road users (AnyContact) with the ego untouched still
    # ends once they rest, the ego on its plans or not.
    world.crashed[0] = False
    assert rule.check(fake_run(world, crash_time=0.0)).outcome == "crash"


def test_post_crash_time_counts_from_the_crash():
    world = FakeWorld()
    rule = PostCrashTime(limit=10.0, interval=10)
    world.time = 12.0
    assert rule.check(fake_run(world, crash_time=None)) is None
    assert rule.check(fake_run(world, crash_time=2.5)) is None
    assert rule.check(fake_run(world, crash_time=2.0)).reason == "collision; stopped 10.0 s after it"


def test_goal_only_before_a_crash_and_at_ten_hertz():
    world = FakeWorld()
    rule = Goal(rate=10.0, interval_multiple=10)
    rule.start(fake_run(world))
    assert rule.interval == 100  # 0.1 s at 1 ms steps
    world.progress = 99.9
    assert rule.check(fake_run(world)) is None
    world.progress = 100.0
    assert rule.check(fake_run(world)).outcome == "goal"
    assert rule.check(fake_run(world, crash_time=1.0)) is None


def test_time_limit_is_a_timeout_or_a_crash():
    world = FakeWorld()
    rule = TimeLimit()
    rule.start(fake_run(world, duration=2.5))
    assert rule.max_steps == 2500
    assert rule.check(fake_run(world, step=2499, duration=2.5)) is None
    # Shorter than the 5 s over which a standstill is judged: a timeout, standing or not.
    world.time = 2.5
    stop = rule.check(fake_run(world, step=2500, duration=2.5))
    assert stop.outcome == "timeout" and "shorter than the 5 s" in stop.reason
    assert rule.check(fake_run(world, crash_time=1.0, step=2500, duration=2.5)).outcome == "crash"
    # 8 s: progress sampled every 100 steps; 1.5 m in the last 5 s is moving.
    rule.start(fake_run(world, duration=8.0))
    for step in range(0, 8001, 100):
        world.time, world.progress = step / 1000.0, 30.0 + 0.3 * step / 1000.0
        stop = rule.check(fake_run(world, step=step, duration=8.0))
    assert stop.outcome == "timeout" and stop.reason.endswith("the ego moved 1.5 m in the last 5 s")


def test_diverged_is_an_untrusted_failure():
    world = FakeWorld()
    rule = Diverged(max_penetration=1.5, interval=10)
    assert rule.check(fake_run(world)) is None
    world.why = "non-finite state"
    stop = rule.check(fake_run(world))
    assert stop.outcome == "failed" and not stop.trusted and "non-finite state" in stop.reason


def test_default_rules_order_and_interval():
    rules = default_rules(RunConfig(distance_interval=5))
    assert [type(r) for r in rules] == [Diverged, CrashAtRest, PostCrashTime, Goal, LeftMap]
    assert all(r.interval == 5 for r in rules)


def test_a_collision_found_at_the_end_turns_clean_outcomes_into_crash():
    record = SimpleNamespace(involves_ego=False)
    assert final_outcome(Stop("goal", "r"), [record], AnyContact()).outcome == "crash"
    assert final_outcome(Stop("timeout", "r"), [record], AnyContact()).outcome == "crash"
    assert final_outcome(Stop("failed", "r"), [record], AnyContact()).outcome == "failed"
    assert final_outcome(Stop("goal", "r"), [record], EgoContact()).outcome == "goal"
    assert final_outcome(Stop("goal", "r"), [], AnyContact()).outcome == "goal"


def _decision(ego_risk, users):
    road_users = tuple(
        SimpleNamespace(type=RoadUserType(t), risk=r, ego_risk=r / 10, collision_probability=0.0)
        for t, r in users
    )
    decision = SimpleNamespace(ego_combined_risk=ego_risk, road_users=road_users, level=10)
    return SimpleNamespace(decision=decision)  # a plan with its decision


def test_risk_log_keeps_the_highest_values_per_group():
    log = RiskLog()
    log.start(None)
    for k in range(150):  # ego risks 0.000 ... 0.149, one car and one pedestrian
        log.on_cycle(None, _decision(k / 1000, [("car", k / 100), ("pedestrian", 1.0 - k / 1000)]))
    values = log.values(None)
    assert values["max_risk"] == {"ego": 0.149, "third_party": 1.49, "vulnerable": 1.0}
    top = values["top_risks"]
    assert len(top["ego"]) == TOP_RISKS and top["ego"][0] == 0.149 and top["ego"][-1] == 0.05
    assert top["vulnerable"][-1] == pytest.approx(0.901)


def test_risk_by_type_keeps_the_highest_values_per_road_user_type():
    metric = RiskByType()
    metric.start(None)
    for k in range(150):  # two cars, one motorcycle per cycle
        users = [("car", k / 100), ("car", k / 200), ("motorcycle", 1.0 - k / 1000)]
        metric.on_cycle(None, _decision(0.0, users))
    metric.on_cycle(None, SimpleNamespace(decision=None))  # a scripted planner's cycle
    values = metric.values(None)
    cars, bikes = values["top_risks_by_type"]["car"], values["top_risks_by_type"]["motorcycle"]
    # The 100 highest of 300 car values, sorted independently.
    expected = sorted([k / 100 for k in range(150)] + [k / 200 for k in range(150)], reverse=True)[:TOP_RISKS]
    assert cars == pytest.approx(expected) and len(cars) == TOP_RISKS
    assert bikes[0] == 1.0 and bikes[-1] == pytest.approx(1.0 - 99 / 1000)
    assert values["top_ego_risks_by_type"]["car"][0] == pytest.approx(0.149)
    assert set(values["top_risks_by_type"]) == {"car", "motorcycle"}


def test_harm_per_group_combines_a_bodys_impacts_adds_bodies_and_skips_walls():
    metric = HarmPerGroup()
    metric.start(None)

    def record(a, b, ego=True):
        entities = SimpleNamespace(
            a=SimpleNamespace(entity=a.pop("entity")), b=SimpleNamespace(entity=b.pop("entity"))
        )
        return SimpleNamespace(
            measurement=entities, a=SimpleNamespace(**a), b=SimpleNamespace(**b), involves_ego=ego
        )

    metric.on_impact(
        None,
        record(
            {"entity": 0, "group": "ego", "harm_measured": 0.2},
            {"entity": 1, "group": "vulnerable", "harm_measured": 0.5},
        ),
    )
    metric.on_impact(
        None,
        record(
            {"entity": 0, "group": "ego", "harm_measured": 0.1},
            {"entity": -1, "group": "static", "harm_measured": math.nan},
        ),
    )
    # a taxi hits a cyclist: third party, not the ego's
    metric.on_impact(
        None,
        record(
            {"entity": 2, "group": "third_party", "harm_measured": 0.05},
            {"entity": 3, "group": "vulnerable", "harm_measured": 0.25},
            ego=False,
        ),
    )
    values = metric.values(None)
    # The ego hit twice: 1 - 0.8 * 0.9 = 0.28 (not 0.3); two vulnerable bodies add up.
    assert values["harm"] == pytest.approx({"ego": 0.28, "third_party": 0.05, "vulnerable": 0.75})
    assert values["harm_ego_involved"] == pytest.approx({"ego": 0.28, "third_party": 0.0, "vulnerable": 0.5})
    assert values["harm_third_party"] == pytest.approx({"ego": 0.0, "third_party": 0.05, "vulnerable": 0.25})


@pytest.mark.parametrize("policy", ["brake", "continue"])
def test_min_distance_follows_the_ego_while_it_drives_on_its_plans(policy):
    types = ("car", RoadUserType.CAR, RoadUserType.PEDESTRIAN, RoadUserType.BICYCLE)
    world = SimpleNamespace(n=4, types=types, crashed=np.zeros(4, bool), ego_on_plan=True)
    world.scene = SimpleNamespace(names=("ego", "van", "walker", "cyclist"))
    distances = iter([np.array([4.0, 6.0, 0.9]), np.array([3.0, 2.5, 50.0]), np.array([-0.2, 0.1, 0.0])])
    world.ego_distances = lambda cap: next(distances)
    run = SimpleNamespace(world=world)
    metric = MinDistance(interval=10)
    metric.start(run)
    metric.sample(run)
    metric.sample(run)
    world.crashed[0] = True
    # After the ego's contact: braking to rest, not measured; driving on (post_crash = continue), measured.
    world.ego_on_plan = policy == "continue"
    metric.sample(run)
    if policy == "brake":
        assert metric.values(run) == {
            "min_distance": 0.9,
            "min_distance_vulnerable": 0.9,
            "clearance_vulnerable": {"walker": 2.5, "cyclist": 0.9},  # each VRU's own closest pass
        }
    else:
        assert metric.values(run) == {
            "min_distance": -0.2,
            "min_distance_vulnerable": 0.0,
            "clearance_vulnerable": {"walker": 0.1, "cyclist": 0.0},
        }


def test_validity_levels_count_cycles():
    metric = ValidityLevels()
    metric.start(None)
    for level in (10, 10, 1):
        metric.on_cycle(None, SimpleNamespace(decision=SimpleNamespace(level=level)))
    metric.on_cycle(None, SimpleNamespace(decision=None))  # a planner without decisions
    assert metric.values(None) == {"levels": {"10": 2, "1": 1}}


class StopAt(StopRule):
    """Ends the run as a timeout at a fixed time (a rule the loop has never seen)."""

    def __init__(self, at):
        self.at = at
        self.interval = 1

    def start(self, run):
        pass

    def check(self, run):
        return Stop("timeout", f"stopped at {self.at} s") if run.time >= self.at - 1e-9 else None


class CountSamples(Metric):
    """Counts its samples and the collisions (a metric the summary has no field for)."""

    interval = 100

    def start(self, run):
        self.samples = 0
        self.impacts = 0

    def sample(self, run):
        self.samples += 1

    def on_impact(self, run, record):
        self.impacts += 1

    def values(self, run):
        return {"samples": self.samples, "impacts_seen": self.impacts}


def test_a_new_rule_and_a_new_metric_plug_in_without_touching_the_loop():
    config = RunConfig()
    summary = run_scenario(
        head_on_beside_the_ego(),
        "standard",
        config=config,
        rules=(*default_rules(config), StopAt(1.0)),
        metrics=(*default_metrics(config), CountSamples()),
    )
    assert (summary.outcome, summary.reason, summary.duration) == ("timeout", "stopped at 1.0 s", 1.0)
    assert summary.extra_metrics == {"samples": 10, "impacts_seen": 0}
    assert summary.steps == 1000


def test_crash_means_what_the_criterion_says():
    any_contact = run_scenario(head_on_beside_the_ego(), "standard", crash=AnyContact())
    assert any_contact.outcome == "crash" and len(any_contact.collisions) == 1
    ego_only = run_scenario(head_on_beside_the_ego(), "standard", crash=EgoContact())
    assert ego_only.outcome == "goal", ego_only.reason  # the ego drove by to its goal
    assert len(ego_only.collisions) == 1 and not ego_only.ego_collided
    assert ego_only.harm["third_party"] > 0


def test_by_default_a_crash_is_ego_involved_and_third_party_harm_is_apart():
    summary = run_scenario(head_on_beside_the_ego(), "standard")
    assert summary.outcome == "goal", summary.reason
    assert summary.ego_collisions == () and len(summary.third_party_collisions) == 1
    assert summary.harm["third_party"] > 0
    assert summary.harm_third_party["third_party"] == pytest.approx(summary.harm["third_party"])
    assert summary.harm_ego_involved == {"ego": 0.0, "third_party": 0.0, "vulnerable": 0.0}


def test_a_metric_may_not_overwrite_what_the_loop_counts():
    with pytest.raises(ValueError, match="outcome"):
        build_summary(
            scenario="s", planner="p", seed=0, outcome="goal", reason="", duration=0.0, steps=0,
            cycles=0, bodies=(), collisions=(), values={"outcome": "crash"}, timings={},
        )  # fmt: skip


def test_no_function_of_the_loop_is_longer_than_60_lines():
    tree = ast.parse(inspect.getsource(runner_module))
    lengths = {
        node.name: node.end_lineno - node.lineno + 1
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef)
    }
    assert lengths and max(lengths.values()) <= 60, lengths


def test_rules_without_an_interval_are_rejected():
    class Broken:
        def start(self, run):
            pass

        def check(self, run):
            return None

    with pytest.raises(ValueError, match="interval"):
        run_scenario(dataclasses.replace(head_on_beside_the_ego(), duration=0.1), rules=(Broken(),))


def test_lane_changes_are_counted_per_mobil_road_user():
    # Three road users, two with MOBIL ("a" changed twice, "c" never); "b" keeps its lane without MOBIL.
    specs = tuple(SimpleNamespace(name=name) for name in ("a", "b", "c"))
    fleet = SimpleNamespace(
        k=3, specs=specs, mobil=np.array([True, False, True]), lane_changes=[(1.0, 0, 0, 1), (6.5, 0, 1, 0)]
    )
    values = LaneChanges().values(SimpleNamespace(world=SimpleNamespace(fleet=fleet)))
    assert values["lane_changes"] == [("a", 1.0, 0, 1), ("a", 6.5, 1, 0)]
    assert values["lane_changes_per_user"] == {"a": 2, "c": 0}
    fleet.mobil[:] = False
    assert LaneChanges().values(SimpleNamespace(world=SimpleNamespace(fleet=fleet))) == {}
