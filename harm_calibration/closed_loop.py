"""Collisions of closed-loop runs (``etp run`` / ``etp demo``) as impact rows.

Every run record below a folder is read (``mujoco_world.storage.run_record``); each
of its collisions becomes one row, with the same columns as a sweep and the offset
computed from the shapes of the bodies that collided, as the run simulated them.
"""

from __future__ import annotations

from pathlib import Path

from harm_calibration.rows import Row, row_from_impact
from mujoco_world.storage.run_record import iter_records


def rows_from_runs(root: Path) -> list[Row]:
    """Rows of all collisions recorded in the run records under ``root``.

    Files named ``summary.json`` that are not run records (for example an impact
    sweep's own summary) are skipped.

    Raises:
        ValueError: ``root`` is not a folder, or a record cannot be read (file named).
    """
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"--from-runs: {root} is not a folder")
    rows: list[Row] = []
    for path, record in iter_records(root):
        summary = record.summary
        source = str(path.parent.relative_to(root)) if path.parent != root else "."
        for k, impact in enumerate(summary.collisions):
            rows.append(row_from_impact(impact, source=f"{source}[{k}]", bodies=summary.bodies))
    return rows
