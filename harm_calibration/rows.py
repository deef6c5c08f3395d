"""Flat table rows of measured-versus-predicted impacts, and their CSV file.

One row per impact, the same columns for controlled sweeps and for collisions of
closed-loop runs. Both are built from the typed ``mujoco_world.evaluation.compare.
ImpactRecord`` (a run's collisions come from its ``RunRecord``, with the run's body
shapes), so the two sources are compared identically.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ethical_planner.geometry import impact_offset_fraction, velocity_angle
from harm_calibration.geometry import STATIC, classify
from mujoco_world.evaluation.compare import ImpactRecord
from mujoco_world.loop.summary import BodyRecord

#: Identification and design columns (sweep design values; derived for runs).
KEY_COLUMNS = (
    "id", "source", "partner", "closing_speed", "angle_deg", "offset", "restitution_set",
    "mode", "cell", "class", "status",
)  # fmt: skip
_BODY_FIELDS = (
    "type", "mass", "speed", "dv_measured", "dv_first", "dv_com", "dv_predicted", "dv_error",
    "dv_planar", "dv_error_planar", "area_measured", "area_predicted", "clock_measured",
    "clock_predicted", "model", "harm_measured", "harm_predicted", "harm_planar",
)  # fmt: skip
_MEASUREMENT_FIELDS = (
    "restitution", "duration", "peak_force", "peak_time", "max_penetration", "n_impulses",
    "first_impulse_share",
)  # fmt: skip
#: Pre-impact state of each body (world frame, the step before the first contact force):
#: x, y [m], yaw [rad], vx, vy [m/s], yaw rate [rad/s], footprint length and width [m].
STATE_FIELDS = ("x", "y", "yaw", "vx", "vy", "yaw_rate", "length", "width")
#: The sequence-aware planar model (``harm_calibration.sequence``), per body: delta-v [m/s],
#: its relative error, harm; and the number of pulses it predicts.
SEQUENCE_FIELDS = ("dv_planar_seq", "dv_error_planar_seq", "harm_planar_seq")
#: Columns added after the first release of the table: an older ``impacts.csv`` without
#: them is read with nan (the sequence model then reports no errors for it).
OPTIONAL_COLUMNS = (
    tuple(f"{f}_{s}" for s in ("a", "b") for f in STATE_FIELDS)
    + tuple(f"{f}_{s}" for s in ("a", "b") for f in SEQUENCE_FIELDS)
    + ("n_pulses_planar_seq",)
)
#: Every column of ``impacts.csv``, in order.
COLUMNS = (
    KEY_COLUMNS
    + tuple(f"{f}_{s}" for s in ("a", "b") for f in _BODY_FIELDS)
    + _MEASUREMENT_FIELDS
    + ("multi_impact",)
    + OPTIONAL_COLUMNS
)
_TEXT = frozenset(
    {"id", "source", "partner", "restitution_set", "mode", "cell", "class", "status", "multi_impact"}
    | {f"{f}_{s}" for s in ("a", "b") for f in ("type", "area_measured", "area_predicted", "model")}
)

Row = dict[str, Any]


def _num(value: float | None) -> float:
    """A CSV number: None and infinite values (a wall's mass) become nan."""
    return math.nan if value is None or math.isinf(value) else float(value)


def row_from_impact(
    impact: ImpactRecord,
    *,
    source: str,
    design: Mapping[str, Any] | None = None,
    bodies: Sequence[BodyRecord] = (),
) -> Row:
    """Flatten one measured impact and its prediction into a table row.

    Args:
        impact: the measured collision with the model's prediction beside it.
        source: where it came from (sweep case id or run folder).
        design: sweep design values (``id``, ``partner``, ``closing_speed`` [m/s],
            ``angle_deg`` [deg], ``offset`` [-], ``restitution_set``); derived from the
            pre-impact states when None.
        bodies: the run's bodies (``RunSummary.bodies``): their shapes give the
            offset fraction when ``design`` is None.

    Returns:
        A dict with every column of ``COLUMNS``.

    Raises:
        ValueError: ``design`` is None and a colliding body is not among ``bodies``.
    """
    meas = impact.measurement
    row: Row = {c: math.nan for c in COLUMNS}
    for side, body, c in (("a", meas.a, impact.a), ("b", meas.b, impact.b)):
        row[f"type_{side}"] = body.type
        row[f"mass_{side}"] = _num(body.mass)
        row[f"speed_{side}"] = float(np.hypot(*body.velocity))
        for field in (
            "dv_measured", "dv_first", "dv_com", "dv_predicted", "dv_error", "dv_planar",
            "dv_error_planar", "clock_measured", "clock_predicted", "harm_measured",
            "harm_predicted", "harm_planar",
        ):  # fmt: skip
            row[f"{field}_{side}"] = _num(getattr(c, field))
        row[f"area_measured_{side}"] = c.area_measured or ""
        row[f"area_predicted_{side}"] = c.area_predicted or ""
        row[f"model_{side}"] = c.model or ""
        if not body.is_static:
            state = (*body.position, body.yaw, *body.velocity, body.yaw_rate, body.length, body.width)
            for field, value in zip(STATE_FIELDS, state, strict=True):
                row[f"{field}_{side}"] = float(value)
    for field in ("restitution", "duration", "peak_force", "peak_time", "max_penetration"):
        row[field] = _num(getattr(meas, field))
    row["n_impulses"] = float(meas.n_impulses)
    row["first_impulse_share"] = meas.first_impulse_share if meas.impulses else math.nan
    row["multi_impact"] = "yes" if meas.multi_impact else "no"
    row["status"] = "ok" if meas.complete else "incomplete"
    row["source"] = source
    if design is not None:
        row.update(design)
        row["source"] = source
        return row
    a, b = meas.a, meas.b
    va, vb = np.asarray(a.velocity, float), np.asarray(b.velocity, float)
    rel_vel = vb - va
    row["id"] = f"{source}#{meas.time:.3f}:{a.name}-{b.name}"
    row["closing_speed"] = float(np.hypot(*rel_vel))
    row["restitution_set"] = "run"
    row["mode"] = "run"
    row["cell"] = ""
    if b.is_static:
        row["partner"] = b.type or STATIC
        row["class"] = STATIC
        return row
    row["partner"] = b.type
    # A body at rest has no velocity direction: its heading stands in for it.
    row["angle_deg"] = math.degrees(float(velocity_angle(va, vb, a.yaw, b.yaw)))
    shapes = {body.id: (body.length, body.width) for body in bodies}
    missing = [body.name for body in (a, b) if body.entity not in shapes]
    if missing:
        raise ValueError(f"{source}: the run's bodies lack {', '.join(missing)} (no shape for the offset)")
    offset = impact_offset_fraction(
        a.position, va, a.yaw, *shapes[a.entity], b.position, vb, b.yaw, *shapes[b.entity]
    )
    row["offset"] = float(offset)
    row["class"] = classify(row["angle_deg"], row["offset"])
    return row


def write_rows(path: Path, rows: Iterable[Row], append: bool = False) -> int:
    """Write rows to a CSV with the header ``COLUMNS`` (appended without header if ``append``).

    Returns:
        The number of rows written.
    """
    mode = "a" if append and path.exists() else "w"
    count = 0
    with path.open(mode, newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=COLUMNS, extrasaction="ignore")
        if mode == "w":
            writer.writeheader()
        for row in rows:
            writer.writerow({k: _fmt(row.get(k, math.nan)) for k in COLUMNS})
            count += 1
    return count


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else repr(value)
    return str(value)


def read_rows(path: Path) -> list[Row]:
    """Read an ``impacts.csv``; numeric columns become floats.

    Raises:
        ValueError: the header lacks a column of ``COLUMNS`` (named) or a number is malformed.
    """
    with path.open(newline="", encoding="utf-8") as handle:
        reader = csv.DictReader(handle)
        present = set(reader.fieldnames or ())
        missing = [c for c in COLUMNS if c not in present and c not in OPTIONAL_COLUMNS]
        if missing:
            raise ValueError(f"{path}: missing columns {missing}")
        rows = []
        for line, raw in enumerate(reader, start=2):
            row: Row = {}
            for key in COLUMNS:
                if key not in present:
                    row[key] = math.nan
                    continue
                text = raw[key]
                if key in _TEXT:
                    row[key] = text
                    continue
                try:
                    row[key] = float(text)
                except (TypeError, ValueError):
                    raise ValueError(
                        f"{path} line {line}: column {key!r} is not a number: {text!r}"
                    ) from None
            rows.append(row)
    return rows


def column(rows: Sequence[Row], key: str) -> np.ndarray:
    """One numeric column as a float array, shape (n_rows,)."""
    return np.array([float(r[key]) for r in rows], dtype=float)
