"""Run folders: one rule for a run's id and folder, and storing a finished run there.

The run id of (scenario, planner, seed) is ``<scenario key>__<planner key>__s<seed>``
(``run_id``), and its folder is ``<out>/<run id>`` (``run_dir``); every command that
writes runs (``etp run``, ``etp demo``, batches) uses these two functions. A key is
the name itself for catalog, generated and registered names (letters, digits and
``_ . + -``, no ``__``), and ``<file stem>-<10 hex digits>`` for a file (scenario or
planner configuration), the digits being the start of the SHA-256 of the file's
resolved absolute path: ``dirA/s.toml`` and ``dirB/s.toml`` get different folders,
the same file named from another working directory gets the same one (a batch
resumes it), a moved file gets a new one. A planner configuration given as a record
(``etp --config``) that is not exactly its named preset adds the start of the SHA-256
of its content to the planner's key.

``store_run`` writes the run's record (``run_record``), keeps or drops its recording
(``keep``) and appends its row to ``<out>/index.jsonl`` (``run_index``), in that order.
``root_lock`` lets one batch at a time write into an output root.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import re
from collections.abc import Iterator
from pathlib import Path

from ethical_planner.config import PRESETS, PlannerConfig, preset
from ethical_planner.records import to_plain
from mujoco_world.evaluation.avoidability import Avoidability
from mujoco_world.loop.config import RunConfig
from mujoco_world.loop.summary import RunSummary
from mujoco_world.storage.recording import PARTIAL_RECORDING_FILE, RECORDING_FILE
from mujoco_world.storage.run_index import INDEX_FILE, NearCrashThresholds, append_row, find_run, make_row
from mujoco_world.storage.run_record import RunRecord, read_record, write_record

#: Lock file of an output root (held by the batch writing into it).
LOCK_FILE = ".etp-batch.lock"
#: Allowed values of ``keep``.
KEEP_CHOICES = ("all", "near_crash")
#: Default output root of ``etp run``.
DEFAULT_ROOT = Path("logs")
#: Suffixes of scenario and planner files.
FILE_SUFFIXES = (".toml", ".xml")
_NAME = re.compile(r"[A-Za-z0-9_.+-]+")
_HASH_DIGITS = 10


def parse_keep(keep: str) -> str:
    """``keep`` as one of ``KEEP_CHOICES`` ("near-crash" is accepted for "near_crash").

    Raises:
        ValueError: an unknown value.
    """
    value = keep.replace("-", "_")
    if value not in KEEP_CHOICES:
        raise ValueError(f"keep must be one of {', '.join(KEEP_CHOICES)} (or near-crash), got {keep!r}")
    return value


def is_file_source(source: str) -> bool:
    """True if ``source`` names a file (a known suffix or a path separator), not a registered name."""
    seps = (os.sep, os.altsep or os.sep)
    return Path(source).suffix.lower() in FILE_SUFFIXES or any(sep in source for sep in seps)


def source_key(source: str, what: str = "name") -> str:
    """The part of a run id that stands for a scenario or planner (see the module docstring).

    Args:
        source: a registered name, or a file path.
        what: what ``source`` is, for the error message ("scenario", "planner").

    Raises:
        ValueError: a name with characters outside letters, digits and ``_ . + -``, or
            with ``__`` (the run id's separator).
    """
    if is_file_source(source):
        path = Path(source).expanduser().resolve()
        digest = hashlib.sha256(str(path).encode("utf-8")).hexdigest()[:_HASH_DIGITS]
        stem = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9_.+-]", "_", path.stem)).strip("_") or "file"
        return f"{stem}-{digest}"
    if not (isinstance(source, str) and _NAME.fullmatch(source) and "__" not in source):
        raise ValueError(
            f"{what} {source!r} cannot name a run: use letters, digits and _ . + - (no '__'), or a file path"
        )
    return source


def run_id(scenario: str, planner: str, seed: int, planner_config: PlannerConfig | None = None) -> str:
    """The id of the run of ``scenario`` with ``planner`` and ``seed`` (module docstring).

    Args:
        scenario: catalog or generated name, or a scenario file.
        planner: planner name, or a planner configuration file.
        seed: run seed.
        planner_config: the configuration the planner runs with, if given explicitly.
            Unless it is exactly the preset ``planner`` names, the planner's key gets
            ``-<10 hex digits of the SHA-256 of the configuration>``: two different
            configurations under one name (``ethical+c`` from ``dirA/c.toml`` and
            ``dirB/c.toml``) never share a folder, the same configuration resumes.
    """
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ValueError(f"seed must be an integer, got {seed!r}")
    key = source_key(planner, "planner")
    if planner_config is not None and not (planner in PRESETS and planner_config == preset(planner)):
        text = json.dumps(to_plain(planner_config), sort_keys=True, default=str)
        key = f"{key}-{hashlib.sha256(text.encode('utf-8')).hexdigest()[:_HASH_DIGITS]}"
    return f"{source_key(scenario, 'scenario')}__{key}__s{seed}"


def run_dir(out: str | Path, run: str) -> Path:
    """Folder of the run with id ``run`` under the output root ``out``."""
    return Path(out) / run


def source_of(source: str) -> str:
    """What a record keeps as the source: the resolved path of a file, else the name."""
    return str(Path(source).expanduser().resolve()) if is_file_source(source) else source


def store_run(
    summary: RunSummary,
    out: str | Path,
    run: str,
    *,
    scenario_source: str = "",
    planner_source: str = "",
    config: RunConfig | None = None,
    recording: str | Path | None = None,
    keep: str = "all",
    thresholds: NearCrashThresholds | None = None,
    write: bool = True,
) -> RunRecord:
    """Store a finished run: its record in ``run_dir(out, run)``, its row in ``out``'s index.

    Args:
        summary: what the loop produced.
        out: output root (holds ``index.jsonl`` and the run folders).
        run: the run id (``run_id``).
        scenario_source, planner_source: what was asked for (kept in the record).
        config: the loop settings of the run.
        recording: the run's ``.rrd`` file, if one was written.
        keep: "all" keeps every recording; "near_crash" deletes it unless the run is
            a near crash (the index lists every run).
        thresholds: near-crash thresholds.
        write: False indexes the run without writing its record (an interrupted run:
            a rerun of the batch runs it again).

    Returns:
        The record as written (``recording`` None if it was dropped).

    Raises:
        ValueError: an unknown ``keep``.
    """
    keep = parse_keep(keep)
    record = RunRecord(
        run_id=run,
        summary=summary,
        scenario_source=scenario_source,
        planner_source=planner_source,
        config=config,
        recording=None if recording is None else str(recording),
    )
    row = make_row(record, thresholds)
    if recording is not None and keep == "near_crash" and not row.near_crash:
        Path(recording).unlink(missing_ok=True)
        record = dataclasses.replace(record, recording=None)
        row = dataclasses.replace(row, recording=None)
    if write:
        write_record(run_dir(out, run), record)
    append_row(out, row)
    return record


def store_avoidability(run_folder: str | Path, verdict: Avoidability) -> RunRecord:
    """Add the avoidability verdict to a stored run: its record rewritten, its index row appended.

    The row goes to the index of the run folder's parent (the output root) if there is
    one; ``read_index`` keeps the latest row of a run, so the verdict replaces the
    earlier row.

    Raises:
        ValueError: the folder holds no readable run record.
    """
    folder = Path(run_folder)
    record = dataclasses.replace(read_record(folder), avoidability=verdict)
    write_record(folder, record)
    if (folder.parent / INDEX_FILE).is_file():
        append_row(folder.parent, make_row(record))
    return record


@contextlib.contextmanager
def root_lock(out: str | Path) -> Iterator[Path]:
    """Hold the output root ``out`` for one batch (an advisory lock on ``out/LOCK_FILE``).

    The lock dies with the process that holds it (a ``kill -9`` frees it). Where the
    platform has no ``fcntl`` (Windows), nothing is locked.

    Raises:
        ValueError: another process holds the root (the message names its pid).
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield Path(out)
        return
    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    path = root / LOCK_FILE
    with path.open("a+", encoding="utf-8") as handle:
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "unknown"
            raise ValueError(
                f"{root}: another batch (pid {holder}) is writing into this output folder; "
                f"wait for it or choose another --out"
            ) from None
        handle.seek(0)
        handle.truncate()
        handle.write(str(os.getpid()))
        handle.flush()
        try:
            yield root
        finally:
            fcntl.flock(handle.fileno(), fcntl.LOCK_UN)


def resolve_recording(run: str, root: str | Path = DEFAULT_ROOT) -> Path:
    """The ``.rrd`` file of a run id, a run folder or a recording path.

    A run folder without ``recording.rrd`` gives its ``recording.partial.rrd`` (left by
    a process that died during the run).

    A run id is looked up in ``root/index.jsonl`` and in ``root/*/index.jsonl``.

    Raises:
        ValueError: nothing found, or the run kept no recording.
    """
    candidate = Path(run)
    if candidate.is_file():
        return candidate
    for name in (RECORDING_FILE, PARTIAL_RECORDING_FILE):
        if candidate.is_dir() and (candidate / name).is_file():
            return candidate / name
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
