"""Which scenes effusivity-fit serves, the default identifier it makes,
and a scene read from a lab's file (known to a model file by its name)."""

import dataclasses
import logging

import numpy as np
import pytest

from telethermal.data.generate import pad_database
from telethermal.errors import IdentificationError
from telethermal.ident import fitted
from telethermal.ident.prepare import from_trials
from telethermal.ident.registry import load_model, make
from telethermal.physics import scene as scene_module
from telethermal.physics.scene import _shipped, load_scene
from telethermal.teleop.models import default_method

MAX_S = 0.1


def test_serves_the_scenes_the_estimator_builds_for_and_says_why_not_the_others():
    fingertip = load_scene("fingertip-7")
    assert fitted.serves(fingertip) is None
    # The passive pad: at the object's own temperature, no heat flows.
    why = fitted.serves(load_scene("gripper-case-I-cnv"))
    assert why is not None and "0 K" in why and "passive pad" in why
    # Objects at two temperatures: one family of curves is at one.
    warm = dataclasses.replace(fingertip.objects[0], temp_c=fingertip.objects[0].temp_c + 5)
    two = dataclasses.replace(fingertip, objects=fingertip.objects + (warm,))
    assert "objects are at" in fitted.serves(two)
    # for_scene refuses what serves refuses, with the same reason.
    from telethermal.ident.effusivity import EffusivityEstimator
    with pytest.raises(IdentificationError, match="passive pad"):
        EffusivityEstimator.for_scene(load_scene("gripper-case-I-cnv"))


def test_the_default_method_is_effusivity_fit_where_it_serves_and_lda_elsewhere(caplog):
    assert default_method(load_scene("fingertip-7")) == "effusivity-fit"
    with caplog.at_level(logging.INFO, logger="telethermal.teleop.models"):
        assert default_method(load_scene("gripper-case-I-cnv")) == "effusivity-lda"
    assert "passive pad" in caplog.text and "gripper-case-I-cnv" in caplog.text


@pytest.fixture
def lab_scene(tmp_path, monkeypatch):
    """fingertip-7's pad and objects in a lab's scene file (another name)."""
    monkeypatch.setattr(fitted, "_SCENES", {})           # this test's registries
    monkeypatch.setattr(scene_module, "_FILES_BY_NAME", {})
    text = _shipped().joinpath("fingertip-7.toml").read_text()
    lines = [('name = "lab-pad"' if line.startswith("name =") else line)
             for line in text.splitlines()]
    path = tmp_path / "lab-pad.toml"
    path.write_text("\n".join(lines) + "\n")
    return load_scene(path)


def test_a_model_of_a_scene_file_finds_its_pad_model_where_the_file_was_loaded(
        lab_scene, tmp_path, monkeypatch):
    assert lab_scene.name == "lab-pad"
    contacts = from_trials(list(pad_database(lab_scene, np.random.default_rng(0))),
                           max_s=MAX_S)[0]
    model = make("effusivity-fit", scene=lab_scene, max_window_s=MAX_S).fit(contacts)
    back = load_model(model.save(tmp_path / "lab.npz"))
    assert back.scene == "lab-pad"                  # the file keeps the name
    held = from_trials(list(pad_database(lab_scene, np.random.default_rng(1))),
                       max_s=MAX_S)[0]
    last = len(model.windows_s_) - 1
    expected = model.proba_normalised(held.x, last)
    # This process loaded the scene file: its name finds it.
    assert np.array_equal(back.proba_normalised(held.x, last), expected)
    # In a process that did not load it, "lab-pad" is neither a shipped
    # scene nor a path: a clear error naming it and what to give, until the
    # file is loaded there (the demo, the slave, --scene FILE do).
    monkeypatch.setattr(scene_module, "_FILES_BY_NAME", {})
    fitted._estimator_of.cache_clear()
    fitted.clear_cache()
    fresh = load_model(tmp_path / "lab.npz")
    with pytest.raises(IdentificationError, match="'lab-pad'.*--scene FILE"):
        fresh.proba_normalised(held.x, last)
    load_scene(tmp_path / "lab-pad.toml")
    assert np.array_equal(fresh.proba_normalised(held.x, last), expected)
