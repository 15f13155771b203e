"""The tools a lab reaches for hold together (issue 44, deliverable 5):
``identify train|eval|cv --scene``, cross-validation of the default method
on a generated and on an imported dataset, a dataset folder holding pad/
and finger/, a shipped scene's name on other content."""

from __future__ import annotations

import dataclasses
import json
import shutil

import pytest

from telethermal.cli import main
from telethermal.data.generate import generate_databases
from telethermal.physics.scene import load_scene

MATERIALS = ("steel", "plexiglass", "wood")


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    """fingertip-7's pad on three materials, six touches each, with no
    finger: the folder holding pad/ (and generation.json)."""
    root = tmp_path_factory.mktemp("scene-cli") / "db"
    scene = load_scene("fingertip-7")
    scene = dataclasses.replace(
        scene, finger=None, pad=dataclasses.replace(scene.pad, trials_per_material=6),
        objects=tuple(o for o in scene.objects if o.material in MATERIALS))
    generate_databases(scene, root, seed=0)
    return root


def _cv(args, tmp_path, capsys):
    out = tmp_path / "cv.json"
    assert main(["identify", "cv", *args, "--folds", "2", "--max-window-s", "0.5",
                 "--json", str(out)]) == 0, capsys.readouterr().err
    return json.loads(out.read_text()), capsys.readouterr().out


def test_cv_of_the_default_method_on_a_generated_dataset(generated, tmp_path, capsys):
    # The folder holding pad/ is accepted for its pad/; no --method: the
    # slave's own (effusivity-fit on fingertip-7), said why.
    report, printed = _cv(["--data", str(generated)], tmp_path, capsys)
    assert report["method"] == "effusivity-fit" and "method effusivity-fit" in printed
    assert report["trials"] == 18 and report["decisions"]["touches"] == 18
    # Steel, plexiglass and wood differ in effusivity 5-fold and more: every
    # held-out touch is named right by 0.5 s.
    assert report["accuracy_by_window_s"]["0.5"] == 1.0


def test_cv_of_effusivity_fit_on_an_imported_dataset_takes_scene(generated, tmp_path, capsys):
    # A lab's import: the touches without the generator's record of a scene.
    imported = tmp_path / "lab"
    shutil.copytree(generated / "pad", imported)
    assert main(["identify", "cv", "--data", str(imported), "--method", "effusivity-fit",
                 "--folds", "2", "--max-window-s", "0.5"]) != 0
    assert "--scene" in capsys.readouterr().err
    report, _ = _cv(["--data", str(imported), "--method", "effusivity-fit", "--scene",
                     "fingertip-7"], tmp_path, capsys)
    assert report["method"] == "effusivity-fit" and report["accuracy_by_window_s"]["0.5"] == 1.0


def test_a_scene_other_than_the_datasets_is_refused(generated, tmp_path, capsys):
    assert main(["identify", "cv", "--data", str(generated), "--scene", "gripper-case-II",
                 "--method", "effusivity-lda"]) != 0
    err = " ".join(capsys.readouterr().err.split())
    assert "generated from scene 'fingertip-7'" in err and "--scene fingertip-7" in err


def test_train_and_eval_take_the_scene_and_the_folder(generated, tmp_path, capsys):
    model = tmp_path / "m.npz"
    assert main(["identify", "train", "--data", str(generated), "--scene", "fingertip-7",
                 "--method", "effusivity-lda", "--out", str(model)]) == 0
    from telethermal.ident.registry import load_model
    assert load_model(model).scene_ == "fingertip-7"
    assert main(["identify", "eval", "--model", str(model), "--data", str(generated),
                 "--scene", "fingertip-7", "--json", str(tmp_path / "e.json")]) == 0


def test_validate_of_the_folder_says_which_database_to_give(generated, capsys):
    assert main(["dataset", "validate", str(generated)]) != 0
    err = " ".join(capsys.readouterr().err.split())
    assert "holds the databases pad/" in err and f"give {generated / 'pad'}" in err


def test_calibrate_pad_writes_its_file_and_another_scenes_is_refused(tmp_path, capsys):
    scene = load_scene("fingertip-7")
    refs = tmp_path / "refs"
    generate_databases(dataclasses.replace(
        scene, finger=None, pad=dataclasses.replace(scene.pad, trials_per_material=3),
        objects=tuple(o for o in scene.objects if o.material in ("steel", "wood"))),
        refs, seed=4)
    cal = tmp_path / "cal.toml"
    assert main(["calibrate", "pad", "--scene", "fingertip-7", "--data", str(refs),
                 "--out", str(cal), "--window-s", "0.5"]) == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    assert "pad calibration of fingertip-7: 6 touches of steel, wood" in printed
    assert "flux sensor lag: x" in printed and f"wrote {cal}" in printed
    from telethermal.ident.pad_calibration import read_calibration
    assert read_calibration(cal).scene == "fingertip-7"
    imported = tmp_path / "imported"                     # no record of its scene
    shutil.copytree(refs / "pad", imported)
    assert main(["identify", "cv", "--data", str(imported), "--scene", "gripper-case-II",
                 "--calibration", str(cal)]) != 0
    err = " ".join(capsys.readouterr().err.split())
    assert "calibrates scene 'fingertip-7'" in err and "gripper-case-II" in err
    assert main(["calibrate", "pad", "--scene", "fingertip-7", "--data", str(refs / "pad"),
                 "--out", str(tmp_path / "x.toml"), "--window-s", "5"]) != 0
    assert "at least 3 touches (5 s long)" in capsys.readouterr().err
    assert not (tmp_path / "x.toml").exists()
