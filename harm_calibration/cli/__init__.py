"""The ``etp`` command line (the application layer): one module per command group.

``planner`` (harm, plan), ``bench``, ``world`` (scenarios, run, demo), ``runs``
(near-crash, replay) and ``impacts`` (impacts, refit-harm) each register their
subcommands here. Nothing below this package imports it.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from harm_calibration.cli import bench as bench_cli
from harm_calibration.cli import impacts as cli_impacts
from harm_calibration.cli import planner as planner_cli
from harm_calibration.cli import runs as runs_cli
from harm_calibration.cli import world as world_cli
from harm_calibration.cli.process import keep_freed_memory


def build_parser() -> argparse.ArgumentParser:
    """Return the ``etp`` argument parser with every layer's subcommands."""
    parser = argparse.ArgumentParser(
        prog="etp",
        description="Ethical trajectory planning checked against MuJoCo contact physics.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    planner_cli.register(subparsers)
    bench_cli.register(subparsers)
    world_cli.register(subparsers)
    runs_cli.register(subparsers)
    cli_impacts.register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``etp`` with ``argv`` (default: ``sys.argv[1:]``) and return the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    keep_freed_memory()
    try:
        return int(args.handler(args) or 0)
    except ValueError as error:
        print(f"etp {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
