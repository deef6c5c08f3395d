"""Subcommands of the ``harm_calibration`` layer (impact sweeps, calibration, refit).

``etp impacts --grid small|full --out DIR``: controlled impact sweep, resumable.
``etp impacts --from-runs RUNS --out DIR``: the same comparison over run collisions.
``etp refit-harm FILE.csv [--model reduced_sym] [--json]``: logistic refit.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

from ethical_planner.harm import HarmModel


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add this layer's subcommands to ``etp``."""
    impacts = subparsers.add_parser(
        "impacts",
        help="measure impacts in MuJoCo and compare them with the harm model",
        description="Controlled impact sweep (--grid) or closed-loop collisions (--from-runs): "
        "measured vs Eq. 1 delta-v, impact areas, harm; writes impacts.csv, summary.json, "
        "report.md, calibration.json and PNG plots to --out.",
    )
    source = impacts.add_mutually_exclusive_group()
    source.add_argument("--grid", choices=["small", "full"], default=None, help="sweep grid (default small)")
    source.add_argument(
        "--from-runs", type=Path, default=None, metavar="DIR", help="folder of etp run/demo output"
    )
    impacts.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    impacts.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1), help="processes")
    impacts.add_argument("--seed", type=int, default=0, help="seed of the calibration train/test split")
    impacts.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    impacts.add_argument("--no-progress", action="store_true", help="no progress bar")
    impacts.set_defaults(handler=_impacts)

    refit = subparsers.add_parser(
        "refit-harm",
        help="refit a logistic harm model to crash records",
        description="Maximum-likelihood refit from a CSV with columns dv [m/s], mais3 (0/1), "
        "area (area models) and optional weight.",
    )
    refit.add_argument("file", type=Path, help="crash records CSV")
    refit.add_argument("--model", default=HarmModel.REDUCED_SYM.value, help="logistic harm model to refit")
    refit.add_argument("--json", action="store_true", help="print JSON instead of a table")
    refit.set_defaults(handler=_refit)


def _impacts(args: argparse.Namespace) -> int:
    from harm_calibration.analysis import analyse, headline_markdown
    from harm_calibration.closed_loop import rows_from_runs
    from harm_calibration.rows import write_rows
    from harm_calibration.sweep import GRIDS, Grid, run_sweep

    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    if args.from_runs is not None:
        rows = rows_from_runs(args.from_runs)
        if not rows:
            raise ValueError(f"--from-runs: no collisions in the summary.json files under {args.from_runs}")
        write_rows(out / "impacts.csv", rows)
        title = f"Closed-loop impacts from {args.from_runs}"
    else:
        grid = Grid(args.grid or "small")
        rows = run_sweep(
            GRIDS[grid].cases(), out / "impacts.csv", args.workers, progress=not args.no_progress
        )
        title = f"Impact sweep, {grid.value} grid"
    summary = analyse(out, rows, title, seed=args.seed, plots=not args.no_plots)
    print(headline_markdown(summary))
    if "calibration" in summary:
        before = summary["calibration"]["test_error_eq1"]["all"]
        after = summary["calibration"]["test_error_calibrated"]["all"]
        print(
            f"calibration (test set): median |dv error| {before['median_abs']:.1%} -> "
            f"{after['median_abs']:.1%}, "
            f"p95 {before['p95_abs']:.1%} -> {after['p95_abs']:.1%}"
        )
    print(f"{len(rows)} impacts in {time.perf_counter() - start:.1f} s; report: {out / 'report.md'}")
    return 0


def _refit(args: argparse.Namespace) -> int:
    from harm_calibration.refit import fit_logistic, read_records

    model = HarmModel.parse(args.model)
    result = fit_logistic(read_records(args.file, model), model)
    print(json.dumps(result.to_dict(), indent=2) if args.json else result.table())
    return 0
