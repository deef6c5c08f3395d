"""``etp bench``: the planning-cycle benchmark (``benchmarks/planning_cycle.py``)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from harm_calibration.cli.common import add_json, output_file, print_json, say

#: The benchmark's candidate sets (``benchmarks.planning_cycle.GRID_NAMES``; listed here so
#: that ``etp --help`` does not import the benchmarks).
GRID_NAMES = ("default", "225", "2025")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``bench`` to ``etp``."""
    bench = subparsers.add_parser(
        "bench",
        help="time the full ethical planning cycle (and frenetix's, if installed)",
        description="Time sampling, prediction, collision probability, harm, all principles, "
        "validity levels and selection on the ethical preset's default candidates and the paper's "
        "225 and 2025 grids with 0, 5 and 20 road users, and the first cycle of a new process "
        "(compiled kernels compiled, then loaded from the disk cache).",
    )
    bench.add_argument("--repetitions", type=int, default=20, help="timed cycles per cell (default 20)")
    bench.add_argument(
        "--grid", choices=list(GRID_NAMES), action="append", help="only this candidate set (repeatable)"
    )
    bench.add_argument("--no-peer", action="store_true", help="do not time frenetix")
    bench.add_argument(
        "--no-first-call", action="store_true", help="do not time the first cycle of a new process"
    )
    bench.add_argument("--out", type=Path, metavar="FILE", help="also write the rows as JSON to FILE")
    add_json(bench)
    bench.set_defaults(handler=_bench)


def _bench(args: argparse.Namespace) -> int:
    from benchmarks.planning_cycle import (
        first_call_times,
        format_first_call_table,
        format_prediction_table,
        format_table,
        run_benchmark,
        time_predictors,
    )

    if args.repetitions < 1:
        raise ValueError(f"--repetitions must be >= 1, got {args.repetitions}")
    if args.out is not None:
        output_file(args.out, "--out")  # before timing anything
    rows = run_benchmark(
        repetitions=args.repetitions,
        grids=tuple(args.grid or GRID_NAMES),
        peer=not args.no_peer,
    )
    if args.json:
        print_json(rows)
    else:
        print(format_table(rows))
        print()
        print(format_prediction_table(time_predictors(20, args.repetitions)))
        if not args.no_first_call:
            print()
            print(format_first_call_table(first_call_times()))
    if args.out is not None:
        args.out.write_text(json.dumps(rows, indent=2), encoding="utf-8")
        say(args, f"wrote {args.out}")
    return 0
