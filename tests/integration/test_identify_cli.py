"""identify train / eval end to end on a small generated database."""

import dataclasses
import json

import pytest

from telethermal.cli import main
from telethermal.data.generate import generate_databases
from telethermal.physics.scene import load_scene


@pytest.fixture(scope="module")
def gripper_db(tmp_path_factory):
    root = tmp_path_factory.mktemp("ident") / "db"
    scene = load_scene("gripper-case-II")
    scene = dataclasses.replace(scene, pad=dataclasses.replace(scene.pad, trials_per_material=6))
    generate_databases(scene, root, seed=2)
    return root / "pad"


def test_train_eval_round_trip(gripper_db, tmp_path, capsys):
    model = tmp_path / "lda.npz"
    assert main(["identify", "train", "--data", str(gripper_db), "--method", "effusivity-lda",
                 "--out", str(model)]) == 0
    out = tmp_path / "eval.json"
    assert main(["identify", "eval", "--model", str(model), "--data", str(gripper_db),
                 "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    # Evaluated on its own training data: said, with the count.
    assert report["trials_in_training"] == report["trials"]
    assert f"warning: {report['trials']} of {report['trials']} evaluation trials were in the " \
        "model's training data" in " ".join(capsys.readouterr().out.split())
    # From the model's first window (decisions commit from there), then tenths.
    from telethermal.ident.registry import load_model
    first = [f"{w:g}" for w in load_model(model).windows_s_ if w < 0.1 - 1e-9]
    assert first and list(report["accuracy_by_window_s"]) == first + [
        f"{0.1 * k:.1f}" for k in range(1, 11)]
    # Aluminium, glass and wood differ in effusivity by 10x and more: separable at 1 s.
    assert report["accuracy_by_window_s"]["1.0"] == 1.0
    # Aluminium alone of the first paper's merged materials: no "5 merged
    # classes" figure (the demo printed "5 merged classes at 1 s nan %").
    assert "confusion" in report and "accuracy_5_at_end" not in report
    # Each window's accuracy with its count and 95 % interval.
    for w, acc in report["accuracy_by_window_s"].items():
        lo, hi = report["accuracy_ci_by_window_s"][w]
        assert lo <= acc <= hi and report["accuracy_n_by_window_s"][w] == report["trials"]
    assert report["inference_ms_p99"] > 0 and "confusion" in report
    assert (tmp_path / "eval.png").stat().st_size > 10_000


def test_methods_lists_names(capsys):
    assert main(["identify", "methods"]) == 0
    out = capsys.readouterr().out
    assert "pca-fnn" in out and "effusivity-lda" in out


def test_eval_with_mismatched_channels_is_a_clear_error(gripper_db, tmp_path, capsys):
    model = tmp_path / "t.npz"
    assert main(["identify", "train", "--data", str(gripper_db), "--method", "effusivity-lda",
                 "--channels", "heat_flux_W_m2,force_N", "--out", str(model)]) == 0
    # A dataset without force_N: strip the column from one trial file.
    import shutil
    other = tmp_path / "noforce"
    shutil.copytree(gripper_db, other)
    for f in (other / "trials").iterdir():
        lines = [",".join(line.split(",")[:3]) for line in f.read_text().splitlines()]
        f.write_text("\n".join(lines) + "\n")
    capsys.readouterr()
    assert main(["identify", "eval", "--model", str(model), "--data", str(other),
                 "--json", str(tmp_path / "x.json")]) == 2
    assert "force_N" in capsys.readouterr().err


def test_passive_pad_at_zero_gap_is_unknown(tmp_path):
    from telethermal.data.dataset import load_dataset
    from telethermal.ident.evaluate import evaluate
    from telethermal.ident.prepare import from_trials
    from telethermal.ident.registry import make

    scene = load_scene("gripper-case-I-pro")
    cnv = load_scene("gripper-case-I-cnv")
    small = lambda s: dataclasses.replace(s, pad=dataclasses.replace(s.pad, trials_per_material=4))  # noqa: E731
    generate_databases(small(scene), tmp_path / "pro", seed=1)
    generate_databases(small(cnv), tmp_path / "cnv", seed=1)
    model = make("effusivity-lda").fit(from_trials(load_dataset(tmp_path / "pro" / "pad"))[0])
    report = evaluate(model, load_dataset(tmp_path / "cnv" / "pad"))
    # The passive pad sits at the object's temperature: the measured gap is
    # under 2 K (five IR-thermometer sigmas). Never a confident wrong class.
    assert report["decision_unknown_rate"] == 1.0
    assert report["unknown_reasons"] == {"gap too small": report["trials"]}


def test_a_model_of_another_scene_is_refused_on_its_data(gripper_db, tmp_path, capsys):
    # The model says it was trained on gripper-case-II; a dataset generated
    # from another scene (its generation.json) is refused, naming both.
    model = tmp_path / "lda.npz"
    assert main(["identify", "train", "--data", str(gripper_db), "--method", "effusivity-lda",
                 "--out", str(model)]) == 0
    other = tmp_path / "other"
    import shutil
    shutil.copytree(gripper_db.parent, other)
    meta = other / "generation.json"
    meta.write_text(meta.read_text().replace('"gripper-case-II"', '"gripper-case-V"'))
    assert main(["identify", "eval", "--model", str(model), "--data", str(other / "pad"),
                 "--json", str(tmp_path / "e.json")]) != 0
    err = capsys.readouterr().err
    assert "gripper-case-II" in err and "gripper-case-V" in err


def test_cross_validation_by_group_with_intervals_and_decisions(gripper_db, tmp_path, capsys):
    out = tmp_path / "cv.json"
    assert main(["identify", "cv", "--data", str(gripper_db), "--method", "effusivity-lda",
                 "--folds", "3", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["folds"] == 3 and report["grouped_by"] == "group" and report["groups"] >= 3
    # The table starts at the method's first window (a decision can use it),
    # not at 0.1 s.
    from telethermal.ident.registry import load_model
    model = tmp_path / "m.npz"
    assert main(["identify", "train", "--data", str(gripper_db), "--method", "effusivity-lda",
                 "--out", str(model)]) == 0
    windows = [float(w) for w in report["accuracy_by_window_s"]]
    assert windows == load_model(model).windows_s_ and windows[0] < 0.1
    for w, acc in report["accuracy_by_window_s"].items():
        lo, hi = report["accuracy_ci_by_window_s"][w]
        assert 0 <= lo <= acc <= hi <= 1
        assert report["accuracy_n_by_window_s"][w] <= report["trials"]
    d = report["decisions"]
    assert d["named_rate"] + d["pair_rate"] + d["unknown_rate"] == pytest.approx(1.0)
    # Every held-out touch is in the decisions' confusion once.
    assert sum(sum(row.values()) for row in d["confusion"].values()) == report["trials"]
    assert set(d["confusion"]) == set(report["classes"])
    assert 0 <= report["calibration_ece"] <= 1
    printed = capsys.readouterr().out
    assert "3 folds by group" in printed and "decisions:" in printed


def test_cross_validation_needs_two_groups_and_two_folds(gripper_db, tmp_path, capsys):
    import shutil

    one = tmp_path / "one-group"
    shutil.copytree(gripper_db, one)
    manifest = one / "manifest.csv"
    lines = manifest.read_text().splitlines()
    col = lines[0].split(",").index("group")
    rows = [r.split(",") for r in lines[1:]]
    for r in rows:
        r[col] = "everyone"
    manifest.write_text("\n".join([lines[0]] + [",".join(r) for r in rows]) + "\n")
    assert main(["identify", "cv", "--data", str(one), "--method", "effusivity-lda"]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "holds out whole groups, and these trials have 1 (everyone)" in err
    assert main(["identify", "cv", "--data", str(gripper_db), "--method", "effusivity-lda",
                 "--folds", "1"]) == 2
    assert "needs at least 2 folds" in capsys.readouterr().err


def test_bench_identify_on_a_labs_own_scene(tmp_path, capsys):
    scene = tmp_path / "two.toml"
    scene.write_text((
        'name = "two"\nroom_temp_c = 24.0\nsample_rate_hz = 100.0\n[pad]\nkind = "peltier"\n'
        'layers = [["flux_sensor_film", 3.0e-4], ["thermal_grease", 2.0e-5]]'
        '\ngap_k = 10.0\ncontact_duration_s = 1.0\n'
        'trials_per_material = 4\n[[objects]]\nmaterial = "wood"\nthickness_m = 0.03\n'
        '[[objects]]\nmaterial = "aluminium"\nthickness_m = 0.03\n'))
    out = tmp_path / "bi.json"
    assert main(["bench", "identify", "--scene", str(scene), "--methods", "effusivity-lda",
                 "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["scene"] == str(scene) and "the papers' sections" in report["not_run"][0]
    cv = report["methods"]["effusivity-lda"]
    assert cv["classes"] == ["aluminium", "wood"] and cv["trials"] == 8
    assert cv["accuracy_by_window_s"]["1"] == 1.0           # 60x apart in effusivity
    assert (tmp_path / "bi.png").is_file()
    printed = capsys.readouterr().out
    # 4 trials of each material, one group each: 4 groups, so 4 folds, said.
    assert "effusivity-lda: 4 folds by group (4 groups, 8 trials)" in printed
    assert "note: 5 folds asked, 4 groups: 4 folds" in printed


def test_the_unseen_weight_is_effusivity_fits_and_kept_in_its_model(gripper_db, tmp_path,
                                                                    capsys):
    from telethermal.ident.registry import load_model

    capsys.readouterr()
    assert main(["identify", "train", "--data", str(gripper_db), "--method", "effusivity-lda",
                 "--unseen-weight", "1", "--out", str(tmp_path / "lda.npz")]) == 2
    err = capsys.readouterr().err
    assert "--unseen-weight" in err and "effusivity-lda" in err
    assert not (tmp_path / "lda.npz").exists()
    assert main(["identify", "train", "--data", str(gripper_db), "--method", "effusivity-fit",
                 "--unseen-weight", "-1", "--out", str(tmp_path / "bad.npz")]) == 2
    assert "unseen_weight" in capsys.readouterr().err
    assert main(["identify", "train", "--data", str(gripper_db), "--method", "effusivity-fit",
                 "--max-window-s", "0.2", "--unseen-weight", "1",
                 "--out", str(tmp_path / "fit.npz")]) == 0
    assert load_model(tmp_path / "fit.npz").unseen_weight == 1.0


def test_a_finger_database_given_for_the_pads_touches_is_refused_naming_the_pad(tmp_path,
                                                                                 capsys):
    """The finger database (fingertip touches, the generator's) given where
    the pad's touches go had been read as pad contacts (calibrate pad and
    models --data ran on for minutes, saying nothing): each command says
    what it is and which folder to give, and models writes no folder."""
    scene = load_scene("fingertip-7")
    scene = dataclasses.replace(
        scene, objects=scene.objects[:2],
        pad=dataclasses.replace(scene.pad, trials_per_material=2),
        finger=dataclasses.replace(scene.finger, persons=1, trials_per_person=1,
                                   contact_duration_s=1.0))
    generate_databases(scene, tmp_path / "db", seed=2)
    finger, pad = tmp_path / "db" / "finger", tmp_path / "db" / "pad"
    for argv in (["calibrate", "pad", "--scene", "fingertip-7", "--data", str(finger),
                  "--out", str(tmp_path / "cal.toml")],
                 ["models", "--data", str(finger), "--out", str(tmp_path / "models")],
                 ["identify", "cv", "--data", str(finger), "--method", "effusivity-lda"]):
        assert main(argv) == 2, argv
        captured = capsys.readouterr()
        err = " ".join((captured.out + captured.err).split())
        assert f"{finger} is a finger database" in err and f"give {pad}" in err, (argv, err)
    assert not (tmp_path / "models").exists() and not (tmp_path / "cal.toml").exists()
