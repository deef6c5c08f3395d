"""The typed record of one run, and the one module that writes and reads it.

Every run folder holds ``summary.json``: one JSON object with

* ``"format": "etp-run-record"`` and ``"version"`` (``RECORD_VERSION``);
* the run's identity and settings: ``run_id``, ``scenario_source`` (catalog or
  generated name, or the resolved path of a scenario file), ``planner_source``
  (planner name or configuration file), ``config`` (the loop's ``RunConfig``),
  ``recording`` (path of the kept ``.rrd`` file, or null) and ``avoidability`` (the
  verdict of ``etp avoidability`` on an ego collision, or null);
* every field of ``mujoco_world.loop.summary.RunSummary`` at the top level: outcome,
  reason, the bodies (id, name, type, length, width, mass), the collisions (each an
  ``ImpactRecord``: measurement and model prediction per body) and the metrics.

Non-finite floats are written as the strings ``"inf"``, ``"-inf"`` and ``"nan"``
(JSON has no such numbers) and read back as floats, so ``read_record(write_record(r))``
equals ``r``. Readers above this module (the run index, the batch aggregate,
``harm_calibration``) use ``RunRecord``, never string keys into the file.

Versions: a field added with a default keeps the version (older files read with the
default); renaming, removing or changing the meaning of a field raises it, and this
module then reads the older versions it still understands (``READABLE_VERSIONS``).
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ethical_planner.records import from_mapping, to_plain
from mujoco_world.evaluation.avoidability import Avoidability
from mujoco_world.loop.config import RunConfig
from mujoco_world.loop.summary import RunSummary

#: File name of the record inside a run folder.
RECORD_FILE = "summary.json"
#: Value of the ``format`` field that marks a run record.
RECORD_FORMAT = "etp-run-record"
#: Version this module writes.
RECORD_VERSION = 1
#: Versions this module reads.
READABLE_VERSIONS = frozenset({1})


class NotARunRecord(ValueError):
    """A JSON file that is not a run record (for example an impact sweep's summary)."""


@dataclass(frozen=True, slots=True)
class RunRecord:
    """One run as stored in its folder.

    Attributes:
        run_id: the run's id (``run_folder.run_id``), also its folder's name.
        summary: what the closed loop produced (outcome, bodies, collisions, metrics).
        scenario_source: catalog or generated scenario name, or the resolved path of
            the scenario file.
        planner_source: planner name (``mujoco_world.agents`` registry) or the
            planner configuration file.
        config: loop settings of the run (None if it failed before the loop started).
        recording: path of the run's ``.rrd`` recording, or None if none was kept.
        avoidability: the avoidability search's verdict on the run's ego collision
            (``mujoco_world.experiments.avoidability``), or None if not searched.
    """

    run_id: str
    summary: RunSummary
    scenario_source: str = ""
    planner_source: str = ""
    config: RunConfig | None = None
    recording: str | None = None
    avoidability: Avoidability | None = None

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of ``summary.json`` (format and version first)."""
        out: dict[str, Any] = {"format": RECORD_FORMAT, "version": RECORD_VERSION}
        for f in dataclasses.fields(self):
            if f.name != "summary":
                out[f.name] = to_plain(getattr(self, f.name))
        out.update(self.summary.to_dict())
        return out

    @classmethod
    def from_dict(cls, data: Any, where: str = "run record") -> RunRecord:
        """Read the JSON object of ``summary.json``.

        Args:
            data: the decoded JSON.
            where: names the source in error messages (a path).

        Raises:
            NotARunRecord: ``data`` is no run record.
            ValueError: a run record of a version this module cannot read, or a field
                that is missing or malformed (named).
        """
        _check_format(data, where)
        own = {f.name for f in dataclasses.fields(cls)} - {"summary"}
        head = {k: v for k, v in data.items() if k in own}
        body = {k: v for k, v in data.items() if k not in own and k not in ("format", "version")}
        try:
            summary = from_mapping(RunSummary, body, "")
            config = from_mapping(RunConfig, head["config"], "config") if head.get("config") else None
            verdict = head.get("avoidability")
            avoidability = from_mapping(Avoidability, verdict, "avoidability") if verdict else None
            return cls(
                run_id=_text(head, "run_id"),
                summary=summary,
                scenario_source=str(head.get("scenario_source", "")),
                planner_source=str(head.get("planner_source", "")),
                config=config,
                recording=head.get("recording"),
                avoidability=avoidability,
            )
        except ValueError as error:
            raise ValueError(f"{where}: {error}") from None


def _text(head: dict[str, Any], name: str) -> str:
    value = head.get(name)
    if not isinstance(value, str) or not value:
        raise ValueError(f"field {name!r} must be a non-empty string, got {value!r}")
    return value


def _check_format(data: Any, where: str) -> None:
    if not isinstance(data, dict):
        raise NotARunRecord(f"{where}: not a run record (a JSON object with format {RECORD_FORMAT!r})")
    fmt = data.get("format")
    if fmt is None and {"scenario", "planner", "outcome"} <= data.keys():
        raise ValueError(
            f"{where}: a run summary written before run records carried a format and version; "
            f"run it again with this version to read it"
        )
    if fmt != RECORD_FORMAT:
        raise NotARunRecord(f"{where}: not a run record (format {fmt!r}, expected {RECORD_FORMAT!r})")
    version = data.get("version")
    if version not in READABLE_VERSIONS:
        readable = ", ".join(str(v) for v in sorted(READABLE_VERSIONS))
        raise ValueError(
            f"{where}: run record version {version!r} is not supported (this version reads {readable})"
        )


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically; return the path.

    The text goes to ``<path>.tmp``, is flushed to disk (fsync) and renamed over
    ``path``: a reader sees the old file or the whole new one. If writing fails (a full
    disk, a read-only folder), the temporary file is removed, ``path`` is left as it
    was, and the ``OSError`` propagates.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    try:
        with tmp.open("w", encoding="utf-8") as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_json(path: str | Path, data: dict[str, Any]) -> Path:
    """Write ``data`` as JSON to ``path`` atomically (``write_text``); return the path."""
    return write_text(path, json.dumps(data, indent=1, allow_nan=False))


def write_record(run_dir: str | Path, record: RunRecord) -> Path:
    """Write ``record`` to ``run_dir/summary.json`` atomically; return the file."""
    return write_json(Path(run_dir) / RECORD_FILE, record.to_dict())


def read_record(path: str | Path) -> RunRecord:
    """Read a run record from its file or its run folder.

    Raises:
        NotARunRecord: the file is JSON but no run record.
        ValueError: missing or unreadable file, invalid JSON, an unsupported version or
            a malformed field; the message names the file.
    """
    path = Path(path)
    if path.is_dir():
        path = path / RECORD_FILE
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise ValueError(f"cannot read run record {path}: {error.strerror}") from None
    except UnicodeDecodeError:
        raise NotARunRecord(f"{path}: not a run record (not UTF-8 text)") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: not valid JSON: {error}") from None
    return RunRecord.from_dict(data, str(path))


def iter_records(root: str | Path) -> Iterator[tuple[Path, RunRecord]]:
    """Every run record below ``root`` (its folder and the file), sorted by path.

    Files named ``summary.json`` that are not run records (an impact sweep's summary)
    are skipped; a damaged record or one of an unsupported version raises.

    Raises:
        ValueError: ``root`` is not a folder, or a record cannot be read (file named).
    """
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"{root} is not a folder")
    for path in sorted(root.rglob(RECORD_FILE)):
        try:
            yield path, read_record(path)
        except NotARunRecord:
            continue
