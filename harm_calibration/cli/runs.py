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

from mujoco_world.storage.run_folder import DEFAULT_ROOT, replay_command, resolve_recording
from mujoco_world.storage.run_index import near_crashes, read_index


def _fmt(value: float, digits: int = 3) -> str:
    if isinstance(value, float) and math.isnan(value):
        return "-"
    if isinstance(value, float) and math.isinf(value):
        return "inf"
    return f"{value:.{digits}f}"


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
    header = (
        f"{'severity':>8}  {'run':<32} {'scenario':<24} {'planner':<9} {'seed':>5} {'coll':>4} "
        f"{'harm':>6} {'min d':>6} {'ttc':>6} {'p max':>6}  recording"
    )
    print(header)
    for r in found:
        harm = max(r.max_harm_measured, r.max_harm_predicted)
        print(
            f"{r.severity:8.3f}  {r.run_id[:32]:<32} {r.scenario[:24]:<24} {r.planner[:9]:<9} {r.seed:>5} "
            f"{r.collisions:>4} {_fmt(harm):>6} {_fmt(r.min_distance, 2):>6} {_fmt(r.min_ttc, 2):>6} "
            f"{_fmt(r.max_collision_probability):>6}  {r.recording or '-'}"
        )
    return 0


def _replay(args: argparse.Namespace) -> int:
    path = resolve_recording(args.run, args.root)
    command = replay_command(path)
    has_display = bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    viewer = shutil.which("rerun")
    if has_display and viewer is not None:
        subprocess.Popen([viewer, *command[1:]])  # noqa: S603 - fixed executable, a file path
        print(f"opened {path} in the Rerun viewer")
        return 0
    why = "no display (DISPLAY/WAYLAND_DISPLAY unset)" if not has_display else "no `rerun` executable on PATH"
    print(f"{why}; open the recording elsewhere with:", file=sys.stderr)
    print(shlex.join(command))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``near-crash`` and ``replay`` to ``etp``."""
    p = subparsers.add_parser(
        "near-crash",
        help="list the near-crash runs of an output root, worst first",
        description="Read DIR/index.jsonl and list runs with a collision or past the "
        "near-crash thresholds, ranked by severity (see mujoco_world.run_index).",
    )
    p.add_argument("dir", metavar="DIR", help="output root holding index.jsonl")
    p.add_argument("--top", type=int, default=None, metavar="N", help="show the N worst")
    p.add_argument("--json", action="store_true", help="print JSON rows")
    p.set_defaults(handler=_near_crash)
    p = subparsers.add_parser(
        "replay",
        help="open a run's recording in the Rerun viewer (or print the command)",
        description="Open a recording with `rerun FILE` if a display and the viewer exist; "
        "otherwise print the command to run elsewhere.",
    )
    p.add_argument("run", metavar="RUN_ID_OR_PATH", help="run id from the index, run folder or .rrd")
    p.add_argument("--root", default=str(DEFAULT_ROOT), help="output root of the index (default: logs)")
    p.set_defaults(handler=_replay)
