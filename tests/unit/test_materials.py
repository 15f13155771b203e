import math

import pytest

from telethermal.errors import UnknownMaterialError
from telethermal.physics.materials import get_material, load_materials, object_materials


def test_effusivity_and_diffusivity_are_derived():
    al = get_material("aluminium")
    assert al.effusivity == pytest.approx(math.sqrt(167.0 * 2700.0 * 896.0))
    assert al.diffusivity_m2_s == pytest.approx(167.0 / (2700.0 * 896.0))


def test_table_has_what_the_papers_need_with_sources():
    table = load_materials()
    for name in ("aluminium", "stainless_steel", "carbon_steel", "copper", "marble", "glass",
                 "plexiglass", "graphite", "rubber", "wood", "skin", "alumina",
                 "flux_sensor_film", "thermal_grease"):
        assert name in table and table[name].source


def test_unknown_material_names_the_known_ones():
    with pytest.raises(UnknownMaterialError) as info:
        get_material("unobtainium")
    assert "unobtainium" in str(info.value) and "aluminium" in str(info.value)


def test_object_materials_exclude_pad_layers():
    objects = object_materials()
    assert "wood" in objects and "alumina" not in objects and "skin" not in objects
