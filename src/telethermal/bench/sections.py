"""The sections of the smaller benches (physics, transport, devices,
record, view, skin-floor, the as-built benches): each one's Markdown from
its JSON, what ``bench report`` writes and the bench itself prints
(:mod:`telethermal.bench.markdown`)."""

from __future__ import annotations

import numpy as np

from telethermal.bench.markdown import Page, figure, pct, provenance, save, table


def physics(d: dict, page: Page) -> list[str]:
    dft, b = d["default"], d["batch_70x1s_1khz"]
    db = d["databases_fingertip_7"]
    fig = figure(page, d, "physics") or _physics_plot(page, d)
    return ["## Physics: error against runtime", "",
            f"The default solver: max relative flux error {dft['max_rel_error']:.2g} "
            f"(tolerance {dft.get('tolerance_rel', float('nan')):g}) over "
            f"{dft['window_s'][0]:g}-{dft['window_s'][1]:g} s, at "
            f"{1e3 * dft['runtime_s_per_simulated_s']:.3f} ms of CPU per simulated second; "
            f"heat balance over 60 s: relative error "
            f"{d['heat_balance_60s']['relative_error']:.2g}.", "",
            f"A batch of {b['trials']} one-second trials at 1 kHz: {b['runtime_s']:.3f} s "
            f"(+ {b['model_choice_s']:.3f} s choosing the models, once per scene); the "
            f"fingertip-7 databases: simulation {db['simulation_s']:.2f} s, with CSV files "
            f"{db['with_csv_files_s']:.2f} s.", "",
            fig, provenance(d), ""]


def _physics_plot(page: Page, d: dict) -> str:
    """Error against runtime, drawn beside the report when the bench's own
    figure (which holds the same points) is not found."""
    import matplotlib.pyplot as plt

    rows = d.get("rows") or []
    if not rows:
        return ""
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
    return save(page, fig, "physics_speed_error.png")


def _pair_rows(where: str, block: dict) -> tuple[list[list], list[str]]:
    """A transport block's latency rows, and its sentences (skipped, the
    slow receiver)."""
    if "skipped" in block:
        return [], [f"{where}: skipped ({block['skipped']})."]
    rows, said = [], []
    for name, r in block.items():
        if isinstance(r, dict) and name == "slow_receiver":
            said.append(f"{where}, a slow receiver ({r['pause_s']:.0f} s without reading): "
                        f"{r['sent']} sent, {r['delivered']} delivered, "
                        f"{r['refused_by_window']} refused by the window, {r['lost']} lost.")
        elif isinstance(r, dict):
            rate = f"{r['messages_per_s']:.0f}" if "messages_per_s" in r else "-"
            rows.append([where, name.replace("_", " "), f"{r['p50_us']:.0f} us",
                         f"{r['p99_us']:.0f} us", f"{r['max_us']:.0f} us", rate])
    return rows, said


def transport(d: dict, page: Page) -> list[str]:
    kind, worst = max(d["codec"].items(), key=lambda kv: kv[1]["encode_us"] + kv[1]["decode_us"])
    rows, said = [], []
    for where in ("loopback", "namespaces"):
        r, s = _pair_rows(where, d.get(where, {"skipped": "not in this report"}))
        rows, said = rows + r, said + s
    lines = ["## Transport: latency beside raw ZeroMQ", "",
             f"End to end (codec, sequence, acks) on loopback: p50 {d['e2e_p50_us']:.0f} us, "
             f"p99 {d['e2e_p99_us']:.0f} us, {d['ratio_to_raw_zmq_p50']:.2f}x raw pyzmq "
             + (f"({d['raw_zmq_p50_us']:.0f} us)" if "raw_zmq_p50_us" in d else "(plain)")
             + f"; with CURVE {d['curve_ratio_to_raw_zmq_p50']:.2f}x. The codec's slowest "
             f"kind: {kind} ({worst['bytes']} B), encode {worst['encode_us']:.1f} us, decode "
             f"{worst['decode_us']:.1f} us.", ""]
    if rows:
        lines += table(["where", "stack", "one-way p50", "p99", "max", "messages/s"], rows)
    lines += [" ".join(said), ""] if said else []
    return lines + [_transport_plot(page, d), provenance(d), ""]


def _transport_plot(page: Page, d: dict) -> str:
    lb = d.get("loopback", {})
    names = [k for k in ("raw_plain", "e2e_plain", "raw_curve", "e2e_curve") if k in lb]
    if not names or not page.draw:
        return ""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 3.6))
    x = np.arange(len(names))
    ax.bar(x - 0.2, [lb[n]["p50_us"] for n in names], 0.4, label="p50")
    ax.bar(x + 0.2, [lb[n]["p99_us"] for n in names], 0.4, label="p99")
    ax.set_xticks(x, [n.replace("_", " ") for n in names])
    ax.set_ylabel("one-way latency (us)")
    ax.legend(fontsize=7)
    ax.set_title("transport on loopback: telethermal (e2e) beside raw pyzmq", fontsize=9)
    return save(page, fig, "transport.png")


def _hop(r: dict) -> list[str]:
    timed_out = r.get("timed_out")
    return [f"{r['p50_us']:.1f} us", f"{r['p99_us']:.1f} us", f"{r['max_us']:.0f} us",
            str(r.get("n", "-")), "-" if timed_out is None else str(timed_out)]


def devices(d: dict, page: Page) -> list[str]:
    p = d["paths"]
    e = p["emulated"]
    rows = [[f"{kind}: {what}", f"{r[what]['p50_us']:.1f} us", f"{r[what]['p99_us']:.1f} us",
             "-", "-", "-"] for kind, r in p.items() for what in ("read", "apply")]
    rows += [["emulated serial: board frame to converted reading",
              *_hop(e["serial_sensor_to_controller"])],
             ["emulated CAN: setpoint to the driver applying it",
              *_hop(e["can_controller_to_actuator"])]]
    lines = ["## Devices: the emulated serial and CAN paths beside the direct simulator", ""]
    lines += table(["path", "p50", "p99", "max", "n", "timed out"], rows)
    # Results written before the display's default rate moved to 500 Hz
    # carry their sessions under the old key (they ran at 1 kHz).
    sessions = d.get("sessions_real_clock") or d["sessions_1khz_real_clock"]
    lines += [f"- {r.get('rate_hz', 1000.0):g} Hz real-clock session, {kind}: period p99 "
              f"{r['loop_period_p99_us']:.0f} us, busy p99 {r['busy_p99_us']:.0f} us, "
              f"{r['deadline_misses']} deadline misses of {r['steps']}, flux error "
              f"{pct(r['flux_rms_error_rel_whole'])}." for kind, r in sessions.items()]
    s = d.get("slave")
    if s:
        lines += ["", "The slave's side (its version-2 board, its active pad's CAN driver):", ""]
        lines += table(["slave path", "p50", "p99", "max", "n", "timed out"], [
            [what, *_hop(s[name])] for name, what in (
                ("sensor_to_identifier", "board frame to the identifier"),
                ("sensor_to_identifier_onset_backlog", "the same, over the onset's backlog"),
                ("serial_sensor_to_driver", "board frame to the driver's reading"),
                ("can_controller_to_actuator", "pad command to the driver applying it"))
            if name in s])
        lines += [f"Identification on the same {s['trials']} touches of {s['scene']}"
                  + (f" ({s['identifier']})" if "identifier" in s else "")
                  + f": {pct(s['accuracy_sim'], 1)} simulated, "
                  f"{pct(s['accuracy_emulated'], 1)} through the drivers "
                  f"({s['accuracy_difference_points']:+.1f} points; a committed pair counted "
                  "wrong"
                  + (f"; with pairs {pct(s['accuracy_with_pairs_sim'], 1)} / "
                     f"{pct(s['accuracy_with_pairs_emulated'], 1)}"
                     if "accuracy_with_pairs_sim" in s else "")
                  + f"); same label on {pct(s['agreement'], 1)}."]
    if d.get("qemu"):
        from telethermal.bench.firmware import report_lines
        lines += ["", *report_lines(d["qemu"])]
    return lines + ["", provenance(d), ""]


def record(d: dict, page: Page) -> list[str]:
    b, m, n = d["busy_mean_us"], d["deadline_misses"], d["steps"]
    rate = d.get("rate_hz", 1000.0)         # results written before the rate was a key
    extra = d.get("extra_busy_per_period_us", b["with"] - b["without"])
    return [f"## Recording: its cost to the master's {rate:g} Hz loop", "",
            f"Busy time per period {b['without']:.0f} us without recording, {b['with']:.0f} us "
            f"with: {extra:+.1f} us, {100 * d['cost_of_period_budget']:+.1f} % of the "
            f"{1e3 / rate:g} ms budget. The recorder's call per period: p50 "
            f"{d['log_call_p50_us']:.1f} us, p99 {d['log_call_p99_us']:.1f} us. Deadline "
            f"misses {m['without']} of {n['without']} without, {m['with']} of {n['with']} "
            "with.", "", provenance(d), ""]


def view(d: dict, page: Page) -> list[str]:
    call = d["publisher_call"]
    prio = d.get("realtime_priority")
    lines = ["## The live view: first paint, lag, and the master's loop with the page open", "",
             f"First paint {d['first_paint_s']:.2f} s after the server started (target 2 s); "
             f"view lag behind the {d['rate_hz']:g} Hz session"
             + (f" p50 {1000 * d['lag_p50_s']:.0f} ms," if "lag_p50_s" in d else "")
             + f" p99 {1000 * d['lag_p99_s']:.0f} ms"
             + (f" over {d['lag_frames']} frames" if "lag_frames" in d else "")
             + " (target 200 ms). The view stream's call per display period alone: "
             f"{call['mean_us']:.1f} us mean, {call['p99_us']:.1f} us p99. "
             + ("" if prio is None else f"The master's loop at SCHED_FIFO priority {prio} "
                                        "(0: normal scheduling). ")
             + (f"{d['touches_per_mode']} touches of {d['contact_s']} s per mode."
                if "touches_per_mode" in d else ""), ""]
    rows = []
    for mode, text in (("no_view", "no view stream"), ("stream_no_page", "view stream, no page"),
                       ("page_open", "view stream, page open")):
        m = d["loop"][mode]
        rows.append([text, f"{m['busy_mean_us']:.0f} us", f"{m['busy_p99_us']:.0f} us",
                     f"{m['period_p99_us']:.0f} us", f"{m['deadline_misses']} of {m['steps']}"]
                    + ([f"{1e3 * m['setup_s_max']:.0f} ms, {m['deadlines_set_aside']} set aside"]
                       if "setup_s_max" in m else ["-"]))
    lines += table(["master loop", "busy mean", "busy p99", "period p99", "deadline misses",
                    "touch set-up: longest; deadlines set aside, all touches"], rows)
    if "setup_s_max" in d["loop"]["no_view"]:
        lines += ["Each touch is set up (its simulated operator and display pad) inside one "
                  "period, with nothing controlled; the deadlines that pass meanwhile are set "
                  "aside, not missed, and its first period starts when it is ready.", ""]
    return lines + [provenance(d), ""]


def skin_floor(d: dict, page: Page) -> list[str]:
    mod, pol = d["module"], d["idle_policy"]
    lines = ["## The display's floor on the real module", "",
             f"Module {mod['name']} (Imax {mod.get('imax_a', '?')} A, Qmax {mod['qmax_w']} W, "
             f"dTmax {mod.get('dtmax_k', '?')} K); {pol['sentence']}", ""]
    rows = []
    for m, v in d["materials"].items():
        pol_row = v.get("policy", {})
        viol = sum(v.get(k, {}).get("violations", 0)
                   for k in ("policy", "at_object", "preconditioned"))
        rows.append([m, f"{v['floor_k']:.3f} K" + (f" (idle {v['idle_policy_c']:.1f} C)"
                                                   if "idle_policy_c" in v else ""),
                     f"{v['floor_at_object_k']:.3f} K",
                     f"{v['floor_preconditioned_k']:.3f} K"
                     + (f" (idle {v['idle_preconditioned_c']:.1f} C)"
                        if "idle_preconditioned_c" in v else ""),
                     f"{pol_row['peak_current_a']:.2f} A" if "peak_current_a" in pol_row else "-",
                     viol])
    lines += table(["material", "idle policy", "pad at the object", "material known, best idle",
                    "peak current", "limit violations"], rows)
    sweep = d.get("sweep") or []
    if sweep:
        lines += ["The module and film swept (aluminium):", ""]
        lines += table(["Qmax", "film R", "floor", "idle"], [
            [f"{r['qmax_w']:.1f} W", f"{r['film_r_m2k_w']:.1e} m^2 K/W",
             f"{r['aluminium_floor_k']:.3f} K", f"{r['idle_policy_c']:.1f} C"] for r in sweep])
    rows = (d.get("decision") or {}).get("rows") or []
    if rows:
        lines += ["The worst material's floor when the display learns the material "
                  "at the slave's decision:", ""]
        lines += table(["decision", "floor (worst)", "per material"], [
            [f"{r['decision_s']:g} s", f"{r['floor_worst_k']:.3f} K"
             + ("" if r.get("converged", True) else " (SLSQP did not converge)"),
             ", ".join(f"{m} {v:.3f}" for m, v in r.get("per_material_k", {}).items())]
            for r in rows])
    t = d["timings"]
    lines += [d.get("sweep_verdict", ""), "",
              f"Time: {t['total_s']:.0f} s (search {t.get('idle_search_s', 0):.0f} s, floors "
              f"{t.get('floors_s', 0):.0f} s, sweep {t.get('sweep_s', 0):.0f} s, decision "
              f"{t.get('decision_s', 0):.0f} s).", "", figure(page, d, "skin-floor"),
              provenance(d), ""]
    return lines


def as_built(title: str, module: str):
    """A section of an as-built bench's JSON: its own lines, preformatted,
    its provenance."""
    def section(d: dict, page: Page) -> list[str]:
        import importlib
        lines = importlib.import_module(f"telethermal.bench.{module}").text_lines(d["as_built"])
        stopped = [f"*{d['stopped']}*", ""] if d.get("stopped") else []
        return [f"## {title}", "", "```", *lines, "```", "", *stopped, provenance(d), ""]
    return section
