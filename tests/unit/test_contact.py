"""The closed forms of a two-body contact (active-heat-flow-sensing eq. 8-10,
extended with a contact conductance)."""

import math

import numpy as np
import pytest

from telethermal.errors import ModelError
from telethermal.physics.contact import (contact_flux_w_m2, contact_surface_temps_c,
                                         contact_temperature_c, semi_infinite_error_bound)
from telethermal.physics.materials import get_material

E_SKIN = get_material("skin").effusivity
E_AL = get_material("aluminium").effusivity
T = np.geomspace(1e-3, 100.0, 400)


def test_contact_temperature_is_effusivity_weighted_mean():
    # eq. (10); and eq. (14): with T_g = T_o + gap the surface sits gap/(1+e_o/e_g) above T_o.
    ts = contact_temperature_c(44.0, 34.0, E_SKIN, E_AL)
    assert ts == pytest.approx(34.0 + 10.0 / (1.0 + E_AL / E_SKIN), rel=1e-12)


def test_perfect_contact_flux_decays_as_inverse_sqrt_time():
    q = contact_flux_w_m2(T, 10.0, 0.0, E_SKIN, E_AL)
    e_eff = E_SKIN * E_AL / (E_SKIN + E_AL)
    np.testing.assert_allclose(q * np.sqrt(np.pi * T), 10.0 * e_eff, rtol=1e-12)


def test_finite_conductance_tends_to_perfect_contact():
    # erfcx(z) ~ 1/(z sqrt(pi)) (1 - 1/(2 z^2)): at h = 1e8 and t >= 1 ms the
    # relative difference is below 1/(2 z^2) < 1e-6.
    q_h = contact_flux_w_m2(T, 10.0, 0.0, E_SKIN, E_AL, 1e8)
    q_inf = contact_flux_w_m2(T, 10.0, 0.0, E_SKIN, E_AL, math.inf)
    np.testing.assert_allclose(q_h, q_inf, rtol=1e-6)


def test_finite_conductance_starts_at_h_times_gap():
    q = contact_flux_w_m2(np.array([0.0, 1e-12]), 10.0, 0.0, E_SKIN, E_AL, 2000.0)
    np.testing.assert_allclose(q, 20000.0, rtol=1e-5)


def test_surface_jump_is_flux_over_conductance():
    h = 3000.0
    q = contact_flux_w_m2(T, 33.0, 24.0, E_SKIN, E_AL, h)
    ta, tb = contact_surface_temps_c(T, 33.0, 24.0, E_SKIN, E_AL, h)
    np.testing.assert_allclose(ta - tb, q / h, rtol=1e-10, atol=1e-12)


def test_surface_temperatures_settle_to_eq_10():
    ta, tb = contact_surface_temps_c(np.array([1e9]), 33.0, 24.0, E_SKIN, E_AL, 3000.0)
    ts = contact_temperature_c(33.0, 24.0, E_SKIN, E_AL)
    assert ta[0] == pytest.approx(ts, abs=1e-3) and tb[0] == pytest.approx(ts, abs=1e-3)


def test_zero_gap_gives_exact_zero_and_no_nan():
    q = contact_flux_w_m2(np.array([0.0, 1e-9, 1.0]), 30.0, 30.0, E_SKIN, E_AL)
    assert np.all(q == 0.0)


def test_before_contact_there_is_no_flux():
    assert np.all(contact_flux_w_m2(np.array([-1.0, -1e-6]), 30.0, 20.0, E_SKIN, E_AL) == 0)


@pytest.mark.parametrize("bad", [dict(e_a=0.0), dict(h=0.0), dict(h=-1.0)])
def test_bad_parameters_raise(bad):
    with pytest.raises(ModelError):
        contact_flux_w_m2(T, 1.0, 0.0, bad.get("e_a", E_SKIN), E_AL, bad.get("h", math.inf))


def test_semi_infinite_bound_grows_with_time_and_vanishes_for_inf():
    alpha = get_material("aluminium").diffusivity_m2_s
    assert semi_infinite_error_bound(math.inf, alpha, 60.0) == 0.0
    assert semi_infinite_error_bound(0.03, alpha, 1.0) < semi_infinite_error_bound(0.03, alpha, 60.0)
