"""Parsing of enums with an error that lists what is allowed (shared by every layer)."""

from __future__ import annotations

from enum import Enum
from typing import TypeVar

E = TypeVar("E", bound=Enum)


def parse_enum(kind: type[E], value: str | E, what: str) -> E:
    """Return the member of ``kind`` named ``value``.

    Raises:
        ValueError: "unknown <what> <value>; allowed: <every value>".
    """
    try:
        return kind(value)
    except ValueError:
        allowed = ", ".join(str(member.value) for member in kind)
        raise ValueError(f"unknown {what} {value!r}; allowed: {allowed}") from None
