"""Train -> calibrate -> save, recalibrate a weights file, evaluate one: what the commands run."""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from ethical_planner.prediction.learned import (
    MOTION_STATES,
    TYPE_GROUPS,
    LearnedModel,
    ModelSpec,
    motion_state,
    to_world,
)
from harm_calibration.predictor.data import SPLIT, Windows, build_windows, split_windows
from harm_calibration.predictor.evaluate import evaluate, write_report
from harm_calibration.predictor.train import TrainConfig, TrainLog, fit_mixture, mahalanobis_sq, train


def calibrate(model: LearnedModel, val_windows: Windows, n_components: int = 2) -> np.ndarray:
    """Fit and set the model's Gaussian scale mixture on validation windows; returns it (``fit_mixture``)."""
    spec = model.spec
    w = val_windows
    if len(w) == 0:
        raise ValueError("calibration needs windows of the validation split")
    mean, _, cov = model.predict_local(w.features(spec), w.groups, w.speeds[:, -1], False)
    mean, cov = to_world(mean, cov[:, :, 0], w.positions[:, -1], w.headings[:, -1])
    d2 = mahalanobis_sq(mean, cov, w.future)
    sizes = 0.5 * (cov[..., 0, 0] + cov[..., 1, 1])
    params = fit_mixture(d2, sizes, w.groups, motion_state(w.speeds[:, -1]), n_components)
    model.calibration = params
    return params


def calibration_summary(params: np.ndarray, times: np.ndarray) -> dict[str, dict]:
    """Weights and standard-deviation factors sqrt(v) per group and motion state at 1, 2, 3 s."""
    cols = {f"{t:g}": int(np.argmin(np.abs(times - t))) for t in (1.0, 2.0, 3.0)}
    return {
        f"{TYPE_GROUPS[g]} {MOTION_STATES[m]}": {
            t: {
                "weight": np.round(params[g, m, c, :, 0], 3).tolist(),
                "sigma_factor": np.round(np.sqrt(params[g, m, c, :, 1]), 3).tolist(),
            }
            for t, c in cols.items()
        }
        for g in range(len(TYPE_GROUPS))
        for m in range(len(MOTION_STATES))
    }


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
    n_components: int = 2,
) -> tuple[LearnedModel, TrainLog, dict]:
    """Read data, train, fit the mixture calibration on the validation split, save to ``out``.

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
    params = calibrate(model, splits["val"], n_components)
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
        "calibration": calibration_summary(params, spec.future_times),
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


def run_calibration(
    weights: Path | None,
    data: Sequence[Path],
    out: Path,
    n_components: int = 2,
    stride: int = 2,
    workers: int = 2,
    cache: Path | None = None,
    max_files: int | None = None,
    log: Callable[[str], None] = print,
) -> dict:
    """Refit the mixture calibration of a weights file (None: the shipped one) on the validation split.

    The network is unchanged; the file written to ``out`` has the new calibration and
    the old provenance plus the calibration's summary.
    """
    model = LearnedModel.load(weights)
    windows, _ = build_windows(data, model.spec, stride, workers, cache, max_files)
    val = split_windows(windows)["val"]
    log(f"calibrating on {len(val)} validation windows from {', '.join(SPLIT['val'])}")
    params = calibrate(model, val, n_components)
    summary = calibration_summary(params, model.spec.future_times)
    model.meta = {**model.meta, "calibration": json.dumps(summary), "calibration_windows": len(val)}
    out.parent.mkdir(parents=True, exist_ok=True)
    model.save(out)
    log(f"saved {out} ({n_components}-component mixture)")
    return {
        "weights": str(out),
        "components": n_components,
        "validation_windows": len(val),
        "calibration": summary,
    }


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
