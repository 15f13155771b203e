"""``telethermal bench identify``'s section: what the bench prints and
``bench report`` writes (:mod:`telethermal.bench.markdown`), from its
JSON."""

from __future__ import annotations

from telethermal.bench.markdown import Page, figure, num, pct, provenance, table

WINDOWS = ("0.25", "0.5", "0.75", "1")


def section(d: dict, page: Page) -> list[str]:
    if "scene" in d:                  # a cross-validation on a scene of the user's
        from telethermal.ident.crossval import text_report as cv_lines
        return [f"## Identification on {d['scene']}: grouped cross-validation", "", "```",
                *[line for rep in d["methods"].values() for line in cv_lines(rep)], "```", "",
                figure(page, d, "identify"), provenance(d), ""]
    lines = ["## Identification: accuracy against time after contact, per method", "",
             "Beside learning-based-thermal-rendering Table 1 (its 7 materials, and 5 "
             "classes with the indistinguishable pairs merged).", ""]
    rows, t1 = [], {}
    for name, m in d["methods"].items():
        t1 = m.get("table1", {}) or t1
        for n in (7, 5):
            acc = m.get("table1", {}).get(f"accuracy_{n}", {})
            rows.append([name, n, *(pct(acc.get(k)) for k in WINDOWS)])
    lim = d.get("limit") or {}
    for n in (7, 5):
        if lim.get(f"accuracy_{n}"):
            rows.append(["physical limit (oracle)", n,
                         *(pct(lim[f"accuracy_{n}"].get(k)) for k in WINDOWS)])
    for n in (7, 5):
        paper = t1.get(f"paper_accuracy_{n}")
        if isinstance(paper, str):
            rows.append(["the paper", n, paper, "", "", ""])
        elif paper:
            rows.append(["the paper", n, *(pct(paper.get(k)) for k in WINDOWS)])
    lines += table(["method", "classes", "0.25 s", "0.5 s", "0.75 s", "1 s"], rows)
    lines += _limit(d) + _paper_confusions(d) + _decisions(d) + _live(d) + _shift(d) + \
        _active(d) + _ablation(d) + _training(d) + \
        [figure(page, d, "identify"), provenance(d), ""]
    return lines


def _limit(d: dict) -> list[str]:
    lim, gaps = d.get("limit"), d.get("limit_gap_points") or {}
    if not lim:
        return []
    return [f"The physical limit: an oracle that knows the pad's model ({lim['touches']} "
            f"touches over {len(lim['sessions'])} session(s)). Points below it, 7 classes: "
            + "; ".join(f"{m} " + ", ".join(f"{w} s {v:+.1f}" for w, v in gap.items())
                        for m, gap in gaps.items()) + ".", ""]


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
            f"{pct(best[0])} ({best[1]}). No property was changed to match the paper.", ""]


def _decisions(d: dict) -> list[str]:
    lines = ["Calibration and decisions on the first paper's protocol (held-out trials; "
             "decisions committed within 1 s of contact, a group counting as right when it "
             "holds the touched material):", ""]
    rows = []
    for name, m in d["methods"].items():
        t1 = m.get("table1", {})
        dec = t1.get("decision") or {}
        rows.append([name, num(t1.get("calibration_ece")), pct(dec.get("commit_rate")),
                     pct(dec.get("accuracy")), f"{num(dec.get('time_s_p50'))} s",
                     pct(dec.get("group_rate")), num(t1.get("inference_ms_p50")),
                     num(t1.get("inference_ms_p99"))])
    return lines + table(["method", "calibration error", "committed", "right",
                          "median commit time", "stayed a group", "inference (ms, p50)",
                          "p99"], rows)


def _live(d: dict) -> list[str]:
    rows = []
    for name, m in d["methods"].items():
        lv, t1 = m.get("live"), m.get("table1", {})
        if not lv:
            continue
        ci = t1.get("accuracy_7_ci", {})
        acc = [f"{100 * v:.1f} [{100 * ci[k][0]:.1f}, {100 * ci[k][1]:.1f}]" if k in ci
               else f"{100 * v:.1f}" for k, v in t1.get("accuracy_7", {}).items()]
        rows.append([name, f"{lv['sessions']} / {lv['touches']}", *acc,
                     pct(lv["named_rate"], 1), pct(lv["pair_rate"], 1),
                     pct(lv["unknown_rate"], 1),
                     f"{pct(lv['wrong_rate'], 1)} [{100 * lv['wrong_rate_ci'][0]:.1f}, "
                     f"{100 * lv['wrong_rate_ci'][1]:.1f}]",
                     "-" if lv["time_s_p50"] is None else f"{lv['time_s_p50']:.2f} s"])
        windows = [f"{k} s" for k in t1.get("accuracy_7", {})]
    if not rows:
        return []
    return ["Live decisions, as the slave commits them (7 classes, % with 95 % intervals):",
            ""] + table(["method", "sessions / touches", *windows, "named alone", "pair",
                         "unknown", "wrong", "first commitment p50"], rows)


def _shift(d: dict) -> list[str]:
    rows = [(n, m["session_shift"]) for n, m in d["methods"].items() if "session_shift" in m]
    if not rows:
        return []
    lines = ["Session shift: trained on one session, tested on another whose object "
             "thermometer reads 1 K lower (+0.5 K then -0.5 K, the datasheet's limit both "
             "ways); 5 classes:", ""]
    out = []
    for name, shift in rows:
        for mode in ("calibrated", "uncalibrated"):
            r = shift[mode]
            acc = r["accuracy_5"]
            out.append([name, mode, *(pct(acc.get(k)) for k in WINDOWS),
                        pct(r["decision"]["commit_rate"]), pct(r["decision"]["accuracy"])])
    return lines + table(["method", "thermometer", "0.25 s", "0.5 s", "0.75 s", "1 s",
                          "committed", "right"], out)


def _windows(by_window: dict) -> list[str]:
    """Accuracies per window, in %, one decimal."""
    return [f"{100 * v:.1f}" if v is not None else "-" for v in by_window.values()]


def _active(d: dict) -> list[str]:
    """The second paper's rows: the active pad per window, its decisions
    and the passive pad; the cross-temperature pairs; the temperature
    channel. Then the rows a method leaves out."""
    active, cross, temp = [], [], []
    a_windows, t_windows = [], []
    for name, m in d["methods"].items():
        ap = m.get("active_passive")
        if ap is not None:
            acc = ap.get("active_accuracy_by_window_s", {})
            a_windows = a_windows or [f"{k} s" for k in acc]
            dec = ap.get("decision") or {}
            active.append([name, *_windows(acc), pct(dec.get("commit_rate")),
                           pct(dec.get("accuracy")), num(ap.get("calibration_ece")),
                           pct(ap.get("passive_unknown_rate"))])
        for pair, r in (m.get("cross_temperature") or {}).items():
            cross.append([name, pair, f"{num(r.get('first_window_at_99pct_s'))} s",
                          f"{num(r.get('paper_100pct_within_s'))} s"])
        tr = m.get("temperature")
        if tr:
            t_acc = tr.get("active_accuracy_by_window_s", {})
            t_windows = t_windows or [f"{k} s" for k in t_acc]
            temp.append([name, *_windows(t_acc), pct(tr.get("passive_unknown_rate"))])
    lines = []
    if active:
        lines += ["Second paper, active pad (gripper I-pro, 4 materials, held-out trials; "
                  "accuracy in % per window), its decisions, and the passive pad:", ""]
        lines += table(["method", *a_windows, "committed", "right", "calibration error",
                        "passive pad unknown"], active)
    if cross:
        lines += ["The cross-temperature pairs: the first window at 99 %, against the "
                  "paper's 100 %:", ""]
        lines += table(["method", "pair", "at 99 % from", "the paper: 100 % within"], cross)
    if temp:
        lines += ["The temperature channel, active pad (accuracy in % per window), and the "
                  "passive pad:", ""]
        lines += table(["method", *t_windows, "passive pad unknown"], temp)
    not_run = [f"{n}: {why}" for n, m in d["methods"].items() for why in m.get("not_run", [])]
    return lines + ([f"Rows a method leaves out: {'; '.join(not_run)}.", ""] if not_run else [])


def _ablation(d: dict) -> list[str]:
    ab = d.get("thermometer_ablation")
    if not ab:
        return []
    lines = [f"Where the accuracy goes ({ab['method']}, leave-trials-out, one session):", ""]
    return lines + table(["scene, object thermometer", "0.2 s", "0.5 s", "1 s"], [
        [name, *(pct(acc.get(k)) for k in ("0.2", "0.5", "1"))]
        for name, acc in ab["accuracy"].items()])


def _training(d: dict) -> list[str]:
    lines = []
    train = [f"{n} {m['table1']['train_s_full_database']:.1f} s"
             for n, m in d["methods"].items() if "train_s_full_database" in m.get("table1", {})]
    if train:
        lines.append(f"Training on the whole database: {', '.join(train)}.")
    if "lm_vs_adam" in d:
        lines.append("Levenberg-Marquardt against Adam: " + "; ".join(
            f"{k} loss {v['final_loss']:.4f} after {v['iterations']} iterations, "
            f"{v['runtime_s']:.2f} s" for k, v in d["lm_vs_adam"].items()) + ".")
    if "lstm_hidden_sweep" in d:
        lines.append("LSTM width sweep (0.4 s / 1 s): " + "; ".join(
            f"{k}: {100 * v['0.4']:.0f} / {100 * v['1']:.0f} %"
            for k, v in d["lstm_hidden_sweep"]["accuracy"].items()) + ".")
    return [" ".join(lines), ""] if lines else []
