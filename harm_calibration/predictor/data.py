"""Training and evaluation windows from recorded CommonRoad traffic, split by location.

Tracks come from ``mujoco_world.scenario.commonroad_tracks.read_tracks`` (declared
step checked against the recorded velocities: highD 0.1 -> 0.2 s, SinD 0.1 -> 0.5 s).
Each track is resampled on the model's 0.2 s grid (linear interpolation; headings
unwrapped), and a window is cut every ``stride`` grid steps where 4 s of future
exist: tracks that leave early give the windows they can, tracks that appear late
give windows whose history is shorter than 2 s (padded as in inference).

The split is by recording location (``SPLIT``), never by window: highD sites A / B / E,
exiD Aachen Brand, NGSIM US101 / Lankershim / Peachtree are locations. All SinD
recordings are one intersection (identical maps), the only one with pedestrians and
cyclists, so SinD is split by recording day instead (``recording_of``).
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ethical_planner.prediction.learned import GROUP_OF_TYPE, ModelSpec, encode, pad_history
from ethical_planner.road_users import RoadUserType
from mujoco_world.scenario.commonroad_tracks import (
    ScenarioTracks,
    Track,
    UnusableScenarioError,
    read_tracks,
)

#: Recording keys per split. Test locations are never seen in training or recalibration.
SPLIT = {
    "train": (
        "highD-A",
        "exiD-AachenBrand",
        "NGSIM-US101",
        "SinD-7281",
        "SinD-8021",
        "SinD-8101",
        "SinD-8111",
    ),
    "val": ("highD-B", "SinD-834"),
    "test": ("highD-E", "NGSIM-Lanker", "NGSIM-Peach", "SinD-851"),
}
SPLITS = tuple(SPLIT)
#: Folders of recorded traffic below ``shared/commonroad`` used by default.
DEFAULT_DATA = (
    "drivability-checker-datasets/highD",
    "drivability-checker-datasets/exiD",
    "drivability-checker-datasets/SinD",
    "tum-cps-scenarios/NGSIM",
)
_SIND = re.compile(r"^CHN_SIND-(\d+)_")
_CACHE_VERSION = "1"


def recording_of(scenario: ScenarioTracks) -> str:
    """Split key of a file: its location, or ``SinD-<recording>`` for SinD."""
    if m := _SIND.match(scenario.scenario_id):
        return f"SinD-{m.group(1)}"
    return scenario.location


def split_of(recording: str) -> str | None:
    """``"train"``, ``"val"``, ``"test"`` or None for a recording outside the split."""
    for name, keys in SPLIT.items():
        if recording in keys:
            return name
    return None


def scenario_files(dirs: Sequence[str | Path]) -> list[Path]:
    """Every CommonRoad XML file below ``dirs``, sorted.

    Raises:
        ValueError: a folder that does not exist or holds no XML file.
    """
    files: list[Path] = []
    for d in dirs:
        d = Path(d)
        if not d.is_dir():
            raise ValueError(f"--data {d}: not a folder")
        found = sorted(d.rglob("*.xml"))
        if not found:
            raise ValueError(f"--data {d}: holds no CommonRoad .xml file")
        files += found
    return sorted(set(files))


@dataclass(frozen=True, slots=True)
class FileReport:
    """What reading one file gave: its split key, the step check, or why it was refused."""

    path: str
    recording: str
    split: str | None
    n_tracks: int
    declared_dt: float
    dt: float
    step_message: str
    error: str = ""


def _cache_path(cache: Path, path: Path) -> Path:
    stat = path.stat()
    key = f"{_CACHE_VERSION}|{path.resolve()}|{stat.st_size}|{stat.st_mtime_ns}"
    return cache / f"{path.stem}-{hashlib.sha1(key.encode()).hexdigest()[:12]}.npz"


def _read_one(args: tuple[Path, Path | None]) -> tuple[FileReport, dict | None]:
    """Read one file (through the cache) into plain arrays."""
    path, cache = args
    cached = _cache_path(cache, path) if cache is not None else None
    if cached is not None and cached.is_file():
        with np.load(cached, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        path_s, recording, split, message = (str(x) for x in arrays.pop("report_str"))
        n, declared, dt = arrays.pop("report_num")
        report = FileReport(path_s, recording, split or None, int(n), float(declared), float(dt), message)
        return report, arrays
    try:
        scenario = read_tracks(path)
    except UnusableScenarioError as error:
        return FileReport(str(path), "", None, 0, 0.0, 0.0, "", str(error)), None
    recording = recording_of(scenario)
    tracks = scenario.tracks
    arrays = {
        "type": np.array([t.type.value for t in tracks]),
        "length": np.array([t.length for t in tracks]),
        "width": np.array([t.width for t in tracks]),
        "offsets": np.cumsum([0] + [len(t) for t in tracks]),
        "times": np.concatenate([t.times for t in tracks]),
        "positions": np.concatenate([t.positions for t in tracks]),
        "headings": np.concatenate([t.headings for t in tracks]),
        "speeds": np.concatenate([t.speeds for t in tracks]),
    }
    report = FileReport(
        str(path),
        recording,
        split_of(recording),
        len(tracks),
        scenario.declared_dt,
        scenario.dt,
        scenario.step_check.message,
    )
    if cached is not None:
        cache.mkdir(parents=True, exist_ok=True)
        tmp = cached.with_suffix(".tmp.npz")
        np.savez(
            tmp,
            report_str=np.array([report.path, report.recording, report.split or "", report.step_message]),
            report_num=np.array([report.n_tracks, report.declared_dt, report.dt]),
            **arrays,
        )
        tmp.replace(cached)
    return report, arrays


@dataclass(frozen=True, slots=True, eq=False)
class Windows:
    """Windows of history and future, struct of arrays (one row per window).

    Attributes:
        groups: type group (``TYPE_GROUPS``), (n,). types: road-user type names, (n,).
        length, width: [m], (n,).
        positions: padded history [m] (n, n_history, 2), world frame, oldest first.
        headings: [rad] (n, n_history). speeds: [m/s] (n, n_history).
        available: real history samples, (n,).
        future: true centres [m] (n, n_future, 2) at ``spec.future_times``.
        recording: split key per window, (n,).
    """

    groups: np.ndarray
    types: np.ndarray
    length: np.ndarray
    width: np.ndarray
    positions: np.ndarray
    headings: np.ndarray
    speeds: np.ndarray
    available: np.ndarray
    future: np.ndarray
    recording: np.ndarray

    def __len__(self) -> int:
        return len(self.groups)

    def features(self, spec: ModelSpec) -> np.ndarray:
        """Network inputs (``encode``), float32 (n, n_features)."""
        return encode(
            self.groups,
            self.length,
            self.width,
            self.positions,
            self.headings,
            self.speeds,
            self.available,
            spec,
        )

    def subset(self, mask: np.ndarray) -> Windows:
        """The windows where ``mask`` is True (or at the given indices)."""
        return Windows(*(getattr(self, f)[mask] for f in self.__slots__))


def track_windows(track: Track, spec: ModelSpec, stride: int) -> dict[str, np.ndarray] | None:
    """Windows of one track on the model grid (see the module docstring), or None."""
    step = spec.history_step
    if abs(spec.future_step - step) > 1e-12:
        raise ValueError("windows need the history and future steps to be equal")
    t = track.times
    if len(t) < 2:
        return None
    n_grid = int(np.floor((t[-1] - t[0]) / step + 1e-6)) + 1
    grid = t[0] + step * np.arange(n_grid)
    x = np.interp(grid, t, track.positions[:, 0])
    y = np.interp(grid, t, track.positions[:, 1])
    yaw = np.interp(grid, t, track.headings)
    v = np.interp(grid, t, track.speeds)
    h, f = spec.n_history, spec.n_future
    anchors = np.arange(0, n_grid - f, stride)
    if len(anchors) == 0:
        return None
    hist_idx = anchors[:, None] + np.arange(1 - h, 1)[None, :]
    fut_idx = anchors[:, None] + np.arange(1, f + 1)[None, :]
    safe = np.clip(hist_idx, 0, None)
    positions = np.stack([x[safe], y[safe]], axis=-1)
    available = np.minimum(anchors + 1, h)
    positions, headings, speeds = pad_history(positions, yaw[safe], v[safe], available, step)
    n = len(anchors)
    return {
        "positions": positions,
        "headings": headings,
        "speeds": speeds,
        "available": available,
        "future": np.stack([x[fut_idx], y[fut_idx]], axis=-1),
        "length": np.full(n, track.length),
        "width": np.full(n, track.width),
        "types": np.full(n, track.type.value),
    }


def build_windows(
    dirs: Sequence[str | Path],
    spec: ModelSpec,
    stride: int = 2,
    workers: int = 2,
    cache: Path | None = None,
    max_files: int | None = None,
) -> tuple[Windows, list[FileReport]]:
    """Read every file below ``dirs`` and cut windows from all usable tracks.

    Args:
        dirs: folders of CommonRoad files.
        spec: the model's window.
        stride: grid steps between window anchors.
        workers: processes for parsing (files are independent).
        cache: folder for parsed tracks (None: parse every time).
        max_files: read at most this many files per split key (quick runs, CI).

    Returns:
        (windows of files inside ``SPLIT``, one report per file read).
    """
    if stride < 1:
        raise ValueError(f"stride must be >= 1 grid step, got {stride}")
    files = scenario_files(dirs)
    if max_files is not None:
        files = _limit_per_recording(files, max_files)
    jobs = [(p, cache) for p in files]
    if workers > 1 and len(jobs) > 1:
        with ProcessPoolExecutor(workers) as pool:
            results = list(pool.map(_read_one, jobs, chunksize=4))
    else:
        results = [_read_one(job) for job in jobs]
    parts: list[dict[str, np.ndarray]] = []
    reports = []
    for report, arrays in results:
        reports.append(report)
        if arrays is None or report.split is None:
            continue
        offsets = arrays["offsets"]
        for k in range(len(arrays["type"])):
            sl = slice(offsets[k], offsets[k + 1])
            kind = RoadUserType(str(arrays["type"][k]))
            if kind not in GROUP_OF_TYPE:
                continue
            track = Track(
                0,
                kind,
                float(arrays["length"][k]),
                float(arrays["width"][k]),
                False,
                np.arange(offsets[k + 1] - offsets[k]),
                arrays["times"][sl],
                arrays["positions"][sl],
                arrays["headings"][sl],
                arrays["speeds"][sl],
            )
            w = track_windows(track, spec, stride)
            if w is not None:
                w["recording"] = np.full(len(w["types"]), report.recording)
                parts.append(w)
    if not parts:
        raise ValueError("no windows: none of the files holds a usable track inside the split")
    cat = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    groups = np.array([GROUP_OF_TYPE[RoadUserType(t)] for t in cat["types"]])
    windows = Windows(
        groups,
        cat["types"],
        cat["length"],
        cat["width"],
        cat["positions"],
        cat["headings"],
        cat["speeds"],
        cat["available"],
        cat["future"],
        cat["recording"],
    )
    return windows, reports


def _limit_per_recording(files: list[Path], max_files: int) -> list[Path]:
    """At most ``max_files`` files per name prefix (recording), in sorted order."""
    kept: dict[str, int] = {}
    out = []
    for path in files:
        key = re.sub(r"_\d+_[TS]-\d+.*$", "", path.name)
        if kept.get(key, 0) < max_files:
            kept[key] = kept.get(key, 0) + 1
            out.append(path)
    return out


def split_windows(windows: Windows) -> dict[str, Windows]:
    """Windows per split (``SPLIT``)."""
    split = np.array([split_of(r) or "" for r in windows.recording])
    return {name: windows.subset(split == name) for name in SPLITS}
