"""Helpers shared by the frozen records of ``mujoco_world``: validation and loading.

``from_mapping`` builds a nested frozen dataclass from plain dicts and lists (as read
from TOML), rejects unknown keys by their dotted name and prefixes every error raised
by a record's ``__post_init__`` with the path of the offending record.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import re
import types
import typing
from collections.abc import Mapping
from typing import Any, TypeVar

import numpy as np

from ethical_planner.enums import parse_enum as shared_parse_enum

T = TypeVar("T")


def check(condition: bool, message: str) -> None:
    """Raise ``ValueError(message)`` unless ``condition`` holds."""
    if not condition:
        raise ValueError(message)


def check_finite(owner: str, **values: float | None) -> None:
    """Raise a ValueError naming ``owner.name`` for every non-finite (or non-numeric) value."""
    for name, value in values.items():
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise ValueError(f"{owner}.{name} must be a finite number, got {value!r}")


def check_positive(owner: str, **values: float | None) -> None:
    """Raise a ValueError naming the field unless every given value is finite and > 0."""
    check_finite(owner, **values)
    for name, value in values.items():
        if value is not None and value <= 0:
            raise ValueError(f"{owner}.{name} must be > 0, got {value!r}")


def check_non_negative(owner: str, **values: float | None) -> None:
    """Raise a ValueError naming the field unless every given value is finite and >= 0."""
    check_finite(owner, **values)
    for name, value in values.items():
        if value is not None and value < 0:
            raise ValueError(f"{owner}.{name} must be >= 0, got {value!r}")


def parse_enum(enum_type: type[enum.Enum], owner: str, name: str, value: Any) -> Any:
    """Return ``enum_type(value)`` or raise a ValueError naming the field and the allowed values."""
    try:
        return shared_parse_enum(enum_type, value, "value")
    except ValueError as error:
        raise ValueError(f"{owner}.{name}: {error}") from None


def knots(owner: str, name: str, value: Any) -> tuple[tuple[float, float], ...]:
    """Validate a sequence of (time [s], value) knots with strictly increasing times."""
    try:
        pairs = tuple((float(t), float(v)) for t, v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}.{name} must be a list of [time, value] pairs, got {value!r}") from None
    for t, v in pairs:
        if not (math.isfinite(t) and math.isfinite(v)):
            raise ValueError(f"{owner}.{name} must hold finite numbers, got {value!r}")
    times = [t for t, _ in pairs]
    if any(b <= a for a, b in zip(times, times[1:], strict=False)) or (times and times[0] < 0):
        raise ValueError(f"{owner}.{name} times must be >= 0 and strictly increasing, got {times}")
    return pairs


def _unwrap_optional(tp: Any) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return tp


def from_mapping(cls: type[T], data: Any, path: str = "") -> T:
    """Build the frozen dataclass ``cls`` from nested mappings and lists.

    Args:
        cls: a dataclass type whose fields may be dataclasses, tuples of dataclasses,
            enums or plain values.
        data: a mapping of field names to values (e.g. a TOML table).
        path: dotted name of ``data`` used in error messages.

    Raises:
        ValueError: unknown or missing keys, or an invalid value; the message starts
            with the dotted name of the field.
    """
    where = path or cls.__name__
    if isinstance(data, cls):
        return data
    if not isinstance(data, Mapping):
        raise ValueError(f"{where} must be a table of keys, got {data!r}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}  # type: ignore[arg-type]
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ValueError(f"{where}: unknown key {unknown[0]!r}; allowed: {', '.join(sorted(fields))}")
    kwargs: dict[str, Any] = {}
    for name, value in data.items():
        kwargs[name] = _convert(hints[name], value, f"{path}.{name}" if path else name)
    try:
        return cls(**kwargs)
    except TypeError as error:  # a required field is missing
        raise ValueError(f"{where}: {error}") from None
    except ValueError as error:
        raise ValueError(_prefixed(path, str(error))) from None


def _prefixed(path: str, message: str) -> str:
    """Put the dotted ``path`` in front of a record's own message.

    A message that starts with the record's short name ("behaviour.speed ...") gets
    that name replaced by the full path ("road_users[2].behaviour.speed ...").
    """
    if not path:
        return message
    leaf = path.rsplit(".", 1)[-1]
    base = re.sub(r"\[\d+\]$", "", leaf)
    for name in (base, base.rstrip("s")):
        if message.startswith(name + "."):
            return f"{path}.{message[len(name) + 1 :]}"
    return f"{path}: {message}"


def _convert(tp: Any, value: Any, path: str) -> Any:
    tp = _unwrap_optional(tp)
    if value is None:
        return None
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return from_mapping(tp, value, path)
    origin = typing.get_origin(tp)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, list | tuple):
            raise ValueError(f"{path} must be a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{path}[{i}]") for i, v in enumerate(value))
        return tuple(value)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return value  # records parse their own enums with a message naming the field
    if tp is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def to_plain(obj: Any) -> Any:
    """JSON-able copy of a record: dataclasses to dicts, enums to values, arrays to lists."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, enum.Enum):
        return obj.value
    if isinstance(obj, np.ndarray):
        return to_plain(obj.tolist())
    if isinstance(obj, np.generic):
        return to_plain(obj.item())
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Mapping):
        return {str(k): to_plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_plain(v) for v in obj]
    return obj
