"""Run index: one JSON line per run, and the search for near crashes among them.

Every run appends one ``IndexRow`` to ``<out_root>/index.jsonl`` (append, flush and
fsync per row, so an interrupted batch keeps every finished run; ``read_index``
skips a truncated or corrupt line).

Safety metrics of a row:

* ``min_distance``: the runner's smallest ego-to-road-user geom distance [m]
  (``RunSummary.min_distance``, MuJoCo ``mj_geomDistance`` every
  ``RunConfig.distance_interval`` steps until the ego's first contact).
* ``min_ttc``: smallest time-to-collision [s] from the true states, computed by
  ``SafetyMetrics`` (a ``RunObserver``) every ``step_interval`` physics steps until the
  ego's first contact: each body keeps its current velocity and heading (constant
  velocity), footprints are oriented rectangles (pedestrians: squares of their
  diameter), and the TTC is the first time in [0, ``horizon``] at which the ego's
  rectangle and a road user's overlap, solved exactly with the separating-axis test
  (four axes, each gives an interval of times; their intersection is the overlap).
  No approach within the horizon gives inf (written as the string "inf").
* ``max_collision_probability``: the highest ``collision_probability`` of any road
  user along the chosen plans (``Decision.road_users``), from ``SafetyMetrics``.
* ``max_risk``: the runner's highest risk per group (ego, third_party, vulnerable).

Near crash: a collision, or ``min_distance < thresholds.min_distance``, or
``min_ttc < thresholds.min_ttc``, or ``max_collision_probability >=
thresholds.collision_probability``. Severity score (higher is worse):

* with a collision: ``1 + max harm`` over all bodies of all collisions, measured or
  predicted (so in [1, 2]: every collision ranks above every near miss);
* otherwise ``max(s_d, s_ttc, s_p)`` in [0, 1): ``s_d = 1 - min_distance /
  thresholds.min_distance``, ``s_ttc = 1 - min_ttc / thresholds.min_ttc``,
  ``s_p = (p - p_thr) / (1 - p_thr)``, each clipped to [0, 0.999].
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ethical_planner.planner import Decision
from ethical_planner.validation import check, check_positive
from mujoco_world.loop.runner import GROUPS, RunObserver, RunSummary
from mujoco_world.loop.world import World
from mujoco_world.scenario.spec import Scenario

#: File name of the index inside an output root.
INDEX_FILE = "index.jsonl"


@dataclass(frozen=True, slots=True)
class NearCrashThresholds:
    """When a run counts as a near crash (any one suffices; a collision always does).

    Attributes:
        min_distance: ego-to-road-user distance below which [m].
        min_ttc: time-to-collision below which [s].
        collision_probability: highest planned collision probability at or above which, in (0, 1].
    """

    min_distance: float = 0.5
    min_ttc: float = 1.0
    collision_probability: float = 0.1

    def __post_init__(self) -> None:
        check_positive(
            "thresholds",
            min_distance=self.min_distance,
            min_ttc=self.min_ttc,
            collision_probability=self.collision_probability,
        )
        check(
            self.collision_probability <= 1.0,
            f"thresholds.collision_probability must lie in (0, 1], got {self.collision_probability}",
        )


@dataclass(frozen=True, slots=True)
class IndexRow:
    """One run in the index.

    Attributes:
        run_id: unique id (the run folder's name). scenario, planner, seed: what ran.
        outcome: goal, timeout, crash or failed.
        collisions: number of measured collisions.
        max_harm_measured, max_harm_predicted: highest harm of any body in any collision
            (0 without collisions).
        min_distance: [m] (nan if there was no road user).
        min_ttc: [s] (inf if no approach within the horizon, nan if unknown).
        max_collision_probability: highest planned collision probability (nan if unknown).
        max_risk: highest risk per group (ego, third_party, vulnerable).
        near_crash: True if the run passes a threshold (see the module docstring).
        severity: ranking score (module docstring).
        recording: path of the ``.rrd`` file, or None if none was kept.
        duration: simulated time [s].
    """

    run_id: str
    scenario: str
    planner: str
    seed: int
    outcome: str
    collisions: int
    max_harm_measured: float
    max_harm_predicted: float
    min_distance: float
    min_ttc: float
    max_collision_probability: float
    max_risk: dict[str, float] = field(default_factory=dict)
    near_crash: bool = False
    severity: float = 0.0
    recording: str | None = None
    duration: float = 0.0

    def to_json(self) -> str:
        """One JSON line (non-finite floats as strings "inf"/"nan" so they survive JSON)."""
        return json.dumps({k: _encode(v) for k, v in asdict(self).items()}, sort_keys=True)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> IndexRow:
        """Row from a decoded JSON line; unknown keys are ignored (newer writers).

        Raises:
            ValueError: not a JSON object, a missing field, or a field of the wrong kind
                (the message names the field).
        """
        if not isinstance(data, dict):
            raise ValueError(f"not a JSON object, got {type(data).__name__}")
        names = set(cls.__slots__)
        values = {k: _decode(v) for k, v in data.items() if k in names}
        missing = [f.name for f in dataclasses.fields(cls) if f.name not in values and _required(f)]
        if missing:
            raise ValueError(f"missing {', '.join(missing)}")
        for name, value in values.items():
            kinds = _FIELD_KINDS.get(name)
            if kinds is None:
                continue
            is_bool = isinstance(value, bool)  # a bool is an int to isinstance; here it is not
            if (is_bool and bool not in kinds) or (
                not is_bool and (bool in kinds or not isinstance(value, kinds))
            ):
                what = {str: "a string", int: "an integer", float: "a number", bool: "true or false"}
                what |= {dict: "a table", type(None): "null"}
                wanted = " or ".join(what[k] for k in kinds if not (k is int and float in kinds))
                raise ValueError(f"{name} must be {wanted}, got {value!r}")
        return cls(**values)


def _required(f: dataclasses.Field) -> bool:
    return f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING


#: Allowed JSON kinds of each index field (after "inf"/"nan" strings became floats).
_FIELD_KINDS: dict[str, tuple[type, ...]] = {
    "run_id": (str,),
    "scenario": (str,),
    "planner": (str,),
    "seed": (int,),
    "outcome": (str,),
    "collisions": (int,),
    "max_harm_measured": (int, float),
    "max_harm_predicted": (int, float),
    "min_distance": (int, float),
    "min_ttc": (int, float),
    "max_collision_probability": (int, float),
    "max_risk": (dict,),
    "near_crash": (bool,),
    "severity": (int, float),
    "recording": (str, type(None)),
    "duration": (int, float),
}


def _encode(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {k: _encode(v) for k, v in value.items()}
    return value


def _decode(value: Any) -> Any:
    if isinstance(value, str) and value in ("inf", "-inf", "nan"):
        return float(value)
    if isinstance(value, dict):
        return {k: _decode(v) for k, v in value.items()}
    return value


def time_to_collision(
    ego: np.ndarray,
    others: np.ndarray,
    horizon: float = 10.0,
) -> np.ndarray:
    """Constant-velocity time to first overlap of oriented rectangles (separating axes).

    Args:
        ego: (x [m], y [m], yaw [rad], vx [m/s], vy [m/s], length [m], width [m]), shape (7,).
        others: the same per road user, shape (k, 7).
        horizon: longest time looked ahead [s].

    Returns:
        (k,) first time of overlap in [0, horizon] [s]; 0 if overlapping now; inf if none.
    """
    others = np.atleast_2d(np.asarray(others, dtype=float))
    ego = np.asarray(ego, dtype=float)
    k = len(others)
    if k == 0:
        return np.zeros(0)
    d0 = others[:, :2] - ego[:2]  # (k, 2)
    dv = others[:, 3:5] - ego[3:5]

    def frame(yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u = np.stack([np.cos(yaw), np.sin(yaw)], axis=-1)
        return u, np.stack([-u[..., 1], u[..., 0]], axis=-1)

    ue, ne = frame(np.full(k, ego[2]))
    uk, nk = frame(others[:, 2])
    lo = np.zeros(k)
    hi = np.full(k, float(horizon))
    for axis in (ue, ne, uk, nk):
        reach = (
            0.5 * ego[5] * np.abs((ue * axis).sum(1))
            + 0.5 * ego[6] * np.abs((ne * axis).sum(1))
            + 0.5 * others[:, 5] * np.abs((uk * axis).sum(1))
            + 0.5 * others[:, 6] * np.abs((nk * axis).sum(1))
        )
        p = (d0 * axis).sum(1)
        q = (dv * axis).sum(1)
        moving = np.abs(q) > 1e-12
        safe_q = np.where(moving, q, 1.0)
        t1 = (-reach - p) / safe_q
        t2 = (reach - p) / safe_q
        inside = np.abs(p) <= reach
        a_lo = np.where(moving, np.minimum(t1, t2), np.where(inside, -np.inf, np.inf))
        a_hi = np.where(moving, np.maximum(t1, t2), np.where(inside, np.inf, -np.inf))
        lo = np.maximum(lo, a_lo)
        hi = np.minimum(hi, a_hi)
    return np.where(lo <= hi, lo, np.inf)


class SafetyMetrics(RunObserver):
    """Collects the minimum TTC and the highest planned collision probability of a run.

    Args:
        horizon: TTC look-ahead [s].
        rate: TTC evaluations per simulated second [Hz].

    Attributes:
        min_ttc: smallest TTC so far [s] (inf if none).
        max_collision_probability: highest planned collision probability so far.
    """

    def __init__(self, horizon: float = 10.0, rate: float = 20.0) -> None:
        check_positive("SafetyMetrics", horizon=horizon, rate=rate)
        self.horizon = float(horizon)
        self.rate = float(rate)
        self.step_interval = 50
        self.min_ttc = math.inf
        self.max_collision_probability = 0.0
        self._extent: np.ndarray | None = None

    def on_start(self, world: World, scenario: Scenario, planner: str, seed: int) -> None:
        """Look up the footprints once."""
        self.step_interval = max(int(round(1.0 / (self.rate * world.scene.dt))), 1)
        bodies = world.scene.bodies
        length = np.array([2 * b.radius if b.is_round else b.length for b in bodies])
        width = np.array([2 * b.radius if b.is_round else b.width for b in bodies])
        self._extent = np.column_stack([length, width])
        self.on_step(world, world.time)

    def on_step(self, world: World, time: float) -> None:
        """Update the minimum TTC from the true states (until the ego's first contact)."""
        if self._extent is None or world.n < 2 or world.crashed[0]:
            return
        qpos, qvel = world.scene.qpos, world.scene.qvel
        states = np.column_stack([qpos[:, :2], qpos[:, 2], qvel[:, :2], self._extent])
        ttc = time_to_collision(states[0], states[1:], self.horizon)
        self.min_ttc = min(self.min_ttc, float(ttc.min()))

    def on_cycle(self, decision: Decision, time: float) -> None:
        """Track the highest planned collision probability."""
        for u in decision.road_users:
            if u.collision_probability > self.max_collision_probability:
                self.max_collision_probability = float(u.collision_probability)


def severity(
    row_collisions: int,
    max_harm: float,
    min_distance: float,
    min_ttc: float,
    max_collision_probability: float,
    thresholds: NearCrashThresholds,
) -> tuple[bool, float]:
    """Near-crash flag and severity score of a run (see the module docstring).

    Args:
        row_collisions: number of collisions.
        max_harm: highest harm (measured or predicted) of any collision, in [0, 1].
        min_distance: smallest ego distance [m].
        min_ttc: smallest time-to-collision [s].
        max_collision_probability: highest planned collision probability in [0, 1]
            (nan values count as "not past the threshold").
        thresholds: what counts as a near crash.

    Returns:
        (near_crash, score).
    """
    if row_collisions > 0:
        return True, 1.0 + (max_harm if math.isfinite(max_harm) else 0.0)

    def clip(x: float) -> float:
        return min(max(x, 0.0), 0.999) if math.isfinite(x) else 0.0

    p_thr = thresholds.collision_probability
    s_d = clip(1.0 - min_distance / thresholds.min_distance) if math.isfinite(min_distance) else 0.0
    s_t = clip(1.0 - min_ttc / thresholds.min_ttc) if math.isfinite(min_ttc) else 0.0
    p = max_collision_probability
    s_p = clip((p - p_thr) / (1.0 - p_thr)) if p_thr < 1.0 and math.isfinite(p) else 0.0
    near = (
        (math.isfinite(min_distance) and min_distance < thresholds.min_distance)
        or (math.isfinite(min_ttc) and min_ttc < thresholds.min_ttc)
        or (math.isfinite(p) and p >= p_thr)
    )
    return bool(near), max(s_d, s_t, s_p)


def make_row(
    summary: RunSummary,
    run_id: str,
    recording_path: str | Path | None = None,
    metrics: SafetyMetrics | None = None,
    thresholds: NearCrashThresholds | None = None,
) -> IndexRow:
    """Index row of a finished run.

    Args:
        summary: the runner's summary.
        run_id: unique id of the run.
        recording_path: its ``.rrd`` file, if kept.
        metrics: TTC and collision probability collected during the run; without it
            those fields are nan (unknown) and do not make a near crash.
        thresholds: near-crash thresholds.
    """
    thresholds = thresholds or NearCrashThresholds()

    def max_of(values: Iterable[float]) -> float:
        finite = [v for v in values if math.isfinite(v)]
        return max(finite) if finite else 0.0

    harm_m = max_of(b.harm_measured for c in summary.collisions for b in (c.a, c.b))
    harm_p = max_of(b.harm_predicted for c in summary.collisions for b in (c.a, c.b))
    min_ttc = metrics.min_ttc if metrics is not None else math.nan
    p_max = metrics.max_collision_probability if metrics is not None else math.nan
    near, score = severity(
        len(summary.collisions), max(harm_m, harm_p), summary.min_distance, min_ttc, p_max, thresholds
    )
    return IndexRow(
        run_id=run_id,
        scenario=summary.scenario,
        planner=summary.planner,
        seed=int(summary.seed),
        outcome=summary.outcome,
        collisions=len(summary.collisions),
        max_harm_measured=harm_m,
        max_harm_predicted=harm_p,
        min_distance=float(summary.min_distance),
        min_ttc=float(min_ttc),
        max_collision_probability=float(p_max),
        max_risk={g: float(summary.max_risk.get(g, 0.0)) for g in GROUPS},
        near_crash=near,
        severity=float(score),
        recording=None if recording_path is None else str(recording_path),
        duration=float(summary.duration),
    )


def append_row(out_root: str | Path, row: IndexRow) -> Path:
    """Append ``row`` to ``out_root/index.jsonl`` (flushed and fsynced); return the file."""
    root = Path(out_root)
    root.mkdir(parents=True, exist_ok=True)
    path = root / INDEX_FILE
    with path.open("ab") as handle:
        # A previous writer killed mid-line leaves no newline: start on a fresh line.
        if handle.tell() > 0:
            with path.open("rb") as check_handle:
                check_handle.seek(-1, os.SEEK_END)
                if check_handle.read(1) != b"\n":
                    handle.write(b"\n")
        handle.write(row.to_json().encode() + b"\n")
        handle.flush()
        os.fsync(handle.fileno())
    return path


def read_index(out_root: str | Path) -> list[IndexRow]:
    """The runs of ``out_root/index.jsonl`` (or of that file itself), one row per run id.

    A run indexed more than once (an interrupted attempt, then its rerun) appears once,
    with its latest row, at the place of its first. A line that is not JSON (a writer
    killed mid-line) is skipped.

    Raises:
        ValueError: the index file does not exist or cannot be read, or a JSON line is
            not an index row (the message names the file, the line and the field).
    """
    path = Path(out_root)
    if path.is_dir() and path.name != INDEX_FILE:
        path = path / INDEX_FILE
    if not path.is_file():
        raise ValueError(f"root: no run index at {path}")
    rows: dict[str, IndexRow] = {}
    try:
        handle = path.open("rb")
    except OSError as error:
        raise ValueError(f"{path}: cannot read: {error.strerror}") from None
    with handle:
        for number, line in enumerate(handle, start=1):
            line = line.strip()
            if not line:
                continue
            try:
                data = json.loads(line)
            except ValueError:
                continue  # a truncated line
            try:
                row = IndexRow.from_dict(data)
            except (ValueError, TypeError) as error:
                raise ValueError(f"{path} line {number}: {error}") from None
            rows[row.run_id] = row  # the latest row, in the place of the first
    return list(rows.values())


def near_crashes(rows: Iterable[IndexRow], top: int | None = None) -> list[IndexRow]:
    """Near-crash rows, worst first (severity, then more collisions, then smaller distance).

    Args:
        rows: index rows.
        top: keep at most this many (None: all).

    Raises:
        ValueError: ``top`` is negative.
    """
    if top is not None and top < 0:
        raise ValueError(f"top must be >= 0, got {top}")
    found = [r for r in rows if r.near_crash]

    def key(r: IndexRow) -> tuple[float, int, float]:
        distance = r.min_distance if math.isfinite(r.min_distance) else math.inf
        return (-r.severity, -r.collisions, distance)

    found.sort(key=key)
    return found if top is None else found[:top]


def find_run(out_root: str | Path, run_id: str) -> IndexRow:
    """The last row of ``run_id`` in the index.

    Raises:
        ValueError: no such run.
    """
    matches = [r for r in read_index(out_root) if r.run_id == run_id]
    if not matches:
        raise ValueError(f"run_id: no run {run_id!r} in {Path(out_root) / INDEX_FILE}")
    return matches[-1]
