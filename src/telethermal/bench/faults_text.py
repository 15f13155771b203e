"""What ``telethermal bench faults`` prints: its report as text lines."""

from __future__ import annotations


def recovery_text(row: dict) -> str:
    """A process row's recovery: '' when it has none to show, 'not back', or
    the seconds it took and their bound."""
    if "recovery_s" not in row:
        return ""
    if row["recovery_s"] is None:
        return "not back"
    return f"{row['recovery_s']:.2f} s ({row['recovery_bound_s']:.2f} s)"


def text_report(report: dict) -> list[str]:
    """What ``telethermal bench faults`` prints."""
    from telethermal.bench.faults_sim import WINDOWS

    def pct(v):
        return "      -" if v is None else f"{100 * v:6.2f}%"

    sim = report["simulated"]
    lines = [f"simulated clock: {len(sim['materials'])} materials x {len(sim['seeds'])} seeds, "
             f"{sim['contact_s']:g} s contacts; flux RMS error (% of peak), mean over touches",
             f"{'row':38s} {'mode':12s} " + " ".join(f"{w:>10s}" for w in WINDOWS) +
             "  blind (s)  safety"]
    for name, row in sim["rows"].items():
        for mode, st in list(row["modes"].items()) + list(row.get("ablations", {}).items()):
            lines.append(f"{name:38s} {mode:12s} " + " ".join(
                f"{pct(st[w]['mean']):>10s}" for w in WINDOWS) +
                f"  {st['blind_s']['mean'] or 0:9.3f}  {st['safety_events']:6d}")
    o = sim["oracle"]
    lines.append(f"{'oracle floor':38s} {'':12s} {'':>10s} {'':>10s} "
                 f"{pct(o['whole']['mean']):>10s}")
    s = report["summary"]

    def x(key, digits=2):
        v = s.get(key)
        return "-" if v is None else f"{v:.{digits}f}x"

    lines.append(
        f"at {s['ratio_setting']}: first touch after the news "
        f"{x('first_touch_after_news_ratio_200ms')} zero delay (target <= 1.2), naive "
        f"{x('naive_after_news_ratio_200ms')} the compensated zero-delay error on that "
        f"window (target >= 2; {x('naive_after_news_ratio_200ms_own_zero')} its own), whole "
        f"contact {x('first_touch_whole_ratio_200ms')} (target <= 1.3); repeated touch "
        f"<= {x('repeat_touch_ratio_to_oracle_max', 3)} the oracle floor at every row "
        f"(target <= 1.05)")
    if report["rows"]:
        lines.append(f"{'processes: fault':38s} {'compensated':>11s} {'naive':>7s} safety  "
                     "lossless (gaps/recovered/dup/resent/refused)  recovery (bound)")
        for r in report["rows"]:
            lo = r["lossless"]
            rec = recovery_text(r)
            lines.append(f"{r['fault']:38s} {pct(r['compensated_flux_rms_error_rel']):>11s} "
                         f"{pct(r['naive_flux_rms_error_rel'])} {r['safety_events']:6d}  "
                         f"{lo['gaps']}/{lo['recovered']}/{lo['duplicates']}/{lo['resent']}/"
                         f"{lo.get('refused_by_window', lo.get('lossless_dropped')):<22} {rec}")
        lines.append(f"processes within the simulated spread (mean +- 2 sd): "
                     f"{s['processes_within_simulated_spread']}; fault matrix: "
                     f"{s['fault_matrix_safety_events']} safety events, all recovered: "
                     f"{s['fault_matrix_all_recovered']}")
    return lines
