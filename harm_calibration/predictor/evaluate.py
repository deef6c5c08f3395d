"""Evaluation of predictors on held-out windows (``etp predictor eval``).

Per type group and per category (cars; pedestrians and cyclists), for the learned
predictor with its calibrated Gaussian scale mixture (``learned``) and as the
network's own single Gaussian (``learned, one Gaussian``), and for analytic baselines:

- ``constant_velocity``: the product's analytic predictor (``predict_constant_turn_rate``)
  with the turn rate off and its default covariance growth (``PredictionConfig``);
- ``ctra``: constant turn rate and constant acceleration (both from the last 0.2 s of
  history, speed not below 0), with the same analytic covariance;
- ``default (...)``: the planner's default analytic predictor (``PredictionConfig()``),
  given the acceleration and turn rate of the last 0.2 s.

Metrics over the model's horizon (0.2 .. 4 s): ADE and FDE [m], mean negative
log-likelihood of the true position [nats, 2-D] under the predicted density, and the
coverage at 1, 2 and 3 s: the fraction of true positions inside the region that holds
the nominal 39.3 % (1 sigma) and 86.5 % (2 sigma) of the predicted probability. For a
single Gaussian that region is the 1- or 2-sigma ellipse; for a scale mixture with a
shared mean (components v_k Sigma) it is the ellipse d^2 <= r^2 of Sigma whose mixture
mass ``mixture_cdf`` is the level (the smallest region of that mass, since the density
falls with d^2). A true position is inside iff the mixture mass within its own d^2 is
at most the level. Baseline covariances are floored at ``EVAL_FLOOR`` (10 cm
standard deviation, the recordings' accuracy; the learned network's covariance is
floored at the same ``RESOLUTION_FLOOR`` before its mixture scales it): the planner's
0.1 m^2 floor would put nearly every true position inside the 1-sigma ellipse at 1 s.
Cars and pedestrians/cyclists are also scored apart as moving (>= 0.5 m/s at
prediction time) and standing road users. A reliability plot draws, for nominal levels
5 .. 95 %, the observed fraction inside the level's region (steps 0.2 .. 3 s).
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
from ethical_planner.prediction.learned import MOVING_SPEED, RESOLUTION_FLOOR, LearnedModel, to_world
from ethical_planner.road_users import KinematicState, RoadUser, RoadUserType, Shape
from harm_calibration.predictor.data import Windows
from harm_calibration.predictor.train import NOMINAL, mahalanobis_sq, mixture_cdf

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
#: Categories also reported for moving (speed at prediction time >= MOVING_SPEED) and standing road users.
MOVING_CATEGORIES = ("car", "pedestrians+cyclists")
#: Covariance floor [m^2] of the baselines in evaluation: that of the learned network. The
#: planner's own floor (0.1 m^2) is applied on top in use.
EVAL_FLOOR = RESOLUTION_FLOOR


@dataclass(frozen=True, slots=True, eq=False)
class Scored:
    """One predictor's output on a set of windows, world frame: a Gaussian scale mixture.

    Attributes:
        mean: [m] (n, n_future, 2).
        weight: component weights (n, n_future, K) (K = 1: one Gaussian).
        cov: component covariances [m^2] (n, n_future, K, 2, 2), proportional to
            each other per window and step.
    """

    mean: np.ndarray
    weight: np.ndarray
    cov: np.ndarray

    @classmethod
    def gaussian(cls, mean: np.ndarray, cov: np.ndarray) -> Scored:
        """One Gaussian per window and step: cov (n, n_future, 2, 2)."""
        return cls(mean, np.ones(mean.shape[:2] + (1,)), cov[:, :, None])


def learned_outputs(model: LearnedModel, windows: Windows, calibrated: bool) -> Scored:
    """The learned model's prediction of every window (its mixture if ``calibrated``)."""
    spec = model.spec
    mean, weight, cov = model.predict_local(
        windows.features(spec), windows.groups, windows.speeds[:, -1], calibrated
    )
    mean, cov = to_world(mean, cov, windows.positions[:, -1], windows.headings[:, -1])
    return Scored(mean, weight, cov)


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
        "constant_velocity": Scored.gaussian(cv.mean[:, 1:], cv.cov[:, 1:]),
        "ctra": Scored.gaussian(ctra_mean(windows, times, step), ct.cov[:, 1:]),
        f"default ({default.name})": Scored.gaussian(analytic.mean[:, 1:], analytic.cov[:, 1:]),
    }


def mixture_nll(scored: Scored, target: np.ndarray) -> np.ndarray:
    """Negative log-likelihood [nats] of 2-D targets (n, n_future, 2) under the mixtures, (n, n_future)."""
    cov = scored.cov
    det = cov[..., 0, 0] * cov[..., 1, 1] - cov[..., 0, 1] ** 2
    d2 = mahalanobis_sq(scored.mean[:, :, None], cov, target[:, :, None])
    log_p = np.log(np.maximum(scored.weight, 1e-300)) - 0.5 * d2 - 0.5 * np.log(det) - math.log(2 * math.pi)
    top = log_p.max(axis=-1)
    return -(top + np.log(np.exp(log_p - top[..., None]).sum(-1)))


def probability_inside(scored: Scored, target: np.ndarray) -> np.ndarray:
    """Predicted probability of the smallest region that reaches each target, (n, n_future).

    A target is inside the region of nominal level p iff this is <= p. Components are
    proportional (v_k Sigma), so the region is an ellipse of the first component's shape.
    """
    cov0 = scored.cov[:, :, 0]
    d2 = mahalanobis_sq(scored.mean, cov0, target)
    factor = scored.cov[..., 0, 0] / cov0[..., None, 0, 0]  # v_k / v_0, (n, n_future, K)
    return mixture_cdf(d2, scored.weight, factor)


def _selections(windows: Windows) -> list[tuple[str, np.ndarray]]:
    """Report rows: each category, then moving and standing road users of MOVING_CATEGORIES."""
    moving = np.abs(windows.speeds[:, -1]) >= MOVING_SPEED
    out = [(name, np.isin(windows.groups, groups)) for name, groups in CATEGORIES.items()]
    for state, mask in (("moving", moving), ("standing", ~moving)):
        out += [
            (f"{name} ({state})", np.isin(windows.groups, CATEGORIES[name]) & mask)
            for name in MOVING_CATEGORIES
        ]
    return out


def metrics(scored: Scored, windows: Windows, times: np.ndarray) -> dict[str, dict]:
    """Per category: n, ADE, FDE [m], NLL [nats], coverage at ``COVERAGE_TIMES`` (fractions)."""
    err = np.linalg.norm(scored.mean - windows.future, axis=-1)
    nll = mixture_nll(scored, windows.future)
    inside = probability_inside(scored, windows.future)
    cols = [int(np.argmin(np.abs(times - t))) for t in COVERAGE_TIMES]
    out = {}
    for name, rows in _selections(windows):
        if not rows.any():
            continue
        out[name] = {
            "n": int(rows.sum()),
            "ade": float(err[rows].mean()),
            "fde": float(err[rows, -1].mean()),
            "nll": float(nll[rows].mean()),
            "coverage_1sigma": {f"{times[c]:g}": float((inside[rows, c] <= NOMINAL[1]).mean()) for c in cols},
            "coverage_2sigma": {f"{times[c]:g}": float((inside[rows, c] <= NOMINAL[2]).mean()) for c in cols},
        }
    return out


def reliability(scored: Scored, windows: Windows, times: np.ndarray, levels: np.ndarray) -> dict[str, list]:
    """Observed fraction inside the region of each nominal level, per category (steps <= 3 s)."""
    inside = probability_inside(scored, windows.future)[:, times <= 3.0 + 1e-9]
    out = {}
    for name in ("car", "pedestrians+cyclists"):
        rows = np.isin(windows.groups, CATEGORIES[name])
        if rows.any():
            values = inside[rows].ravel()
            out[name] = [float((values <= level).mean()) for level in levels]
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
        ax.set_ylabel("observed fraction inside the region of that probability")
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
        f"learned ({model.n_components}-Gaussian mixture)": learned_outputs(model, windows, True),
        "learned, one Gaussian": learned_outputs(model, windows, False),
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
