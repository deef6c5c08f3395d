"""``etp study``: the paper's experiment (Figs. 5 and 6) on your scenarios, with statistics and a report."""

from __future__ import annotations

import argparse

from ethical_planner.validation import check
from harm_calibration.cli.common import (
    add_config,
    add_json,
    output_dir,
    parse_seeds,
    planner_configs,
    print_json,
    say,
    show_progress,
    split_items,
)
from harm_calibration.cli.process import keep_freed_memory

EXAMPLE = """\
examples:
  etp study ../shared/commonroad --out logs/study            every *.xml and *.toml below the folder
  etp study 'data/**/*.xml' pedestrian_behind_parked --planners ethical,standard
  etp study my_scenarios --backend dask --scheduler tcp://10.0.0.5:8786 --out /shared/study

The study runs each scenario x planner x seed headless, one folder per run
(<out>/<run id>/summary.json, index.jsonl), and writes statistics.json, fig5_risks.png/.pdf,
fig6_harm.png/.pdf, table.txt and report.md into --out. Rerunning the same command resumes:
finished runs are read back, not run again. A scenario the importer refuses, or a run that
fails, is recorded with its reason and the study goes on.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``etp study``."""
    p = subparsers.add_parser(
        "study",
        help="run the paper's planner comparison on scenario folders and write figures, statistics, report",
        description="The paper's evaluation (Geisslinger et al. 2023, Figs. 5 and 6) on your scenarios: "
        "every scenario with every planner in closed loop, then the 100 highest risks per group "
        "(ego, 3rd party, VRU), the measured harm per group, bootstrap confidence intervals, "
        "paired Wilcoxon tests between planners over the same scenarios with effect sizes, a table "
        "of outcomes and crashes per 1000 km, and report.md stating which of the paper's claims "
        "the runs support.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "scenarios",
        nargs="+",
        metavar="SCENARIO",
        help="catalog or generated names, .toml or CommonRoad .xml files (FILE.xml#ID picks a "
        "planning problem), folders (every .xml and .toml below) or quoted globs",
    )
    p.add_argument(
        "--planners",
        default="ethical,selfish,standard",
        help="comma-separated planners (default ethical,selfish,standard)",
    )
    add_config(p)
    p.add_argument("--seeds", default="0", help="comma-separated run seeds, each >= 0 (default 0)")
    p.add_argument("--out", default="logs/study", metavar="DIR", help="output folder (default logs/study)")
    p.add_argument(
        "--backend",
        default="process",
        help="process (a local process pool, default) or dask (a Dask distributed cluster)",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="address of a running Dask scheduler (tcp://host:8786); without it --backend dask starts "
        "a LocalCluster on 127.0.0.1",
    )
    p.add_argument("--workers", type=int, default=2, help="worker processes on this machine (default 2)")
    p.add_argument(
        "--keep-recordings",
        choices=["all", "near-crash"],
        default="near-crash",
        help="keep every Rerun recording, or only those of near-crash runs (default)",
    )
    p.add_argument("--no-record", action="store_true", help="write no Rerun recordings")
    p.add_argument(
        "--analyse-only",
        action="store_true",
        help="run nothing: analyse the runs of these scenarios already stored in --out (a study "
        "stopped early), and write the figures, statistics and report of those",
    )
    p.add_argument(
        "--motorcycles-not-vru",
        action="store_true",
        help="count motorcyclists with the 3rd parties only, not as VRUs (the paper's reference "
        "evaluation counts them as VRUs)",
    )
    p.add_argument(
        "--resamples", type=int, default=2000, help="bootstrap resamples per interval (default 2000)"
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_json(p)
    p.set_defaults(handler=_study)


def _study(args: argparse.Namespace) -> int:
    from harm_calibration.study.analysis import GroupDefinition
    from harm_calibration.study.runner import STUDY_BACKENDS, BackendOptions, run_study, speed
    from harm_calibration.study.scenarios import expand_scenarios
    from mujoco_world.experiments.batch import make_tasks

    check(args.workers >= 1, f"--workers must be >= 1, got {args.workers}")
    check(100 <= args.resamples <= 100_000, f"--resamples must lie in [100, 100000], got {args.resamples}")
    check(args.backend != "none", "--backend none is spelled --analyse-only")
    STUDY_BACKENDS.get(args.backend)  # an unknown backend lists the registered ones
    check(args.scheduler is None or args.backend == "dask", "--scheduler needs --backend dask")
    scenarios = expand_scenarios(args.scenarios)
    planners = planner_configs(split_items(args.planners, "--planners"), args.config)
    seeds = parse_seeds(args.seeds)
    root = output_dir(args.out)
    tasks = make_tasks(scenarios, planners, seeds, root, record=not args.no_record, keep=args.keep_recordings)
    names = [p if isinstance(p, str) else p.name for p in planners]
    say(args, f"{len(tasks)} runs: {len(scenarios)} scenarios x {len(names)} planners x {len(seeds)} seed(s)")
    options = BackendOptions(
        workers=args.workers,
        scheduler=args.scheduler,
        progress=show_progress(args),
        worker_initializer=keep_freed_memory,
    )
    study = run_study(
        tasks,
        names,
        backend="none" if args.analyse_only else args.backend,
        options=options,
        groups=GroupDefinition(motorcycles=not args.motorcycles_not_vru),
        resamples=args.resamples,
    )
    outcomes: dict[str, int] = {}
    for result in study.results:
        outcome = result.record.summary.outcome
        outcomes[outcome] = outcomes.get(outcome, 0) + 1
    paths = {name: str(path) for name, path in study.paths.items()}
    if args.json:
        print_json(
            {
                "runs": len(study.results),
                "outcomes": outcomes,
                **speed(study.results, study.wall_time),
                **paths,
            }
        )
        return 0
    print(study.paths["report"].read_text(encoding="utf-8").split("## Fig. 5")[0].rstrip())
    resumed = sum(1 for r in study.results if r.resumed)
    say(
        args,
        f"\n{len(study.results)} runs ({resumed} resumed) in {study.wall_time:.0f} s, outcomes {outcomes}",
    )
    say(args, f"report: {paths['report']}; figures: {paths['fig5_png']}, {paths['fig6_png']}")
    return 0
