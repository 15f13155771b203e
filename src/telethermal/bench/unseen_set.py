"""``bench unseen``'s unseen set: the package's materials and a scene
file's objects touched beside the trained ones, checked (a trained or
unknown material, one given twice, is an error naming it)."""

from __future__ import annotations

import dataclasses
from importlib import resources

from telethermal.errors import SceneError, UnknownMaterialError
from telethermal.physics.materials import get_material, load_materials, object_materials
from telethermal.physics.scene import ObjectSpec, Scene, load_scene

#: The package's materials touched by default (the scene file adds its own).
DEFAULT_UNSEEN = ("copper", "carbon_steel", "glass", "foam")
#: How the report names the shipped unseen scene (not by this machine's path).
SHIPPED_UNSEEN_SCENE = "shipped: telethermal/bench/unseen_objects/unseen-objects.toml"


def default_unseen_scene_path() -> str:
    """The shipped scene file whose objects (brass, concrete) and materials
    table add to :data:`DEFAULT_UNSEEN`."""
    return str(resources.files("telethermal.bench").joinpath(
        "unseen_objects", "unseen-objects.toml"))


def package_objects(names, trained, temp_c: float, thickness_m: float) -> list[ObjectSpec]:
    """Objects of the package's materials ``names`` (a comma-separated
    string or a list), at ``temp_c``, ``thickness_m`` thick; an unknown
    name, a non-object material or a trained one is an error naming it."""
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",")]
    if not names or any(not n for n in names):
        raise SceneError(f"--unseen: an empty material name in {','.join(names)!r}")
    out = []
    for name in names:
        if name not in load_materials():
            raise UnknownMaterialError(f"--unseen: unknown material {name!r}; the package's "
                                       f"objects: {', '.join(object_materials())}")
        if get_material(name).role != "object":
            raise SceneError(f"--unseen: {name!r} is a {get_material(name).role} material, "
                             f"not an object; objects: {', '.join(object_materials())}")
        if name in trained:
            raise SceneError(f"--unseen: {name!r} is one of the trained materials "
                             f"({', '.join(trained)})")
        out.append(ObjectSpec(name, temp_c, thickness_m))
    return out


def scene_objects(path, trained) -> list[ObjectSpec]:
    """The objects of the scene file ``path`` (its own materials table
    registered for this process); a trained material among them is an error
    (a layered object is its own, whatever its layers)."""
    scene = load_scene(path)
    clash = [o.name for o in scene.objects if o.name in trained]
    if clash:
        raise SceneError(f"--unseen-scene {path}: {', '.join(clash)} is a trained material")
    return list(scene.objects)


def touch_scene(base: Scene, unseen) -> Scene:
    """``base`` with the unseen objects after its own (the same pad,
    instruments and variability): what ``pad_database`` touches."""
    objects = tuple(base.objects) + tuple(unseen)
    names = [o.name for o in objects]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise SceneError(f"unseen set: {', '.join(twice)} given twice")
    return dataclasses.replace(base, objects=objects, name=f"{base.name}+unseen")


def same_as_trained(name: str, trained) -> str | None:
    """The trained material with the very same properties (an alias), if any."""
    m = get_material(name)
    for t in trained:
        o = get_material(t)
        if (o.conductivity_w_mk, o.volumetric_heat_j_m3k) == (m.conductivity_w_mk,
                                                                m.volumetric_heat_j_m3k):
            return t
    return None


def unseen_objects(base: Scene, unseen=None, unseen_scene=None) -> tuple[list, str | None]:
    """(the unseen objects, the scene file they came from or None):
    ``unseen`` (package materials, at the temperature and thickness of
    ``base``'s first object) and the objects of the scene file
    ``unseen_scene``; with neither, :data:`DEFAULT_UNSEEN` less ``base``'s
    own (glass on the active pad) and the shipped unseen-objects scene's,
    at ``base``'s temperature."""
    trained = base.materials
    first = base.objects[0]
    if unseen is None:
        names = [] if unseen_scene is not None else [m for m in DEFAULT_UNSEEN
                                                      if m not in trained]
    else:
        names = unseen
    objects = package_objects(names, trained, first.temp_c, first.thickness_m) if names else []
    if unseen is None and unseen_scene is None:
        path = default_unseen_scene_path()
        objects += [dataclasses.replace(o, temp_c=first.temp_c)
                    for o in scene_objects(path, trained)]
    else:
        path = unseen_scene
        objects += scene_objects(path, trained) if path is not None else []
    return objects, path
