"""Closed forms for two semi-infinite bodies brought into contact at t = 0.

Body ``a`` (the pad or the finger) starts uniformly at ``temp_a_c``, body ``b``
(the object) at ``temp_b_c``. With a perfect contact the surface temperature
jumps to the effusivity-weighted mean (active-heat-flow-sensing eq. (10)) and
the flux decays as 1/sqrt(t) (eq. (8)-(9)). With an interfacial contact
conductance ``h`` (W/m^2/K) the flux starts finite at ``h * gap`` and, in the
Laplace domain, ``q(s) = h * gap / (sqrt(s) * (sqrt(s) + a))`` with
``a = h * (1/e_a + 1/e_b)``, whose inverse is

    q(t) = h * gap * erfcx(a * sqrt(t)),

and the surface temperatures approach eq. (10) as
``T_a,s(t) = T_a - gap * e_b / (e_a + e_b) * (1 - erfcx(a sqrt(t)))``.
erfcx (the scaled complementary error function) keeps this finite for any
``a sqrt(t)``; ``h = inf`` gives the perfect-contact limit exactly.

Flux is positive from body ``a`` into body ``b``.
"""

from __future__ import annotations

import numpy as np
from scipy.special import erfcx, wofz

from telethermal.errors import ModelError

_SQRT_PI = np.sqrt(np.pi)


def _check(e_a: float, e_b: float, conductance_w_m2k: float) -> None:
    if not (np.all(np.asarray(e_a) > 0) and np.all(np.asarray(e_b) > 0)):
        raise ModelError(f"effusivities must be positive, got e_a={e_a}, e_b={e_b}")
    if not np.all(np.asarray(conductance_w_m2k) > 0):
        raise ModelError(f"contact conductance must be positive (inf for a perfect "
                         f"contact), got {conductance_w_m2k}")


def contact_temperature_c(temp_a_c, temp_b_c, e_a, e_b):
    """Steady contact-surface temperature of eq. (10), degC.

    Parameters
    ----------
    temp_a_c, temp_b_c : float or ndarray
        Initial temperatures of the two bodies, degC.
    e_a, e_b : float or ndarray
        Effusivities sqrt(k rho c), W s^0.5 m^-2 K^-1.
    """
    _check(e_a, e_b, 1.0)
    return (np.asarray(temp_a_c) * e_a + np.asarray(temp_b_c) * e_b) / (e_a + e_b)


def contact_flux_w_m2(t_s, temp_a_c, temp_b_c, e_a, e_b, conductance_w_m2k=np.inf):
    """Heat flux from body ``a`` into body ``b`` after contact, W/m^2.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Times since contact, s. Negative times give zero flux; ``t = 0`` gives
        ``h * gap`` (``inf * sign(gap)`` for a perfect contact with a gap).
    temp_a_c, temp_b_c : float
        Initial temperatures, degC.
    e_a, e_b : float
        Effusivities, W s^0.5 m^-2 K^-1.
    conductance_w_m2k : float
        Interfacial contact conductance h; ``np.inf`` for a perfect contact.

    Returns
    -------
    ndarray, shape (n,)
    """
    _check(e_a, e_b, conductance_w_m2k)
    t = np.asarray(t_s, dtype=np.float64)
    gap = float(temp_a_c) - float(temp_b_c)
    after = t > 0
    root_t = np.sqrt(np.where(after, t, 1.0))
    h = float(conductance_w_m2k)
    if np.isinf(h):
        e_eff = e_a * e_b / (e_a + e_b)
        q = gap * e_eff / (_SQRT_PI * root_t)
        at_zero = np.inf * np.sign(gap) if gap else 0.0
    else:
        a = h * (1.0 / e_a + 1.0 / e_b)
        q = h * gap * erfcx(a * root_t)
        at_zero = h * gap
    q = np.where(after, q, 0.0)
    return np.where(t == 0, at_zero, q)


def contact_surface_temps_c(t_s, temp_a_c, temp_b_c, e_a, e_b, conductance_w_m2k=np.inf):
    """Surface temperatures of both bodies after contact, degC.

    Returns
    -------
    (ndarray, ndarray), each shape (n,)
        ``T_a,s(t)`` and ``T_b,s(t)``; equal for a perfect contact, and
        differing by ``q / h`` otherwise.
    """
    _check(e_a, e_b, conductance_w_m2k)
    t = np.asarray(t_s, dtype=np.float64)
    gap = float(temp_a_c) - float(temp_b_c)
    h = float(conductance_w_m2k)
    if np.isinf(h):
        settled = np.where(t > 0, 1.0, 0.0)
    else:
        a = h * (1.0 / e_a + 1.0 / e_b)
        settled = 1.0 - erfcx(a * np.sqrt(np.clip(t, 0.0, None)))
    share_a = e_b / (e_a + e_b)
    share_b = e_a / (e_a + e_b)
    return (temp_a_c - gap * share_a * settled, temp_b_c + gap * share_b * settled)


def semi_infinite_error_bound(thickness_m: float, diffusivity_m2_s: float, duration_s: float) -> float:
    """Relative error of treating a slab of finite thickness as semi-infinite.

    The first image term of the slab solution (adiabatic or isothermal back
    face) changes the surface flux by ``2 exp(-L^2 / (alpha t))`` relative;
    returned at the end of the run, where it is largest.
    """
    if np.isinf(thickness_m):
        return 0.0
    return float(2.0 * np.exp(-thickness_m**2 / (diffusivity_m2_s * duration_s)))


def contact_flux_sensed_w_m2(t_s, temp_a_c, temp_b_c, e_a, e_b, conductance_w_m2k=np.inf,
                             sensor_lag_s=0.0):
    """:func:`contact_flux_w_m2` as a first-order sensor (time constant
    ``sensor_lag_s``, zero reading before contact) reads it, W/m^2.

    In the Laplace domain, with ``p = sqrt(s)`` and ``mu = 1/tau``, the
    reading per kelvin of gap is ``N mu / (p (p + a) (p^2 + mu))`` (``N = h``)
    or, for a perfect contact, ``N mu / (p (p^2 + mu))`` (``N = e_a e_b /
    (e_a + e_b)``). Partial fractions over the roots ``r_k`` of ``p`` and
    ``L^-1[1 / (sqrt(s) - r)] = 1/sqrt(pi t) + r erfcx(-r sqrt(t))`` give
    ``sum_k A_k r_k erfcx(-r_k sqrt(t))`` (the ``1/sqrt(pi t)`` terms cancel:
    ``sum A_k = 0``), with ``erfcx(z) = w(i z)`` (Faddeeva) for the complex
    roots ``+-i sqrt(mu)``. ``sensor_lag_s = 0``: :func:`contact_flux_w_m2`.
    """
    if sensor_lag_s == 0:
        return contact_flux_w_m2(t_s, temp_a_c, temp_b_c, e_a, e_b, conductance_w_m2k)
    _check(e_a, e_b, conductance_w_m2k)
    if not (sensor_lag_s > 0 and np.isfinite(sensor_lag_s)):
        raise ModelError(f"sensor_lag_s must be >= 0 and finite, got {sensor_lag_s}")
    t = np.asarray(t_s, dtype=np.float64)
    gap = float(temp_a_c) - float(temp_b_c)
    mu = 1.0 / float(sensor_lag_s)
    h = float(conductance_w_m2k)
    beta = np.sqrt(mu)
    if np.isinf(h):
        scale, roots = e_a * e_b / (e_a + e_b), [0.0, 1j * beta, -1j * beta]
    else:
        scale, roots = h, [0.0, -h * (1.0 / e_a + 1.0 / e_b), 1j * beta, -1j * beta]
    root_t = np.sqrt(np.clip(t, 0.0, None))
    total = np.zeros(t.shape, dtype=np.complex128)
    for k, r in enumerate(roots):
        if r == 0:
            continue
        a_k = scale * mu / np.prod([r - q for j, q in enumerate(roots) if j != k])
        total = total + a_k * r * wofz(1j * (-r) * root_t)
    return np.where(t > 0, gap * total.real, 0.0)
