"""``telethermal bench faults``' section: what the bench prints and
``bench report`` writes (:mod:`telethermal.bench.markdown`), from its
JSON."""

from __future__ import annotations

from telethermal.bench.markdown import Page, figure, pct, provenance, val


def recovery_text(row: dict) -> str:
    """A process row's recovery: '' when it has none to show, 'not back', or
    the seconds it took and their bound."""
    if "recovery_s" not in row:
        return ""
    if row["recovery_s"] is None:
        return "not back"
    return f"{row['recovery_s']:.2f} s ({row['recovery_bound_s']:.2f} s)"


def section(d: dict, page: Page) -> list[str]:
    """The faults bench's section: the simulated rows, the targets, the
    processes behind the fault proxy."""
    if "simulated" not in d:
        return ["## Rendering under network faults", "",
                "The results predate the simulated-clock benchmark: re-run "
                "`telethermal bench faults`.", "", provenance(d), ""]
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
                         f"{cell(st['whole'])} | {val(st['blind_s']['mean'], '.3f')} | "
                         f"{st['safety_events']} |")
    lines.append(f"| - | oracle floor | | | {cell(sim['oracle']['whole'])} | 0 | "
                 f"{sim['oracle']['safety_events']} |")

    def x(key, digits=2):
        return val(s.get(key), f".{digits}f", "x")

    lines += ["", f"At {s.get('ratio_setting', '-')}: the first touch after the news "
              f"**{x('first_touch_after_news_ratio_200ms')}** its zero-delay error "
              f"(target <= 1.2), the whole contact **{x('first_touch_whole_ratio_200ms')}** "
              f"(target <= 1.3); naive after the news **{x('naive_after_news_ratio_200ms')}** "
              f"the same zero-delay error (target >= 2; "
              f"{x('naive_after_news_ratio_200ms_own_zero')} its own, "
              f"{x('naive_after_news_ratio_200ms_to_compensated_200ms')} the compensated on "
              f"the same row). A repeated touch (object memory) is at most "
              f"**{x('repeat_touch_ratio_to_oracle_max', 3)}** the oracle floor over every row "
              f"(target <= 1.05). (-: a row the run left out.)", ""]
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
            lines.append(f"| {r['fault']} | {pct(r['compensated_flux_rms_error_rel'])} | "
                         f"{pct(r['naive_flux_rms_error_rel'])} | {r['safety_events']} | "
                         f"{lo['gaps']}/{lo['recovered']}/{lo['duplicates']}/{lo['resent']}/"
                         f"{lo.get('refused_by_window', lo.get('lossless_dropped'))} | {r['recovered']} | "
                         f"{rec} |")
        lines += ["", f"The processes' whole-contact errors within the simulated mean +- 2 sd "
                  f"of the same material: {s.get('processes_within_simulated_spread', '-')}; "
                  f"the fault matrix: {s.get('fault_matrix_safety_events', '-')} safety events, "
                  f"all recovered: {s.get('fault_matrix_all_recovered', '-')}.",
                  ""]
    lines += [figure(page, d, "faults"), figure(page, d, "faults", "-traces"), provenance(d), ""]
    return lines
