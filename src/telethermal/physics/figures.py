"""A part's figures, for the keys that say what a table or a calibration was
made for: a dataclass by its fields less its descriptive text (``source``:
a datasheet's name, a pointer into the docs), so that rewording a comment
never makes a shipped idle policy or a lab's pad calibration stale."""

from __future__ import annotations

import dataclasses

import numpy as np

#: Fields that describe a part and do not change its physics.
DESCRIPTIVE_FIELDS = frozenset({"source"})


def physical(value, leave_out: frozenset[str] = DESCRIPTIVE_FIELDS):
    """``value`` as nested tuples of its figures, for hashing: a dataclass by
    its fields less ``leave_out`` (at every depth), containers item by item,
    anything else by ``repr``."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return (type(value).__name__,
                tuple((f.name, physical(getattr(value, f.name), leave_out))
                      for f in dataclasses.fields(value) if f.name not in leave_out))
    if isinstance(value, (list, tuple)):
        return tuple(physical(v, leave_out) for v in value)
    if isinstance(value, dict):
        return tuple(sorted((repr(k), physical(v, leave_out)) for k, v in value.items()))
    if isinstance(value, np.ndarray):
        return repr(value.tolist())
    return repr(value)
