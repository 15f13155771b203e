"""Reading a scene's TOML tables: typed, range-checked values, materials and
stacks of layers, every error naming the file, the table and the key
(split out of :mod:`telethermal.physics.scene`)."""

from __future__ import annotations

import dataclasses
import difflib
import math

from telethermal.errors import SceneError, UnknownMaterialError
from telethermal.physics.layered import Layer
from telethermal.physics.materials import get_material, object_materials


#: A name's length in UTF-8 bytes: the wire caps every string at 256.
MAX_NAME_BYTES = 256


class TableReader:
    """Pulls typed, range-checked values out of a TOML table, naming the key."""

    def __init__(self, table: dict, where: str, source: str):
        self.table, self.where, self.source = table, where, source
        self.used: set[str] = set()

    def fail(self, message: str):
        raise SceneError(f"{self.source}: {self.where}: {message}")

    def num(self, key, default=None, lo=-math.inf, hi=math.inf, integer=False):
        self.used.add(key)
        value = self.table.get(key, default)
        if value is None:
            self.fail(f"missing '{key}'")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(f"'{key}' must be a number, got {value!r}")
        if integer and int(value) != value:
            self.fail(f"'{key}' must be a whole number, got {value!r}")
        if not (lo <= value <= hi) or not math.isfinite(value):
            self.fail(f"'{key}' = {value} is outside [{lo}, {hi}]" if math.isfinite(value)
                      else f"'{key}' = {value}: a number must be finite")
        return int(value) if integer else float(value)

    def text(self, key, default=None, choices=None, max_bytes=MAX_NAME_BYTES):
        """A string of at most ``max_bytes`` UTF-8 bytes (a name: the wire's
        cap on a string, 256)."""
        self.used.add(key)
        value = self.table.get(key, default)
        if not isinstance(value, str):
            self.fail(f"'{key}' must be a string, got {str(value)[:64]!r}")
        if len(value.encode("utf-8")) > max_bytes:
            self.fail(f"'{key}' is {len(value.encode('utf-8'))} bytes long, over the "
                      f"{max_bytes}-byte limit (docs/limits.md)")
        if choices and value not in choices:
            self.fail(f"'{key}' = {value!r}; expected one of {', '.join(choices)}")
        return value

    def done(self):
        self.only(self.used)

    def only(self, keys) -> None:
        """Fail on any key of the table outside ``keys``, naming it and the
        nearest known key (a typo is the likely cause)."""
        extra = sorted(set(self.table) - set(keys))
        if extra:
            hints = []
            for key in extra:
                near = difflib.get_close_matches(key, sorted(keys), n=1)
                hints.append(f"'{key}'" + (f" (did you mean '{near[0]}'?)" if near else ""))
            self.fail(f"unknown key(s) {', '.join(hints)}; known: {', '.join(sorted(keys))}")


def read_material(name, reader: TableReader, roles=None, field: str | None = None):
    """The material ``name``; unknown, or of a role outside ``roles``, fails
    naming ``field`` (the key or list item it came from) when given."""
    where = f"{field}: " if field else ""
    try:
        mat = get_material(name)
    except UnknownMaterialError as exc:
        reader.fail(f"{where}{exc}")
    if roles and mat.role not in roles:
        reader.fail(f"{where}material {name!r} is a {mat.role} material; objects must be one "
                    f"of {', '.join(object_materials())}")
    return mat


def read_layers(raw, reader: TableReader, key: str = "layers", roles=None,
                thickness_range_m: tuple[float, float] = (0.0, math.inf)) -> tuple[Layer, ...]:
    """``key = [[material, thickness_m], ...]``: a non-empty stack of layers,
    each material of ``roles`` (any when None) and each thickness in
    ``thickness_range_m`` (both ends included; and above 0), in m."""
    reader.used.add(key)
    if not isinstance(raw, list) or not raw:
        reader.fail(f"'{key}' must be a non-empty list of [material, thickness_m]")
    lo, hi = thickness_range_m
    layers = []
    for i, item in enumerate(raw):
        if (not isinstance(item, list) or len(item) != 2 or not isinstance(item[0], str)
                or isinstance(item[1], bool) or not isinstance(item[1], (int, float))
                or not item[1] > 0):
            reader.fail(f"{key}[{i}] must be [material, thickness_m > 0], got {item!r}")
        if not lo <= item[1] <= hi:
            reader.fail(f"{key}[{i}]: thickness_m = {item[1]} is outside [{lo}, {hi}]")
        layers.append(Layer(read_material(item[0], reader, roles, f"{key}[{i}]"),
                            float(item[1])))
    return tuple(layers)


# A scene file's name is its identity: a model file, a dataset's
# generation.json and the slave find its pad model by it. A file that keeps a
# shipped scene's name but changes its content would have its touches fitted
# with the shipped pad's model (issue 44: a lab's copy of fingertip-7.toml
# with its own pad, still named fingertip-7, was identified 25 % right).
#: Fields that say where a scene came from, not what it is.
_PROVENANCE = {"source": "", "ref": "", "materials_table": None, "description": ""}


def _content(scene):
    return dataclasses.replace(scene, **_PROVENANCE)


def check_own_name(scene, shipped_names, load_shipped) -> None:
    """Refuse a scene file that names a shipped scene (one of
    ``shipped_names``; ``load_shipped(name)`` loads it) but differs from it
    (any key but its description; ``[as_built]`` included), naming the
    sections that differ and the fix."""
    if scene.name not in shipped_names:
        return
    shipped = load_shipped(scene.name)
    if _content(scene) == _content(shipped):
        return
    differs = [f.name for f in dataclasses.fields(scene) if f.name not in _PROVENANCE
               and getattr(scene, f.name) != getattr(shipped, f.name)]
    raise SceneError(
        f"{scene.source}: name = {scene.name!r} is a shipped scene's, but this file differs "
        f"from it ({', '.join(differs)}): models and datasets find a scene's pad model by its "
        f"name, so this file's touches would be fitted with the shipped pad's: give your "
        f"scene its own name (name = \"...\" at the top of {scene.source})")


THERMOMETER_KINDS = ("ir", "contact")

#: Keys that were replaced, with what replaced them.
_RENAMED = {"ir_error_k": "'ir_error_k' was one error drawn afresh for every reading; it is "
                          "now 'object_bias_limit_k' (the instrument's bias in a session, a "
                          "datasheet accuracy) and 'object_noise_k' (per reading)"}


def parse_dataclass(cls, table, where, source):
    """``cls`` (SensorSpec, VariabilitySpec) from its table, every key checked."""
    from telethermal.physics.scenefile import UPPER_BOUNDS
    from telethermal.physics.thermoelectric import junction_sensor_names
    r = TableReader(table or {}, where, source)
    for old, why in _RENAMED.items():
        if old in (table or {}):
            r.fail(why)
    defaults = cls()
    values = {}
    for f in cls.__dataclass_fields__:
        default = getattr(defaults, f)
        if f == "object_thermometer":
            values[f] = r.text(f, default, choices=THERMOMETER_KINDS)
        elif f == "junction_sensor":
            values[f] = r.text(f, default, choices=junction_sensor_names())
        elif f == "flux_sensitivity_uv_per_w_m2":     # divides: never 0
            values[f] = r.num(f, default, lo=0.01, hi=1000.0)
        elif f == "flux_adc_lsb_uv":                  # a step: readings divide by it
            values[f] = r.num(f, default, lo=1e-6, hi=100.0)
        elif f == "junction_lag_s":
            values[f] = None if f not in (table or {}) else r.num(f, lo=0, hi=10.0)
        else:
            values[f] = r.num(f, default, lo=0, hi=UPPER_BOUNDS.get(f, 1e6))
    r.done()
    return cls(**values)
