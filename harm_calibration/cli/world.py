"""``etp scenarios``, ``etp run`` and ``etp demo``: the closed loop from the command line."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from ethical_planner.validation import check
from harm_calibration.cli.process import keep_freed_memory


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add this layer's subcommands to ``etp``."""
    p = subparsers.add_parser("scenarios", help="list the scenario catalog, one line each")
    p.set_defaults(handler=_scenarios)

    p = subparsers.add_parser(
        "run",
        help="run one scenario in closed loop and write DIR/summary.json",
        description="Drive the ego with a planner through a MuJoCo scenario; every "
        "collision is measured from the physics and compared with the harm model.",
    )
    p.add_argument(
        "scenario",
        help="catalog name (see 'etp scenarios'), a generated name such as dense_urban-s3-17, "
        "or a scenario .toml file",
    )
    p.add_argument("--planner", default="ethical", help="ethical, selfish or standard (default ethical)")
    p.add_argument("--seed", type=int, default=0, help="seed of the observation noise (default 0)")
    p.add_argument(
        "--out", default=None, help="output folder (default logs/run/<scenario>-<planner>-s<seed>)"
    )
    p.add_argument("--noise", type=float, default=0.0, help="position noise std [m] of observed road users")
    p.add_argument("--replan-rate", type=float, default=10.0, help="planning cycles per second [Hz]")
    _recording_arguments(p)
    p.set_defaults(handler=_run)

    p = subparsers.add_parser(
        "demo",
        help="run the catalog with the three planners on two cores and print a comparison",
        description="Run every catalog scenario with the ethical, selfish and standard "
        "planners (multiprocessing), one folder per run with summary.json, an "
        "aggregate.json and a comparison table. Existing summaries are skipped (resume).",
    )
    p.add_argument("--out", default="logs/demo", help="output folder (default logs/demo)")
    p.add_argument("--quick", action="store_true", help="run a small subset of the catalog")
    p.add_argument("--scenarios", default=None, help="comma-separated scenario names")
    p.add_argument("--planners", default="ethical,selfish,standard", help="comma-separated presets")
    p.add_argument("--seeds", default="0", help="comma-separated run seeds (default 0)")
    p.add_argument(
        "--random",
        type=int,
        default=0,
        metavar="N",
        help="instead of the catalog, run N random variants of the families (see --scenario-seed)",
    )
    p.add_argument("--scenario-seed", type=int, default=0, help="seed of the random variants (default 0)")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    _recording_arguments(p)
    p.set_defaults(handler=_demo)


def _recording_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-record", action="store_true", help="write no Rerun recording (still indexed)")
    parser.add_argument(
        "--keep-recordings",
        choices=["all", "near-crash"],
        default="all",
        help="keep every recording, or only those of near-crash runs (the index lists every run)",
    )


def _split(text: str, what: str) -> list[str]:
    items = [item.strip() for item in text.split(",") if item.strip()]
    check(bool(items), f"{what} must name at least one item")
    return items


def _scenarios(args: argparse.Namespace) -> int:
    from mujoco_world.scenario.catalog import catalog_names, describe

    for name in catalog_names():
        print(describe(name))
    return 0


def _check_planner(name: str) -> None:
    from ethical_planner.config import preset

    preset(name)  # raises ValueError listing the presets


def _run(args: argparse.Namespace) -> int:
    from mujoco_world.loop.batch import write_json
    from mujoco_world.loop.runner import RunConfig, run_scenario
    from mujoco_world.loop.world import ObservationNoise
    from mujoco_world.scenario.sources import resolve_scenario

    _check_planner(args.planner)
    scenario = resolve_scenario(args.scenario)
    config = RunConfig(noise=ObservationNoise(position=args.noise), replan_rate=args.replan_rate)
    out = Path(args.out) if args.out else Path("logs/run") / f"{scenario.name}-{args.planner}-s{args.seed}"
    from mujoco_world.storage.run_folder import recording_observer

    observer = recording_observer(out, keep=args.keep_recordings, record=not args.no_record)
    summary = run_scenario(scenario, args.planner, args.seed, config, observer)
    path = out / "summary.json"
    data = summary.to_dict()
    data["recording"] = observer.row.recording if observer.row is not None else None
    write_json(path, data)
    risk = summary.max_risk
    print(
        f"{scenario.name} [{summary.planner}, seed {summary.seed}]: {summary.outcome} after "
        f"{summary.duration:.2f} s ({summary.reason}); {len(summary.collisions)} collision(s); "
        f"max risk ego {risk['ego']:.4f}, 3rd party {risk['third_party']:.4f}, "
        f"VRU {risk['vulnerable']:.4f}; {summary.timings['real_time_factor']:.1f}x real time"
    )
    for record in summary.collisions:
        m = record.measurement
        print(
            f"  t={m.time:.2f} s {m.a.name} ({m.a.type}) - {m.b.name} ({m.b.type}): "
            f"dv measured {record.a.dv_measured:.2f}/{record.b.dv_measured:.2f} m/s, "
            f"Eq. 1 {record.a.dv_predicted:.2f}/{record.b.dv_predicted:.2f} m/s; "
            f"areas {m.a.reduced_area}/{m.b.reduced_area}"
        )
    print(f"wrote {path}")
    if data["recording"]:
        print(f"recording: {data['recording']}  (open with: rerun {data['recording']})")
    return 1 if summary.outcome == "failed" else 0


def _demo(args: argparse.Namespace) -> int:
    from mujoco_world.loop.batch import (
        QUICK_SCENARIOS,
        comparison_table,
        make_tasks,
        run_batch,
        write_aggregate,
    )
    from mujoco_world.scenario.catalog import catalog_names, generated_names, get_family

    check(args.random >= 0, f"--random must be >= 0, got {args.random}")
    families = None
    if args.scenarios:
        scenarios = _split(args.scenarios, "--scenarios")
        for name in scenarios:
            if not name.endswith(".toml"):
                get_family(name)
        families = scenarios
    if args.random:
        scenarios = generated_names(args.random, args.scenario_seed, families)
    elif args.scenarios:
        pass
    elif args.quick:
        scenarios = list(QUICK_SCENARIOS)
    else:
        scenarios = catalog_names()
    planners = _split(args.planners, "--planners")
    for name in planners:
        _check_planner(name)
    try:
        seeds = [int(s) for s in _split(args.seeds, "--seeds")]
    except ValueError:
        raise ValueError(f"--seeds must be comma-separated integers, got {args.seeds!r}") from None
    check(args.workers >= 1, f"--workers must be >= 1, got {args.workers}")
    tasks = make_tasks(
        scenarios, planners, seeds, args.out, record=not args.no_record, keep=args.keep_recordings
    )
    start = time.perf_counter()
    rows = run_batch(
        tasks, workers=args.workers, progress=not args.no_progress, worker_initializer=keep_freed_memory
    )
    wall = time.perf_counter() - start
    path = write_aggregate(args.out, rows, wall)
    print(comparison_table(rows))
    skipped = sum(1 for r in rows if r.get("skipped"))
    print(f"\n{len(rows)} runs ({skipped} resumed from existing summaries) in {wall:.1f} s; wrote {path}")
    print(f"run index: {Path(args.out) / 'index.jsonl'}; near-crash runs: etp near-crash {args.out}")
    return 0
