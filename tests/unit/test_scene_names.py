"""A scene file that names a shipped scene but differs from it is refused
with the fix (issue 44, deliverable 5)."""

from __future__ import annotations

from importlib import resources

import pytest

from telethermal.errors import SceneError
from telethermal.physics.scene import load_scene


def _shipped_text(name="fingertip-7") -> str:
    return resources.files("telethermal").joinpath(f"scenes/{name}.toml").read_text()


def test_a_copy_with_another_pad_keeping_the_name_is_refused(tmp_path):
    path = tmp_path / "lab.toml"
    path.write_text(_shipped_text().replace('["flux_sensor_film", 3.0e-4]',
                                            '["flux_sensor_film", 6.0e-4]'))
    with pytest.raises(SceneError, match="give your scene its own name") as err:
        load_scene(path)
    assert "'fingertip-7' is a shipped scene's" in str(err.value) and "pad" in str(err.value)


def test_a_copy_with_as_built_tables_keeping_the_name_is_refused(tmp_path):
    path = tmp_path / "lab.toml"
    path.write_text(_shipped_text() + "\n[as_built]\nsd = 0.15\nseed = 1\n")
    with pytest.raises(SceneError, match="as_built"):
        load_scene(path)


def test_an_unchanged_copy_or_a_renamed_one_loads(tmp_path):
    same = tmp_path / "same.toml"
    same.write_text(_shipped_text().replace("sampled at 100 Hz", "sampled at 100 Hz (a copy)"))
    assert load_scene(same).name == "fingertip-7"
    other = tmp_path / "lab.toml"
    other.write_text(_shipped_text().replace('name = "fingertip-7"', 'name = "lab"').replace(
        '["flux_sensor_film", 3.0e-4]', '["flux_sensor_film", 6.0e-4]'))
    assert load_scene(other).pad.layers[0].thickness_m == 6.0e-4


def test_models_says_which_method_and_why():
    from telethermal.teleop.models import _dataset_method, method_and_reason
    method, why = method_and_reason(load_scene("fingertip-7"))
    assert method == "effusivity-fit" and "pad model" in why
    method, why = method_and_reason(load_scene("gripper-case-I-cnv"))
    assert method == "effusivity-lda" and "passive pad" in why
    method, scene, why = _dataset_method(load_scene("fingertip-7"), None)
    assert method == "effusivity-lda" and scene is None and "names no scene" in why
