"""The sequence-aware planar impulse model on an impact table (a third model beside Eq. 1).

``ethical_planner.impulse.planar_impulse_sequence`` predicts the delta-v of the whole
impact sequence: the planar impulse at the first contact, then the bodies moved on with
their new velocities and yaw rates, skidding at the tyre limit as the world's crashed
bodies do (``mujoco_world.physics.impact.skid_model``), the next contact and its
impulse, and so on, with the world's sequence rules (``MeasurementWindow``). It runs
here, after the physics, vectorised over every row with a pre-impact state (one call
per restitution law), from the same pre-impact states the other models use.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ethical_planner.config import RiskConfig
from ethical_planner.harm import HarmModel, harm
from ethical_planner.impulse import RestitutionLaw, planar_impulse_sequence
from ethical_planner.road_users import RoadUserType
from harm_calibration.rows import Row, column
from harm_calibration.sweep import RESTITUTION_SETS, restitution_for
from mujoco_world.physics.impact import MeasurementWindow, skid_model


def _law(restitution_set: str) -> RestitutionLaw:
    """The restitution law of a row: its sweep setting, else the planner's default (runs)."""
    if restitution_set in RESTITUTION_SETS:
        return restitution_for(restitution_set)
    return RiskConfig().restitution_law


def clock_angle(clock: np.ndarray) -> np.ndarray:
    """Angle [rad] of a clock position 1..12 (12 = 0, 3 = -pi/2, 9 = +pi/2), shape kept.

    The inverse of ``harm.clock_area`` on bin centres; the reduced area of the angle is
    that of any angle in the bin, so harm from it equals harm from the geometric angle for
    every area model.
    """
    return np.radians(np.remainder(12.0 - np.asarray(clock, dtype=float), 12.0) * 30.0)


def add_sequence_model(rows: Sequence[Row], window: MeasurementWindow | None = None) -> list[Row]:
    """Rows with the sequence model's columns (``rows.SEQUENCE_FIELDS``, ``n_pulses_planar_seq``).

    Rows without a pre-impact state of both bodies (walls, older tables, misses) get nan.

    Args:
        rows: impact rows (any source).
        window: the world's sequence rules (default ``MeasurementWindow()``).

    Returns:
        New row dicts, in the same order.
    """
    window = window or MeasurementWindow()
    out = [dict(r) for r in rows]
    for r in out:
        for side in ("a", "b"):
            for field in ("dv_planar_seq", "dv_error_planar_seq", "harm_planar_seq"):
                r[f"{field}_{side}"] = math.nan
        r["n_pulses_planar_seq"] = math.nan
    if not out:
        return out
    ready = np.isfinite(column(out, "x_a")) & np.isfinite(column(out, "x_b"))
    ready &= np.array([r.get("status") in ("ok", "incomplete") for r in out])
    skid = skid_model(window=window)
    laws: dict[str, list[int]] = {}
    for i in np.flatnonzero(ready):
        laws.setdefault(out[i]["restitution_set"], []).append(int(i))
    friction = RiskConfig().impulse_ratio
    for restitution_set, index in laws.items():
        sel = [out[i] for i in index]

        def col(key: str, sel: list[Row] = sel) -> np.ndarray:
            return column(sel, key)

        seq = planar_impulse_sequence(
            col("mass_a"), np.stack([col("x_a"), col("y_a")], -1), col("yaw_a"), col("length_a"),
            col("width_a"), np.stack([col("vx_a"), col("vy_a")], -1),
            col("mass_b"), np.stack([col("x_b"), col("y_b")], -1), col("yaw_b"), col("length_b"),
            col("width_b"), np.stack([col("vx_b"), col("vy_b")], -1),
            _law(restitution_set), friction,
            round_a=np.array([r["type_a"] == RoadUserType.PEDESTRIAN.value for r in sel]),
            round_b=np.array([r["type_b"] == RoadUserType.PEDESTRIAN.value for r in sel]),
            yaw_rate_a=col("yaw_rate_a"), yaw_rate_b=col("yaw_rate_b"), skid=skid,
            pulse_gap=window.pulse_gap, separation_time=window.separation_time,
            max_duration=window.max_duration,
        )  # fmt: skip
        for k, r in enumerate(sel):
            r["n_pulses_planar_seq"] = float(seq.n_pulses[k])
            for side, dv in (("a", float(seq.dv_a[k])), ("b", float(seq.dv_b[k]))):
                r[f"dv_planar_seq_{side}"] = dv
                measured = r[f"dv_measured_{side}"]
                r[f"dv_error_planar_seq_{side}"] = (measured - dv) / dv if dv > 1e-9 else math.nan
                model = r.get(f"model_{side}") or ""
                if model:
                    angle = clock_angle(r[f"clock_predicted_{side}"])
                    r[f"harm_planar_seq_{side}"] = float(harm(HarmModel.parse(model), dv, angle))
    return out


__all__ = ["add_sequence_model", "clock_angle"]
