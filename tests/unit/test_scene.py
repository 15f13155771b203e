import tomllib

import pytest

from telethermal.errors import SceneError
from telethermal.physics.scene import (PAD_KEYS, describe_models, finger_contact_model,
                                       list_scenes, load_scene, pad_contact_model, parse_scene)

REQUIRED = {"fingertip-7", "gripper-case-I-cnv", "gripper-case-I-pro", "gripper-case-II",
            "gripper-case-III", "gripper-case-IV", "gripper-case-V"}

MINIMAL = """
name = "mini"
room_temp_c = 24.0
sample_rate_hz = 100.0
[pad]
kind = "peltier"
layers = [["flux_sensor_film", 3.0e-4], ["thermal_grease", 2.0e-5]]
gap_k = 10.0
contact_duration_s = 1.0
trials_per_material = 2
[[objects]]
material = "wood"
"""


def test_every_required_scene_is_shipped_and_loads():
    assert REQUIRED <= set(list_scenes())
    for name in REQUIRED:
        scene = load_scene(name)
        assert scene.name == name


def test_gripper_scenes_follow_tables_1_and_2():
    expected = {"I-cnv": (34.0, 34.0), "I-pro": (44.0, 34.0), "II": (34.0, 24.0),
                "III": (29.0, 19.0), "IV": (24.0, 34.0), "V": (19.0, 29.0)}
    for case, (pad_c, obj_c) in expected.items():
        scene = load_scene(f"gripper-case-{case}")
        assert scene.sample_rate_hz == 1000.0 and scene.room_temp_c == 24.0
        assert all(o.temp_c == obj_c for o in scene.objects)
        assert scene.pad_temp_c(obj_c) == pad_c


def test_fingertip_scene_is_the_first_papers_setup():
    scene = load_scene("fingertip-7")
    assert scene.sample_rate_hz == 100.0 and scene.pad.gap_k == 10.0
    assert len(scene.objects) == 7 and scene.finger.persons == 5


def test_unknown_material_names_the_file_and_the_known_ones(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(MINIMAL.replace('"wood"', '"kryptonite"'))
    with pytest.raises(SceneError) as info:
        load_scene(path)
    message = str(info.value)
    assert "bad.toml" in message and "kryptonite" in message and "aluminium" in message


@pytest.mark.parametrize("change,needle", [
    (("gap_k = 10.0", "gap_k = 10.0\ntemp_c = 30.0"), "exactly one"),
    (("kind = \"peltier\"", "kind = \"laser\""), "kind"),
    (("sample_rate_hz = 100.0", "sample_rate_hz = \"fast\""), "sample_rate_hz"),
    (("trials_per_material = 2", "trials_per_material = 2.5"), "trials_per_material"),
    (("room_temp_c = 24.0", "room_temp_c = 24.0\ncolour = 3"), "colour"),
    (("[\"thermal_grease\", 2.0e-5]", "[\"thermal_grease\", -1]"), "layers[1]"),
])
def test_bad_keys_are_named(change, needle):
    with pytest.raises(SceneError) as info:
        parse_scene(tomllib.loads(MINIMAL.replace(*change)), "x.toml")
    assert needle in str(info.value)


def test_not_toml_and_missing_file_are_clear_errors(tmp_path):
    bad = tmp_path / "broken.toml"
    bad.write_text("name = ")
    with pytest.raises(SceneError, match="not valid TOML"):
        load_scene(bad)
    with pytest.raises(SceneError, match="does not exist"):
        load_scene(tmp_path / "absent.toml")
    with pytest.raises(SceneError, match="shipped scenes"):
        load_scene("no-such-scene")


def test_a_typo_names_the_file_section_key_and_the_key_meant(tmp_path):
    # 'gapk' for 'gap_k' said "give exactly one of 'gap_k' or 'temp_c'",
    # without the key written or, through the CLI's markup, the section.
    with pytest.raises(SceneError, match=r"^x\.toml: \[pad\]: unknown key\(s\) 'gapk' "
                                         r"\(did you mean 'gap_k'\?\)"):
        parse_scene(tomllib.loads(MINIMAL.replace("gap_k = 10.0", "gapk = 10.0")), "x.toml")
    # A path typed wrong is a missing file, not an unknown shipped scene.
    (tmp_path / "lab-pad.toml").write_text(MINIMAL)
    with pytest.raises(SceneError, match=r"scene file .*lab-pad\.tml does not exist \(did you "
                                         r"mean .*lab-pad\.toml\?\); a scene file ends in "
                                         r"\.toml"):
        load_scene(tmp_path / "lab-pad.tml")
    with pytest.raises(SceneError, match=r"unknown scene 'fingertip7' \(did you mean "
                                         r"'fingertip-7'\?\)"):
        load_scene("fingertip7")


def test_the_command_line_prints_an_error_s_brackets(tmp_path, capsys):
    from telethermal.cli import main

    scene = tmp_path / "typo.toml"
    scene.write_text(MINIMAL.replace("gap_k = 10.0", "gapk = 10.0"))
    assert main(["session", "--scene", str(scene), "--material", "wood",
                 "--json", str(tmp_path / "x.json")]) == 2
    out = " ".join(capsys.readouterr().err.split())
    assert "typo.toml: [pad]: unknown key(s) 'gapk'" in out
    assert not (tmp_path / "x.json").exists()


def test_model_choice_follows_penetration_depth():
    scene = load_scene("fingertip-7")
    by_material = {o.material: o for o in scene.objects}
    # Wood: sqrt(alpha t) over 60 s is 2.8 mm in a 30 mm block -> closed form.
    _, wood = finger_contact_model(scene, by_material["wood"])
    # Aluminium: 8 cm penetration in 30 mm -> the finite block matters.
    _, alu = finger_contact_model(scene, by_material["aluminium"])
    # The pad is a stack of thin layers -> layered.
    _, pad = pad_contact_model(scene, by_material["wood"])
    assert wood.kind == "analytic" and alu.kind == "layered" and pad.kind == "layered"
    for choice in (wood, alu, pad):
        assert choice.error_bound_rel <= scene.tolerance_rel


def test_every_shipped_contact_can_be_modelled_within_tolerance():
    for name in list_scenes():
        scene = load_scene(name)
        for _side, _material, choice in describe_models(scene):
            assert choice.error_bound_rel <= scene.tolerance_rel


def test_scene_with_unreachable_tolerance_is_refused():
    data = tomllib.loads(MINIMAL.replace("trials_per_material = 2",
                                         "trials_per_material = 2\n") + "[model]\ntolerance_rel = 1e-9\n")
    scene = parse_scene(data, "tight.toml")
    with pytest.raises(SceneError, match="cannot model wood"):
        pad_contact_model(scene, scene.objects[0])


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_values = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8),
                    st.lists(st.integers(), max_size=3))


@settings(max_examples=150, deadline=None)
@given(st.sampled_from(["room_temp_c", "sample_rate_hz", "pre_contact_s", "name"]), _values,
       st.sampled_from(["kind", "gap_k", "layers", "contact_duration_s", "trials_per_material"]),
       _values)
def test_any_bad_value_is_a_scene_error_not_a_crash(top_key, top_value, pad_key, pad_value):
    data = tomllib.loads(MINIMAL)
    data[top_key] = top_value
    data["pad"][pad_key] = pad_value
    try:
        parse_scene(data, "fuzz.toml")
    except SceneError as exc:
        assert "fuzz.toml" in str(exc)


def test_the_display_floor_and_idle_policy_take_the_module_and_sink_the_scene_names():
    """control/display_floor.hardware (the idle policy's search, bench
    skin-floor) builds the module and heat sink of the scene's [pad], not
    the default ones: a scene naming parts the catalogue lacks is refused
    by their names (the catalogue holds one of each today)."""
    import dataclasses

    from telethermal.control.display_floor import hardware
    from telethermal.physics.thermoelectric import derive, get_module

    scene = parse_scene(tomllib.loads(MINIMAL), "x.toml")
    assert hardware(scene).params == derive(get_module(scene.pad.module))
    for key in ("module", "heat_sink"):
        other = dataclasses.replace(scene, pad=dataclasses.replace(scene.pad, **{key: "X-1"}))
        with pytest.raises(SceneError, match="'X-1'"):
            hardware(other)
        hardware(other, **{key: getattr(scene.pad, key)})     # named instead: built


def test_the_pad_face_size_is_a_key_and_sets_the_area_the_module_pumps_over(tmp_path):
    import dataclasses

    import numpy as np

    from telethermal.control.display_floor import hardware, pump_bounds_w_m2

    default = parse_scene(tomllib.loads(MINIMAL), "x.toml")
    module_face = default.pad.module_params()[0].spec.area_m2
    assert default.pad.size_mm is None and default.pad.area_m2 == module_face
    sized = parse_scene(tomllib.loads(MINIMAL.replace("gap_k = 10.0",
                                                      "gap_k = 10.0\nsize_mm = [10, 12.5]")),
                        "x.toml")
    assert sized.pad.size_mm == (10.0, 12.5) and sized.pad.area_m2 == pytest.approx(1.25e-4)
    for bad in ("[10]", "[0, 10]", "[10, \"a\"]", "10"):
        with pytest.raises(SceneError, match=r"x\.toml: \[pad\]: 'size_mm' must be \[width, "
                                             r"height\] in mm"):
            parse_scene(tomllib.loads(MINIMAL.replace("gap_k = 10.0",
                                                      f"gap_k = 10.0\nsize_mm = {bad}")), "x.toml")
    # Every user of the area gets the pad's face: the display's load model,
    # the in-process plant (its pad heat capacity), the display floor.
    from telethermal.teleop.display_setup import display_model_args
    assert display_model_args(with_finger_for_test(sized))["pad_area_m2"] == sized.pad.area_m2
    assert hardware(sized).area_m2 == sized.pad.area_m2
    # The same module's heat over a face a quarter of its own: four times the
    # flux at every junction temperature (W/m^2 = Qc / area), to rounding.
    side = 1e3 * module_face ** 0.5 / 2
    quarter = dataclasses.replace(default, pad=dataclasses.replace(default.pad,
                                                                   size_mm=(side, side)))
    cold, hot = np.array([10.0, 25.0, 40.0]), np.array([30.0, 30.0, 35.0])
    for a, b in zip(pump_bounds_w_m2(hardware(default), cold, hot),
                    pump_bounds_w_m2(hardware(quarter), cold, hot)):
        np.testing.assert_allclose(b, 4 * a, rtol=1e-12)


def test_every_key_a_scene_may_hold_is_documented():
    # docs/scenes.md is the schema a lab writes from: each key in a table row.
    from pathlib import Path

    from telethermal.physics.scene import FingerSpec, SensorSpec, VariabilitySpec

    doc = (Path(__file__).resolve().parents[2] / "docs" / "scenes.md").read_text()
    keys = {"name", "description", "room_temp_c", "room_humidity_pct", "sample_rate_hz",
            "pre_contact_s", "materials", "tolerance_rel", "material",
            "thickness_m"} | set(PAD_KEYS)
    for spec in (FingerSpec, SensorSpec, VariabilitySpec):
        keys |= set(spec.__dataclass_fields__)
    missing = sorted(k for k in keys if f"| `{k}` |" not in doc)
    assert not missing, f"docs/scenes.md leaves out {missing}"


@pytest.fixture
def own_materials(monkeypatch):
    """A clean registry of scene materials (they apply to the process)."""
    from telethermal.physics import materials
    monkeypatch.setattr(materials, "_SCENE_MATERIALS", {})
    monkeypatch.setattr(materials, "_PACKAGE_USED", set())


TABLE = """name,role,conductivity_w_mk,density_kg_m3,specific_heat_j_kgk,source
cork,object,0.045,120,1800,"a supplier's datasheet"
glass,object,1.05,2500,840,our own glass
"""


def test_a_scene_brings_its_own_materials(tmp_path, own_materials):
    from telethermal.physics.materials import get_material, load_materials

    (tmp_path / "lab-materials.csv").write_text(TABLE)
    scene = tmp_path / "lab.toml"
    scene.write_text('materials = "lab-materials.csv"\n' + MINIMAL.replace(
        'material = "wood"', 'material = "cork"\n[[objects]]\nmaterial = "glass"\n'
                             '[[objects]]\nmaterial = "wood"'))
    loaded = load_scene(scene)
    assert loaded.materials == ["cork", "glass", "wood"]
    assert get_material("cork").conductivity_w_mk == 0.045                  # added
    assert get_material("glass").conductivity_w_mk == 1.05                  # shadowed
    assert load_materials()["glass"].conductivity_w_mk != 1.05              # the package's kept
    assert get_material("wood") == load_materials()["wood"]                 # the package's
    # The contact models read the scene's: cork's closed form with its effusivity.
    _, choice = finger_contact_model(with_finger_for_test(loaded), loaded.objects[0])
    assert choice.error_bound_rel <= loaded.tolerance_rel
    # Another scene in this process using the package's glass is refused.
    other = tmp_path / "other.toml"
    other.write_text(MINIMAL.replace('material = "wood"', 'material = "glass"'))
    with pytest.raises(SceneError, match=r"other\.toml: .*'glass' was redefined in this "
                                         r"process by .*lab-materials\.csv"):
        load_scene(other)


@pytest.mark.parametrize("table, message", [
    (TABLE.replace("0.045", "-1"), r"lab-materials\.csv line 2, column 'conductivity_w_mk': "
                                   r"'-1' must be positive"),
    (TABLE.replace("1800", "lots"), r"lab-materials\.csv line 2, column 'specific_heat_j_kgk': "
                                    r"'lots' is not a number"),
    (TABLE.replace("cork,object", "cork,furniture"), r"line 2, column 'role': 'furniture'"),
    (TABLE.replace("density_kg_m3", "rho"), r"missing column\(s\) density_kg_m3"),
    (TABLE + "cork,object,1,1,1,x\n", r"line 4: material 'cork' appears twice"),
])
def test_a_bad_materials_table_is_named_by_file_line_and_column(tmp_path, own_materials,
                                                                table, message):
    (tmp_path / "lab-materials.csv").write_text(table)
    scene = tmp_path / "lab.toml"
    scene.write_text('materials = "lab-materials.csv"\n' + MINIMAL)
    with pytest.raises(SceneError, match=message):
        load_scene(scene)
    scene.write_text('materials = "absent.csv"\n' + MINIMAL)
    with pytest.raises(SceneError, match=r"lab\.toml: top level: 'materials' = 'absent\.csv': "
                                         r"no such file"):
        load_scene(scene)


def with_finger_for_test(scene):
    from telethermal.physics.scene import with_finger
    return with_finger(scene)


def test_what_a_scene_uses_of_the_package_cannot_change_under_it(tmp_path, own_materials):
    # A table that redefines a pad layer (alumina): a scene using the
    # package's alumina is refused after it, whatever it touches.
    (tmp_path / "t.csv").write_text(TABLE + "alumina,pad,1.0,3900,880,ours\n")
    (tmp_path / "a.toml").write_text('materials = "t.csv"\n' + MINIMAL)
    load_scene(tmp_path / "a.toml")
    with pytest.raises(SceneError, match=r"'alumina' was redefined in this process"):
        load_scene("fingertip-7")


def test_a_table_cannot_shadow_a_row_already_used_and_a_failed_scene_registers_nothing(
        tmp_path, own_materials):
    from telethermal.physics import materials

    load_scene("fingertip-7")                    # uses the package's rows (aluminium, ...)
    (tmp_path / "t.csv").write_text("# our table\n# (comments count as lines)\n" +
                                    TABLE.replace("glass,object", "aluminium,object"))
    (tmp_path / "a.toml").write_text('materials = "t.csv"\n' + MINIMAL)
    with pytest.raises(SceneError, match=r"'aluminium' shadows the package's row, which this "
                                         r"process has already used"):
        load_scene(tmp_path / "a.toml")
    assert "cork" not in materials._SCENE_MATERIALS
    # The line numbers count the comment lines: the bad value is on line 4.
    (tmp_path / "t.csv").write_text("# ours\n# two comments\n" + TABLE.replace("0.045", "x"))
    with pytest.raises(SceneError, match=r"t\.csv line 4, column 'conductivity_w_mk': 'x'"):
        load_scene(tmp_path / "a.toml")
    # A scene whose table is fine but whose body is not registers nothing.
    (tmp_path / "t.csv").write_text(TABLE)
    (tmp_path / "a.toml").write_text('materials = "t.csv"\n' + MINIMAL.replace(
        "gap_k = 10.0", "gapk = 10.0"))
    with pytest.raises(SceneError, match="gapk"):
        load_scene(tmp_path / "a.toml")
    assert "cork" not in materials._SCENE_MATERIALS


def test_a_peltier_pads_stack_ends_with_its_modules_own_plate():
    """One figure for the module's cold plate: the pad's stack is the listed
    layers, then the module's plate (modules.toml's plate_mm of alumina), the
    same plate whose thickness sets the module's pellet length and hot plate."""
    from telethermal.physics.thermoelectric import get_module
    scene = parse_scene(tomllib.loads(MINIMAL), "x.toml")
    module = get_module(scene.pad.module)
    assert [(lay.material.name, lay.thickness_m) for lay in scene.pad.layers] == [
        ("flux_sensor_film", 3.0e-4), ("thermal_grease", 2.0e-5),
        ("alumina", module.plate_mm * 1e-3)]
    assert module.plate_mm == 0.8
    water = parse_scene(tomllib.loads(MINIMAL.replace('"peltier"', '"water"')), "x.toml")
    assert [lay.material.name for lay in water.pad.layers] == ["flux_sensor_film",
                                                               "thermal_grease"]


def test_a_stack_that_lists_the_plate_itself_is_refused_saying_why():
    text = MINIMAL.replace('["thermal_grease", 2.0e-5]]',
                           '["thermal_grease", 2.0e-5], ["alumina", 2.5e-4]]')
    with pytest.raises(SceneError) as info:
        parse_scene(tomllib.loads(text), "x.toml")
    message = str(info.value)
    assert "x.toml" in message and "'alumina'" in message and "0.25 mm" in message
    assert "0.8 mm" in message and "TM-31-1.4-8.5" in message and "cold plate" in message
