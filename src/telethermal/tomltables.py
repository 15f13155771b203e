"""TOML files and tables to dataclass fields, with errors that name the file,
the table and the key (service configs, fault profiles, calibrations)."""

from __future__ import annotations

import tomllib
from dataclasses import fields
from pathlib import Path

from telethermal.errors import TelethermalError

def read_toml(path: str | Path, what: str, error=TelethermalError) -> dict:
    """The TOML file at ``path`` (a ``what``: "config file", ...) as a dict;
    a missing file or bad TOML is ``error``, naming the file."""
    path = Path(path)
    if not path.is_file():
        raise error(f"{path}: no such {what}")
    try:
        return tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML: {exc}") from exc


_KINDS = {"int": int, "float": (int, float), "str": str, "bool": bool}


def table_values(cls, table: dict, where: str, error=TelethermalError,
                 exclude: tuple[str, ...] = ()) -> dict:
    """The keyword arguments for ``cls`` from ``table``: unknown keys and
    values of the wrong scalar type are refused (``error``, naming ``where``);
    fields of other types pass as they are, for ``cls`` to check."""
    known = {f.name: f for f in fields(cls) if f.name not in exclude}
    out = {}
    for key, value in table.items():
        if key not in known:
            raise error(f"{where}: unknown key {key!r}; keys: {', '.join(known)}")
        expected = known[key].type
        kind = _KINDS.get(expected if isinstance(expected, str) else expected.__name__)
        if kind is not None and (not isinstance(value, kind) or
                                 (kind is int and isinstance(value, bool))):
            raise error(f"{where}.{key}: expected {expected}, got {value!r}")
        out[key] = float(value) if expected == "float" else value
    return out
