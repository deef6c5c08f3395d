"""Tracking control: the heading error uses the project's one angle convention."""

import math

import numpy as np
import pytest

from mujoco_world.physics.control import ControlConfig, tracking_forces


def _torque(yaw, yaw_ref, inertia=2.0):
    config = ControlConfig()
    out = tracking_forces(
        config,
        mass=np.array([1000.0]),
        inertia=np.array([inertia]),
        qpos=np.array([[0.0, 0.0, yaw]]),
        qvel=np.zeros((1, 3)),
        p_ref=np.zeros((1, 2)),
        v_ref=np.zeros((1, 2)),
        a_ref=np.zeros((1, 2)),
        yaw_ref=np.array([yaw_ref]),
        yaw_rate_ref=np.zeros(1),
    )
    return float(out[0, 2])


def test_heading_error_takes_the_short_way_round():
    # kp_yaw = 400 1/s^2, inertia 2 kg m^2: 0.01 rad of error asks for 8 N m.
    assert _torque(0.0, 0.01) == pytest.approx(8.0)
    assert _torque(0.0, -0.01) == pytest.approx(-8.0)
    # 0.01 rad across the +-pi seam: still the short way (not 2 pi - 0.01 the other way)
    assert _torque(math.pi - 0.005, -math.pi + 0.005) == pytest.approx(8.0)
    assert _torque(-math.pi + 0.005, math.pi - 0.005) == pytest.approx(-8.0)


def test_heading_error_of_exactly_pi_turns_counter_clockwise():
    # (-pi, pi]: an error of +pi or -pi is +pi, the torque limit (40 rad/s^2) times inertia.
    assert _torque(0.0, math.pi) == pytest.approx(80.0)
    assert _torque(math.pi, 0.0) == pytest.approx(80.0)
