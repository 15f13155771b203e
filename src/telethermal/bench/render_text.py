"""What ``telethermal bench render`` prints of its report."""

from __future__ import annotations

from pathlib import Path

from telethermal.bench.clock_text import real_clock_sentences


def _controller_line(c: dict) -> str:
    return f"controller {c['feedforward_model']} (mean/worst): " + ", ".join(
        f"{m} flux {100 * v['mean_flux_rms_error_rel']:.2f}/"
        f"{100 * v['max_flux_rms_error_rel']:.2f} % skin "
        f"{v['mean_temp_rms_error_c']:.2f}/{v['max_temp_rms_error_c']:.2f} K"
        for m, v in c["per_material"].items())


def dew_line(dew: dict) -> str:
    """The report's dew sentence (``dew``: bench render's ``dew`` section)."""
    if dew["dew_point_c"] is None:
        return f"dew: {dew['humidity']:.0f} % RH at {dew['room_c']:.1f} C: dry air, no dew point"
    return (f"dew: {dew['humidity']:.0f} % RH at {dew['room_c']:.1f} C, dew point "
            f"{dew['dew_point_c']:.2f} C; the idle at least "
            f"{dew['min_idle_minus_dew_k']:.2f} K above it over {dew['sessions']} "
            f"sessions (margin {dew['margin_k']:.1f} K)")


def text_report(report: dict, json_path: str | Path) -> list[str]:
    """What ``telethermal bench render`` prints of ``report``."""
    lines = [f"{r['rate_hz']:6.0f} Hz: flux error after identification "
             f"{100 * r['mean_flux_rms_error_rel']:.2f} % (max "
             f"{100 * r['max_flux_rms_error_rel']:.2f} %), first second "
             f"{100 * r['mean_flux_rms_error_rel_first_s']:.2f} %, skin "
             f"{r['mean_temp_rms_error_c']:.2f} K, CPU {r['mean_cpu_s_per_simulated_s']:.3f} s/s, "
             f"safety events {r['safety_events']}" for r in report["rate"]]
    lines += [_controller_line(c) for c in report["controller"]]
    lines += [f"gains {r['gains']:20s} pad model x{r['pad_resistance_belief']:.1f}: flux "
              f"{100 * r['mean_flux_rms_error_rel']:.2f} %, skin "
              f"{r['mean_temp_rms_error_c']:.2f} K" for r in report["gains"]]
    lines += [f"before identification {r['before']:5s}: first second "
              f"{100 * r['mean_flux_rms_error_rel_first_s']:.2f} %, skin "
              f"{r['mean_temp_rms_error_c']:.2f} K" for r in report["before"]]
    if report["generator"]:
        g = report["generator"]["rms_error_rel_of_peak"]
        lines.append(f"generators on held-out persons: network {100 * g['network']:.2f} %, "
                     f"closed form {100 * g['contact']:.2f} % RMS of peak")
    per = report.get("materials")
    if isinstance(per, dict):
        lines += [f"{m:10s}: first touch skin {v['skin_rms_k']:.2f} K (idling at the object "
                  f"{v['skin_rms_idle_at_object_k']:.2f} K), repeated (pre-conditioned) "
                  f"{v['skin_rms_repeat_k']:.2f} K; flux from the decision "
                  f"{100 * v['flux_rms_from_decision_rel']:.2f} %, first second "
                  f"{100 * v['flux_rms_first_second_rel']:.2f} % of peak; heat extracted "
                  f"over the first second {v['heat_extraction_ratio_first_s']:.2f}x direct "
                  f"contact's (told apart beyond 1 +- 0.43), skin off by more than a "
                  f"fingertip detects for {v['skin_above_threshold_s']:.2f} s"
                  for m, v in per.items() if v]
    d = report.get("decision_floor")
    if isinstance(d, dict) and "floor_worst_k" in d:
        lines.append(f"floor (nominal touch, this model) of a display learning each material "
                     f"only at the slave's decision "
                     f"({', '.join(f'{m} {t:.3f} s' for m, t in d['decision_s'].items())}): "
                     f"worst {d['floor_worst_k']:.3f} K; the worst first touch "
                     f"({d['first_touch_worst_material']}) {d['first_touch_worst_k']:.3f} K, "
                     f"{d['ratio']:.2f}x it; no display learning then has every material "
                     f"under {d['least_worst_ratio_to_floor_k']:.2f}x its floor known at "
                     f"contact (this one: "
                     f"{max(d['first_touch_ratio_to_floor_k'].values()):.2f}x)")
    if "limits" in report:
        lim = report["limits"]
        lines.append(f"module limits of the shipped display ({lim.get('configuration', '?')}; "
                     f"first touches; every row's own in its 'limits', all sessions pooled "
                     f"in 'limits_all_sessions') over {lim['sessions']} sessions (requests, before any "
                     f"clamp): over Imax {lim['current_requested_over_imax_periods']} periods, "
                     f"largest {lim['largest_request_a']:.2f} A, voltage over the supply "
                     f"{lim['voltage_exceeded']} periods, hot side exceeded "
                     f"{lim['hot_side_exceeded']}; current sign reversals "
                     f"{lim['reversals_per_s']:.2f} per s of contact, ripple "
                     f"{lim['ripple_rms_a']:.3f} A RMS while rendering; "
                     f"safety events {report['safety_events']} in "
                     f"{report.get('safety_events_sessions', '?')} sessions with the "
                     f"product's gains, the junction loop stopped "
                     f"{report.get('junction_stops', '?')} times (re-armed "
                     f"{report.get('junction_rearms', '?')}) in them")
        study = {k: n for k, n in report.get("safety_events_gain_study", {}).items() if n}
        if study:
            lines.append("the gain study's other gains (not shipped): " + "; ".join(
                f"{k}: {n} safety events" for k, n in study.items()))
    if "dew" in report:
        lines.append(dew_line(report["dew"]))
    if "junction_sensor" in report:
        js = report["junction_sensor"]
        lines.append(f"junction sensor {js['name']}, {js['tau_s']:.2f} s as mounted")
    lines += real_clock_sentences(report)
    return lines + [f"wrote {json_path} and {report['png']}"]
