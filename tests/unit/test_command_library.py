"""What the commands call, called without the command line: the benches'
printed lines from made-up reports, the JSON writer, the session's models,
the demo's pieces, identify train/eval, replay into a folder and the admin
status poll. Expected lines are written out by hand from the formats."""

import dataclasses
import json
from types import SimpleNamespace

import pytest

from telethermal.bench import devices, identify_text, physics, record, transport, view
from telethermal.errors import TransportError
from telethermal.ident import evaluate as ident_evaluate
from telethermal.jsonfile import write_json
from telethermal.physics.scene import load_scene
from telethermal.services import admin_client
from telethermal.demo.run import DemoResult, demo_identify, demo_materials
from telethermal.teleop import models as teleop_models


# ------------------------------------------------------------------ bench lines
def test_physics_lines():
    report = {"default": {"max_rel_error": 1.234e-4, "window_s": [0.05, 60.0],
                          "runtime_s_per_simulated_s": 2e-4},
              "batch_70x1s_1khz": {"trials": 70, "runtime_s": 0.5, "model_choice_s": 0.25},
              "databases_fingertip_7": {"simulation_s": 1.5, "with_csv_files_s": 3.75},
              "heat_balance_60s": {"relative_error": 3e-9}, "png": "p.png"}
    assert physics.text_report(report, "r.json") == [
        "default model: max relative flux error 1.23e-04 over 0.05-60 s, 0.200 ms per "
        "simulated second",
        "batch of 70 one-second trials at 1 kHz: 0.500 s (+ 0.250 s choosing the models, once "
        "per scene)",
        "fingertip-7 databases: simulation 1.50 s, with CSV files 3.75 s",
        "heat balance over 60 s: 3.0e-09 relative",
        "wrote r.json and p.png"]


def test_record_lines():
    report = {"busy_mean_us": {"without": 300.4, "with": 310.6}, "extra_busy_per_period_us": 10.2,
              "cost_of_period_budget": 0.0102, "log_call_p50_us": 2.0, "log_call_p99_us": 5.4,
              "deadline_misses": {"without": 1, "with": 2},
              "steps": {"without": 3000, "with": 3000}}
    assert record.text_report(report, "r.json") == [
        "master loop busy per period: 300 us without recording, 311 us with: +10.2 us = +1.0 % "
        "of the 1 ms budget",
        "recorder call per period: p50 2.0 us, p99 5.4 us; deadline misses 1 of 3000 without, "
        "2 of 3000 with",
        "wrote r.json"]
    # Cheaper with than without (the spread between runs): one sign, not "+-".
    report.update(extra_busy_per_period_us=-47.1, cost_of_period_budget=-0.0471)
    assert record.text_report(report, "r.json")[0].endswith("with: -47.1 us = -4.7 % of the "
                                                            "1 ms budget")


def test_transport_lines_name_the_slowest_kind_and_a_skipped_part():
    report = {"codec": {"hello": {"bytes": 40, "encode_us": 1.0, "decode_us": 2.0},
                        "flux_trajectory": {"bytes": 900, "encode_us": 5.0, "decode_us": 7.5}},
              "loopback": {"e2e_plain": {"p50_us": 80.0, "p99_us": 150.0, "max_us": 400.0,
                                         "messages_per_s": 12000.0},
                           "ratio": 1.5},                      # not a row: not printed
              "namespaces": {"skipped": "not root"},
              "e2e_p50_us": 80.0, "e2e_p99_us": 150.0, "ratio_to_raw_zmq_p50": 1.6,
              "curve_ratio_to_raw_zmq_p50": 1.25}
    assert transport.text_report(report, "r.json") == [
        "codec: slowest kind flux_trajectory (900 B) encode 5.0 us, decode 7.5 us",
        "loopback   e2e_plain  one-way p50     80 us, p99    150 us, max    400 us, 12000 msg/s",
        "namespaces: skipped (not root)",
        "end to end on loopback: p50 80 us, p99 150 us; 1.60x raw pyzmq (plain), 1.25x with "
        "CURVE",
        "wrote r.json"]


def _devices_report(slave):
    path = {"read": {"p50_us": 1.0, "p99_us": 2.0}, "apply": {"p50_us": 3.0, "p99_us": 4.0}}
    hop = {"p50_us": 100.0, "p99_us": 200.0, "max_us": 900.0, "n": 5}
    return {"paths": {"sim": path, "emulated": path | {"serial_sensor_to_controller": hop,
                                                       "can_controller_to_actuator": hop}},
            "sessions_real_clock": {"sim": {
                "rate_hz": 500.0, "loop_period_p99_us": 1001.0, "busy_p99_us": 300.0, "deadline_misses": 0,
                "steps": 3000, "flux_rms_error_rel_whole": 0.0125}},
            "slave": slave}


def test_devices_lines_keep_the_empty_line_where_there_is_no_slave_part():
    lines = devices.text_report(_devices_report(None), "r.json")
    assert lines == [
        "sim       read p50    1.0 us p99    2.0 us; apply p50    3.0 us p99    4.0 us",
        "emulated  read p50    1.0 us p99    2.0 us; apply p50    3.0 us p99    4.0 us",
        "emulated serial_sensor_to_controller: p50 100.0 us, p99 200.0 us, max 900 us",
        "emulated can_controller_to_actuator: p50 100.0 us, p99 200.0 us, max 900 us",
        "500 Hz real-clock session, sim     : period p99 1001 us, busy p99 300 us, 0 missed "
        "deadlines of 3000, flux error 1.25 %",
        "",
        "wrote r.json"]
    hop = {"p50_us": 10.0, "p99_us": 20.0, "max_us": 30.0, "n": 7}
    slave = {"trials": 70, "scene": "fingertip-7", "identifier": "effusivity-lda",
             "accuracy_sim": 0.9, "accuracy_emulated": 0.8, "accuracy_difference_points": -10.0,
             "accuracy_with_pairs_sim": 0.95, "accuracy_with_pairs_emulated": 0.85,
             "agreement": 0.75} | dict.fromkeys(
        ("sensor_to_identifier", "sensor_to_identifier_onset_backlog",
         "serial_sensor_to_driver", "can_controller_to_actuator"), hop)
    lines = devices.text_report(_devices_report(slave), "r.json")
    assert "" not in lines and lines[-1] == "wrote r.json"
    assert lines[-2] == "slave can_controller_to_actuator: p50 10.0 us, p99 20.0 us, max 30 us (n 7)"


def test_view_lines():
    mode = {"busy_mean_us": 300.0, "busy_p99_us": 500.0, "period_p99_us": 1001.0,
            "deadline_misses": 2, "steps": 1000}
    report = {"first_paint_s": 0.4, "lag_p99_s": 0.079, "rate_hz": 1000.0,
              "realtime_priority": 20,
              "loop": dict.fromkeys(("no_view", "stream_no_page", "page_open"), mode),
              "publisher_call": {"mean_us": 8.5, "p99_us": 125.7}}
    tail = "busy 300 us mean, 500 us p99; period p99 1001 us; 2 of 1000 deadlines missed"
    assert view.text_report(report, "v.json") == [
        "first paint 0.40 s after the server started; view lag p99 79 ms at 1000 Hz; master "
        "loop at SCHED_FIFO priority 20 (0: normal)",
        f"  master loop, no view stream : {tail}",
        f"  master loop, stream, no page: {tail}",
        f"  master loop, page open      : {tail}",
        "  the view stream's call per period alone: 8.5 us mean, 125.7 us p99; wrote v.json"]


def test_render_lines_skip_what_the_report_does_not_hold():
    per = {"wood": {"skin_rms_k": 0.6, "skin_rms_idle_at_object_k": 0.14,
                    "skin_rms_repeat_k": 0.06, "flux_rms_from_decision_rel": 0.0157,
                    "flux_rms_first_second_rel": 0.0645,
                    # Perceptual units (issue 43, deliverable 6), in every row
                    # bench render writes since the display's junction loop.
                    "heat_extraction_ratio_first_s": 0.874, "skin_above_threshold_s": 0.25},
           "steel": {}}                                     # a material not run: no line
    report = {"rate": [], "controller": [], "gains": [], "before": [], "materials": per,
              "generator": None, "real_clock": [], "png": "p.png"}
    from telethermal.bench.render_text import text_report
    assert text_report(report, "r.json") == [
        "wood      : first touch skin 0.60 K (idling at the object 0.14 K), repeated "
        "(pre-conditioned) 0.06 K; flux from the decision 1.57 %, first second 6.45 % of peak; "
        "heat extracted over the first second 0.87x direct contact's (told apart beyond "
        "1 +- 0.43), skin off by more than a fingertip detects for 0.25 s",
        "wrote r.json and p.png"]


def test_identify_bench_lines():
    table1 = {"accuracy_7": {"0.5": 0.9}, "accuracy_5": {"0.5": 0.95, "1": 1.0},
              "paper_accuracy_5": {"0.5": 0.8}, "train_s_full_database": 1.5,
              "inference_ms_p99": 0.1234, "calibration_ece": 0.05,
              "decision": {"commit_rate": 0.5, "accuracy": None}}
    rep = {"table1": table1,
           "active_passive": {"active_accuracy_by_window_s": {"0.5": 0.7},
                              "passive_unknown_rate": 1.0},
           "cross_temperature": {"hot": {"first_window_at_99pct_s": 0.3,
                                         "paper_100pct_within_s": 0.5}},
           "session_shift": {"raw": {"accuracy_5": {"1": 0.6}}}}
    report = {"methods": {"m": rep},
              "thermometer_ablation": {"accuracy": {"ir": {"0.2": 0.5, "0.5": 0.75, "1": 1.0}}}}
    assert identify_text.text_report(report, "i.json", "i.png") == [
        "m: Table 1, 7 classes 0.5 s 90 %",
        "   5 classes 0.5 s 95 % (paper 80 %), 1 s 100 %",
        "   train 1.5 s; inference p99 0.123 ms",
        "   active pad: 0.5 s 70 %; passive pad unknown 100 %",
        "   hot: >= 99 % from 0.3 s (paper 100 % within 0.5 s)",
        "   calibration error 0.050; decisions within 1 s: 50 % committed, - of them right",
        "   session shift (1 K), thermometer raw: 1 s 60 %",
        "object-thermometer ablation (effusivity-lda, 0.2 / 0.5 / 1 s): ir: 50 / 75 / 100 %",
        "wrote i.json and i.png"]


def test_identify_bench_keeps_a_method_run_on_table1_only(tmp_path):
    """effusivity-fit runs Table 1 and the session shift, not the rows on
    another pad: its lines say so, and the plot is made (it had crashed
    the bench after 11 minutes, before the JSON was written)."""
    from telethermal.bench.identify_plot import plot

    table1 = {"accuracy_7": {"0.5": 0.9}, "accuracy_5": {"0.5": 0.95},
              "paper_accuracy_5": {}, "train_s_full_database": 1.5,
              "inference_ms_p99": 0.1234, "calibration_ece": 0.05,
              "decision": {"commit_rate": 0.5, "accuracy": None}}
    rep = {"table1": table1, "not_run": ["active/passive: another pad"],
           "session_shift": {"raw": {"accuracy_5": {"1": 0.6}}}}
    report = {"methods": {"m": rep}, "date": "d", "machine": "x",
              "thermometer_ablation": {"accuracy": {}}}
    lines = identify_text.text_report(report, "i.json", "i.png")
    assert "   not run: active/passive: another pad" in lines
    assert not any("active pad:" in line for line in lines)
    plot(report, tmp_path / "i.png")
    assert (tmp_path / "i.png").stat().st_size > 0


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
    monkeypatch.setattr(view, "run_view_bench",
                        lambda **kw: {"command": "telethermal bench view --json default.json"})
    cmd = "telethermal bench view --json v.json --touches 1"
    view.run_and_save(tmp_path / "v.json", touches=1, command=cmd)
    assert json.loads((tmp_path / "v.json").read_text())["command"] == cmd
    view.run_and_save(tmp_path / "d.json")                  # no command given: the bench's own
    assert json.loads((tmp_path / "d.json").read_text())["command"] == \
        "telethermal bench view --json default.json"
