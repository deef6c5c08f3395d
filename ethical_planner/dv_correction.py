"""Correction of the plastic delta-v (paper Eq. 1) towards measured impacts.

Eq. 1 assumes the two bodies end with a common velocity. Measured impacts
(``harm_calibration``) show that this holds for central hits but not for glancing
ones, where the bodies slide off each other and the delta-v is smaller. A
``DeltaVCorrection`` multiplies the Eq. 1 delta-v by a factor looked up in a table
over two quantities the planner can compute from the pre-impact states:

- the angle between the two velocity directions (0 = rear-end, 90 deg = T-bone,
  180 deg = head-on), ``ethical_planner.geometry.velocity_angle``;
- the impact offset fraction (0 = central, 1 = grazing),
  ``ethical_planner.geometry.impact_offset_fraction``.

Both bodies of an impact share one factor, since both delta-v come from one impulse.
The table is fitted by ``harm_calibration.calibration``; this module only applies it,
so the planner needs nothing above its own layer.

Planner use::

    corr = DeltaVCorrection.load(path)
    offset = impact_offset_fraction(ego_pos, ego_vel, ego_yaw, 4.508, 1.610,
                                    obs_pos, obs_vel, obs_yaw, obs_len, obs_wid)
    dv = corr(dv_eq1, velocity_angle(ego_vel, obs_vel, ego_yaw, obs_yaw), offset)
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ethical_planner.geometry import wrap_angle

#: Default bin edges of the angle between the velocity directions [deg] (15-deg bins
#: centred on multiples of 15 deg, half bins at 0 and 180 deg).
DEFAULT_ANGLE_EDGES_DEG = (
    0.0, 7.5, 22.5, 37.5, 52.5, 67.5, 82.5, 97.5, 112.5, 127.5, 142.5, 157.5, 172.5, 180.0,
)  # fmt: skip
#: Default bin edges of the impact offset fraction [-] (bins centred on 0, 0.25, 0.5, 0.75, 1).
DEFAULT_OFFSET_EDGES = (0.0, 0.125, 0.375, 0.625, 0.875, 1.0)

_KEYS = ("angle_edges_deg", "offset_edges", "factors", "n_train")
_REQUIRED = ("angle_edges_deg", "offset_edges", "factors")


def _edges(name: str, edges: Sequence[float], low: float, high: float) -> tuple[float, ...]:
    array = np.asarray(edges, dtype=float)
    if array.ndim != 1 or array.size < 2 or not np.all(np.isfinite(array)):
        raise ValueError(f"DeltaVCorrection.{name} needs >= 2 finite values, got {edges!r}")
    if array[0] != low or array[-1] != high or np.any(np.diff(array) <= 0):
        raise ValueError(f"DeltaVCorrection.{name} must increase from {low:g} to {high:g}, got {edges!r}")
    return tuple(float(e) for e in array)


@dataclass(frozen=True, slots=True)
class DeltaVCorrection:
    """Delta-v correction factor per bin of (velocity angle, impact offset fraction).

    Attributes:
        angle_edges_deg: increasing bin edges of the angle between the velocity
            directions [deg], from 0 to 180, length n_angle + 1.
        offset_edges: increasing bin edges of the offset fraction [-], from 0 to 1,
            length n_offset + 1.
        factors: measured / Eq. 1 factor, n_angle rows of n_offset values, > 0.
        n_train: training impacts per bin, same layout as ``factors`` (empty: unknown).
            Bins with few impacts hold a fall-back factor (see the fit).
    """

    angle_edges_deg: tuple[float, ...]
    offset_edges: tuple[float, ...]
    factors: tuple[tuple[float, ...], ...]
    n_train: tuple[tuple[int, ...], ...] = ()
    _table: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        angle_edges = _edges("angle_edges_deg", self.angle_edges_deg, 0.0, 180.0)
        offset_edges = _edges("offset_edges", self.offset_edges, 0.0, 1.0)
        shape = (len(angle_edges) - 1, len(offset_edges) - 1)
        try:
            table = np.array(self.factors, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(
                f"DeltaVCorrection.factors must be a table of numbers, got {self.factors!r}"
            ) from None
        if table.shape != shape:
            raise ValueError(
                f"DeltaVCorrection.factors needs shape {shape} (one row per angle bin, one value per "
                f"offset bin), got shape {table.shape}"
            )
        if not np.all(np.isfinite(table) & (table > 0.0)):
            raise ValueError(f"DeltaVCorrection.factors must be finite and > 0, got {self.factors!r}")
        counts = np.array(self.n_train, dtype=int) if len(self.n_train) else np.zeros((0,), dtype=int)
        if counts.size and counts.shape != shape:
            raise ValueError(f"DeltaVCorrection.n_train needs shape {shape}, got shape {counts.shape}")
        if np.any(counts < 0):
            raise ValueError("DeltaVCorrection.n_train must be >= 0")
        table.flags.writeable = False
        object.__setattr__(self, "angle_edges_deg", angle_edges)
        object.__setattr__(self, "offset_edges", offset_edges)
        object.__setattr__(self, "factors", tuple(tuple(float(f) for f in row) for row in table))
        object.__setattr__(self, "n_train", tuple(tuple(int(n) for n in row) for row in counts))
        object.__setattr__(self, "_table", table)

    @classmethod
    def identity(cls) -> DeltaVCorrection:
        """The correction with factor 1 everywhere (Eq. 1 unchanged)."""
        return cls((0.0, 180.0), (0.0, 1.0), ((1.0,),))

    @property
    def shape(self) -> tuple[int, int]:
        """(n_angle, n_offset) bins."""
        return self._table.shape

    def factor(self, angle: ArrayLike, offset_fraction: ArrayLike) -> np.ndarray:
        """Correction factor, vectorised.

        Args:
            angle: angle between the velocity directions [rad], any shape; folded
                into [0, pi] (sign and full turns do not matter).
            offset_fraction: impact offset fraction [-], broadcastable; clipped to [0, 1].

        Returns:
            Factor, the broadcast shape; nan where an input is nan.
        """
        a = np.asarray(angle, dtype=float)
        o = np.asarray(offset_fraction, dtype=float)
        folded = np.degrees(np.abs(wrap_angle(a)))
        n_angle, n_offset = self._table.shape
        ia = np.clip(np.searchsorted(self.angle_edges_deg, folded, side="right") - 1, 0, n_angle - 1)
        io = np.clip(
            np.searchsorted(self.offset_edges, np.clip(o, 0.0, 1.0), side="right") - 1, 0, n_offset - 1
        )
        out = self._table[ia, io]
        bad = np.isnan(a) | np.isnan(o)
        return np.where(bad, np.nan, out) if bad.any() else out

    def __call__(self, dv_eq1: ArrayLike, angle: ArrayLike, offset_fraction: ArrayLike) -> np.ndarray:
        """Corrected delta-v.

        Args:
            dv_eq1: delta-v of paper Eq. 1 [m/s], any shape.
            angle: angle between the two velocity directions [rad] (the alpha of Eq. 1),
                broadcastable against ``dv_eq1``.
            offset_fraction: impact offset fraction [-] (``impact_offset_fraction``),
                broadcastable.

        Returns:
            Corrected delta-v [m/s], the broadcast shape.
        """
        return np.asarray(dv_eq1, dtype=float) * self.factor(angle, offset_fraction)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict (the keys of ``from_dict``)."""
        return {
            "angle_edges_deg": list(self.angle_edges_deg),
            "offset_edges": list(self.offset_edges),
            "factors": [list(row) for row in self.factors],
            "n_train": [list(row) for row in self.n_train],
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> DeltaVCorrection:
        """Inverse of ``to_dict``.

        Raises:
            ValueError: not a dict, unknown or missing keys (named), or invalid values.
        """
        if not isinstance(data, dict):
            raise ValueError(f"DeltaVCorrection: expected a JSON object, got {type(data).__name__}")
        unknown = sorted(set(data) - set(_KEYS))
        if unknown:
            raise ValueError(f"DeltaVCorrection: unknown keys {unknown}; allowed: {list(_KEYS)}")
        missing = [k for k in _REQUIRED if k not in data]
        if missing:
            raise ValueError(f"DeltaVCorrection: missing keys {missing}")
        for key, rows in (
            ("angle_edges_deg", False),
            ("offset_edges", False),
            ("factors", True),
            ("n_train", True),
        ):
            value = data.get(key, [])
            if not isinstance(value, list) or (rows and not all(isinstance(row, list) for row in value)):
                shape = "a list of rows (lists of numbers)" if rows else "a list of numbers"
                raise ValueError(f"DeltaVCorrection.{key} must be {shape}, got {value!r}")
        return cls(
            tuple(data["angle_edges_deg"]),
            tuple(data["offset_edges"]),
            tuple(tuple(row) for row in data["factors"]),
            tuple(tuple(row) for row in data.get("n_train", ())),
        )

    def save(self, path: Path | str) -> None:
        """Write the JSON file."""
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n", encoding="utf-8")

    @classmethod
    def load(cls, path: Path | str) -> DeltaVCorrection:
        """Read a JSON file written by ``save``.

        Raises:
            ValueError: not valid JSON, or ``from_dict`` rejects it; the message names the file.
        """
        try:
            data = json.loads(Path(path).read_text(encoding="utf-8"))
        except json.JSONDecodeError as error:
            raise ValueError(f"{path}: not valid JSON: {error}") from None
        except UnicodeDecodeError as error:
            raise ValueError(f"{path}: not UTF-8 text (byte {error.start})") from None
        try:
            return cls.from_dict(data)
        except ValueError as error:
            raise ValueError(f"{path}: {error}") from None


__all__ = [
    "DEFAULT_ANGLE_EDGES_DEG",
    "DEFAULT_OFFSET_EDGES",
    "DeltaVCorrection",
]
