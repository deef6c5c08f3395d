"""Recorded road-user tracks from CommonRoad scenario files.

The reader that the learned predictor's training and the CommonRoad scenario
importer share: it opens a CommonRoad XML file (``commonroad-io`` 2024.3, imported
lazily) and returns every dynamic obstacle's recorded trajectory as plain arrays.

API:

- ``read_tracks(path, step="velocity") -> ScenarioTracks``: one file. Raises
  ``UnusableScenarioError`` (a ``ValueError``) for a file without any usable
  recorded trajectory (no obstacles, or only set-based occupancies), naming the
  file and why; ``ValueError`` for an unknown ``step`` policy; the parser's own
  error, wrapped in ``UnusableScenarioError``, for a file it cannot parse.
- ``ScenarioTracks``: ``scenario_id``, ``location`` (see ``location_of``),
  ``declared_dt``, ``dt`` (the step used for ``Track.times``), ``step_check`` (the
  cross-check of the declared step against the recorded velocities), ``tracks``,
  ``skipped`` (obstacle id and reason for every obstacle left out).
- ``Track``: one obstacle: ``obstacle_id``, ``type`` (``RoadUserType``), ``length``,
  ``width`` [m] (a circle of radius r becomes a 2r x 2r square, ``circle`` is True),
  ``time_steps`` (integer steps of the file, shape (n,)), ``times`` [s] (shape (n,),
  ``time_steps * dt``), ``positions`` [m] (n, 2), ``headings`` [rad] (n,, unwrapped),
  ``speeds`` [m/s] (n,). A track starts at the obstacle's initial time step, which
  may be after the scenario's start, and ends at its last recorded state, which may
  be before the scenario's end (late-appearing, early-leaving obstacles); time steps
  within a track are consecutive (a gap splits nothing: such an obstacle is skipped
  with the reason).
- ``StepCheck``: ``declared_dt`` [s], ``ratio`` (median of recorded displacement per
  step over velocity x declared step, over moving samples), ``n_samples``,
  ``dt`` (the step used), ``corrected`` (True if it differs from the declared one)
  and ``message`` (what was done, for a report).
- ``shared_commonroad() -> Path | None``: where the shared real files are.
- ``location_of(scenario_id) -> str``: the recording location of a scenario id
  (highD ``DEU_LocationALower26-1_...`` -> ``highD-A``; SinD recordings are all one
  intersection -> ``SinD``; NGSIM ``USA_US101-14_1_T-1`` -> ``NGSIM-US101``; exiD
  ``DEU_AachenBrand-1_...`` -> ``exiD-AachenBrand``; others: the map name).

Measured facts this module handles (``shared/commonroad/README.md``): highD files move
about 2x and SinD files about 5x further per declared step than their velocities say.
The velocities are the plausible ones, so with ``step="velocity"`` (the default) the
step becomes ``declared_dt x ratio`` rounded to the nearest integer multiple when the
ratio is within 10 % of one (2 for highD, 5 for SinD), else ``declared_dt x ratio``;
a ratio within 10 % of 1 keeps the declared step. ``step="declared"`` keeps the
declared step and only reports.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ethical_planner.road_users import RoadUserType

#: CommonRoad obstacle type value -> road-user type (types not listed are not road users).
COMMONROAD_TYPES = {
    "car": RoadUserType.CAR,
    "taxi": RoadUserType.TAXI,
    "truck": RoadUserType.TRUCK,
    "bus": RoadUserType.BUS,
    "bicycle": RoadUserType.BICYCLE,
    "motorcycle": RoadUserType.MOTORCYCLE,
    "pedestrian": RoadUserType.PEDESTRIAN,
    "priorityVehicle": RoadUserType.PRIORITY_VEHICLE,
    "parkedVehicle": RoadUserType.PARKED_VEHICLE,
    "train": RoadUserType.TRAIN,
}
#: Step policies of ``read_tracks``.
STEP_POLICIES = ("velocity", "declared")
#: Below this speed [m/s] a sample does not take part in the step cross-check.
MIN_CHECK_SPEED = 1.0
#: Relative tolerance within which a ratio counts as an integer.
RATIO_TOLERANCE = 0.10


class UnusableScenarioError(ValueError):
    """A CommonRoad file that holds no usable recorded trajectory."""


@dataclass(frozen=True, slots=True, eq=False)
class Track:
    """One obstacle's recorded trajectory (see the module docstring for the fields)."""

    obstacle_id: int
    type: RoadUserType
    length: float
    width: float
    circle: bool
    time_steps: np.ndarray
    times: np.ndarray
    positions: np.ndarray
    headings: np.ndarray
    speeds: np.ndarray

    def __len__(self) -> int:
        return len(self.time_steps)


@dataclass(frozen=True, slots=True)
class StepCheck:
    """The declared time step checked against the recorded velocities."""

    declared_dt: float
    ratio: float
    n_samples: int
    dt: float
    corrected: bool
    message: str


@dataclass(frozen=True, slots=True, eq=False)
class ScenarioTracks:
    """Every usable recorded track of one file."""

    path: Path
    scenario_id: str
    location: str
    declared_dt: float
    dt: float
    step_check: StepCheck
    tracks: tuple[Track, ...]
    skipped: tuple[tuple[int, str], ...]


_HIGHD = re.compile(r"^DEU_Location([A-Z])(Upper|Lower)")
_SIND = re.compile(r"^CHN_SIND-")
_NGSIM = re.compile(r"^USA_(US101|Lanker|Peach)")
_MAP = re.compile(r"^([A-Z]{3}_[A-Za-z0-9]+)-\d+")


def location_of(scenario_id: str) -> str:
    """The recording location of a CommonRoad scenario id (for splits by location).

    highD directions (Upper/Lower) and recording numbers of one site are one location;
    all SinD recordings are one intersection (their maps are identical); a
    cooperative copy (``C-`` prefix) belongs to its original's location.
    """
    scenario_id = scenario_id.removeprefix("C-")
    if m := _HIGHD.match(scenario_id):
        return f"highD-{m.group(1)}"
    if _SIND.match(scenario_id):
        return "SinD"
    if m := _NGSIM.match(scenario_id):
        return f"NGSIM-{m.group(1)}"
    if scenario_id.startswith("DEU_AachenBrand"):
        return "exiD-AachenBrand"
    if m := _MAP.match(scenario_id):
        return m.group(1)
    return scenario_id


def shared_commonroad() -> Path | None:
    """The shared folder of real CommonRoad files, or None where it is absent.

    ``$ETP_COMMONROAD`` if set, else the first ``shared/commonroad`` beside the
    repository or one of its parent folders (``<repo>/../shared/commonroad`` in CI,
    ``/work/shared/commonroad`` from a worktree under ``/work/wt``).
    """
    env = os.environ.get("ETP_COMMONROAD")
    if env:
        return Path(env) if Path(env).is_dir() else None
    for folder in Path(__file__).resolve().parents[2].parents:
        candidate = folder / "shared" / "commonroad"
        if candidate.is_dir():
            return candidate
    return None


def _exact(value: object) -> object:
    """An uncertain CommonRoad value as one number or point: an interval's middle, a shape's centre."""
    if hasattr(value, "start") and hasattr(value, "end"):
        return 0.5 * (float(value.start) + float(value.end))
    return getattr(value, "center", value)


def _state_array(states: list, name: str) -> np.ndarray | None:
    values = [getattr(s, name, None) for s in states]
    if any(v is None for v in values):
        return None
    return np.asarray([_exact(v) for v in values], dtype=float)


def _footprint(shape) -> tuple[float, float, bool] | str:  # noqa: ANN001 - a CommonRoad shape
    """(length, width, circle) [m] of an obstacle's shape, or why it has none."""
    from commonroad.geometry.shape import Circle, Rectangle

    if isinstance(shape, Rectangle):
        return float(shape.length), float(shape.width), False
    if isinstance(shape, Circle):
        return 2.0 * float(shape.radius), 2.0 * float(shape.radius), True
    return f"shape {type(shape).__name__} is not a rectangle or circle"


def _headings_and_speeds(
    states: list, times: np.ndarray, positions: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | str:
    """Recorded headings [rad] and speeds [m/s], missing ones derived from the positions; or why not."""
    if len(states) < 2:
        return "a single state"
    headings = _state_array(states, "orientation")
    speeds = _state_array(states, "velocity")
    if headings is None or speeds is None:
        # Derive what is missing from the positions (central differences).
        vel = np.gradient(positions, times, axis=0)
        if speeds is None:
            speeds = np.hypot(vel[:, 0], vel[:, 1])
        if headings is None:
            headings = np.arctan2(vel[:, 1], vel[:, 0])
    if not (np.all(np.isfinite(headings)) and np.all(np.isfinite(speeds))):
        return "orientation or velocity is not finite"
    return headings, speeds


def _obstacle_track(obstacle, dt_scale: float) -> tuple[Track | None, str]:
    """(track, "") or (None, reason) for one CommonRoad dynamic obstacle."""
    from commonroad.prediction.prediction import TrajectoryPrediction

    kind = COMMONROAD_TYPES.get(obstacle.obstacle_type.value)
    if kind is None:
        return None, f"obstacle type {obstacle.obstacle_type.value!r} is not a road user"
    if not isinstance(obstacle.prediction, TrajectoryPrediction):
        what = type(obstacle.prediction).__name__ if obstacle.prediction is not None else "no prediction"
        return None, f"no recorded trajectory ({what})"
    footprint = _footprint(obstacle.obstacle_shape)
    if isinstance(footprint, str):
        return None, footprint
    length, width, circle = footprint
    states = [obstacle.initial_state, *obstacle.prediction.trajectory.state_list]
    steps = np.array([int(s.time_step) for s in states])
    if len(steps) > 1 and np.any(np.diff(steps) != 1):
        return None, "time steps are not consecutive"
    # An uncertain position is a shape: its centre stands for it.
    positions = np.asarray([_exact(s.position) for s in states], dtype=float)
    if positions.ndim != 2 or positions.shape[1] != 2 or not np.all(np.isfinite(positions)):
        return None, "positions are not finite points"
    motion = _headings_and_speeds(states, steps * dt_scale, positions)
    if isinstance(motion, str):
        return None, motion
    headings, speeds = motion
    if length <= 0 or width <= 0:
        return None, f"non-positive shape {length} x {width} m"
    track = Track(
        obstacle_id=int(obstacle.obstacle_id),
        type=kind,
        length=length,
        width=width,
        circle=circle,
        time_steps=steps,
        times=steps * dt_scale,
        positions=positions,
        headings=np.unwrap(headings),
        speeds=speeds,
    )
    return track, ""


def check_step(
    tracks: list[Track] | tuple[Track, ...], declared_dt: float, policy: str = "velocity"
) -> StepCheck:
    """Cross-check ``declared_dt`` [s] against the tracks' recorded velocities.

    The ratio is the median, over samples moving faster than ``MIN_CHECK_SPEED``,
    of the displacement between consecutive states over the mean of their speeds
    times ``declared_dt``; 1 means the declared step is consistent.

    Args:
        tracks: tracks read with the declared step.
        declared_dt: the file's step [s].
        policy: ``"velocity"`` (trust the velocities) or ``"declared"``.
    """
    if policy not in STEP_POLICIES:
        raise ValueError(f"step policy must be one of {', '.join(STEP_POLICIES)}, got {policy!r}")
    ratios = []
    for track in tracks:
        if len(track) < 2:
            continue
        moved = np.hypot(*np.diff(track.positions, axis=0).T)
        speed = 0.5 * (np.abs(track.speeds[1:]) + np.abs(track.speeds[:-1]))
        keep = speed > MIN_CHECK_SPEED
        ratios.append(moved[keep] / (speed[keep] * declared_dt))
    values = np.concatenate(ratios) if ratios else np.zeros(0)
    if len(values) == 0:
        msg = f"declared step {declared_dt:g} s kept: no moving samples to check it against"
        return StepCheck(declared_dt, math.nan, 0, declared_dt, False, msg)
    ratio = float(np.median(values))
    nearest = max(1, round(ratio))
    factor = float(nearest) if abs(ratio - nearest) <= RATIO_TOLERANCE * nearest else ratio
    if policy == "declared" or factor == 1.0:
        verdict = "consistent" if factor == 1.0 else f"inconsistent (x{ratio:.2f}), kept by request"
        msg = f"declared step {declared_dt:g} s {verdict}; displacement / (v dt) = {ratio:.3f}"
        return StepCheck(declared_dt, ratio, len(values), declared_dt, False, msg)
    dt = declared_dt * factor
    msg = (
        f"declared step {declared_dt:g} s disagrees with the recorded velocities "
        f"(displacement / (v dt) = {ratio:.3f} over {len(values)} samples): using {dt:g} s"
    )
    return StepCheck(declared_dt, ratio, len(values), dt, True, msg)


def open_commonroad(path: str | Path) -> tuple[object, object]:
    """Parse a CommonRoad file: (commonroad ``Scenario``, ``PlanningProblemSet``).

    Raises:
        UnusableScenarioError: no such file, or the parser cannot read it (its message
            named).
    """
    from commonroad.common.file_reader import CommonRoadFileReader

    path = Path(path)
    if not path.is_file():
        raise UnusableScenarioError(f"{path}: no such file")
    try:
        return CommonRoadFileReader(str(path)).open()
    except Exception as error:  # noqa: BLE001 - the parser raises many kinds
        raise UnusableScenarioError(f"{path}: not a readable CommonRoad file ({error})") from error


def read_tracks(path: str | Path, step: str = "velocity") -> ScenarioTracks:
    """Read every recorded road-user trajectory of a CommonRoad file.

    Args:
        path: a CommonRoad XML file.
        step: ``"velocity"`` corrects a declared step that disagrees with the
            recorded velocities; ``"declared"`` keeps it (and reports the ratio).

    Returns:
        The file's tracks with times on the checked step.

    Raises:
        ValueError: an unknown ``step`` policy.
        UnusableScenarioError: the file cannot be parsed, or holds no obstacle with
            a recorded trajectory (e.g. set-based occupancies only, or no obstacles).
    """
    if step not in STEP_POLICIES:
        raise ValueError(f"step must be one of {', '.join(STEP_POLICIES)}, got {step!r}")
    scenario, _ = open_commonroad(path)
    return scenario_tracks(scenario, path, step)


def scenario_tracks(
    scenario: object, path: str | Path, step: str = "velocity", allow_empty: bool = False
) -> ScenarioTracks:
    """The recorded road-user trajectories of a parsed CommonRoad scenario (see ``read_tracks``).

    Args:
        scenario: a commonroad-io ``Scenario`` (from ``open_commonroad``).
        path: the file it came from (for messages and ``ScenarioTracks.path``).
        step: step policy, as in ``read_tracks``.
        allow_empty: return no tracks (declared step kept) instead of raising when the
            scenario has no usable recorded trajectory.

    Raises:
        ValueError: an unknown ``step`` policy.
        UnusableScenarioError: no usable trajectory and not ``allow_empty``.
    """
    if step not in STEP_POLICIES:
        raise ValueError(f"step must be one of {', '.join(STEP_POLICIES)}, got {step!r}")
    path = Path(path)
    declared = float(scenario.dt)
    scenario_id = str(scenario.scenario_id)
    obstacles = list(scenario.dynamic_obstacles)
    if not obstacles and not allow_empty:
        raise UnusableScenarioError(f"{path}: no dynamic obstacles, so no recorded trajectories")
    tracks: list[Track] = []
    skipped: list[tuple[int, str]] = []
    for obstacle in obstacles:
        try:
            track, reason = _obstacle_track(obstacle, declared)
        except (TypeError, ValueError, AttributeError) as error:
            track, reason = None, f"unreadable state ({error})"
        if track is None:
            skipped.append((int(obstacle.obstacle_id), reason))
        else:
            tracks.append(track)
    if not tracks and not allow_empty:
        reasons = sorted({r for _, r in skipped})
        raise UnusableScenarioError(
            f"{path}: none of its {len(obstacles)} obstacles has a recorded trajectory ({'; '.join(reasons)})"
        )
    check = check_step(tracks, declared, step)
    if check.corrected:
        scale = check.dt / declared
        tracks = [_rescaled(t, scale) for t in tracks]
    return ScenarioTracks(
        path=path,
        scenario_id=scenario_id,
        location=location_of(scenario_id),
        declared_dt=declared,
        dt=check.dt,
        step_check=check,
        tracks=tuple(tracks),
        skipped=tuple(skipped),
    )


def _rescaled(track: Track, scale: float) -> Track:
    from dataclasses import replace

    return replace(track, times=track.times * scale)
