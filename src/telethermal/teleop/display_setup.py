"""How every driver sets up its display and reports on it: where the pad
idles before a touch and the pre-conditioning it keeps applying (the idle
policy, :mod:`telethermal.control.preconditioning`), and the summaries of
the module's limits and of the safety events over a touch; what the
display's skin controller knows of the display (:func:`display_model_args`). The in-process
run, the services and the simulated network all call these."""

from __future__ import annotations

import math

from telethermal.control.safety import safety_event_count
from telethermal.physics.scene import Scene
from telethermal.teleop.master import DisplayConfig, MasterDisplay


def display_model_args(scene: Scene) -> dict:
    """What the display's skin controller knows of the display: the pad's
    layers and the nominal pad-fingertip contact conductance."""
    return {"pad_layers": tuple(scene.pad.layers),
            "contact_conductance_w_m2k": scene.finger.contact_conductance_w_m2k,
            "module": scene.pad.module_params()[0], "pad_area_m2": scene.pad.area_m2}


def precondition_for(scene: Scene, finger_c: float):
    """The display's pre-conditioning for this scene and operator:
    ``f(material or None, object_temp_c) -> idle offset from the object, K``."""
    from telethermal.control.preconditioning import policy_fractions, precondition_from
    return precondition_from(policy_fractions(scene), finger_c)


def display_idle(scene: Scene, config: DisplayConfig, finger_c: float,
                 object_temp_c: float | None, expected_material: str | None = None):
    """Where the display's pad idles before a touch, and the pre-conditioning
    the display keeps applying (``MasterDisplay(precondition=...)``): with
    ``config.idle`` "policy" the object's temperature shifted by the scene's
    idle policy for ``expected_material`` (None: an unknown object, the
    minimax idle); "object": the object's temperature. Every driver (the
    in-process run, the services, the simulated network) starts its display
    here. Returns (idle C, precondition or None)."""
    shift = precondition_for(scene, finger_c) if config.idle == "policy" else None
    obj = object_temp_c
    if shift is not None and obj is not None and math.isfinite(obj):
        obj = obj + shift(expected_material, obj)
    return MasterDisplay.standby_c_for(config.limits, obj), shift


def module_summary(touch, master: MasterDisplay) -> dict:
    """The display's module over the touch: its datasheet limits never
    exceeded (counted), how close it came, how often the current saturated
    (``touch``: a :class:`~telethermal.teleop.run.DisplayTouch`)."""
    spec = touch.module.spec
    loop = master.junction_loop
    return {"name": spec.name, **touch.limit_counts,
            "max_current_a": round(touch.max_current_a, 4), "imax_a": spec.imax_a,
            "max_hot_c": round(touch.max_hot_c, 3), "hot_side_max_c": spec.hot_side_max_c,
            "max_sink_c": round(touch.max_sink_c, 3),
            "saturated_periods": loop.saturated_periods if loop is not None else 0}


def safety_summary(master: MasterDisplay) -> dict:
    events = dict(master.safety.events)
    return {"safety_events": safety_event_count(events), "safety_event_counts": events,
            "display_event_counts": dict(master.events)}
