"""Training and recalibration of the learned predictor (``etp predictor train``).

Training minimises the Gaussian negative log-likelihood of the true future centres,
averaged over the 20 future steps, with each type group weighted so that the groups
count equally (cars outnumber pedestrians four to one). Adam, a fixed number of
epochs, the epoch with the best validation NLL kept. Reproducible: one seed drives
torch's initialisation and the numpy generator that shuffles, and torch runs on a
fixed number of threads.

Recalibration fits one covariance factor per type group and future step on the
validation split: the factor c that brings the fractions of true positions inside
the 1-sigma and 2-sigma ellipses of c * Sigma closest to their nominal values
(sum of absolute errors, searched on a log grid).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ethical_planner.prediction.learned import (
    TYPE_GROUPS,
    LearnedModel,
    ModelSpec,
    gaussian_nll,
    gaussian_params,
)
from harm_calibration.predictor.data import Windows

#: Fractions of a bivariate normal inside its 1- and 2-sigma ellipses.
NOMINAL = {1: 1.0 - math.exp(-0.5), 2: 1.0 - math.exp(-2.0)}


@dataclass(frozen=True, slots=True)
class TrainConfig:
    """Optimisation settings.

    Attributes:
        epochs: passes over the training windows.
        batch: windows per step.
        lr: Adam learning rate (cosine-decayed to 5 % over the run).
        weight_decay: AdamW weight decay.
        seed: initialisation and shuffling.
        threads: torch intra-op threads.
        max_seconds: stop after this many seconds of training (None: no limit).
    """

    epochs: int = 40
    batch: int = 512
    lr: float = 1e-3
    weight_decay: float = 1e-5
    seed: int = 0
    threads: int = 1
    max_seconds: float | None = None

    def __post_init__(self) -> None:
        if self.epochs < 1 or self.batch < 1 or self.threads < 1:
            raise ValueError("epochs, batch and threads must be >= 1")
        if not (self.lr > 0 and self.weight_decay >= 0):
            raise ValueError("lr must be > 0 and weight_decay >= 0")


@dataclass(slots=True)
class TrainLog:
    """Loss per epoch (training and validation NLL [nats]), the kept epoch and the time taken."""

    train_nll: list[float] = field(default_factory=list)
    val_nll: list[float] = field(default_factory=list)
    best_epoch: int = -1
    seconds: float = 0.0


def _local_targets(windows: Windows) -> np.ndarray:
    """True future centres in each road user's frame [m], (n, n_future, 2)."""
    origin = windows.positions[:, -1]
    yaw = windows.headings[:, -1]
    rel = windows.future - origin[:, None, :]
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    return np.stack([c * rel[..., 0] + s * rel[..., 1], -s * rel[..., 0] + c * rel[..., 1]], axis=-1)


def group_weights(groups: np.ndarray) -> np.ndarray:
    """Per-window weights so that every present group has the same total weight (mean 1)."""
    counts = np.bincount(groups, minlength=len(TYPE_GROUPS)).astype(float)
    present = counts > 0
    per_group = np.zeros_like(counts)
    per_group[present] = len(groups) / (present.sum() * counts[present])
    return per_group[groups]


def train(
    train_windows: Windows,
    val_windows: Windows,
    spec: ModelSpec,
    config: TrainConfig,
    progress: Callable[[int, float, float], None] | None = None,
) -> tuple[LearnedModel, TrainLog]:
    """Train a model (uncalibrated) and return it with its loss log.

    Args:
        train_windows, val_windows: windows from disjoint locations.
        spec: window and network shape.
        config: optimisation settings.
        progress: called after each epoch with (epoch, train NLL, validation NLL).
    """
    import torch

    if len(train_windows) == 0 or len(val_windows) == 0:
        raise ValueError("training needs windows in both the training and the validation split")
    torch.set_num_threads(config.threads)
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    model = LearnedModel(spec)
    net = model.network
    tensors = {}
    for name, w in (("train", train_windows), ("val", val_windows)):
        tensors[name] = (
            torch.as_tensor(w.features(spec)),
            torch.as_tensor(w.speeds[:, -1], dtype=torch.float32),
            torch.as_tensor(_local_targets(w), dtype=torch.float32),
            torch.as_tensor(group_weights(w.groups), dtype=torch.float32),
        )
    x, v0, y, wt = tensors["train"]
    n = len(x)
    steps_per_epoch = max(1, math.ceil(n / config.batch))
    optimiser = torch.optim.AdamW(net.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    total = config.epochs * steps_per_epoch
    schedule = torch.optim.lr_scheduler.LambdaLR(
        optimiser, lambda k: 0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * min(k, total) / total))
    )
    log = TrainLog()
    best_state, best_val = None, math.inf
    start = time.perf_counter()
    for epoch in range(config.epochs):
        net.train()
        order = torch.as_tensor(rng.permutation(n))
        running, seen = 0.0, 0.0
        for k in range(steps_per_epoch):
            idx = order[k * config.batch : (k + 1) * config.batch]
            mean, chol = gaussian_params(net(x[idx]), v0[idx], spec)
            nll = gaussian_nll(mean, chol, y[idx]).mean(dim=1)
            loss = (nll * wt[idx]).sum() / wt[idx].sum()
            optimiser.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), 10.0)
            optimiser.step()
            schedule.step()
            running += loss.item() * len(idx)
            seen += len(idx)
        val = weighted_nll(model, *tensors["val"])
        log.train_nll.append(running / seen)
        log.val_nll.append(val)
        if val < best_val:
            best_val, log.best_epoch = val, epoch
            best_state = {k: t.detach().clone() for k, t in net.state_dict().items()}
        if progress is not None:
            progress(epoch, running / seen, val)
        if config.max_seconds is not None and time.perf_counter() - start > config.max_seconds:
            break
    log.seconds = time.perf_counter() - start
    if best_state is not None:
        net.load_state_dict(best_state)
    net.eval()
    return model, log


def weighted_nll(model: LearnedModel, x, v0, y, wt) -> float:  # noqa: ANN001 - torch tensors
    """Group-weighted mean NLL [nats] of a model on prepared tensors."""
    import torch

    net = model.network
    net.eval()
    with torch.inference_mode():
        mean, chol = gaussian_params(net(x), v0, model.spec)
        nll = gaussian_nll(mean, chol, y).mean(dim=1)
        return float((nll * wt).sum() / wt.sum())


def mahalanobis_sq(mean: np.ndarray, cov: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Squared Mahalanobis distances of targets, shapes (..., 2), (..., 2, 2), (..., 2) -> (...)."""
    d = target - mean
    a, b, c = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    det = a * c - b * b
    return (c * d[..., 0] ** 2 - 2 * b * d[..., 0] * d[..., 1] + a * d[..., 1] ** 2) / det


def _eigen_parts(cov: np.ndarray, error: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (..., 2) of ``cov`` and squared projections (..., 2) of ``error`` on its eigenvectors."""
    eigval, eigvec = np.linalg.eigh(cov)
    proj = np.einsum("...ji,...j->...i", eigvec, error)
    return np.maximum(eigval, 0.0), proj**2


def coverage_d2(eigval: np.ndarray, proj2: np.ndarray, factor: np.ndarray, floor: float) -> np.ndarray:
    """Squared Mahalanobis distances under factor * Sigma with eigenvalues floored at ``floor`` [m^2]."""
    return (proj2 / np.maximum(factor[..., None] * eigval, floor)).sum(-1)


def fit_calibration(
    cov: np.ndarray,
    error: np.ndarray,
    groups: np.ndarray,
    floor: float,
    a_grid: np.ndarray | None = None,
    b_grid: np.ndarray | None = None,
) -> np.ndarray:
    """Recalibration (a, b) per type group and step from validation errors.

    The covariance becomes a * s^(2 (b - 1)) * Sigma (s^2 = trace / 2,
    ``ethical_planner.prediction.learned.recalibrate``), then floored like the
    planner's; (a, b) minimise the sum of absolute differences between the observed
    and nominal fractions inside the 1- and 2-sigma ellipses. b = 1 is a plain scale;
    b > 1 widens the unsure predictions more than the confident ones (errors with
    heavier tails than one Gaussian).

    Args:
        cov: uncalibrated covariances [m^2], (n, n_steps, 2, 2).
        error: true minus predicted position [m], (n, n_steps, 2).
        groups: type group per row, (n,).
        floor: covariance floor [m^2] applied after recalibration.
        a_grid, b_grid: candidates (default: a 0.1 .. 10 log spaced x 60, b 0.75 .. 1.5 x 16).

    Returns:
        (n_groups, n_steps, 2); (1, 1) for a group without rows.
    """
    a_grid = np.geomspace(0.1, 10.0, 60) if a_grid is None else a_grid
    b_grid = np.linspace(0.75, 1.5, 16) if b_grid is None else b_grid
    out = np.ones((len(TYPE_GROUPS), cov.shape[1], 2))
    eigval, proj2 = _eigen_parts(cov, error)
    s2 = np.maximum(eigval.mean(-1), 1e-12)
    for g in range(len(TYPE_GROUPS)):
        rows = groups == g
        if not rows.any():
            continue
        for step in range(cov.shape[1]):
            lam, p2, size = eigval[rows, step], proj2[rows, step], s2[rows, step]
            best, best_err = (1.0, 1.0), np.inf
            for b in b_grid:
                shape = size ** (b - 1.0)  # (n,)
                factor = a_grid[:, None] * shape[None, :]  # (n_a, n)
                d2 = coverage_d2(lam[None], p2[None], factor, floor)
                err = np.abs((d2 <= 1.0).mean(1) - NOMINAL[1]) + np.abs((d2 <= 4.0).mean(1) - NOMINAL[2])
                k = int(np.argmin(err))
                if err[k] < best_err - 1e-12:
                    best, best_err = (float(a_grid[k]), float(b)), float(err[k])
            out[g, step] = best
    return out
