"""Model selection and the closed-form contact model with a sensor lag."""

import math

import numpy as np
import pytest

from telethermal.errors import ModelError
from telethermal.physics.layered import Boundary, Layer, LayeredContact
from telethermal.physics.materials import get_material as mat
from telethermal.physics.model import AnalyticContact, choose_model, first_order_lag

TAU = 0.15


def test_first_order_lag_of_a_step_and_a_ramp_on_a_non_uniform_grid():
    # Closed forms: lag(1) = 1 - exp(-t/tau); lag(t) = t - tau (1 - exp(-t/tau)).
    t = np.concatenate([[0.0], np.geomspace(1e-6, 400.0, 3000)])   # crosses block limits
    step = first_order_lag(t, np.ones_like(t)[None], TAU)[0]
    ramp = first_order_lag(t, t[None], TAU)[0]
    np.testing.assert_allclose(step, -np.expm1(-t / TAU), atol=1e-12)
    np.testing.assert_allclose(ramp, t + TAU * np.expm1(-t / TAU), atol=1e-10 * t.max())


def test_first_order_lag_needs_increasing_times():
    with pytest.raises(ModelError):
        first_order_lag(np.array([0.0, 1.0, 1.0]), np.ones((1, 3)), TAU)


@pytest.mark.parametrize("obj", ["aluminium", "wood"])
def test_closed_form_and_layered_agree_on_the_lagged_sensor(obj):
    # Two independent exact lags (first-order hold on the closed form; mode by
    # mode on the layered grid): agree to the layered grid's error, 2e-3.
    t = np.arange(-0.2, 5.0, 0.001)
    args = (t, 33.0, 24.0, 4000.0)
    a = AnalyticContact(mat("skin"), mat(obj)).solve(*args, sensor_lag_s=TAU)
    lay = LayeredContact([Layer(mat("skin"), math.inf)], [Layer(mat(obj), math.inf)],
                         Boundary(), Boundary(), 1e-3, 5.0).solve(*args, sensor_lag_s=TAU)
    late = t >= 0.05
    peak = np.abs(lay.flux_sensed_w_m2).max()
    assert np.max(np.abs(a.flux_sensed_w_m2 - lay.flux_sensed_w_m2)[:, late]) < 2e-3 * peak
    assert np.all(a.flux_sensed_w_m2[:, t <= 0] == 0.0)


def test_a_perfect_contact_with_a_lag_needs_the_layered_model():
    with pytest.raises(ModelError, match="layered"):
        AnalyticContact(mat("skin"), mat("wood")).solve(np.array([0.1]), 33.0, 24.0,
                                                        math.inf, sensor_lag_s=TAU)


def test_choice_is_cached_and_stacked_layers_go_layered():
    side_a = (Layer(mat("flux_sensor_film"), 3e-4), Layer(mat("alumina"), 2.5e-4))
    side_b = (Layer(mat("glass"), 0.02),)
    first = choose_model(side_a, side_b, Boundary("isothermal"), Boundary(), 0.01, 1.0)
    again = choose_model(list(side_a), list(side_b), Boundary("isothermal"), Boundary(), 0.01, 1.0)
    assert first[0] is again[0]
    assert first[1].kind == "layered" and first[1].n_cells > 0


def test_bad_tolerance_is_refused():
    with pytest.raises(ModelError):
        choose_model([Layer(mat("skin"), math.inf)], [Layer(mat("wood"), math.inf)],
                     Boundary(), Boundary(), 0.01, 1.0, tolerance_rel=0.0)
