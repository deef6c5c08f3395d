"""Train -> recalibrate -> save, and evaluate a weights file: what the commands run."""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from ethical_planner.prediction.learned import TYPE_GROUPS, LearnedModel, ModelSpec, to_world
from harm_calibration.predictor.data import SPLIT, build_windows, split_windows
from harm_calibration.predictor.evaluate import EVAL_FLOOR, evaluate, write_report
from harm_calibration.predictor.train import TrainConfig, TrainLog, fit_calibration, train


def calibrate(model: LearnedModel, val_windows, floor: float) -> np.ndarray:  # noqa: ANN001 - Windows
    """Fit and set the model's recalibration on validation windows; returns it (see ``fit_calibration``)."""
    spec = model.spec
    w = val_windows
    mean, cov = model.predict_local(w.features(spec), w.groups, w.speeds[:, -1], False)
    mean, cov = to_world(mean, cov, w.positions[:, -1], w.headings[:, -1])
    params = fit_calibration(cov, w.future - mean, w.groups, floor)
    model.calibration = params
    return params


def run_training(
    data: Sequence[Path],
    out: Path,
    config: TrainConfig,
    spec: ModelSpec | None = None,
    stride: int = 2,
    workers: int = 2,
    cache: Path | None = None,
    max_files: int | None = None,
    report: Path | None = None,
    log: Callable[[str], None] = print,
) -> tuple[LearnedModel, TrainLog, dict]:
    """Read data, train, recalibrate on the validation split, save to ``out``.

    Returns:
        (model, training log, a summary: window counts, step checks, timings).
    """
    spec = spec or ModelSpec()
    start = time.perf_counter()
    windows, reports = build_windows(data, spec, stride, workers, cache, max_files)
    read_seconds = time.perf_counter() - start
    refused = [r for r in reports if r.error]
    corrected = sorted(
        {(r.recording.split("-")[0], r.declared_dt, r.dt) for r in reports if r.dt != r.declared_dt}
    )
    log(f"read {len(reports)} files in {read_seconds:.0f} s ({len(refused)} refused)")
    for prefix, declared, dt in corrected:
        log(
            f"  step check: {prefix} declared {declared:g} s, recorded velocities say {dt:g} s "
            f"-> using {dt:g} s"
        )
    for r in refused:
        log(f"  refused: {r.error}")
    splits = split_windows(windows)
    counts = {
        name: {TYPE_GROUPS[g]: int((w.groups == g).sum()) for g in range(len(TYPE_GROUPS))}
        for name, w in splits.items()
    }
    for name, c in counts.items():
        log(f"  {name}: {len(splits[name])} windows {c} from {', '.join(SPLIT[name])}")
    model, train_log = train(
        splits["train"],
        splits["val"],
        spec,
        config,
        progress=lambda e, a, b: log(f"  epoch {e + 1}: train NLL {a:.3f}, validation NLL {b:.3f}"),
    )
    factors = calibrate(model, splits["val"], EVAL_FLOOR)
    total = time.perf_counter() - start
    summary = {
        "seed": config.seed,
        "epochs": config.epochs,
        "best_epoch": train_log.best_epoch + 1,
        "train_seconds": round(train_log.seconds, 1),
        "total_seconds": round(total, 1),
        "threads": config.threads,
        "windows": counts,
        "split": {k: list(v) for k, v in SPLIT.items()},
        "step_checks": [list(c) for c in corrected],
        "files_read": len(reports),
        "files_refused": len(refused),
        "calibration_mean_factor": {
            TYPE_GROUPS[g]: float(factors[g].mean()) for g in range(len(TYPE_GROUPS))
        },
    }
    model.meta = {k: json.dumps(v) if isinstance(v, dict | list) else v for k, v in summary.items()}
    out.parent.mkdir(parents=True, exist_ok=True)
    model.save(out)
    log(
        f"trained in {train_log.seconds:.0f} s (total {total:.0f} s); "
        f"best epoch {train_log.best_epoch + 1}; saved {out}"
    )
    if report is not None:
        write_report(evaluate(model, splits["test"]), report)
        log(f"held-out evaluation: {report / 'report.md'}")
    return model, train_log, summary


def run_evaluation(
    weights: Path | None,
    data: Sequence[Path],
    out: Path,
    split: str = "test",
    stride: int = 2,
    workers: int = 2,
    cache: Path | None = None,
    max_files: int | None = None,
) -> dict:
    """Evaluate a weights file (None: the shipped one) on one split; write the report to ``out``."""
    model = LearnedModel.load(weights)
    windows, _ = build_windows(data, model.spec, stride, workers, cache, max_files)
    chosen = split_windows(windows)[split]
    if len(chosen) == 0:
        raise ValueError(f"no windows of split {split!r} in the data given ({', '.join(SPLIT[split])})")
    result = evaluate(model, chosen)
    write_report(result, out)
    return result
