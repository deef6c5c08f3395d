"""The ego-planner protocol: your own planner, scripted manoeuvres, the planner registry."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest

import mujoco_world
from ethical_planner.config import PRESETS
from mujoco_world.agents import (
    EGO_PLANNERS,
    EgoSetup,
    Observation,
    Plan,
    ScriptedPlanner,
    SwitchingPlanner,
    brake,
    lane_change,
    make_ego_planner,
)
from mujoco_world.loop.observers import RunObserver
from mujoco_world.loop.runner import run_scenario
from mujoco_world.scenario.catalog import get_scenario
from mujoco_world.scenario.spec import scenario_from_dict

README = Path(__file__).resolve().parents[3] / "README.md"


class Cautious:
    """A planner written here: keeps its lane, brakes at 6 m/s^2 while anything is close ahead."""

    name = "cautious"

    def __init__(self, setup):
        self.path = setup.environment.reference_path
        self.limit = setup.environment.speed_limit
        self.cycles = 0

    def plan(self, observation):
        self.cycles += 1
        ego = observation.ego
        s0, d0 = self.path.to_frenet(np.array(ego.x), np.array(ego.y))
        others = [
            self.path.to_frenet(np.array(u.state.x), np.array(u.state.y)) for u in observation.road_users
        ]
        close = any(0 < s - s0 < 3 * ego.v + 10 and abs(d - d0) < 2.5 for s, d in others)
        t = np.linspace(0.0, 3.0, 31)
        accel = -6.0 if close else float(np.clip(self.limit - ego.v, -2.0, 2.0))
        v = np.clip(ego.v + accel * t, 0.0, max(self.limit, ego.v))
        s = s0 + np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2 * np.diff(t))])
        x, y, yaw, kappa, _ = self.path.evaluate(s)
        return Plan.from_arrays(t, x, y, yaw, v, np.gradient(v, t), kappa)


def open_road(duration=6.0, speed=10.0, users=()):
    return scenario_from_dict(
        {
            "name": "open_road",
            "road": {"length": 400.0},
            "ego": {"s0": 20.0, "speed": speed, "goal_s": 380.0},
            "duration": duration,
            "road_users": list(users),
        }
    )


class Plans(RunObserver):
    """Keeps every plan with its time."""

    def __init__(self):
        self.plans = []

    def on_cycle(self, plan, time):
        self.plans.append((time, plan))


def test_a_planner_of_your_own_drives_a_catalog_scenario():
    planners = []

    def build(setup):
        planners.append(Cautious(setup))
        return planners[-1]

    summary = run_scenario(get_scenario("red_light_runner"), build)
    assert summary.planner == "cautious"
    assert summary.outcome == "goal" and not summary.collisions, summary.reason
    assert summary.min_distance > 1.0
    assert planners[0].cycles == summary.cycles > 0
    assert summary.max_risk == {"ego": 0.0, "third_party": 0.0, "vulnerable": 0.0}  # no decisions to log
    assert summary.levels == {}


def test_the_readme_example_runs(monkeypatch):
    text = README.read_text(encoding="utf-8")
    section = text[text.index("## Your own planner") :]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    real = mujoco_world.run_scenario
    monkeypatch.setattr(  # the README's run, cut to 2 s
        mujoco_world,
        "run_scenario",
        lambda s, p, *a, **k: real(dataclasses.replace(s, duration=2.0), p, *a, **k),
    )
    namespace: dict = {}
    exec(compile(code, str(README), "exec"), namespace)  # noqa: S102 - our own README
    summary = namespace["summary"]
    assert summary.planner == "cautious" and summary.outcome == "timeout" and summary.cycles == 20


def test_scripted_braking_plan_follows_the_kinematics():
    # 10 m/s braking at 4 m/s^2 from t = 0.5 s: s = 10 t until 0.5 s, then
    # 5 + 10 tau - 2 tau^2 (tau = t - 0.5) to the stop at tau = 2.5 s, s = 17.5 m after the start.
    world_setup = _setup()
    planner = ScriptedPlanner(brake(4.0, start=0.5), world_setup, horizon=4.0, step=0.05)
    ego = _state(world_setup, s=20.0, v=10.0)
    plan = planner.plan(Observation(0.0, ego, ())).trajectory
    t = plan.t
    expected_s = np.where(t < 0.5, 10 * t, 5 + 10 * (t - 0.5) - 2 * (t - 0.5) ** 2)
    expected_s = np.where(t > 3.0, 17.5, expected_s)
    expected_v = np.clip(np.where(t < 0.5, 10.0, 10.0 - 4.0 * (t - 0.5)), 0.0, None)
    # A straight road along x: the arc length is x minus the start.
    np.testing.assert_allclose(plan.x - plan.x[0], expected_s, atol=0.02)
    np.testing.assert_allclose(plan.v, expected_v, atol=0.05)
    assert plan.v[-1] == 0.0 and plan.a[-1] == 0.0  # stopped and held, never reversing
    # A later cycle continues the same manoeuvre (open loop): at t = 1.5 s it is 13 m on.
    later = planner.plan(Observation(1.5, ego, ())).trajectory
    assert later.x[0] - plan.x[0] == pytest.approx(5 + 10 * 1.0 - 2 * 1.0, abs=0.02)


def test_scripted_lane_change_follows_the_quintic():
    setup = _setup()
    planner = ScriptedPlanner(lane_change(3.5, start=1.0, duration=2.0), setup, horizon=4.0, step=0.1)
    plan = planner.plan(Observation(0.0, _state(setup, s=20.0, v=10.0), ())).trajectory
    u = np.clip((plan.t - 1.0) / 2.0, 0.0, 1.0)
    np.testing.assert_allclose(plan.y - plan.y[0], 3.5 * (10 * u**3 - 15 * u**4 + 6 * u**5), atol=1e-3)
    np.testing.assert_allclose(np.diff(plan.x) / np.diff(plan.t), 10.0, atol=0.3)  # speed kept


def test_scripted_emergency_brake_stops_the_ego_where_the_kinematics_say():
    summary = run_scenario(open_road(duration=4.0), "emergency_brake")
    assert summary.planner == "emergency_brake" and summary.outcome == "timeout"
    # 10 m/s at 8 m/s^2 (VehicleConfig.emergency_deceleration): 6.25 m from s = 20 m.
    assert summary.progress == pytest.approx(26.25, abs=0.15)


def test_switching_planner_hands_over_at_the_given_time():
    plans = Plans()

    def build(setup):
        ethical = make_ego_planner("ethical", setup)
        return SwitchingPlanner(ethical, ScriptedPlanner(brake(3.0), setup), at=1.0)

    summary = run_scenario(open_road(duration=3.0), build, observer=plans)
    assert summary.planner == "ethical+brake"
    before = [p.decision is not None for t, p in plans.plans if t < 1.0 - 1e-9]
    after = [p.decision is None for t, p in plans.plans if t >= 1.0 - 1e-9]
    assert before and all(before) and after and all(after)
    speed_at_switch = next(p.trajectory.v[0] for t, p in plans.plans if t >= 1.0 - 1e-9)
    # From the switch on the ego brakes at 3 m/s^2: at 3 s it has lost 6 m/s.
    assert plans.plans[-1][1].trajectory.v[0] == pytest.approx(max(speed_at_switch - 3.0 * 1.9, 0.0), abs=0.1)


def test_every_preset_and_the_scripted_kinds_are_registered():
    assert set(PRESETS.names()) <= set(EGO_PLANNERS.names())
    assert {"keep_lane", "emergency_brake"} <= set(EGO_PLANNERS.names())
    with pytest.raises(ValueError, match=r"unknown planner 'nope'; allowed: ethical, .*keep_lane"):
        make_ego_planner("nope", _setup())


def test_a_bad_plan_fails_the_run_with_the_reason():
    class Broken:
        name = "broken"

        def plan(self, observation):
            t = np.linspace(0.0, 1.0, 5)
            return Plan.from_arrays(t, t, t, t, t, t, np.zeros(4))  # kappa too short

    summary = run_scenario(open_road(duration=1.0), Broken())
    assert summary.outcome == "failed"
    assert "planner raised ValueError at t = 0.000 s: plan.kappa must have shape" in summary.reason


def test_a_factory_must_build_a_planner():
    with pytest.raises(ValueError, match="has no name and plan"):
        make_ego_planner(lambda setup: object(), _setup())


@pytest.mark.parametrize(
    ("t", "match"),
    [
        (np.array([0.0]), "at least 2"),
        (np.array([0.1, 0.2]), "start at 0"),
        (np.array([0.0, 0.0]), "increasing"),
    ],
)
def test_plans_are_validated(t, match):
    with pytest.raises(ValueError, match=match):
        Plan.from_arrays(t, t, t, t, t, t, t)
    with pytest.raises(ValueError, match="finite"):
        Plan.from_arrays(*([np.array([0.0, math.nan])] * 7))


def _setup() -> EgoSetup:
    from mujoco_world.loop.world import World

    world = World(open_road())
    scenario = world.scenario
    from ethical_planner.road_users import Shape

    return EgoSetup(
        world.environment(), Shape(scenario.ego.length, scenario.ego.width), scenario.ego.mass, 380.0
    )


def _state(setup: EgoSetup, s: float, v: float):
    from ethical_planner.road_users import KinematicState

    x, y, yaw, _, _ = setup.environment.reference_path.evaluate(np.array(s))
    return KinematicState(float(x), float(y), float(yaw), v)
