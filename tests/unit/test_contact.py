"""The closed forms of a two-body contact (active-heat-flow-sensing eq. 8-10,
extended with a contact conductance)."""

import math

import numpy as np
import pytest

from telethermal.errors import ModelError
from telethermal.physics.contact import (contact_flux_sensed_w_m2, contact_flux_w_m2,
                                         contact_surface_temps_c,
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


@pytest.mark.parametrize("h", [5000.0, math.inf])
def test_the_sensed_closed_form_is_the_lag_of_the_closed_form(h):
    # The lag's convolution integral of contact_flux_w_m2, by adaptive
    # quadrature (tolerance ~1e-10), against the partial-fraction closed form:
    # within 1e-8 relative (measured <= 4e-10, at 3 s where the quadrature
    # is least sure). Starts at 0, tends to the unlagged flux late.
    from scipy.integrate import quad

    tau, e_glass = 0.15, 1400.0
    for t in (0.01, 0.1, 0.5, 1.0, 3.0, 20.0):
        def integrand(u):
            q = contact_flux_w_m2(np.array([u]), 10.0, 0.0, E_SKIN, e_glass, h)[0]
            return q * math.exp(-(t - u) / tau) / tau
        ref = quad(integrand, 0.0, t, limit=400)[0]
        got = contact_flux_sensed_w_m2(np.array([t]), 10.0, 0.0, E_SKIN, e_glass, h, tau)[0]
        assert got == pytest.approx(ref, rel=1e-8)
    early = contact_flux_sensed_w_m2(np.array([-1.0, 0.0, 1e-9]), 10.0, 0.0, E_SKIN, e_glass, h,
                                     tau)
    assert early[0] == 0.0 and early[1] == 0.0
    # Just after contact the sensor integrates q / tau: h gap t / tau, or
    # 2 gap e_eff sqrt(t) / (sqrt(pi) tau) for a perfect contact (leading order).
    e_eff = E_SKIN * e_glass / (E_SKIN + e_glass)
    leading = 10.0 * (h * 1e-9 if math.isfinite(h) else 2 * e_eff * math.sqrt(1e-9 / math.pi))
    assert early[2] == pytest.approx(leading / tau, rel=1e-3)
    late = np.array([200.0])
    # Late, the lag is a delay of tau on a 1/sqrt(t) tail: 1 + tau/(2 t) to first order.
    ratio = contact_flux_sensed_w_m2(late, 10.0, 0.0, E_SKIN, e_glass, h, tau) / \
        contact_flux_w_m2(late, 10.0, 0.0, E_SKIN, e_glass, h)
    assert ratio[0] == pytest.approx(1.0 + tau / (2 * 200.0), abs=1e-5)
    with pytest.raises(ModelError, match="sensor_lag_s"):
        contact_flux_sensed_w_m2(late, 10.0, 0.0, E_SKIN, e_glass, h, -1.0)
