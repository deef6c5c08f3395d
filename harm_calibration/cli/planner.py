"""``etp harm`` and ``etp plan``: the harm model and the planner, open loop."""

from __future__ import annotations

import argparse

from harm_calibration.cli import harm as harm_cli
from harm_calibration.cli.common import add_json, print_json


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``harm`` and ``plan`` to ``etp``."""
    harm_cli.register(subparsers)

    plan = subparsers.add_parser(
        "plan",
        help="plan a few cycles of a built-in situation and print the decision records",
        description="Open loop, no physics: the ego overtakes a cyclist with oncoming traffic "
        "(paper Fig. 3). Each cycle prints the decision record: the validity level chosen and "
        "why, every principle's cost, and each road user's collision probability, harm and risk.",
    )
    plan.add_argument(
        "--planner", default="ethical", help="ethical, selfish, standard or ethical_responsible"
    )
    plan.add_argument("--cycles", type=int, default=3, help="planning cycles to run (default 3)")
    add_json(plan)
    plan.set_defaults(handler=_plan)


def _plan(args: argparse.Namespace) -> int:
    """Overtaking a cyclist with oncoming traffic (paper Fig. 3), open loop."""
    from dataclasses import replace

    from ethical_planner.config import preset
    from ethical_planner.planner import Planner
    from ethical_planner.situations import overtaking_cyclist

    if args.cycles < 1:
        raise ValueError("--cycles must be >= 1")
    situation = overtaking_cyclist()
    planner = Planner(preset(args.planner), situation.environment)
    ego, users = situation.ego, situation.road_users
    records = []
    for cycle in range(args.cycles):
        decision = planner.plan(ego, users)
        records.append(decision.to_dict())
        if not args.json:
            print(f"cycle {cycle} at t = {cycle * 0.1:.1f} s")
            print(decision.summary())
        # Advance open loop by one step along the plan; others keep their speed.
        traj = decision.trajectory
        ego = replace(
            ego,
            x=float(traj.x[1]),
            y=float(traj.y[1]),
            yaw=float(traj.yaw[1]),
            v=float(traj.v[1]),
            a=float(traj.a[1]),
        )
        users = [u.advanced(0.1) for u in users]
    if args.json:
        print_json(records)
    return 0
