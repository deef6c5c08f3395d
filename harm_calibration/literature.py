"""Anchor points from the injury-risk literature, held against the planner's harm models.

Car occupants (protected, MAIS3+, reduced symmetric model): a closing speed between
two cars of equal mass gives each delta-v = closing / 2; the model should agree with
the reported risk within a factor of ``CAR_FACTOR``.

Pedestrians (unprotected, MAIS3+ model): the reported risks are of AIS4+ injury and
of death, both subsets of MAIS3+, so the MAIS3+ risk at the same impact speed must be
at or above them. The pedestrian's delta-v is the planner's m_ego / (m_ego + m_ped)
times the impact speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ethical_planner.harm import HarmModel, harm
from ethical_planner.road_users import EGO_MASS_KG, RoadUserType, mass_of

#: Largest accepted ratio between model and reported risk for car occupants.
CAR_FACTOR = 2.5
KMH = 1.0 / 3.6  # [m/s per km/h]

_TARGET = "TARGET analysis of US crash data (10% MAIS3+ risk)"
_JUREWICZ = "Jurewicz et al. 2016"
_TEFFT = "Tefft 2013"


@dataclass(frozen=True, slots=True)
class Anchor:
    """A reported risk at a speed.

    Attributes:
        source: citation. case: description. road_user: "car" or "pedestrian".
        outcome: injury level reported. speed_kmh: closing (cars) or impact speed
        (pedestrians) [km/h]. risk: reported probability. angle_deg: impact angle in
        the body frame for the area models [deg]. criterion: "factor" (within
        ``CAR_FACTOR``) or "at_or_above" (the model must not be below).
    """

    source: str
    case: str
    road_user: str
    outcome: str
    speed_kmh: float
    risk: float
    angle_deg: float
    criterion: str


ANCHORS: tuple[Anchor, ...] = (
    Anchor(_TARGET, "frontal", "car", "MAIS3+", 99.0, 0.10, 0.0, "factor"),
    Anchor(_TARGET, "near-side", "car", "MAIS3+", 73.0, 0.10, 90.0, "factor"),
    Anchor(_TARGET, "rear-end", "car", "MAIS3+", 126.0, 0.10, 180.0, "factor"),
    Anchor(_JUREWICZ, "head-on, 30 km/h each", "car", "MAIS3+", 60.0, 0.10, 0.0, "factor"),
    Anchor(_TEFFT, "pedestrian", "pedestrian", "AIS4+", 27.5, 0.10, 0.0, "at_or_above"),
    Anchor(_TEFFT, "pedestrian", "pedestrian", "AIS4+", 40.1, 0.25, 0.0, "at_or_above"),
    Anchor(_TEFFT, "pedestrian", "pedestrian", "AIS4+", 53.1, 0.50, 0.0, "at_or_above"),
    Anchor(_TEFFT, "pedestrian", "pedestrian", "AIS4+", 65.7, 0.75, 0.0, "at_or_above"),
    Anchor(_TEFFT, "pedestrian", "pedestrian", "death", 38.8, 0.10, 0.0, "at_or_above"),
    Anchor(_TEFFT, "pedestrian", "pedestrian", "death", 65.3, 0.50, 0.0, "at_or_above"),
)


@dataclass(frozen=True, slots=True)
class AnchorCheck:
    """An anchor with the model's value beside it.

    Attributes:
        anchor: the literature point. model: harm model used. dv: delta-v fed to the
        model [m/s]. predicted: model probability. ratio: predicted / reported.
        passed: the criterion holds.
    """

    anchor: Anchor
    model: str
    dv: float
    predicted: float
    ratio: float
    passed: bool


def check_anchor(
    anchor: Anchor,
    car_model: HarmModel | str = HarmModel.REDUCED_SYM,
    pedestrian_model: HarmModel | str = HarmModel.PEDESTRIAN_MAIS3,
    ego_mass: float = EGO_MASS_KG,
) -> AnchorCheck:
    """Evaluate the model at an anchor point (see the module docstring)."""
    speed = anchor.speed_kmh * KMH
    if anchor.road_user == "car":
        model = HarmModel.parse(car_model)
        dv = 0.5 * speed
    elif anchor.road_user == "pedestrian":
        model = HarmModel.parse(pedestrian_model)
        m_ped = mass_of(RoadUserType.PEDESTRIAN, 0.5, 0.5)
        dv = ego_mass / (ego_mass + m_ped) * speed
    else:
        raise ValueError(f"Anchor.road_user must be 'car' or 'pedestrian', got {anchor.road_user!r}")
    predicted = float(harm(model, dv, math.radians(anchor.angle_deg)))
    ratio = predicted / anchor.risk
    if anchor.criterion == "factor":
        passed = 1.0 / CAR_FACTOR <= ratio <= CAR_FACTOR
    elif anchor.criterion == "at_or_above":
        passed = predicted >= anchor.risk
    else:
        raise ValueError(f"Anchor.criterion must be 'factor' or 'at_or_above', got {anchor.criterion!r}")
    return AnchorCheck(anchor, model.value, dv, predicted, ratio, passed)


def literature_table(
    car_model: HarmModel | str = HarmModel.REDUCED_SYM,
    pedestrian_model: HarmModel | str = HarmModel.PEDESTRIAN_MAIS3,
) -> list[AnchorCheck]:
    """Every anchor of ``ANCHORS`` checked against the models."""
    return [check_anchor(a, car_model, pedestrian_model) for a in ANCHORS]


def literature_markdown(checks: list[AnchorCheck]) -> str:
    """Markdown table of the checks."""
    lines = [
        "| source | case | outcome | speed [km/h] | reported | model | dv [m/s] | model risk | ratio "
        "| criterion | ok |",
        "| --- | --- | --- | ---: | ---: | --- | ---: | ---: | ---: | --- | --- |",
    ]
    for c in checks:
        a = c.anchor
        crit = f"within x{CAR_FACTOR:g}" if a.criterion == "factor" else "model >= reported"
        lines.append(
            f"| {a.source} | {a.case} | {a.outcome} | {a.speed_kmh:.1f} | {a.risk:.0%} | {c.model} | "
            f"{c.dv:.2f} | {c.predicted:.1%} | {c.ratio:.2f} | {crit} | {'yes' if c.passed else 'NO'} |"
        )
    return "\n".join(lines)
