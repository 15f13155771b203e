"""What ``telethermal bench identify`` prints of its report."""

from __future__ import annotations


def _pct(by_window: dict) -> str:
    return ", ".join(f"{k} s {100 * v:.0f} %" for k, v in by_window.items())


def _method_lines(method: str, rep: dict) -> list[str]:
    """One method's lines of ``telethermal bench identify``."""
    pad = " " * len(method)
    t1, ap = rep["table1"], rep.get("active_passive")
    lines = [f"{method}: Table 1, 7 classes " + _pct(t1["accuracy_7"]),
             f"{pad}  5 classes " + ", ".join(
                 f"{k} s {100 * v:.0f} % (paper {100 * t1['paper_accuracy_5'][k]:.0f} %)"
                 if k in t1["paper_accuracy_5"] else f"{k} s {100 * v:.0f} %"
                 for k, v in t1["accuracy_5"].items()),
             f"{pad}  train {t1['train_s_full_database']:.1f} s; inference "
             f"p99 {t1['inference_ms_p99']:.3f} ms"]
    if ap is not None:
        lines.append(f"{pad}  active pad: " + _pct(ap["active_accuracy_by_window_s"])
                     + f"; passive pad unknown {100 * ap['passive_unknown_rate']:.0f} %")
    lines += [f"{pad}  not run: {why}" for why in rep.get("not_run", [])]
    if "temperature" in rep:
        tr = rep["temperature"]
        lines.append(f"{pad}  temperature channel, active pad: "
                     + _pct(tr["active_accuracy_by_window_s"])
                     + f"; passive unknown {100 * tr['passive_unknown_rate']:.0f} %")
    lines += [f"{pad}  {name}: >= 99 % from {row['first_window_at_99pct_s']} s (paper 100 % "
              f"within {row['paper_100pct_within_s']} s)"
              for name, row in rep.get("cross_temperature", {}).items()]
    dec = t1["decision"]
    lines.append(f"{pad}  calibration error {t1['calibration_ece']:.3f}; decisions "
                 f"within 1 s: {100 * dec['commit_rate']:.0f} % committed, "
                 + ("-" if dec["accuracy"] is None else f"{100 * dec['accuracy']:.0f} %")
                 + " of them right")
    if "live" in rep:
        lv = rep["live"]
        lines.append(f"{pad}  over {lv['sessions']} session(s), {lv['touches']} touches: 7 classes "
                     + ", ".join(f"{k} s {100 * v:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}]"
                                 for (k, v), (lo, hi) in zip(t1["accuracy_7"].items(),
                                                             t1["accuracy_7_ci"].values())))
        lines.append(f"{pad}  live decisions: named alone {100 * lv['named_rate']:.1f} %, pair "
                     f"{100 * lv['pair_rate']:.1f} %, unknown {100 * lv['unknown_rate']:.1f} %, "
                     f"wrong {100 * lv['wrong_rate']:.1f} % [{100 * lv['wrong_rate_ci'][0]:.1f}, "
                     f"{100 * lv['wrong_rate_ci'][1]:.1f}]; first commitment p50 "
                     + ("-" if lv["time_s_p50"] is None else f"{lv['time_s_p50']:.2f} s"))
    return lines + [f"{pad}  session shift (1 K), thermometer {mode}: " + _pct(row["accuracy_5"])
                    for mode, row in rep.get("session_shift", {}).items()]


def text_report(report: dict, json_path, png_path) -> list[str]:
    """What ``telethermal bench identify`` prints of ``report``."""
    if "scene" in report:
        from telethermal.ident.crossval import text_report as cv_lines
        return [line for rep in report["methods"].values() for line in cv_lines(rep)] + \
            [f"wrote {json_path} and {png_path}"]
    lines = [line for method, rep in report["methods"].items()
             for line in _method_lines(method, rep)]
    lines.append("object-thermometer ablation (effusivity-lda, 0.2 / 0.5 / 1 s): " + "; ".join(
        f"{k}: " + " / ".join(f"{100 * x:.0f}" for x in v.values()) + " %"
        for k, v in report["thermometer_ablation"]["accuracy"].items()))
    if "limit" in report:
        lim = report["limit"]
        lines.append(f"physical limit (oracle, {len(lim['sessions'])} session(s), "
                     f"{lim['touches']} touches): "
                     "7 classes " + _pct(lim["accuracy_7"]) + "; 5 classes "
                     + _pct(lim["accuracy_5"]))
        lines += [f"  {m}: points below the limit " + ", ".join(
            f"{w} s {v:+.1f}" for w, v in gap.items())
            for m, gap in report.get("limit_gap_points", {}).items()]
    if "lm_vs_adam" in report:
        lines.append("LM against Adam: " + "; ".join(
            f"{k} loss {v['final_loss']:.4f} after {v['iterations']} iterations, "
            f"{v['runtime_s']:.2f} s" for k, v in report["lm_vs_adam"].items()))
    if "lstm_hidden_sweep" in report:
        lines.append("LSTM width sweep (0.4 s / 1 s): " + "; ".join(
            f"{k}: {100 * v['0.4']:.0f} / {100 * v['1']:.0f} %"
            for k, v in report["lstm_hidden_sweep"]["accuracy"].items()))
    return lines + [f"wrote {json_path} and {png_path}"]
