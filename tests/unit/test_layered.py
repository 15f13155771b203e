"""The layered solver against closed forms and conservation laws."""

import math

import numpy as np
import pytest

from telethermal.errors import ModelError
from telethermal.physics.contact import contact_flux_w_m2, contact_surface_temps_c
from telethermal.physics.layered import Boundary, Layer, LayeredContact, crank_nicolson
from telethermal.physics.materials import get_material as mat

ADIABATIC = Boundary()


def semi_infinite(a, b, t_min=0.05, t_max=60.0, **kw):
    return LayeredContact([Layer(mat(a), math.inf)], [Layer(mat(b), math.inf)],
                          ADIABATIC, ADIABATIC, t_min, t_max, **kw)


def pad_stack(grease_m=2e-5):
    return [Layer(mat("flux_sensor_film"), 3e-4), Layer(mat("thermal_grease"), grease_m),
            Layer(mat("alumina"), 2.5e-4)]


# The default grid (first cell 0.1 sqrt(alpha t_min), growth 1.15) is second
# order in space; its measured error against the closed form is 1.3e-3, so
# 2e-3 is the tolerance for "agrees with the closed form".
GRID_TOL = 2e-3


@pytest.mark.parametrize("a,b,h", [("skin", "aluminium", math.inf), ("skin", "wood", 5000.0),
                                   ("aluminium", "foam", math.inf), ("copper", "wood", 2000.0)])
def test_flux_matches_closed_form_over_a_minute(a, b, h):
    t = np.geomspace(0.05, 60.0, 300)
    q = semi_infinite(a, b).solve(t, 34.0, 24.0, h).flux_w_m2[0]
    exact = contact_flux_w_m2(t, 34.0, 24.0, mat(a).effusivity, mat(b).effusivity, h)
    np.testing.assert_allclose(q, exact, rtol=GRID_TOL)


def test_surface_temperatures_match_closed_form():
    t = np.geomspace(0.05, 60.0, 100)
    out = semi_infinite("skin", "glass").solve(t, 33.0, 24.0, 4000.0)
    ta, tb = contact_surface_temps_c(t, 33.0, 24.0, mat("skin").effusivity,
                                     mat("glass").effusivity, 4000.0)
    # Temperatures relative to the 9 K gap: same grid tolerance.
    np.testing.assert_allclose(out.surface_temp_a_c[0], ta, atol=9.0 * GRID_TOL)
    np.testing.assert_allclose(out.surface_temp_b_c[0], tb, atol=9.0 * GRID_TOL)


def test_heat_balance_over_sixty_seconds():
    # Energy in through the back faces = change of stored heat (to 1e-6),
    # with a held junction behind the pad and a room-coupled object.
    model = LayeredContact(pad_stack(), [Layer(mat("aluminium"), 0.02)],
                           Boundary("isothermal"), Boundary("convective", 24.0, 10.0), 0.01, 60.0)
    out = model.solve(np.linspace(0, 60, 601), 34.0, 26.0, 3000.0, energy=True)
    assert out.heat_balance_error()[0] < 1e-6
    assert out.energy_in_j_m2[0, -1] > 0  # heat did flow: the check is not vacuous


def test_heat_crossing_the_contact_is_what_the_object_stored():
    # Object with an adiabatic back: all heat that crossed the contact is in it.
    model = LayeredContact(pad_stack(), [Layer(mat("glass"), 0.01)], Boundary("isothermal"),
                           ADIABATIC, 0.01, 10.0)
    t = np.linspace(0, 10, 201)
    out = model.solve(t, 34.0, 24.0, 3000.0, energy=True)
    # Stored in b = total stored - stored in a; total = inflow at a's back.
    rho_c = mat("glass").volumetric_heat_j_m3k
    # At the end the object has warmed; its mean temperature rise times
    # rho c L equals the heat that crossed (to the same 1e-6).
    crossed = out.energy_into_b_j_m2[0, -1]
    assert crossed > 0
    assert abs(out.energy_in_j_m2[0, -1] - out.energy_stored_j_m2[0, -1]) < 1e-6 * crossed
    assert crossed < rho_c * 0.01 * 10.0  # cannot exceed warming the whole slab by the gap


def test_steady_state_is_series_resistance():
    # Isothermal backs on both sides: q_inf = gap / (sum L/k + 1/h).
    stack = pad_stack()
    glass = Layer(mat("glass"), 2e-3)
    h = 2500.0
    model = LayeredContact(stack, [glass], Boundary("isothermal"), Boundary("isothermal"),
                           0.01, 2000.0)
    q = model.solve(np.array([2000.0]), 34.0, 24.0, h).flux_w_m2[0, 0]
    resistance = sum(la.thickness_m / la.material.conductivity_w_mk for la in stack + [glass])
    assert q == pytest.approx(10.0 / (resistance + 1.0 / h), rel=1e-6)


@pytest.mark.parametrize("a,b", [("aluminium", "foam"), ("copper", "wood"), ("aluminium", "wood")])
def test_high_contrast_at_coarse_steps_has_no_oscillation(a, b):
    # Contrast of effusivity over 10^3 (aluminium|foam ~ 530x in e, 6e5 in k):
    # sampled once a second, the flux must fall monotonically and stay
    # positive, and the surface must stay between the two initial temperatures.
    t = np.arange(1.0, 61.0)
    out = semi_infinite(a, b, t_min=1.0).solve(t, 34.0, 24.0)
    q = out.flux_w_m2[0]
    assert np.all(q > 0) and np.all(np.diff(q) < 0)
    for surface in (out.surface_temp_a_c[0], out.surface_temp_b_c[0]):
        assert np.all((surface >= 24.0) & (surface <= 34.0))


def test_the_oscillation_check_catches_crank_nicolson():
    # The same check fails for plain Crank-Nicolson at that coarse step
    # (stiff modes flip sign each step), which is why the solver integrates
    # modes exactly instead.
    model = semi_infinite("aluminium", "foam", t_min=1e-3)
    _, q = crank_nicolson(model, 1.0, 60, 34.0, 24.0, damped_steps=0)
    assert np.any(np.diff(q) > 0) or np.any(q <= 0)


def test_zero_gap_is_exactly_zero():
    model = LayeredContact(pad_stack(), [Layer(mat("wood"), 0.02)], Boundary("isothermal"),
                           Boundary("convective", 30.0, 10.0), 0.01, 10.0)
    out = model.solve(np.linspace(-1, 10, 50), 30.0, 30.0, 3000.0, sensor_lag_s=0.15, energy=True)
    assert np.all(out.flux_w_m2 == 0.0) and np.all(out.flux_sensed_w_m2 == 0.0)
    assert np.all(out.surface_temp_a_c == 30.0)
    assert np.isfinite(out.heat_balance_error()).all()


def test_a_20_micron_layer_is_resolved():
    # Splitting a layer into a 20 um layer and the rest of the same material
    # changes nothing physical: the flux agrees to the grid tolerance.
    alumina = mat("alumina")
    whole = [Layer(mat("flux_sensor_film"), 3e-4), Layer(alumina, 2.7e-4)]
    split = [Layer(mat("flux_sensor_film"), 3e-4), Layer(alumina, 2e-5), Layer(alumina, 2.5e-4)]
    t = np.geomspace(0.01, 5.0, 100)
    runs = [LayeredContact(s, [Layer(mat("glass"), 0.02)], Boundary("isothermal"), ADIABATIC,
                           0.01, 5.0).solve(t, 34.0, 24.0, 3000.0).flux_w_m2[0] for s in (whole, split)]
    np.testing.assert_allclose(runs[1], runs[0], rtol=GRID_TOL)
    # And the grease layer itself has at least three cells.
    model = LayeredContact(pad_stack(), [Layer(mat("glass"), 0.02)], Boundary("isothermal"),
                           ADIABATIC, 0.01, 5.0)
    grease = [i for i, la in enumerate(model.grid.layers) if la.material.name == "thermal_grease"]
    assert np.sum(model.grid.layer_of_cell == grease[0]) >= 3


def test_ten_minute_run_matches_closed_form():
    t = np.geomspace(0.05, 600.0, 200)
    q = semi_infinite("skin", "wood", t_max=600.0).solve(t, 33.0, 24.0, 5000.0).flux_w_m2[0]
    exact = contact_flux_w_m2(t, 33.0, 24.0, mat("skin").effusivity, mat("wood").effusivity, 5000.0)
    assert np.all(np.isfinite(q))
    np.testing.assert_allclose(q, exact, rtol=GRID_TOL)


def test_float32_input_gives_float64_output_of_same_value():
    model = semi_infinite("skin", "marble", t_max=5.0)
    t64 = np.geomspace(0.05, 5.0, 50)
    t32 = t64.astype(np.float32)
    a = model.solve(t32, np.float32(33.0), np.float32(24.0), np.float32(4000.0))
    b = model.solve(t32.astype(np.float64), 33.0, 24.0, 4000.0)
    assert a.flux_w_m2.dtype == np.float64
    # Same float32 times on both sides: identical results; float32 only
    # perturbs the inputs by its 6e-8 rounding.
    np.testing.assert_allclose(a.flux_w_m2, b.flux_w_m2, rtol=1e-12)


def test_sensor_lag_is_exact():
    # Against a 100 kHz trapezoidal integration of dy/dt = (q - y)/tau.
    model = LayeredContact([Layer(mat("flux_sensor_film"), 3e-4), Layer(mat("alumina"), 2e-4)],
                           [Layer(mat("glass"), 0.02)], Boundary("isothermal"), ADIABATIC, 1e-4, 1.0)
    dt, tau = 1e-5, 0.15
    t = np.arange(0.0, 1.0, dt)
    out = model.solve(t, 34.0, 24.0, 3000.0, sensor_lag_s=tau)
    q = out.flux_w_m2[0]
    a = dt / (2 * tau)
    y = np.zeros_like(q)
    for k in range(1, len(q)):
        y[k] = (y[k - 1] * (1 - a) + a * (q[k] + q[k - 1])) / (1 + a)
    # Trapezoid error (dt/tau)^2 and the first-step start: under 1e-5 of the peak.
    assert np.max(np.abs(y - out.flux_sensed_w_m2[0])) < 1e-5 * np.abs(q).max()


def test_per_trial_times_and_parameters_batch():
    model = semi_infinite("skin", "wood", t_max=2.0)
    t = np.stack([np.linspace(0.1, 2, 20), np.linspace(0.2, 2.1, 20)])
    batch = model.solve(t, [33.0, 30.0], 24.0, [3000.0, 6000.0])
    for i, (ta, h) in enumerate([(33.0, 3000.0), (30.0, 6000.0)]):
        single = model.solve(t[i], ta, 24.0, h)
        np.testing.assert_allclose(batch.flux_w_m2[i], single.flux_w_m2[0], rtol=1e-12)


@pytest.mark.parametrize("kwargs", [dict(temp_a_c=np.nan), dict(conductance_w_m2k=0.0),
                                    dict(sensor_lag_s=-1.0), dict(k_scale_a=0.0)])
def test_bad_inputs_raise(kwargs):
    args = dict(temp_a_c=33.0, temp_b_c=24.0)
    args.update(kwargs)
    with pytest.raises(ModelError):
        semi_infinite("skin", "wood", t_max=1.0).solve(np.array([0.1]), **args)


def test_bad_layers_and_grids_raise():
    with pytest.raises(ModelError):
        Layer(mat("wood"), 0.0)
    with pytest.raises(ModelError):
        LayeredContact([Layer(mat("wood"), math.inf), Layer(mat("glass"), 1e-3)],
                       [Layer(mat("glass"), 1e-3)], ADIABATIC, ADIABATIC, 0.01, 1.0)
    with pytest.raises(ModelError):
        semi_infinite("skin", "wood", t_min=2.0, t_max=1.0)
