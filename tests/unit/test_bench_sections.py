"""The benches' one renderer (telethermal.bench.markdown): each bench's
section is Markdown written from its JSON, what ``bench report`` writes
and what the bench prints in the terminal. Made-up reports, the expected
lines written out by hand from the formats; then every committed result
printed, holding every figure its report section holds."""

import json
import re
from pathlib import Path

import pytest

from telethermal.bench import identify_text, render_text, sections
from telethermal.bench.markdown import Page, table, terminal
from telethermal.bench.report import BY_HAND, SECTIONS, bench_text

RESULTS = Path(__file__).parents[2] / "bench" / "results"


@pytest.fixture
def page(tmp_path):
    return Page(out=tmp_path, results=tmp_path, draw=False)


def test_a_table_is_a_markdown_table_and_the_terminal_draws_it_in_columns():
    lines = table(["a", "b"], [[1, "x"], [22, "yy"]])
    assert lines == ["| a | b |", "|---|---|", "| 1 | x |", "| 22 | yy |", ""]
    text = terminal(["Some *words*.", ""] + lines, width=60)
    assert "Some words." in text and "|" not in text and "*" not in text
    rows = [line.split() for line in text.splitlines() if line.strip()]
    assert ["a", "b"] in rows and ["1", "x"] in rows and ["22", "yy"] in rows
    assert all(line == line.rstrip() for line in text.splitlines())


def test_physics_section(page):
    report = {"default": {"max_rel_error": 1.234e-4, "window_s": [0.05, 60.0],
                          "runtime_s_per_simulated_s": 2e-4, "tolerance_rel": 1e-3},
              "batch_70x1s_1khz": {"trials": 70, "runtime_s": 0.5, "model_choice_s": 0.25},
              "databases_fingertip_7": {"simulation_s": 1.5, "with_csv_files_s": 3.75},
              "heat_balance_60s": {"relative_error": 3e-9}, "png": "p.png",
              "machine": "m", "date": "d", "command": "telethermal bench physics --json p.json"}
    lines = sections.physics(report, page)
    assert lines[0] == "## Physics: error against runtime"
    assert ("The default solver: max relative flux error 0.00012 (tolerance 0.001) over 0.05-60 s,"
            " at 0.200 ms of CPU per simulated second; heat balance over 60 s: relative error "
            "3e-09.") in lines
    assert ("A batch of 70 one-second trials at 1 kHz: 0.500 s (+ 0.250 s choosing the models, "
            "once per scene); the fingertip-7 databases: simulation 1.50 s, with CSV files "
            "3.75 s.") in lines
    assert "*Machine m; d; `telethermal bench physics --json p.json`.*" in lines


def test_record_section_signs_a_negative_cost_once(page):
    report = {"busy_mean_us": {"without": 300.4, "with": 310.6}, "extra_busy_per_period_us": 10.2,
              "cost_of_period_budget": 0.0102, "log_call_p50_us": 2.0, "log_call_p99_us": 5.4,
              "deadline_misses": {"without": 1, "with": 2},
              "steps": {"without": 3000, "with": 3000}}
    text = "\n".join(sections.record(report, page))
    assert ("Busy time per period 300 us without recording, 311 us with: +10.2 us, +1.0 % of "
            "the 1 ms budget. The recorder's call per period: p50 2.0 us, p99 5.4 us. Deadline "
            "misses 1 of 3000 without, 2 of 3000 with.") in text
    report.update(extra_busy_per_period_us=-47.1, cost_of_period_budget=-0.0471)
    assert "with: -47.1 us, -4.7 % of the" in "\n".join(sections.record(report, page))


def test_transport_section_names_the_slowest_kind_and_a_skipped_part(page):
    report = {"codec": {"hello": {"bytes": 40, "encode_us": 1.0, "decode_us": 2.0},
                        "flux_trajectory": {"bytes": 900, "encode_us": 5.0, "decode_us": 7.5}},
              "loopback": {"e2e_plain": {"p50_us": 80.0, "p99_us": 150.0, "max_us": 400.0,
                                         "messages_per_s": 12000.0},
                           "ratio": 1.5},                      # not a row: not shown
              "namespaces": {"skipped": "not root"},
              "e2e_p50_us": 80.0, "e2e_p99_us": 150.0, "ratio_to_raw_zmq_p50": 1.6,
              "curve_ratio_to_raw_zmq_p50": 1.25}
    lines = sections.transport(report, page)
    assert ("End to end (codec, sequence, acks) on loopback: p50 80 us, p99 150 us, 1.60x raw "
            "pyzmq (plain); with CURVE 1.25x. The codec's slowest kind: flux_trajectory (900 B), "
            "encode 5.0 us, decode 7.5 us.") in lines
    assert "| loopback | e2e plain | 80 us | 150 us | 400 us | 12000 |" in lines
    assert "namespaces: skipped (not root)." in lines
    assert not any("ratio" in line for line in lines)
    assert not list(Path(page.out).iterdir())            # a printout draws nothing


def _devices_report(slave):
    path = {"read": {"p50_us": 1.0, "p99_us": 2.0}, "apply": {"p50_us": 3.0, "p99_us": 4.0}}
    hop = {"p50_us": 100.0, "p99_us": 200.0, "max_us": 900.0, "n": 5}
    return {"paths": {"sim": path, "emulated": path | {"serial_sensor_to_controller": hop,
                                                       "can_controller_to_actuator": hop}},
            "sessions_real_clock": {"sim": {
                "rate_hz": 500.0, "loop_period_p99_us": 1001.0, "busy_p99_us": 300.0,
                "deadline_misses": 0, "steps": 3000, "flux_rms_error_rel_whole": 0.0125}},
            "slave": slave}


def test_devices_section_with_and_without_the_slave_part(page):
    lines = sections.devices(_devices_report(None), page)
    assert "| sim: read | 1.0 us | 2.0 us | - | - | - |" in lines
    assert "| emulated: apply | 3.0 us | 4.0 us | - | - | - |" in lines
    assert "| emulated CAN: setpoint to the driver applying it | 100.0 us | 200.0 us | 900 us " \
           "| 5 | - |" in lines
    assert ("- 500 Hz real-clock session, sim: period p99 1001 us, busy p99 300 us, 0 deadline "
            "misses of 3000, flux error 1.25 %.") in lines
    assert not any("slave" in line for line in lines)
    hop = {"p50_us": 10.0, "p99_us": 20.0, "max_us": 30.0, "n": 7, "timed_out": 1}
    slave = {"trials": 70, "scene": "fingertip-7", "identifier": "effusivity-lda",
             "accuracy_sim": 0.9, "accuracy_emulated": 0.8, "accuracy_difference_points": -10.0,
             "accuracy_with_pairs_sim": 0.95, "accuracy_with_pairs_emulated": 0.85,
             "agreement": 0.75} | dict.fromkeys(
        ("sensor_to_identifier", "sensor_to_identifier_onset_backlog",
         "serial_sensor_to_driver", "can_controller_to_actuator"), hop)
    lines = sections.devices(_devices_report(slave), page)
    assert "| pad command to the driver applying it | 10.0 us | 20.0 us | 30 us | 7 | 1 |" \
        in lines
    assert ("Identification on the same 70 touches of fingertip-7 (effusivity-lda): 90.0 % "
            "simulated, 80.0 % through the drivers (-10.0 points; a committed pair counted "
            "wrong; with pairs 95.0 % / 85.0 %); same label on 75.0 %.") in lines


def test_view_section(page):
    mode = {"busy_mean_us": 300.0, "busy_p99_us": 500.0, "period_p99_us": 1001.0,
            "deadline_misses": 2, "steps": 1000}
    report = {"first_paint_s": 0.4, "lag_p99_s": 0.079, "rate_hz": 1000.0,
              "realtime_priority": 20,
              "loop": dict.fromkeys(("no_view", "stream_no_page", "page_open"), mode),
              "publisher_call": {"mean_us": 8.5, "p99_us": 125.7}}
    lines = sections.view(report, page)
    assert lines[2] == ("First paint 0.40 s after the server started (target 2 s); view lag "
                        "behind the 1000 Hz session p99 79 ms (target 200 ms). The view stream's "
                        "call per display period alone: 8.5 us mean, 125.7 us p99. The master's "
                        "loop at SCHED_FIFO priority 20 (0: normal scheduling). ")
    for text in ("no view stream", "view stream, no page", "view stream, page open"):
        assert f"| {text} | 300 us | 500 us | 1001 us | 2 of 1000 | - |" in lines
    assert not any(line.startswith("Each touch is set up") for line in lines)
    # A report with each touch's set-up (the set-aside deadlines beside the missed).
    report["loop"] = dict.fromkeys(report["loop"], mode | {"setup_s_max": 0.0123,
                                                           "deadlines_set_aside": 17})
    lines = sections.view(report, page)
    assert "| no view stream | 300 us | 500 us | 1001 us | 2 of 1000 | 12 ms, 17 set aside |" \
        in lines
    assert any(line.startswith("Each touch is set up") for line in lines)


def test_render_section_skips_what_the_report_does_not_hold(page):
    per = {"wood": {"skin_rms_k": 0.6, "skin_rms_idle_at_object_k": 0.14,
                    "skin_rms_repeat_k": 0.06, "flux_rms_from_decision_rel": 0.0157,
                    "flux_rms_first_second_rel": 0.0645,
                    "heat_extraction_ratio_first_s": 0.874, "skin_above_threshold_s": 0.25},
           "steel": {}}                                     # a material not run: no row
    report = {"rate": [], "controller": [], "gains": [], "before": [], "materials": per,
              "generator": None, "real_clock": [], "png": "p.png"}
    lines = render_text.section(report, page)
    assert "| wood | 0.60 K | 0.14 K | 0.06 K | 1.57 % | 6.45 % | 0.87x | 0.25 s |" in lines
    assert not any(line.startswith("| steel") for line in lines)
    for absent in ("gain study", "Before identification", "generators", "Module limits",
                   "Dew", "Real clock"):
        assert not any(absent in line for line in lines), absent


def test_identify_section_says_what_a_method_did_not_run(page):
    table1 = {"accuracy_7": {"0.5": 0.9}, "accuracy_5": {"0.5": 0.95, "1": 1.0},
              "paper_accuracy_5": {"0.5": 0.8}, "train_s_full_database": 1.5,
              "inference_ms_p50": 0.05, "inference_ms_p99": 0.1234, "calibration_ece": 0.05,
              "decision": {"commit_rate": 0.5, "accuracy": None}}
    rep = {"table1": table1, "not_run": ["active/passive: another pad"],
           "session_shift": {m: {"accuracy_5": {"1": 0.6},
                                 "decision": {"commit_rate": 1.0, "accuracy": 0.5}}
                             for m in ("calibrated", "uncalibrated")}}
    report = {"methods": {"m": rep},
              "thermometer_ablation": {"method": "effusivity-lda",
                                       "accuracy": {"ir": {"0.2": 0.5, "0.5": 0.75, "1": 1.0}}}}
    lines = identify_text.section(report, page)
    assert "| m | 7 | - | 90.00 % | - | - |" in lines
    assert "| m | 5 | - | 95.00 % | - | 100.00 % |" in lines
    assert "| the paper | 5 | - | 80.00 % | - | - |" in lines
    assert "| m | 0.05 | 50.00 % | - | - s | - | 0.05 | 0.123 |" in lines
    assert "| m | uncalibrated | - | - | - | 60.00 % | 100.00 % | 50.00 % |" in lines
    assert "Rows a method leaves out: m: active/passive: another pad." in lines
    assert "| ir | 50.00 % | 75.00 % | 100.00 % |" in lines
    assert "Training on the whole database: m 1.5 s." in lines
    assert not any(line.startswith("| method | 0.1 s") for line in lines)    # no active rows


COMMITTED = [name for name, _ in SECTIONS + BY_HAND if (RESULTS / f"{name}.json").is_file()]
NUMBER = re.compile(r"-?\d[\d,]*(?:\.\d+)?(?:e[+-]?\d+)?")


@pytest.mark.parametrize("name", COMMITTED)
def test_a_bench_prints_every_figure_of_its_report_section(name, tmp_path):
    """One renderer: what ``telethermal bench NAME`` prints holds the
    numbers its section of bench/report.md holds, on an 80-column terminal
    too (rich squeezes a table too wide for its console and cuts words:
    the printout draws each table as wide as its rows need), and names the
    files it wrote."""
    d = json.loads((RESULTS / f"{name}.json").read_text())
    section = dict(SECTIONS + BY_HAND)[name]
    markdown = [line for line in section(d, Page(tmp_path, RESULTS, draw=False))
                if not line.startswith("![")]
    printed = bench_text(name, d, tmp_path / f"{name}.json", tmp_path / f"{name}.png",
                         width=80)
    want = NUMBER.findall(" ".join(markdown))
    got = NUMBER.findall(printed)
    assert want, "a section with no figure"
    missing = [n for n in set(want) if got.count(n) < want.count(n)]
    assert not missing, missing[:20]
    assert "\u2026" not in printed                          # no cell cut short
    assert printed.rstrip().endswith(f"wrote {tmp_path / f'{name}.json'} and "
                                     f"{tmp_path / f'{name}.png'}")


def test_faults_section_says_dash_for_what_a_run_left_out(page):
    """``bench faults --only crash,partition`` runs no 200 ms row: its
    ratios are None, and the section says '-' (it had crashed the
    printout after the JSON was written)."""
    d = json.loads((RESULTS / "faults.json").read_text())
    for key in [k for k in d["summary"] if k.endswith("_200ms") or "200ms_" in k]:
        d["summary"][key] = None
    d["summary"]["repeat_touch_ratio_to_oracle_max"] = None
    row = next(iter(d["simulated"]["rows"].values()))
    next(iter(row["modes"].values()))["blind_s"]["mean"] = None
    from telethermal.bench import faults_text
    text = "\n".join(faults_text.section(d, page))
    assert "the first touch after the news **-** its zero-delay error" in text
    assert "at most **-** the oracle floor" in text
    assert bench_text("faults", d, "f.json", width=80)


def test_a_bench_says_how_long_it_took_and_keeps_its_exit_code(capsys):
    from telethermal.cli.bench import _timed

    assert _timed("x", lambda args: 3)(None) == 3
    assert re.fullmatch(r"bench x: \d+ s\n", capsys.readouterr().err)
