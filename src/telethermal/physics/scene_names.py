"""A scene file's name is its identity: a model file, a dataset's
``generation.json`` and the slave find its pad model by it. A file that
keeps a shipped scene's name but changes its content would have its touches
fitted with the shipped pad's model (issue 44: a lab's copy of
``fingertip-7.toml`` with its own pad, still named ``fingertip-7``, was
identified 25 % right); it is refused with the fix."""

from __future__ import annotations

import dataclasses

from telethermal.errors import SceneError

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
