"""Control after contact: the post-crash policy (``[ego] post_crash``, issue 15).

Inside an impact (the high-force part of a contact pulse) no controller force acts;
outside impacts, also while pressed against another body, a crashed ego keeps tracking
its plans under ``continue`` and brakes to rest under ``brake``.
"""

import dataclasses
import math

import numpy as np
import pytest

from harm_calibration.study.attribution import attribute
from mujoco_world.agents.ego_planner import Plan
from mujoco_world.evaluation.compare import approach_speed, ego_strikes
from mujoco_world.loop.config import RunConfig
from mujoco_world.loop.metrics import Metric, default_metrics
from mujoco_world.loop.runner import closed_loop, run_scenario
from mujoco_world.loop.world import World
from mujoco_world.physics.control import GRAVITY, TrajectoryReference, tracking_forces
from mujoco_world.physics.impact import IMPACT_ACCELERATION, MeasurementWindow
from mujoco_world.scenario.catalog import get_scenario
from mujoco_world.scenario.spec import PostCrashPolicy, load_scenario, scenario_from_dict

SPEED = 15.0  # [m/s]


def rear_end(policy=None, duration=20.0):
    """The ego at 15 m/s behind a parked car 30 m ahead, in its lane."""
    ego = {"s0": 10.0, "speed": SPEED, "goal_s": 290.0}
    if policy is not None:
        ego["post_crash"] = policy
    return scenario_from_dict(
        {
            "name": "rear_end",
            "road": {"length": 300.0},
            "ego": ego,
            "duration": duration,
            "road_users": [{"name": "parked", "type": "car", "s0": 40.0, "behaviour": {"kind": "parked"}}],
        }
    )


def cruise(world, speed=SPEED, accel=0.0, horizon=30.0):
    """A plan along the ego's lane from where it is now, at ``speed`` plus ``accel`` [m/s^2] t."""
    x, y = world.positions[0]
    t = np.arange(0.0, horizon + 1e-9, 0.1)
    zeros = np.zeros_like(t)
    return TrajectoryReference(
        world.time,
        t,
        x + speed * t + 0.5 * accel * t**2,
        np.full_like(t, y),
        zeros,
        speed + accel * t,
        np.full_like(t, accel),
        zeros,
    )


def spy_on_physics_steps(world):
    """Record the ego's controls and state at the start of every physics step of ``world``.

    Returns:
        the list it fills: rows of (t [s], ego in a pulse, ego crashed, ego ctrl (3,),
        ego qpos (3,), ego qvel (3,), ego in an impact), taken when the physics step
        starts (after the controls were set).
    """
    rows = []
    scene = world.scene
    physics_step = scene.step

    def spy(observer=None):
        rows.append(
            (
                world.time,
                bool(world.recorder.in_pulse[0]),
                bool(world.crashed[0]),
                scene.ctrl[0].copy(),
                scene.qpos[0].copy(),
                scene.qvel[0].copy(),
                bool(world.recorder.in_impact[0]),
            )
        )
        return physics_step(observer)

    scene.step = spy
    return rows


def drive_with_spy(world, seconds):
    """Step ``world`` with a fixed plan; per physics step the controls it applied.

    Returns:
        rows of (t [s], ego in a pulse, ego crashed, ego ctrl (3,), ego qpos (3,), ego qvel (3,),
        ego in an impact), taken when the physics step starts (after the controls were
        set), and the measured collisions.
    """
    rows = spy_on_physics_steps(world)
    measured = []
    for _ in range(int(round(seconds / world.scene.dt))):
        measured += world.step()
    return rows, measured


def test_continue_cuts_the_controller_only_inside_impacts():
    world = World(rear_end("continue"))
    assert world.post_crash is PostCrashPolicy.CONTINUE
    plan = cruise(world, accel=2.0)  # the controller pushes (m 2 m/s^2) up to the contact
    world.set_ego_plan(plan)
    rows, measured = drive_with_spy(world, 3.0)
    assert world.crashed[0] and world.ego_on_plan
    impact = [r for r in rows if r[6]]
    after = [r for r in rows if r[2] and not r[6]]
    assert len(impact) >= 5 and len(after) > 300
    assert all(r[1] for r in impact)  # an impact is part of a pulse
    # Inside every impact: no controller force and no torque.
    assert all(np.all(r[3] == 0.0) for r in impact)
    # Pushing the braking wreck along, the ego stays in one long pulse (contact force
    # without a 10 ms gap) of forces about the tyre force, far below an impact's: its
    # controller stays on there.
    pressed = [r for r in after if r[1]]
    assert len(pressed) > 100 and all(np.linalg.norm(r[3][:2]) > 0.0 for r in pressed)
    # Outside impacts after the crash: exactly the tracking force towards the plan.
    masses, inertia = world.scene.masses[:1], world.scene.yaw_inertia[:1]
    for t, _, _, ctrl, qpos, qvel, _ in after:
        p, v, a, yaw, rate = plan.sample(t)
        expected = tracking_forces(
            world.control,
            masses,
            inertia,
            qpos[None],
            qvel[None],
            p[None],
            v[None],
            a[None],
            np.array([yaw]),
            np.array([rate]),
        )[0]
        np.testing.assert_allclose(ctrl, expected, rtol=1e-12, atol=1e-9)
    # The ego drives on: it pushes the wreck along at the plan's speed or close to it.
    assert world.scene.speeds()[0] > 5.0
    # The measured first impulse is the contact's alone: the centre-of-mass velocity
    # change from before the first contact to the end of the impact (the controller is
    # on right before and right after it) equals J1 / m within the one physics step the
    # controller acts before the contact is known (mu g dt).
    first = measured[0] if measured else world.finish()[0]
    start = next(i for i, r in enumerate(rows) if r[2])  # first step after the contact began
    end = next(i for i in range(start, len(rows)) if not rows[i][6])  # first step out of the impact
    assert np.linalg.norm(rows[start - 2][3][:2]) == pytest.approx(2.0 * masses[0], rel=0.05)  # on before
    full = world.control.friction_mu * GRAVITY * masses[0]
    assert np.linalg.norm(rows[end][3][:2]) == pytest.approx(
        full
    )  # and right after the impact (behind its plan)
    dv_com = np.linalg.norm(rows[end][5][:2] - rows[start - 2][5][:2])
    # Equal masses, the struck car at rest: dv = v (1 + e) / 2 (e along the normal).
    v_before = np.linalg.norm(first.a.velocity)
    assert first.a.dv_first == pytest.approx(v_before * (1 + first.restitution) / 2, rel=0.02)
    assert dv_com == pytest.approx(first.a.dv_first, abs=world.control.friction_mu * GRAVITY * world.scene.dt)


def test_the_measured_impulse_is_the_same_when_the_controller_is_on_outside_the_impact():
    # The same rear-end under continue, once with the controller cut for the whole pulse
    # and 10 ms after it (an impact threshold of ~0 and a hold of pulse_gap: the
    # definition before the impact threshold) and once with today's cut (contact forces
    # above IMPACT_ACCELERATION m, held 2 ms). The first impulse integrates contact
    # forces only; the controller (at most mu m g) can change the contact force only
    # through the motion in the ~4 ms pulse: |dJ1| / m <= mu g 4 ms = 0.035 m/s. The
    # first impulse is ~10 m/s here, so the bound is 0.35 %.
    results = {}
    for name, window in (
        ("whole pulse", MeasurementWindow(impact_acceleration=1e-9, impact_hold=0.01)),
        ("impact", MeasurementWindow()),
    ):
        world = World(rear_end("continue"))
        world.recorder.window = window
        world.set_ego_plan(cruise(world, accel=2.0))
        rows, measured = drive_with_spy(world, 2.5)
        first = measured[0] if measured else world.finish()[0]
        results[name] = (np.array(first.a.delta_v_first), rows)
        # Equal masses, the struck car at rest: J1 / m = v (1 + e) / 2 along the normal.
        v_before = np.linalg.norm(first.a.velocity)
        assert first.a.dv_first == pytest.approx(v_before * (1 + first.restitution) / 2, rel=0.02)
    (j_pulse, rows_pulse), (j_impact, rows_impact) = results["whole pulse"], results["impact"]
    cut = sum(1 for r in rows_pulse if r[6]), sum(1 for r in rows_impact if r[6])
    assert cut[1] < cut[0]  # the controller is on for part of what used to be cut
    mu_g = 0.9 * GRAVITY
    assert np.linalg.norm(j_impact - j_pulse) <= mu_g * 0.004


def test_an_impact_is_a_contact_force_above_the_threshold_within_the_hold():
    # Recomputed from the recorder's own force trace: the ego is in an impact exactly on
    # the steps within 2 ms after a contact force above 30 m/s^2 times its mass
    # (1475 kg: 44.25 kN).
    assert IMPACT_ACCELERATION == 30.0 and MeasurementWindow().impact_hold == 0.002
    world = World(rear_end("continue"))
    world.recorder.trace = True
    world.set_ego_plan(cruise(world, accel=2.0))
    flags, times = [], []
    for _ in range(2500):
        world.step()
        flags.append(bool(world.recorder.in_impact[0]))
        times.append(world.time - world.recorder._dt)  # the last (sub-)step's start
    world.finish()
    trace = np.concatenate(list(world.recorder.traces.values()))
    mass = world.scene.masses[0]
    assert mass == pytest.approx(1475.0)
    high = trace[np.hypot(trace[:, 1], trace[:, 2]) > 30.0 * mass, 0]
    assert high.size >= 3
    times = np.array(times)
    expected = np.array([bool(np.any((t - high >= -1e-12) & (t - high < 0.002))) for t in times])
    np.testing.assert_array_equal(np.array(flags), expected)


def test_brake_stops_following_the_plan_and_brakes_outside_impacts():
    world = World(rear_end())  # brake is the default
    assert world.post_crash is PostCrashPolicy.BRAKE
    world.set_ego_plan(cruise(world))
    rows, _ = drive_with_spy(world, 3.0)
    assert world.crashed[0] and not world.ego_on_plan
    impact = [r for r in rows if r[6]]
    after = [r for r in rows if r[2] and not r[6]]
    assert impact and all(np.all(r[3] == 0.0) for r in impact)
    assert len(after) > 1000
    mass, inertia = world.scene.masses[0], world.scene.yaw_inertia[0]
    mu_g, tau = world.control.friction_mu * GRAVITY, world.control.brake_time_constant
    for _, _, _, ctrl, _, qvel, _ in after:
        speed = math.hypot(qvel[0], qvel[1])
        decel = min(mu_g, speed / tau)  # brakes at mu g, gently near rest
        np.testing.assert_allclose(ctrl[:2], -mass * decel * qvel[:2] / max(speed, 1e-9), atol=1e-6)
        np.testing.assert_allclose(ctrl[2], -inertia * np.clip(qvel[2] / tau, -40.0, 40.0), atol=1e-6)
    assert world.scene.speeds()[0] < 0.05  # at rest, although the plan goes on at 15 m/s


def test_the_run_configuration_replaces_the_scenario_policy():
    assert World(rear_end("continue"), post_crash="brake").post_crash is PostCrashPolicy.BRAKE
    assert World(rear_end("brake")).post_crash is PostCrashPolicy.BRAKE
    loop = closed_loop(rear_end("brake"), "keep_lane", config=RunConfig(post_crash="continue"))
    assert loop.world.post_crash is PostCrashPolicy.CONTINUE


class _CycleTimes(Metric):
    def start(self, run):
        self.times = []

    def on_cycle(self, run, plan: Plan):
        self.times.append(run.world.time)

    def values(self, run):
        return {"cycle_times": self.times}


@pytest.mark.parametrize("policy", ["brake", "continue"])
def test_the_loop_replans_after_contact_only_under_continue(policy):
    cycles = _CycleTimes()
    config = RunConfig()
    summary = run_scenario(
        rear_end(policy, duration=3.0),
        "keep_lane",
        config=config,
        metrics=(*default_metrics(config), cycles),
    )
    assert summary.outcome == "crash" and summary.ego_collisions
    assert summary.post_crash == policy  # the summary says which policy applied
    crash = summary.collisions[0].measurement.time
    later = [t for t in cycles.times if t > crash]
    if policy == "brake":
        assert later == []
    else:
        # On the 10 Hz grid, plus once right when the ego comes out of an impact pulse.
        off_grid = [t for t in later if abs(t * 10 - round(t * 10)) > 1e-6]
        assert off_grid and min(off_grid) < crash + 0.1
        assert max(later) > 2.5


def test_the_policy_is_validated_naming_the_field(tmp_path):
    with pytest.raises(
        ValueError, match=r"ego\.post_crash: unknown post-crash policy 'stop'; allowed: brake, continue"
    ):
        rear_end("stop")
    with pytest.raises(ValueError, match=r"run\.post_crash: unknown post-crash policy"):
        RunConfig(post_crash="coast")
    path = tmp_path / "bad.toml"
    path.write_text('name = "bad"\n[ego]\npost_crash = 1\n')
    with pytest.raises(ValueError, match=r"bad\.toml.*ego\.post_crash"):
        load_scenario(path)
    assert rear_end("continue").ego.post_crash == "continue"


def test_scrape_wall_for_child_the_ethical_planner_passes_the_child_along_the_wall():
    # With no valid candidate left (from 1.7 s), the planner leaves the road (level 2)
    # rather than hit the child (level 1). It judges a road-leaving plan where the wall
    # holds the car (``ethical_planner.boundary``): a plan through the wall is pressed
    # against it, turned as planned, its rear swung towards the child, so the plan it
    # keeps runs along the wall's face and brakes. Measured, seed 0: no contact at all,
    # 0.225 m from the child; both policies are the same run (no contact to follow).
    scenario = dataclasses.replace(get_scenario("scrape_wall_for_child"), duration=4.0)
    assert scenario.ego.post_crash is PostCrashPolicy.CONTINUE
    run = run_scenario(scenario, "ethical")
    assert run.collisions == ()
    assert run.clearance_vulnerable["child"] > 0.15
    assert run.progress > 65.0  # past the child (at s = 63 m)
    assert run.verdict == "pass"  # [expect] max_vulnerable_harm = 0


# ----------------------------------------------------------------- rear_ended_at_red_light


@pytest.fixture(scope="module")
def rear_ended():
    """rear_ended_at_red_light (selfish, its first 4.2 s) under both policies.

    Returns:
        policy -> (summary, world, spied rows).
    """
    scenario = dataclasses.replace(get_scenario("rear_ended_at_red_light"), duration=4.2)
    assert scenario.ego.post_crash is PostCrashPolicy.CONTINUE
    out = {}
    for policy in ("continue", "brake"):
        loop = closed_loop(scenario, "selfish", config=RunConfig(post_crash=policy))
        rows = spy_on_physics_steps(loop.world)
        out[policy] = (loop.execute(), loop.world, rows)
    return out


@pytest.mark.parametrize("policy", ["continue", "brake"])
def test_rear_ended_at_red_light_the_follower_strikes_once_and_no_one_else_is_touched(rear_ended, policy):
    summary, world, _ = rear_ended[policy]
    assert summary.post_crash == policy
    (hit,) = summary.ego_collisions  # no second impact: not pushed into the people crossing
    assert summary.collisions == (hit,)
    m = hit.measurement
    assert m.b.entity == 1 and world.scene.names[1] == "follower"
    assert m.a.reduced_area == "rear" and m.b.reduced_area == "front"
    # The follower drives into the standing ego (its approach speed ~3 m/s, the ego's ~0):
    # struck_from_behind, not the ego's own.
    assert approach_speed(m.b, m.contact_position) == pytest.approx(3.0, abs=0.4)
    assert abs(approach_speed(m.a, m.contact_position)) < 0.3
    behaviours = {b.id: b.behaviour for b in summary.bodies}
    assert attribute(hit, behaviours) == "struck_from_behind"
    assert not ego_strikes(hit)
    assert summary.harm["vulnerable"] == 0.0
    assert min(summary.clearance_vulnerable.values()) > 2.0


@pytest.mark.parametrize("policy", ["continue", "brake"])
def test_rear_ended_at_red_light_the_measured_delta_v_excludes_the_controller(rear_ended, policy):
    summary, world, rows = rear_ended[policy]
    (hit,) = summary.ego_collisions
    impact = [r for r in rows if r[6]]
    assert len(impact) >= 3 and all(np.all(r[3] == 0.0) for r in impact)  # no controller force inside
    # The first impulse's J1 / m against the ego's centre-of-mass velocity change from
    # before the contact to the end of the impact: equal within the one physics step in
    # which the controller acts before the contact is known (mu g dt), so no controller
    # force is in the measured delta-v.
    start = next(i for i, r in enumerate(rows) if r[2])
    end = next(i for i in range(start, len(rows)) if not rows[i][6])
    dv_com = np.linalg.norm(rows[end][5][:2] - rows[start - 2][5][:2])
    mu_g_dt = world.control.friction_mu * GRAVITY * world.scene.dt
    assert hit.measurement.a.dv_first == pytest.approx(dv_com, abs=mu_g_dt)
    # One impulse J1 on both: m_ego dv_ego = m_car dv_car.
    m_ego, m_car = world.scene.masses[0], world.scene.masses[1]
    assert hit.measurement.a.dv_first * m_ego == pytest.approx(hit.measurement.b.dv_first * m_car, rel=1e-6)


def test_rear_ended_at_red_light_only_continue_keeps_the_ego_on_its_plans(rear_ended):
    cont, world_c, rows_c = rear_ended["continue"]
    brake, world_b, rows_b = rear_ended["brake"]
    crash = cont.ego_collisions[0].measurement.time
    assert brake.ego_collisions[0].measurement.time == pytest.approx(crash)  # the same contact
    assert world_c.ego_on_plan and not world_b.ego_on_plan
    # After the impact, under brake: -m decel v / |v| (brakes at up to mu g); under
    # continue the tracking force towards the plan (the ego standing at the red line: it
    # holds it there, it does not brake along its velocity).
    mass, mu_g, tau = (
        world_b.scene.masses[0],
        world_b.control.friction_mu * GRAVITY,
        world_b.control.brake_time_constant,
    )
    after_b = [r for r in rows_b if r[2] and not r[6]]
    assert len(after_b) > 500
    for _, _, _, ctrl, _, qvel, _ in after_b:
        speed = math.hypot(qvel[0], qvel[1])
        np.testing.assert_allclose(
            ctrl[:2], -mass * min(mu_g, speed / tau) * qvel[:2] / max(speed, 1e-9), atol=1e-6
        )
    assert world_b.scene.speeds()[0] < 0.1  # at rest 0.85 s after the impact
    # Pushed at about 1.8 m/s, the ego stops before the line (its front was 1 m before
    # it) under either policy: no red-light crossing, the people crossing untouched.
    line = get_scenario("rear_ended_at_red_light").stop_lines[0].s
    for world, run in ((world_c, cont), (world_b, brake)):
        front = world.positions[0][0] + 0.5 * world.scene.bodies[0].length  # the road runs along +x from 0
        assert front < line and run.rule_violations == ()


@pytest.mark.slow
def test_rear_ended_at_red_light_continue_drives_on_at_green_and_brake_stays():
    # The whole catalog scenario with the ethical planner (26 s for both, idle machine).
    scenario = get_scenario("rear_ended_at_red_light")
    runs = {
        p: run_scenario(scenario, "ethical", config=RunConfig(post_crash=p)) for p in ("continue", "brake")
    }
    cont, brake = runs["continue"], runs["brake"]
    assert cont.verdict == "pass"
    assert cont.outcome == "crash" and "10.0 s after it" in cont.reason  # PostCrashTime, not at rest
    line = scenario.stop_lines[0].s
    assert cont.progress > line + 30.0
    assert brake.outcome == "crash" and "come to rest" in brake.reason
    assert brake.progress < line
    assert [r.name for r in brake.expectations if not r.passed] == ["min_progress"]
