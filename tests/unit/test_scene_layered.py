"""Layered objects in scene files (issue 30's hard case, "a thin object on
a metal base"): parsing, the errors that name the file, the object and the
field, the object's name standing in for its material, and the contact
model's side b being the object's stack on the pad and the finger side."""

import tomllib

import numpy as np
import pytest

from telethermal.data.generate import pad_database
from telethermal.errors import SceneError
from telethermal.physics.scene import (ObjectSpec, describe_models, finger_contact_model,
                                       load_scene, pad_contact_model, parse_scene)

from test_scene import MINIMAL as HEAD     # one minimal scene, wood its object

LAYERED = """
[[objects]]
name = "plexiglass-on-aluminium"
material = "plexiglass"
thickness_m = 0.001
base = [["aluminium", 0.02]]
"""


def parse(text, source="lab.toml"):
    return parse_scene(tomllib.loads(text), source)


def test_a_layered_object_is_parsed_with_its_stack_and_name():
    scene = parse(HEAD + LAYERED)
    wood, obj = scene.objects
    assert obj.name == "plexiglass-on-aluminium" and obj.layered
    assert [(la.material.name, la.thickness_m) for la in obj.layers()] == [
        ("plexiglass", 0.001), ("aluminium", 0.02)]
    assert scene.materials == ["wood", "plexiglass-on-aluminium"]
    assert scene.object_named("plexiglass-on-aluminium") is obj
    # a plain object keeps its material as its name, and its repr (cache keys hold it)
    assert wood.name == "wood" and not wood.layered and wood.layers()[0].thickness_m == 0.02
    assert repr(wood) == "ObjectSpec(material='wood', temp_c=24.0, thickness_m=0.02)"


def test_a_plain_object_may_be_named():
    scene = parse(HEAD.replace('material = "wood"', 'material = "wood"\nname = "oak-block"'))
    assert scene.materials == ["oak-block"] and scene.objects[0].material == "wood"


@pytest.mark.parametrize("change,needles", [
    (('name = "plexiglass-on-aluminium"\n', ""), ["[[objects]] #2", "needs a 'name'"]),
    (('[["aluminium", 0.02]]', '[["kryptonite", 0.02]]'), ["[[objects]] #2", "base[0]",
                                                          "kryptonite"]),
    (('[["aluminium", 0.02]]', '[["aluminium", 20.0]]'), ["[[objects]] #2", "base[0]",
                                                         "outside"]),
    (('[["aluminium", 0.02]]', '[["aluminium", 1e-9]]'), ["base[0]", "outside"]),
    (('[["aluminium", 0.02]]', '[["aluminium", -1]]'), ["base[0]", "thickness_m > 0"]),
    (('[["aluminium", 0.02]]', '[["alumina", 0.02]]'), ["base[0]", "is a pad material"]),
    (('[["aluminium", 0.02]]', '[]'), ["'base' must be a non-empty list"]),
    (('[["aluminium", 0.02]]', '"aluminium"'), ["'base' must be a non-empty list"]),
    (('thickness_m = 0.001', 'thickness_m = 0'), ["[[objects]] #2", "'thickness_m'"]),
    (('name = "plexiglass-on-aluminium"', 'name = ""'), ["[[objects]] #2", "'name'"]),
    (('name = "plexiglass-on-aluminium"', 'name = "a|b"'), ["[[objects]] #2", "'|' joins"]),
    (('name = "plexiglass-on-aluminium"', 'name = "oak block"'), ["'name' = 'oak block'"]),
    (('name = "plexiglass-on-aluminium"', 'name = "aluminium"'), ["is a material's name"]),
    (('name = "plexiglass-on-aluminium"', 'name = "plexiglass"'), ["is a material's name"]),
    (('name = "plexiglass-on-aluminium"', 'name = 3'), ["[[objects]] #2", "'name' must be"]),
    (('base =', 'bases ='), ["'bases'", "did you mean 'base'"]),
])
def test_bad_layered_objects_name_the_file_the_object_and_the_field(change, needles):
    with pytest.raises(SceneError) as info:
        parse(HEAD + LAYERED.replace(*change))
    message = str(info.value)
    assert "lab.toml" in message
    for needle in needles:
        assert needle in message


def test_two_objects_of_one_name_are_refused():
    with pytest.raises(SceneError, match=r"lab\.toml: \[\[objects\]\]: the name\(s\) 'wood'"):
        parse(HEAD + '[[objects]]\nmaterial = "wood"\n')
    with pytest.raises(SceneError, match=r"the name\(s\) 'plexiglass-on-aluminium' appear twice "
                                         r"\('plexiglass-on-aluminium' in #2 and #3; 'name'"):
        parse(HEAD + LAYERED + LAYERED)


def test_the_contact_model_is_the_objects_stack_on_the_pad_and_the_finger():
    scene = parse(HEAD + LAYERED + "[finger]\n")
    obj = scene.objects[1]
    for model, _choice in (pad_contact_model(scene, obj), finger_contact_model(scene, obj)):
        side_b = model.grid.layers[-2:]
        assert [la.material.name for la in side_b] == ["plexiglass", "aluminium"]
        assert [la.thickness_m for la in side_b] == [0.001, 0.02]
    assert [row[1] for row in describe_models(scene)] == ["wood", "plexiglass-on-aluminium"] * 2


def test_a_database_labels_the_layered_objects_touches_by_its_name():
    scene = parse(HEAD + LAYERED)
    labels = {t.material for t in pad_database(scene, np.random.default_rng(0))}
    assert labels == {"wood", "plexiglass-on-aluminium"}


def test_the_shipped_scenes_objects_are_plain_and_named_by_their_material():
    for name in ("fingertip-7", "gripper-case-II"):
        scene = load_scene(name)
        assert all(isinstance(o, ObjectSpec) and o.name == o.material and not o.layered
                   for o in scene.objects)


def test_every_key_an_object_may_hold_is_documented():
    from pathlib import Path

    from telethermal.physics.scene import OBJECT_KEYS

    doc = (Path(__file__).resolve().parents[2] / "docs" / "scenes.md").read_text()
    objects = doc[doc.index("## `[[objects]]`"):]
    assert not [k for k in OBJECT_KEYS if f"| `{k}` |" not in objects]
