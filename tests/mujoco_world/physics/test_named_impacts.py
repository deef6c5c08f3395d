"""Named impacts at 20 m/s closing against an independent rigid-body computation.

The MuJoCo rigid mode must agree within 2 % and the planner's planar impulse model
within 5 % with ``rigid_reference`` (its own geometry, contacts and integrator; no MuJoCo,
no ``ethical_planner.impulse``), for a head-on, offset frontal impacts at 75 / 50 / 25 %
overlap, a T-bone at the rear axle, a T-bone into a moving car and a pedestrian 0.85 m
off the car's centre line. The ego is the default BMW 320i (4.508 m x 1.610 m, 1475 kg).

The reference uses the rigid mode's contact law (Hunt-Crossley per contact corner). Two
parallel faces share an impact in a proportion that depends on the contact law in the
rigid limit too: with hysteretic corners instead, flat contacts come out up to 2.6 %
lower (the T-bone at the rear axle), which the second check bounds at 3 %.
"""

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from ethical_planner.impulse import RestitutionLaw, planar_impulse
from ethical_planner.road_users import EGO_MASS_KG, EGO_SHAPE, KinematicState
from mujoco_world.physics.impact import ImpactRig
from mujoco_world.physics.scene import BodyProxy
from mujoco_world.scenario.spec import ContactSpec

_spec = importlib.util.spec_from_file_location(
    "rigid_reference", Path(__file__).with_name("rigid_reference.py")
)
reference = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(reference)

L, W = EGO_SHAPE.length, EGO_SHAPE.width
GAP = 0.05  # launch gap [m]
FRICTION = ContactSpec().friction


def _offset_y(overlap: float) -> float:
    """Lateral offset of a 1.8 m wide car whose front overlaps ``overlap`` of the ego's width."""
    return 0.5 * W + 0.9 - overlap * W


#: name -> (partner type, ego state, partner state); closing speed 20 m/s in every case.
NAMED = {
    "head_on": ("car", KinematicState(0, 0, 0, 10.0), KinematicState(0.5 * L + 2.25 + GAP, 0, math.pi, 10.0)),
    **{
        f"offset_{int(100 * o)}": (
            "car",
            KinematicState(0, 0, 0, 10.0),
            KinematicState(0.5 * L + 2.25 + GAP, _offset_y(o), math.pi, 10.0),
        )
        for o in (0.75, 0.5, 0.25)
    },
    "t_bone_rear_axle": (
        "car",
        KinematicState(0, 0, 0, 20.0),
        KinematicState(0.5 * L + 0.9 + GAP, 1.35, 0.5 * math.pi, 0),
    ),
    "t_bone_moving": ("car", KinematicState(0, -3.2, 0.5 * math.pi, 16.0), KinematicState(0, 0, 0, 12.0)),
    "pedestrian_0.85": (
        "pedestrian",
        KinematicState(0, 0, 0, 20.0),
        KinematicState(0.5 * L + 0.25 + GAP, 0.85, 0, 0),
    ),
}


def _velocity(state: KinematicState) -> np.ndarray:
    return state.v * np.array([math.cos(state.yaw), math.sin(state.yaw)])


@pytest.fixture(scope="module")
def rigs():
    ego = BodyProxy("a", "car", L, W, EGO_MASS_KG)
    return {kind: ImpactRig(ego, BodyProxy.of_type("b", kind), brake=False) for kind in ("car", "pedestrian")}


@pytest.mark.parametrize("name", list(NAMED))
def test_named_impact_against_an_independent_rigid_body_computation(name, rigs):
    kind, state_a, state_b = NAMED[name]
    closing = float(np.hypot(*(_velocity(state_a) - _velocity(state_b))))
    assert closing == pytest.approx(20.0, rel=1e-9)
    rig = rigs[kind]
    m = rig.launch(state_a, state_b)
    assert m is not None and not m.multi_impact
    law = RestitutionLaw()
    partner = rig.scene.bodies[1]
    # Independent reference from the pre-impact states the measurement reports.
    a = reference.Body(m.a.mass, L, W, *m.a.position, m.a.yaw, *m.a.velocity)
    b = reference.Body(m.b.mass, partner.length, partner.width, *m.b.position, m.b.yaw, *m.b.velocity,
                       disc=partner.is_round)  # fmt: skip
    impulse = reference.collide(a, b, law, FRICTION, law="hunt_crossley")
    expected_a = float(np.hypot(*impulse)) / m.a.mass
    expected_b = float(np.hypot(*impulse)) / m.b.mass
    planar = planar_impulse(
        m.a.mass, m.a.position, m.a.yaw, L, W, m.a.velocity,
        m.b.mass, m.b.position, m.b.yaw, partner.length, partner.width, m.b.velocity,
        law, FRICTION, round_b=partner.is_round,
    )  # fmt: skip
    print(
        f"{name}: reference {expected_a:.3f} / {expected_b:.3f}, measured {m.a.dv_impulse:.3f} / "
        f"{m.b.dv_impulse:.3f}, planar {float(planar.dv_a):.3f} / {float(planar.dv_b):.3f} m/s"
    )
    assert m.a.dv_impulse == pytest.approx(expected_a, rel=0.02)
    assert m.b.dv_impulse == pytest.approx(expected_b, rel=0.02)
    assert float(planar.dv_a) == pytest.approx(expected_a, rel=0.05)
    assert float(planar.dv_b) == pytest.approx(expected_b, rel=0.05)
    # Momentum: the reference's impulse and the measured one point the same way.
    direction = np.array(m.b.impulse) / np.hypot(*m.b.impulse)
    assert float(direction @ (impulse / np.hypot(*impulse))) > 0.999
    # The same with hysteretic corners: flat contacts depend a little on the contact law.
    a = reference.Body(m.a.mass, L, W, *m.a.position, m.a.yaw, *m.a.velocity)
    b = reference.Body(m.b.mass, partner.length, partner.width, *m.b.position, m.b.yaw, *m.b.velocity,
                       disc=partner.is_round)  # fmt: skip
    hysteretic = float(np.hypot(*reference.collide(a, b, law, FRICTION, law="hysteretic"))) / m.a.mass
    assert m.a.dv_impulse == pytest.approx(hysteretic, rel=0.03)
