"""The real-clock rows of ``bench render`` in words, for its printout and
for ``bench/report.md`` alike."""

from __future__ import annotations

from telethermal.control.loop import WORLD_PAUSED


def real_clock_sentences(report: dict) -> list[str]:
    """One sentence per real-clock row: this machine's empty loop, the
    master's own loop (rows on the world-paused clock) and the whole
    session on the loop's thread (rows written before the master's own
    loop was measured carry no clock: they are those)."""
    out = []
    e = report.get("real_clock_empty_loop")
    if e:
        out.append(f"real clock at {e.get('rate_hz', 1000.0):g} Hz, an empty loop (this "
                   f"machine's own floor): period p99 {e['period_p99_us']:.0f} us, max "
                   f"{e['period_max_us']:.0f} us, "
                   f"{e['deadline_misses']} deadline misses of {e['steps']}, "
                   f"{e['stalls']} stalls")
    for key in ("real_clock", "real_clock_world_on_thread", "real_clock_deployed"):
        for r in report.get(key, []):
            who = ("the master's loop (the simulated world not charged to it)"
                   if r.get("clock") == WORLD_PAUSED else "the whole session on the loop's thread")
            if key == "real_clock_deployed":
                who += (f", as deployed: SCHED_FIFO priority {r['realtime_priority']}"
                        if r.get("realtime_priority") else
                        ", as deployed but SCHED_FIFO not granted ("
                        f"{r.get('realtime_refused', 'no reason given')}): normal scheduling")
            own = (f", the master's step p99 {r['master_step_p99_us']:.0f} us"
                   if "master_step_p99_us" in r else "")
            if "gc_collections" in r:
                own += (f"; garbage collections {'/'.join(map(str, r['gc_collections']))} "
                        f"(generations 0/1/2), the longest {r['gc_max_us']:.0f} us")
            out.append(f"real clock at {r['rate_hz']:g} Hz, {who}: period p50 "
                       f"{r['period_p50_us']:.0f} us, p99 {r['period_p99_us']:.0f} us, max "
                       f"{r['period_max_us']:.0f} us, {r['deadline_misses']} deadline misses of "
                       f"{r['steps']}" + (f" ({r['sessions']} touch{'es' if r['sessions'] != 1 else ''} of "
                                           f"{r['contact_s']:g} s)"
                                          if "contact_s" in r else "") +
                       f", {r['stalls']} stalls; busy p99 {r['busy_p99_us']:.0f} us"
                       f"{own}")
    default = report.get("default_rate_hz")
    for key, how in (("real_clock", "at normal priority"),
                     ("real_clock_deployed", "as deployed (SCHED_FIFO)")):
        row = next((r for r in report.get(key, []) if r["rate_hz"] == default
                    and r.get("clock") == WORLD_PAUSED), None)
        if row is None or (key == "real_clock_deployed" and not row.get("realtime_priority")):
            continue
        share = row["deadline_misses"] / max(row["steps"], 1)
        ratio = row["period_p99_us"] / row["period_target_us"]
        # Under 1,000 periods one miss is over 0.1 %: too few to judge it.
        verdict = ("too few periods to judge" if row["steps"] < 1000 else
                   "met" if share <= 1e-3 else "MISSED")
        out.append(f"the display's default rate, {default:g} Hz, {how}: "
                   f"{row['deadline_misses']} of "
                   f"{row['steps']} deadlines missed ({100 * share:.3f} %, target 0.1 %: "
                   f"{verdict}), period p99 {ratio:.3f}x the "
                   f"period (target 1.2x: {'met' if ratio <= 1.2 else 'MISSED'})")
    return out
