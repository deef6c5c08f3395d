"""``etp near-crash`` and ``etp replay``: find the worst runs of a batch and open their recordings."""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

from harm_calibration.cli.common import add_json, print_json
from mujoco_world.storage.run_folder import DEFAULT_ROOT, replay_command, resolve_recording
from mujoco_world.storage.run_index import near_crashes, read_index


def _fmt(value: float, digits: int = 3) -> str:
    if isinstance(value, float) and math.isnan(value):
        return "-"
    if isinstance(value, float) and math.isinf(value):
        return "inf"
    return f"{value:.{digits}f}"


#: What the near-crash table's harm columns are (printed under the table).
HARM_LEGEND = (
    "harm meas / harm pred: highest MAIS3+ probability of any body in any collision of the run, "
    "from the measured delta-v and impact area / from the planner's Eq. 1 prediction "
    "(0 without a collision)"
)


def _verdict(row) -> str:  # noqa: ANN001 - an IndexRow
    if row.avoidable is not None:
        return "yes" if row.avoidable else "no"
    return "?" if row.ego_collisions else "-"


def _near_crash(args: argparse.Namespace) -> int:
    if args.top is not None and args.top < 1:
        raise ValueError(f"--top must be >= 1, got {args.top}")
    rows = read_index(args.dir)
    found = near_crashes(rows, args.top)
    if args.json:
        print(json.dumps([json.loads(r.to_json()) for r in found], indent=2))
        return 0
    print(f"{len(found)} near crash(es) among {len(rows)} run(s) in {Path(args.dir)}")
    if not found:
        return 0
    run_width = max(len("run id"), *(len(r.run_id) for r in found))
    header = (
        f"{'severity':>8}  {'run id':<{run_width}}  {'planner':<9} {'seed':>5} {'outcome':<8} {'ego':>3} "
        f"{'3rd':>3} {'harm meas':>9} {'harm pred':>9} {'min d':>6} {'VRU d':>6} {'ttc':>6} {'p max':>6}  "
        "recording"
    )
    print(header)
    for r in found:
        print(
            f"{r.severity:8.3f}  {r.run_id:<{run_width}}  {r.planner:<9} {r.seed:>5} {r.outcome:<8} "
            f"{r.ego_collisions:>3} {r.third_party_collisions:>3} "
            f"{_fmt(r.max_harm_measured):>9} {_fmt(r.max_harm_predicted):>9} "
            f"{_fmt(r.min_distance, 2):>6} {_fmt(r.min_distance_vulnerable, 2):>6} {_fmt(r.min_ttc, 2):>6} "
            f"{_fmt(r.max_collision_probability):>6} {_verdict(r):>5}  {r.recording or '-'}"
        )
    print(HARM_LEGEND)
    print("ego / 3rd: collisions the ego took part in (a crash) / between other road users (ranked after")
    print("crashes). min d / VRU d: smallest ego distance to any / a vulnerable road user [m]; ttc: smallest")
    print("time-to-collision [s]; p max: highest planned collision probability; avoid: the ego collision")
    print("was avoidable (etp avoidability ROOT; ?: not searched yet).")
    print(f"Open a run: etp replay RUN_ID --root {args.dir}")
    return 0


def _replay(args: argparse.Namespace) -> int:
    path = resolve_recording(args.run, args.root)
    command = replay_command(path)
    has_display = bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    viewer = shutil.which("rerun")
    opened = has_display and viewer is not None
    if opened:
        subprocess.Popen([viewer, *command[1:]])  # noqa: S603 - fixed executable, a file path
    if args.json:
        print_json({"recording": str(path), "command": command, "opened": opened})
    elif opened:
        print(f"opened {path} in the Rerun viewer")
    else:
        why = (
            "no display (DISPLAY/WAYLAND_DISPLAY unset)"
            if not has_display
            else "no `rerun` executable on PATH"
        )
        print(f"{why}; open the recording elsewhere with:", file=sys.stderr)
        print(shlex.join(command))
    return 0


def _run_folders(paths: list[str]) -> list[Path]:
    """Run folders named on the command line: a run folder, its ``summary.json``, or an output root."""
    from mujoco_world.storage.run_record import RECORD_FILE, iter_records

    folders: list[Path] = []
    for text in paths:
        path = Path(text)
        if path.is_file() and path.name == RECORD_FILE:
            path = path.parent
        if (path / RECORD_FILE).is_file():
            folders.append(path)
        elif path.is_dir():
            folders += [p.parent for p, _ in iter_records(path)]
        else:
            raise ValueError(f"RUN_DIR: {path} is no run folder, summary.json or output root")
    return folders


def _avoidability(args: argparse.Namespace) -> int:
    from harm_calibration.cli.common import planner_configs, show_progress
    from harm_calibration.cli.process import keep_freed_memory
    from mujoco_world.experiments.avoidability import AvoidabilityFamily, search_crashes
    from mujoco_world.storage.run_record import read_record

    if args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    if not 0.0 < args.lookback <= 60.0:
        raise ValueError(f"--lookback must lie in (0, 60] s, got {args.lookback}")
    family = AvoidabilityFamily(lookback=args.lookback)
    folders = _run_folders(args.run)
    planners = {}
    if args.config is not None:
        for name in sorted({read_record(f).summary.planner for f in folders}):
            (config,) = planner_configs([name.split("+")[0]], args.config)
            if config.name == name:
                planners[name] = config
    results = search_crashes(
        folders, planners, family, args.workers, show_progress(args), worker_initializer=keep_freed_memory
    )
    if args.json:
        print_json(
            [
                {"run": str(f), "avoidability": r.to_dict()["avoidability"]}
                if not isinstance(r, str)
                else {"run": str(f), "error": r}
                for f, r in results
            ]
        )
    else:
        print(f"{len(results)} run(s) with an ego collision among {len(folders)}")
        for folder, result in results:
            if isinstance(result, str):
                print(f"{folder.name}: search failed: {result}")
            else:
                print(f"{folder.name}: {result.avoidability.describe()}")
    return 1 if any(isinstance(r, str) for _, r in results) else 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``near-crash``, ``replay`` and ``avoidability`` to ``etp``."""
    p = subparsers.add_parser(
        "near-crash",
        help="list the near-crash runs of an output root, worst first",
        description="Read DIR/index.jsonl and list runs with a collision or past the "
        "near-crash thresholds (min distance < 0.5 m, distance to a vulnerable road user < 1 m, "
        "time-to-collision < 1 s, planned collision probability >= 0.1), worst first: ego-involved "
        "collisions (crashes) by 2 + highest harm, third-party collisions by 1 + highest harm, then "
        "near misses (see mujoco_world.storage.run_index). The run ids printed are the ones etp "
        "replay takes.",
    )
    p.add_argument("dir", metavar="DIR", help="output root holding index.jsonl")
    p.add_argument("--top", type=int, default=None, metavar="N", help="show the N worst")
    add_json(p)
    p.set_defaults(handler=_near_crash)
    p = subparsers.add_parser(
        "replay",
        help="open a run's recording in the Rerun viewer (or print the command)",
        description="Open a recording with `rerun FILE` if a display and the viewer exist; "
        "otherwise print the command to run elsewhere.",
    )
    p.add_argument("run", metavar="RUN_ID_OR_PATH", help="run id from the index, run folder or .rrd")
    p.add_argument(
        "--root",
        default=str(DEFAULT_ROOT),
        help="output root holding index.jsonl (default: logs, and the roots one level below it)",
    )
    add_json(p)
    p.set_defaults(handler=_replay)
    p = subparsers.add_parser(
        "avoidability",
        help="search whether each ego collision of stored runs was avoidable",
        description="For every run with an ego-involved collision: re-simulate it with its own planner, "
        "world and seed, copy the closed loop at every planning cycle from the first sight of the "
        "collision partner (at most --lookback s before the collision), and try a family of open-loop "
        "manoeuvres from each copy (brake profiles, swerves, lane changes, swerve-and-brake within the "
        "friction circle). Avoidable: some manoeuvre avoids every ego contact until 2 s after the "
        "collision. The verdict is stored in the run's summary.json and index row "
        "(see mujoco_world.experiments.avoidability).",
    )
    p.add_argument(
        "run", nargs="+", metavar="RUN_DIR", help="run folder, its summary.json, or an output root"
    )
    p.add_argument("--lookback", type=float, default=5.0, help="earliest branch before the collision [s]")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        metavar="FILE.toml",
        help="the planner configuration the runs used with etp demo/run --config",
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_json(p)
    p.set_defaults(handler=_avoidability)
