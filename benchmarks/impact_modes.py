"""Delta-v of the contact modes against rigid-body mechanics, and the biases issue 10 measured.

Three tables, each contact mode (``rigid``, ``crush``, ``soft``) side by side:

1. The named impacts at 20 m/s closing of ``tests/mujoco_world/physics/test_named_impacts.py``
   (head-on, offset frontal 75/50/25 %, T-bone at the rear axle, T-bone into a moving car,
   pedestrian 0.85 m off centre): measured |J| / m of both bodies (whole sequence and first
   impulse), the planar impulse model and paper Eq. 1, each as a relative error against the
   independent rigid-body computation of ``tests/mujoco_world/physics/rigid_reference.py``
   (no MuJoCo, no ``ethical_planner.impulse``; Hunt-Crossley corners, the default
   restitution law, Coulomb friction 0.3).
2. Pedestrian bias: the car's front centre line 0.85 m and 0.95 m off a standing
   pedestrian at 5, 10 and 20 m/s, measured against the same reference.
3. Glancing speed dependence: the sweep's truck-front-into-car-side cell (90 deg, offset
   0.5), measured / Eq. 1 of the car at closing speeds 3-30 m/s, with the number of
   impulses of each sequence (rigid-body ratios do not depend on speed).

The named cases and the reference are loaded from the test folder, so this script and
the tests measure the same thing. Run: python benchmarks/impact_modes.py
"""

from __future__ import annotations

import argparse
import importlib.util
import math
from pathlib import Path
from types import ModuleType

import numpy as np

from ethical_planner.impulse import RestitutionLaw
from ethical_planner.road_users import EGO_MASS_KG, EGO_SHAPE, KinematicState
from harm_calibration.sweep import ImpactCase, run_case
from mujoco_world.evaluation.compare import compare_impact
from mujoco_world.physics.impact import ImpactRig
from mujoco_world.physics.scene import BodyProxy
from mujoco_world.scenario.spec import ContactMode, ContactSpec

TESTS = Path(__file__).resolve().parents[1] / "tests" / "mujoco_world" / "physics"
MODES = tuple(m.value for m in ContactMode)


def _load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, TESTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _rig(kind: str, mode: str) -> ImpactRig:
    """The default ego against a ``kind`` partner in a contact mode, coasting (no brakes)."""
    ego = BodyProxy("a", "car", EGO_SHAPE.length, EGO_SHAPE.width, EGO_MASS_KG)
    return ImpactRig(ego, BodyProxy.of_type("b", kind), ContactSpec(mode=ContactMode(mode)), brake=False)


def _reference_dv(reference: ModuleType, rig: ImpactRig, m) -> tuple[float, float]:  # noqa: ANN001
    """Reference |J| / m of both bodies from the measurement's pre-impact states."""
    mine, partner = rig.scene.bodies
    bodies = [
        reference.Body(b.mass, body.length, body.width, *b.position, b.yaw, *b.velocity, disc=body.is_round)
        for b, body in ((m.a, mine), (m.b, partner))
    ]
    law = RestitutionLaw()
    impulse = float(np.hypot(*reference.collide(*bodies, law, ContactSpec().friction, law="hunt_crossley")))
    return impulse / m.a.mass, impulse / m.b.mass


def _pct(x: float) -> str:
    return f"{100 * x:+.1f} %" if math.isfinite(x) else "-"


def named_table(reference: ModuleType, named: dict, modes: tuple[str, ...]) -> None:
    """Table 1: named impacts, relative errors against the reference (body a / body b)."""
    print("| case | mode | reference dv a / b [m/s] | measured (sequence) | measured (first impulse) "
          "| impulses | planar model | Eq. 1 |")  # fmt: skip
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    errors: dict[str, list[float]] = {f"{m}:{k}": [] for m in modes for k in ("seq", "planar", "eq1")}
    for mode in modes:
        rigs = {kind: _rig(kind, mode) for kind in ("car", "pedestrian")}
        for name, (kind, state_a, state_b) in named.items():
            rig = rigs[kind]
            m = rig.launch(state_a, state_b)
            ref = _reference_dv(reference, rig, m)
            rec = compare_impact(m)
            cols = {
                "seq": (m.a.dv_impulse, m.b.dv_impulse),
                "first": (m.a.dv_first, m.b.dv_first),
                "planar": (rec.a.dv_planar, rec.b.dv_planar),
                "eq1": (rec.a.dv_predicted, rec.b.dv_predicted),
            }
            rel = {k: [(v[i] - ref[i]) / ref[i] for i in (0, 1)] for k, v in cols.items()}
            for k in ("seq", "planar", "eq1"):
                errors[f"{mode}:{k}"] += [abs(x) for x in rel[k]]
            cell = {k: f"{_pct(v[0])} / {_pct(v[1])}" for k, v in rel.items()}
            print(
                f"| {name} | {mode} | {ref[0]:.3f} / {ref[1]:.3f} | {cell['seq']} | {cell['first']} "
                f"| {m.n_impulses} | {cell['planar']} | {cell['eq1']} |"
            )
    print()
    print("| mode | largest abs error: measured (sequence) | planar model | Eq. 1 |")
    print("| --- | ---: | ---: | ---: |")
    for mode in modes:
        e = {k: max(errors[f"{mode}:{k}"]) for k in ("seq", "planar", "eq1")}
        print(f"| {mode} | {100 * e['seq']:.1f} % | {100 * e['planar']:.1f} % | {100 * e['eq1']:.1f} % |")


def pedestrian_table(reference: ModuleType, modes: tuple[str, ...]) -> None:
    """Table 2: pedestrian off the centre line, measured dv of the pedestrian against the reference."""
    offsets, speeds = (0.85, 0.95), (5.0, 10.0, 20.0)
    header = " | ".join(f"{o} m, {v:g} m/s" for o in offsets for v in speeds)
    print(f"| mode | {header} | deepest penetration |")
    print("| --- |" + " ---: |" * (len(offsets) * len(speeds) + 1))
    for mode in modes:
        rig = _rig("pedestrian", mode)
        cells, depth = [], 0.0
        for offset in offsets:
            for v in speeds:
                state_b = KinematicState(0.5 * EGO_SHAPE.length + 0.25 + 0.05, offset, 0.0, 0.0)
                m = rig.launch(KinematicState(0, 0, 0, v), state_b)
                if m is None:
                    cells.append("miss")
                    continue
                ref = _reference_dv(reference, rig, m)[1]
                cells.append(_pct((m.b.dv_impulse - ref) / ref))
                depth = max(depth, m.max_penetration)
        print(f"| {mode} | " + " | ".join(cells) + f" | {100 * depth:.1f} cm |")


def glancing_table(modes: tuple[str, ...]) -> None:
    """Table 3: measured / Eq. 1 of the car in the truck-front-into-car-side cell, by closing speed."""
    speeds = (3.0, 5.0, 10.0, 20.0, 30.0)
    print("| mode | " + " | ".join(f"{v:g} m/s" for v in speeds) + " | spread (max / min - 1) |")
    print("| --- |" + " ---: |" * (len(speeds) + 1))
    for mode in modes:
        ratios, cells = [], []
        for v in speeds:
            row = run_case(ImpactCase("truck", v, 90.0, 0.5, "default", ContactMode(mode)))
            ratio = row["dv_measured_a"] / row["dv_predicted_a"]
            ratios.append(ratio)
            cells.append(f"{ratio:.3f} ({int(row['n_impulses'])})")
        print(f"| {mode} | " + " | ".join(cells) + f" | {100 * (max(ratios) / min(ratios) - 1):.1f} % |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", nargs="+", default=list(MODES), choices=list(MODES))
    args = parser.parse_args()
    modes = tuple(args.modes)
    reference = _load("rigid_reference")
    named = _load("test_named_impacts").NAMED
    print("## Named impacts at 20 m/s closing: relative error against rigid-body mechanics (a / b)\n")
    named_table(reference, named, modes)
    print("\n## Pedestrian off the car's centre line: measured dv against rigid-body mechanics\n")
    pedestrian_table(reference, modes)
    print("\n## Truck front into a car side (90 deg, offset 0.5): measured / Eq. 1 of the car (impulses)\n")
    glancing_table(modes)


if __name__ == "__main__":
    main()
