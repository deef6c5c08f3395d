"""Restitution of the contact modes: the soft mode's table, and the rigid mode against its law.

Two default cars (1475 kg) collide head-on at 1.25-15 m/s each, at three contact phases
within a physics step; the restitution at the contact point along the normal is
averaged. ``--mode soft`` prints the ``(dampratio, e)`` table of
``mujoco_world.physics.contact`` (MuJoCo constraint contacts, solref 0.05 s);
``--mode rigid`` prints the measured restitution against the restitution law.

Run: python benchmarks/restitution_table.py [--mode soft|rigid]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from ethical_planner.impulse import RestitutionLaw
from ethical_planner.road_users import KinematicState
from mujoco_world.physics.impact import ImpactRig
from mujoco_world.physics.scene import BodyProxy
from mujoco_world.scenario.spec import ContactMode, ContactSpec

DAMPRATIOS = (0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0)
SPEEDS = (1.25, 5.0, 10.0, 15.0)
GAPS = (0.05, 0.0523, 0.0571)


def launches(rig: ImpactRig, speed: float) -> list[float]:
    reach = 0.5 * (rig.scene.bodies[0].length + rig.scene.bodies[1].length)
    return [
        rig.launch(KinematicState(0, 0, 0, speed), KinematicState(reach + gap, 0, math.pi, speed)).restitution
        for gap in GAPS
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mode", default="rigid", choices=["soft", "rigid"])
    args = parser.parse_args()
    cars = BodyProxy.of_type("a", "car"), BodyProxy.of_type("b", "car")
    if args.mode == "soft":
        print(f"{'dampratio':>9} {'e':>8} {'spread':>8}")
        for ratio in DAMPRATIOS:
            rig = ImpactRig(*cars, ContactSpec(mode=ContactMode.SOFT, dampratio=ratio), brake=False)
            values = [e for v in SPEEDS for e in launches(rig, v)]
            print(f"{ratio:>9.2f} {np.mean(values):>8.4f} {np.ptp(values):>8.4f}")
        return
    law = RestitutionLaw()
    rig = ImpactRig(*cars, brake=False)
    print(f"{'closing m/s':>11} {'law e':>8} {'measured':>9} {'spread':>8}")
    for v in SPEEDS:
        values = launches(rig, v)
        print(f"{2 * v:>11.1f} {float(law(2 * v)):>8.4f} {np.mean(values):>9.4f} {np.ptp(values):>8.4f}")


if __name__ == "__main__":
    main()
