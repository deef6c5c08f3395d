"""``etp predictor train``, ``calibrate`` and ``eval``: the learned predictor's data commands.

Both read recorded CommonRoad traffic (default: ``../shared/commonroad`` beside the
repository, or ``$ETP_COMMONROAD``) and need the extra ``[learned]`` (torch).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from harm_calibration.cli.common import add_json, print_json, say

#: Parsed tracks are cached here between runs (git-ignored).
DEFAULT_CACHE = Path("logs/predictor_cache")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``predictor train``, ``predictor calibrate`` and ``predictor eval`` to ``etp``."""
    predictor = subparsers.add_parser(
        "predictor",
        help="train or evaluate the learned predictor on recorded CommonRoad traffic",
        description="Learned probabilistic predictor (torch): train on recorded trajectories split by "
        "location, calibrate a Gaussian scale mixture, evaluate against constant velocity and CTRA.",
    )
    commands = predictor.add_subparsers(dest="predictor_command", required=True, metavar="ACTION")

    def data_options(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            "--data",
            type=Path,
            nargs="+",
            default=None,
            metavar="DIR",
            help="folders of CommonRoad XML files "
            "(default: highD, exiD, SinD and NGSIM of ../shared/commonroad)",
        )
        p.add_argument("--stride", type=int, default=2, help="grid steps (0.2 s) between windows (default 2)")
        p.add_argument("--workers", type=int, default=2, help="processes parsing files (default 2)")
        p.add_argument(
            "--max-files", type=int, default=None, help="at most N files per recording (quick runs)"
        )
        p.add_argument(
            "--cache", type=Path, default=DEFAULT_CACHE, help=f"parsed-track cache ({DEFAULT_CACHE})"
        )
        p.add_argument("--no-cache", action="store_true", help="parse every file, write no cache")

    def components_option(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            "--components",
            type=int,
            default=2,
            help="Gaussians of the calibrated scale mixture, 1..4 (default 2; the planner integrates each)",
        )

    train = commands.add_parser(
        "train",
        help="train, calibrate on the validation locations, save the weights",
        description="Train the learned predictor; writes a weights file loadable with weights_only=True.",
    )
    data_options(train)
    train.add_argument("--out", type=Path, required=True, metavar="FILE", help="weights file to write (.pt)")
    train.add_argument("--epochs", type=int, default=40, help="epochs (default 40)")
    train.add_argument("--seed", type=int, default=0, help="seed of initialisation and shuffling (default 0)")
    train.add_argument(
        "--threads", type=int, default=1, help="torch threads (default 1: faster on a shared machine)"
    )
    train.add_argument(
        "--max-minutes", type=float, default=None, help="stop training after this many minutes"
    )
    train.add_argument(
        "--report", type=Path, default=None, metavar="DIR", help="also evaluate on the test split"
    )
    components_option(train)
    add_json(train)
    train.set_defaults(handler=_train)

    calibrate = commands.add_parser(
        "calibrate",
        help="refit a weights file's mixture calibration on the validation locations",
        description="Keep the network, fit the Gaussian scale mixture (weights and variance factors per "
        "type, motion state and step) by maximum likelihood on the validation split, write a new file.",
    )
    data_options(calibrate)
    calibrate.add_argument(
        "--weights", type=Path, default=None, metavar="FILE", help="weights (default: shipped)"
    )
    calibrate.add_argument("--out", type=Path, required=True, metavar="FILE", help="weights file to write")
    components_option(calibrate)
    add_json(calibrate)
    calibrate.set_defaults(handler=_calibrate)

    evaluate = commands.add_parser(
        "eval",
        help="ADE, FDE, NLL, coverage and a reliability plot on held-out locations",
        description="Evaluate a weights file (default: the shipped one) per road-user type against "
        "constant velocity and CTRA; writes report.md, metrics.json and reliability.png.",
    )
    data_options(evaluate)
    evaluate.add_argument(
        "--weights", type=Path, default=None, metavar="FILE", help="weights (default: shipped)"
    )
    evaluate.add_argument(
        "--out", type=Path, default=Path("logs/predictor_eval"), metavar="DIR", help="report folder"
    )
    evaluate.add_argument(
        "--split", choices=["train", "val", "test"], default="test", help="split (default test)"
    )
    add_json(evaluate)
    evaluate.set_defaults(handler=_eval)


def _data(args: argparse.Namespace) -> list[Path]:
    from harm_calibration.predictor.data import DEFAULT_DATA
    from mujoco_world.scenario.commonroad_tracks import shared_commonroad

    if args.data:
        return list(args.data)
    root = shared_commonroad()
    if root is None:
        raise ValueError(
            "--data: no folders given and ../shared/commonroad (or $ETP_COMMONROAD) does not exist"
        )
    return [root / d for d in DEFAULT_DATA]


def _check_counts(args: argparse.Namespace) -> None:
    # A missing weights file is named first: it is the user's typo, while a missing
    # data folder may only mean the shared CommonRoad files are not installed here.
    weights = getattr(args, "weights", None)
    if weights is not None and not Path(weights).is_file():
        raise ValueError(f"learned predictor weights {weights}: no such file")
    if args.stride < 1:
        raise ValueError(f"--stride must be >= 1, got {args.stride}")
    if args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    if args.max_files is not None and args.max_files < 1:
        raise ValueError(f"--max-files must be >= 1, got {args.max_files}")


def _check_components(args: argparse.Namespace) -> None:
    if not 1 <= args.components <= 4:
        raise ValueError(f"--components must be between 1 and 4, got {args.components}")


def _require_torch() -> None:
    try:
        import torch  # noqa: F401
    except ImportError:
        raise ValueError('the learned predictor needs torch: pip install -e ".[learned]"') from None


def _train(args: argparse.Namespace) -> int:
    from harm_calibration.predictor.pipeline import run_training
    from harm_calibration.predictor.train import TrainConfig

    _check_counts(args)
    _check_components(args)
    _require_torch()
    if args.max_minutes is not None and args.max_minutes <= 0:
        raise ValueError(f"--max-minutes must be > 0, got {args.max_minutes}")
    config = TrainConfig(
        epochs=args.epochs,
        seed=args.seed,
        threads=args.threads,
        max_seconds=None if args.max_minutes is None else 60.0 * args.max_minutes,
    )
    _, _, summary = run_training(
        _data(args),
        args.out,
        config,
        stride=args.stride,
        workers=args.workers,
        cache=None if args.no_cache else args.cache,
        max_files=args.max_files,
        report=args.report,
        log=lambda line: say(args, line),
        n_components=args.components,
    )
    if args.json:
        print_json({"weights": str(args.out), **summary})
    return 0


def _calibrate(args: argparse.Namespace) -> int:
    from harm_calibration.predictor.pipeline import run_calibration

    _check_counts(args)
    _check_components(args)
    _require_torch()
    result = run_calibration(
        args.weights,
        _data(args),
        args.out,
        args.components,
        args.stride,
        args.workers,
        None if args.no_cache else args.cache,
        args.max_files,
        log=lambda line: say(args, line),
    )
    if args.json:
        print_json(result)
    return 0


def _eval(args: argparse.Namespace) -> int:
    from harm_calibration.predictor.evaluate import report_markdown
    from harm_calibration.predictor.pipeline import run_evaluation

    _check_counts(args)
    _require_torch()
    result = run_evaluation(
        args.weights,
        _data(args),
        args.out,
        args.split,
        args.stride,
        args.workers,
        None if args.no_cache else args.cache,
        args.max_files,
    )
    if args.json:
        print_json(result["metrics"])
    else:
        print(report_markdown(result))
        print(f"written: {args.out / 'report.md'}, metrics.json, reliability.png")
    return 0
