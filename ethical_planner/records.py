"""Frozen records from and to plain data: TOML tables in, JSON-able dicts out.

One loader for every nested frozen dataclass of the project (planner configuration,
scenarios): ``from_mapping`` builds a record from nested dicts and lists, or applies
them as overrides to an existing record (``base``); it rejects unknown keys by their
dotted name (``weights.bogus``, ``road_users[2].behaviour.sped``) and puts the dotted
path of the offending record in front of every error its ``__post_init__`` raises.
``read_toml`` and ``errors_in`` name the file. ``to_plain`` is the way back (to
JSON): non-finite floats become the strings ``"inf"``, ``"-inf"`` and ``"nan"`` (JSON
has no such numbers), which ``from_mapping`` reads back as floats where the field is a
float, so a record survives the round trip exactly (run records rely on it).

Why not a library: cattrs, dacite and pydantic were weighed against this ~150-line
module. None of them puts the dotted path in front of the ``ValueError`` that a
record's own ``__post_init__`` raises (dacite lets it through unchanged, cattrs wraps
it into an exception group, pydantic wants its own validators instead), dacite names
no path for unknown keys, and the planner layer depends on numpy, scipy and shapely
only (SPEC section 1).
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import math
import re
import tomllib
import types
import typing
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

T = TypeVar("T")
#: JSON spelling of the non-finite floats (``to_plain`` writes them, ``from_mapping`` reads them).
NON_FINITE = {"inf": math.inf, "-inf": -math.inf, "nan": math.nan}


def from_mapping(cls: type[T], data: Any, path: str = "", base: T | None = None) -> T:
    """Build the frozen dataclass ``cls`` from nested mappings and lists.

    Args:
        cls: a dataclass type whose fields may be dataclasses, tuples of dataclasses,
            enums or plain values (records parse their own enums).
        data: a mapping of field names to values (e.g. a TOML table).
        path: dotted name of ``data`` used in error messages ("" at the top).
        base: an existing record to override: fields missing from ``data`` keep its
            values, nested tables override its nested records key by key.

    Returns:
        The record (``data`` itself if it already is one).

    Raises:
        ValueError: an unknown key (named with its dotted path, the message lists the
            allowed keys), a missing required key, a value of the wrong kind, or the
            record's own validation; the message starts with the dotted field.
    """
    where = path or cls.__name__
    if isinstance(data, cls):
        return data
    if not isinstance(data, Mapping):
        raise ValueError(f"{where} must be a table of keys, got {data!r}")
    hints = typing.get_type_hints(cls)
    fields = {f.name for f in dataclasses.fields(cls) if f.init}  # type: ignore[arg-type]
    for key in data:
        if key not in fields:
            raise ValueError(f"unknown key {_join(path, key)!r}; allowed: {', '.join(sorted(fields))}")
    if base is None:
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
            if f.init and required and f.name not in data:
                raise ValueError(f"missing key {_join(path, f.name)!r}")
    kwargs: dict[str, Any] = {}
    for name, value in data.items():
        current = getattr(base, name) if base is not None else None
        kwargs[name] = _convert(hints[name], value, _join(path, name), current)
    try:
        return dataclasses.replace(base, **kwargs) if base is not None else cls(**kwargs)  # type: ignore[type-var]
    except TypeError as error:  # a value of the wrong kind met the record's checks
        raise ValueError(f"{where}: {error}") from None
    except ValueError as error:
        raise ValueError(_prefixed(path, str(error))) from None


def read_toml(path: str | Path, what: str) -> dict[str, Any]:
    """The tables of a TOML file.

    Args:
        path: the file.
        what: what the file holds, for messages ("scenario").

    Raises:
        ValueError: "cannot read <what> file <path>: <reason>", "<path>: not valid TOML: ..."
            or "<path>: not UTF-8 text ...".
    """
    try:
        with open(path, "rb") as handle:
            return tomllib.load(handle)
    except OSError as error:
        raise ValueError(f"cannot read {what} file {path}: {error.strerror}") from None
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"{path}: not valid TOML: {error}") from None
    except UnicodeDecodeError as error:
        raise ValueError(f"{path}: not UTF-8 text (byte {error.start}); TOML files are UTF-8") from None


@contextlib.contextmanager
def errors_in(path: str | Path) -> Iterator[None]:
    """Put ``<path>: `` in front of every ValueError raised inside the block."""
    try:
        yield
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None


def to_plain(obj: Any) -> Any:
    """JSON-able copy of a record: dataclasses to dicts, enums to values, arrays to lists.

    Non-finite floats become "inf", "-inf" or "nan" (read back by ``from_mapping``).
    """
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, enum.Enum):
        return obj.value
    if isinstance(obj, np.ndarray):
        return to_plain(obj.tolist())
    if isinstance(obj, np.generic):
        return to_plain(obj.item())
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else str(obj)
    if isinstance(obj, Mapping):
        return {str(k): to_plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_plain(v) for v in obj]
    return obj


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


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


def _unwrap_optional(tp: Any) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return tp


def _convert(tp: Any, value: Any, path: str, current: Any = None) -> Any:
    tp = _unwrap_optional(tp)
    if value is None:
        return None
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return from_mapping(tp, value, path, base=current if isinstance(current, tp) else None)
    origin = typing.get_origin(tp)
    if origin is tuple:
        return _convert_tuple(typing.get_args(tp), value, path)
    if origin is dict:
        return _convert_dict(typing.get_args(tp), value, path)
    return _convert_scalar(tp, value, path)


def _convert_tuple(args: tuple[Any, ...], value: Any, path: str) -> tuple[Any, ...]:
    """``tuple[X, ...]`` converts every item to X, ``tuple[X, Y]`` item by item."""
    if not isinstance(value, list | tuple):
        raise ValueError(f"{path} must be a list, got {value!r}")
    if len(args) == 2 and args[1] is Ellipsis:
        return tuple(_convert(args[0], v, f"{path}[{i}]") for i, v in enumerate(value))
    if args and len(args) == len(value):
        pairs = enumerate(zip(args, value, strict=True))
        return tuple(_convert(a, v, f"{path}[{i}]") for i, (a, v) in pairs)
    return tuple(value)


def _convert_dict(args: tuple[Any, ...], value: Any, path: str) -> dict[Any, Any]:
    """``dict[K, V]`` converts every value to V."""
    if not isinstance(value, Mapping):
        raise ValueError(f"{path} must be a table of keys, got {value!r}")
    value_type = args[1] if args else Any
    return {k: _convert(value_type, v, _join(path, str(k))) for k, v in value.items()}


def _convert_scalar(tp: Any, value: Any, path: str) -> Any:
    """Check integers, booleans and strings; floats also accept integers and ``NON_FINITE`` strings."""
    if tp is int and (isinstance(value, bool) or not isinstance(value, int)):
        raise ValueError(f"{path} must be an integer, got {value!r}")
    if tp is float:
        if isinstance(value, str) and value in NON_FINITE:
            return NON_FINITE[value]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{path} must be a finite number, got {value!r}")
        return float(value)
    if tp is bool and not isinstance(value, bool):
        raise ValueError(f"{path} must be true or false, got {value!r}")
    if tp is str and not isinstance(value, str):
        raise ValueError(f"{path} must be a string, got {value!r}")
    return value


__all__ = ["errors_in", "from_mapping", "read_toml", "to_plain"]
