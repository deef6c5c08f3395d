"""Evaluation of predictors on held-out windows (``etp predictor eval``).

Per type group and per category (cars; pedestrians and cyclists), for the learned
predictor before and after recalibration and for two analytic baselines:

- ``constant_velocity``: the product's analytic predictor (``predict_constant_turn_rate``)
  with the turn rate off and its default covariance growth (``PredictionConfig``);
- ``ctra``: constant turn rate and constant acceleration (both from the last 0.2 s of
  history, speed not below 0), with the same analytic covariance;
- ``default (...)``: the planner's default analytic predictor (``PredictionConfig()``),
  given the acceleration and turn rate of the last 0.2 s.

Metrics over the model's horizon (0.2 .. 4 s): ADE and FDE [m], mean negative
log-likelihood of the true position [nats, 2-D], and the fractions of true positions
inside the 1- and 2-sigma ellipses at 1, 2 and 3 s (nominal 39.3 % and 86.5 %). All
covariances are floored at ``EVAL_FLOOR`` (10 cm standard deviation, the recordings'
resolution; recalibration uses the same floor) before they are scored: the planner's
0.1 m^2 floor would put nearly every true position inside the 1-sigma ellipse at 1 s.
Cars and pedestrians/cyclists are also scored on moving road users only: road users
standing still (waiting at the SinD intersection) have almost no error. A reliability
plot draws, for nominal levels 5 .. 95 %, the observed fraction inside the level's ellipse (steps 0.2 .. 3 s).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ethical_planner.config import PredictionConfig
from ethical_planner.prediction import make_predictor
from ethical_planner.prediction.constant_turn_rate import predict_constant_turn_rate
from ethical_planner.prediction.learned import LearnedModel, to_world
from ethical_planner.road_users import KinematicState, RoadUser, RoadUserType, Shape
from harm_calibration.predictor.data import Windows
from harm_calibration.predictor.train import NOMINAL, mahalanobis_sq

#: Report categories: name -> type groups.
CATEGORIES = {
    "car": (0,),
    "truck/bus": (1,),
    "motorcycle": (2,),
    "bicycle": (3,),
    "pedestrian": (4,),
    "pedestrians+cyclists": (3, 4),
}
COVERAGE_TIMES = (1.0, 2.0, 3.0)
#: Categories also reported for moving road users only (speed at prediction time >= MOVING_SPEED).
MOVING_CATEGORIES = ("car", "pedestrians+cyclists")
MOVING_SPEED = 0.5  # [m/s]
#: Covariance floor [m^2] of calibration and evaluation: a 10 cm standard deviation, the
#: recordings' position resolution. The planner's own floor (0.1 m^2) is applied on top in use.
EVAL_FLOOR = 0.01


@dataclass(frozen=True, slots=True, eq=False)
class Scored:
    """One predictor's output on a set of windows, world frame.

    Attributes:
        mean: [m] (n, n_future, 2). cov: [m^2] (n, n_future, 2, 2), floored.
    """

    mean: np.ndarray
    cov: np.ndarray


def floor_covariance(cov: np.ndarray, floor: float) -> np.ndarray:
    """Covariances with eigenvalues raised to ``floor`` [m^2] (as the planner does)."""
    eigval, eigvec = np.linalg.eigh(cov)
    return np.einsum("...ij,...j,...kj->...ik", eigvec, np.maximum(eigval, floor), eigvec)


def learned_outputs(model: LearnedModel, windows: Windows, calibrated: bool, floor: float) -> Scored:
    """The learned model's prediction of every window."""
    spec = model.spec
    mean, cov = model.predict_local(windows.features(spec), windows.groups, windows.speeds[:, -1], calibrated)
    mean, cov = to_world(mean, cov, windows.positions[:, -1], windows.headings[:, -1])
    return Scored(mean, floor_covariance(cov, floor))


def _road_users(windows: Windows, yaw_rate: np.ndarray, accel: np.ndarray | None = None) -> list[RoadUser]:
    pos, yaw, v = windows.positions[:, -1], windows.headings[:, -1], windows.speeds[:, -1]
    accel = np.zeros(len(windows)) if accel is None else accel
    return [
        RoadUser(
            k,
            RoadUserType(str(windows.types[k])),
            KinematicState(
                float(pos[k, 0]),
                float(pos[k, 1]),
                float(yaw[k]),
                float(v[k]),
                float(accel[k]),
                float(yaw_rate[k]),
            ),
            Shape(float(windows.length[k]), float(windows.width[k])),
        )
        for k in range(len(windows))
    ]


def history_rates(windows: Windows, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Yaw rate [rad/s] and acceleration [m/s^2] over the last history interval (0 if none)."""
    has = windows.available >= 2
    yaw_rate = np.where(has, (windows.headings[:, -1] - windows.headings[:, -2]) / step, 0.0)
    accel = np.where(has, (windows.speeds[:, -1] - windows.speeds[:, -2]) / step, 0.0)
    return yaw_rate, accel


def ctra_mean(windows: Windows, times: np.ndarray, step: float, substeps: int = 10) -> np.ndarray:
    """Constant turn rate and acceleration means [m], (n, n_t, 2), integrated in substeps."""
    yaw_rate, accel = history_rates(windows, step)
    x = windows.positions[:, -1].copy()
    yaw = windows.headings[:, -1].copy()
    v = windows.speeds[:, -1].copy()
    out = np.empty((len(windows), len(times), 2))
    t_prev = 0.0
    for k, t in enumerate(times):
        h = (t - t_prev) / substeps
        for _ in range(substeps):
            v_mid = np.maximum(v + 0.5 * accel * h, 0.0)
            yaw_mid = yaw + 0.5 * yaw_rate * h
            x = x + h * v_mid[:, None] * np.stack([np.cos(yaw_mid), np.sin(yaw_mid)], axis=-1)
            v = np.maximum(v + accel * h, 0.0)
            yaw = yaw + yaw_rate * h
        out[:, k] = x
        t_prev = t
    return out


def baseline_outputs(
    windows: Windows, times: np.ndarray, step: float, config: PredictionConfig
) -> dict[str, Scored]:
    """Constant velocity and CTRA with the analytic covariance, and the planner's default predictor."""
    yaw_rate, accel = history_rates(windows, step)
    cv_config = PredictionConfig(use_turn_rate=False, covariance_floor=config.covariance_floor)
    cv = predict_constant_turn_rate(_road_users(windows, yaw_rate), np.concatenate([[0.0], times]), cv_config)
    ct = predict_constant_turn_rate(_road_users(windows, yaw_rate), np.concatenate([[0.0], times]), config)
    default = make_predictor(replace(PredictionConfig(), covariance_floor=config.covariance_floor))
    analytic = default.predict(_road_users(windows, yaw_rate, accel), np.concatenate([[0.0], times]))
    return {
        "constant_velocity": Scored(cv.mean[:, 1:], cv.cov[:, 1:]),
        "ctra": Scored(ctra_mean(windows, times, step), ct.cov[:, 1:]),
        f"default ({default.name})": Scored(analytic.mean[:, 1:], analytic.cov[:, 1:]),
    }


def gaussian_nll_np(mean: np.ndarray, cov: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Negative log-likelihood [nats] of 2-D targets, (...)."""
    det = cov[..., 0, 0] * cov[..., 1, 1] - cov[..., 0, 1] ** 2
    return 0.5 * mahalanobis_sq(mean, cov, target) + 0.5 * np.log(det) + math.log(2 * math.pi)


def metrics(scored: Scored, windows: Windows, times: np.ndarray) -> dict[str, dict]:
    """Per category: n, ADE, FDE [m], NLL [nats], coverage at ``COVERAGE_TIMES`` (fractions)."""
    err = np.linalg.norm(scored.mean - windows.future, axis=-1)
    nll = gaussian_nll_np(scored.mean, scored.cov, windows.future)
    d2 = mahalanobis_sq(scored.mean, scored.cov, windows.future)
    cols = [int(np.argmin(np.abs(times - t))) for t in COVERAGE_TIMES]
    out = {}
    moving = np.abs(windows.speeds[:, -1]) >= MOVING_SPEED
    selections = [(name, np.isin(windows.groups, groups)) for name, groups in CATEGORIES.items()]
    selections += [
        (f"{name} (moving)", np.isin(windows.groups, CATEGORIES[name]) & moving) for name in MOVING_CATEGORIES
    ]
    for name, rows in selections:
        if not rows.any():
            continue
        out[name] = {
            "n": int(rows.sum()),
            "ade": float(err[rows].mean()),
            "fde": float(err[rows, -1].mean()),
            "nll": float(nll[rows].mean()),
            "coverage_1sigma": {f"{times[c]:g}": float((d2[rows, c] <= 1.0).mean()) for c in cols},
            "coverage_2sigma": {f"{times[c]:g}": float((d2[rows, c] <= 4.0).mean()) for c in cols},
        }
    return out


def reliability(scored: Scored, windows: Windows, times: np.ndarray, levels: np.ndarray) -> dict[str, list]:
    """Observed fraction inside the ellipse of each nominal level, per category (steps <= 3 s)."""
    d2 = mahalanobis_sq(scored.mean, scored.cov, windows.future)[:, times <= 3.0 + 1e-9]
    radius_sq = -2.0 * np.log(1.0 - levels)
    out = {}
    for name in ("car", "pedestrians+cyclists"):
        rows = np.isin(windows.groups, CATEGORIES[name])
        if rows.any():
            values = d2[rows].ravel()
            out[name] = [float((values <= r).mean()) for r in radius_sq]
    return out


def plot_reliability(curves: dict[str, dict[str, list]], levels: np.ndarray, path: Path) -> None:
    """Reliability diagram: one panel per category, one line per predictor."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    categories = sorted({c for per in curves.values() for c in per})
    fig, axes = plt.subplots(1, len(categories), figsize=(5 * len(categories), 4.5), squeeze=False)
    for ax, category in zip(axes[0], categories, strict=True):
        ax.plot([0, 1], [0, 1], color="0.6", linestyle=":", label="ideal")
        for name, per in curves.items():
            if category in per:
                ax.plot(levels, per[category], marker="o", markersize=3, label=name)
        ax.set_title(f"{category}: steps 0.2-3 s, held-out locations")
        ax.set_xlabel("nominal probability inside the ellipse")
        ax.set_ylabel("observed fraction inside")
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def evaluate(model: LearnedModel, windows: Windows, config: PredictionConfig | None = None) -> dict:
    """Scores of the learned model and the baselines on ``windows``."""
    config = config or PredictionConfig(covariance_floor=EVAL_FLOOR)
    spec = model.spec
    times = spec.future_times
    outputs = {
        "learned": learned_outputs(model, windows, False, config.covariance_floor),
        "learned_recalibrated": learned_outputs(model, windows, True, config.covariance_floor),
        **baseline_outputs(windows, times, spec.history_step, config),
    }
    levels = np.linspace(0.05, 0.95, 19)
    return {
        "metrics": {name: metrics(s, windows, times) for name, s in outputs.items()},
        "reliability": {name: reliability(s, windows, times, levels) for name, s in outputs.items()},
        "levels": levels.tolist(),
        "nominal": {"1sigma": NOMINAL[1], "2sigma": NOMINAL[2]},
        "n_windows": len(windows),
        "recordings": sorted(set(windows.recording.tolist())),
    }


def report_markdown(result: dict) -> str:
    """Tables of ``evaluate``'s result (per category: one row per predictor)."""
    lines = [
        f"Held-out windows: {result['n_windows']} from {', '.join(result['recordings'])}.",
        "",
        "| category | predictor | n | ADE [m] | FDE 4 s [m] | NLL [nats] | 1σ cov 1/2/3 s | 2σ cov 1/2/3 s |",
        "| --- | --- | ---: | ---: | ---: | ---: | --- | --- |",
    ]
    per_predictor = result["metrics"]
    categories = list(next(iter(per_predictor.values())).keys())
    for category in categories:
        for name in per_predictor:
            m = per_predictor[name].get(category)
            if m is None:
                continue
            c1 = " / ".join(f"{100 * v:.1f}" for v in m["coverage_1sigma"].values())
            c2 = " / ".join(f"{100 * v:.1f}" for v in m["coverage_2sigma"].values())
            lines.append(
                f"| {category} | {name} | {m['n']} | {m['ade']:.2f} | {m['fde']:.2f} | "
                f"{m['nll']:.2f} | {c1} | {c2} |"
            )
    lines += ["", f"Nominal coverage: 1σ {100 * NOMINAL[1]:.1f} %, 2σ {100 * NOMINAL[2]:.1f} %."]
    return "\n".join(lines) + "\n"


def write_report(result: dict, out: Path) -> None:
    """``metrics.json``, ``report.md`` and ``reliability.png`` in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "metrics.json").write_text(json.dumps(result, indent=2))
    (out / "report.md").write_text(report_markdown(result))
    plot_reliability(result["reliability"], np.asarray(result["levels"]), out / "reliability.png")
