"""Crush mode: realistic crash pulses from force-deflection curves per body region."""

import math

import numpy as np
import pytest

from ethical_planner.impulse import RestitutionLaw
from ethical_planner.road_users import KinematicState
from harm_calibration.pulses import KMH, crash_pulses
from mujoco_world.physics.contact import CRUSH_REGIONS
from mujoco_world.physics.impact import measure_impact
from mujoco_world.scenario.spec import ContactSpec

CRUSH = ContactSpec(mode="crush")


@pytest.fixture(scope="module")
def pulses():
    return {(p.name, p.mode): p for p in crash_pulses()}


def test_frontal_crash_into_a_wall_at_56_km_h(pulses):
    """0.5-0.7 m of crush, a pulse of 60-110 ms, 25-50 g at most, highest mid-pulse."""
    p = pulses[("car into a wall, 56 km/h", "crush")]
    assert 0.5 <= p.max_crush <= 0.7
    assert 0.06 <= p.duration <= 0.11
    assert 25.0 <= p.peak_g <= 50.0
    peak = p.force.max()
    middle = np.interp(0.5 * p.duration, p.time, p.force)
    start = p.force[p.time < 0.1 * p.duration].max()
    assert middle >= 0.95 * peak and start < 0.5 * peak
    assert p.restitution == pytest.approx(float(RestitutionLaw()(56 * KMH)), abs=0.02)
    # The rigid mode's pulse of the same impact lasts a few milliseconds.
    rigid = pulses[("car into a wall, 56 km/h", "rigid")]
    assert rigid.duration < 0.01 and rigid.max_crush < 0.02
    assert rigid.dv == pytest.approx(p.dv, rel=0.01)  # same restitution, same delta-v


def test_two_cars_head_on_crush_twice_as_deep(pulses):
    wall = pulses[("car into a wall, 56 km/h", "crush")]
    head_on = pulses[("two cars head-on, 56 km/h each", "crush")]
    assert head_on.max_crush == pytest.approx(2 * wall.max_crush, rel=0.05)
    assert head_on.peak_g == pytest.approx(wall.peak_g, rel=0.05)


def test_pedestrians_are_softer_and_reach_the_cars_speed(pulses):
    p = pulses[("car into a pedestrian, 40 km/h", "crush")]
    assert p.duration > 0.06  # a long, soft push, not a rigid knock
    m = measure_impact("car", KinematicState(0, 0, 0, 40 * KMH), "pedestrian",
                       KinematicState(2.55, 0.3, 0.5 * math.pi, 0.0), contact=CRUSH)  # fmt: skip
    e = m.restitution
    expected = (1 + e) * m.a.mass / (m.a.mass + m.b.mass) * 40 * KMH
    assert 0.0 <= e <= 0.3
    assert m.b.dv_impulse == pytest.approx(expected, rel=0.05)


def test_crush_regions_are_softer_at_the_side_and_for_vulnerable_road_users():
    front, side = CRUSH_REGIONS[("vehicle", "front")], CRUSH_REGIONS[("vehicle", "side")]
    assert side.yield_force < front.yield_force and side.yield_crush < front.yield_crush
    vulnerable = CRUSH_REGIONS[("unprotected", "front")]
    # Per kilogram of the body: a pedestrian (75 kg) is 40 times softer than a car (1475 kg).
    assert vulnerable.stiffness * 75.0 < 0.05 * front.stiffness * 1475.0
    assert vulnerable.yield_crush > front.yield_crush


@pytest.mark.parametrize(
    ("partner", "state_b"),
    [
        ("car", KinematicState(4.6, 0.9, math.pi, 13.9)),  # offset frontal at 50 km/h each
        ("car", KinematicState(3.2, 0.0, 0.5 * math.pi, 0.0)),  # T-bone
        ("truck", KinematicState(5.96, 0.0, 0.5 * math.pi, 0.0)),
        ("bicycle", KinematicState(2.6, 0.0, 0.5 * math.pi, 0.0)),
    ],
)
def test_deep_crush_stays_stable(partner, state_b):
    """Deep overlaps keep the first touch's normal: no sideways escape, restitution near the law."""
    m = measure_impact("car", KinematicState(0, 0, 0, 13.9), partner, state_b, contact=CRUSH)
    assert m.complete and m.n_impulses == 1
    assert 0.0 <= m.restitution <= 0.3
    assert m.max_penetration < 1.5


def _kinetic_energy(body, velocity, yaw_rate) -> float:
    """Translational plus yaw kinetic energy [J] of a rectangular body."""
    inertia = body.mass * (body.length**2 + body.width**2) / 12.0
    return 0.5 * body.mass * float(np.dot(velocity, velocity)) + 0.5 * inertia * yaw_rate**2


def test_a_t_bone_at_the_rear_axle_creates_no_energy():
    """The struck car spins during the 0.1 s pulse; a deflection read along the turning
    normal grew with the spin and pushed the bodies apart (restitution 1.85, dv +106 %)."""
    struck = KinematicState(3.204, 1.35, 0.5 * math.pi, 0.0)  # side at the ego's front, rear axle ahead
    m = measure_impact("car", KinematicState(0, 0, 0, 20.0), "car", struck, contact=CRUSH, brake=False)
    before = sum(_kinetic_energy(b, np.array(b.velocity), b.yaw_rate) for b in (m.a, m.b))
    after = sum(_kinetic_energy(b, np.array(b.velocity_after), b.yaw_rate_after) for b in (m.a, m.b))
    assert after < before
    assert 0.0 <= m.restitution <= 0.3
