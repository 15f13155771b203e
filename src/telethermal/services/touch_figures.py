"""A master touch's figures: the touch against the same finger touching the
object directly (when the request named the placed object), and the log line
that reports them."""

from __future__ import annotations

import logging

import numpy as np

from telethermal.devices.simulated import simulated
from telethermal.teleop.decision import when_decided

log = logging.getLogger("telethermal.master")


def touch_figures(scene, touch, result: dict) -> dict:
    """The touch against the same finger touching the object directly, when
    the touch request named the placed object (a simulated scene holding it):
    flux and skin-temperature errors (``sim/direct.py``'s metrics); ``touch``
    is the master's :class:`~telethermal.services.master.Touch`."""
    compare_with_direct = simulated("direct_contact")
    n = touch.sim.n_total
    result["trace"] = {k: v[:n] for k, v in touch.sim.trace.items()}
    truth = touch.truth or {}
    material = truth.get("material")
    if material not in scene.materials or \
            truth.get("object_true_c") is None:
        return {"direct": None}
    # From the slave's decision (its time after the master's onset), not
    # from the master's own render start.
    render_from = result["render_start_s"]
    if result.get("decision_time_s") is not None and result.get("master_onset_s") is not None:
        render_from = result["master_onset_s"] + result["decision_time_s"]
    trace = {k: np.asarray(v, dtype=object if k == "phase" else float)
             for k, v in result["trace"].items()}
    metrics = compare_with_direct(scene, material, float(truth["object_true_c"]),
                                  touch.operator, trace, touch.contact_s, render_from)
    result["trace"] = trace
    return {"direct": {"material": material, **metrics}}


def log_touch_figures(result: dict) -> None:
    d = result.get("direct")
    when = when_decided(result)
    when = "no decision" if when is None else f"decided {when}"
    rtt = result.get("rtt_s")
    figures = "" if not d else (
        f"; against direct contact with {d['material']}: flux error "
        f"{100 * d['flux_rms_error_rel']:.2f} % of peak after rendering began, "
        f"{100 * d['flux_rms_error_rel_first_s']:.2f} % over the first second, skin "
        f"{d['temp_rms_error_c']:.2f} K RMS")
    log.info("touch over contact_id=%d identified=%s (%s)%s; safety events %d; rtt %s",
             result["contact_id"], result["identified"], when, figures,
             result["safety_events"], "-" if rtt is None else f"{1e3 * rtt:.2f} ms")
