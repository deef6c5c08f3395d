"""The ``etp`` command line: each layer registers its own subcommands.

The entry point lives in the top layer so that ``ethical_planner`` and
``mujoco_world`` never import anything above themselves.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from ethical_planner import cli as planner_cli
from ethical_planner.allocator import keep_freed_memory
from mujoco_world import cli as world_cli

from . import cli_impacts


def build_parser() -> argparse.ArgumentParser:
    """Return the ``etp`` argument parser with every layer's subcommands."""
    parser = argparse.ArgumentParser(
        prog="etp",
        description="Ethical trajectory planning checked against MuJoCo contact physics.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    planner_cli.register(subparsers)
    world_cli.register(subparsers)
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
