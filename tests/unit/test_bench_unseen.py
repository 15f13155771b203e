"""``telethermal bench unseen`` (issue 30, part 4, first cut): the unseen
set, the touched scene, the per-material figures, and the command line's
bad input (one line naming the bad value, exit 2)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from telethermal.bench import unseen
from telethermal.cli import main
from telethermal.data.generate import pad_database
from telethermal.errors import SceneError, UnknownMaterialError
from telethermal.ident.effusivity import EffusivityEstimate
from telethermal.physics.materials import get_material
from telethermal.physics.scene import load_scene

TRAINED = ["aluminium", "steel", "marble", "plexiglass", "graphite", "rubber", "wood"]


def test_default_unseen_set_holds_the_issues_materials_and_two_from_a_scene_table():
    objects = (unseen.package_objects(unseen.DEFAULT_UNSEEN, TRAINED, 24.0, 0.03)
               + unseen.scene_objects(unseen.default_unseen_scene_path(), TRAINED))
    names = [o.material for o in objects]
    assert {"copper", "carbon_steel", "glass", "foam"} <= set(names) and len(names) >= 6
    for name in names:                         # every property with its source named
        m = get_material(name)
        assert m.role == "object" and "Incropera" in m.source and name not in TRAINED


@pytest.mark.parametrize("names, error, word", [
    ("copper,unobtainium", UnknownMaterialError, "unobtainium"),
    ("skin", SceneError, "skin"),
    ("glass,wood", SceneError, "wood"),
    ("glass,,foam", SceneError, "empty"),
])
def test_bad_unseen_names_are_refused_naming_the_value(names, error, word):
    with pytest.raises(error, match=word):
        unseen.package_objects(names, TRAINED, 24.0, 0.03)


def test_touch_scene_adds_the_unseen_objects_on_the_same_pad():
    base = load_scene("fingertip-7")
    objects = unseen.package_objects("glass,foam", TRAINED, 24.0, 0.03)
    scene = unseen.touch_scene(base, objects)
    assert scene.pad == base.pad and scene.sensors == base.sensors
    assert scene.materials == TRAINED + ["glass", "foam"]
    with pytest.raises(SceneError, match="glass given twice"):
        unseen.touch_scene(scene, objects[:1])
    short = dataclasses.replace(
        unseen.touch_scene(dataclasses.replace(base, objects=base.objects[:1]), objects),
        pad=dataclasses.replace(base.pad, trials_per_material=1, contact_duration_s=0.2))
    trials = pad_database(short, np.random.default_rng(0))
    assert [t.material for t in trials] == ["aluminium", "glass", "foam"]


def test_aliases_of_trained_materials_are_named():
    assert unseen.same_as_trained("stainless_steel", TRAINED) == "steel"
    assert unseen.same_as_trained("glass", TRAINED) is None


def _estimate(e, lo, hi, fits=True):
    return EffusivityEstimate(e, (lo, hi), 0.01, 0.5, 51, 3000.0, -0.005, 1.0, fits, False,
                              (np.log(e), 0.0, -0.005))


def test_material_summary_counts_coverage_and_median_error():
    true = get_material("glass").effusivity
    rows = [{"windows": {w: _estimate(true * f, true * f * 0.97, true * f * 1.03)
                         for w in unseen.WINDOWS_S}} for f in (1.0, 1.02, 1.10, 0.90)]
    out = unseen.material_summary("glass", rows, TRAINED)
    assert out["effusivity_rel_error"]["0.5"] == pytest.approx(0.06)      # median of 0, 2, 10, 10 %
    cov = out["interval_coverage"]["0.5"]
    assert (cov["covered"], cov["n"], cov["rate"]) == (2, 4, 0.5)
    assert cov["ci"][0] < 0.5 < cov["ci"][1]
    # the standardised error: ln(e_hat / e) over each estimate's sd (0.01)
    z = np.log([1.0, 1.02, 1.10, 0.90]) / 0.01
    assert out["interval_z"]["0.5"]["mean"] == pytest.approx(z.mean(), rel=1e-12)
    assert out["interval_z"]["0.5"]["rms"] == pytest.approx(np.sqrt(np.mean(z * z)), rel=1e-12)
    assert not out["trained"] and out["reported"].startswith("not_run")
    assert out["flux_rms_rel"].startswith("not_run") and out["skin_rms_k"].startswith("not_run")


@pytest.fixture(autouse=True)
def wide_console(monkeypatch):
    """The error console as wide as a long message: its lines are then the
    message's own, not the terminal's wrapping."""
    from telethermal.cli._common import console
    monkeypatch.setattr(console, "width", 1000)


def _run_cli(tmp_path, capsys, *args):
    code = main(["bench", "unseen", "--json", str(tmp_path / "u.json"), *args])
    err = capsys.readouterr().err.strip()
    return code, err


def test_cli_unknown_material_is_one_line_naming_it(tmp_path, capsys):
    code, err = _run_cli(tmp_path, capsys, "--unseen", "copper,unobtainium")
    assert code == 2 and "unobtainium" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "u.json").exists()


def test_cli_trained_material_as_unseen_is_refused(tmp_path, capsys):
    code, err = _run_cli(tmp_path, capsys, "--unseen", "marble")
    assert code == 2 and "marble" in err and "trained" in err and len(err.splitlines()) == 1


def test_cli_missing_unseen_scene_names_the_file(tmp_path, capsys):
    code, err = _run_cli(tmp_path, capsys, "--unseen-scene", str(tmp_path / "nope.toml"))
    assert code == 2 and "nope.toml" in err and len(err.splitlines()) == 1


def test_cli_bad_seeds_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["bench", "unseen", "--json", str(tmp_path / "u.json"), "--seeds", "0"])
    assert exc.value.code == 2 and "'0' must be positive" in capsys.readouterr().err


def test_targets_pool_coverage_per_window_and_judge_the_unseen_error():
    e_glass, e_wood = get_material("glass").effusivity, get_material("wood").effusivity
    glass = [{"windows": {w: _estimate(e_glass * 1.2, e_glass * 1.1, e_glass * 1.3)
                          for w in unseen.WINDOWS_S}}] * 3          # 20 % off, never covered
    wood = [{"windows": {w: _estimate(e_wood, e_wood * 0.9, e_wood * 1.1)
                         for w in unseen.WINDOWS_S}}] * 5
    materials = {"glass": unseen.material_summary("glass", glass, TRAINED),
                 "wood": unseen.material_summary("wood", wood, TRAINED)}
    targets = unseen._targets(materials)
    assert targets["unseen_rel_error_within_10pct_by_0.5_s"] == {"glass": False}
    pooled = targets["coverage_by_window"]["0.5"]
    assert (pooled["covered"], pooled["n"], pooled["within_90_98"]) == (5, 8, False)
    assert targets["unseen_coverage_by_window"]["1"]["covered"] == 0


def test_the_unseen_set_from_the_options(tmp_path):
    base = load_scene("fingertip-7")
    default, path = unseen.unseen_objects(base)
    assert [o.name for o in default] == ["copper", "carbon_steel", "glass", "foam", "brass",
                                         "concrete", "glass-slide-on-aluminium"]
    assert path == unseen.default_unseen_scene_path()
    (tmp_path / "lab.csv").write_text(
        "name,role,conductivity_w_mk,density_kg_m3,specific_heat_j_kgk,source\n"
        "cork_lab,object,0.039,120.0,1800.0,\"Cork, board, Incropera A.3\"\n")
    scene_file = tmp_path / "lab.toml"
    text = Path(unseen.default_unseen_scene_path()).read_text()
    scene_file.write_text(text[:text.index("[[objects]]")].replace(
        "unseen-materials.csv", "lab.csv")
        + '[[objects]]\nmaterial = "cork_lab"\ntemp_c = 40.0\nthickness_m = 0.03\n')
    alone, path = unseen.unseen_objects(base, unseen_scene=str(scene_file))
    assert [(o.material, o.temp_c) for o in alone] == [("cork_lab", 40.0)]
    both, _ = unseen.unseen_objects(base, unseen="foam", unseen_scene=str(scene_file))
    assert [o.material for o in both] == ["foam", "cork_lab"]
    active = load_scene("gripper-case-I-pro")          # glass is trained there: left out
    names = [o.name for o in unseen.unseen_objects(active)[0]]
    assert "glass" not in names and "copper" in names
    assert {o.temp_c for o in unseen.unseen_objects(active)[0]} == {34.0}


def test_reported_counts_named_new_and_unknown_from_the_decisions():
    from telethermal.ident.anytime import Decision
    from telethermal.ident.label import Reason
    decisions = [Decision("graphite", 0.999, 0.1, Reason.CONFIDENT),
                 Decision("aluminium|steel", 0.999, 0.1, Reason.CONFIDENT_GROUP),
                 Decision("graphite", 0.999, 0.2, Reason.CONFIDENT),
                 Decision("new material", 0.99999, 1.0, Reason.NEW_MATERIAL),
                 Decision("new material", 0.99999, 1.0, Reason.NEW_MATERIAL, 0.06,
                          revised_from="graphite"),
                 Decision("unknown", 0.5, None, Reason.NOT_CONFIDENT)]
    assert unseen.reported(decisions) == {
        "named": 3, "new": 2, "unknown": 1, "n": 6,
        "named_as": {"aluminium|steel": 1, "graphite": 2},
        "unknown_reasons": {"not confident": 1},
        # told graphite from 0.06 s until the last window: counted apart
        "named_then_new": 1, "named_first_as": {"graphite": 1}}


def test_within_spread_is_the_classes_t_predictive_at_the_last_window():
    """A stand-in model whose last window holds graphite at ln 1505 with an
    sd of 0.02 from ten touches: glass (ln 1620) is 3.5 predictive scales
    (0.02 sqrt(1.1)) out, within its 1 - 1e-4 predictive (t with 9 degrees
    of freedom: 6.6 scales); marble's mean at ln 2496 puts glass 21 out."""
    class Model:
        classes_ = ["graphite", "marble"]
        windows_s_ = [0.5, 1.0]
        outlier_p = 1e-4
        params_ = [{}, {"n": np.array([10.0, 10.0]),
                        "means": np.log([1505.0, 2496.0]),
                        "var": np.array([0.02, 0.02]) ** 2}]
    assert unseen.within_spread(Model(), "glass", ["graphite", "marble"]) == {
        "graphite": True, "marble": False}


def test_the_bench_scores_what_the_slave_reports(fit_model_0_3s, monkeypatch):
    """Each window's estimate in the bench is the identifier's own
    (EffusivityFit.interval_of: the fit walked as the slave walks, the
    calibrated interval): at the slave's 0.1 and 0.3 s windows it is the
    reading the slave sends (effusivity_reading's ends), its sd the one
    the interval is made of, and the uncalibrated column the estimator's
    own interval at the same fit."""
    from fitcases import SCENE, contacts

    monkeypatch.setattr(unseen, "WINDOWS_S", (0.1, 0.3))
    touches = contacts(SCENE, 3)
    timed = {0}
    rows = unseen.estimates(fit_model_0_3s, touches, timed)
    est, gap_k = fit_model_0_3s.estimator()
    assert len(rows) == len(touches.labels)
    for i in (0, 7, len(rows) - 1):
        x = touches.x[i, :, 0]
        for w in (0.1, 0.3):
            got = rows[i]["windows"][w]
            theta, e, lo, hi, sd, _ = fit_model_0_3s.interval_of(x, w)
            reading = fit_model_0_3s.effusivity_reading(touches.x[i:i + 1],
                                                        fit_model_0_3s.windows_s_.index(w))
            assert (got.effusivity_w_s05_m2k, *got.interval_w_s05_m2k, got.log_sd) == \
                (e, lo, hi, sd)
            assert (reading.effusivity_lo_w_s05_m2k, reading.effusivity_hi_w_s05_m2k) == (lo, hi)
            n = int(round(w * est.sample_rate_hz)) + 1
            assert rows[i]["laplace"][w].interval_w_s05_m2k == \
                est.interval_at(x[:n], gap_k, theta)[1:3]
    assert set(rows[0]["cold_s"]) == {0.1, 0.3} and not rows[1]["cold_s"]


@pytest.mark.parametrize("typed, kept", [
    ("telethermal bench unseen --json /home/ada/runs/u.json",
     "telethermal bench unseen --json u.json"),
    ("telethermal bench render --json=/srv/a/r.json --png out/r.png",
     "telethermal bench render --json=r.json --png out/r.png"),
    ("telethermal bench unseen --json bench/results/u.json",
     "telethermal bench unseen --json bench/results/u.json"),
])
def test_a_reports_command_names_no_folder_of_the_machine(typed, kept):
    """The command kept in a bench's JSON (and so in bench/report.md): an
    absolute path is shortened to its file's name, a relative one kept."""
    from telethermal.cli._common import portable_command
    assert portable_command(typed) == kept


def test_the_command_typed_keeps_a_path_with_a_space_whole(monkeypatch):
    from telethermal.cli._common import _command
    monkeypatch.setattr("sys.argv", ["telethermal", "bench", "unseen", "--json",
                                     "/home/ada/run 4/u.json", "--seeds", "2"])
    assert _command() == "telethermal bench unseen --json u.json --seeds 2"
