"""Planar impulse model against hand-computed impacts and physical laws."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ethical_planner.impulse import (
    DeltaVModel,
    RestitutionLaw,
    contact_geometry,
    planar_impulse,
    yaw_inertia,
)

CAR = (4.5, 1.8)


def car_inertia(m, length=4.5, width=1.8):
    return m * (length**2 + width**2) / 12.0


def test_restitution_law_limits_and_validation():
    law = RestitutionLaw(e_high=0.1, e_low=0.4, speed_scale=4.0)
    assert float(law(0.0)) == pytest.approx(0.4)
    assert float(law(4.0)) == pytest.approx(0.1 + 0.3 / math.e)
    assert float(law(100.0)) == pytest.approx(0.1, abs=1e-9)
    assert float(law(-4.0)) == float(law(4.0))
    assert float(RestitutionLaw.constant(0.2)(7.0)) == 0.2
    with pytest.raises(ValueError, match="restitution_law.e_low must lie in"):
        RestitutionLaw(e_low=1.5)
    with pytest.raises(ValueError, match="restitution_law.speed_scale must be > 0"):
        RestitutionLaw(speed_scale=0.0)
    assert DeltaVModel.parse("planar_impulse") is DeltaVModel.PLANAR_IMPULSE
    with pytest.raises(ValueError, match="allowed: eq1, planar_impulse"):
        DeltaVModel.parse("eq2")


def test_yaw_inertia_of_rectangles_and_discs():
    assert float(yaw_inertia(1200.0, 4.5, 1.8)) == pytest.approx(1200 * (4.5**2 + 1.8**2) / 12)
    assert float(yaw_inertia(75.0, 0.5, 0.5, True)) == pytest.approx(0.5 * 75 * 0.25**2)


@pytest.mark.parametrize("e", [0.0, 0.1, 0.4])
@pytest.mark.parametrize(
    ("m_a", "m_b", "v_a", "v_b"), [(1500, 1500, 10, -10), (1500, 25000, 20, -5), (1500, 1500, 20, 5)]
)
def test_central_collinear_is_eq1_times_one_plus_e(e, m_a, m_b, v_a, v_b):
    result = planar_impulse(
        m_a, (0.0, 0.0), 0.0, *CAR, (v_a, 0.0),
        m_b, (6.0, 0.0), 0.0 if v_b > 0 else math.pi, *CAR, (v_b, 0.0),
        RestitutionLaw.constant(e), friction=math.inf,
    )  # fmt: skip
    closing = abs(v_a - v_b)
    assert float(result.dv_a) == pytest.approx((1 + e) * m_b / (m_a + m_b) * closing, rel=1e-12)
    assert float(result.dv_b) == pytest.approx((1 + e) * m_a / (m_a + m_b) * closing, rel=1e-12)
    np.testing.assert_allclose(result.geometry.normal, [1.0, 0.0], atol=1e-12)
    assert float(result.impulse_ratio) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("friction", [0.0, 0.3, math.inf])
def test_t_bone_at_the_centre_of_mass(friction):
    """a's front face hits the middle of b's side; b stands still.

    Both centres lie on the contact normal: no lever arm, no tangential relative motion,
    so any friction gives Eq. 1 x (1 + e): dv_a = (1 + e) m_b / (m_a + m_b) v.
    """
    m_a, m_b, v, e = 1500.0, 1100.0, 12.0, 0.15
    result = planar_impulse(
        m_a, (0.0, 0.0), 0.0, *CAR, (v, 0.0),
        m_b, (2.25 + 0.9, 0.0), math.pi / 2, *CAR, (0.0, 0.0),
        RestitutionLaw.constant(e), friction,
    )  # fmt: skip
    assert float(result.dv_a) == pytest.approx((1 + e) * m_b / (m_a + m_b) * v, rel=1e-12)
    np.testing.assert_allclose(result.point, [2.25, 0.0], atol=1e-12)


def test_t_bone_at_the_centre_of_mass_into_a_sliding_car_frictionless():
    """b moves along its own axis (sideways for a): without friction only the normal part counts."""
    m_a, m_b, e = 1500.0, 1100.0, 0.1
    result = planar_impulse(
        m_a, (0.0, 0.0), 0.0, *CAR, (10.0, 0.0),
        m_b, (3.15, 0.0), math.pi / 2, *CAR, (0.0, 6.0),
        RestitutionLaw.constant(e), friction=0.0,
    )  # fmt: skip
    p_n = (1 + e) * 10.0 / (1 / m_a + 1 / m_b)
    assert float(result.dv_a) == pytest.approx(p_n / m_a, rel=1e-12)
    np.testing.assert_allclose(result.impulse, [p_n, 0.0], atol=1e-6)
    # Eq. 1 would use |v_a - v_b| = sqrt(136) m/s and a common final velocity.
    assert float(result.dv_a) < m_b / (m_a + m_b) * math.sqrt(136.0)


def test_offset_hit_on_a_corner_with_a_known_lever_arm():
    """A stationary car turned 45 deg presents a corner to a's front face, 0.6 m left of a's axis.

    Point contact on a's face: n = x, lever arms r_a = (2.25, 0.6) and r_b = corner -
    centre. Frictionless: P_n = (1 + e) v / (1/m_a + 1/m_b + r_at^2/I_a + r_bt^2/I_b).
    """
    m_a, m_b, v, e = 1500.0, 1300.0, 15.0, 0.1
    yaw_b = math.pi / 4
    c, s = math.cos(yaw_b), math.sin(yaw_b)
    # b's corner furthest in -x: local (-2.25, +0.9) or (-2.25, -0.9); with yaw 45 deg it is (-2.25, +0.9).
    corner_local = np.array([-2.25, 0.9])
    corner_offset = np.array(
        [c * corner_local[0] - s * corner_local[1], s * corner_local[0] + c * corner_local[1]]
    )
    assert corner_offset[0] == pytest.approx(min(c * x - s * y for x in (-2.25, 2.25) for y in (-0.9, 0.9)))
    centre_b = np.array([2.25, 0.6]) - corner_offset  # the corner touches a's face at y = 0.6
    result = planar_impulse(
        m_a, (0.0, 0.0), 0.0, *CAR, (v, 0.0), m_b, centre_b, yaw_b, *CAR, (0.0, 0.0),
        RestitutionLaw.constant(e), friction=0.0,
    )  # fmt: skip
    np.testing.assert_allclose(result.point, [2.25, 0.6], atol=1e-9)
    np.testing.assert_allclose(result.geometry.normal, [1.0, 0.0], atol=1e-12)
    r_bt = 0.6 - centre_b[1]
    k_nn = 1 / m_a + 1 / m_b + 0.6**2 / car_inertia(m_a) + r_bt**2 / car_inertia(m_b)
    assert float(result.dv_a) == pytest.approx((1 + e) * v / k_nn / m_a, rel=1e-12)


def test_offset_hit_on_a_pedestrian_with_stick():
    """A pedestrian (disc) 0.5 m left of the car's axis, hit by its front face; full stick.

    Lever arms r_a = (2.25, 0.5), r_b = (-rho, 0): a 2 x 2 system, solved here by hand.
    """
    m_a, m_b, v, e, rho = 1500.0, 75.0, 10.0, 0.1, 0.25
    i_a, i_b = car_inertia(m_a), 0.5 * m_b * rho**2
    result = planar_impulse(
        m_a, (0.0, 0.0), 0.0, *CAR, (v, 0.0), m_b, (2.25 + rho, 0.5), 0.0, 0.5, 0.5, (0.0, 0.0),
        RestitutionLaw.constant(e), friction=math.inf, round_b=True,
    )  # fmt: skip
    np.testing.assert_allclose(result.point, [2.25, 0.5], atol=1e-9)
    inv = 1 / m_a + 1 / m_b
    k_nn = inv + 0.5**2 / i_a
    k_tt = inv + 2.25**2 / i_a + rho**2 / i_b
    k_nt = -(2.25 * 0.5 / i_a + (-rho) * 0.0 / i_b)
    target_n, target_t = (1 + e) * v, 0.0
    det = k_nn * k_tt - k_nt**2
    p_n = (k_tt * target_n - k_nt * target_t) / det
    p_t = (k_nn * target_t - k_nt * target_n) / det
    assert float(result.dv_b) == pytest.approx(math.hypot(p_n, p_t) / m_b, rel=1e-12)


def test_sliding_uses_the_impulse_ratio():
    """Stick would need |P_t| / P_n > friction: the bodies slide at exactly that ratio."""
    law = RestitutionLaw.constant(0.1)
    args = (1500.0, (0.0, 0.0), 0.0, *CAR, (10.0, 0.0), 1100.0, (3.15, 0.0), math.pi / 2, *CAR, (0.0, 8.0))
    stick = planar_impulse(*args, law, friction=math.inf)
    assert float(stick.impulse_ratio) > 0.3
    slide = planar_impulse(*args, law, friction=0.3)
    assert bool(slide.sliding) and float(slide.impulse_ratio) == pytest.approx(0.3)
    # Normal condition: P_n = (1 + e) u_n / (K_nn + s mu K_nt); K_nt = 0 here (centres on the normal).
    p_n = 1.1 * 10.0 / (1 / 1500 + 1 / 1100)
    assert float(slide.dv_a) == pytest.approx(p_n * math.hypot(1, 0.3) / 1500, rel=1e-12)


def test_flat_t_bone_at_the_rear_axle_acts_at_the_near_end():
    """The ego's front face (1.61 m) hits a stationary car's side 1.35 m behind its centre.

    As the struck car spins, the far end of the contact swings away: the impulse acts at
    the end nearer its centre (0.805 m left of the ego's axis; the rigid simulation finds
    the same, see tests/mujoco_world/physics/test_named_impacts.py).
    """
    result = planar_impulse(
        1475.0, (0.0, 0.0), 0.0, 4.508, 1.61, (20.0, 0.0),
        1475.0, (2.254 + 0.9, 1.35), math.pi / 2, *CAR, (0.0, 0.0),
        RestitutionLaw.constant(0.1), friction=math.inf,
    )  # fmt: skip
    assert float(result.geometry.half_length) == pytest.approx(0.805)
    np.testing.assert_allclose(result.point, [2.254, 0.805], atol=1e-9)


def test_symmetric_flat_contact_acts_in_the_middle():
    """Offset head-on of equal cars (50 % overlap): both ends share the impulse equally."""
    result = planar_impulse(
        1500.0, (0.0, 0.0), 0.0, *CAR, (10.0, 0.0), 1500.0, (4.5, 0.9), math.pi, *CAR, (-10.0, 0.0),
        RestitutionLaw.constant(0.1), friction=math.inf,
    )  # fmt: skip
    np.testing.assert_allclose(result.point, [2.25, 0.45], atol=1e-9)


def test_first_touch_does_not_depend_on_the_step_it_is_seen_at():
    """States moved along the relative velocity (before contact or overlapping) give one contact."""
    base = dict(pos_a=(0.0, 0.0), yaw_a=0.1, length_a=4.5, width_a=1.8, vel_a=(12.0, 1.0),
                yaw_b=2.0, length_b=4.5, width_b=1.8, vel_b=(-3.0, 6.0))  # fmt: skip
    w = np.subtract(base["vel_b"], base["vel_a"])
    ref = contact_geometry(pos_b=(4.0, 1.0), **base)
    for lam in (-0.15, -0.05, 0.05):
        moved = contact_geometry(pos_b=tuple(np.array([4.0, 1.0]) + lam * w), **base)
        np.testing.assert_allclose(moved.point, ref.point, atol=1e-9)
        np.testing.assert_allclose(moved.normal, ref.normal, atol=1e-12)


def test_a_missing_approach_is_moved_onto_the_grazing_line():
    geo = contact_geometry((0, 0), 0.0, *CAR, (10.0, 0.0), (8.0, 3.0), math.pi, *CAR, (-10.0, 0.0))
    assert bool(geo.grazing)
    np.testing.assert_allclose(geo.offset_b[1], 1.8, atol=1e-6)  # sum of half-widths
    np.testing.assert_allclose(geo.point, [2.25, 0.9], atol=1e-6)  # corner to corner


def test_no_relative_motion_no_impulse():
    result = planar_impulse(1500, (0, 0), 0.0, *CAR, (5.0, 0.0), 1500, (4.6, 0.0), 0.0, *CAR, (5.0, 0.0))
    assert float(result.dv_a) == 0.0 and float(result.dv_b) == 0.0


def test_vectorised_equals_one_by_one():
    rng = np.random.default_rng(3)
    n = 40
    args = dict(
        mass_a=rng.uniform(800, 2000, n), pos_a=rng.normal(0, 1, (n, 2)), yaw_a=rng.uniform(-3, 3, n),
        length_a=rng.uniform(3.5, 5.0, n), width_a=rng.uniform(1.5, 2.0, n), vel_a=rng.normal(0, 8, (n, 2)),
        mass_b=rng.uniform(60, 25000, n), pos_b=rng.normal(0, 1, (n, 2)) + [6.0, 0.0],
        yaw_b=rng.uniform(-3, 3, n),
        length_b=rng.uniform(0.5, 12, n), width_b=rng.uniform(0.5, 2.5, n), vel_b=rng.normal(0, 8, (n, 2)),
        round_b=rng.random(n) < 0.3,
    )  # fmt: skip
    law = RestitutionLaw()
    together = planar_impulse(**args, restitution=law, friction=0.3)
    for k in range(n):
        one = planar_impulse(**{key: value[k] for key, value in args.items()}, restitution=law, friction=0.3)
        assert float(one.dv_a) == pytest.approx(float(together.dv_a[k]), rel=1e-9, abs=1e-12)
        np.testing.assert_allclose(one.point, together.point[k], atol=1e-9)
    # Broadcasting like the planner: ego (n, 1, t) against road users (1, k, t).
    ego = planar_impulse(
        1500.0, np.zeros((3, 1, 4, 2)), np.zeros((3, 1, 4)), 4.5, 1.8, np.full((3, 1, 4, 2), [10.0, 0.0]),
        np.array([1500.0, 75.0])[None, :, None], np.full((1, 2, 4, 2), [6.0, 0.0]), np.zeros((1, 2, 4)),
        np.array([4.5, 0.5])[None, :, None], np.array([1.8, 0.5])[None, :, None], np.zeros((1, 2, 4, 2)),
        round_b=np.array([False, True])[None, :, None],
    )  # fmt: skip
    assert ego.dv_a.shape == (3, 2, 4)


@settings(max_examples=200, deadline=None)
@given(
    yaw_b=st.floats(-math.pi, math.pi),
    y_b=st.floats(-2.0, 2.0),
    vx_b=st.floats(-15, 15),
    vy_b=st.floats(-15, 15),
    m_b=st.floats(60.0, 30000.0),
    e=st.floats(0.0, 0.6),
    friction=st.sampled_from([0.0, 0.3, 1.0, math.inf]),
    round_b=st.booleans(),
)
def test_energy_is_never_created_and_momentum_is_kept(yaw_b, y_b, vx_b, vy_b, m_b, e, friction, round_b):
    """For e <= 0.6 (vehicle crashes: ~0.1); near e = 1 Newton's restitution with friction
    can gain energy (Kane's paradox), a known limit of the kinematic coefficient."""
    m_a = 1500.0
    va, vb = np.array([12.0, 0.0]), np.array([vx_b, vy_b])
    lb, wb = (0.6, 0.6) if round_b else (4.5, 1.8)
    result = planar_impulse(m_a, (0.0, 0.0), 0.0, *CAR, va, m_b, (6.0, y_b), yaw_b, lb, wb, vb,
                            RestitutionLaw.constant(e), friction, round_b=round_b)  # fmt: skip
    p = np.asarray(result.impulse)
    ra = np.asarray(result.point)
    rb = ra - np.asarray(result.geometry.offset_b)
    i_a, i_b = car_inertia(m_a), float(yaw_inertia(m_b, lb, wb, round_b))
    va2, vb2 = va - p / m_a, vb + p / m_b
    wa2 = -(ra[0] * p[1] - ra[1] * p[0]) / i_a
    wb2 = (rb[0] * p[1] - rb[1] * p[0]) / i_b
    before = 0.5 * m_a * va @ va + 0.5 * m_b * vb @ vb
    after = 0.5 * m_a * va2 @ va2 + 0.5 * m_b * vb2 @ vb2 + 0.5 * i_a * wa2**2 + 0.5 * i_b * wb2**2
    assert after <= before * (1 + 1e-9) + 1e-6
    assert float(result.dv_a) * m_a == pytest.approx(float(result.dv_b) * m_b, rel=1e-9)
