"""``telethermal bench unseen``'s report in words: the lines the command
prints (:func:`text_report`) and ``bench report``'s section
(:func:`report_section`), from the JSON report of
:func:`telethermal.bench.unseen.run` (split out of that module)."""

from __future__ import annotations

from telethermal.bench import unseen_layered as ul
from telethermal.bench import unseen_render as ur
from telethermal.bench import unseen_trade as ut


def text_report(report: dict, json_path) -> list[str]:
    """The lines ``telethermal bench unseen`` prints."""
    lines = [f"bench unseen on {report['scene']}, seeds {report['seeds']}: median |e - e_true|"
             f"/e_true and 95 % interval coverage at {', '.join(map(str, report['windows_s']))} s"]
    for m, r in report["materials"].items():
        if r.get("layered"):
            lines.append(ul.text_line(m, r))
            continue
        tag = "trained" if r["trained"] else "unseen "
        err = " ".join(f"{100 * v:5.1f}%" for v in r["effusivity_rel_error"].values())
        cov = " ".join(f"{100 * c['rate']:3.0f}%" for c in r["interval_coverage"].values())
        lines.append(f"  {tag} {m:<13} e {r['effusivity_w_s05_m2k']:8.0f}  error {err}  "
                     f"coverage {cov}  z rms {_z_rms(r, ' ')}  (n {r['touches']})")
    for key, who in (("coverage_by_window", "every material"),
                     ("unseen_coverage_by_window", "unseen materials")):
        if report["targets"].get(key):
            lines.append(f"  coverage, {who} (target 90-98 %): " + ", ".join(
                f"{k} s {100 * c['rate']:.1f} % [{100 * c['ci'][0]:.1f}, {100 * c['ci'][1]:.1f}]"
                for k, c in report["targets"][key].items())
                + (" (layered objects left out)" if report["targets"].get("left_out_layered")
                   else ""))
    lines.append("  one estimate, ms (cold p50 / warm p50): " + ", ".join(
        f"{k} s {1e3 * v['cold_s_p50']:.1f}/{1e3 * v['warm_s_p50']:.1f}"
        for k, v in report["time_per_estimate_s"].items()))
    lines.append("  reported (named as / new / unknown) by effusivity-fit:")
    for m, r in report["materials"].items():
        rep = r["reported"]
        if isinstance(rep, dict):
            named = ", ".join(f"{k} {v}" for k, v in rep["named_as"].items()) or "none"
            first = ", ".join(f"{k} {v}" for k, v in rep["named_first_as"].items())
            lines.append(f"    {m:<13} named {rep['named']} ({named}), new {rep['new']}"
                         + (f" ({rep['named_then_new']} named {first} before the last "
                            f"window)" if rep["named_then_new"] else "")
                         + f", unknown {rep['unknown']} of {rep['n']}")
    lines += ut.text_lines(report)
    lines += ur.text_lines(report)
    lines.append(f"wrote {json_path}")
    return lines


def _z_rms(r: dict, sep: str) -> str:
    """A material's rms standardised error per window (``-`` in a report
    made before it was measured)."""
    z = r.get("interval_z")
    return sep.join(f"{v['rms']:.2f}" for v in z.values()) if isinstance(z, dict) else "-"


def report_section(out, d: dict) -> list[str]:
    """``bench report``'s section: per material its effusivity, the median
    error and 95 % coverage per window, and what was reported."""
    windows = [f"{w:g}" for w in d["windows_s"]]
    lines = ["## Materials the identifier never saw (issue 30)", "",
             f"Trained on {', '.join(d['trained'])} ({d['scene']}); unseen "
             f"{', '.join(d['unseen'])}; {len(d['seeds'])} sessions. Median effusivity error "
             f"and 95 % interval coverage at {', '.join(windows)} s; what "
             f"{d['identifier']['method']}'s decisions reported (named, new material; a new "
             "material named a class before the last window counted in brackets; unknown). "
             "z rms: the rms of (ln e_hat - ln e) / sd, 1 where the intervals are as wide as "
             "the errors, under 1 wider.",
             "",
             "| material | e, W s^0.5/(m^2 K) | error | coverage | z rms | named | new | unknown |",
             "|---|---|---|---|---|---|---|---|"]
    for m, r in d["materials"].items():
        if r.get("layered"):
            lines.append(ul.section_line(m, r, windows))
            continue
        rep = r["reported"] if isinstance(r["reported"], dict) else {}
        err = " / ".join(f"{100 * r['effusivity_rel_error'][k]:.1f}" for k in windows)
        cov = " / ".join(f"{100 * r['interval_coverage'][k]['rate']:.0f}" for k in windows)
        first = rep.get("named_then_new", 0)
        lines.append(f"| {m}{'' if r['trained'] else ' (unseen)'} | "
                     f"{r['effusivity_w_s05_m2k']:,.0f} | {err} % | {cov} % | {_z_rms(r, ' / ')} | "
                     f"{rep.get('named', '-')} | {rep.get('new', '-')}"
                     f"{f' ({first})' if first else ''} | {rep.get('unknown', '-')} |")
    left = (d["targets"].get("left_out_layered") or {}).get("objects")
    lines.append("")
    for key, who in (("coverage_by_window", "Coverage, every material"),
                     ("unseen_coverage_by_window", "Coverage, unseen materials")):
        if d["targets"].get(key):
            lines.append(f"{who} (target 90-98 %): " + ", ".join(
                f"{k} s {100 * c['rate']:.1f} %" for k, c in d["targets"][key].items())
                + (f" ({', '.join(left)} left out: layered, no single true effusivity)" if left
                   else "") + ".")
    lines.append("")
    return lines + ur.section_lines(d)
