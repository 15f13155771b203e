"""The in-process session's figures against the same finger touching the
object directly (the metrics every touch reports: in process, on the
simulated network and on the services)."""

from __future__ import annotations

import math
from dataclasses import fields, replace

import numpy as np

from telethermal.physics.scene import Scene, finger_contact_model

#: Rendered flux within this fraction of the direct-contact peak counts as correct.
CORRECT_WITHIN = 0.10


def _drop_first(result):
    """A contact result without its first time (the arrays' last axis)."""
    return replace(result, **{f.name: getattr(result, f.name)[..., 1:] for f in fields(result)
                              if isinstance(getattr(result, f.name), np.ndarray)})


def compare_with_direct(scene: Scene, material: str, object_true_c: float, operator,
                        trace: dict, contact_s: float, render_from_s: float | None) -> dict:
    """The issue's metrics against the same finger (``operator``, a
    :class:`~telethermal.sim.touch.Operator`) touching the object directly;
    adds the direct-contact curves to ``trace``."""
    obj = next(o for o in scene.objects if o.name == material)
    t = trace["t_s"]
    during = (t >= 0) & (t < contact_s)
    finger_model, _ = finger_contact_model(scene, obj)
    tc = t[during]
    # The simulated finger meets the pad at the first period at or after
    # t = 0 (exactly 0 on the simulated clock, up to a period later on the
    # real one): the direct contact is timed from there. Solved at that
    # instant too: the peak the errors are relative to is the direct
    # contact's own (largest at 0+, falling within a millisecond), not
    # wherever a period happened to land (on the real clock: 30 % lower).
    touched = float(tc[0]) if len(tc) else 0.0
    ref = finger_model.solve(np.concatenate([[1e-9], np.clip(tc - touched, 1e-9, None)]),
                             operator.finger_c, object_true_c,
                             operator.conductance_w_m2k, k_scale_a=operator.skin_k_scale,
                             heat_scale_a=operator.skin_heat_scale,
                             sensor_lag_s=scene.sensors.flux_lag_s)
    # Direct contact: the finger loses q to the object; the display must give -q.
    peak = float(np.max(np.abs(ref.flux_w_m2[0])))
    ref = _drop_first(ref)
    direct = -ref.flux_w_m2[0]
    for key, values in (("direct_flux_w_m2", direct),
                        ("direct_flux_sensed_w_m2", -ref.flux_sensed_w_m2[0]),
                        ("direct_skin_c", ref.surface_temp_a_c[0])):
        trace[key] = np.full(len(t), np.nan)
        trace[key][during] = values
    err = trace["flux_w_m2"][during] - direct
    window = tc >= render_from_s if render_from_s is not None else np.ones(len(tc), bool)

    def rms_rel(mask):
        return float(np.sqrt(np.mean(err[mask] ** 2)) / peak) if mask.any() and peak > 0 \
            else math.nan

    bad = np.abs(err) > CORRECT_WITHIN * peak
    correct_from = float(tc[np.nonzero(bad)[0][-1] + 1]) if bad.any() and not bad[-1] else \
        (float(tc[0]) if not bad.any() else math.nan)
    return {"direct_peak_flux_w_m2": peak,
            "flux_rms_error_rel": rms_rel(window),
            "flux_rms_error_rel_first_s": rms_rel(tc < 1.0),
            "flux_rms_error_rel_whole": rms_rel(np.ones(len(tc), bool)),
            "temp_rms_error_c": float(np.sqrt(np.nanmean(
                (trace["skin_surface_c"][during] - ref.surface_temp_a_c[0]) ** 2))),
            "time_to_correct_flux_s": correct_from, "correct_within_rel": CORRECT_WITHIN}
