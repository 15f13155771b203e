"""The demo's touches over the network: one placed and touched through the
running services and compared with direct contact (:func:`networked_touch`,
which the fault benches and the tests use too), and the demo's line for it
beside the same touch in one process."""

from __future__ import annotations

import logging
import math
import time

from telethermal.control.loop import DEFAULT_RATE_HZ
from telethermal.errors import TelethermalError, TransportError
from telethermal.ident.anytime import Label, Reason
from telethermal.ident.openset import EFFUSIVITY_KEYS
from telethermal.services.admin import call
from telethermal.sim.direct import compare_with_direct
from telethermal.sim.inprocess import SessionResult
from telethermal.teleop.decision import DECISION_KEYS, when_decided
from telethermal.teleop.memory import memory_counts
from telethermal.teleop.plots import plot_session

log = logging.getLogger(__name__)


def _wait_pad_up(slave_admin: int, timeout_s: float) -> bool:
    """Until the slave's pad is up (its contact over); False on timeout or
    when the slave does not answer by then (killed: the caller's fallback
    applies). A slave that answers late is not dead: after a lift it
    prepares its next touch (the simulated pad's next trial: a fraction
    of a second) before it serves its admin socket again."""
    end = time.monotonic() + timeout_s
    while (remaining := end - time.monotonic()) > 0:
        try:
            if not call(slave_admin, "status", timeout_s=remaining).get("pad_down"):
                return True
        except TransportError:
            return False
        time.sleep(0.01)
    return False


def networked_touch(scene, material: str, ports, seed: int, contact_s: float,
                    source: str = "trajectory", during=None) -> SessionResult:
    """Place, touch, compare with direct contact; returns the session result.
    ``source``: "trajectory" (compensated) or "setpoints" (naive).
    ``during``: called in a thread once the touch is under way (a fault to
    inject mid-contact, e.g. killing the slave); the touch's figures then
    come from the master alone if the slave's report is lost with it."""
    import threading

    _, _, slave_admin, master_admin = ports
    placed = call(slave_admin, "place", material=material, seed=seed)
    if not placed.get("ok"):
        raise TelethermalError(f"slave: {placed.get('error')}")
    # The master hears of the new object: this placement's announcement, not
    # an earlier one with the same temperature (after a lift the slave puts
    # the previous material back with the next seed, the one this touch may
    # use: same object temperature, another object and memory).
    announced = {"object_temp_c": placed["object_ir_c"], "object_id": placed["object_id"],
                 "object_material": placed.get("object_material")}

    def heard(status):
        t, want = status.get("object_temp_c"), announced["object_temp_c"]
        same = t == want or (None not in (t, want) and (abs(t - want) <= 1e-9 or
                                                        math.isnan(t) and math.isnan(want)))
        return same and all(status.get(k) == announced[k]
                            for k in ("object_id", "object_material"))

    end = time.monotonic() + 30.0     # a hang guard: heard at once on a link that works
    while not heard(call(master_admin, "status")):
        if time.monotonic() > end:
            log.warning("the master did not hear the placement of %s in 30 s", material)
            break
        time.sleep(0.05)
    thread = None
    if during is not None:
        thread = threading.Thread(target=during, daemon=True)
        thread.start()
    # A hang guard: the contact lasts contact_s of the master's clock, time_scale
    # of the machine's (and on QEMU's cores a period may take several times its length).
    status = call(master_admin, "status")
    slow = float(status.get("time_scale", 1.0)) * (6.0 if status.get("devices") == "qemu"
                                                   else 1.0)
    try:
        result = call(master_admin, "touch", timeout_s=slow * contact_s + 30,
                      contact_s=contact_s, seed=seed, source=source)
    finally:
        if thread is not None:
            thread.join()
    if not result.get("ok"):
        raise TelethermalError(f"master: {result.get('error')}")
    # The lift reaches the slave a network delay later: its report is this
    # touch's only once its pad is up, and the next place must not find it
    # down (it would lift it, and the memory learn it after a forget).
    if not _wait_pad_up(slave_admin, timeout_s=5.0):
        log.warning(
            "%s: the slave's pad was not up 5 s after the touch (or the slave did not "
            "answer): its report may be an earlier touch's", material)
    report = call(slave_admin, "report")
    slave_devices = report.get("devices")
    if report.get("object_true_c") is None:          # the slave was restarted meanwhile
        report = {"object_true_c": placed["object_true_c"], "identified": result["identified"],
                  "decision_time_s": None, "onset_s": None, "reason": Reason.SLAVE_RESTARTED,
                  "unknown_reason": result.get("unknown_reason") and Reason.SLAVE_RESTARTED}
    import numpy as np

    from telethermal.sim.touch import Operator
    trace = {k: np.array(v, dtype=object if k == "phase" else float)
             for k, v in result["trace"].items()}
    operator = Operator(**result["operator"])
    # Errors "after identification" run from the slave's decision, never
    # from where the master began to render (that would hide the transient).
    render_from = result["render_start_s"]
    if report.get("decision_time_s") is not None and report.get("onset_s") is not None:
        render_from = report["onset_s"] + report["decision_time_s"]
    metrics = compare_with_direct(scene, material, report["object_true_c"], operator, trace,
                                  contact_s, render_from)
    summary = {"scene": scene.name, "material": material, "seed": seed,
               "identified": report["identified"], "decision_time_s": report["decision_time_s"],
               "identified_at_s": report.get("identified_at_s"),
               "decision_reason": report["reason"], "decision_from_s": render_from,
               # why it is "unknown" (None: named), as the slave reports it
               "unknown_reason": report.get("unknown_reason"),
               # a new material's estimate and nearest class, as the slave reports it
               **{k: report.get(k) for k in EFFUSIVITY_KEYS},
               "decision_text": report.get("decision_text"),
               # the object's temperature, true and as the slave measured it
               "object_true_c": report["object_true_c"],
               "object_ir_c": report.get("object_ir_c", placed["object_ir_c"]),
               "render_start_s": result["render_start_s"],
               "object_memory": result.get("object_memory"),
               # the memory's counters of this touch, on each side (as in process)
               "memory_counts": memory_counts(result["memory_judged"],
                                              report.get("memory_judged", {})),
               "rate_hz": 1.0 / float(np.median(np.diff(trace["t_s"]))),
               "contact_s": contact_s, **metrics,
               **{k: result[k] for k in ("safety_events", "safety_event_counts",
                                         "display_event_counts", "loop", "transport",
                                         "trajectory_at_s", "rtt_s", "link_counters",
                                         "anchor_lag_s", "devices", "device_counters",
                                         "time_scale")},
               "loop_period_p99_us": result["loop"]["period_p99_us"], "clock": "real",
               "devices_per_side": {"master": master_device_summary(result),
                                    "slave": slave_devices}}
    return SessionResult(summary, trace)


def master_device_summary(result: dict) -> dict | None:
    """The master's device counters of one touch, in the slave's terms
    (None on the simulator)."""
    c = result.get("device_counters") or {}
    board = c.get("board")
    if not board:
        return None
    return {"kind": result.get("devices"), "frames": board["frames"],
            "crc_errors": board["crc"], "gaps": board["seq_gaps"],
            "lost_frames": board["lost_frames"], "garbage": board["garbage"],
            "stale_readings": c.get("stale_readings", 0),
            "untrusted_periods": c.get("untrusted_periods", 0),
            "peltier_commands": c.get("peltier", {}).get("sent"),
            "peltier_statuses": c.get("peltier", {}).get("statuses")}


def touch_said(s: dict) -> str:
    """What the demo's line says the slave said: the label; an "unknown"
    with why; a new material with its estimate and nearest class."""
    if Label(s["identified"]).is_new and s.get("decision_text"):
        return s["decision_text"]
    return s["identified"] if s["unknown_reason"] is None else \
        f"{s['identified']} ({s['unknown_reason']})"


def decided_alike(a: dict, b: dict) -> bool:
    """Two summaries of a touch decided the same label at the same times."""
    return all(a.get(k) == b.get(k) for k in DECISION_KEYS)


def same_decision(networked: dict, local: dict) -> str:
    """The in-process touch's decision against the networked one's, as the
    demo's line says it: "the same decision" when the label and its time
    are equal, else what the in-process slave decided."""
    if decided_alike(networked, local):
        return "the same decision"
    when = when_decided(local) or "never"
    return f"decided {local['identified']} {when}"


def demo_touch(scene, material, ports, seed, contact_s, out, identifier, generator,
                again: bool, echo, display_cal=None, remembered=None,
                slave_sensors=None, rate_hz: float = DEFAULT_RATE_HZ) -> tuple[dict, object]:
    """One touch of the demo over the network, beside the same touch in one
    process; prints its line and returns its summary and the in-process
    slave's decision. ``remembered``: what the in-process slave's memory
    holds of the object (an earlier in-process touch's decision), as the
    networked slave's memory holds its own for a repeated touch.
    ``slave_sensors``: the slave service's instruments and calibration
    (:func:`~telethermal.sim.inprocess.service_sensors`), so the in-process
    slave makes the service's touch of the seed. ``rate_hz``: the master's
    display rate (its config's), the in-process touch's too."""
    from telethermal.sim.inprocess import run_session
    from telethermal.teleop.display_config import DisplayConfig

    result = networked_touch(scene, material, ports[:4], seed, contact_s)
    s = result.summary
    name = f"{material}-again" if again else material
    plot_session(result, out / f"touch-{name}.png",       # its errors: plots.error_windows
                 f"{scene.name}: {material}{' again' if again else ''} over the network (two "
                 "processes)")
    local_result = run_session(scene, material, identifier, generator,
                               DisplayConfig(rate_hz=rate_hz), contact_s=contact_s,
                               seed=seed, display_calibration=display_cal,
                               expected_material=remembered, slave_sensors=slave_sensors)
    local = local_result.summary
    when = when_decided(s) or "never"
    start = "never" if s["render_start_s"] is None else f"{s['render_start_s']:.2f} s"
    memory = "" if s["object_memory"] is None else \
        f"announced from memory as {s['object_memory']}, rendered from {start}; "
    said = touch_said(s)
    echo(f"touch on {material + (' again' if again else ''):16s}: {memory}slave said "
         f"{said} {when}; rendered flux "
         f"{100 * s['flux_rms_error_rel']:.2f} % of peak from the decision on, "
         f"{100 * s['flux_rms_error_rel_first_s']:.2f} % over the first second, "
         f"{100 * s['flux_rms_error_rel_whole']:.2f} % over the whole contact; skin "
         f"{s['temp_rms_error_c']:.2f} K RMS; safety events {s['safety_events']}; "
         f"master loop p99 {s['loop_period_p99_us']:.0f} us, "
         f"{s['loop']['deadline_misses']} missed deadlines (set up in "
         f"{1e3 * s['loop']['setup_s']:.0f} ms before its first period); in one process "
         f"{same_decision(s, local)}, {100 * local['flux_rms_error_rel']:.2f} %")
    return {k: s[k] for k in (
        "material", "identified", "unknown_reason", *EFFUSIVITY_KEYS, "decision_text",
        "decision_time_s", "render_start_s", "object_memory",
        "flux_rms_error_rel", "flux_rms_error_rel_first_s", "flux_rms_error_rel_whole",
        "temp_rms_error_c", "time_to_correct_flux_s", "safety_events", "loop_period_p99_us")} | \
        {"again": again, "deadline_misses": s["loop"]["deadline_misses"],
         "setup_s": s["loop"]["setup_s"],
         "loop_steps": s["loop"]["steps"], "transport": s["transport"],
         "devices": s["devices_per_side"],
         "in_process_identified": local["identified"],
         "in_process_rate_hz": local["rate_hz"],
         "in_process_same_decision": decided_alike(s, local),
         "in_process_decision_time_s": local["decision_time_s"],
         "in_process_render_start_s": local["render_start_s"],
         "in_process_flux_rms_error_rel": local["flux_rms_error_rel"],
         "network_over_in_process": s["flux_rms_error_rel"] / local["flux_rms_error_rel"]}, \
        local_result.slave_estimate
