"""How every driver sets up its display and reports on it: where the pad
idles before a touch and the pre-conditioning it keeps applying (the idle
policy, :mod:`telethermal.control.preconditioning`), and the summaries of
the module's limits and of the safety events over a touch; what the
display's skin controller knows of the display (:func:`display_model_args`). The in-process
run, the services and the simulated network all call these."""

from __future__ import annotations

import logging
import math
from dataclasses import asdict, replace

import numpy as np

from telethermal.control.current_quality import ripple_rms_a, sign_reversals
from telethermal.control.dew import DEW_MARGIN_K, idle_floor_c
from telethermal.control.safety import safety_event_count
from telethermal.errors import ControlError
from telethermal.physics.layered import pad_resistance
from telethermal.physics.scene import Scene
from telethermal.teleop.display_config import DisplayConfig, Idle
from telethermal.teleop.master import MasterDisplay

log = logging.getLogger(__name__)


def horizon_scale(calibration=None) -> float:
    """How much longer the impedance controller's horizon is on a display
    whose calibrated face layer is slower than its design: the face layer's
    diffusion time (``L^2 rho c / k``, its thickness factor squared) over the
    design's, never under 1. The horizon (``impedance_horizon_s``) was set
    for the design's film. A rule chosen after seeing, on ``bench render
    --as-built``'s pad 3 (its film fitted 1.66x), the current chatter once
    the layers were modelled (graphite, seed 1: 15 reversals per s, 0.34 A
    of ripple; 1.34 per s with the design's layers), and checked on the
    same five pads and two seeds (bench/results/README.md): stretched 2.76x
    there, 0.67 per s. Not shortened for a faster film: a 0.1 s horizon
    oscillated on the designed pad (docs/display-loop.md), and shortened
    in proportion, pad 0 (0.82x) reversed 3.7 times per s on marble against
    1.7 (seed 1). Exercised up to 2.76; a face layer up to 5x (the fit's
    bound) would stretch it 25x, untested."""
    if calibration is None:
        return 1.0
    return max(1.0, calibration.face_layer_thickness ** 2)


def display_model_args(scene: Scene, calibration=None) -> dict:
    """What the display's skin controller knows of the display, all from the
    configuration: the pad's layers and resistance, the nominal pad-fingertip
    contact conductance, the module, the flux sensor's lag (``[sensors]
    flux_lag_s``) and the junction sensor the scene names with its stated lag
    (``junction_sensor``, ``junction_lag_s``); with ``calibration`` (a
    :class:`~telethermal.teleop.display_calibration.DisplayCalibration`,
    checked against ``scene``) the flux sensor's lag and gain it measured
    and the pad's layers with its face layer's fitted thickness, the
    impedance horizon stretched for it (:func:`horizon_scale`; the junction
    sensor keeps its stated lag: docs/calibration.md).
    ``MasterDisplay(config, generator, finger_temp_c=..., **these)``."""
    from telethermal.teleop.display_calibration import calibrated_lags, calibrated_layers
    flux_lag_s, junction_lag_s = calibrated_lags(scene, calibration)
    layers = calibrated_layers(scene, calibration)
    return {"pad_resistance_m2k_w": pad_resistance(layers),
            "sensor_lag_s": flux_lag_s, "pad_layers": layers,
            "contact_conductance_w_m2k": scene.finger.contact_conductance_w_m2k,
            "module": scene.pad.module_params()[0], "pad_area_m2": scene.pad.area_m2,
            "junction_sensor": replace(scene.sensors.junction_sensor_spec(),
                                       tau_s=junction_lag_s),
            "dew_floor_c": idle_floor_c(scene.room_temp_c, scene.room_humidity_pct),
            "flux_gain": 1.0 if calibration is None else calibration.flux_gain,
            "impedance_horizon_scale": horizon_scale(calibration)}


def precondition_for(scene: Scene, finger_c: float, calibration=None):
    """The display's pre-conditioning for this scene and operator:
    ``f(material or None, object_temp_c) -> idle offset from the object, K``;
    the idle policy searched on the display's layers as ``calibration``
    (the display's, or None) models them."""
    from telethermal.control.preconditioning import policy_fractions, precondition_from
    from telethermal.teleop.display_calibration import modelled_scene
    return precondition_from(policy_fractions(modelled_scene(scene, calibration)), finger_c)


def display_idle(scene: Scene, config: DisplayConfig, finger_c: float,
                 object_temp_c: float | None, expected_material: str | None = None,
                 calibration=None):
    """Where the display's pad idles before a touch, and the pre-conditioning
    the display keeps applying (``MasterDisplay(precondition=...)``): with
    ``config.idle`` "policy" the object's temperature shifted by the scene's
    idle policy for ``expected_material`` (None: an unknown object, the
    minimax idle); "object": the object's temperature. The policy is the
    one of the display's layers as its ``calibration`` models them. Every
    driver (the in-process run, the services, the simulated network) starts
    its display here. Returns (idle C, precondition or None)."""
    shift = precondition_for(scene, finger_c, calibration) \
        if config.idle == Idle.POLICY else None
    obj = object_temp_c
    if shift is not None and obj is not None and math.isfinite(obj):
        obj = obj + shift(expected_material, obj)
    idle = MasterDisplay.standby_c_for(config.limits, obj)
    floor = idle_floor_c(scene.room_temp_c, scene.room_humidity_pct)
    if idle < floor:
        log.info("idle lifted from %.2f C to %.2f C: the dew point of the room (%.1f C, "
                 "%.0f %% RH) plus %.1f K", idle, floor, scene.room_temp_c,
                 scene.room_humidity_pct, DEW_MARGIN_K)
        idle = floor
    return idle, shift


def build_display(scene: Scene, config: DisplayConfig, finger_c: float, heard, *,
                  calibration=None, idle_scene: Scene | None = None,
                  expected_material: str | None = None, idling: bool = True,
                  model: dict | None = None) -> tuple[MasterDisplay, float | None]:
    """The master's display, as every driver builds it (the services, the
    in-process run, the simulated network): its skin controller's model
    from the configuration (:func:`display_model_args` of ``scene`` and the
    display's ``calibration``), the generator the session's link holds, and
    idled before the touch on what the master heard from the slave
    (``heard``, a :class:`~telethermal.teleop.link.SlaveLink`: its
    ``object_temp_c`` and ``expected_material``), pre-conditioned by the
    idle policy of ``idle_scene`` (default ``scene``: the trained
    materials' scene where the touched object is outside them, as a
    deployed master's policy knows only those) (:func:`display_idle`).

    ``expected_material``: the material the display idles for instead of
    what the slave announced (the simulated network's oracle, which knows
    it). ``idling`` False: the display starts in its safe state rather than
    idling (a hardware display whose loop runs before anything is heard).
    ``model``: the controller's model in place of :func:`display_model_args`'s
    (its keys; a bench's oracle, never the services'), given without a
    ``calibration`` (its idle policy: ``idle_scene``'s).
    Returns the display and its idle temperature (C; None when not idling)."""
    if model is None:
        model = display_model_args(scene, calibration)    # checks the calibration first
    elif calibration is not None:
        raise ControlError("build_display: a model given in place of the configured one "
                           "takes no calibration (it would go unchecked, and only pick the "
                           "idle policy)")
    expected = heard.expected_material if expected_material is None else expected_material
    idle_c, shift = display_idle(idle_scene or scene, config, finger_c,
                                 heard.object_temp_c if idling else None, expected,
                                 calibration)
    display = MasterDisplay(config, heard.generator, finger_temp_c=finger_c,
                            idle_c=idle_c if idling else None, precondition=shift, **model)
    return display, (idle_c if idling else None)


def module_summary(touch, master: MasterDisplay) -> dict:
    """The display's module over the touch: its datasheet limits never
    exceeded (counted), how close it came, how often the current saturated
    (``touch``: a :class:`~telethermal.sim.touch.DisplayTouch`)."""
    spec = touch.module.spec
    loop = master.junction_loop
    js = master.junction_sensor          # as the controller was designed for it
    return {"name": spec.name, **touch.limit_counts,
            "max_current_a": round(touch.max_current_a, 4), "imax_a": spec.imax_a,
            "max_hot_c": round(touch.max_hot_c, 3), "hot_side_max_c": spec.hot_side_max_c,
            "max_sink_c": round(touch.max_sink_c, 3),
            "saturated_periods": loop.saturated_periods if loop is not None else 0,
            "junction_stopped_at_s": master.junction_stopped_at_s,
            "junction_sensor": {"name": js.name, "tau_s": js.tau_s, "source": js.source,
                                "true_tau_s": touch.junction_lag_s},
            "requested": asdict(loop.limits) if loop is not None else None,
            "supply_v": loop.driver.supply_v if loop is not None else None,
            "vmax_v": spec.vmax_v, **current_quality(touch)}


#: The module's limits over many sessions (``bench render``'s ``limits``):
#: sums, the largest request, and the totals reversals and ripple pool from.
LIMIT_TOTALS = ("sessions", "current_exceeded", "hot_side_exceeded",
                "current_requested_over_imax_periods", "largest_request_a", "voltage_exceeded",
                "voltage_over_vmax_periods", "reversals", "contact_s", "ripple_sum_sq_a2",
                "ripple_sessions")


def new_limit_totals() -> dict:
    return dict.fromkeys(LIMIT_TOTALS, 0)


def add_limits(totals: dict, module: dict) -> None:
    """Add one session's ``module`` summary to ``totals`` (new_limit_totals)."""
    req = module.get("requested") or {}
    totals["sessions"] += 1
    for key in ("current_exceeded", "hot_side_exceeded", "reversals"):
        totals[key] += int(module[key])
    totals["contact_s"] += module["contact_s"]
    totals["current_requested_over_imax_periods"] += req.get("requested_over_imax_periods", 0)
    totals["voltage_exceeded"] += req.get("voltage_over_supply_periods", 0)
    totals["voltage_over_vmax_periods"] += req.get("voltage_over_vmax_periods", 0)
    totals["largest_request_a"] = max(totals["largest_request_a"],
                                      req.get("largest_request_a", 0.0))
    if math.isfinite(module["ripple_rms_a"]):
        totals["ripple_sum_sq_a2"] += module["ripple_rms_a"] ** 2
        totals["ripple_sessions"] += 1


def limits_report(totals: dict) -> dict:
    """The pooled limits: the sums, reversals per second of contact and the
    ripple's RMS over the sessions that rendered."""
    out = {k: v for k, v in totals.items() if k not in ("ripple_sum_sq_a2", "ripple_sessions")}
    out["reversals_per_s"] = totals["reversals"] / totals["contact_s"] \
        if totals["contact_s"] else 0.0
    out["ripple_rms_a"] = math.sqrt(totals["ripple_sum_sq_a2"] / totals["ripple_sessions"]) \
        if totals["ripple_sessions"] else math.nan
    return out


def current_quality(touch) -> dict:
    """The current's sign reversals per second of contact and its ripple
    while rendering (control/current_quality.py), from the touch's trace."""
    trace, dt = touch.trace, touch.dt_s
    phase = np.array([str(p) for p in trace["phase"]])
    current = trace["current_a"]
    contact = np.isin(phase, ("contact", "render", "link lost")) & np.isfinite(current)
    render = (phase == "render") & np.isfinite(current)
    seconds = contact.sum() * dt
    return {"contact_s": float(seconds),
            "reversals": sign_reversals(current[contact]),
            "reversals_per_s": sign_reversals(current[contact]) / seconds if seconds else 0.0,
            "ripple_rms_a": ripple_rms_a(current[render], dt) if render.any() else math.nan}


def safety_summary(master: MasterDisplay) -> dict:
    events = dict(master.safety.events)
    return {"safety_events": safety_event_count(events), "safety_event_counts": events,
            "display_event_counts": dict(master.events)}
