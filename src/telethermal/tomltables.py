"""TOML files and tables to dataclass fields, with errors that name the file,
the table and the key (service configs, fault profiles, calibrations)."""

from __future__ import annotations

import json
import tomllib
from dataclasses import fields
from pathlib import Path

from telethermal.errors import TelethermalError
from telethermal.filelimits import read_text

#: A TOML file's size, read before parsing (the project's: a few KB).
MAX_TOML_BYTES = 1024 * 1024
#: Parts of one dotted key (``a.b.c`` has 3): ``tomllib`` keeps every prefix
#: of a dotted key, so its memory grows with the square of their number
#: (a 40 KB key took 1.58 GB).
MAX_KEY_PARTS = 32


def toml_str(text: str) -> str:
    """``text`` as a TOML basic string, quotes included: every character
    TOML needs escaped is (a quote, a backslash, control characters, DEL);
    reads back as ``text``."""
    return json.dumps(str(text), ensure_ascii=False).replace("\x7f", "\\u007f")


def read_toml(path: str | Path, what: str, error=TelethermalError) -> dict:
    """The TOML file at ``path`` (a ``what``: "config file", ...) as a dict;
    a missing file, one over ``MAX_TOML_BYTES``, not UTF-8, or bad TOML is
    ``error``, naming the file (``docs/limits.md``)."""
    path = Path(path)
    if path.is_dir():
        raise error(f"{path}: a folder, not a {what} (give the file in it)")
    if not path.is_file():
        raise error(f"{path}: no such {what}")
    return loads_checked(read_text(path, MAX_TOML_BYTES, what, error), str(path), error)


def loads_checked(text: str, source: str, error=TelethermalError) -> dict:
    """``tomllib.loads`` after the dotted keys' check (no key or table header
    of more than ``MAX_KEY_PARTS`` parts, counted before a line's ``=`` or
    within its ``[header]``: a quoted key's dots count too, erring on the side
    of refusing); bad TOML or nesting too deep for the parser is ``error``."""
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.lstrip()
        key = stripped.split("]", 1)[0] if stripped.startswith("[") else \
            stripped.split("=", 1)[0] if "=" in stripped else ""
        if key.count(".") >= MAX_KEY_PARTS:
            raise error(f"{source}: line {number}: a key of {key.count('.') + 1} dotted parts, "
                        f"over the limit of {MAX_KEY_PARTS}")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{source}: not valid TOML: {exc}") from exc
    except RecursionError as exc:
        raise error(f"{source}: arrays or tables nested too deep to read") from exc


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
