"""A layer on a semi-infinite base against its closed form (issue 30's
layered object: "a thin object on a metal base").

A layer 0 < x < L (effusivity e1, diffusivity alpha1) on a semi-infinite
base x > L (e2), both at 0, whose surface is held at dT from t = 0. By the
method of images (Carslaw & Jaeger, Conduction of Heat in Solids, 2nd ed.,
1959, the composite solid of a slab on a semi-infinite body under a
constant surface temperature; their ``alpha = (sigma - 1)/(sigma + 1)``,
``sigma = e2/e1``, is ``-g`` here) the surface flux is

    q(t) = e1 dT / sqrt(pi t) [1 + 2 sum_{n>=1} (-g)^n exp(-n^2 L^2 / (alpha1 t))],
    g = (e1 - e2) / (e1 + e2)

(g is the temperature reflection at the interface: a metal base, e2 >> e1,
reflects with g ~ -1, a cold wall, and the flux grows). The sign is checked
here rather than trusted: the series tends to e2/e1 as t grows (the base
alone) and to 1 as t -> 0 (the layer alone). Its integral, the heat that
entered by t, uses int_0^t exp(-a/s) / sqrt(pi s) ds = 2 sqrt(t/pi)
exp(-a/t) - 2 sqrt(a) erfc(sqrt(a/t)).

The configuration closest to a held surface the solver allows: side a a
10 um copper film whose back is held (isothermal) at dT, in perfect
contact (conductance inf) with the object; the film's resistance (2.5e-8
m^2 K/W) moves the flux by under 5e-5 of it at 0.05 s, its heat capacity
settles in microseconds. The model is the one the scenes use
(:func:`~telethermal.physics.model.choose_model`, tolerance 1e-3); the
tolerance is twice its own spatial error estimate (``error_bound_rel``,
below 1e-3 by construction): that estimate is Richardson's leading term
(4/3 of the distance to a grid refined twice), not a bound.
"""

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import erfc

from telethermal.physics.layered import Boundary, Layer
from telethermal.physics.materials import get_material as mat
from telethermal.physics.model import choose_model

GAP_K = 10.0
T_S = np.geomspace(0.05, 3.0, 120)
TOLERANCE_REL = 1e-3
TERMS = 400          # (-g)^n exp(-n^2 a/t): below 1e-12 of the first term well before n = 400


def _series(m1: str, thickness_m: float, m2: str, t_s, term):
    e1, e2 = mat(m1).effusivity, mat(m2).effusivity
    g = (e1 - e2) / (e1 + e2)
    n = np.arange(1, TERMS + 1)[:, None]
    a = n ** 2 * thickness_m ** 2 / mat(m1).diffusivity_m2_s
    return e1, (((-g) ** n) * term(a, np.asarray(t_s, float)[None, :])).sum(axis=0)


def layer_flux_w_m2(m1, thickness_m, m2, t_s, gap_k=GAP_K):
    """The image series' surface flux, W/m^2."""
    e1, s = _series(m1, thickness_m, m2, t_s, lambda a, t: np.exp(-a / t))
    return e1 * gap_k / np.sqrt(np.pi * t_s) * (1.0 + 2.0 * s)


def layer_heat_j_m2(m1, thickness_m, m2, t_s, gap_k=GAP_K):
    """The heat that entered the surface by ``t_s``, J/m^2."""
    e1, s = _series(m1, thickness_m, m2, t_s, lambda a, t: 2 * np.sqrt(t / np.pi) * np.exp(
        -a / t) - 2 * np.sqrt(a) * erfc(np.sqrt(a / t)))
    return e1 * gap_k * (2.0 * np.sqrt(t_s / np.pi) + 2.0 * s)


def held_surface_on(m1, thickness_m, m2):
    side_a = [Layer(mat("copper"), 1e-5)]
    side_b = [Layer(mat(m1), thickness_m), Layer(mat(m2), math.inf)]
    return choose_model(side_a, side_b, Boundary("isothermal"), Boundary("adiabatic"),
                        float(T_S[0]), float(T_S[-1]), TOLERANCE_REL, math.inf)


def test_the_series_sign_gives_the_layer_early_and_the_base_late():
    e1, e2 = mat("plexiglass").effusivity, mat("aluminium").effusivity

    def ratio(thickness_m, t_s):
        q = layer_flux_w_m2("plexiglass", thickness_m, "aluminium", np.array([t_s]))[0]
        return q * np.sqrt(np.pi * t_s) / (e1 * GAP_K)

    assert ratio(1e-3, 0.05) == pytest.approx(1.0, abs=1e-12)    # exp(-178): the layer
    assert ratio(0.0, 1.0) == pytest.approx(e2 / e1, rel=1e-9)   # L^2/(alpha t) -> 0: the base
    # and the heat is the flux's integral (by quadrature in u = sqrt(t), where
    # the integrand 2 u q(u^2) is smooth)
    heat, _ = quad(lambda u: 2 * u * layer_flux_w_m2("glass", 1e-3, "aluminium",
                                                     np.array([max(u, 1e-12) ** 2]))[0],
                   0.0, math.sqrt(3.0), epsabs=0.0, epsrel=1e-10, limit=200)
    assert heat == pytest.approx(layer_heat_j_m2("glass", 1e-3, "aluminium", np.array([3.0]))[0],
                                 rel=1e-8)


# 1 mm acrylic on aluminium (the base felt after L^2/alpha1 = 8.9 s: 10 % by 3 s);
# 0.2 mm of it (0.36 s: the base's within the window); a 1 mm glass slide on
# aluminium (1.3 s); and a base of lower effusivity (g > 0: the series alternates).
@pytest.mark.parametrize("m1,thickness_m,m2", [
    ("plexiglass", 1e-3, "aluminium"), ("plexiglass", 2e-4, "aluminium"),
    ("glass", 1e-3, "aluminium"), ("marble", 1e-3, "wood")])
def test_a_layer_on_a_base_matches_the_image_series(m1, thickness_m, m2):
    model, choice = held_surface_on(m1, thickness_m, m2)
    assert choice.kind == "layered" and choice.error_bound_rel <= TOLERANCE_REL
    out = model.solve(np.concatenate([[0.0], T_S]), GAP_K, 0.0, math.inf, energy=True)
    flux = out.flux_w_m2[0, 1:]
    exact = layer_flux_w_m2(m1, thickness_m, m2, T_S)
    tol = 2.0 * choice.error_bound_rel
    np.testing.assert_allclose(flux, exact, rtol=tol)
    # the layer matters here: the flux is not the layer's alone by the end
    alone = mat(m1).effusivity * GAP_K / np.sqrt(np.pi * T_S[-1])
    assert abs(exact[-1] / alone - 1) > 10 * tol
    # heat: what crossed into the object is the series' integral (to the same
    # tolerance: a flux error of tol integrates to at most tol), and what
    # entered the back faces is what the two sides store (conservation)
    crossed = out.energy_into_b_j_m2[0, -1]
    assert crossed == pytest.approx(layer_heat_j_m2(m1, thickness_m, m2, T_S[-1:])[0], rel=tol)
    assert out.heat_balance_error()[0] < 1e-6
