"""``telethermal bench render``'s section: what the bench prints and
``bench report`` writes (:mod:`telethermal.bench.markdown`), from its
JSON."""

from __future__ import annotations

from telethermal.bench.clock_text import real_clock_sentences
from telethermal.bench.markdown import Page, figure, pct, provenance, save, table, val


def _controller_rows(c: dict) -> list[list]:
    return [[c["feedforward_model"], m,
             f"{100 * v['mean_flux_rms_error_rel']:.2f} / {100 * v['max_flux_rms_error_rel']:.2f} %",
             f"{v['mean_temp_rms_error_c']:.2f} / {v['max_temp_rms_error_c']:.2f} K"]
            for m, v in c["per_material"].items()]


def dew_line(dew: dict) -> str:
    """The report's dew sentence (``dew``: bench render's ``dew`` section)."""
    if dew["dew_point_c"] is None:
        return f"dew: {dew['humidity']:.0f} % RH at {dew['room_c']:.1f} C: dry air, no dew point"
    return (f"dew: {dew['humidity']:.0f} % RH at {dew['room_c']:.1f} C, dew point "
            f"{dew['dew_point_c']:.2f} C; the idle at least "
            f"{dew['min_idle_minus_dew_k']:.2f} K above it over {dew['sessions']} "
            f"sessions (margin {dew['margin_k']:.1f} K)")


def section(d: dict, page: Page) -> list[str]:
    """The rendering bench's section: error against loop rate, the
    controllers, the gains, the first touches per material, the module's
    limits, dew and the real clock."""
    lines = ["## Rendering: error against loop rate", ""]
    lines += table(["rate", "flux error after identification", "worst", "first second",
                    "skin RMS", "CPU s / simulated s", "safety events"], [
        [f"{r['rate_hz']:g} Hz", pct(r["mean_flux_rms_error_rel"]),
         pct(r["max_flux_rms_error_rel"]), pct(r["mean_flux_rms_error_rel_first_s"]),
         f"{r['mean_temp_rms_error_c']:.2f} K", f"{r['mean_cpu_s_per_simulated_s']:.3g}",
         r["safety_events"]] for r in d["rate"]])
    rows = [row for c in d.get("controller", []) for row in _controller_rows(c)]
    if rows:
        lines += ["The display's internal model per material (mean / worst over seeds):", ""]
        lines += table(["controller model", "material", "flux error", "skin RMS"], rows)
    if d.get("gains"):
        lines += ["The gain study:", ""]
        lines += table(["gains", "pad model", "flux error", "skin RMS"], [
            [r["gains"], f"x{r['pad_resistance_belief']:.1f}", pct(r["mean_flux_rms_error_rel"]),
             f"{r['mean_temp_rms_error_c']:.2f} K"] for r in d["gains"]])
    if d.get("before"):
        lines += ["Before identification:", ""]
        lines += table(["before", "first second flux error", "skin RMS"], [
            [r["before"], pct(r["mean_flux_rms_error_rel_first_s"]),
             f"{r['mean_temp_rms_error_c']:.2f} K"] for r in d["before"]])
    if d.get("generator"):
        g = d["generator"]["rms_error_rel_of_peak"]
        lines += [f"Flux generators on held-out persons: network {pct(g['network'])}, closed "
                  f"form {pct(g['contact'])} RMS of peak.", ""]
    lines += _materials(d) + _decision_floor(d) + _limits(d)
    if "dew" in d:
        dew = dew_line(d["dew"])
        lines += [f"{dew[0].upper()}{dew[1:]}.", ""]
    if "junction_sensor" in d:
        js = d["junction_sensor"]
        lines += [f"Junction sensor {js['name']}, {js['tau_s']:.2f} s as mounted.", ""]
    lines += [f"- {t[0].upper()}{t[1:]}." for t in real_clock_sentences(d)]
    fig = figure(page, d, "render") or _render_plot(page, d["rate"])
    return lines + ["", fig, provenance(d), ""]


def _materials(d: dict) -> list[str]:
    per = d.get("materials")
    if not isinstance(per, dict) or not any(per.values()):
        return []
    return ["First touches per material: the skin's RMS error (idling at the object; "
            "repeated, pre-conditioned), the flux error from the decision and over the first "
            "second (% of peak), the heat extracted over the first second against direct "
            "contact's (told apart beyond 1 +- 0.43), and how long the skin is off by more "
            "than a fingertip detects:", ""] + table(
        ["material", "skin", "idling at the object", "repeated", "flux from the decision",
         "first second", "heat extracted", "skin off"], [
            [m, val(v.get("skin_rms_k"), ".2f", " K"),
             val(v.get("skin_rms_idle_at_object_k"), ".2f", " K"),
             val(v.get("skin_rms_repeat_k"), ".2f", " K"),
             pct(v.get("flux_rms_from_decision_rel")), pct(v.get("flux_rms_first_second_rel")),
             val(v.get("heat_extraction_ratio_first_s"), ".2f", "x"),
             val(v.get("skin_above_threshold_s"), ".2f", " s")]
            for m, v in per.items() if v])


def _decision_floor(d: dict) -> list[str]:
    f = d.get("decision_floor")
    if not (isinstance(f, dict) and "floor_worst_k" in f):
        return []
    return [f"The floor (nominal touch, this model) of a display learning each material only "
            f"at the slave's decision "
            f"({', '.join(f'{m} {t:.3f} s' for m, t in f['decision_s'].items())}): worst "
            f"{f['floor_worst_k']:.3f} K; the worst first touch "
            f"({f['first_touch_worst_material']}) {f['first_touch_worst_k']:.3f} K, "
            f"{f['ratio']:.2f}x it; no display learning then has every material under "
            f"{f['least_worst_ratio_to_floor_k']:.2f}x its floor known at contact (this one: "
            f"{max(f['first_touch_ratio_to_floor_k'].values()):.2f}x).", ""]


def _limits(d: dict) -> list[str]:
    if "limits" not in d:
        return []
    lim = d["limits"]
    lines = [f"Module limits of the shipped display ({lim.get('configuration', '?')}; first "
             f"touches; every row's own in its 'limits', all sessions pooled in "
             f"'limits_all_sessions') over {lim['sessions']} sessions (requests, before any "
             f"clamp): over Imax {lim['current_requested_over_imax_periods']} periods, largest "
             f"{lim['largest_request_a']:.2f} A, voltage over the supply "
             f"{lim['voltage_exceeded']} periods, hot side exceeded "
             f"{lim['hot_side_exceeded']}; current sign reversals "
             f"{lim['reversals_per_s']:.2f} per s of contact, ripple "
             f"{lim['ripple_rms_a']:.3f} A RMS while rendering; safety events "
             f"{d['safety_events']} in {d.get('safety_events_sessions', '?')} sessions with "
             f"the product's gains, the junction loop stopped {d.get('junction_stops', '?')} "
             f"times (re-armed {d.get('junction_rearms', '?')}) in them.", ""]
    study = {k: n for k, n in d.get("safety_events_gain_study", {}).items() if n}
    if study:
        lines += ["The gain study's other gains (not shipped): " + "; ".join(
            f"{k}: {n} safety events" for k, n in study.items()) + ".", ""]
    return lines


def _render_plot(page: Page, rate: list[dict]) -> str:
    """Error and CPU against loop rate, drawn beside the report when the
    bench's own figure (whose first panel shows both) is not found."""
    import matplotlib.pyplot as plt

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
    return save(page, fig, "render_rate.png")
