"""``etp bench``: the planning-cycle benchmark (``benchmarks/planning_cycle.py``)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``bench`` to ``etp``."""
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


def _bench(args: argparse.Namespace) -> int:
    from benchmarks.planning_cycle import format_table, run_benchmark

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
