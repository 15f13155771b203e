"""Scenes: what a session contains, read from TOML, validated, and turned
into the cheapest contact models that meet the scene's tolerance.

A scene names the room, the pad (``peltier``: the fingertip display of the
first paper, a Peltier held at a set temperature under a sensor film; or
``water``: the active gripper pad of the second paper, pre-conditioned by
eq. (11)-(13)), optionally the operator's finger, the objects, the sensors,
the trial-to-trial variability and the model tolerance. The shipped scenes are
listed by :func:`list_scenes`; ``load_scene`` takes a shipped name or a path.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from telethermal.errors import SceneError
from telethermal.physics.as_built import AsBuilt, read_as_built
from telethermal.physics.sensorspec import SensorSpec
from telethermal.physics.layered import Boundary, Layer
from telethermal.physics.materials import (get_material, load_materials, read_table,
                                           register_materials, shadowed_by,
                                           unregister_materials)
from telethermal.physics.model import ModelChoice, choose_model
from telethermal.physics.scenefile import MAX_OBJECTS, parse_toml, read_scene_text
from telethermal.physics.scenereader import (TableReader as _Reader, check_own_name,
                                             parse_dataclass as _parse_dataclass, read_layers,
                                             read_material)

PAD_KINDS = ("peltier", "water")
#: Simulated beyond a contact's duration: a recording is cut at the onset its
#: contact detector finds, up to a few periods after the true one, and must
#: still hold the whole duration after it.
ONSET_MARGIN_S = 0.05


@dataclass(frozen=True)
class PadSpec:
    kind: str
    layers: tuple[Layer, ...]          # from the contact surface inwards
    gap_k: float | None                # pad = object (IR-measured) + gap; or
    temp_c: float | None               # a fixed pad temperature
    contact_duration_s: float
    trials_per_material: int
    contact_conductance_w_m2k: float   # at reference_force_n
    back_h_w_m2k: float                # water pad: natural convection to the water
    #: The Peltier module behind the layers and its heat sink (names in
    #: physics/modules.toml); a scene that names none gets the first paper's
    #: stand-in (thermoelectric.DEFAULT_MODULE / DEFAULT_HEAT_SINK).
    module: str = "TM-31-1.4-8.5"
    heat_sink: str = "fan-40"
    #: The pad's contact face, [width, height] in mm; None: the module's own
    #: face (its datasheet's size). The layers, the flux sensor and the
    #: module's heat act on this area: the module pumps its heat over the
    #: pad's face, lumped (a plate conductive enough to be one temperature).
    size_mm: tuple[float, float] | None = None

    @property
    def area_m2(self) -> float:
        """The contact face's area: ``size_mm``, or the module's face."""
        if self.size_mm is not None:
            return self.size_mm[0] * self.size_mm[1] * 1e-6
        return self.module_params()[0].spec.area_m2

    def module_params(self):
        """(ModuleParams, SinkParams) of this pad's module and heat sink."""
        from telethermal.physics.thermoelectric import (derive, get_heat_sink, get_module,
                                                        sink_params)
        params = derive(get_module(self.module))
        return params, sink_params(get_heat_sink(self.heat_sink), params.spec)


#: The keys a scene's [pad] table may hold (its fields: TOML names them the same).
PAD_KEYS = tuple(PadSpec.__dataclass_fields__)


@dataclass(frozen=True)
class FingerSpec:
    temp_c: float
    temp_sd_c: float
    persons: int
    trials_per_person: int
    contact_duration_s: float
    contact_conductance_w_m2k: float
    property_sd: float


@dataclass(frozen=True, repr=False)
class ObjectSpec:
    """An object: its surface ``material``, ``thickness_m`` thick, on the
    layers of ``base`` (from the surface layer outwards; none for a plain
    object), the last one's back adiabatic. ``label``: the object's name
    (required in a scene file when layered); a plain object's name is its
    material, which stands for it wherever an object is named (databases'
    labels, identifiers' classes, recordings)."""

    material: str
    temp_c: float
    thickness_m: float
    base: tuple[Layer, ...] = ()
    label: str = ""

    @property
    def name(self) -> str:
        """What the object is called: its ``label``, else its material."""
        return self.label or self.material

    @property
    def layered(self) -> bool:
        return bool(self.base)

    def layers(self) -> tuple[Layer, ...]:
        """The object's stack from its contact surface outwards."""
        return (Layer(get_material(self.material), self.thickness_m),) + tuple(self.base)

    def __repr__(self) -> str:
        # A plain object's repr is what it was before layers (cache keys hold it).
        extra = "" if not (self.base or self.label) else \
            f", base={self.base!r}, label={self.label!r}"
        return (f"ObjectSpec(material={self.material!r}, temp_c={self.temp_c!r}, "
                f"thickness_m={self.thickness_m!r}{extra})")




@dataclass(frozen=True)
class VariabilitySpec:
    force_n: float = 10.0
    force_sd_n: float = 1.5
    reference_force_n: float = 10.0    # the force at which the contact conductances hold
    conductance_force_exponent: float = 0.8
    object_temp_sd_c: float = 0.2


@dataclass(frozen=True)
class Scene:
    name: str
    description: str
    room_temp_c: float
    sample_rate_hz: float
    pre_contact_s: float
    pad: PadSpec
    finger: FingerSpec | None
    objects: tuple[ObjectSpec, ...]
    sensors: SensorSpec = field(default_factory=SensorSpec)
    variability: VariabilitySpec = field(default_factory=VariabilitySpec)
    tolerance_rel: float = 1e-3
    source: str = ""
    #: The scene's own materials table (its ``materials`` key), if any.
    materials_table: str | None = None
    #: What loads this scene again in another process: a shipped scene's
    #: name, or a scene file's absolute path ("" when parsed from a table).
    ref: str = ""
    #: The room's relative humidity, % (the display keeps its pad above the
    #: dew point: control/dew.py). Default 50 %: the middle of the 30-70 %
    #: ISO 7730 (Ergonomics of the thermal environment, annex) recommends indoors.
    room_humidity_pct: float = 50.0
    as_built: AsBuilt | None = None     # [as_built]: the simulator's alone (physics/as_built.py)

    @property
    def materials(self) -> list[str]:
        """The objects' names (a plain object's is its material)."""
        return [o.name for o in self.objects]

    def object_named(self, name: str) -> ObjectSpec | None:
        """The object called ``name`` (:attr:`ObjectSpec.name`), else None."""
        return next((o for o in self.objects if o.name == name), None)

    def pad_temp_c(self, object_temp_c: float) -> float:
        """The pad's set temperature before contact with an object."""
        return self.pad.temp_c if self.pad.gap_k is None else object_temp_c + self.pad.gap_k


# ---------------------------------------------------------------- parsing
def _parse_pad(table, source) -> PadSpec:
    from telethermal.physics.thermoelectric import (DEFAULT_HEAT_SINK, DEFAULT_MODULE,
                                                    get_module, heat_sink_names, module_names)

    r = _Reader(table, "[pad]", source)
    r.only(PAD_KEYS)              # a typo first: 'gapk' is not a missing 'gap_k'
    kind = r.text("kind", choices=PAD_KINDS)
    layers = read_layers(table.get("layers"), r)
    module = r.text("module", DEFAULT_MODULE, choices=module_names())
    if kind == "peltier":
        layers = _with_cold_plate(layers, get_module(module), r)
    gap = table.get("gap_k")
    fixed = table.get("temp_c")
    if (gap is None) == (fixed is None):
        r.fail("give exactly one of 'gap_k' (pad = object + gap) or 'temp_c' (fixed)")
    spec = PadSpec(
        kind=kind, layers=layers,
        gap_k=None if gap is None else r.num("gap_k", lo=-40, hi=40),
        temp_c=None if fixed is None else r.num("temp_c", lo=0, hi=60),
        contact_duration_s=r.num("contact_duration_s", 1.0, 1e-3, 3600),
        trials_per_material=r.num("trials_per_material", 10, 1, 10000, integer=True),
        contact_conductance_w_m2k=r.num("contact_conductance_w_m2k", 3000.0, 1.0, 1e7),
        back_h_w_m2k=r.num("back_h_w_m2k", 300.0, 1e-3, 1e7),
        module=module,
        heat_sink=r.text("heat_sink", DEFAULT_HEAT_SINK, choices=heat_sink_names()),
        size_mm=_size_mm(table, r),
    )
    r.done()
    return spec


def _with_cold_plate(layers, module, reader: _Reader):
    """A Peltier pad's stack: its listed layers, then its module's own cold
    plate (physics/modules.toml's ``plate_mm``: one figure for the pad's
    stack and the module's geometry). A list that already ends in the
    plate's ceramic would count the plate twice: refused, saying why."""
    from telethermal.physics.thermoelectric import PLATE_MATERIAL, cold_plate
    plate = cold_plate(module)
    if layers[-1].material.name == PLATE_MATERIAL:
        reader.fail(f"'layers' ends with {PLATE_MATERIAL!r} (layers[{len(layers) - 1}], "
                    f"{layers[-1].thickness_m * 1e3:g} mm): "
                    f"the module's own cold plate ({module.plate_mm:g} mm {PLATE_MATERIAL}, "
                    f"module {module.name!r} in physics/modules.toml) is added behind the listed "
                    "layers; list only the layers in front of it")
    return tuple(layers) + (plate,)


def _size_mm(table, reader: _Reader) -> tuple[float, float] | None:
    """``size_mm = [width, height]``: the pad's face in mm (0.5 to 200 each)."""
    reader.used.add("size_mm")
    raw = table.get("size_mm")
    if raw is None:
        return None
    if not isinstance(raw, list) or len(raw) != 2 or any(
            isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.5 <= v <= 200
            for v in raw):
        reader.fail(f"'size_mm' must be [width, height] in mm, each in [0.5, 200], got {raw!r}")
    return float(raw[0]), float(raw[1])


def _parse_finger(table, source) -> FingerSpec:
    r = _Reader(table, "[finger]", source)
    spec = FingerSpec(
        temp_c=r.num("temp_c", 33.0, 15, 42), temp_sd_c=r.num("temp_sd_c", 0.8, 0, 5),
        persons=r.num("persons", 5, 1, 1000, integer=True),
        trials_per_person=r.num("trials_per_person", 10, 1, 10000, integer=True),
        contact_duration_s=r.num("contact_duration_s", 60.0, 1e-3, 3600),
        contact_conductance_w_m2k=r.num("contact_conductance_w_m2k", 5000.0, 1.0, 1e7),
        property_sd=r.num("property_sd", 0.12, 0, 0.5))
    r.done()
    return spec


#: The keys an ``[[objects]]`` table may hold.
OBJECT_KEYS = ("material", "temp_c", "thickness_m", "base", "name")
#: What an object's ``name`` may be: it names trial files and identifier
#: classes, and is listed with commas and paired with '|'.
OBJECT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]*")
#: An object's thickness (and each of its base layers'), m.
OBJECT_THICKNESS_RANGE_M = (1e-6, 10.0)


def _parse_objects(items, source, room_c) -> tuple[ObjectSpec, ...]:
    if not isinstance(items, list) or not items:
        raise SceneError(f"{source}: at least one [[objects]] table is needed")
    if len(items) > MAX_OBJECTS:
        raise SceneError(f"{source}: {len(items)} [[objects]], over the limit of {MAX_OBJECTS} "
                         "(docs/limits.md: each is modelled at load)")
    objects = []
    for i, table in enumerate(items):
        r = _Reader(table, f"[[objects]] #{i + 1}", source)
        objects.append(_parse_object(table, r, room_c))
        r.done()
    names = [o.name for o in objects]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        where = "; ".join(f"{n!r} in " + " and ".join(
            f"#{i + 1}" for i, m in enumerate(names) if m == n) for n in twice)
        raise SceneError(f"{source}: [[objects]]: the name(s) {', '.join(map(repr, twice))} "
                         f"appear twice ({where}; 'name', else the material, must be "
                         f"unique): {names}")
    return tuple(objects)


def _parse_object(table, r: _Reader, room_c) -> ObjectSpec:
    """One ``[[objects]]`` table: ``material``, ``temp_c``, ``thickness_m``,
    and for a layered object ``base`` (its layers beneath, outwards) and
    ``name`` (required with ``base``)."""
    r.only(OBJECT_KEYS)            # a typo first: 'bases' is not a missing 'base'
    material = r.text("material")
    read_material(material, r, roles=("object",), field="'material'")
    temp = table.get("temp_c", "room")
    r.used.add("temp_c")
    if temp == "room":
        temp = room_c
    elif isinstance(temp, bool) or not isinstance(temp, (int, float)) or not -20 <= temp <= 100:
        r.fail(f"'temp_c' must be 'room' or a number in [-20, 100], got {temp!r}")
    lo, hi = OBJECT_THICKNESS_RANGE_M
    thickness = r.num("thickness_m", 0.02, lo, hi)
    base = () if "base" not in table else read_layers(
        table["base"], r, "base", roles=("object",), thickness_range_m=(lo, hi))
    label = "" if "name" not in table else r.text("name")
    r.used.add("name")
    if base and not label:
        r.fail(f"a layered object (material {material!r} with a 'base') needs a 'name'")
    if "name" in table and not OBJECT_NAME.fullmatch(label):
        r.fail(f"'name' = {label!r}: a letter or digit, then letters, digits, '_', '-', '.' "
               "or '+' (it names trial files and labels; '|' joins a pair, ',' lists)")
    if label in load_materials() and (base or label != material):
        r.fail(f"'name' = {label!r} is a material's name; the object (of {material!r}) "
               "would be read as that material wherever its name is looked up")
    return ObjectSpec(material, float(temp), thickness, base, label)


def parse_scene(data: dict, source: str = "<scene>") -> Scene:
    """Build a :class:`Scene` from parsed TOML, naming every bad key."""
    own_table, added = _own_materials(data, _Reader(data, "top level", source), source)
    try:
        return _parse_scene(data, source, own_table)
    except BaseException:
        unregister_materials(added)             # a scene that did not load changes nothing
        raise


def _parse_scene(data: dict, source: str, own_table: str | None) -> Scene:
    r = _Reader(data, "top level", source)
    r.used.add("materials")
    room = r.num("room_temp_c", lo=-20, hi=60)
    for table in ("pad", "finger", "objects", "sensors", "variability", "model", "as_built"):
        r.used.add(table)
    if not isinstance(data.get("pad"), dict):
        r.fail("a [pad] table is needed")
    model = data.get("model") or {}
    mr = _Reader(model, "[model]", source)
    tolerance = mr.num("tolerance_rel", 1e-3, 1e-9, 0.5)
    mr.done()
    scene = read_as_built(Scene(
        name=r.text("name"), description=r.text("description", "", max_bytes=4096),
        room_temp_c=room, sample_rate_hz=r.num("sample_rate_hz", lo=1, hi=1e6),
        pre_contact_s=r.num("pre_contact_s", 0.5, 0, 60),
        pad=_parse_pad(data["pad"], source),
        finger=_parse_finger(data["finger"], source) if "finger" in data else None,
        objects=_parse_objects(data.get("objects"), source, room),
        sensors=_parse_dataclass(SensorSpec, data.get("sensors"), "[sensors]", source),
        variability=_parse_dataclass(VariabilitySpec, data.get("variability"),
                                     "[variability]", source),
        tolerance_rel=tolerance, source=source, materials_table=own_table,
        room_humidity_pct=r.num("room_humidity_pct", 50.0, 0, 100)), data.get("as_built"), source)
    for name in [lay.material.name for o in scene.objects for lay in o.layers()] + [
            lay.material.name for lay in scene.pad.layers]:
        other = shadowed_by(name)
        if other is not None and other != own_table:
            r.fail(f"material {name!r} was redefined in this process by {other}; this "
                   f"scene uses the package's (run the two scenes in separate processes)")
    r.done()
    return scene


def _own_materials(data: dict, reader: _Reader, source: str) -> tuple[str | None, list]:
    """``materials = "FILE.csv"``: the scene's own materials table (the
    package's columns), relative to the scene file; its rows add to the
    package's or shadow them. Returns the table's path (or None) and the
    names it added to this process."""
    name = data.get("materials")
    if name is None:
        return None, []
    if not isinstance(name, str) or not name.strip():
        reader.fail(f"'materials' must be the path of a CSV table, got {name!r}")
    path = Path(source).parent / name
    if not path.is_file():
        reader.fail(f"'materials' = {name!r}: no such file {path}")
    try:
        table = read_table(path.read_text(encoding="utf-8"), str(path))
        added = register_materials(table, str(path))
    except (ValueError, UnicodeDecodeError) as exc:
        raise SceneError(f"{source}: {exc}") from exc
    return str(path), added


def _shipped():
    return resources.files("telethermal").joinpath("scenes")


def list_scenes() -> list[str]:
    """Names of the scenes shipped with telethermal."""
    return sorted(p.name[:-5] for p in _shipped().iterdir() if p.name.endswith(".toml"))


#: Scene files this process loaded, by the name inside them: a model file
#: keeps its scene's name, and a process that loaded the file finds it
#: again by that name (:func:`loaded_scene_file`).
_FILES_BY_NAME: dict[str, "Scene"] = {}


def loaded_scene_file(name: str) -> "Scene | None":
    """The scene file of that name this process last loaded, else None."""
    return _FILES_BY_NAME.get(name)


def load_scene(name_or_path: str | Path) -> Scene:
    """Load a shipped scene by name, or any scene file by path (which this
    process then also finds by the name in it: :func:`loaded_scene_file`)."""
    path = Path(name_or_path)
    name = str(name_or_path)
    shipped = list_scenes()
    if name not in shipped and (path.suffix or path.exists() or "/" in name):
        # A path (shipped names have no dot and no slash): the file, or an
        # error that names it and, for a near miss, the file meant.
        if path.is_dir():
            raise SceneError(f"scene file {path}: a folder, not a scene file (give the .toml "
                             "in it)")
        if not path.is_file():
            near = difflib.get_close_matches(path.name, [p.name for p in path.parent.glob(
                "*.toml")] if path.parent.is_dir() else [], n=1)
            raise SceneError(f"scene file {path} does not exist" + (
                f" (did you mean {path.parent / near[0]}?)" if near else "") +
                ("" if path.suffix == ".toml" else "; a scene file ends in .toml"))
        text, source, ref = read_scene_text(path), str(path), str(path.resolve())
        from_file = True
    else:
        if name not in shipped:
            near = difflib.get_close_matches(name, shipped, n=1)
            raise SceneError(f"unknown scene {name!r}" + (
                f" (did you mean {near[0]!r}?)" if near else "") +
                f"; shipped scenes: {', '.join(shipped)}; or give a scene file's path (.toml)")
        text, source = _shipped().joinpath(f"{name}.toml").read_text(), f"{name}.toml"
        ref, from_file = name, False
    data = parse_toml(text, source)
    scene = dataclasses.replace(parse_scene(data, source), ref=ref)
    if from_file:
        check_own_name(scene, shipped, load_scene)     # a shipped name, other content: refused
        _FILES_BY_NAME[scene.name] = scene
    return scene


# ---------------------------------------------------------------- models
def pad_contact_model(scene: Scene, obj: ObjectSpec):
    """Model for the pad (side a) touching ``obj``; returns (model, ModelChoice)."""
    if scene.pad.kind == "peltier":
        back_a = Boundary("isothermal")          # Peltier junction held at the set point
    else:
        back_a = Boundary("convective", h_w_m2k=scene.pad.back_h_w_m2k)  # water, pump off
    return _choose(scene, scene.pad.layers, obj, back_a,
                   scene.pad.contact_duration_s + ONSET_MARGIN_S,
                   scene.pad.contact_conductance_w_m2k)


def finger_contact_model(scene: Scene, obj: ObjectSpec):
    """Model for the operator's fingertip (side a) touching ``obj``."""
    if scene.finger is None:
        raise SceneError(f"{scene.source}: the scene has no [finger]")
    skin = (Layer(get_material("skin"), math.inf),)
    return _choose(scene, skin, obj, Boundary("adiabatic"),
                   scene.finger.contact_duration_s + ONSET_MARGIN_S,
                   scene.finger.contact_conductance_w_m2k)


def _choose(scene, side_a, obj, back_a, duration_s, conductance):
    side_b = obj.layers()
    t_min = min(1.0 / scene.sample_rate_hz, 0.05)
    try:
        return choose_model(side_a, side_b, back_a, Boundary("adiabatic"), t_min, duration_s,
                            scene.tolerance_rel, conductance)
    except Exception as exc:  # a ModelError from deep inside: say which scene and object
        raise SceneError(f"{scene.source}: cannot model {obj.name}: {exc}") from exc


def describe_models(scene: Scene) -> list[tuple[str, str, ModelChoice]]:
    """(side, object name, choice) for every contact the scene contains."""
    rows = [("pad", o.name, pad_contact_model(scene, o)[1]) for o in scene.objects]
    if scene.finger is not None:
        rows += [("finger", o.name, finger_contact_model(scene, o)[1]) for o in scene.objects]
    return rows


#: The fingertip used where a scene has none (the gripper scenes): the
#: first paper's operator, nominal skin.
DEFAULT_FINGER = FingerSpec(temp_c=33.0, temp_sd_c=0.8, persons=5, trials_per_person=10,
                            contact_duration_s=60.0, contact_conductance_w_m2k=5000.0,
                            property_sd=0.12)


def with_finger(scene: Scene) -> Scene:
    """``scene`` with :data:`DEFAULT_FINGER` where it names no finger."""
    return scene if scene.finger is not None else dataclasses.replace(scene,
                                                                      finger=DEFAULT_FINGER)
