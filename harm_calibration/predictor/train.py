"""Training and recalibration of the learned predictor (``etp predictor train``).

Training minimises the Gaussian negative log-likelihood of the true future centres,
averaged over the 20 future steps, with each type group weighted so that the groups
count equally (cars outnumber pedestrians four to one). Adam, a fixed number of
epochs, the epoch with the best validation NLL kept. Reproducible: one seed drives
torch's initialisation and the numpy generator that shuffles, and torch runs on a
fixed number of threads.

Calibration fits, on the validation split, a Gaussian scale mixture per type group,
motion state and future step: with d^2 the squared Mahalanobis distance of the true
position under the network's (floored) covariance Sigma, the mixture
sum_k w_k N(mu, v_k Sigma) has the density sum_k w_k exp(-d^2 / (2 v_k)) / (2 pi v_k
sqrt|Sigma|), so maximising its likelihood is fitting a mixture of exponentials to
d^2 / 2, done by expectation-maximisation (``fit_mixture``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ethical_planner.prediction.learned import (
    MOTION_STATES,
    RESOLUTION_FLOOR,
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


#: A calibration cell (type group, motion state, step) with fewer validation windows than
#: this takes the fit of its type group's windows of both motion states.
MIN_CELL_WINDOWS = 50
#: Quantile of the covariance sizes in a calibration cell that sets its narrowest component
#: (``fit_mixture``): 5 %, the cell's most confident windows.
BOUND_QUANTILE = 0.05
#: Smallest variance factor a component may take (a component of exactly zero size
#: would be a point mass).
MIN_VARIANCE_FACTOR = 1e-6


def fit_scale_mixture(
    d2: np.ndarray, n_components: int, min_factor: float = MIN_VARIANCE_FACTOR, iterations: int = 500
) -> np.ndarray:
    """Maximum-likelihood weights and variance factors of a 2-D Gaussian scale mixture.

    Args:
        d2: squared Mahalanobis distances of the true positions under Sigma, shape (n,).
        n_components: K.
        min_factor: smallest variance factor of a component. The M-step clips each
            v_k to it, which is the constrained maximum (the likelihood is unimodal in
            each v_k given the responsibilities).
        iterations: expectation-maximisation steps (stops earlier once the
            log-likelihood changes by less than 1e-10 nats per window).

    Returns:
        (K, 2): weight and variance factor v of each component, narrowest first. Under
        the fit, component k is N(mu, v_k Sigma), so d^2 / (2 v_k) is exponential.
    """
    d2 = np.asarray(d2, dtype=float)
    if d2.ndim != 1 or len(d2) == 0 or not np.all(np.isfinite(d2)) or d2.min() < 0:
        raise ValueError("d2 must be a non-empty 1-D array of finite values >= 0")
    if n_components < 1:
        raise ValueError(f"n_components must be >= 1, got {n_components}")
    # Start from spread quantiles: each component covers a band of the distances.
    quantiles = np.linspace(0.25, 0.9, n_components) if n_components > 1 else np.array([0.5])
    min_factor = max(float(min_factor), MIN_VARIANCE_FACTOR)
    v = np.maximum(np.quantile(d2, quantiles) / 2.0, min_factor)
    if n_components == 1:
        v = np.array([max(d2.mean() / 2.0, min_factor)])
    w = np.full(n_components, 1.0 / n_components)
    previous = -np.inf
    for _ in range(iterations):
        log_p = np.log(np.maximum(w, 1e-300)) - d2[:, None] / (2.0 * v) - np.log(v)  # (n, K)
        top = log_p.max(axis=1, keepdims=True)
        resp = np.exp(log_p - top)
        total = resp.sum(axis=1, keepdims=True)
        loglik = float(np.mean(np.log(total[:, 0]) + top[:, 0]))
        resp /= total
        mass = resp.sum(axis=0)
        w = mass / len(d2)
        v = np.maximum((resp * d2[:, None]).sum(axis=0) / (2.0 * np.maximum(mass, 1e-300)), min_factor)
        if loglik - previous < 1e-10:
            break
        previous = loglik
    order = np.argsort(v)
    return np.stack([w[order], v[order]], axis=-1)


def fit_mixture(
    d2: np.ndarray,
    sizes: np.ndarray,
    groups: np.ndarray,
    states: np.ndarray,
    n_components: int = 2,
    resolution: float = RESOLUTION_FLOOR,
) -> np.ndarray:
    """The calibration of a ``LearnedModel``: a scale mixture per type group, motion state and step.

    No component may be narrower than the recordings' accuracy for the most confident
    windows of its cell: v_k >= resolution / q(size), with size = trace(Sigma) / 2 and
    q its ``BOUND_QUANTILE`` quantile in the cell. Without this bound, standing road
    users (whose recorded positions are frozen to the millimetre) get components of
    millimetres, claiming a precision the recordings cannot confirm; for moving road
    users (size >> resolution from about 0.5 s on) it is inactive.

    Args:
        d2: squared Mahalanobis distances of validation positions under the network's
            floored covariance Sigma, shape (n, n_steps).
        sizes: trace(Sigma) / 2 [m^2], shape (n, n_steps).
        groups: type group per window, shape (n,).
        states: motion state per window (``motion_state``), shape (n,).
        n_components: K.
        resolution: [m^2] the bound's variance (``RESOLUTION_FLOOR``).

    Returns:
        (len(TYPE_GROUPS), len(MOTION_STATES), n_steps, K, 2). A cell with fewer than
        ``MIN_CELL_WINDOWS`` windows takes its group's fit over both states; a group
        without windows keeps the network's Gaussian (w = (1, 0, ..), v = 1).
    """
    n_steps = d2.shape[1]
    out = np.zeros((len(TYPE_GROUPS), len(MOTION_STATES), n_steps, n_components, 2))
    out[..., 1] = 1.0
    out[..., 0, 0] = 1.0
    for g in range(len(TYPE_GROUPS)):
        in_group = groups == g
        if not in_group.any():
            continue
        for state in range(len(MOTION_STATES)):
            rows = in_group & (states == state)
            if rows.sum() < MIN_CELL_WINDOWS:
                rows = in_group
            for step in range(n_steps):
                bound = resolution / float(np.quantile(sizes[rows, step], BOUND_QUANTILE))
                out[g, state, step] = fit_scale_mixture(d2[rows, step], n_components, bound)
    return out


def mixture_cdf(d2: np.ndarray, weight: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """Mass of sum_k w_k N(mu, v_k Sigma) inside the ellipse d^2(x) <= d2 of Sigma, shape (...).

    Args:
        d2: squared Mahalanobis radii under Sigma, shape (...).
        weight, factor: w_k and v_k, shape (..., K).
    """
    return (weight * -np.expm1(-np.asarray(d2)[..., None] / (2.0 * factor))).sum(-1)
