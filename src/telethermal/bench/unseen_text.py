"""``telethermal bench unseen``'s section: what the bench prints and
``bench report`` writes (:mod:`telethermal.bench.markdown`), from the JSON
report of :func:`telethermal.bench.unseen.run`."""

from __future__ import annotations

from telethermal.bench import unseen_layered as ul
from telethermal.bench import unseen_render as ur
from telethermal.bench import unseen_trade as ut
from telethermal.bench.markdown import Page, provenance


def _z_rms(r: dict, sep: str) -> str:
    """A material's rms standardised error per window (``-`` in a report
    made before it was measured)."""
    z = r.get("interval_z")
    return sep.join(f"{v['rms']:.2f}" for v in z.values()) if isinstance(z, dict) else "-"


def section(d: dict, page: Page) -> list[str]:
    """Per material its effusivity, the median error and 95 % coverage per
    window, and what was reported; the coverage targets, the estimate's
    time, the open-set trade and the rendered columns."""
    windows = [f"{w:g}" for w in d["windows_s"]]
    lines = ["## Materials the identifier never saw", "",
             f"Trained on {', '.join(d['trained'])} ({d['scene']}); unseen "
             f"{', '.join(d['unseen'])}; {len(d['seeds'])} sessions (seeds "
             f"{', '.join(map(str, d['seeds']))}). Median effusivity error "
             f"and 95 % interval coverage at {', '.join(windows)} s; what "
             f"{d['identifier']['method']}'s decisions reported (named, new material; a new "
             "material named a class before the last window counted in brackets; unknown). "
             "z rms: the rms of (ln e_hat - ln e) / sd, 1 where the intervals are as wide as "
             "the errors, under 1 wider.",
             "",
             "| material | e, W s^0.5/(m^2 K) | error | coverage | z rms | named | new | "
             "unknown | touches |", "|---|---|---|---|---|---|---|---|---|"]
    named_as = []
    for m, r in d["materials"].items():
        if r.get("layered"):
            lines.append(ul.section_line(m, r, windows) + f" {r.get('touches', '-')} |")
            continue
        rep = r["reported"] if isinstance(r["reported"], dict) else {}
        err = " / ".join(f"{100 * r['effusivity_rel_error'][k]:.1f}" for k in windows)
        cov = " / ".join(f"{100 * r['interval_coverage'][k]['rate']:.0f}" for k in windows)
        first = rep.get("named_then_new", 0)
        lines.append(f"| {m}{'' if r['trained'] else ' (unseen)'} | "
                     f"{r['effusivity_w_s05_m2k']:,.0f} | {err} % | {cov} % | {_z_rms(r, ' / ')} | "
                     f"{rep.get('named', '-')} | {rep.get('new', '-')}"
                     f"{f' ({first})' if first else ''} | {rep.get('unknown', '-')} | "
                     f"{r.get('touches', '-')} |")
        if rep.get("named_as") or rep.get("named_first_as"):
            named_as.append(f"{m} named " + (", ".join(
                f"{k} {v}" for k, v in rep.get("named_as", {}).items()) or "none")
                + (" (before the last window: " + ", ".join(
                    f"{k} {v}" for k, v in rep["named_first_as"].items()) + ")"
                   if rep.get("named_first_as") else ""))
    lines.append("")
    if named_as:
        lines += ["What the named touches were named: " + "; ".join(named_as) + ".", ""]
    left = (d["targets"].get("left_out_layered") or {}).get("objects")
    for key, who in (("coverage_by_window", "Coverage, every material"),
                     ("unseen_coverage_by_window", "Coverage, unseen materials")):
        if d["targets"].get(key):
            lines += [f"{who} (target 90-98 %): " + ", ".join(
                f"{k} s {100 * c['rate']:.1f} %" + (
                    f" [{100 * c['ci'][0]:.1f}, {100 * c['ci'][1]:.1f}]" if "ci" in c else "")
                for k, c in d["targets"][key].items())
                + (f" ({', '.join(left)} left out: layered, no single true effusivity)" if left
                   else "") + ".", ""]
    if d.get("time_per_estimate_s"):
        lines += ["One estimate, cold / warm p50: " + ", ".join(
            f"{k} s {1e3 * v['cold_s_p50']:.1f} / {1e3 * v['warm_s_p50']:.1f} ms"
            for k, v in d["time_per_estimate_s"].items()) + ".", ""]
    return lines + ut.section_lines(d) + ur.section_lines(d) + [provenance(d), ""]
