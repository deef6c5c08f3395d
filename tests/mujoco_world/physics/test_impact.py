"""Impact measurement against the plastic-collision formula (paper Eq. 1)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ethical_planner.harm import delta_v
from ethical_planner.road_users import KinematicState
from mujoco_world.evaluation.compare import compare_impact
from mujoco_world.physics.impact import ImpactRig, measure_impact
from mujoco_world.physics.scene import BodyProxy, Scene, dampratio_for_restitution
from mujoco_world.scenario.spec import ContactSpec, RestitutionSpec


def plastic(m):
    """Eq. 1 delta-v of both bodies from the measured pre-impact velocities."""
    dv_a, dv_b = delta_v(m.a.mass, m.b.mass, np.array(m.a.velocity), np.array(m.b.velocity))
    return float(dv_a), float(dv_b)


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
def test_collinear_impacts_match_the_plastic_formula_within_5_percent(name):
    type_a, state_a, type_b, state_b = CASES[name]
    m = measure_impact(type_a, state_a, type_b, state_b)
    assert m is not None and m.complete and not m.multi_body
    dv_a, dv_b = plastic(m)
    assert m.a.dv_impulse == pytest.approx(dv_a, rel=0.05)
    assert m.b.dv_impulse == pytest.approx(dv_b, rel=0.05)
    # Near-plastic contacts: a little restitution, measured delta-v slightly above Eq. 1.
    assert 0.0 <= m.restitution < 0.03
    # Impulse and centre-of-mass velocity change agree (no other force acts).
    assert m.a.dv_com == pytest.approx(m.a.dv_impulse, abs=1e-3)
    assert m.b.dv_com == pytest.approx(m.b.dv_impulse, abs=1e-3)
    # Newton's third law: equal and opposite impulses.
    assert m.a.mass * m.a.dv_impulse == pytest.approx(m.b.mass * m.b.dv_impulse, rel=1e-9)


def test_head_on_geometry_front_to_front():
    m = measure_impact(*CASES["head_on"])
    for body in (m.a, m.b):
        assert body.reduced_area == "front"
        assert body.clock_area == 12
        assert body.force_clock == 12
    assert m.peak_force > 1e5
    assert 0.1 < m.duration < 0.4


def test_rear_end_areas_and_force_direction():
    m = measure_impact(*CASES["rear_end"])
    assert (m.a.reduced_area, m.b.reduced_area) == ("front", "rear")
    assert (m.a.force_clock, m.b.force_clock) == (12, 6)
    # The follower is slowed, the leader pushed forward.
    assert m.a.delta_v_impulse[0] < 0 < m.b.delta_v_impulse[0]


def test_pedestrian_hit_from_its_left_side():
    m = measure_impact(*CASES["car_pedestrian"])
    # The pedestrian walks north (+y); the car comes from the west, i.e. its left.
    assert m.b.reduced_area == "driver_side"
    assert m.b.clock_area == 9
    record = compare_impact(m)
    assert record.b.model == "pedestrian_mais3"
    assert record.a.model == "ignore_angle"
    assert record.b.dv_error == pytest.approx(0.0, abs=0.05)
    assert record.b.harm_measured == pytest.approx(record.b.harm_predicted, rel=0.05)


def test_t_bone_documents_the_oblique_gap():
    """A T-bone into a moving car: Eq. 1 assumes a common final velocity, sideways too.

    The struck car slides along the striking car's front: the measured delta-v is far
    below Eq. 1 (here about 37% lower), and the areas still agree (front / right side).
    """
    m = measure_impact(
        "car", KinematicState(0.0, -4.0, math.pi / 2, 12.0), "car", KinematicState(0.0, 0.0, 0.0, 10.0)
    )
    record = compare_impact(m)
    dv_a, _ = plastic(m)
    gap = (m.a.dv_impulse - dv_a) / dv_a
    assert -0.5 < gap < -0.2, f"oblique gap {gap:.1%} changed"
    assert record.a.dv_error == pytest.approx(gap)
    assert m.a.reduced_area == "front"
    assert m.b.reduced_area == "right_side"
    assert record.b.area_predicted == "right_side"
    # Still no free energy: impulses equal and opposite, COM change matches the impulse.
    assert m.a.dv_com == pytest.approx(m.a.dv_impulse, abs=1e-3)


def test_wall_impact_gives_the_speed():
    from mujoco_world.scenario.road import StaticBox
    from mujoco_world.scenario.spec import Boundary

    wall = StaticBox((5.0, 0.0), 0.2, 5.0, 0.5, 0.0, Boundary.WALL)
    scene = Scene([BodyProxy.of_type("car", "car")], [wall])
    from mujoco_world.physics.impact import ImpactRecorder

    recorder = ImpactRecorder(scene)
    scene.set_states(np.array([0.0]), np.array([0.0]), np.array([0.0]), np.array([10.0]), np.array([0.0]))
    found = []
    for _ in range(1500):
        recorder.before_step()
        scene.step()
        found += recorder.after_step()
        if found:
            break
    (m,) = found
    assert m.b.is_static and m.b.type == "wall"
    assert m.a.dv_impulse == pytest.approx(10.0, rel=0.03)
    record = compare_impact(m)
    assert record.a.dv_predicted == pytest.approx(10.0, rel=1e-6)
    assert record.a.model == "ignore_angle"
    assert math.isnan(record.b.harm_measured)


@pytest.mark.parametrize("e", [0.1, 0.3, 0.5])
def test_configured_restitution_is_measured(e):
    contact = ContactSpec(restitution=(RestitutionSpec("car", "car", e),))
    m = measure_impact(*CASES["head_on"], contact=contact)
    assert m.restitution == pytest.approx(e, abs=0.03)
    dv_a, _ = plastic(m)
    assert m.a.dv_impulse == pytest.approx((1 + m.restitution) * dv_a, rel=0.01)


def test_dampratio_table_is_monotone():
    values = [dampratio_for_restitution(e) for e in (0.01, 0.05, 0.1, 0.3, 0.7)]
    assert values == sorted(values, reverse=True)
    with pytest.raises(ValueError, match="restitution"):
        dampratio_for_restitution(0.9)


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

    assert energy(after=True) <= energy(after=False) * (1 + 1e-3)
    # Eq. 1 is not an upper bound for oblique hits (the struck car can rotate into the
    # striker during the soft pulse), but a perfectly elastic hit is: 2x Eq. 1.
    dv_a, _ = plastic(m)
    assert m.a.dv_impulse <= 2.0 * dv_a + 1e-6
    assert m.a.dv_com == pytest.approx(m.a.dv_impulse, abs=2e-3)


def test_corner_impact_can_exceed_the_plastic_formula():
    """Documented gap: a car hitting a stationary car turned by 1 rad near its corner.

    The soft near-plastic pulse (solref 0.05 4) lasts ~0.4 s; the struck car rotates
    into the striker meanwhile and the measured delta-v exceeds Eq. 1 by ~17%.
    """
    m = measure_impact("car", KinematicState(0.0, 0.0, 0.0, 9.0), "car", KinematicState(9.0, 0.0, 1.0, 0.0))
    dv_a, _ = plastic(m)
    assert 1.05 < m.a.dv_impulse / dv_a < 1.3
    assert m.b.yaw_rate_after > 0.5


_RIG = {}


def _shared_rig():
    if "rig" not in _RIG:
        _RIG["rig"] = ImpactRig(BodyProxy.of_type("a", "car"), BodyProxy.of_type("b", "car"))
    return _RIG["rig"]
