"""The direct-contact reference every touch is measured against
(sim/direct.py): timed from when the simulated finger met the pad, and
relative to the direct contact's own peak, whatever the sampling grid."""

import numpy as np
import pytest

from telethermal.physics.scene import finger_contact_model, load_scene, with_finger
from telethermal.sim.direct import compare_with_direct
from telethermal.sim.touch import Operator

SCENE = with_finger(load_scene("fingertip-7"))
OPERATOR = Operator(finger_c=33.0, finger_ir_c=33.0, skin_k_scale=1.0, skin_heat_scale=1.0,
                    force_n=2.0, conductance_w_m2k=5000.0)


def direct_flux(material, t):
    obj = next(o for o in SCENE.objects if o.material == material)
    model, _ = finger_contact_model(SCENE, obj)
    ref = model.solve(np.clip(t, 1e-9, None), OPERATOR.finger_c, 24.0,
                      OPERATOR.conductance_w_m2k, sensor_lag_s=SCENE.sensors.flux_lag_s)
    return -ref.flux_w_m2[0]


@pytest.mark.parametrize("first_s", [0.0, 0.0004, 0.0009])
def test_a_perfect_rendering_is_zero_error_on_any_grid(first_s):
    # A real-clock trace: the first period lands ``first_s`` after t = 0 and
    # the simulated finger touches there. Rendering exactly what the finger
    # would feel from that instant is no error, and the peak is the contact's
    # own (before: the reference ran from t = 0, the peak was the first
    # sample's, and wood on the services measured 2.3 % where 1.1 % was true).
    t = first_s + np.arange(3000) / 1000.0
    trace = {"t_s": t, "flux_w_m2": direct_flux("wood", t - first_s),
             "skin_surface_c": np.full(len(t), 30.0)}
    m = compare_with_direct(SCENE, "wood", 24.0, OPERATOR, trace, 3.0, None)
    assert m["flux_rms_error_rel_whole"] == pytest.approx(0.0, abs=1e-12)
    assert m["direct_peak_flux_w_m2"] == pytest.approx(abs(direct_flux("wood", np.zeros(1))[0]),
                                                       rel=1e-12)
    # A rendering one period late is an error (the check can fail).
    trace["flux_w_m2"] = direct_flux("wood", np.clip(t - first_s - 1e-3, 0, None))
    assert compare_with_direct(SCENE, "wood", 24.0, OPERATOR, trace, 3.0,
                               None)["flux_rms_error_rel_whole"] > 1e-3
