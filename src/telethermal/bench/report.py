"""``telethermal bench report``: every benchmark's JSON in one Markdown
report with its figures (speed against error), each stating the machine,
the date and the command that produced it."""

from __future__ import annotations

import json
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from telethermal.bench.faults_text import recovery_text  # noqa: E402
from telethermal.bench.options import reduced_options  # noqa: E402
from telethermal.bench.clock_text import real_clock_sentences  # noqa: E402
from telethermal.bench.unseen import report_section as unseen_section  # noqa: E402


def _load(results: Path, name: str) -> dict | None:
    path = results / f"{name}.json"
    return json.loads(path.read_text()) if path.is_file() else None


def _provenance(d: dict) -> str:
    reduced = d.get("_reduced", [])
    note = "" if not reduced else (
        f" **Reduced run** (`{' '.join(reduced)}`): fewer methods, seeds, trials, rounds or "
        "settings than the bench's defaults, so its figures are not those of the committed "
        "run (`make bench-full`, every bench at its defaults).")
    return (f"*Machine {d.get('machine', '?')}; {d.get('date', '?')}; "
            f"`{d.get('command', '?')}`.*{note}")


def _save(fig, path: Path) -> str:
    fig.tight_layout()
    tmp = path.with_name(f".{path.name}.tmp")
    fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    os.replace(tmp, path)
    return path.name


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.2f} %"


def _bench_png(d: dict, name: str, suffix: str = "") -> Path | None:
    """Where the bench wrote its figure ``<name><suffix>.png``: beside its
    JSON (the default of every bench's ``--png``), else beside the path its
    JSON names (``faults`` writes ``<stem>-traces.png`` next to its PNG), if
    either is there."""
    beside = Path(d.get("_results", Path("."))) / f"{name}{suffix}.png"
    if beside.is_file():
        return beside
    if not d.get("png"):
        return None
    named = Path(d["png"])
    named = named.with_name(f"{named.stem}{suffix}{named.suffix}")
    return named if named.is_file() else None


def _link(out: Path, png: Path, alt: str) -> str:
    """A Markdown image of ``png`` as it lies, relative to the report's
    folder ``out``: no copy."""
    rel = os.path.relpath(Path(png).resolve(), Path(out).resolve())
    return f"![{alt}]({Path(rel).as_posix()})\n"


def _figure(out: Path, d: dict, name: str, suffix: str = "") -> str:
    """The bench's own PNG, linked where the bench wrote it ("" if none)."""
    png = _bench_png(d, name, suffix)
    return "" if png is None else _link(out, png, name + suffix)


def _physics_plot(out: Path, d: dict) -> str:
    """Error against runtime, drawn beside the report when the bench's own
    figure (which holds the same points) is not found."""
    rows = d["rows"]
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for model in sorted({r["model"] for r in rows}):
        rs = [r for r in rows if r["model"] == model]
        ax.loglog([r["runtime_s"] for r in rs], [r["max_rel_error"] for r in rs], "o",
                  ms=3, label=model)
    ax.set_xlabel("runtime (s)")
    ax.set_ylabel("max relative error against the reference")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ax.set_title("physics: error against runtime", fontsize=9)
    return _save(fig, out / "physics_speed_error.png")


def physics(out: Path, d: dict) -> list[str]:
    figure = _figure(out, d, "physics") or f"![physics]({_physics_plot(out, d)})\n"
    dft = d["default"]
    return ["## Physics: error against runtime", "",
            f"The default solver: max relative error {dft['max_rel_error']:.2g} "
            f"(tolerance {dft['tolerance_rel']:g}) at {dft['runtime_s_per_simulated_s']:.2g} s "
            f"of CPU per simulated second; heat balance over 60 s: relative error "
            f"{d['heat_balance_60s']['relative_error']:.2g}.", "",
            figure, _provenance(d), ""]


def identify(out: Path, d: dict) -> list[str]:
    lines = ["## Identification: accuracy against time after contact, per method", "",
             "Beside learning-based-thermal-rendering Table 1 (its 7 materials, and 5 "
             "classes with the indistinguishable pairs merged).", "",
             "| method | classes | 0.25 s | 0.5 s | 0.75 s | 1 s |", "|---|---|---|---|---|---|"]
    keys = ("0.25", "0.5", "0.75", "1")
    t1 = {}
    for name, m in d["methods"].items():
        t1 = m.get("table1", {}) or t1
        for n in (7, 5):
            acc = m.get("table1", {}).get(f"accuracy_{n}", {})
            lines.append(f"| {name} | {n} | " + " | ".join(_pct(acc.get(k)) for k in keys) + " |")
    lim = d.get("limit") or {}
    for n in (7, 5):
        if lim.get(f"accuracy_{n}"):
            lines.append(f"| physical limit (oracle) | {n} | " + " | ".join(
                _pct(lim[f"accuracy_{n}"].get(k)) for k in keys) + " |")
    for n in (7, 5):
        paper = t1.get(f"paper_accuracy_{n}")
        if isinstance(paper, str):
            lines.append(f"| the paper | {n} | {paper} | | | |")
        elif paper:
            lines.append(f"| the paper | {n} | " + " | ".join(_pct(paper.get(k)) for k in keys)
                         + " |")
    lines += [""] + _paper_confusions(d) + _identify_decisions(d) + _identify_shift(d) + \
        _identify_active(d) + _identify_ablation(d) + \
        [_figure(out, d, "identify"), _provenance(d), ""]
    return lines


def _paper_confusions(d: dict) -> list[str]:
    """What the materials table says of the first paper's confusions."""
    from telethermal.physics.materials import get_material

    best = max((m.get("table1", {}).get("accuracy_7", {}).get("1", 0.0), n)
               for n, m in d["methods"].items())
    pairs = ", ".join(
        f"{a} {get_material(a).effusivity:,.0f} against {b} {get_material(b).effusivity:,.0f} "
        f"W s^0.5/(m^2 K) ({get_material(a).effusivity / get_material(b).effusivity:.1f}x)"
        for a, b in (("aluminium", "steel"), ("graphite", "rubber")))
    verdict = ("the simulated pad tells them apart, so the confusions are not reproduced"
               if best[0] >= 0.95 else "the simulated pad confuses some of them too")
    return [f"The paper confuses aluminium with steel and graphite with rubber at 1 s; "
            f"with handbook properties ({pairs}) {verdict}: 7 classes at 1 s reach "
            f"{_pct(best[0])} ({best[1]}). No property was changed to match the paper.", ""]


def _num(x, digits=3) -> str:
    return "-" if x is None else f"{x:.{digits}g}"


def _identify_decisions(d: dict) -> list[str]:
    lines = ["Calibration and decisions on the first paper's protocol (held-out trials; "
             "decisions committed within 1 s of contact, a group counting as right when it "
             "holds the touched material):", "",
             "| method | calibration error | committed | right | median commit time | "
             "stayed a group | inference (ms, p50) |", "|---|---|---|---|---|---|---|"]
    for name, m in d["methods"].items():
        t1 = m.get("table1", {})
        dec = t1.get("decision") or {}
        lines.append(f"| {name} | {_num(t1.get('calibration_ece'))} | "
                     f"{_pct(dec.get('commit_rate'))} | {_pct(dec.get('accuracy'))} | "
                     f"{_num(dec.get('time_s_p50'))} s | {_pct(dec.get('group_rate'))} | "
                     f"{_num(t1.get('inference_ms_p50'))} |")
    return lines + [""]


def _identify_shift(d: dict) -> list[str]:
    rows = [(n, m["session_shift"]) for n, m in d["methods"].items() if "session_shift" in m]
    if not rows:
        return []
    lines = ["Session shift: trained on one session, tested on another whose object "
             "thermometer reads 1 K lower (+0.5 K then -0.5 K, the datasheet's limit both "
             "ways); 5 classes:", "",
             "| method | thermometer | 0.25 s | 0.5 s | 0.75 s | 1 s | committed | right |",
             "|---|---|---|---|---|---|---|---|"]
    for name, shift in rows:
        for mode in ("calibrated", "uncalibrated"):
            r = shift[mode]
            acc = r["accuracy_5"]
            lines.append(f"| {name} | {mode} | " + " | ".join(
                _pct(acc.get(k)) for k in ("0.25", "0.5", "0.75", "1")) +
                f" | {_pct(r['decision']['commit_rate'])} | {_pct(r['decision']['accuracy'])} |")
    return lines + [""]


def _identify_active(d: dict) -> list[str]:
    lines = ["Second paper, active pad (gripper I-pro, 4 materials, held-out trials), and "
             "the cross-temperature pairs (first window at 99 %):", "",
             "| method | 0.1 s | 0.2 s | 0.3 s | 0.4 s | committed | right | calibration "
             "error | II, III, V at 99 % from |", "|---|---|---|---|---|---|---|---|---|"]
    for name, m in d["methods"].items():
        ap = m.get("active_passive", {})
        acc = ap.get("active_accuracy_by_window_s", {})
        dec = ap.get("decision") or {}
        cross = ", ".join(_num(r.get("first_window_at_99pct_s")) + " s"
                          for r in m.get("cross_temperature", {}).values())
        lines.append(f"| {name} | " + " | ".join(_pct(acc.get(k)) for k in
                                                ("0.1", "0.2", "0.3", "0.4")) +
                     f" | {_pct(dec.get('commit_rate'))} | {_pct(dec.get('accuracy'))} | "
                     f"{_num(ap.get('calibration_ece'))} | {cross} |")
    return lines + [""]


def _identify_ablation(d: dict) -> list[str]:
    ab = d.get("thermometer_ablation")
    if not ab:
        return []
    lines = [f"Where the accuracy goes ({ab['method']}, leave-trials-out, one session):", "",
             "| scene, object thermometer | 0.2 s | 0.5 s | 1 s |", "|---|---|---|---|"]
    for name, acc in ab["accuracy"].items():
        lines.append(f"| {name} | " + " | ".join(_pct(acc.get(k)) for k in ("0.2", "0.5", "1"))
                     + " |")
    return lines + [""]


def _render_plot(out: Path, rate: list[dict]) -> str:
    """Error and CPU against loop rate, drawn beside the report when the
    bench's own figure (whose first panel shows both) is not found."""
    fig, ax = plt.subplots(figsize=(6.5, 4))
    ax.semilogx([r["rate_hz"] for r in rate], [100 * r["mean_flux_rms_error_rel"] for r in rate],
                "o-", label="flux error after identification (% of peak)")
    ax2 = ax.twinx()
    ax2.loglog([r["rate_hz"] for r in rate], [r["mean_cpu_s_per_simulated_s"] for r in rate],
               "s--", color="C1", label="CPU s per simulated s")
    ax.set_xlabel("display loop rate (Hz)")
    ax.set_ylabel("mean flux error (% of peak)")
    ax2.set_ylabel("CPU s per simulated s")
    ax.grid(alpha=0.3)
    fig.legend(fontsize=7, loc="upper center")
    return _save(fig, out / "render_rate.png")


def render(out: Path, d: dict) -> list[str]:
    rate = d["rate"]
    figure = _figure(out, d, "render") or f"![render rate]({_render_plot(out, rate)})\n"
    lines = ["## Rendering: error against loop rate", "",
             "| rate | mean flux error | worst | skin RMS | CPU s / simulated s |",
             "|---|---|---|---|---|"]
    for r in rate:
        lines.append(f"| {r['rate_hz']:g} Hz | {_pct(r['mean_flux_rms_error_rel'])} | "
                     f"{_pct(r['max_flux_rms_error_rel'])} | {r['mean_temp_rms_error_c']:.2f} K"
                     f" | {r['mean_cpu_s_per_simulated_s']:.3g} |")
    lines += [f"\n{t[0].upper()}{t[1:]}." for t in real_clock_sentences(d)]
    lines += ["", figure, _provenance(d), ""]
    return lines


def transport(out: Path, d: dict) -> list[str]:
    lb = d["loopback"]
    names = [k for k in ("raw_plain", "e2e_plain", "raw_curve", "e2e_curve") if k in lb]
    fig, ax = plt.subplots(figsize=(6.5, 3.6))
    x = np.arange(len(names))
    ax.bar(x - 0.2, [lb[n]["p50_us"] for n in names], 0.4, label="p50")
    ax.bar(x + 0.2, [lb[n]["p99_us"] for n in names], 0.4, label="p99")
    ax.set_xticks(x, [n.replace("_", " ") for n in names])
    ax.set_ylabel("one-way latency (us)")
    ax.legend(fontsize=7)
    ax.set_title("transport on loopback: telethermal (e2e) beside raw pyzmq", fontsize=9)
    png = _save(fig, out / "transport.png")
    return ["## Transport: latency beside raw ZeroMQ", "",
            f"End to end (codec, sequence, acks) on loopback: p50 {d['e2e_p50_us']:.0f} us, "
            f"p99 {d['e2e_p99_us']:.0f} us, {d['ratio_to_raw_zmq_p50']:.2f}x raw pyzmq "
            f"({d['raw_zmq_p50_us']:.0f} us); with CURVE {d['curve_ratio_to_raw_zmq_p50']:.2f}x.",
            "", f"![transport]({png})", "", _provenance(d), ""]


def faults(out: Path, d: dict) -> list[str]:
    if "simulated" not in d:
        return ["## Rendering under network faults", "",
                "The results predate the simulated-clock benchmark (issue 15): re-run "
                "`telethermal bench faults`.", "", _provenance(d), ""]
    sim, s = d["simulated"], d["summary"]
    lines = ["## Rendering under network faults: the first touch, a repeated touch, the "
             "naive baseline", "",
             f"Simulated clock: {len(sim['materials'])} materials x {len(sim['seeds'])} seeds "
             f"per row, {sim['contact_s']:g} s contacts, the display at {sim['rate_hz']:g} Hz; "
             "flux RMS error in % of the direct contact's peak, mean over touches (sd). "
             "Blind: contact until the first news of the slave reaches the master.", "",
             "| row | mode | blind | after the news | whole | blind window (s) | safety |",
             "|---|---|---|---|---|---|---|"]

    def cell(st):
        return "-" if st["mean"] is None else f"{100 * st['mean']:.2f} ({100 * st['sd']:.2f})"

    for name, row in sim["rows"].items():
        for mode, st in list(row["modes"].items()) + list(row.get("ablations", {}).items()):
            lines.append(f"| {name} | {mode} | {cell(st['blind'])} | {cell(st['after_news'])} | "
                         f"{cell(st['whole'])} | {st['blind_s']['mean']:.3f} | "
                         f"{st['safety_events']} |")
    lines.append(f"| - | oracle floor | | | {cell(sim['oracle']['whole'])} | 0 | "
                 f"{sim['oracle']['safety_events']} |")
    lines += ["", f"At {s['ratio_setting']}: the first touch after the news "
              f"**{s['first_touch_after_news_ratio_200ms']:.2f}x** its zero-delay error "
              f"(target <= 1.2), the whole contact **{s['first_touch_whole_ratio_200ms']:.2f}x** "
              f"(target <= 1.3); naive after the news **{s['naive_after_news_ratio_200ms']:.2f}x** "
              f"the same zero-delay error (target >= 2; {s['naive_after_news_ratio_200ms_own_zero']:.2f}x "
              f"its own, {s['naive_after_news_ratio_200ms_to_compensated_200ms']:.2f}x the "
              f"compensated on the same row). A repeated touch (object memory) is at most "
              f"**{s['repeat_touch_ratio_to_oracle_max']:.3f}x** the oracle floor over every row "
              f"(target <= 1.05).", ""]
    rows = d.get("rows", [])
    if rows:
        lines += ["Processes on loopback behind the fault proxy (the same services as a "
                  "session):", "",
                  "| fault | compensated | naive | safety events | lossless stream "
                  "(gaps/recovered/dup/resent/refused) | recovered | recovery (bound) |",
                  "|---|---|---|---|---|---|---|"]
        for r in rows:
            lo = r["lossless"]
            rec = recovery_text(r)
            lines.append(f"| {r['fault']} | {_pct(r['compensated_flux_rms_error_rel'])} | "
                         f"{_pct(r['naive_flux_rms_error_rel'])} | {r['safety_events']} | "
                         f"{lo['gaps']}/{lo['recovered']}/{lo['duplicates']}/{lo['resent']}/"
                         f"{lo.get('refused_by_window', lo.get('lossless_dropped'))} | {r['recovered']} | "
                         f"{rec} |")
        lines += ["", f"The processes' whole-contact errors within the simulated mean +- 2 sd "
                  f"of the same material: {s.get('processes_within_simulated_spread', '-')}.",
                  ""]
    lines += [_figure(out, d, "faults"), _figure(out, d, "faults", "-traces"), _provenance(d), ""]
    return lines


def devices(out: Path, d: dict) -> list[str]:
    p = d["paths"]
    e = p["emulated"]
    lines = ["## Devices: the emulated serial and CAN paths beside the direct simulator", "",
             "| path | p50 | p99 |", "|---|---|---|",
             f"| direct simulator read | {p['sim']['read']['p50_us']:.0f} us | "
             f"{p['sim']['read']['p99_us']:.0f} us |",
             f"| serial: board frame to converted reading | "
             f"{e['serial_sensor_to_controller']['p50_us']:.0f} us | "
             f"{e['serial_sensor_to_controller']['p99_us']:.0f} us |",
             f"| CAN: setpoint to the driver applying it | "
             f"{e['can_controller_to_actuator']['p50_us']:.0f} us | "
             f"{e['can_controller_to_actuator']['p99_us']:.0f} us |", ""]
    # Results written before the display's default rate moved to 500 Hz
    # carry their sessions under the old key (they ran at 1 kHz).
    sessions = d.get("sessions_real_clock") or d["sessions_1khz_real_clock"]
    for kind, r in sessions.items():
        lines.append(f"- {r.get('rate_hz', 1000.0):g} Hz real-clock session, {kind}: period p99 "
                     f"{r['loop_period_p99_us']:.0f} us, busy p99 {r['busy_p99_us']:.0f} us, "
                     f"{r['deadline_misses']} deadline misses of {r['steps']}, flux error "
                     f"{_pct(r['flux_rms_error_rel_whole'])}.")
    slave = d.get("slave")
    if slave:
        lines += ["", "The slave's side (its version-2 board, its active pad's CAN driver):", "",
                  "| slave path | p50 | p99 |", "|---|---|---|"]
        for name, what in (("sensor_to_identifier", "board frame to the identifier"),
                           ("serial_sensor_to_driver", "board frame to the driver's reading"),
                           ("can_controller_to_actuator", "pad command to the driver applying "
                                                          "it")):
            r = slave[name]
            lines.append(f"| {what} | {r['p50_us']:.0f} us | {r['p99_us']:.0f} us |")
        lines += ["", f"Identification on the same {slave['trials']} touches of "
                      f"{slave['scene']}: {100 * slave['accuracy_sim']:.1f} % simulated, "
                      f"{100 * slave['accuracy_emulated']:.1f} % through the drivers "
                      f"({slave['accuracy_difference_points']:+.1f} points; same label on "
                      f"{100 * slave['agreement']:.1f} %)."]
    if d.get("qemu"):
        from telethermal.bench.firmware import report_lines
        lines += ["", *report_lines(d["qemu"])]
    return lines + ["", _provenance(d), ""]


def record(out: Path, d: dict) -> list[str]:
    b, m, n = d["busy_mean_us"], d["deadline_misses"], d["steps"]
    rate = d.get("rate_hz", 1000.0)         # results written before the rate was a key
    return [f"## Recording: its cost to the master's {rate:g} Hz loop", "",
            f"Busy time per period {b['without']:.0f} us without recording, {b['with']:.0f} us "
            f"with: {100 * d['cost_of_period_budget']:.1f} % of the {1e3 / rate:g} ms budget. "
            f"The recorder's call per period: p50 {d['log_call_p50_us']:.1f} us, p99 "
            f"{d['log_call_p99_us']:.1f} us. Deadline misses {m['without']} of {n['without']} "
            f"without, {m['with']} of {n['with']} with.", "", _provenance(d), ""]


def view(out: Path, d: dict) -> list[str]:
    lines = ["## The live view: first paint, lag, and the master's loop with the page open", "",
             f"First paint {d['first_paint_s']:.2f} s after the server started (target 2 s); "
             f"view lag behind the {d['rate_hz']:g} Hz session p50 "
             f"{1000 * d['lag_p50_s']:.0f} ms, p99 "
             f"{1000 * d['lag_p99_s']:.0f} ms over {d['lag_frames']} frames (target 200 ms). "
             f"The view stream's call per display period alone: "
             f"{d['publisher_call']['mean_us']:.1f} us mean. {d.get('touches_per_mode', '?')} "
             f"touches of {d.get('contact_s', '?')} s per mode.", "",
             "| master loop | busy mean | busy p99 | period p99 | deadline misses |",
             "|---|---|---|---|---|"]
    for mode, text in (("no_view", "no view stream"), ("stream_no_page", "view stream, no page"),
                       ("page_open", "view stream, page open")):
        m = d["loop"][mode]
        lines.append(f"| {text} | {m['busy_mean_us']:.0f} us | {m['busy_p99_us']:.0f} us | "
                     f"{m['period_p99_us']:.0f} us | {m['deadline_misses']} of {m['steps']} |")
    return lines + ["", _provenance(d), ""]


def skin_floor(out: Path, d: dict) -> list[str]:
    rows = (d.get("decision") or {}).get("rows") or []
    lines = ["## The display's floor on the real module", "",
             f"Module {d['module']['name']} (Qmax {d['module']['qmax_w']} W); "
             f"{d['idle_policy']['sentence']}", "",
             "| material | idle policy | pad at the object | material known, best idle |",
             "|---|---|---|---|"]
    for m, v in d["materials"].items():
        lines.append(f"| {m} | {v['floor_k']:.3f} K | {v['floor_at_object_k']:.3f} K | "
                     f"{v['floor_preconditioned_k']:.3f} K |")
    if rows:
        lines += ["", "The worst material's floor when the display learns the material "
                  "at the slave's decision: " + ", ".join(
                      f"{r['floor_worst_k']:.3f} K at {r['decision_s']:g} s" for r in rows)
                  + "."]
    lines += ["", d.get("sweep_verdict", ""), "",
              f"Time: {d['timings']['total_s']:.0f} s.", "", _figure(out, d, "skin-floor"),
              _provenance(d), ""]
    return lines


def unseen(out: Path, d: dict) -> list[str]:
    return unseen_section(out, d) + [_provenance(d), ""]


def _as_built(title: str, module: str):
    """A section of an as-built bench's JSON: its own text, its provenance."""
    def section(out: Path, d: dict) -> list[str]:
        import importlib
        lines = importlib.import_module(f"telethermal.bench.{module}").text_lines(d["as_built"])
        stopped = [f"*{d['stopped']}*", ""] if d.get("stopped") else []
        return [f"## {title}", "", "```", *lines, "```", "", *stopped, _provenance(d), ""]
    return section


SECTIONS = (("physics", physics), ("identify", identify), ("render", render),
            ("transport", transport), ("faults", faults), ("devices", devices),
            ("record", record), ("view", view), ("unseen", unseen))
#: Reported when its JSON is there, not run by the Makefile's bench targets:
#: ``telethermal bench skin-floor`` takes 20 minutes at its defaults (10
#: with --quick), past bench-quick's 3 and most of bench's 15; the as-built
#: benches (``bench identify|unseen|render --as-built 0.15``) calibrate five
#: pads, 10-40 minutes each run.
BY_HAND = (("skin-floor", skin_floor),
           ("identify-as-built", _as_built("Identification on pads built off their datasheet",
                                           "identify_as_built")),
           ("unseen-as-built", _as_built("Unseen materials on pads built off their datasheet",
                                         "unseen_as_built")),
           ("render-as-built", _as_built("First touches on pads built off their datasheet",
                                         "render_as_built")))


def write_report(results: str | Path, out_md: str | Path, command: str = "") -> Path:
    results, out_md = Path(results), Path(out_md)
    out = out_md.parent
    out.mkdir(parents=True, exist_ok=True)
    where = Path(os.path.relpath(results.resolve(), out.resolve())).as_posix()
    where = "beside this file" if where == "." else f"in `{where}/`"
    lines = ["# telethermal: speed against error", "",
             "Every figure below comes from a `telethermal bench ...` command run on the "
             "machine and at the date stated under it; the JSON it was read from and the "
             f"bench's own figures are {where}. Report written by "
             f"`{command or 'telethermal bench report'}`.", ""]
    missing, reduced, sections = [], [], []
    for name, section in SECTIONS + BY_HAND:
        d = _load(results, name)
        if d is None:
            if (name, section) in SECTIONS:
                missing.append(name)
            continue
        d["_results"] = results
        d["_reduced"] = reduced_options(d.get("command", ""))
        if d["_reduced"]:
            reduced.append(f"{name} `{' '.join(d['_reduced'])}`")
        sections += section(out, d)
    if reduced:
        lines += ["Reduced runs (options other than the bench's defaults: fewer methods, "
                  "seeds, trials, rounds or settings; their figures are not the committed "
                  "ones): " + "; ".join(reduced) + ".", ""]
    lines += sections
    if missing:
        lines += [f"Not run: {', '.join(missing)} (no JSON in {results})."]
    tmp = out_md.with_name(f".{out_md.name}.tmp")
    tmp.write_text("\n".join(lines) + "\n")
    os.replace(tmp, out_md)
    return out_md
