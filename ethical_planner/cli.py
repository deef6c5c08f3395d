"""Subcommands of the ``ethical_planner`` layer: ``harm``, ``bench``, ``plan``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from . import harm_cli


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add this layer's subcommands to ``etp``."""
    harm_cli.register(subparsers)

    bench = subparsers.add_parser(
        "bench",
        help="time the full ethical planning cycle (and frenetix's, if installed)",
        description="Time sampling, prediction, collision probability, harm, all principles, "
        "validity levels and selection on 225 and 2025 candidates with 0, 5 and 20 road users.",
    )
    bench.add_argument("--repetitions", type=int, default=20, help="timed cycles per cell (default 20)")
    bench.add_argument("--grid", choices=["225", "2025"], action="append", help="only this grid (repeatable)")
    bench.add_argument("--no-peer", action="store_true", help="do not time frenetix")
    bench.add_argument("--json", type=Path, metavar="FILE", help="also write the table as JSON")
    bench.set_defaults(handler=_bench)

    plan = subparsers.add_parser(
        "plan",
        help="plan a few cycles of a built-in situation and print the decision records",
    )
    plan.add_argument(
        "--planner", default="ethical", help="ethical, selfish, standard or ethical_responsible"
    )
    plan.add_argument("--cycles", type=int, default=3, help="planning cycles to run (default 3)")
    plan.add_argument("--json", action="store_true", help="print the decision records as JSON")
    plan.set_defaults(handler=_plan)


def _bench(args: argparse.Namespace) -> int:
    from .bench import format_table, run_benchmark

    if args.repetitions < 1:
        raise ValueError("--repetitions must be >= 1")
    rows = run_benchmark(
        repetitions=args.repetitions,
        grids=tuple(args.grid or ("225", "2025")),
        peer=not args.no_peer,
    )
    print(format_table(rows))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=2))
        print(f"wrote {args.json}")
    return 0


def _plan(args: argparse.Namespace) -> int:
    """Overtaking a cyclist with oncoming traffic (paper Fig. 3), open loop."""
    from dataclasses import replace

    from .config import preset
    from .planner import Planner
    from .situations import overtaking_cyclist

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
        print(json.dumps(records, indent=2))
    return 0
