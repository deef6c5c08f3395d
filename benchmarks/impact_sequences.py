"""Multi-impact sequences: what a sequence-aware prediction would have to reproduce.

For every vehicle impact of an ``etp impacts`` table whose sequence is flagged
``multi_impact``, the ego's delta-v (|J| / m):

* measured in the rigid mode as the sweep does it (bodies skid at the tyre limit between
  impulses), over the whole sequence and its first impulse;
* measured with coasting bodies (no tyre forces between impulses);
* with ``--reference`` also the independent rigid-body reference
  (``tests/mujoco_world/physics/rigid_reference.py``, no MuJoCo; pure Python, about a
  minute per sequence) integrated over the whole sequence of the *free* bodies, until they
  have been apart for 0.3 s;
* the planar impulse model (first contact only), the planar sequence model (every hit,
  bodies skidding between them as in the sweep; ``harm_calibration.sequence``, read from
  the table, "-" for a table without it) and paper Eq. 1.

Coasting bodies show what the tyre forces between hits change: the sequence model takes
them (``ethical_planner.impulse.SkidModel``).

Run: python benchmarks/impact_sequences.py logs/small_rigid/impacts.csv [--reference]
"""

from __future__ import annotations

import argparse
import importlib.util
from pathlib import Path

import numpy as np

from ethical_planner.impulse import RestitutionLaw
from ethical_planner.road_users import DEFAULT_SHAPES, EGO_SHAPE, RoadUserType
from harm_calibration.rows import read_rows
from harm_calibration.sweep import ImpactCase, contact_for, ego_proxy, launch_case, restitution_for
from mujoco_world.physics.impact import ImpactRig
from mujoco_world.physics.scene import BodyProxy

TESTS = Path(__file__).resolve().parents[1] / "tests" / "mujoco_world" / "physics"
VEHICLES = ("car", "truck", "bus")


def _reference():  # noqa: ANN202 - a module
    spec = importlib.util.spec_from_file_location("rigid_reference", TESTS / "rigid_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _stats(errors: list[float]) -> str:
    e = np.abs(np.array(errors))
    e = e[np.isfinite(e)]
    if not e.size:
        return "-"
    return f"median {100 * np.median(e):.1f} %, p95 {100 * np.percentile(e, 95):.1f} %"


def _reference_dv(reference, case: ImpactCase, m) -> float:  # noqa: ANN001
    """The ego's |J| / m over the whole sequence of free rigid bodies, from the measured launch."""
    shape = DEFAULT_SHAPES[RoadUserType(case.partner)]
    a = reference.Body(m.a.mass, EGO_SHAPE.length, EGO_SHAPE.width, *m.a.position, m.a.yaw, *m.a.velocity)
    b = reference.Body(m.b.mass, shape.length, shape.width, *m.b.position, m.b.yaw, *m.b.velocity)
    law: RestitutionLaw = restitution_for(case.restitution_set)
    impulse = reference.collide(
        a, b, law, contact_for(case.restitution_set).friction, law="hunt_crossley", t_max=2.0,
        apart=0.3, dt_free=2e-5,
    )  # fmt: skip
    return float(np.hypot(*impulse)) / m.a.mass


def main() -> None:
    """Print the table and the summary."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("impacts", type=Path, help="impacts.csv of etp impacts --grid small|full")
    parser.add_argument("--reference", action="store_true", help="integrate the rigid-body reference too")
    args = parser.parse_args()
    rows = [
        r for r in read_rows(args.impacts)
        if r["status"] == "ok" and r["partner"] in VEHICLES and r.get("multi_impact") == "yes"
    ]  # fmt: skip
    reference = _reference() if args.reference else None
    coasting: dict[tuple[str, str], ImpactRig] = {}
    print(
        "| impact | impulses | measured first | measured sequence | coasting sequence "
        "| free rigid bodies (reference) | planar | Eq. 1 |"
    )
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    nan = float("nan")
    err: dict[str, list[float]] = {
        k: []
        for k in (
            "planar",
            "sequence",
            "eq1",
            "coasting",
            "first_coasting",
            "reference",
            "reference_coasting",
        )
    }
    for r in rows:
        case = ImpactCase(r["partner"], r["closing_speed"], r["angle_deg"], r["offset"], r["restitution_set"])
        key = (case.partner, case.restitution_set)
        if key not in coasting:
            partner = BodyProxy.of_type("partner", case.partner)
            contact = contact_for(case.restitution_set)
            coasting[key] = ImpactRig(ego_proxy(), partner, contact=contact, brake=False)
        m = launch_case(case, coasting[key])
        if m is None:
            continue
        ref = _reference_dv(reference, case, m) if args.reference else nan
        measured = r["dv_measured_a"]
        err["planar"].append((measured - r["dv_planar_a"]) / r["dv_planar_a"])
        err["sequence"].append((measured - r["dv_planar_seq_a"]) / r["dv_planar_seq_a"])
        err["eq1"].append((measured - r["dv_predicted_a"]) / r["dv_predicted_a"])
        err["reference"].append((measured - ref) / ref)
        err["reference_coasting"].append((m.a.dv_impulse - ref) / ref)
        err["coasting"].append((measured - m.a.dv_impulse) / m.a.dv_impulse)
        err["first_coasting"].append((m.a.dv_impulse - r["dv_planar_a"]) / r["dv_planar_a"])
        print(
            f"| {case.id} | {r['n_impulses']:.0f} | {r['dv_first_a']:.2f} | {measured:.2f} "
            f"| {m.a.dv_impulse:.2f} | {ref:.2f} | {r['dv_planar_a']:.2f} | {r['dv_predicted_a']:.2f} |"
        )
    print()
    print(f"{len(err['planar'])} multi-impact vehicle sequences; |measured sequence - model| / model:")
    print(f"- planar model (first contact): {_stats(err['planar'])}")
    print(f"- planar sequence model (every hit, skidding): {_stats(err['sequence'])}")
    print(f"- Eq. 1: {_stats(err['eq1'])}")
    print(f"- the same sequence measured with coasting bodies: {_stats(err['coasting'])}")
    print(f"- free rigid bodies (reference): {_stats(err['reference'])}")
    print(f"coasting sequence against the planar model (first contact): {_stats(err['first_coasting'])}")
    print(f"coasting sequence against the free rigid bodies (reference): {_stats(err['reference_coasting'])}")


if __name__ == "__main__":
    main()
