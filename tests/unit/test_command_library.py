"""What the commands call, called without the command line: identify's
printed lines from made-up reports, the JSON writer, the session's models,
the demo's pieces, identify train/eval, replay into a folder and the admin
status poll. Expected lines are written out by hand from the formats."""

import dataclasses
import json
from types import SimpleNamespace

import pytest

from telethermal.errors import TransportError
from telethermal.ident import evaluate as ident_evaluate
from telethermal.jsonfile import write_json
from telethermal.physics.scene import load_scene
from telethermal.services import admin_client
from telethermal.demo.run import DemoResult, demo_identify, demo_materials
from telethermal.teleop import models as teleop_models


# ------------------------------------------------------------------ identify lines
def test_identify_eval_lines_show_decisions_only_when_some_were_committed():
    report = {"accuracy_by_window_s": {"0.1": 0.5, "1.0": 0.96},
              "decision_time_s": {"n": 0}, "inference_ms_p50": 0.0123, "inference_ms_p99": 0.5}
    assert ident_evaluate.text_report(report, "e.json", "e.png") == [
        "accuracy: 0.1 s 50 %, 1.0 s 96 %",
        "inference p50 0.012 ms, p99 0.500 ms",
        "wrote e.json and e.png"]
    report |= {"decision_time_s": {"n": 3, "p50": 0.25}, "decision_accuracy": 0.9,
               "decision_unknown_rate": 0.1}
    assert ident_evaluate.text_report(report, "e.json", "e.png")[1] == (
        "decisions: 3 committed, median 0.25 s, accuracy 90.0 %; unknown 10 %")


# ------------------------------------------------------------------ JSON reports
def test_json_reports_hold_null_for_nan_and_leave_no_temporary_file(tmp_path):
    path = write_json(tmp_path / "a" / "r.json",
                      {"x": float("nan"), "y": (1.0, float("inf")), "z": {"w": 2}})
    assert path.read_text() == ('{\n  "x": null,\n  "y": [\n    1.0,\n    null\n  ],\n'
                                '  "z": {\n    "w": 2\n  }\n}\n')
    assert [p.name for p in path.parent.iterdir()] == ["r.json"]


# ------------------------------------------------------------------ session models
def test_session_models_load_what_is_given_and_train_the_rest(monkeypatch):
    said = []

    class Status:
        def __init__(self, text):
            said.append(text)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

    monkeypatch.setattr(teleop_models, "load_model", lambda p: ("loaded", p))
    monkeypatch.setattr(teleop_models, "train_generator", lambda scene, seed: ("trained", seed))
    scene = load_scene("fingertip-7")
    got = teleop_models.session_models(scene, "id.npz", None, 4, status=Status)
    assert got == (("loaded", "id.npz"), ("trained", 4))
    assert said == ["identifier: loading",
                    "generator: training on fingertip-7's finger database"]


# ------------------------------------------------------------------ the demo's pieces
def test_demo_materials_default_to_the_scenes_share_of_three():
    scene = load_scene("fingertip-7")
    assert demo_materials(scene) == ["aluminium", "plexiglass", "wood"]
    assert demo_materials(scene, ["steel"]) == ["steel"]
    assert demo_materials(scene, []) == []                 # "--materials ," runs no touch
    assert demo_materials(SimpleNamespace(materials=["glass", "rubber", "wood"])) == ["wood"]
    assert demo_materials(SimpleNamespace(materials=["a", "b", "c", "d"])) == ["a", "b", "c"]


def test_a_demo_is_ok_only_when_both_services_exited_with_0():
    assert DemoResult({"exit_codes": {"slave": 0, "master": 0}}).ok
    assert not DemoResult({"exit_codes": {"slave": 0, "master": -15}}).ok


@pytest.fixture(scope="module")
def small_scene_db(tmp_path_factory):
    """gripper-case-II with 4 pad trials per material, its databases generated."""
    from telethermal.data.generate import generate_databases

    scene = load_scene("gripper-case-II")
    scene = dataclasses.replace(scene, pad=dataclasses.replace(scene.pad, trials_per_material=4))
    out = tmp_path_factory.mktemp("demo")
    generate_databases(scene, out / "databases", seed=2)
    return scene, out


def test_demo_identify_writes_its_files_and_one_line(small_scene_db):
    scene, out = small_scene_db
    lines = []
    model = demo_identify(scene, out, 2, echo=lines.append)
    assert model.scene_ == scene.name
    assert {p.name for p in out.iterdir()} >= {"identifier.npz", "identify.json", "identify.png"}
    report = json.loads((out / "identify.json").read_text())
    assert report["trials"] == 4 * len(scene.materials)   # fresh trials: the same count
    # The default identifier on a scene it can model: effusivity-fit.
    from telethermal.ident.fitted import serves
    assert serves(scene) is None and model.method == "effusivity-fit"
    # With its model-free fallback, as the slave service trains it, saved in the file.
    from telethermal.ident.registry import load_model
    assert model.fallback_.method == "effusivity-lda"
    assert load_model(out / "identifier.npz").fallback_.method == "effusivity-lda"
    assert len(lines) == 1 and lines[0].startswith("identification (effusivity-fit, fresh "
                                                   "trials): 0.2 s ")
    assert lines[0].endswith(f"; decisions {report['decision_time_s']['n']}/"
                             f"{report['trials']} committed")


def test_identify_train_then_eval_on_a_dataset_folder(small_scene_db, tmp_path):
    from telethermal.ident.registry import train_on_dataset

    scene, out = small_scene_db
    said = []
    trained = train_on_dataset(out / "databases" / "pad", "effusivity-lda",
                               ("heat_flux_W_m2",), 1.0, tmp_path / "m.npz",
                               status=lambda text: said.append(text) or _Quiet())
    assert trained.path == tmp_path / "m.npz" and trained.path.is_file()
    assert trained.model.scene_ == scene.name and trained.skipped == []
    assert said == [f"reading {out / 'databases' / 'pad'}",
                    f"training effusivity-lda on {4 * len(scene.materials)} trials"]
    report = ident_evaluate.evaluate_saved(trained.path, out / "databases" / "pad",
                                           tmp_path / "e.json", tmp_path / "e.png",
                                           command="telethermal identify eval")
    written = json.loads((tmp_path / "e.json").read_text())
    assert written["command"] == "telethermal identify eval"
    assert written["accuracy_by_window_s"] == report["accuracy_by_window_s"]
    assert (tmp_path / "e.png").stat().st_size > 0


class _Quiet:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


# ------------------------------------------------------------------ replay
def test_replay_into_a_folder_with_the_recorded_and_with_new_gains(tmp_path, capsys, trained_models):
    from telethermal.teleop.display_config import DEFAULT_GAINS, DisplayConfig
    from telethermal.teleop.replay import replay_to_folder
    from telethermal.sim.inprocess import run_session
    from telethermal.physics.scene import with_finger

    scene = with_finger(load_scene("fingertip-7"))
    path = tmp_path / "s.mcap"
    run_session(scene, "plexiglass", *trained_models.pair(scene, 0),
                DisplayConfig(feedforward_model="static"), contact_s=0.5, seed=2, record=path)
    same, png = replay_to_folder(path, tmp_path / "same")
    # Same models and gains: the replay is the recording, sample for sample.
    assert same["identical"] and same["junction_max_abs_diff_c"] == 0.0
    assert json.loads((tmp_path / "same" / "replay.json").read_text()) == same
    assert png == tmp_path / "same" / "replay.png" and png.is_file()
    other, _ = replay_to_folder(path, tmp_path / "other",
                                gains_kp_ki_kd=(2 * DEFAULT_GAINS.kp, DEFAULT_GAINS.ki, 0.0))
    assert not other["identical"] and other["junction_max_abs_diff_c"] > 0.0
    # The error against direct contact, as the session measured it.
    session = json.loads(json.dumps(same))["direct"]
    assert set(session) == {"flux_rms_error_rel", "flux_rms_error_rel_first_s",
                            "temp_rms_error_c"} and 0 < session["temp_rms_error_c"] < 5
    # The command: every touch by default, the figures printed; a touch the
    # recording does not hold is a clear error.
    from telethermal.cli import main

    assert main(["replay", str(path), "--out", str(tmp_path / "cli")]) == 0
    printed = capsys.readouterr().out
    assert f"skin {session['temp_rms_error_c']:.2f} K RMS" in printed
    assert main(["replay", str(path), "--out", str(tmp_path / "cli2"), "--touch", "2"]) == 2
    assert "touch 2 asked, the recording holds one touch (0)" in capsys.readouterr().err
    assert not (tmp_path / "cli2").exists()


# ------------------------------------------------------------------ admin status
def _fake_requests(monkeypatch, answers):
    """``request`` answering from ``answers[role]``: a list of replies (or
    errors) taken in turn."""
    asked = []

    def request(where, role, cmd, timeout_s=5.0, **args):
        asked.append((role, cmd))
        answer = answers[role].pop(0) if len(answers[role]) > 1 else answers[role][0]
        if isinstance(answer, Exception):
            raise answer
        return answer

    monkeypatch.setattr(admin_client, "request", request)
    return asked


SLAVE = {"role": "slave", "state": "idle", "peer_alive": True, "counters": {}}


def test_a_status_poll_names_a_role_that_does_not_answer(monkeypatch):
    _fake_requests(monkeypatch, {"slave": [SLAVE],
                                 "master": [TransportError("no reply")]})
    poll = admin_client.poll_status({"slave": 1, "master": 2}, ("slave", "master"))
    assert poll.replies == {"slave": SLAVE}
    assert poll.lines == admin_client.describe_status(SLAVE) + [
        "master: not reachable here (no reply)"]
    assert isinstance(poll.error, TransportError)
    # The slave answered, the master did not: the session is not live
    # ('admin status --wait' exits 1), however the slave's reply looks.
    assert not poll.live


def test_a_status_poll_asks_again_until_the_session_is_live(monkeypatch):
    idle = {"role": "master", "state": "idle", "peer_alive": False, "counters": {}}
    live = idle | {"state": "session", "peer_alive": True, "session": {"id": 1}}
    asked = _fake_requests(monkeypatch, {"master": [idle, idle, live]})
    poll = admin_client.poll_status({"master": 2}, ("master",), wait_s=3600.0, every_s=0.0)
    assert poll.live and poll.replies == {"master": live} and poll.error is None
    assert asked == [("master", "status")] * 3


def test_bench_view_keeps_the_command_it_ran_with(tmp_path, monkeypatch):
    from telethermal.bench import view

    monkeypatch.setattr(view, "run_view_bench",
                        lambda **kw: {"command": "telethermal bench view --json default.json"})
    cmd = "telethermal bench view --json v.json --touches 1"
    view.run_and_save(tmp_path / "v.json", touches=1, command=cmd)
    assert json.loads((tmp_path / "v.json").read_text())["command"] == cmd
    view.run_and_save(tmp_path / "d.json")                  # no command given: the bench's own
    assert json.loads((tmp_path / "d.json").read_text())["command"] == \
        "telethermal bench view --json default.json"
