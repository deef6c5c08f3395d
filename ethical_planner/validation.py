"""Input validation shared by every layer: one wording for every rejected value.

Records check their fields at construction (``check_finite``, ``check_positive``...,
messages "<owner>.<field> must be ..., got <value>"); vectorised functions check their
array arguments (``finite_array``, ``positive_array``..., messages "<name> must be
..., got <value> at index <i>"); enums parse with ``parse_enum`` ("unknown <what>
<value>; allowed: <every value>"). Every failure is a ``ValueError``.
"""

from __future__ import annotations

import dataclasses
import math
from enum import Enum
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

E = TypeVar("E", bound=Enum)


def check(condition: bool, message: str) -> None:
    """Raise ``ValueError(message)`` unless ``condition`` holds."""
    if not condition:
        raise ValueError(message)


def check_finite(owner: str, **values: float | None) -> None:
    """Raise a ValueError naming ``owner.name`` for a non-finite or non-numeric value (None passes)."""
    for name, value in values.items():
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise ValueError(f"{owner}.{name} must be a finite number, got {value!r}")


def check_positive(owner: str, **values: float | None) -> None:
    """Raise a ValueError naming the field unless every given value is finite and > 0 (None passes)."""
    check_finite(owner, **values)
    for name, value in values.items():
        if value is not None and value <= 0:
            raise ValueError(f"{owner}.{name} must be > 0, got {value!r}")


def check_non_negative(owner: str, **values: float | None) -> None:
    """Raise a ValueError naming the field unless every given value is finite and >= 0 (None passes)."""
    check_finite(owner, **values)
    for name, value in values.items():
        if value is not None and value < 0:
            raise ValueError(f"{owner}.{name} must be >= 0, got {value!r}")


def check_numeric_fields_finite(owner: str, record: Any) -> None:
    """Raise a ValueError naming ``owner.field`` unless every number field of ``record`` is finite.

    Number fields are those declared ``int`` or ``float`` and those holding a number.
    """
    for f in dataclasses.fields(record):
        value = getattr(record, f.name)
        declared = f.type in (int, float, "int", "float")
        if declared or (isinstance(value, float | int) and not isinstance(value, bool)):
            check_finite(owner, **{f.name: value})


def parse_enum(kind: type[E], value: Any, what: str, field: str | None = None) -> E:
    """Return the member of ``kind`` whose value (or which itself) is ``value``.

    Args:
        kind: the enum type.
        value: a member or a member's value.
        what: what the values are, for the message ("harm model").
        field: dotted name of the field being parsed, put in front of the message.

    Raises:
        ValueError: "[<field>: ]unknown <what> <value>; allowed: <every value>".
    """
    try:
        return kind(value)
    except ValueError:
        allowed = ", ".join(str(member.value) for member in kind)
        prefix = f"{field}: " if field else ""
        raise ValueError(f"{prefix}unknown {what} {value!r}; allowed: {allowed}") from None


# --------------------------------------------------------------------------- arrays


def finite_array(name: str, value: ArrayLike, allowed: str = "finite numbers") -> np.ndarray:
    """``value`` as a float array, or a ValueError naming ``name`` and the first bad entry."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {allowed}, got {value!r}") from None
    ok = np.isfinite(array)
    if not ok.all():
        _raise_bad(name, array, ok, allowed)
    return array


def non_negative_array(name: str, value: ArrayLike, unit: str) -> np.ndarray:
    """``value`` as a float array of finite values >= 0 [``unit``], or a ValueError naming it."""
    return _array_where(name, value, f"finite and >= 0 {unit}", np.greater_equal)


def positive_array(name: str, value: ArrayLike, unit: str) -> np.ndarray:
    """``value`` as a float array of finite values > 0 [``unit``], or a ValueError naming it."""
    return _array_where(name, value, f"finite and > 0 {unit}", np.greater)


def _array_where(name: str, value: ArrayLike, allowed: str, compare: np.ufunc) -> np.ndarray:
    array = finite_array(name, value, allowed)
    ok = compare(array, 0.0)
    if not ok.all():
        _raise_bad(name, array, ok, allowed)
    return array


def vector_array(name: str, value: ArrayLike, unit: str) -> np.ndarray:
    """``value`` as a finite float array of planar vectors, shape (..., 2), or a ValueError naming it."""
    array = finite_array(name, value, f"finite {unit}")
    if array.ndim == 0 or array.shape[-1] != 2:
        raise ValueError(f"{name} must have shape (..., 2) {unit}, got shape {array.shape}")
    return array


def shaped_array(
    name: str, value: ArrayLike, expected: str, ndim: int | None = None, shape: tuple[int, ...] | None = None
) -> np.ndarray:
    """``value`` as a finite float64 array of rank ``ndim`` and ``shape``.

    Args:
        name: argument name for the message.
        value: the argument.
        expected: the shape in words, e.g. "(n_traj, n_t)".
        ndim: required rank, or None.
        shape: required shape, or None.

    Raises:
        ValueError: wrong rank or shape, or a non-finite entry; the message names ``name``.
    """
    array = np.asarray(value, dtype=np.float64)
    if ndim is not None and array.ndim != ndim:
        raise ValueError(f"{name} must have shape {expected}, got {array.shape}")
    if shape is not None:
        check_shape(name, array, expected, shape)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite")
    return array


def check_shape(name: str, array: np.ndarray, expected: str, shape: tuple[int, ...]) -> None:
    """Raise a ValueError naming ``name`` unless ``array`` has ``shape`` (``expected`` in words)."""
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {expected} = {shape}, got {array.shape}")


def _raise_bad(name: str, array: np.ndarray, ok: np.ndarray, allowed: str) -> None:
    if array.ndim == 0:
        raise ValueError(f"{name} must be {allowed}, got {array.item()!r}")
    index = tuple(int(i) for i in np.argwhere(~ok)[0])
    raise ValueError(f"{name} must be {allowed}, got {array[index].item()!r} at index {index}")


__all__ = [
    "check",
    "check_finite",
    "check_non_negative",
    "check_numeric_fields_finite",
    "check_positive",
    "check_shape",
    "finite_array",
    "non_negative_array",
    "parse_enum",
    "positive_array",
    "shaped_array",
    "vector_array",
]
