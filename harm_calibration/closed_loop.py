"""Collisions of closed-loop runs (``etp run`` / ``etp demo``) as impact rows.

Every ``summary.json`` below a folder is read; each entry of its ``collisions``
list (``ImpactRecord.to_dict``) becomes one row, with the same columns as a sweep.
"""

from __future__ import annotations

import json
from pathlib import Path

from harm_calibration.rows import Row, row_from_record


def find_summaries(root: Path) -> list[Path]:
    """Every ``summary.json`` under ``root``, sorted.

    Raises:
        ValueError: ``root`` is not a folder.
    """
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"--from-runs: {root} is not a folder")
    return sorted(root.rglob("summary.json"))


def rows_from_runs(root: Path) -> list[Row]:
    """Rows of all collisions recorded in the run summaries under ``root``.

    Summaries without a ``collisions`` list (for example an impact sweep's own
    ``summary.json``) are skipped.

    Raises:
        ValueError: a file is not valid JSON or a collision lacks a key (file named).
    """
    root = Path(root)
    rows: list[Row] = []
    for path in find_summaries(root):
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as error:
            raise ValueError(f"{path}: not valid JSON: {error}") from None
        collisions = data.get("collisions") if isinstance(data, dict) else None
        if not isinstance(collisions, list):
            continue
        source = str(path.parent.relative_to(root)) if path.parent != root else "."
        for k, record in enumerate(collisions):
            rows.append(row_from_record(record, source=f"{source}[{k}]"))
    return rows
