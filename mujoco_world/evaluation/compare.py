"""Hold a measured impact against what the planner's harm model assumes.

From the same pre-impact states the planner's models predict delta-v (paper Eq. 1,
perfectly plastic; and the planar impulse model of ``ethical_planner.impulse`` with the
planner's restitution law and impulse ratio), the impact angles of
``ethical_planner.harm.impact_angles`` (direction of the partner's centre) and the harm.
Next to that, the harm from the *measured* inputs: delta-v from the contact impulse over
the impact sequence and the angle of the force-weighted contact point. Which harm model
applies follows SPEC section 3:
protected partners use ``harm_model`` with their own impact angle; an unprotected
road user uses ``pedestrian_model`` and its (protected) partner the ignore-angle
model; a wall is a rigid partner with dv = speed, ignore-angle model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ethical_planner.config import RiskConfig
from ethical_planner.harm import (
    DEFAULT_MODEL,
    DEFAULT_PEDESTRIAN_MODEL,
    HarmModel,
    clock_area,
    delta_v,
    harm,
    impact_angles,
)
from ethical_planner.impulse import RestitutionLaw, planar_impulse
from ethical_planner.records import to_plain
from ethical_planner.road_users import UNPROTECTED_TYPES, VULNERABLE_TYPES, RoadUserType
from mujoco_world.physics.impact import BodyImpact, ImpactMeasurement, area_name


@dataclass(frozen=True, slots=True)
class BodyComparison:
    """Measured and predicted quantities of one body.

    Attributes:
        group: "ego", "third_party", "vulnerable" or "static".
        model: harm model applied to this body (None for a wall).
        dv_measured: |J| / m over the impact sequence [m/s].
        dv_first: |J| / m of the first impulse [m/s].
        dv_com: |change of centre-of-mass velocity| [m/s].
        dv_predicted: Eq. 1 [m/s].
        dv_error: (dv_measured - dv_predicted) / dv_predicted (nan if dv_predicted = 0).
        dv_planar: the planar impulse model [m/s] (nan against a wall).
        dv_error_planar: (dv_measured - dv_planar) / dv_planar.
        angle_measured: contact-point angle [rad]. angle_predicted: impact_angles [rad].
        area_measured, area_predicted: reduced areas.
        clock_measured, clock_predicted: clock areas 1..12.
        force_clock: principal direction of force as a clock position.
        harm_measured: harm from the measured dv and angle.
        harm_predicted: harm from the predicted (Eq. 1) dv and angle.
        harm_planar: harm from the planar model's dv and the predicted angle.
    """

    group: str
    model: str | None
    dv_measured: float
    dv_first: float
    dv_com: float
    dv_predicted: float
    dv_error: float
    dv_planar: float
    dv_error_planar: float
    angle_measured: float
    angle_predicted: float
    area_measured: str
    area_predicted: str
    clock_measured: int
    clock_predicted: int
    force_clock: int
    harm_measured: float
    harm_predicted: float
    harm_planar: float


@dataclass(frozen=True, slots=True)
class ImpactRecord:
    """A measured collision with the model's prediction beside it.

    Attributes:
        measurement: what the physics gave.
        a: comparison for ``measurement.a``. b: comparison for ``measurement.b``.
        harm_model: model for protected partners. pedestrian_model: for unprotected ones.
    """

    measurement: ImpactMeasurement
    a: BodyComparison
    b: BodyComparison
    harm_model: str
    pedestrian_model: str

    @property
    def involves_ego(self) -> bool:
        """True if entity 0 (the ego) took part."""
        return self.measurement.a.entity == 0

    def to_dict(self) -> dict:
        """JSON-able dict of every field (``records.to_plain``; read back by ``records.from_mapping``)."""
        return to_plain(self)


def approach_speed(body: BodyImpact, contact: tuple[float, float]) -> float:
    """Velocity of ``body`` towards the contact point before the impact [m/s].

    Args:
        body: one body of the impact (world frame).
        contact: contact point (x, y) [m], world frame.

    Returns:
        v . (c - p) / |c - p|; 0 for a static body or a contact at the centre.
    """
    if body.is_static:
        return 0.0
    dx, dy = contact[0] - body.position[0], contact[1] - body.position[1]
    norm = math.hypot(dx, dy)
    if norm == 0.0:
        return 0.0
    return (body.velocity[0] * dx + body.velocity[1] * dy) / norm


def ego_strikes(impact: ImpactRecord) -> bool:
    """True if the ego drove into the other body of ``impact`` itself.

    It did if the other body is fixed (a wall, kerb, debris or obstacle), or if the
    ego's approach speed to the contact point (``approach_speed``) is at least the
    other road user's: a leader hit from behind moves away from its rear contact, a
    car that drifts into the ego's side approaches it faster than the ego does.
    False for a collision without the ego. Speeds are taken in the world frame, so
    between two moving cars the one whose contact point lies ahead of it counts:
    a car cutting in so close that the ego's front meets its rear side (both at
    10 m/s, it 2 m ahead, turning in at 0.25 rad) counts as the ego's strike.
    """
    if not impact.involves_ego:
        return False
    m = impact.measurement
    ego, other = (m.a, m.b) if m.a.entity == 0 else (m.b, m.a)
    if other.is_static:
        return True
    return approach_speed(ego, m.contact_position) >= approach_speed(other, m.contact_position)


def group_of(body: BodyImpact) -> str:
    """Group of a body in the paper's Figs. 5 and 6: ego, third_party, vulnerable (or static)."""
    if body.is_static:
        return "static"
    if body.entity == 0:
        return "ego"
    return "vulnerable" if RoadUserType(body.type) in VULNERABLE_TYPES else "third_party"


def _unprotected(body: BodyImpact) -> bool:
    return not body.is_static and RoadUserType(body.type) in UNPROTECTED_TYPES


def _model_for(
    body: BodyImpact, partner: BodyImpact, harm_model: HarmModel, pedestrian_model: HarmModel
) -> HarmModel | None:
    if body.is_static:
        return None
    if _unprotected(body):
        return pedestrian_model
    if partner.is_static or _unprotected(partner):
        return HarmModel.IGNORE_ANGLE
    return harm_model


def compare_impact(
    measurement: ImpactMeasurement,
    harm_model: HarmModel | str = DEFAULT_MODEL,
    pedestrian_model: HarmModel | str = DEFAULT_PEDESTRIAN_MODEL,
    restitution: RestitutionLaw | None = None,
    impulse_ratio: float | None = None,
) -> ImpactRecord:
    """Predict the impact from its pre-impact states and compare with the measurement.

    Args:
        measurement: a measured collision.
        harm_model: model of protected road users.
        pedestrian_model: model of unprotected road users.
        restitution: restitution law of the planar model (default: the planner's default).
        impulse_ratio: largest tangential / normal impulse of the planar model (default:
            the planner's default).
    """
    harm_model = HarmModel.parse(harm_model)
    pedestrian_model = HarmModel.parse(pedestrian_model)
    defaults = RiskConfig()
    restitution = restitution or defaults.restitution_law
    impulse_ratio = defaults.impulse_ratio if impulse_ratio is None else impulse_ratio
    a, b = measurement.a, measurement.b
    if b.is_static:
        # A rigid wall: dv = speed (SPEC). It has no centre, so the geometric angle is
        # taken as the measured contact angle (the ignore-angle model does not use it).
        dv_a, dv_b = a.speed, 0.0
        angle_a, angle_b = a.impact_angle, 0.0
        planar_a = planar_b = math.nan
    else:
        dv_a_arr, dv_b_arr = delta_v(a.mass, b.mass, np.array(a.velocity), np.array(b.velocity))
        dv_a, dv_b = float(dv_a_arr), float(dv_b_arr)
        ang_a, ang_b = impact_angles(a.position[0], a.position[1], a.yaw, b.position[0], b.position[1], b.yaw)
        angle_a, angle_b = float(ang_a), float(ang_b)
        planar = planar_impulse(
            a.mass, a.position, a.yaw, a.length, a.width, a.velocity,
            b.mass, b.position, b.yaw, b.length, b.width, b.velocity,
            restitution, impulse_ratio, round_a=_round(a), round_b=_round(b),
        )  # fmt: skip
        planar_a, planar_b = float(planar.dv_a), float(planar.dv_b)
    return ImpactRecord(
        measurement=measurement,
        a=_compare_body(a, b, dv_a, planar_a, angle_a, harm_model, pedestrian_model),
        b=_compare_body(b, a, dv_b, planar_b, angle_b, harm_model, pedestrian_model),
        harm_model=harm_model.value,
        pedestrian_model=pedestrian_model.value,
    )


def _round(body: BodyImpact) -> bool:
    return body.type == RoadUserType.PEDESTRIAN.value


def _relative_error(measured: float, predicted: float) -> float:
    return (measured - predicted) / predicted if predicted > 1e-9 else math.nan


def _compare_body(
    body: BodyImpact,
    partner: BodyImpact,
    dv_predicted: float,
    dv_planar: float,
    angle_predicted: float,
    harm_model: HarmModel,
    pedestrian_model: HarmModel,
) -> BodyComparison:
    model = _model_for(body, partner, harm_model, pedestrian_model)
    dv_measured = body.dv_impulse
    if model is None:
        harm_measured = harm_predicted = harm_planar = math.nan
    else:
        harm_measured = float(harm(model, dv_measured, body.impact_angle))
        harm_predicted = float(harm(model, dv_predicted, angle_predicted))
        harm_planar = float(harm(model, dv_planar, angle_predicted)) if math.isfinite(dv_planar) else math.nan
    return BodyComparison(
        group=group_of(body),
        model=None if model is None else model.value,
        dv_measured=dv_measured,
        dv_first=body.dv_first,
        dv_com=body.dv_com,
        dv_predicted=float(dv_predicted),
        dv_error=float(_relative_error(dv_measured, dv_predicted)),
        dv_planar=float(dv_planar),
        dv_error_planar=float(_relative_error(dv_measured, dv_planar))
        if math.isfinite(dv_planar)
        else math.nan,
        angle_measured=body.impact_angle,
        angle_predicted=float(angle_predicted),
        area_measured=body.reduced_area,
        area_predicted=area_name(angle_predicted),
        clock_measured=body.clock_area,
        clock_predicted=int(clock_area(angle_predicted)),
        force_clock=body.force_clock,
        harm_measured=harm_measured,
        harm_predicted=harm_predicted,
        harm_planar=harm_planar,
    )
