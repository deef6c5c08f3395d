"""Controllers, behaviours and the physical world without the planner."""

import math

import mujoco
import numpy as np
import pytest

from ethical_planner.reference_path import curvature
from mujoco_world.agents.behaviour import linear_profile, smoothstep_profile
from mujoco_world.loop.world import ObservationNoise, World
from mujoco_world.physics.control import GRAVITY, ControlConfig, TrajectoryReference, tracking_forces
from mujoco_world.scenario.catalog import get_scenario
from mujoco_world.scenario.spec import scenario_from_dict


def lane_change(t0=0.0, x0=10.0, y0=-1.75, v=10.0, width=3.5, duration=3.0, total=7.0, start=1.0, dt=0.1):
    """A quintic lane change sampled like a planner trajectory (dt = 0.1 s)."""
    t = np.arange(0.0, total + 1e-9, dt)
    u = np.clip((t - start) / duration, 0.0, 1.0)
    d = width * (10 * u**3 - 15 * u**4 + 6 * u**5)
    dd = width * (30 * u**2 - 60 * u**3 + 30 * u**4) / duration
    ddd = width * (60 * u - 180 * u**2 + 120 * u**3) / duration**2
    speed = np.hypot(v, dd)
    kappa = curvature(np.full_like(t, v), dd, np.zeros_like(t), ddd)
    yaw = np.arctan2(dd, v)
    return TrajectoryReference(t0, t, x0 + v * t, y0 + d, yaw, speed, np.gradient(speed, t), kappa)


def standstill(world):
    """A plan that holds the ego where it is."""
    x, y = world.positions[0]
    zeros = np.zeros(2)
    t = np.array([0.0, 1.0])
    return TrajectoryReference(0.0, t, np.full(2, x), np.full(2, y), zeros, zeros, zeros, zeros)


def empty_road(**ego):
    ego = {"s0": 10.0, "speed": 10.0, **ego}
    return scenario_from_dict({"name": "empty", "road": {"length": 300.0}, "ego": ego})


def test_lane_change_tracking_error_is_below_5_cm():
    world = World(empty_road())
    world.set_ego_plan(lane_change())
    for _ in range(7000):
        world.step()
    rms, worst = world.tracking_error()
    assert rms < 0.05
    assert worst < 0.10
    assert world.positions[0, 1] == pytest.approx(1.75, abs=0.02)


def test_tracking_force_stays_in_the_friction_circle():
    config = ControlConfig()
    mass = np.array([1475.0, 75.0])
    forces = tracking_forces(
        config,
        mass,
        np.array([3000.0, 3.0]),
        np.zeros((2, 3)),
        np.zeros((2, 3)),
        np.array([[50.0, 0.0], [0.0, -20.0]]),
        np.zeros((2, 2)),
        np.array([[30.0, 0.0], [0.0, 0.0]]),
        np.zeros(2),
        np.zeros(2),
    )
    planar = np.hypot(forces[:, 0], forces[:, 1])
    np.testing.assert_allclose(planar, config.friction_mu * GRAVITY * mass)


def test_smoothstep_profile_is_smooth_and_holds():
    knots = ((1.0, 2.0), (3.0, -1.0))
    assert smoothstep_profile(knots, -1.0) == (0.0, 0.0, 0.0)
    assert smoothstep_profile(knots, 1.0)[0] == pytest.approx(2.0)
    assert smoothstep_profile(knots, 1.0)[1] == pytest.approx(0.0)
    assert smoothstep_profile(knots, 2.0)[0] == pytest.approx(0.5)
    assert smoothstep_profile(knots, 10.0) == (-1.0, 0.0, 0.0)
    assert linear_profile(((0.0, 4.0), (2.0, 0.0)), 1.0, 9.0) == pytest.approx(2.0)
    assert linear_profile((), 1.0, 9.0) == 9.0


def test_idm_follower_stops_behind_a_braking_leader():
    scenario = scenario_from_dict(
        {
            "name": "follow",
            "road": {"length": 400.0},
            "ego": {"s0": 380.0, "speed": 0.0, "goal_s": 395.0},
            "road_users": [
                {
                    "name": "lead",
                    "type": "car",
                    "s0": 60.0,
                    "behaviour": {
                        "kind": "scripted",
                        "speed": 12.0,
                        "start_time": 3.0,
                        "speed_profile": [[0.0, 12.0], [3.0, 0.0]],
                    },
                },
                {
                    "name": "follower",
                    "type": "car",
                    "s0": 30.0,
                    "behaviour": {"kind": "idm", "speed": 12.0, "idm": {"time_headway": 1.2, "min_gap": 2.0}},
                },
            ],
        }
    )
    world = World(scenario)
    world.set_ego_plan(standstill(world))
    for _ in range(15000):
        world.step()
    assert not world.crashed.any()
    gap = world.positions[1, 0] - world.positions[2, 0] - 4.5
    assert 1.0 < gap < 6.0
    assert abs(world.speeds_along_heading()[2]) < 0.1


def test_pedestrian_waits_for_the_gap_then_crosses():
    scenario = scenario_from_dict(
        {
            "name": "crossing",
            "road": {"length": 300.0},
            "ego": {"s0": 5.0, "speed": 0.0, "goal_s": 290.0},
            "road_users": [
                {
                    "name": "ped",
                    "type": "pedestrian",
                    "route": {"road": "waypoints", "waypoints": [[100.0, -6.0], [100.0, 6.0]]},
                    "behaviour": {
                        "kind": "pedestrian",
                        "speed": 1.4,
                        "crossing": {"wait_at": 1.5, "gap_time": 8.0},
                    },
                },
                {"name": "car", "type": "car", "s0": 40.0, "behaviour": {"kind": "scripted", "speed": 10.0}},
            ],
        }
    )
    world = World(scenario)
    world.set_ego_plan(standstill(world))
    ys, car_x = [], []
    for _ in range(14000):
        world.step()
        ys.append(world.positions[1, 1])
        car_x.append(world.positions[2, 0])
    ys, car_x = np.array(ys), np.array(car_x)
    started = np.argmax(ys > -4.3)  # left the kerb
    assert -4.7 < ys[2000] < -4.3  # waiting at the kerb while the car approaches
    assert car_x[started] > 97.0  # it went once the car had passed
    assert ys[-1] > 3.0  # and it crossed
    assert not world.crashed.any()


def test_cut_in_reaches_the_target_lane():
    world = World(get_scenario("highway_cut_in"))
    for _ in range(6000):
        world.step()
    cutter = world.scenario.road_users[0].name
    index = 1 + [u.name for u in world.scenario.road_users].index(cutter)
    assert world.positions[index, 1] == pytest.approx(0.0, abs=0.15)  # centre lane of three


def test_legal_corridors_reach_the_planner():
    world = World(get_scenario("red_light_runner"))
    _, users = world.observe()
    runner = users[0]
    assert runner.legal is not None and runner.legal.stop_distance is not None
    assert runner.legal.stop_distance > 0
    obeying = users[1]
    assert obeying.legal.stop_distance > 0
    assert users[2].legal is None


def test_observation_noise_needs_a_generator_and_is_seeded():
    world = World(get_scenario("oncoming_drift"))
    noise = ObservationNoise(position=0.5)
    with pytest.raises(ValueError, match="Generator"):
        world.observe(None, noise)
    a = world.observe(np.random.default_rng(1), noise)[1][0].state
    b = world.observe(np.random.default_rng(1), noise)[1][0].state
    c = world.observe(np.random.default_rng(2), noise)[1][0].state
    exact = world.observe()[1][0].state
    assert a == b and a != c
    assert math.hypot(a.x - exact.x, a.y - exact.y) > 0


def test_crashed_bodies_brake_to_rest_and_controls_are_cut():
    scenario = scenario_from_dict(
        {
            "name": "crash",
            "road": {"length": 300.0},
            "ego": {"s0": 10.0, "speed": 15.0, "goal_s": 290.0},
            "road_users": [{"name": "wall_car", "type": "car", "s0": 40.0, "behaviour": {"kind": "parked"}}],
        }
    )
    world = World(scenario)
    measured = []
    for _ in range(6000):
        measured += world.step()
    assert world.crashed.all()
    assert world.ego_crash_time == pytest.approx(25.62 / 15.0, abs=0.01)
    assert np.all(world.scene.speeds() < 0.05)
    (m,) = measured
    assert m.a.name == "ego" and m.b.name == "wall_car"
    assert 0.05 < m.restitution < 0.15  # rigid contact, e at the contact point along the normal
    assert m.a.dv_impulse == pytest.approx(0.5 * 15.0 * (1 + m.restitution), rel=0.01)
    assert m.a.dv_com == pytest.approx(m.a.dv_impulse, abs=0.02)


def test_observed_road_users_carry_their_sampled_history():
    world = World(get_scenario("highway_cut_in"), history_step=0.1, history_length=11)
    _, users = world.observe()
    assert all(len(u.history) == 1 and u.history.times[-1] == 0.0 for u in users)
    for _ in range(1550):  # 1.55 s of 1 ms steps
        world.step()
    _, users = world.observe()
    user = users[0]
    history = user.history
    # 16 samples were taken (t = 0, 0.1, ..., 1.5); the newest 11 are kept, 0.05 s old.
    assert len(history) == 11 and history.step == pytest.approx(0.1)
    assert history.times == pytest.approx(np.arange(0.5, 1.51, 0.1) - 1.55)
    # Speeds agree with the displacement between samples (an independent check).
    moved = np.hypot(*np.diff(history.positions, axis=0).T) / 0.1
    assert moved == pytest.approx(0.5 * (history.speeds[1:] + history.speeds[:-1]), rel=0.05, abs=0.05)
    # The newest sample lies behind the current state by about 0.05 s of motion.
    gap = math.hypot(user.state.x - history.positions[-1, 0], user.state.y - history.positions[-1, 1])
    assert gap == pytest.approx(0.05 * user.state.v, rel=0.1, abs=0.02)
    with pytest.raises(ValueError, match="history_step"):
        World(get_scenario("highway_cut_in"), history_step=0.00015)


def _cyclist_road(speed):
    return scenario_from_dict(
        {
            "name": "fast",
            "road": {"length": 300.0},
            "road_users": [
                {
                    "name": "rider",
                    "type": "bicycle",
                    "s0": 60.0,
                    "behaviour": {"kind": "scripted", "speed": speed},
                }
            ],
        }
    )


def test_a_body_that_would_jump_a_quarter_of_its_size_per_step_is_refused():
    # a bicycle is 0.6 m wide here: at 20 m/s it moves 2 cm per 1 ms step, 20 cm per 10 ms
    World(_cyclist_road(20.0), timestep=0.001, history_step=0.1)
    with pytest.raises(
        ValueError, match=r"rider: at 20 m/s it moves 20.0 cm per 10 ms physics step, more than 25%"
    ):
        World(_cyclist_road(20.0), timestep=0.01, history_step=0.1)


def test_a_goal_beyond_the_route_or_behind_the_start_is_refused():
    with pytest.raises(ValueError, match=r"ego.goal_s: the goal at s = -5.0 m must lie between"):
        World(
            scenario_from_dict({"name": "short", "road": {"length": 15.0}, "ego": {"s0": 2.0, "speed": 1.0}})
        )


@pytest.mark.parametrize(
    ("break_it", "message"),
    [
        (lambda world: world.scene.qvel.__setitem__((1, 0), 500.0), "a body moves at 500 m/s"),
        (lambda world: world.scene.qpos.__setitem__((1, 0), math.nan), "non-finite state"),
        (
            lambda world: setattr(world.scene.data.warning[mujoco.mjtWarning.mjWARN_BADQACC], "number", 1),
            "MuJoCo warned: bad acceleration",
        ),
    ],
)
def test_unstable_physics_is_reported(break_it, message):
    world = World(_cyclist_road(5.0))
    assert world.diverged(1.5) is None
    break_it(world)
    assert message in world.diverged(1.5)
