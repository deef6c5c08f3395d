"""Subcommands of the ``harm_calibration`` layer (impact sweeps, calibration, refit).

``etp impacts --grid small|full|speed [--contact rigid] --out DIR``: controlled impact sweep, resumable.
``etp impacts --from-runs RUNS --out DIR``: the same comparison over run collisions.
``etp refit-harm FILE.csv [--model reduced_sym] [--json]``: logistic refit of crash
records or of an ``impacts.csv``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from ethical_planner.harm import HarmModel
from harm_calibration.cli.common import add_json, output_dir, print_json, show_progress


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add this layer's subcommands to ``etp``."""
    impacts = subparsers.add_parser(
        "impacts",
        help="measure impacts in MuJoCo and compare them with the harm model",
        description="Controlled impact sweep (--grid) or closed-loop collisions (--from-runs): "
        "measured delta-v against paper Eq. 1 and the planar impulse model, impact areas, harm; "
        "held-back evaluation by geometry cell; writes impacts.csv, summary.json, report.md and "
        "figures (PNG and PDF) to --out.",
    )
    source = impacts.add_mutually_exclusive_group()
    source.add_argument(
        "--grid",
        choices=["small", "full", "speed"],
        default=None,
        help="sweep grid (default small): small 336 impacts; full every angle x offset bin; speed the "
        "small grid's car, truck and bus cells at a constant restitution 0.1 (speed independence)",
    )
    source.add_argument(
        "--from-runs", type=Path, default=None, metavar="DIR", help="folder of etp run/demo output"
    )
    source.add_argument(
        "--pulses",
        action="store_true",
        help="crash pulses of the crush and rigid modes (car into a wall at 56 km/h, ...): "
        "pulses.md and crash_pulses.png/pdf",
    )
    impacts.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    impacts.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1), help="processes")
    impacts.add_argument(
        "--contact", choices=["rigid", "crush", "soft"], default="rigid", help="contact mode of the sweep"
    )
    impacts.add_argument(
        "--seeds", type=int, default=10, help="held-back splits by geometry cell (seeds 0..N-1, default 10)"
    )
    impacts.add_argument("--no-plots", action="store_true", help="skip the figures")
    impacts.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_json(impacts)
    impacts.set_defaults(handler=_impacts)

    refit = subparsers.add_parser(
        "refit-harm",
        help="refit a logistic harm model to crash records or to an etp impacts table",
        description="Maximum-likelihood refit of a logistic harm model, with standard errors. "
        "FILE is either crash records (CSV columns dv [m/s], mais3 (0/1), area for area models, "
        "optional weight) or the impacts.csv of 'etp impacts': then each body assessed with "
        "--model is a record whose outcome is the harm at the measured delta-v and area and "
        "whose inputs are the planner's predicted ones (--inputs). Separable or "
        "rank-deficient records are refused with the reason.",
    )
    refit.add_argument("file", type=Path, metavar="FILE.csv", help="crash records or impacts.csv")
    refit.add_argument(
        "--model",
        default=HarmModel.REDUCED_SYM.value,
        help="logistic harm model to refit: "
        + ", ".join(m.value for m in HarmModel if not m.value.startswith("ref_speed")),
    )
    refit.add_argument(
        "--inputs",
        choices=["predicted", "measured"],
        default="predicted",
        help="impacts.csv only: fit on the planner's predicted delta-v and area (default) or on the "
        "measured ones (gives back the shipped coefficients, a check)",
    )
    add_json(refit)
    refit.set_defaults(handler=_refit)


def _impacts(args: argparse.Namespace) -> int:
    import dataclasses

    from harm_calibration.analysis import analyse, headline_markdown
    from harm_calibration.closed_loop import rows_from_runs
    from harm_calibration.rows import write_rows
    from harm_calibration.sequence import add_sequence_model
    from harm_calibration.sweep import GRIDS, Grid, run_sweep

    out = output_dir(args.out)
    if args.from_runs is not None and not Path(args.from_runs).is_dir():
        raise ValueError(f"--from-runs {args.from_runs}: no such folder")
    if args.seeds < 1:
        raise ValueError(f"--seeds must be >= 1, got {args.seeds}")
    if args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    start = time.perf_counter()
    if args.pulses:
        from harm_calibration.pulses import crash_pulses, pulse_table, write_pulse_figure

        pulses = crash_pulses()
        table = pulse_table(pulses)
        figure = [] if args.no_plots else [write_pulse_figure(out, pulses)]
        text = "# Crash pulses\n\n" + table + "\n" + "".join(f"\n![{f}]({f})\n" for f in figure)
        (out / "pulses.md").write_text(text, encoding="utf-8")
        if args.json:
            print_json({"pulses": [p.summary() for p in pulses], "figures": figure})
            return 0
        print(table)
        print(f"{len(pulses)} pulses in {time.perf_counter() - start:.1f} s; {out / 'pulses.md'}")
        return 0
    if args.from_runs is not None:
        rows = rows_from_runs(args.from_runs)
        if not rows:
            raise ValueError(f"--from-runs: no collisions in the summary.json files under {args.from_runs}")
        write_rows(out / "impacts.csv", rows)
        title = f"Closed-loop impacts from {args.from_runs}"
    else:
        grid = Grid(args.grid or "small")
        spec = dataclasses.replace(GRIDS[grid], mode=args.contact)
        rows = run_sweep(spec.cases(), out / "impacts.csv", args.workers, progress=show_progress(args))
        title = f"Impact sweep, {grid.value} grid, {args.contact} contact"
    # The sequence-aware model, vectorised over every impact (and written to the table).
    rows = add_sequence_model(rows)
    write_rows(out / "impacts.csv", rows)
    summary = analyse(out, rows, title, seeds=tuple(range(args.seeds)), plots=not args.no_plots)
    if args.json:
        print_json(summary)
        return 0
    print(headline_markdown(summary))
    held = summary.get("held_back")
    if held is not None:
        overall = held["groups"]["all"]
        print(
            "held-back cells (median over splits): |dv error| median "
            + ", ".join(
                f"{m} {overall[m]['median_abs']['median']:.1%}"
                for m in ("eq1", "planar", "planar_seq", "correction")
            )
            + "; p95 "
            + ", ".join(
                f"{m} {overall[m]['p95_abs']['median']:.1%}"
                for m in ("eq1", "planar", "planar_seq", "correction")
            )
        )
    print(f"{len(rows)} impacts in {time.perf_counter() - start:.1f} s; report: {out / 'report.md'}")
    return 0


def _refit(args: argparse.Namespace) -> int:
    from harm_calibration.refit import fit_logistic, read_records

    model = HarmModel.parse(args.model)
    result = fit_logistic(read_records(args.file, model, args.inputs), model)
    if args.json:
        print_json(result.to_dict())
    else:
        print(result.table())
    return 0
