"""``etp harm``: ask the harm model directly.

Example: ``etp harm --dv 12 --area side`` prints the MAIS3+ probability of a car
whose delta-v is 12 m/s in a side impact, by the default model (LR4S).
"""

from __future__ import annotations

import argparse
import math

from ethical_planner.geometry import wrap_angle
from ethical_planner.harm import (
    DEFAULT_MODEL,
    DEFAULT_PEDESTRIAN_MODEL,
    AreaScheme,
    FunctionalForm,
    HarmModel,
    coefficients,
    harm,
)
from ethical_planner.road_users import DEFAULT_SHAPES, EGO_MASS_KG, UNPROTECTED_TYPES, RoadUserType, mass_of
from harm_calibration.cli.common import add_json, print_json

#: Largest delta-v asked about [m/s] (a 360 km/h closing speed).
MAX_DV = 100.0
#: Named impact areas and their direction in the road user's frame [deg], + = left.
_NAMED_AREAS_DEG = {
    "front": 0.0,
    "side": 90.0,  # only for symmetric models
    "driver_side": 90.0,
    "right_side": -90.0,
    "rear": 180.0,
}
_ASYMMETRIC = frozenset({AreaScheme.REDUCED_ASYM, AreaScheme.CLOCK})
_ALLOWED_AREAS = ", ".join(_NAMED_AREAS_DEG) + " or a clock position 1..12"


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``etp harm`` to the parser."""
    parser = subparsers.add_parser(
        "harm",
        help="injury probability of one road user from its delta-v and impact area",
        description=(
            "Injury probability (paper Eq. 2) of a road user whose delta-v is --dv. "
            "Unprotected partners (pedestrian, bicycle, motorcycle) use a pedestrian model."
        ),
    )
    parser.add_argument(
        "--dv", type=float, required=True, help="delta-v of the road user whose harm is asked [m/s]"
    )
    parser.add_argument("--area", default=None, help=f"impact area on that road user: {_ALLOWED_AREAS}")
    parser.add_argument(
        "--model",
        default=None,
        help=(
            f"harm model: {', '.join(m.value for m in HarmModel)} (default: {DEFAULT_MODEL}, "
            f"or {DEFAULT_PEDESTRIAN_MODEL} for unprotected partners)"
        ),
    )
    parser.add_argument(
        "--partner",
        default=RoadUserType.CAR.value,
        help="type of the road user whose harm is asked: " + ", ".join(t.value for t in RoadUserType),
    )
    parser.add_argument(
        "--ego-mass",
        type=float,
        default=EGO_MASS_KG,
        help="mass of the ego it collides with [kg], for the implied closing speed",
    )
    add_json(parser)
    parser.set_defaults(handler=_run)


def _resolve_model(model: str | None, partner: RoadUserType) -> HarmModel:
    """Return the harm model for ``partner``, checked against its protection."""
    unprotected = partner in UNPROTECTED_TYPES
    if model is None:
        return DEFAULT_PEDESTRIAN_MODEL if unprotected else DEFAULT_MODEL
    chosen = HarmModel.parse(model)
    takes_unprotected = coefficients(chosen).form is FunctionalForm.UNPROTECTED_LOGISTIC
    if takes_unprotected != unprotected:
        allowed = [
            m.value
            for m in HarmModel
            if (coefficients(m).form is FunctionalForm.UNPROTECTED_LOGISTIC) == unprotected
        ]
        kind = "unprotected" if unprotected else "protected"
        raise ValueError(
            f"partner {partner.value} is {kind}; model {chosen.value} does not apply; "
            f"allowed: {', '.join(allowed)}"
        )
    return chosen


def _area_angle(area: str | None, model: HarmModel) -> float | None:
    """Angle [rad] of the impact area named ``area``, or None if ``model`` has no areas."""
    scheme = coefficients(model).areas
    if area is None:
        if scheme is AreaScheme.NONE:
            return None
        raise ValueError(f"model {model.value} needs --area: {_ALLOWED_AREAS}")
    name = area.strip().lower()
    if name in _NAMED_AREAS_DEG:
        if name == "side" and scheme in _ASYMMETRIC:
            raise ValueError(
                f"area 'side' is ambiguous for the asymmetric model {model.value}; "
                "use driver_side or right_side"
            )
        degrees = _NAMED_AREAS_DEG[name]
    elif name.isdigit() and 1 <= int(name) <= 12:
        degrees = 30.0 * (12 - int(name))
    else:
        raise ValueError(f"unknown area {area!r}; allowed: {_ALLOWED_AREAS}")
    return None if scheme is AreaScheme.NONE else float(wrap_angle(math.radians(degrees)))


def _run(args: argparse.Namespace) -> int:
    partner = RoadUserType.parse(args.partner)
    model = _resolve_model(args.model, partner)
    angle = _area_angle(args.area, model)
    if not 0.0 <= args.dv <= MAX_DV:
        raise ValueError(f"--dv must lie in [0, {MAX_DV:g}] m/s, got {args.dv}")
    if not 100.0 <= args.ego_mass <= 60000.0:
        raise ValueError(f"--ego-mass must lie in [100, 60000] kg, got {args.ego_mass}")
    probability = float(harm(model, args.dv, angle))
    c = coefficients(model)
    shape = DEFAULT_SHAPES[partner]
    partner_mass = mass_of(partner, shape.length, shape.width)
    # Eq. 1: dv_partner = m_ego / (m_ego + m_partner) * closing speed.
    closing = args.dv * (args.ego_mass + partner_mass) / args.ego_mass
    ego_dv = args.dv * partner_mass / args.ego_mass
    if args.json:
        record = {
            "model": model.value,
            "label": c.label,
            "injury": c.injury,
            "partner": partner.value,
            "unprotected": partner in UNPROTECTED_TYPES,
            "partner_mass_kg": partner_mass,
            "dv_mps": args.dv,
            "area": args.area,
            "angle_rad": angle,
            "probability": probability,
            "ego_mass_kg": args.ego_mass,
            "closing_speed_mps": closing,
            "ego_dv_mps": ego_dv,
        }
        print_json(record)
        return 0
    area = "" if args.area is None else f", area {args.area}"
    if args.area is not None and angle is None:
        area += " (not used by this model)"
    print(
        f"{model.value} ({c.label}): {partner.value} dv {args.dv:.2f} m/s{area} -> "
        f"P({c.injury}) = {probability:.3f}  "
        f"[closing speed {closing:.2f} m/s with a {args.ego_mass:.0f} kg ego]"
    )
    return 0
