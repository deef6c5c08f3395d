"""Scenario-level regressions of the planner's competence (issue 9, causes 1-6).

Each test puts the planner (or its predictor) into a situation of the catalog, in the
MuJoCo world, where the old planner failed, and checks the behaviour that avoids the
failure. They are short: a few seconds of world time or a few planning cycles.
"""

import dataclasses

import numpy as np
import pytest

from ethical_planner.config import PredictionConfig
from ethical_planner.prediction import predict_constant_acceleration, predict_constant_turn_rate
from mujoco_world.loop.world import World
from mujoco_world.scenario.catalog import get_scenario


def _advance(world, seconds):
    for _ in range(int(round(seconds / world.scene.dt))):
        world.step()


def test_cause_3_a_braking_lead_is_predicted_to_stop_where_it_stops():
    """tailgater_sudden_stop: the lead brakes at 7.5 m/s^2 from 15 m/s.

    The world reports the measured acceleration, and the default predictor puts the
    stopped lead within 0.5 m of where it actually stops; the constant-velocity model
    put it ~10 m further.
    """
    scenario = get_scenario("tailgater_sudden_stop")
    lead = scenario.road_users[0]
    # The ego stands far behind, so nothing hits the lead: only its braking is watched.
    scenario = dataclasses.replace(
        scenario, road_users=(lead,), ego=dataclasses.replace(scenario.ego, s0=2.0, speed=0.0)
    )
    world = World(scenario)
    _advance(world, lead.behaviour.start_time + 0.3)
    _, users = world.observe()
    (observed,) = users
    assert observed.state.a == pytest.approx(-7.5, abs=0.3)
    times = np.linspace(0.0, 3.0, 31)
    predicted = predict_constant_acceleration(users, times, PredictionConfig()).mean[0, -1, 0]
    blind = predict_constant_turn_rate(users, times, PredictionConfig()).mean[0, -1, 0]
    _advance(world, 3.0)
    actual = world.positions[1, 0]
    assert abs(world.speeds_along_heading()[1]) < 0.1  # it has stopped
    assert predicted == pytest.approx(actual, abs=0.5)
    assert blind - actual > 5.0


def test_cause_3_a_drift_is_not_extrapolated_to_the_kerb():
    """oncoming_drift: early in the drift (turn rate near its peak) the default predictor
    puts the drifter 2 s ahead where it is, in the ego lane; the constant turn rate
    drives it on a circle through the ego lane to the kerb."""
    scenario = get_scenario("oncoming_drift")
    drifter = scenario.road_users[0]
    scenario = dataclasses.replace(
        scenario, road_users=(drifter,), ego=dataclasses.replace(scenario.ego, s0=2.0, speed=0.0)
    )
    world = World(scenario)
    # Run until the drifter has moved 0.5 m sideways, then predict 2 s ahead.
    y_start = world.positions[1, 1]
    while abs(world.positions[1, 1] - y_start) < 0.5:
        _advance(world, 0.05)
    _, users = world.observe()
    assert abs(users[0].state.yaw_rate) > 0.05
    times = np.linspace(0.0, 2.0, 21)
    decayed = predict_constant_acceleration(users, times, PredictionConfig()).mean[0, -1, 1]
    circle = predict_constant_turn_rate(users, times, PredictionConfig()).mean[0, -1, 1]
    _advance(world, 2.0)
    actual = world.positions[1, 1]
    # Measured: the circle ends 5.2 m beyond the drifter's final offset (past the ego
    # lane, at the kerb); the drift returning to the course of the drifter's history
    # (straight along its lane) ends 0.4 m off.
    assert abs(decayed - actual) < 0.6
    assert abs(circle - actual) > 4.0


def _ego_collisions(summary):
    return [c for c in summary.collisions if c.involves_ego]


@pytest.mark.parametrize(
    "name,duration",
    [
        # Cause 1 (commitment, hard stops) and cause 2 (short horizons): a pedestrian steps
        # out from behind a van; braking after 4.1 s always hits, a committed 1 m swerve
        # (a 1 s lateral move covers 0.5 m in 0.5 s) does not.
        ("pedestrian_behind_parked", 7.0),
        # Causes 1 and 2: the cyclist swerves out of the truck's way into the ego lane;
        # the truck-cyclist crash itself is unavoidable, the ego's is not.
        ("turning_truck_cyclist", 8.0),
        # Causes 1 and 3: the lead brakes at 7.5 m/s^2 with a tailgater 0.4 s behind.
        ("tailgater_sudden_stop", 7.0),
    ],
)
def test_causes_1_2_the_ego_avoids_what_the_old_planner_hit(name, duration):
    from mujoco_world.loop.runner import run_scenario

    scenario = dataclasses.replace(get_scenario(name), duration=duration)
    summary = run_scenario(scenario, "ethical", seed=0)
    assert summary.outcome != "failed", summary.reason
    assert not _ego_collisions(summary), [
        (c.measurement.a.name, c.measurement.b.name) for c in summary.collisions
    ]


@pytest.mark.slow
def test_cause_4_overtake_cyclist_waits_for_oncoming_traffic_then_passes_with_clearance():
    """Cause 4 in closed loop: the ego stays behind the cyclist while the oncoming cars
    pass, then overtakes and reaches the goal, at least 1 m from the cyclist. With
    w_risk = 1000 Eq. 5 itself refuses the risky overtakes, so R_max refuses none for
    the ethical preset; R_max deciding (the paper's Fig. 3) is shown with the standard
    preset in test_principles.py."""
    from mujoco_world.loop.runner import run_scenario

    summary = run_scenario(get_scenario("overtake_cyclist"), "ethical", seed=0)
    assert summary.outcome == "goal", summary.reason
    assert not _ego_collisions(summary)
    assert summary.min_distance_vulnerable >= 1.0


@pytest.mark.slow
def test_cause_4_curve_truck_reaches_the_goal_passing_the_walker_with_clearance():
    """After the truck has passed, the ego follows the walker at 1.5 m/s. From 9.2 s a pass
    through the free oncoming lane is the cheapest plan on every cycle, within the commitment
    margin of the crawl; the crawl was kept to the time limit until a kept plan outvoted on
    10 consecutive cycles is dropped (``CommitmentConfig.switch_after_cycles``): it passes at
    10.1 s, reaches the goal at 22.2 s, 2.0 m from the walker at the closest."""
    from mujoco_world.loop.runner import run_scenario

    summary = run_scenario(get_scenario("curve_truck"), "ethical", seed=0)
    assert summary.outcome == "goal", summary.reason
    assert not _ego_collisions(summary)
    assert summary.min_distance_vulnerable >= 1.0


def test_terminal_safety_the_ego_does_not_end_its_plans_in_the_way_of_the_oncoming_truck():
    """curve_truck-s0-7 (a random variant): to give the walker room the ego moved into
    the oncoming lane while the truck was 100 m ahead; every plan was collision-free
    over its 3 s, the truck arrived just beyond it and cut the corner into the ego
    (collision at 5.1 s). Plans that end in the oncoming lane too late to return before
    the truck arrives are now level 1 (``ethical_planner.terminal``): the ego stays in
    its lane and shifts right while the truck passes."""
    from mujoco_world.loop.runner import run_scenario
    from mujoco_world.scenario.catalog import generated_scenario

    scenario = dataclasses.replace(generated_scenario("curve_truck-s0-7"), duration=6.5)
    summary = run_scenario(scenario, "ethical", seed=0)
    assert summary.outcome != "failed", summary.reason
    assert not _ego_collisions(summary), [
        (c.measurement.a.name, c.measurement.b.name) for c in summary.collisions
    ]


def test_standstill_distance_the_ego_waits_with_room_to_pass_the_debris():
    """debris_on_lane: while the oncoming cars passed, the ego crept up to 0.6 m behind
    the fallen load (its front at s = 88.9 m, the load from 89.4 m) and stalled there:
    from so close it cannot steer around without reversing (the scenario's [expect]
    failed). Plans must now end able to stop 9 m plus their stopping distance short of
    static obstacles (``ethical_planner.terminal.crowds_static_obstacle``): it waits
    further back and passes the load on the left by 11 s."""
    from mujoco_world.loop.runner import run_scenario

    scenario = get_scenario("debris_on_lane")
    debris = scenario.debris[0]
    summary = run_scenario(dataclasses.replace(scenario, duration=11.5), "ethical", seed=0)
    assert summary.outcome != "failed", summary.reason
    assert not _ego_collisions(summary)
    assert summary.progress > debris.s + debris.length + 5.0  # its rear is past the load
