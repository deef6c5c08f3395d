"""Recording and run-index glue for ``etp run``/``etp demo``, and the ``near-crash``/``replay`` commands.

Wiring for a command that runs one scenario into ``out_dir`` (one folder per run,
whose name is the run id; the index lives in ``out_dir.parent`` unless told)::

    observer = recording_observer(out_dir, keep="near_crash", record=not args.no_record)
    summary = run_scenario(scenario, planner, seed, config, observer=observer)
    row = observer.row  # already appended to <out_root>/index.jsonl

``index_run(summary, out_root, recording_path)`` appends a row by hand when no
``RecordedRun`` observer was used.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

from mujoco_world.loop.runner import ObserverGroup, RunSummary
from mujoco_world.storage.recording import RECORDING_FILE, RecorderConfig, RerunRecorder
from mujoco_world.storage.run_index import (
    INDEX_FILE,
    IndexRow,
    NearCrashThresholds,
    SafetyMetrics,
    append_row,
    find_run,
    make_row,
)

#: Allowed values of ``keep``.
KEEP_CHOICES = ("all", "near_crash")
#: Default output root of ``etp run``.
DEFAULT_ROOT = Path("logs")


def _parse_keep(keep: str) -> str:
    value = keep.replace("-", "_")
    if value not in KEEP_CHOICES:
        raise ValueError(f"keep must be one of {', '.join(KEEP_CHOICES)} (or near-crash), got {keep!r}")
    return value


class RecordedRun(ObserverGroup):
    """Observer of one run: recording (optional), safety metrics, index row at the end.

    Attributes:
        out_dir: the run's folder; its name is the run id.
        out_root: folder of ``index.jsonl``.
        recorder: the Rerun recorder, or None with ``record=False``.
        metrics: minimum TTC and highest planned collision probability.
        row: the index row, set by ``on_end``.
    """

    def __init__(
        self,
        out_dir: str | Path,
        out_root: str | Path | None = None,
        keep: str = "all",
        record: bool = True,
        config: RecorderConfig | None = None,
        thresholds: NearCrashThresholds | None = None,
        run_id: str | None = None,
    ) -> None:
        self.out_dir = Path(out_dir)
        self.out_root = Path(out_root) if out_root is not None else self.out_dir.parent
        self.keep = _parse_keep(keep)
        self.thresholds = thresholds or NearCrashThresholds()
        self.run_id = run_id or self.out_dir.resolve().name
        self.metrics = SafetyMetrics()
        self.recorder = RerunRecorder(self.out_dir, config, self.run_id) if record else None
        members = [self.metrics] + ([self.recorder] if self.recorder is not None else [])
        super().__init__(members)
        self.row: IndexRow | None = None

    def on_end(self, summary: RunSummary) -> None:
        """Close the recording, index the run, drop the recording if it is not kept."""
        super().on_end(summary)
        path = self.recorder.path if self.recorder is not None else None
        row = make_row(summary, self.run_id, path, self.metrics, self.thresholds)
        if path is not None and self.keep == "near_crash" and not row.near_crash:
            path.unlink(missing_ok=True)
            row = IndexRow(**{**asdict(row), "recording": None})
        append_row(self.out_root, row)
        self.row = row


def recording_observer(
    out_dir: str | Path,
    keep: str = "all",
    record: bool = True,
    out_root: str | Path | None = None,
    config: RecorderConfig | None = None,
    thresholds: NearCrashThresholds | None = None,
    run_id: str | None = None,
) -> RecordedRun:
    """Observer that records a run to ``out_dir/recording.rrd`` and indexes it.

    Args:
        out_dir: the run's folder (its name is the run id unless ``run_id`` is given).
        keep: "all" keeps every recording; "near_crash" (or "near-crash") deletes it
            at the end unless the run is a near crash. The index lists every run.
        record: False (``--no-record``) writes no recording but still indexes the run.
        out_root: folder of ``index.jsonl`` (default: ``out_dir``'s parent).
        config: what the recorder logs.
        thresholds: near-crash thresholds.
        run_id: id in the index and of the Rerun recording.

    Raises:
        ValueError: an unknown ``keep``.
    """
    return RecordedRun(out_dir, out_root, keep, record, config, thresholds, run_id)


def index_run(
    summary: RunSummary,
    out_root: str | Path,
    recording_path: str | Path | None = None,
    run_id: str | None = None,
    metrics: SafetyMetrics | None = None,
    thresholds: NearCrashThresholds | None = None,
) -> IndexRow:
    """Append one row for a finished run to ``out_root/index.jsonl`` and return it.

    Args:
        summary: the run's summary.
        out_root: folder of the index.
        recording_path: the run's ``.rrd`` (its folder names the run), or None.
        run_id: id of the run (default: the recording's folder name, else
            ``scenario-planner-sSEED``).
        metrics: TTC and collision probability collected during the run (else unknown).
        thresholds: near-crash thresholds.
    """
    if run_id is None:
        if recording_path is not None:
            run_id = Path(recording_path).resolve().parent.name
        else:
            run_id = f"{summary.scenario}-{summary.planner}-s{summary.seed}"
    row = make_row(summary, run_id, recording_path, metrics, thresholds)
    append_row(out_root, row)
    return row


def resolve_recording(run: str, root: str | Path = DEFAULT_ROOT) -> Path:
    """The ``.rrd`` file of a run id, a run folder or a recording path.

    A run id is looked up in ``root/index.jsonl`` and in ``root/*/index.jsonl``.

    Raises:
        ValueError: nothing found, or the run kept no recording.
    """
    candidate = Path(run)
    if candidate.is_file():
        return candidate
    if candidate.is_dir() and (candidate / RECORDING_FILE).is_file():
        return candidate / RECORDING_FILE
    root = Path(root)
    # The index of ``root`` and those one level below (``etp run`` writes logs/run/index.jsonl).
    indexes = [root / INDEX_FILE] + sorted(root.glob(f"*/{INDEX_FILE}"))
    for index in (i for i in indexes if i.is_file()):
        try:
            row = find_run(index, run)
        except ValueError:
            continue
        if row.recording is None:
            raise ValueError(f"run {run!r} kept no recording (not a near crash, or --no-record)")
        path = Path(row.recording)
        if not path.is_file() and (index.parent / path).is_file():
            path = index.parent / path
        if not path.is_file():
            raise ValueError(f"run {run!r}: recording {path} is missing")
        return path
    if (root / run / RECORDING_FILE).is_file():
        return root / run / RECORDING_FILE
    raise ValueError(f"RUN_ID_OR_PATH: no recording for {run!r} (looked in {root})")


def replay_command(path: str | Path) -> list[str]:
    """The command that opens a recording in the Rerun viewer."""
    return ["rerun", str(Path(path).resolve())]
