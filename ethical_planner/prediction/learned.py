"""The learned predictor: a small torch network whose prediction is a Gaussian scale mixture per step.

The network gives each road user one bivariate normal per future step (mean and
covariance), like the paper's WaleNet. Its errors on held-out locations are
heavier-tailed than one Gaussian: a single covariance scale can match the 1-sigma
or the 2-sigma coverage, never both. So the calibrated prediction is a mixture of K
Gaussians (K = 2 shipped) with the network's mean and shape: component k is
N(mu, v_k Sigma) with weight w_k, and (w_k, v_k) are fitted by maximum likelihood
per type group, motion state (standing below ``MOVING_SPEED``, moving) and step on
validation locations (``harm_calibration.predictor.train.fit_mixture``). The planner's
collision probability of a mixture is the weighted sum of its components'
(``ethical_planner.risk.prediction_collision_probability``).

Input per road user (in its own frame: origin at its centre, x along its heading):
its type group, length and width, and its past 2 s sampled every 0.2 s (positions,
headings, speeds; ``ModelSpec``). A road user seen for less than that (it just
appeared, or has no ``history``) is padded backwards at constant velocity from its
oldest known state, and the network is told how much of its history is real (it was
trained on tracks that appear late, so it has seen such windows).

Output per future step (0.2 s .. 4 s every 0.2 s): the mean as a correction of the
constant-velocity position, and a Cholesky factor of the covariance Sigma; Sigma's
eigenvalues are raised to ``RESOLUTION_FLOOR`` (the recordings' 10 cm accuracy) and
its size (trace / 2) to its running maximum along the horizon; then the mixture's
components are v_k Sigma, all scaled alike where needed so that the mixture's size
sum_k w_k v_k trace(Sigma) / 2 never shrinks along the horizon either (before the
planner's covariance floor, which raises each component on its own). Times between
steps are interpolated linearly (mean, weights, covariances apart); t = 0 is the
observed state with the config's ``sigma0`` uncertainty; beyond 4 s the mean continues
at the last predicted velocity and the covariances grow with t^2.

torch is imported only when a model is loaded (extra ``[learned]``); its intra-op
threads are set explicitly (``PredictionConfig.torch_threads``) so that a process
pool of planners does not oversubscribe the cores.
"""

from __future__ import annotations

import importlib.resources
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ethical_planner.config import PredictionConfig
from ethical_planner.prediction.base import (
    PREDICTORS,
    Prediction,
    check_unique_ids,
    empty_prediction,
    floor_eigenvalues,
    rotated_covariance,
)
from ethical_planner.road_users import RoadUser, RoadUserType

#: Identifies a weights file of this model; bump ``FORMAT_VERSION`` when the layout changes.
FORMAT = "etp-learned-predictor"
FORMAT_VERSION = 2
#: The weights shipped with the package (``ethical_planner/data``).
SHIPPED_WEIGHTS = "learned_predictor.pt"

#: Type groups the model knows, in one-hot order.
TYPE_GROUPS = ("car", "truck", "motorcycle", "bicycle", "pedestrian")
GROUP_OF_TYPE = {
    RoadUserType.CAR: 0,
    RoadUserType.TAXI: 0,
    RoadUserType.PRIORITY_VEHICLE: 0,
    RoadUserType.PARKED_VEHICLE: 0,
    RoadUserType.TRUCK: 1,
    RoadUserType.BUS: 1,
    RoadUserType.MOTORCYCLE: 2,
    RoadUserType.BICYCLE: 3,
    RoadUserType.PEDESTRIAN: 4,
}
#: Smallest eigenvalue [m^2] of the network's covariance before the mixture scales it: a
#: 10 cm standard deviation, the recordings' position accuracy (the planner floors at its
#: own ``PredictionConfig.covariance_floor`` on top).
RESOLUTION_FLOOR = 0.01
#: Road users slower than this [m/s] at prediction time are "standing": their mixture is
#: fitted apart from that of moving ones (a queue that stays or starts, not a drift).
MOVING_SPEED = 0.5
#: Motion states of the calibration: index 0 standing, 1 moving.
MOTION_STATES = ("standing", "moving")
_POSITION_SCALE = 10.0  # [m]
_LOG_2PI = float(np.log(2.0 * np.pi))
_SPEED_SCALE = 10.0  # [m/s]


@dataclass(frozen=True, slots=True)
class ModelSpec:
    """Shape of the model's input and output windows and of its network.

    Attributes:
        history_step: [s] between history samples.
        n_history: history samples, the current one included.
        future_step: [s] between predicted steps.
        n_future: predicted steps (the first at ``future_step``).
        hidden: widths of the hidden layers.
    """

    history_step: float = 0.2
    n_history: int = 11
    future_step: float = 0.2
    n_future: int = 20
    hidden: tuple[int, ...] = (128, 128)

    def __post_init__(self) -> None:
        object.__setattr__(self, "hidden", tuple(int(h) for h in self.hidden))
        if not (self.history_step > 0 and self.future_step > 0):
            raise ValueError("ModelSpec.history_step and future_step must be > 0 s")
        if self.n_history < 2 or self.n_future < 1 or not self.hidden or min(self.hidden) < 1:
            raise ValueError("ModelSpec needs n_history >= 2, n_future >= 1 and hidden widths >= 1")

    @property
    def n_features(self) -> int:
        """Length of one input vector."""
        return 6 * self.n_history + 1 + len(TYPE_GROUPS) + 2

    @property
    def future_times(self) -> np.ndarray:
        """Predicted times [s], shape (n_future,)."""
        return self.future_step * np.arange(1, self.n_future + 1)

    @property
    def history_times(self) -> np.ndarray:
        """History sample times [s], oldest first, shape (n_history,), last = 0."""
        return self.history_step * np.arange(1 - self.n_history, 1)

    def to_dict(self) -> dict[str, Any]:
        """Plain values for a weights file."""
        return {
            "history_step": self.history_step,
            "n_history": self.n_history,
            "future_step": self.future_step,
            "n_future": self.n_future,
            "hidden": list(self.hidden),
        }


def type_groups(types: Sequence[RoadUserType | str]) -> np.ndarray:
    """Group index (``TYPE_GROUPS``) of each type, shape (n,).

    Raises:
        ValueError: a type the model has no data for (names it and lists the known ones).
    """
    out = np.empty(len(types), dtype=np.int64)
    for k, kind in enumerate(types):
        group = GROUP_OF_TYPE.get(RoadUserType.parse(kind))
        if group is None:
            known = ", ".join(t.value for t in GROUP_OF_TYPE)
            raise ValueError(
                f"the learned predictor has no model for road-user type {kind!r}; known: {known}"
            )
        out[k] = group
    return out


def pad_history(
    positions: np.ndarray, headings: np.ndarray, speeds: np.ndarray, n_available: np.ndarray, step: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fill history slots older than the available samples at constant velocity.

    Args:
        positions: [m], shape (n, h, 2), oldest first, the last ``n_available``
            slots valid (the rest is overwritten).
        headings: [rad], shape (n, h). speeds: [m/s], shape (n, h).
        n_available: valid samples per road user, shape (n,), 1 <= n_available <= h.
        step: [s] between slots.

    Returns:
        New (positions, headings, speeds); arguments are not changed.
    """
    n, h = headings.shape
    n_available = np.asarray(n_available)
    if n == 0:
        return positions.copy(), headings.copy(), speeds.copy()
    if n_available.min() < 1 or n_available.max() > h:
        raise ValueError(f"history: between 1 and {h} samples must be available per road user")
    oldest = h - n_available  # index of the oldest valid slot, shape (n,)
    rows = np.arange(n)
    p0 = positions[rows, oldest]  # (n, 2)
    yaw0, v0 = headings[rows, oldest], speeds[rows, oldest]
    slots = np.arange(h)[None, :]
    missing = slots < oldest[:, None]  # (n, h)
    back = (oldest[:, None] - slots) * step  # seconds before the oldest valid sample
    direction = np.stack([np.cos(yaw0), np.sin(yaw0)], axis=-1)  # (n, 2)
    filled = p0[:, None, :] - (v0[:, None] * back)[..., None] * direction[:, None, :]
    positions = np.where(missing[..., None], filled, positions)
    headings = np.where(missing, yaw0[:, None], headings)
    speeds = np.where(missing, v0[:, None], speeds)
    return positions, headings, speeds


def encode(
    groups: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
    positions: np.ndarray,
    headings: np.ndarray,
    speeds: np.ndarray,
    n_available: np.ndarray,
    spec: ModelSpec,
) -> np.ndarray:
    """Input vectors of the network (one implementation for training and inference).

    Args:
        groups: type-group index, shape (n,).
        length, width: footprint [m], shape (n,).
        positions: history centres [m] in the world frame, shape (n, n_history, 2),
            oldest first, already padded (``pad_history``); the last is the current one.
        headings: [rad], shape (n, n_history). speeds: [m/s], shape (n, n_history).
        n_available: samples that are real, shape (n,).
        spec: the model's window.

    Returns:
        float32 features, shape (n, spec.n_features).

    Raises:
        ValueError: wrong shapes (naming the argument and the expected shape) or
            non-finite values.
    """
    n, h = len(groups), spec.n_history
    expected = {
        "length": (n,),
        "width": (n,),
        "positions": (n, h, 2),
        "headings": (n, h),
        "speeds": (n, h),
        "n_available": (n,),
    }
    arrays = {"length": length, "width": width, "positions": positions, "headings": headings}
    arrays |= {"speeds": speeds, "n_available": n_available}
    for name, shape in expected.items():
        value = np.asarray(arrays[name], dtype=float)
        if value.shape != shape:
            raise ValueError(
                f"history {name} must have shape {shape} ({h} samples every {spec.history_step:g} s), "
                f"got {value.shape}"
            )
        if not np.all(np.isfinite(value)):
            raise ValueError(f"history {name} must be finite (found NaN or inf)")
    yaw0 = headings[:, -1]
    c, s = np.cos(yaw0)[:, None], np.sin(yaw0)[:, None]
    rel = positions - positions[:, -1:, :]
    local_x = c * rel[..., 0] + s * rel[..., 1]
    local_y = -s * rel[..., 0] + c * rel[..., 1]
    dyaw = headings - yaw0[:, None]
    onehot = np.zeros((n, len(TYPE_GROUPS)))
    onehot[np.arange(n), groups] = 1.0
    parts = [
        local_x / _POSITION_SCALE,
        local_y / _POSITION_SCALE,
        np.sin(dyaw),
        np.cos(dyaw),
        speeds / _SPEED_SCALE,
        # Speed of the last interval from positions (robust where headings are noisy).
        np.hypot(*np.diff(positions, axis=1, prepend=positions[:, :1]).transpose(2, 0, 1))
        / spec.history_step
        / _SPEED_SCALE,
        (np.asarray(n_available, dtype=float)[:, None] - 1) / (h - 1),
        onehot,
        np.asarray(length, dtype=float)[:, None] / 5.0,
        np.asarray(width, dtype=float)[:, None] / 2.0,
    ]
    return np.concatenate(parts, axis=1).astype(np.float32)


def build_network(spec: ModelSpec):  # noqa: ANN201 - torch is imported lazily
    """The torch network: an MLP from features to 5 numbers per future step."""
    import torch

    layers: list[Any] = []
    width = spec.n_features
    for hidden in spec.hidden:
        layers += [torch.nn.Linear(width, hidden), torch.nn.SiLU()]
        width = hidden
    layers.append(torch.nn.Linear(width, 5 * spec.n_future))
    return torch.nn.Sequential(*layers)


def gaussian_params(output, current_speed, spec: ModelSpec):  # noqa: ANN001, ANN201 - torch tensors
    """Network output -> local-frame mean and Cholesky factor per step (torch).

    Args:
        output: network output, shape (n, 5 n_future).
        current_speed: [m/s], shape (n,).
        spec: the model's window.

    Returns:
        (mean [m] shape (n, n_future, 2) in the road user's frame, lower Cholesky
        factor [m] shape (n, n_future, 2, 2)).
    """
    import torch

    n = output.shape[0]
    out = output.reshape(n, spec.n_future, 5)
    t = torch.as_tensor(spec.future_times, dtype=output.dtype)
    base_x = current_speed[:, None] * t[None, :]
    mean = torch.stack([base_x + out[..., 0] * (1.0 + t), out[..., 1] * (1.0 + t)], dim=-1)
    base_log_sigma = torch.log(0.2 + 0.5 * t)[None, :]
    sx = torch.exp(torch.clamp(out[..., 2] + base_log_sigma, -7.0, 5.0))
    sy = torch.exp(torch.clamp(out[..., 3] + base_log_sigma, -7.0, 5.0))
    zero = torch.zeros_like(sx)
    chol = torch.stack([torch.stack([sx, zero], -1), torch.stack([out[..., 4] * sy, sy], -1)], -2)
    return mean, chol


def gaussian_nll(mean, chol, target):  # noqa: ANN001, ANN201 - torch tensors
    """Negative log-likelihood [nats] of 2-D targets under N(mean, L L^T), shape (n, n_future).

    With L = [[a, 0], [c, b]]: z1 = d1 / a, z2 = (d2 - c z1) / b, NLL = |z|^2 / 2 + log(a b) + log(2 pi).
    """
    import torch

    diff = target - mean
    a, c, b = chol[..., 0, 0], chol[..., 1, 0], chol[..., 1, 1]
    z1 = diff[..., 0] / a
    z2 = (diff[..., 1] - c * z1) / b
    return 0.5 * (z1 * z1 + z2 * z2) + torch.log(a) + torch.log(b) + _LOG_2PI


class LearnedModel:
    """A trained network with its window, calibration and provenance.

    Args:
        spec: the window and network shape.
        state: the network's parameters (``state_dict``).
        calibration: the Gaussian scale mixture per type group, motion state
            (``MOTION_STATES``) and step, shape (len(TYPE_GROUPS), 2, n_future, K, 2):
            [..., k, 0] the weight w_k (>= 0, summing to 1 over k), [..., k, 1] the
            variance factor v_k > 0 of component k (covariance v_k Sigma). None: one
            component with w = v = 1 (the network's own Gaussian).
        meta: provenance (data, split, seed, metrics); plain values.
    """

    def __init__(
        self,
        spec: ModelSpec,
        state: dict | None = None,
        calibration: np.ndarray | None = None,
        meta: dict | None = None,
    ) -> None:
        import torch

        self.spec = spec
        self.network = build_network(spec)
        if state is not None:
            try:
                self.network.load_state_dict(state)
            except (RuntimeError, KeyError) as error:
                raise ValueError(f"weights do not fit the model {spec}: {error}") from None
        self.network.eval()
        self.calibration = check_calibration(
            np.ones((len(TYPE_GROUPS), len(MOTION_STATES), spec.n_future, 1, 2))
            if calibration is None
            else calibration,
            spec,
        )
        self.meta = dict(meta or {})
        self._torch = torch

    @property
    def n_components(self) -> int:
        """Components K of the calibrated mixture."""
        return int(self.calibration.shape[3])

    # ------------------------------------------------------------------ files

    def save(self, path: str | Path) -> None:
        """Write the model as a weights file loadable with ``weights_only=True``."""
        torch = self._torch
        payload = {
            "format": FORMAT,
            "version": FORMAT_VERSION,
            "spec": self.spec.to_dict(),
            "state": {k: v.detach().clone() for k, v in self.network.state_dict().items()},
            "calibration": torch.as_tensor(self.calibration, dtype=torch.float64),
            "meta": self.meta,
        }
        torch.save(payload, str(path))

    @classmethod
    def load(cls, path: str | Path | None = None) -> LearnedModel:
        """Load a weights file (``torch.load(..., weights_only=True)``); None loads the shipped one.

        A version-1 file (one covariance factor per step) gives its network with no
        calibration (one Gaussian); ``etp predictor calibrate`` refits it as a mixture.

        Raises:
            ValueError: the file is missing, corrupted, or not a weights file of this model.
        """
        import torch

        if path is None:
            ref = importlib.resources.files("ethical_planner") / "data" / SHIPPED_WEIGHTS
            with importlib.resources.as_file(ref) as shipped:
                return cls.load(shipped)
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"learned predictor weights {path}: no such file")
        try:
            payload = torch.load(str(path), map_location="cpu", weights_only=True)
        except Exception as error:  # noqa: BLE001 - torch raises many kinds for a bad file
            raise ValueError(
                f"learned predictor weights {path}: not a readable weights file "
                f"({type(error).__name__}: {error})"
            ) from None
        if not isinstance(payload, dict) or payload.get("format") != FORMAT:
            raise ValueError(f"learned predictor weights {path}: not a {FORMAT} file")
        version = payload.get("version")
        if version not in (1, FORMAT_VERSION):
            raise ValueError(
                f"learned predictor weights {path}: format version {version!r}, "
                f"this code reads 1 and {FORMAT_VERSION}"
            )
        try:
            spec = ModelSpec(**payload["spec"])
            # Version 1 held one covariance factor per step (off by default): its network
            # is read with the network's own Gaussian; `etp predictor calibrate` fits a mixture.
            calibration = payload["calibration"].numpy() if version == FORMAT_VERSION else None
            return cls(spec, payload["state"], calibration, payload.get("meta", {}))
        except (KeyError, TypeError, AttributeError, ValueError) as error:
            raise ValueError(f"learned predictor weights {path}: {error}") from None

    # ------------------------------------------------------------------ inference

    def predict_local(
        self, features: np.ndarray, groups: np.ndarray, current_speed: np.ndarray, calibrated: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The mixture of each road user in its own frame.

        Args:
            features: ``encode`` output, shape (n, n_features).
            groups: type-group index, shape (n,).
            current_speed: [m/s], shape (n,); selects the motion state.
            calibrated: False gives the network's own Gaussian (K = 1, v = 1).

        Returns:
            (mean [m] (n, n_future, 2), weights (n, n_future, K), component covariances
            [m^2] (n, n_future, K, 2, 2)).
        """
        torch = self._torch
        with torch.inference_mode():
            output = self.network(torch.as_tensor(features, dtype=torch.float32))
            mean, chol = gaussian_params(
                output, torch.as_tensor(current_speed, dtype=torch.float32), self.spec
            )
            cov = chol @ chol.transpose(-1, -2)
        mean = mean.double().numpy()
        cov = floor_eigenvalues(cov.double().numpy(), RESOLUTION_FLOOR)
        # Uncertainty never shrinks along the horizon: the size s^2 = trace / 2 is raised
        # to its running maximum (the network's steps need not be monotone).
        s2 = 0.5 * (cov[..., 0, 0] + cov[..., 1, 1])
        s2_max = np.maximum.accumulate(s2, axis=1)
        cov = cov * (s2_max / s2)[..., None, None]
        s2 = s2_max
        if not calibrated:
            return mean, np.ones(mean.shape[:2] + (1,)), cov[:, :, None]
        params = self.calibration[groups, motion_state(current_speed)]  # (n, n_future, K, 2)
        weight, components = params[..., 0].copy(), params[..., 1, None, None] * cov[:, :, None]
        # Nor does the mixture's: its size sum_k w_k v_k s^2 is raised to its running maximum
        # by scaling every component of the step alike (weights per step need not be monotone).
        total = np.einsum("nfk,nfk->nf", weight, params[..., 1]) * s2
        components *= (np.maximum.accumulate(total, axis=1) / total)[..., None, None, None]
        return mean, weight, components


def motion_state(speed: np.ndarray) -> np.ndarray:
    """Index into ``MOTION_STATES`` of each speed [m/s], shape (n,): 1 from ``MOVING_SPEED`` on."""
    return (np.abs(np.asarray(speed, dtype=float)) >= MOVING_SPEED).astype(np.int64)


def check_calibration(calibration: np.ndarray, spec: ModelSpec) -> np.ndarray:
    """The mixture parameters as float64, checked (see ``LearnedModel``).

    Raises:
        ValueError: wrong shape, non-finite values, negative weights or weights not
            summing to 1, or variance factors <= 0.
    """
    calibration = np.asarray(calibration, dtype=float)
    shape = (len(TYPE_GROUPS), len(MOTION_STATES), spec.n_future)
    if calibration.ndim != 5 or calibration.shape[:3] != shape or calibration.shape[4] != 2:
        raise ValueError(
            f"calibration must have shape {shape + ('K', 2)} (weight, variance factor per component), "
            f"got {calibration.shape}"
        )
    weights, factors = calibration[..., 0], calibration[..., 1]
    if not np.all(np.isfinite(calibration)):
        raise ValueError("calibration must be finite")
    if np.any(weights < 0) or not np.allclose(weights.sum(-1), 1.0, atol=1e-9):
        raise ValueError("calibration weights must be >= 0 and sum to 1 over the components")
    if np.any(factors <= 0):
        raise ValueError("calibration variance factors must be > 0")
    return calibration


def history_windows(
    road_users: Sequence[RoadUser], spec: ModelSpec
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each road user's history on the model's grid, padded where too short.

    The current state is the sample at t = 0; history samples (any fixed step) are
    interpolated linearly at the model's times (headings unwrapped first).

    Returns:
        (positions [m] (n, n_history, 2), headings [rad] (n, n_history), speeds [m/s]
        (n, n_history), n_available (n,)).
    """
    n, h = len(road_users), spec.n_history
    grid = spec.history_times
    positions = np.zeros((n, h, 2))
    headings = np.zeros((n, h))
    speeds = np.zeros((n, h))
    available = np.ones(n, dtype=np.int64)
    now = np.array([[u.state.x, u.state.y, u.state.yaw, u.state.v] for u in road_users]).reshape(n, 4)
    # Road users whose histories share sample times are interpolated together.
    groups: dict[tuple, list[int]] = {}
    for k, user in enumerate(road_users):
        key = () if user.history is None else tuple(np.round(user.history.times, 9))
        groups.setdefault(key, []).append(k)
    for key, members in groups.items():
        idx = np.array(members)
        hist_times = np.array(key, dtype=float)
        keep = hist_times < -1e-6
        times = np.concatenate([hist_times[keep], [0.0]])
        m = len(times)
        samples = np.empty((len(idx), m, 4))
        samples[:, -1] = now[idx]
        if m > 1:
            hist = [road_users[k].history for k in members]
            samples[:, :-1, 0:2] = np.stack([hh.positions[keep] for hh in hist])
            samples[:, :-1, 2] = np.stack([hh.headings[keep] for hh in hist])
            samples[:, :-1, 3] = np.stack([hh.speeds[keep] for hh in hist])
        # Unwrap towards the current heading so that interpolation never jumps by 2 pi.
        yaw = samples[..., 2]
        yaw = np.unwrap(yaw[:, ::-1], axis=1)[:, ::-1]
        samples[..., 2] = yaw
        valid = grid >= times[0] - 1e-9
        weights = _interpolation_matrix(times, grid[valid])  # (n_valid, m)
        values = np.einsum("gm,kmc->kgc", weights, samples)
        slot = np.flatnonzero(valid)
        positions[idx[:, None], slot[None, :]] = values[..., 0:2]
        headings[idx[:, None], slot[None, :]] = values[..., 2]
        speeds[idx[:, None], slot[None, :]] = values[..., 3]
        available[idx] = len(slot)
    positions, headings, speeds = pad_history(positions, headings, speeds, available, spec.history_step)
    return positions, headings, speeds, available


def _interpolation_matrix(times: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Weights W (len(at), len(times)) with W @ values = linear interpolation of values at ``at``."""
    m = len(times)
    weights = np.zeros((len(at), m))
    if m == 1:
        weights[:, 0] = 1.0
        return weights
    j = np.clip(np.searchsorted(times, at, side="right") - 1, 0, m - 2)
    frac = np.clip((at - times[j]) / (times[j + 1] - times[j]), 0.0, 1.0)
    rows = np.arange(len(at))
    weights[rows, j] = 1.0 - frac
    weights[rows, j + 1] += frac
    return weights


def to_world(
    mean_local: np.ndarray, cov_local: np.ndarray, origin: np.ndarray, heading: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Rotate local-frame means (n, k, 2) and covariances (n, k, ..., 2, 2) into the world frame."""
    c, s = np.cos(heading), np.sin(heading)
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # (n, 2, 2)
    mean = np.einsum("nij,nkj->nki", rot, mean_local) + origin[:, None, :]
    cov = np.einsum("nij,nk...jl,nml->nk...im", rot, cov_local, rot)
    return mean, cov


def _on_times(
    mean: np.ndarray,
    weight: np.ndarray,
    cov: np.ndarray,
    origin: np.ndarray,
    cov0: np.ndarray,
    spec: ModelSpec,
    times: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Model steps -> the caller's times: linear in between, t=0 observed, t^2 growth beyond.

    Args:
        mean: [m] (n, n_future, 2). weight: (n, n_future, K). cov: [m^2] (n, n_future, K, 2, 2).
        origin: [m] (n, 2). cov0: observation covariance [m^2] (n, 2, 2) (every component at t = 0).

    Returns:
        (mean (n, n_t, 2), weights (n, n_t, K), covariances (n, n_t, K, 2, 2)).
    """
    k = weight.shape[-1]
    knots = np.concatenate([[0.0], spec.future_times])
    mean_k = np.concatenate([origin[:, None, :], mean], axis=1)  # (n, K_t, 2)
    weight_k = np.concatenate([weight[:, :1], weight], axis=1)
    cov_k = np.concatenate([np.repeat(cov0[:, None, None], k, axis=2), cov], axis=1)
    last = knots[-1]
    inside = np.minimum(times, last)
    matrix = _interpolation_matrix(knots, inside)  # (n_t, K_t)
    out_mean = np.einsum("tk,nkc->ntc", matrix, mean_k)
    out_weight = np.einsum("tk,nkc->ntc", matrix, weight_k)
    out_cov = np.einsum("tk,nkcij->ntcij", matrix, cov_k)
    beyond = times > last
    if beyond.any():
        velocity = (mean_k[:, -1] - mean_k[:, -2]) / (knots[-1] - knots[-2])  # (n, 2)
        extra = times[beyond] - last
        out_mean[:, beyond] = mean_k[:, -1][:, None, :] + velocity[:, None, :] * extra[None, :, None]
        growth = (times[beyond] / last) ** 2
        out_cov[:, beyond] = cov_k[:, -1][:, None] * growth[None, :, None, None, None]
    return out_mean, out_weight / out_weight.sum(-1, keepdims=True), out_cov


class LearnedPredictor:
    """``Predictor`` backed by a ``LearnedModel`` (registered as ``"learned"``).

    Args:
        config: ``learned_weights`` (a path, or empty for the shipped weights),
            ``torch_threads``, ``sigma0_long`` / ``sigma0_lat`` (uncertainty of the
            observed state at t = 0) and the covariance floor.
        model: an already loaded model (tests, training); overrides the file.
    """

    name = "learned"

    def __init__(self, config: PredictionConfig, model: LearnedModel | None = None) -> None:
        import torch

        torch.set_num_threads(max(1, int(config.torch_threads)))
        self.config = config
        self.model = model or LearnedModel.load(config.learned_weights or None)

    def predict(self, road_users: Sequence[RoadUser], times: np.ndarray) -> Prediction:
        """Predict every road user at ``times`` [s] from now, shape (n_t,), times[0] = 0.

        Raises:
            ValueError: a road-user type the model does not know; non-finite input.
        """
        times = np.asarray(times, dtype=float)
        n_obs, n_t = len(road_users), len(times)
        if times.ndim != 1 or n_t == 0 or not np.all(np.isfinite(times)) or times.min() < 0:
            raise ValueError("times must be a non-empty 1-D array of finite seconds >= 0")
        if n_obs == 0:
            return empty_prediction(n_t)
        ids = check_unique_ids(road_users)
        spec, config = self.model.spec, self.config
        groups = type_groups([u.type for u in road_users])
        length = np.array([u.shape.length for u in road_users])
        width = np.array([u.shape.width for u in road_users])
        positions, headings, speeds, available = history_windows(road_users, spec)
        features = encode(groups, length, width, positions, headings, speeds, available, spec)
        mean_l, weight, cov_l = self.model.predict_local(
            features, groups, speeds[:, -1], config.learned_recalibration
        )
        origin, yaw0 = positions[:, -1], headings[:, -1]
        mean, cov = to_world(mean_l, cov_l, origin, yaw0)
        cov0 = rotated_covariance(np.float64(config.sigma0_long), np.float64(config.sigma0_lat), yaw0)
        mean_t, weight_t, comp_t = _on_times(mean, weight, cov, origin, cov0, spec, times)
        step = np.diff(mean_t, axis=1, prepend=mean_t[:, :1])
        step[:, 0] = step[:, 1] if n_t > 1 else 0.0
        moving = np.hypot(step[..., 0], step[..., 1]) > 1e-3
        heading = np.where(moving, np.arctan2(step[..., 1], step[..., 0]), yaw0[:, None])
        dt = np.diff(times, prepend=times[0])
        dt[0] = dt[1] if n_t > 1 else 1.0
        speed = np.hypot(step[..., 0], step[..., 1]) / np.maximum(dt, 1e-9)[None, :]
        speed[:, 0] = np.abs(speeds[:, -1])
        comp_t = 0.5 * (comp_t + np.swapaxes(comp_t, -1, -2))
        mixture = weight_t.shape[-1] > 1
        prediction = Prediction(
            ids=ids,
            types=tuple(u.type for u in road_users),
            mean=mean_t,
            cov=np.einsum("ntk,ntkij->ntij", weight_t, comp_t),
            heading=heading,
            speed=speed,
            length=length,
            width=width,
            mass=np.array([u.mass for u in road_users]),
            component_weight=weight_t if mixture else None,
            component_cov=comp_t if mixture else None,
        )
        return prediction.with_covariance_floor(config.covariance_floor)


PREDICTORS.register("learned", LearnedPredictor)
