"""The display plant, stepped, against the batch solver's exact solution."""

import math

import numpy as np
import pytest

from telethermal.sim.plant import DisplayPlant
from telethermal.errors import ControlError
from telethermal.physics.layered import Boundary, Layer, LayeredContact
from telethermal.physics.materials import get_material as mat


def display(t_max=2.0):
    pad = [Layer(mat("flux_sensor_film"), 3e-4), Layer(mat("thermal_grease"), 2e-5),
           Layer(mat("alumina"), 2.5e-4)]
    return LayeredContact(pad, [Layer(mat("skin"), math.inf)], Boundary("isothermal"),
                          Boundary(), 1e-3, t_max)


@pytest.mark.parametrize("junction", [34.0, 28.0])
def test_stepping_reproduces_the_exact_solution(junction):
    # Junction held at `junction` from contact on; the batch solver's answer
    # for the same held back face is exact, so the two agree to rounding.
    model, dt = display(), 1e-3
    plant = DisplayPlant(model, 34.0, 31.0, 3000.0, dt, sensor_lag_s=0.15)
    readings = [plant.step(junction) for _ in range(2000)]
    t = dt * np.arange(1, 2001)
    ref = model.solve(t, 34.0, 31.0, 3000.0, back_temp_a_c=junction, sensor_lag_s=0.15)
    scale = np.abs(ref.flux_w_m2).max()
    np.testing.assert_allclose([r.contact_flux_w_m2 for r in readings], ref.flux_w_m2[0],
                               atol=1e-9 * scale)
    np.testing.assert_allclose([r.flux_w_m2 for r in readings], ref.flux_sensed_w_m2[0],
                               atol=1e-9 * scale)
    np.testing.assert_allclose([r.skin_surface_c for r in readings], ref.surface_temp_b_c[0],
                               atol=1e-9)


def test_no_gap_and_junction_at_the_same_temperature_is_still():
    plant = DisplayPlant(display(), 32.0, 32.0, 3000.0, 1e-2, sensor_lag_s=0.15)
    for _ in range(50):
        r = plant.step(32.0)
    assert r.contact_flux_w_m2 == 0.0 and r.flux_w_m2 == 0.0 and r.skin_surface_c == 32.0


def test_bad_inputs_are_refused():
    with pytest.raises(ControlError):
        DisplayPlant(display(), 34.0, 31.0, 3000.0, 0.0)
    with pytest.raises(ControlError):
        DisplayPlant(display(), 34.0, 31.0, 3000.0, 1e-3).step(math.nan)
