"""A mode named by a string, read as its enum: one place for the coercion
and for the error that names the choices."""

from __future__ import annotations

from enum import Enum
from typing import TypeVar

E = TypeVar("E", bound=Enum)


def choice(kind: type[E], value, name: str, error: type[Exception] = ValueError) -> E:
    """``value`` (a member of ``kind`` or its value) as a member of
    ``kind``; ``error`` saying "``name`` must be one of ..." otherwise."""
    try:
        return kind(value)
    except (ValueError, TypeError):
        raise error(f"{name} must be one of {', '.join(repr(m.value) for m in kind)}, "
                    f"got {value!r}") from None
