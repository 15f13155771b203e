"""A scene file's limits, checked before and around ``tomllib``
(``docs/limits.md``): its size and encoding, its dotted keys, its number of
objects and the upper bounds of ``[sensors]`` and ``[variability]``."""

from __future__ import annotations

import tomllib
from pathlib import Path

from telethermal.errors import SceneError

#: Objects in a scene (the shipped ones: 4-7; 5,000 took over 40 s to load).
MAX_OBJECTS = 256
#: A scene file's size (the shipped ones: under 2 KB), read before parsing.
MAX_SCENE_BYTES = 1024 * 1024
#: Parts of one dotted key (``a.b.c`` has 3): ``tomllib`` keeps every prefix
#: of a dotted key, so its memory grows with the square of their number
#: (a 40 KB key took 1.58 GB).
MAX_KEY_PARTS = 32


def read_scene_text(path: Path) -> str:
    """The file's text: at most ``MAX_SCENE_BYTES``, UTF-8 (a SceneError
    naming the file and the byte otherwise)."""
    try:
        size = path.stat().st_size
        if size > MAX_SCENE_BYTES:
            raise SceneError(f"{path}: {size} bytes, over the {MAX_SCENE_BYTES}-byte limit "
                             "of a scene file (docs/limits.md)")
        data = path.read_bytes()
        return data[:MAX_SCENE_BYTES + 1].decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(f"{path}: not UTF-8 text (byte {exc.start}: "
                         f"{data[exc.start:exc.start + 1]!r})") from exc
    except OSError as exc:
        raise SceneError(f"{path}: cannot read: {exc}") from exc


def check_dotted_keys(text: str, source: str) -> None:
    """No key or table header with more than ``MAX_KEY_PARTS`` dotted parts
    (counted before the ``=`` of a line, or within a ``[header]``; a quoted
    key's dots count too, erring on the side of refusing)."""
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.lstrip()
        key = stripped.split("]", 1)[0] if stripped.startswith("[") else \
            stripped.split("=", 1)[0] if "=" in stripped else ""
        if key.count(".") >= MAX_KEY_PARTS:
            raise SceneError(f"{source}: line {number}: a key of {key.count('.') + 1} dotted "
                             f"parts, over the limit of {MAX_KEY_PARTS}")


#: Upper bounds of ``[sensors]`` and ``[variability]`` (docs/limits.md):
#: far above any instrument's figure, below what the simulator can hold
#: (``object_readings = 1e9`` allocated 1e9 readings); others at most 1e6.
UPPER_BOUNDS = {"flux_lag_s": 10.0, "flux_sensitivity_limit_rel": 1.0, "onset_jitter_s": 1.0,
                "object_gain_limit": 1.0, "object_readings": 10_000,
                "instrument_seed": 2 ** 32 - 1, "force_n": 1000.0, "force_sd_n": 1000.0,
                "reference_force_n": 1000.0, "conductance_force_exponent": 10.0}


def parse_toml(text: str, source: str) -> dict:
    """``tomllib.loads`` after the dotted keys' check; a SceneError naming
    the file for bad TOML or nesting too deep for the parser."""
    check_dotted_keys(text, source)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{source}: not valid TOML: {exc}") from exc
    except RecursionError as exc:
        raise SceneError(f"{source}: arrays or tables nested too deep to read (a scene "
                         "nests a few levels)") from exc
