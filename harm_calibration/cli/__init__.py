"""The ``etp`` command line (the application layer): one module per command group.

``planner`` (harm, plan), ``bench``, ``world`` (scenarios, run, demo), ``runs``
(near-crash, replay), ``study``, ``impacts`` (impacts, refit-harm) and ``predictor`` (train, eval)
each register their
subcommands here. Nothing below this package imports it.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from importlib import metadata

from harm_calibration.cli import bench as bench_cli
from harm_calibration.cli import impacts as cli_impacts
from harm_calibration.cli import planner as planner_cli
from harm_calibration.cli import predictor as predictor_cli
from harm_calibration.cli import runs as runs_cli
from harm_calibration.cli import study as study_cli
from harm_calibration.cli import world as world_cli
from harm_calibration.cli.process import keep_freed_memory


def version() -> str:
    """The installed version of the package (``etp --version``)."""
    try:
        return metadata.version("ethical-trajectory-planning")
    except metadata.PackageNotFoundError:  # pragma: no cover - run from a source tree
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    """Return the ``etp`` argument parser with every layer's subcommands."""
    parser = argparse.ArgumentParser(
        prog="etp",
        description="Ethical trajectory planning checked against MuJoCo contact physics. "
        "Every command takes --json (print JSON on stdout instead of text); bad input exits "
        "with code 2 and a message naming the option, field or file.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    planner_cli.register(subparsers)
    bench_cli.register(subparsers)
    world_cli.register(subparsers)
    runs_cli.register(subparsers)
    study_cli.register(subparsers)
    cli_impacts.register(subparsers)
    predictor_cli.register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``etp`` with ``argv`` (default: ``sys.argv[1:]``) and return the exit code.

    Exit codes: 0 success; 1 a run ended as ``failed`` (``etp run``); 2 bad input (the
    message names the option, field or file); 130 interrupted (Ctrl-C).
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # argparse: --help, --version (0) or a usage error (2)
        return int(exit_.code or 0)
    keep_freed_memory()
    try:
        return int(args.handler(args) or 0)
    except ValueError as error:
        print(f"etp {args.command}: error: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        where = f"{error.filename}: " if error.filename else ""
        print(f"etp {args.command}: error: {where}{error.strerror or error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"etp {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
