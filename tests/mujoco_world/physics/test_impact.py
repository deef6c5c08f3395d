"""Impact measurement: contact modes, the measurement window, restitution, force direction."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ethical_planner.harm import delta_v
from ethical_planner.impulse import RestitutionLaw
from ethical_planner.road_users import KinematicState
from mujoco_world.evaluation.compare import compare_impact
from mujoco_world.physics.contact import (
    MODES,
    dampratio_for_restitution,
    hunt_crossley_damping,
    restitution_dampratio,
    restitution_range,
)
from mujoco_world.physics.impact import ImpactRecorder, ImpactRig, MeasurementWindow, measure_impact
from mujoco_world.physics.scene import BodyProxy, Scene
from mujoco_world.scenario.road import StaticBox
from mujoco_world.scenario.spec import Boundary, ContactMode, ContactSpec, RestitutionSpec


def plastic(m):
    """Eq. 1 delta-v of both bodies from the measured pre-impact velocities."""
    dv_a, dv_b = delta_v(m.a.mass, m.b.mass, np.array(m.a.velocity), np.array(m.b.velocity))
    return float(dv_a), float(dv_b)


def closing_speed(m):
    return float(np.hypot(*np.subtract(m.a.velocity, m.b.velocity)))


CASES = {
    # name: (type a, state a, type b, state b)
    "head_on": ("car", KinematicState(0.0, 0.0, 0.0, 15.0), "car", KinematicState(6.0, 0.0, math.pi, 15.0)),
    "rear_end": ("car", KinematicState(0.0, 0.0, 0.0, 20.0), "car", KinematicState(6.0, 0.0, 0.0, 5.0)),
    "car_pedestrian": (
        "car",
        KinematicState(0.0, 0.0, 0.0, 12.0),
        "pedestrian",
        KinematicState(3.0, 0.0, math.pi / 2, 1.4),
    ),
    "truck_car": (
        "truck",
        KinematicState(0.0, 0.0, 0.0, 15.0),
        "car",
        KinematicState(9.0, 0.0, math.pi, 10.0),
    ),
    "car_bicycle_rear": (
        "car",
        KinematicState(0.0, 0.0, 0.0, 14.0),
        "bicycle",
        KinematicState(4.0, 0.0, 0.0, 5.0),
    ),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_collinear_impacts_are_eq1_times_one_plus_e(name):
    """Rigid contact: central collinear impacts give Eq. 1 x (1 + e), e from the restitution law."""
    type_a, state_a, type_b, state_b = CASES[name]
    m = measure_impact(type_a, state_a, type_b, state_b, brake=False)
    assert m is not None and m.complete and not m.multi_body and not m.multi_impact
    dv_a, dv_b = plastic(m)
    law = RestitutionLaw()
    # Measured at the contact point along the normal, close to the law at the closing speed.
    assert m.restitution == pytest.approx(float(law(closing_speed(m))), abs=0.02)
    assert m.a.dv_impulse == pytest.approx((1 + m.restitution) * dv_a, rel=0.01)
    assert m.b.dv_impulse == pytest.approx((1 + m.restitution) * dv_b, rel=0.01)
    # Impulse and centre-of-mass velocity change agree (no other force acts in the rig).
    assert m.a.dv_com == pytest.approx(m.a.dv_impulse, abs=1e-3)
    assert m.b.dv_com == pytest.approx(m.b.dv_impulse, abs=1e-3)
    # Newton's third law: equal and opposite impulses.
    assert m.a.mass * m.a.dv_impulse == pytest.approx(m.b.mass * m.b.dv_impulse, rel=1e-9)
    assert m.a.dv_first == pytest.approx(m.a.dv_impulse)


def test_head_on_geometry_front_to_front():
    m = measure_impact(*CASES["head_on"])
    for body in (m.a, m.b):
        assert body.reduced_area == "front"
        assert body.clock_area == 12
        assert body.force_clock == 12
    assert m.peak_force > 1e6
    assert m.duration < 0.02  # a rigid pulse lasts a few milliseconds
    assert m.n_impulses == 1


def test_rear_end_areas_and_force_direction():
    m = measure_impact(*CASES["rear_end"])
    assert (m.a.reduced_area, m.b.reduced_area) == ("front", "rear")
    assert (m.a.force_clock, m.b.force_clock) == (12, 6)
    assert m.a.delta_v_impulse[0] < 0 < m.b.delta_v_impulse[0]


def test_pedestrian_hit_from_its_left_side():
    m = measure_impact(*CASES["car_pedestrian"])
    # The pedestrian walks north (+y); the car comes from the west, i.e. its left.
    assert m.b.reduced_area == "driver_side"
    assert m.b.clock_area == 9
    record = compare_impact(m)
    assert record.b.model == "pedestrian_mais3"
    assert record.a.model == "ignore_angle"
    assert record.b.dv_error == pytest.approx(m.restitution, abs=0.02)  # Eq. 1 x (1 + e)
    assert record.b.dv_error_planar == pytest.approx(0.0, abs=0.02)


def test_t_bone_into_a_moving_car_documents_the_oblique_gap():
    """A T-bone into a moving car: Eq. 1 assumes a common final velocity, sideways too.

    The struck car slides along the striking car's front: the measured delta-v is far
    below Eq. 1 (about 22% lower); the planar impulse model gets it within 2%.
    """
    m = measure_impact(
        "car",
        KinematicState(0.0, -4.0, math.pi / 2, 12.0),
        "car",
        KinematicState(0.0, 0.0, 0.0, 10.0),
        brake=False,
    )
    record = compare_impact(m)
    dv_a, _ = plastic(m)
    gap = (m.a.dv_impulse - dv_a) / dv_a
    assert -0.3 < gap < -0.15, f"oblique gap {gap:.1%} changed"
    assert record.a.dv_error == pytest.approx(gap)
    assert abs(record.a.dv_error_planar) < 0.02
    assert m.a.reduced_area == "front"
    assert m.b.reduced_area == "right_side"
    assert record.b.area_predicted == "right_side"
    assert m.a.dv_com == pytest.approx(m.a.dv_impulse, abs=1e-3)


def test_wall_impact_gives_the_speed_times_one_plus_e():
    wall = StaticBox((5.0, 0.0), 0.2, 5.0, 0.5, 0.0, Boundary.WALL)
    scene = Scene([BodyProxy.of_type("car", "car")], [wall])
    recorder = ImpactRecorder(scene)
    scene.set_states(np.array([0.0]), np.array([0.0]), np.array([0.0]), np.array([10.0]), np.array([0.0]))
    found = []
    for _ in range(1500):
        found += scene.step(recorder)
        if found:
            break
    (m,) = found
    assert m.b.is_static and m.b.type == "wall"
    assert m.restitution == pytest.approx(float(RestitutionLaw()(10.0)), abs=0.02)
    assert m.a.dv_impulse == pytest.approx(10.0 * (1 + m.restitution), rel=0.01)
    assert m.max_penetration < 0.02
    record = compare_impact(m)
    assert record.a.dv_predicted == pytest.approx(10.0, rel=1e-6)
    assert record.a.model == "ignore_angle"
    assert math.isnan(record.b.harm_measured) and math.isnan(record.a.dv_planar)


@pytest.mark.parametrize("e", [0.05, 0.1, 0.3, 0.5])
def test_configured_constant_restitution_is_measured(e):
    contact = ContactSpec(restitution=(RestitutionSpec("car", "car", e),))
    m = measure_impact(*CASES["head_on"], contact=contact)
    assert m.restitution == pytest.approx(e, abs=0.02)
    dv_a, _ = plastic(m)
    assert m.a.dv_impulse == pytest.approx((1 + m.restitution) * dv_a, rel=1e-3)


@pytest.mark.parametrize("closing", [2.0, 5.0, 10.0, 30.0])
def test_restitution_follows_the_law_of_the_closing_speed(closing):
    """Speed-dependent restitution: ~0.1 at high closing speed, more for gentle contacts."""
    law = RestitutionLaw()
    state_b = KinematicState(4.6, 0.0, math.pi, 0.5 * closing)
    m = measure_impact("car", KinematicState(0.0, 0.0, 0.0, 0.5 * closing), "car", state_b)
    assert m.restitution == pytest.approx(float(law(closing)), abs=0.02)


def test_restitution_does_not_depend_on_where_in_a_step_the_bodies_touch():
    """Sub-steps during the impact: the contact phase within a 1 ms step hardly matters."""
    rig = ImpactRig(BodyProxy.of_type("a", "car"), BodyProxy.of_type("b", "car"))
    values = []
    for gap in np.linspace(0.05, 0.07, 7):
        m = rig.launch(KinematicState(0, 0, 0, 10.0), KinematicState(4.5 + gap, 0, math.pi, 10.0))
        values.append(m.restitution)
    assert np.ptp(values) < 0.02


def test_an_impact_is_sub_stepped_and_resting_contacts_are_not():
    rig = ImpactRig(BodyProxy.of_type("a", "car"), BodyProxy.of_type("b", "car"))
    scene = rig.scene
    scene.reset()
    velocity = np.array([10.0, -10.0])
    scene.set_states(np.array([0.0, 4.54]), np.zeros(2), np.array([0.0, math.pi]), velocity, np.zeros(2))
    substeps = MODES[ContactMode.RIGID].substeps
    assert substeps == 10
    # 4 cm apart at 20 m/s: no touch within 1.5 steps (plain step), then sub-steps
    # (2 cm apart: touching within the step).
    assert scene.dynamics.prepare() == 1 and not scene.dynamics.near
    scene.step()
    assert scene.dynamics.prepare() == substeps
    for _ in range(5):
        scene.step()
    (a, b, speed, e) = scene.dynamics.onsets[0]
    assert (a, b) == (0, 1) and speed == pytest.approx(20.0, rel=0.01)
    assert e == pytest.approx(float(RestitutionLaw()(speed)))
    # Two cars parked 5 cm apart: a contact inside the look-ahead, but nothing approaches.
    scene.set_states(np.array([0.0, 4.55]), np.zeros(2), np.array([0.0, math.pi]), np.zeros(2), np.zeros(2))
    assert scene.dynamics.prepare() == 1


def test_hunt_crossley_damping_gives_the_restitution_of_a_one_dimensional_impact():
    """Independent check: integrate m x'' = -k x (1 + lambda x') and read the rebound speed."""
    for e in (0.05, 0.1, 0.4, 0.8):
        v0 = 12.0
        lam = hunt_crossley_damping(e, v0)
        x, v, dt, k_over_m = 0.0, v0, 1e-7, 800.0**2
        while x >= 0.0:
            v -= k_over_m * x * (1.0 + lam * v) * dt
            x += v * dt
        assert -v / v0 == pytest.approx(e, rel=2e-3)


@pytest.mark.parametrize(
    ("partner", "speed_b", "bound"),
    [("car", 10.0, 0.06), ("pedestrian", 0.0, 0.05), ("bicycle", 0.0, 0.05), ("truck", 10.0, 0.06)],
)
def test_rigid_penetration_bounds_at_20_m_s_closing(partner, speed_b, bound):
    reach = 0.5 * (4.5 + BodyProxy.of_type("b", partner).length) + 0.05
    speed_a = 20.0 - speed_b
    m = measure_impact(
        "car", KinematicState(0, 0, 0, speed_a), partner, KinematicState(reach, 0.3, math.pi, speed_b)
    )
    assert m.max_penetration <= bound


def test_soft_mode_sinks_in_and_rigid_does_not():
    """The wave-1 contact (kept as ``soft``) lets a car sink ~0.45 m into another at 20 m/s."""
    soft = measure_impact(*CASES["head_on"], contact=ContactSpec(mode=ContactMode.SOFT))
    rigid = measure_impact(*CASES["head_on"])
    assert soft.max_penetration > 0.3 > 0.03 > rigid.max_penetration
    assert soft.duration > 0.15 > 0.01 > rigid.duration


def test_restitution_ranges_and_the_soft_table():
    values = restitution_dampratio(np.array([0.01, 0.05, 0.1, 0.3, 0.7]), ContactMode.SOFT)
    assert np.all(np.diff(values) < 0)
    low, high = restitution_range(ContactMode.SOFT)
    assert low < 0.01 and 0.7 < high < 0.8
    assert restitution_range(ContactMode.RIGID) == (0.01, 0.9)
    with pytest.raises(ValueError, match="restitution"):
        dampratio_for_restitution(0.9)
    with pytest.raises(ValueError, match=r"contact.restitution\[0\].e must lie in"):
        ContactSpec(restitution=(RestitutionSpec("car", "car", e=0.95),))


def test_rig_is_reusable_and_deterministic():
    rig = ImpactRig(BodyProxy.of_type("a", "car"), BodyProxy.of_type("b", "car"))
    first = rig.launch(*CASES["head_on"][1::2])
    rig.launch(*CASES["rear_end"][1::2])
    again = rig.launch(*CASES["head_on"][1::2])
    assert first == again


def test_rig_reports_misses_and_rejects_overlap():
    rig = ImpactRig(BodyProxy.of_type("a", "car"), BodyProxy.of_type("b", "car"))
    miss = rig.launch(KinematicState(0, 0, 0, 10), KinematicState(0, 10, 0, 10), max_time=0.5)
    assert miss is None
    with pytest.raises(ValueError, match="overlap"):
        rig.launch(KinematicState(0, 0, 0, 1), KinematicState(1, 0, 0, 1))


#: A car at 13 m/s and one at 10 m/s, 120 deg apart, meeting at half the edge offset: a
#: glancing corner hit that spins the struck car into a second, longer impact.
GLANCING = (
    KinematicState(0.0, 0.0, 0.0, 13.0278),
    KinematicState(2.5261, -3.3202, 2.0944, 10.0),
)


def test_a_glancing_hit_is_a_flagged_sequence_of_impulses():
    """The sequence keeps both impacts (the window stays open until the bodies stay
    apart), the first impulse is reported separately and the sequence is flagged."""
    m = measure_impact("car", GLANCING[0], "car", GLANCING[1])
    assert m.n_impulses == 2 and m.multi_impact
    assert m.impulse_times[1][0] >= MeasurementWindow().pulse_gap
    assert m.a.dv_first < 0.5 * m.a.dv_impulse
    assert m.impulse == pytest.approx(float(np.hypot(*m.b.impulse)))
    assert sum(m.impulses) >= m.impulse  # magnitudes of impulses in different directions


def test_force_direction_is_taken_at_the_impulse_weighted_yaw():
    """The struck car turns by ~0.4 rad (impulse-weighted) during a two-impact sequence.

    Independent check from the force history: the impulse-weighted mean yaw of the
    body, and the sequence's impulse seen from it; the pre-impact frame differs.
    """
    rig = ImpactRig(BodyProxy.of_type("a", "car"), BodyProxy.of_type("b", "car"), trace=True, brake=False)
    m = rig.launch(KinematicState(0.0, 0.0, 0.0, 23.0278), KinematicState(1.99966, -3.23332, 1.0472, 10.0))
    assert m.n_impulses == 2
    trace = rig.last_trace
    weight = np.hypot(trace[:, 1], trace[:, 2])
    yaw = np.unwrap(np.r_[m.b.yaw, trace[:, 5]])[1:]
    mean_yaw = float((weight * yaw).sum() / weight.sum())

    def seen_from(angle):
        source = -np.array(m.b.impulse)
        c, s = math.cos(angle), math.sin(angle)
        return math.atan2(-s * source[0] + c * source[1], c * source[0] + s * source[1])

    assert abs(math.remainder(m.b.force_angle - seen_from(mean_yaw), 2 * math.pi)) < 0.02
    assert abs(math.remainder(m.b.force_angle - seen_from(m.b.yaw), 2 * math.pi)) > 0.3


def test_measurement_window_is_validated():
    with pytest.raises(ValueError, match="window.pulse_gap must be <="):
        MeasurementWindow(pulse_gap=1.0, separation_time=0.5)
    with pytest.raises(ValueError, match="window.separation_time must be > 0"):
        MeasurementWindow(separation_time=0.0)


@settings(max_examples=25, deadline=None)
@given(
    v_a=st.floats(2.0, 25.0),
    v_b=st.floats(0.0, 25.0),
    heading_b=st.floats(-math.pi, math.pi),
    lateral=st.floats(-1.0, 1.0),
)
def test_impulses_conserve_momentum_and_never_create_energy(v_a, v_b, heading_b, lateral):
    rig = _shared_rig()
    # b stands or rolls 9 m ahead, at any angle; a drives into it.
    state_b = KinematicState(9.0, lateral, heading_b, v_b * 0.3)
    m = rig.launch(KinematicState(0.0, 0.0, 0.0, v_a), state_b, max_time=3.0)
    if m is None:
        return
    momentum_a = np.array(m.a.delta_v_impulse) * m.a.mass
    momentum_b = np.array(m.b.delta_v_impulse) * m.b.mass
    np.testing.assert_allclose(momentum_a, -momentum_b, atol=1e-6 * max(1.0, np.abs(momentum_a).max()))
    inertia = rig.scene.yaw_inertia

    def energy(after):
        total = 0.0
        for body, i in ((m.a, inertia[0]), (m.b, inertia[1])):
            v = np.array(body.velocity_after if after else body.velocity)
            rate = body.yaw_rate_after if after else body.yaw_rate
            total += 0.5 * body.mass * v @ v + 0.5 * i * rate**2
        return total

    assert energy(True) <= energy(False) * 1.001 + 1.0
    assert m.a.dv_com == pytest.approx(m.a.dv_impulse, abs=2e-3)
    assert m.max_penetration < 0.06


_RIG = {}


def _shared_rig():
    if "rig" not in _RIG:
        _RIG["rig"] = ImpactRig(BodyProxy.of_type("a", "car"), BodyProxy.of_type("b", "car"), brake=False)
    return _RIG["rig"]


def test_rig_bodies_skid_after_their_first_contact_like_the_world():
    """Braking acts outside the pulses only: the impulse is that of coasting bodies."""
    coast = measure_impact(*CASES["rear_end"], brake=False)
    rig = ImpactRig(BodyProxy.of_type("a", "car"), BodyProxy.of_type("b", "car"))
    skid = rig.launch(*CASES["rear_end"][1::2])
    assert skid.a.dv_impulse == pytest.approx(coast.a.dv_impulse, rel=1e-6)
    # After the pulse both bodies skid at the friction limit (0.9 g), as crashed bodies in the world.
    force = np.hypot(rig.scene.ctrl[:, 0], rig.scene.ctrl[:, 1])
    np.testing.assert_allclose(force, 0.9 * 9.81 * rig.scene.masses, rtol=1e-6)


def test_contacts_switched_in_one_fork_of_a_scene_stay_in_the_others():
    """Forks (avoidability branches) share the MuJoCo model; soft-mode contact bits must not."""
    import copy

    scene = Scene(
        [BodyProxy.of_type("a", "car"), BodyProxy.of_type("b", "car")],
        contact=ContactSpec(mode=ContactMode.SOFT),
    )
    geom = scene.geom_ids[1]
    before = (int(scene.model.geom_contype[geom]), int(scene.model.geom_conaffinity[geom]))
    assert before != (0, 0)
    fork = copy.deepcopy(scene)
    fork.set_contacts(np.array([1]), enabled=False)
    assert (fork.model.geom_contype[geom], fork.model.geom_conaffinity[geom]) == (0, 0)
    assert (int(scene.model.geom_contype[geom]), int(scene.model.geom_conaffinity[geom])) == before
    fork.set_contacts(np.array([1]), enabled=True)
    assert (int(fork.model.geom_contype[geom]), int(fork.model.geom_conaffinity[geom])) == before
