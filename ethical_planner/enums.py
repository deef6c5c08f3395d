"""Parsing of string enums with an error that lists what is allowed."""

from __future__ import annotations

from enum import StrEnum
from typing import TypeVar

E = TypeVar("E", bound=StrEnum)


def parse_enum(kind: type[E], value: str | E, what: str) -> E:
    """Return the member of ``kind`` named ``value``.

    Raises:
        ValueError: "unknown <what> <value>; allowed: <every value>".
    """
    try:
        return kind(value)
    except ValueError:
        allowed = ", ".join(member.value for member in kind)
        raise ValueError(f"unknown {what} {value!r}; allowed: {allowed}") from None
