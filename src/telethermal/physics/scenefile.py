"""A scene file's limits, checked before and around ``tomllib``
(``docs/limits.md``): its size and encoding, its dotted keys, its number of
objects and the upper bounds of ``[sensors]`` and ``[variability]``."""

from __future__ import annotations

from pathlib import Path

from telethermal.errors import SceneError
from telethermal.filelimits import read_text
from telethermal.tomltables import loads_checked

#: Objects in a scene (the shipped ones: 4-7; 5,000 took over 40 s to load).
MAX_OBJECTS = 256
#: A scene file's size (the shipped ones: under 2 KB), read before parsing.
MAX_SCENE_BYTES = 1024 * 1024


def read_scene_text(path: Path) -> str:
    """The file's text: at most ``MAX_SCENE_BYTES``, UTF-8 (a SceneError
    naming the file and the byte otherwise)."""
    return read_text(path, MAX_SCENE_BYTES, "scene file", SceneError)


#: Upper bounds of ``[sensors]`` and ``[variability]`` (docs/limits.md):
#: far above any instrument's figure, below what the simulator can hold
#: (``object_readings = 1e9`` allocated 1e9 readings); others at most 1e6.
UPPER_BOUNDS = {"flux_lag_s": 10.0, "flux_sensitivity_limit_rel": 1.0, "onset_jitter_s": 1.0,
                "object_gain_limit": 1.0, "object_readings": 10_000,
                "instrument_seed": 2 ** 32 - 1, "force_n": 1000.0, "force_sd_n": 1000.0,
                "reference_force_n": 1000.0, "conductance_force_exponent": 10.0}


def parse_toml(text: str, source: str) -> dict:
    """The scene's TOML, its dotted keys checked first (``tomltables``); a
    SceneError naming the file for bad TOML or nesting too deep."""
    return loads_checked(text, source, SceneError)
