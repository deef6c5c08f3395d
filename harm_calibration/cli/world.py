"""``etp scenarios``, ``etp run`` and ``etp demo``: the closed loop from the command line.

``etp run`` and ``etp demo`` write the same layout: ``--out ROOT`` holds one folder per
run (``RunTask.run_dir``, its name is the run id) with ``summary.json`` and
``recording.rrd``, and ``ROOT/index.jsonl``. Nothing is written outside ``ROOT``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

from ethical_planner.validation import check
from harm_calibration.cli.common import (
    add_config,
    add_json,
    non_negative,
    output_dir,
    parse_seeds,
    planner_configs,
    print_json,
    say,
    show_progress,
    split_items,
)
from harm_calibration.cli.process import keep_freed_memory

#: Largest number of runs one ``etp demo`` accepts (``--random`` times planners times seeds).
MAX_RUNS = 100_000


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add this layer's subcommands to ``etp``."""
    p = subparsers.add_parser(
        "scenarios",
        help="list the scenario catalog, one line each",
        description="List the built-in scenario catalog: name, road layout, number of road users "
        "and what happens. Any name can be given to 'etp run' and 'etp demo --scenarios'.",
    )
    add_json(p)
    p.set_defaults(handler=_scenarios)

    p = subparsers.add_parser(
        "run",
        help="run one scenario in closed loop and write ROOT/<run id>/summary.json",
        description="Drive the ego with a planner through a MuJoCo scenario; every "
        "collision is measured from the physics and compared with the harm model. Writes "
        "ROOT/<run id>/summary.json and recording.rrd and a row in ROOT/index.jsonl "
        "(ROOT is --out); an existing run of the same id is replaced.",
    )
    p.add_argument(
        "scenario",
        help="catalog name (see 'etp scenarios'), a generated name such as dense_urban-s3-17, "
        "a scenario .toml file, or a CommonRoad .xml file (FILE.xml#ID picks a planning problem)",
    )
    p.add_argument(
        "--planner",
        default="ethical",
        help="a planner preset (ethical, selfish, standard, ethical_responsible) or a scripted "
        "manoeuvre (keep_lane, emergency_brake); default ethical",
    )
    add_config(p)
    p.add_argument("--seed", type=int, default=0, help="seed of the observation noise, >= 0 (default 0)")
    p.add_argument("--out", default="logs/run", metavar="ROOT", help="output root (default logs/run)")
    p.add_argument(
        "--noise", type=float, default=0.0, help="position noise std [m] of observed road users, >= 0"
    )
    p.add_argument("--replan-rate", type=float, default=10.0, help="planning cycles per second [Hz]")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_json(p)
    _predictor_argument(p)
    _post_crash_argument(p)
    _recording_arguments(p)
    p.set_defaults(handler=_run)

    p = subparsers.add_parser(
        "demo",
        help="run the catalog with the three planners on two cores and print a comparison",
        description="Run every catalog scenario with the ethical, selfish and standard "
        "planners (multiprocessing), one folder per run with summary.json, an "
        "aggregate.json and a comparison table. Existing summaries are skipped (resume; "
        "--retry-failed runs the failed ones again). A run that fails or whose worker "
        "crashes is stored as failed and the batch goes on; Ctrl-C closes the runs in "
        "flight as failed, writes the aggregate of what finished and exits with 130.",
    )
    p.add_argument("--out", default="logs/demo", metavar="ROOT", help="output root (default logs/demo)")
    p.add_argument("--quick", action="store_true", help="run a small subset of the catalog")
    p.add_argument(
        "--scenarios", default=None, help="comma-separated scenario names, .toml or CommonRoad .xml files"
    )
    p.add_argument(
        "--planners",
        default="ethical,selfish,standard",
        help="comma-separated planner presets or scripted manoeuvres (keep_lane, emergency_brake)",
    )
    add_config(p)
    p.add_argument("--seeds", default="0", help="comma-separated run seeds, each >= 0 (default 0)")
    p.add_argument(
        "--random",
        type=int,
        default=0,
        metavar="N",
        help="instead of the catalog, run N random variants of the families (see --scenario-seed)",
    )
    p.add_argument(
        "--scenario-seed", type=int, default=0, help="seed of the random variants, >= 0 (default 0)"
    )
    p.add_argument(
        "--workers",
        type=int,
        default=2,
        help="worker processes (default 2; 1 runs in this process, without crash isolation)",
    )
    p.add_argument(
        "--avoidability",
        action="store_true",
        help="after the runs, search whether each ego collision was avoidable (etp avoidability)",
    )
    p.add_argument(
        "--retry-failed",
        action="store_true",
        help="run again the runs whose stored summary says failed (default: resume skips them)",
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_json(p)
    _predictor_argument(p)
    _post_crash_argument(p)
    _recording_arguments(p)
    p.set_defaults(handler=_demo)


def _predictor_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--predictor",
        default=None,
        help="predictor of the planner (constant_acceleration, constant_turn_rate, learned; "
        "default: the planner configuration's)",
    )


def _post_crash_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--post-crash",
        choices=["brake", "continue"],
        default=None,
        help="what the ego does after its first contact, replacing each scenario's ego.post_crash: "
        "brake to rest, or continue replanning and tracking its plans (the controller is cut only "
        "inside impact pulses); default: the scenario's (brake unless it says otherwise)",
    )


def _search_avoidability(args: argparse.Namespace, tasks: list, results: list) -> list:
    """Search every ego collision of a batch (in parallel); the results with their verdicts."""
    from mujoco_world.experiments.avoidability import search_crashes
    from mujoco_world.experiments.batch import TaskResult

    planners = {t.planner: t.planner_config for t in tasks if t.planner_config is not None}
    clock = time.perf_counter()
    found = dict(
        search_crashes(
            [t.run_dir for t in tasks],
            planners,
            workers=args.workers,
            progress=show_progress(args),
            worker_initializer=keep_freed_memory,
        )
    )
    failed = {folder: why for folder, why in found.items() if isinstance(why, str)}
    for folder, why in failed.items():
        say(args, f"avoidability search of {folder.name} failed: {why}")
    say(args, f"avoidability: {len(found)} ego collision(s) searched in {time.perf_counter() - clock:.1f} s")
    return [
        TaskResult(found[t.run_dir], r.resumed) if t.run_dir in found and t.run_dir not in failed else r
        for t, r in zip(tasks, results, strict=True)
    ]


def _run_config(args: argparse.Namespace, **fields: object):  # noqa: ANN202 - RunConfig, imported lazily
    from ethical_planner.prediction import PREDICTORS
    from mujoco_world.loop.config import RunConfig

    if args.predictor is not None:
        PREDICTORS.get(args.predictor)  # raises ValueError listing the registered predictors
    return RunConfig(predictor=args.predictor, post_crash=args.post_crash, **fields)


def _recording_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-record", action="store_true", help="write no Rerun recording (still indexed)")
    parser.add_argument(
        "--keep-recordings",
        choices=["all", "near-crash"],
        default="all",
        help="keep every recording, or only those of near-crash runs (the index lists every run)",
    )


def _scenarios(args: argparse.Namespace) -> int:
    from mujoco_world.scenario.catalog import CATALOG, catalog_names, describe, get_scenario

    if args.json:
        entries = []
        for name in catalog_names():
            scenario = get_scenario(name)
            entries.append(
                {
                    "name": name,
                    "road": scenario.road.kind.value,
                    "road_users": len(scenario.road_users),
                    "duration": scenario.duration,
                    "description": CATALOG[name].description,
                    "expect": _expectations(scenario.expect),
                }
            )
        print_json(entries)
        return 0
    for name in catalog_names():
        print(describe(name))
    return 0


def _expectations(expect) -> dict:  # noqa: ANN001 - an ExpectSpec or None, imported lazily
    """The items a scenario expects, by name (empty if none)."""
    if expect is None:
        return {}
    from ethical_planner.records import to_plain

    return {k: v for k, v in to_plain(expect).items() if v is not None and v != []}


def _progress_observer(label: str, enabled: bool):
    """A ``RunObserver`` that shows a run's simulated time as a progress bar (changes nothing)."""
    from tqdm import tqdm

    from mujoco_world.loop.observers import RunObserver

    class SimulatedTime(RunObserver):
        step_interval = 100  # every 0.1 s of simulated time

        def __init__(self) -> None:
            self.bar = None

        def on_start(self, world, scenario, planner, seed) -> None:
            self.bar = tqdm(
                total=float(scenario.duration),
                desc=label,
                disable=not enabled,
                bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} s simulated [{elapsed}]",
            )

        def on_step(self, world, time) -> None:
            self.bar.update(min(time, self.bar.total) - self.bar.n)

        def on_end(self, summary) -> None:
            self.bar.close()

    return SimulatedTime()


def _run(args: argparse.Namespace) -> int:
    from mujoco_world.experiments.batch import RunTask, run_task
    from mujoco_world.loop.world import ObservationNoise
    from mujoco_world.scenario.sources import resolve_scenario

    non_negative(args.seed, "--seed")
    check(0.0 <= args.noise <= 10.0, f"--noise must lie in [0, 10] m, got {args.noise}")
    check(
        0.5 <= args.replan_rate <= 100.0, f"--replan-rate must lie in [0.5, 100] Hz, got {args.replan_rate}"
    )
    (planner,) = planner_configs([args.planner], args.config)
    scenario = resolve_scenario(args.scenario)  # a bad name or file is bad input, not a failed run
    config = _run_config(args, noise=ObservationNoise(position=args.noise), replan_rate=args.replan_rate)
    root = output_dir(args.out)
    name, planner_config = (planner, None) if isinstance(planner, str) else (planner.name, planner)
    task = RunTask(
        args.scenario, name, args.seed, str(root), not args.no_record, args.keep_recordings, planner_config
    )
    progress = _progress_observer(f"{scenario.name} [{name}]", show_progress(args))
    record = run_task(task, config, resume=False, observers=[progress]).record
    summary = record.summary
    code = 1 if summary.outcome == "failed" or summary.verdict == "fail" else 0
    if args.json:
        print_json(record.to_dict())
        return code
    _print_run(record)
    print(f"wrote {task.record_path}  (run id {record.run_id}, index {root / 'index.jsonl'})")
    if record.recording:
        print(f"recording: {record.recording}  (open with: etp replay {record.run_id} --root {root})")
    return code


def _print_run(record) -> None:  # noqa: ANN001 - a RunRecord, imported lazily
    summary = record.summary
    risk = summary.max_risk
    print(
        f"{summary.scenario} [{summary.planner}, seed {summary.seed}]: {summary.outcome} after "
        f"{summary.duration:.2f} s ({summary.reason}); {len(summary.collisions)} collision(s); "
        f"max risk ego {risk.get('ego', math.nan):.4f}, 3rd party {risk.get('third_party', math.nan):.4f}, "
        f"VRU {risk.get('vulnerable', math.nan):.4f}; "
        f"{summary.timings.get('real_time_factor', math.nan):.1f}x real time"
    )
    if summary.expectations:
        print(f"  expectations: {summary.verdict.upper()}")
        for e in summary.expectations:
            print(f"    {'pass' if e.passed else 'FAIL'}  {e.name}: expected {e.expected}, got {e.measured}")
    for v in summary.rule_violations:
        print(f"  rule violation: {v.rule} ({v.line}) at t={v.time:.2f} s, {v.speed:.1f} m/s")
    for crossing in summary.extra_metrics.get("amber_crossings", ()):
        print(
            f"  amber crossing (dilemma zone, not a violation): {crossing['line']} at "
            f"t={crossing['time']:.2f} s, {crossing['speed']:.1f} m/s"
        )
    for impact in summary.collisions:
        m = impact.measurement
        print(
            f"  t={m.time:.2f} s {m.a.name} ({m.a.type}) - {m.b.name} ({m.b.type}): "
            f"dv measured {impact.a.dv_measured:.2f}/{impact.b.dv_measured:.2f} m/s, "
            f"Eq. 1 {impact.a.dv_predicted:.2f}/{impact.b.dv_predicted:.2f} m/s; "
            f"areas {m.a.reduced_area}/{m.b.reduced_area}"
        )


def _demo_tasks(args: argparse.Namespace) -> list:
    """The tasks of ``etp demo`` (every option checked before anything runs)."""
    from mujoco_world.experiments.batch import QUICK_SCENARIOS, check_unique, make_tasks
    from mujoco_world.scenario.catalog import catalog_names, generated_names, get_family
    from mujoco_world.scenario.sources import resolve_scenario

    non_negative(args.random, "--random")
    non_negative(args.scenario_seed, "--scenario-seed")
    check(args.workers >= 1, f"--workers must be >= 1, got {args.workers}")
    families = None
    if args.scenarios:
        scenarios = split_items(args.scenarios, "--scenarios")
        for name in scenarios:
            if name.split("#", 1)[0].lower().endswith((".toml", ".xml")):
                resolve_scenario(name)  # a bad file is bad input, not a failed run
            else:
                get_family(name)
        families = scenarios
    planners = planner_configs(split_items(args.planners, "--planners"), args.config)
    seeds = parse_seeds(args.seeds)
    runs = (args.random or 1) * len(planners) * len(seeds)
    check(
        runs <= MAX_RUNS,
        f"--random x --planners x --seeds asks for {runs} runs; one batch takes at most {MAX_RUNS}",
    )
    if args.random:
        scenarios = generated_names(args.random, args.scenario_seed, families)
    elif args.scenarios:
        pass
    elif args.quick:
        scenarios = list(QUICK_SCENARIOS)
    else:
        scenarios = catalog_names()
    record, keep = not args.no_record, args.keep_recordings
    tasks = make_tasks(scenarios, planners, seeds, args.out, record=record, keep=keep)
    check_unique(tasks)
    return tasks


def _demo(args: argparse.Namespace) -> int:
    from mujoco_world.experiments.batch import (
        BatchInterrupted,
        aggregate_rows,
        comparison_table,
        run_batch,
        suite_result,
        write_aggregate,
    )

    tasks = _demo_tasks(args)
    root = output_dir(args.out)
    config = _run_config(args) if args.predictor is not None or args.post_crash is not None else None
    start = time.perf_counter()
    interrupted = None
    try:
        results = run_batch(
            tasks,
            workers=args.workers,
            config=config,
            progress=show_progress(args),
            worker_initializer=keep_freed_memory,
            retry_failed=args.retry_failed,
        )
    except BatchInterrupted as stop:
        interrupted, results = stop, stop.results
    if args.avoidability and interrupted is None:
        results = _search_avoidability(args, tasks, results)
    wall = time.perf_counter() - start
    path = write_aggregate(root, results, wall)
    resumed = sum(1 for r in results if r.resumed)
    failed = sum(1 for r in results if r.record.summary.outcome == "failed")
    if args.json:
        data = {
            "runs": aggregate_rows(results),
            "suite": suite_result(r.record for r in results),
            "wall_time": wall,
            "aggregate": str(path),
        }
        print_json({**data, "interrupted": interrupted is not None, "total": len(tasks)})
    else:
        print(comparison_table(r.record for r in results))
    say(
        args,
        f"\n{len(results)} runs ({resumed} resumed from existing records, {failed} failed) in "
        f"{wall:.1f} s; wrote {path}",
    )
    say(args, f"run index: {root / 'index.jsonl'}; near-crash runs: etp near-crash {root}")
    if interrupted is not None:
        closed = sum(1 for r in results if r.record.summary.reason.startswith("interrupted"))
        print(
            f"etp demo: interrupted: {len(results) - closed} of {len(tasks)} runs finished, {closed} in "
            f"flight closed as failed (indexed, no summary); run the same command again to resume",
            file=sys.stderr,
        )
        return 130
    if failed:
        say(args, f"{failed} run(s) failed (see the reason column); --retry-failed runs them again")
    return 0
