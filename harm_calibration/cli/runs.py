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
            f"{_fmt(r.max_collision_probability):>6}  {r.recording or '-'}"
        )
    print(HARM_LEGEND)
    print("ego / 3rd: collisions the ego took part in (a crash) / between other road users (ranked after")
    print("crashes). min d / VRU d: smallest ego distance to any / a vulnerable road user [m]; ttc: smallest")
    print("time-to-collision [s]; p max: highest planned collision probability.")
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


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``near-crash`` and ``replay`` to ``etp``."""
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
