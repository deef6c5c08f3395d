"""Run index: one JSON line per run, and the search for near crashes among them.

Every run appends one ``IndexRow`` to ``<out_root>/index.jsonl`` (append, flush and
fsync per row, so an interrupted batch keeps every finished run; ``read_index``
skips a truncated or corrupt line). When a batch ends it rewrites the file with one
row per run (``compact_index``: temporary file, then rename).

A row is made from the run's ``RunRecord`` (``make_row``), so the index can always be
rebuilt from the records. Its safety metrics are the run's (``mujoco_world.loop.
metrics``):

* ``min_distance``: smallest ego-to-road-user geom distance [m] (MuJoCo
  ``mj_geomDistance`` every ``RunConfig.distance_interval`` steps until the ego's
  first contact).
* ``min_ttc``: smallest time-to-collision [s] from the true states at 20 Hz until the
  ego's first contact: each body keeps its current velocity and heading, footprints
  are oriented rectangles (pedestrians: squares of their diameter), and the TTC is
  the first time in [0, 10 s] at which the ego's rectangle and a road user's overlap
  (``physics.safety.time_to_collision``). No approach within the horizon gives inf
  (written as the string "inf").
* ``max_collision_probability``: the highest ``collision_probability`` of any road
  user along the chosen plans (``Decision.road_users``).
* ``max_risk``: highest risk per group (ego, third_party, vulnerable).
* ``min_distance_vulnerable``: smallest ego distance to a vulnerable road user [m]
  (the smallest of the run's ``clearance_vulnerable``).

Collisions are counted apart: ``ego_collisions`` (the ego took part: a crash) and
``third_party_collisions`` (between other road users: measured, not the ego's crash).

Near crash: a collision (ego-involved or third-party), or ``min_distance <
thresholds.min_distance``, or ``min_distance_vulnerable <
thresholds.vulnerable_clearance`` (a pass at 0.06 m from a cyclist is a near crash,
not a clean goal), or ``min_ttc < thresholds.min_ttc``, or
``max_collision_probability >= thresholds.collision_probability``. Severity score
(higher is worse):

* with an ego-involved collision: ``2 + max harm`` over all bodies of the ego's
  collisions, measured or predicted (in [2, 3]: every crash ranks first);
* with third-party collisions only: ``1 + max harm`` over theirs (in [1, 2]);
* otherwise ``max(s_d, s_v, s_ttc, s_p)`` in [0, 1): ``s_d = 1 - min_distance /
  thresholds.min_distance``, ``s_v = 1 - min_distance_vulnerable /
  thresholds.vulnerable_clearance``, ``s_ttc = 1 - min_ttc / thresholds.min_ttc``,
  ``s_p = (p - p_thr) / (1 - p_thr)``, each clipped to [0, 0.999].
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from ethical_planner.validation import check, check_positive
from mujoco_world.evaluation.compare import ImpactRecord
from mujoco_world.loop.summary import GROUPS
from mujoco_world.storage.run_record import RunRecord, write_text

#: File name of the index inside an output root.
INDEX_FILE = "index.jsonl"


@dataclass(frozen=True, slots=True)
class NearCrashThresholds:
    """When a run counts as a near crash (any one suffices; a collision always does).

    Attributes:
        min_distance: ego-to-road-user distance below which [m].
        min_ttc: time-to-collision below which [s].
        collision_probability: highest planned collision probability at or above which, in (0, 1].
        vulnerable_clearance: ego-to-vulnerable-road-user distance below which [m]
            (1.0 m: the clearance a cyclist or pedestrian is owed when passed).
    """

    min_distance: float = 0.5
    min_ttc: float = 1.0
    collision_probability: float = 0.1
    vulnerable_clearance: float = 1.0

    def __post_init__(self) -> None:
        check_positive(
            "thresholds",
            min_distance=self.min_distance,
            min_ttc=self.min_ttc,
            collision_probability=self.collision_probability,
            vulnerable_clearance=self.vulnerable_clearance,
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
        outcome: goal, timeout, crash (an ego-involved collision) or failed.
        collisions: number of measured collisions.
        max_harm_measured, max_harm_predicted: highest harm of any body in any collision
            (0 without collisions).
        min_distance: [m] (nan if there was no road user).
        ego_collisions: collisions the ego took part in.
        third_party_collisions: collisions between other road users.
        max_harm_ego_involved: highest harm (measured or predicted) of any body in
            the ego's collisions (0 without).
        min_distance_vulnerable: smallest ego distance to a vulnerable road user [m]
            (nan without one).
        avoidable: the avoidability search's verdict on the ego collision (None: not
            searched, or no ego collision).
        min_ttc: [s] (inf if no approach within the horizon, nan if unknown).
        max_collision_probability: highest planned collision probability (nan if unknown).
        max_risk: highest risk per group (ego, third_party, vulnerable; nan for a run
            that failed before planning).
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
    ego_collisions: int = 0
    third_party_collisions: int = 0
    max_harm_ego_involved: float = 0.0
    min_distance_vulnerable: float = math.nan
    avoidable: bool | None = None

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
            # a bool is an int to isinstance; here it is not
            others = tuple(k for k in kinds if k is not bool)
            fits = bool in kinds if isinstance(value, bool) else isinstance(value, others)
            if not fits:
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
    "ego_collisions": (int,),
    "third_party_collisions": (int,),
    "max_harm_ego_involved": (int, float),
    "min_distance_vulnerable": (int, float),
    "avoidable": (bool, type(None)),
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


def severity(
    ego_collisions: int,
    max_harm: float,
    min_distance: float,
    min_ttc: float,
    max_collision_probability: float,
    thresholds: NearCrashThresholds,
    *,
    third_party_collisions: int = 0,
    min_distance_vulnerable: float = math.nan,
) -> tuple[bool, float]:
    """Near-crash flag and severity score of a run (see the module docstring).

    Args:
        ego_collisions: number of collisions the ego took part in.
        max_harm: highest harm (measured or predicted) in [0, 1] of any body of the
            ego's collisions if there are any, else of the third-party collisions.
        min_distance: smallest ego distance [m].
        min_ttc: smallest time-to-collision [s].
        max_collision_probability: highest planned collision probability in [0, 1]
            (nan values count as "not past the threshold").
        thresholds: what counts as a near crash.
        third_party_collisions: number of collisions between other road users.
        min_distance_vulnerable: smallest ego distance to a vulnerable road user [m].

    Returns:
        (near_crash, score).
    """
    harm = max_harm if math.isfinite(max_harm) else 0.0
    if ego_collisions > 0:
        return True, 2.0 + harm
    if third_party_collisions > 0:
        return True, 1.0 + harm

    def below(value: float, threshold: float) -> tuple[bool, float]:
        if not math.isfinite(value):
            return False, 0.0
        return value < threshold, min(max(1.0 - value / threshold, 0.0), 0.999)

    near_d, s_d = below(min_distance, thresholds.min_distance)
    near_v, s_v = below(min_distance_vulnerable, thresholds.vulnerable_clearance)
    near_t, s_t = below(min_ttc, thresholds.min_ttc)
    p, p_thr = max_collision_probability, thresholds.collision_probability
    near_p = math.isfinite(p) and p >= p_thr
    s_p = min(max((p - p_thr) / (1.0 - p_thr), 0.0), 0.999) if p_thr < 1.0 and math.isfinite(p) else 0.0
    return bool(near_d or near_v or near_t or near_p), max(s_d, s_v, s_t, s_p)


def make_row(record: RunRecord, thresholds: NearCrashThresholds | None = None) -> IndexRow:
    """Index row of a stored run.

    Args:
        record: the run's record (its summary's ``min_ttc`` and
            ``max_collision_probability`` are nan when unknown and then make no
            near crash).
        thresholds: near-crash thresholds.
    """
    thresholds = thresholds or NearCrashThresholds()
    summary = record.summary

    def max_of(values: Iterable[float]) -> float:
        finite = [v for v in values if math.isfinite(v)]
        return max(finite) if finite else 0.0

    def harm_of(collisions: Iterable[ImpactRecord]) -> float:
        return max_of(h for c in collisions for b in (c.a, c.b) for h in (b.harm_measured, b.harm_predicted))

    harm_m = max_of(b.harm_measured for c in summary.collisions for b in (c.a, c.b))
    harm_p = max_of(b.harm_predicted for c in summary.collisions for b in (c.a, c.b))
    ego, third = summary.ego_collisions, summary.third_party_collisions
    near, score = severity(
        len(ego),
        harm_of(ego) if ego else harm_of(third),
        summary.min_distance,
        summary.min_ttc,
        summary.max_collision_probability,
        thresholds,
        third_party_collisions=len(third),
        min_distance_vulnerable=summary.min_distance_vulnerable,
    )
    return IndexRow(
        run_id=record.run_id,
        scenario=summary.scenario,
        planner=summary.planner,
        seed=int(summary.seed),
        outcome=summary.outcome,
        collisions=len(summary.collisions),
        max_harm_measured=harm_m,
        max_harm_predicted=harm_p,
        min_distance=float(summary.min_distance),
        min_ttc=float(summary.min_ttc),
        max_collision_probability=float(summary.max_collision_probability),
        max_risk={g: float(summary.max_risk.get(g, math.nan)) for g in GROUPS},
        near_crash=near,
        severity=float(score),
        recording=record.recording,
        duration=float(summary.duration),
        ego_collisions=len(ego),
        third_party_collisions=len(third),
        max_harm_ego_involved=harm_of(ego),
        min_distance_vulnerable=float(summary.min_distance_vulnerable),
        avoidable=record.avoidability.avoidable if record.avoidability is not None else None,
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


def compact_index(out_root: str | Path, rows: Sequence[IndexRow]) -> Path:
    """Rewrite ``out_root/index.jsonl`` with one row per run id; return the file.

    The runs of the file that ``rows`` does not hold come first (their latest row, in
    the order of their first), then ``rows`` in their order (``rows`` replaces every
    older row of its runs). Written to a temporary file, fsynced and renamed, so an
    interruption leaves the old index or the new one.

    Raises:
        ValueError: the existing index holds a line that is not an index row.
    """
    root = Path(out_root)
    path = root / INDEX_FILE
    mine = {r.run_id for r in rows}
    kept = [r for r in read_index(root) if r.run_id not in mine] if path.is_file() else []
    text = "".join(r.to_json() + "\n" for r in [*kept, *rows])
    return write_text(path, text)


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
