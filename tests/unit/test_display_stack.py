"""The display pad's layers as the calibration models them
(control/display_stack.py): the finite-volume chain against the closed
forms of a layered wall, and the fit on synthetic readings."""

from __future__ import annotations

import math

import numpy as np
import pytest

from telethermal.control import display_stack as ds
from telethermal.control.display_calibration import STEPS, Record, current_at
from telethermal.errors import CalibrationError
from telethermal.physics.layered import Layer, pad_resistance
from telethermal.physics.materials import get_material
from telethermal.physics.scene import load_scene

LAYERS = load_scene("fingertip-7").pad.layers


@pytest.mark.parametrize("face, back", [(1.0, 1.0), (1.6, 0.7)])
def test_steady_state_face_is_the_junction_less_flux_times_resistance(face, back):
    """Held long at a junction temperature and a face flux, the face sits at
    ``T_j - q R`` (R the layers' series resistance, the face and back layer
    scaled): the closed form of a steady wall, to 1e-9 K."""
    a, b, r = ds.stack_system(LAYERS, face, back)
    scaled = [Layer(LAYERS[0].material, LAYERS[0].thickness_m * face), *LAYERS[1:-1],
              Layer(LAYERS[-1].material, LAYERS[-1].thickness_m * back)]
    tj, q = np.full(50, 31.0), np.full(50, 2500.0)
    out = ds.face_c(a, b, r, tj, q, 1.0, 25.0)     # 50 s: every mode long decayed
    assert out[-1] == pytest.approx(31.0 - 2500.0 * pad_resistance(scaled), abs=1e-9)


def test_a_slab_follows_its_junction_as_the_series_solution_says():
    """One layer, its face insulated (no flux), its back stepped 1 K: the
    face's rise is ``1 - sum 4 (-1)^n / ((2n+1) pi) exp(-((2n+1) pi / 2)^2
    alpha t / L^2)`` (Carslaw and Jaeger, a slab with one face held). The
    chain of at most :data:`MAX_CELLS` cells, stepped exactly, follows it
    within 1.5 % of the step from a tenth of the slab's diffusion time on
    (earlier, a few cells cannot carry the front's curve)."""
    film = Layer(get_material("flux_sensor_film"), 3e-4)
    layers = (film, Layer(get_material("flux_sensor_film"), 1e-9))   # a back layer of nothing
    a, b, r = ds.stack_system(layers, window_s=0.01)
    alpha = film.material.conductivity_w_mk / film.material.volumetric_heat_j_m3k
    t_diff = film.thickness_m ** 2 / alpha
    dt = t_diff / 200
    n = 600
    out = ds.face_c(a, b, r, np.ones(n), np.zeros(n), dt, 0.0)
    t = dt * np.arange(1, n + 1)
    k = np.arange(60)[:, None]
    exact = 1 - np.sum(4 * (-1.0) ** k / ((2 * k + 1) * math.pi)
                       * np.exp(-((2 * k + 1) * math.pi / 2) ** 2 * alpha * t / film.thickness_m ** 2),
                       axis=0)
    late = t >= 0.1 * t_diff
    assert np.max(np.abs(out[late] - exact[late])) < 0.015


#: The configured sensors' noise (fingertip-7: the junction chip's 0.01 K
#: and its 0.01 K count, the thermocouple's ``thermocouple_noise_uv`` at
#: 40.7 uV/K, the flux film's ``flux_noise_uv`` through its sensitivity).
SENSORS = load_scene("fingertip-7").sensors
JUNCTION_NOISE_K, JUNCTION_LSB_K = 0.01, 0.01
TC_NOISE_K = SENSORS.thermocouple_noise_uv / 40.7
FLUX_NOISE_W_M2 = SENSORS.flux_noise_w_m2()


def _readings(face: float, back: float, tau_j: float, offset_k: float, seed: int = 0,
              rate_hz: float = 500.0, noisy: bool = True) -> Record:
    """The routine's part on a block as the sensors read it: the face's flux
    made up (the current's steps smoothed over 50 ms), the junction stepped
    (smoothed over 100 ms), the face from a chain with ``face`` and ``back``
    finer than the fit's (cells for the sample period, not the fit's
    window), stepped at the sample period; the junction read through a
    first-order lag ``tau_j``, ``offset_k`` off and quantised, every
    reading with the configured sensors' noise (``noisy``; else exact)."""
    rng = np.random.default_rng(seed)
    k = 1.0 if noisy else 0.0
    dt = 1.0 / rate_hz
    n = int(round(sum(s for _, s in STEPS) * rate_hz)) + 1
    t = np.arange(n) * dt
    cur = np.array([current_at(x) for x in t])
    q = 3000.0 * np.convolve(cur, np.full(25, 1 / 25))[:n]
    tj = 25.0 + 4.0 * np.convolve(cur, np.full(50, 1 / 50))[:n]
    a, b, r = ds.stack_system(LAYERS, face, back, window_s=dt, max_cells=40)
    surface = np.r_[25.0, ds.face_c(a, b, r, tj[1:], q[1:], dt, 25.0)]
    g = -math.expm1(-dt / tau_j)
    sensed = np.empty(n)
    sensed[0] = tj[0]
    for i in range(1, n):
        sensed[i] = sensed[i - 1] + g * (tj[i] - sensed[i - 1])
    junction = sensed + offset_k + k * rng.normal(0, JUNCTION_NOISE_K, n)
    if noisy:
        junction = np.round(junction / JUNCTION_LSB_K) * JUNCTION_LSB_K
    return Record(t, cur, junction, surface + k * rng.normal(0, TC_NOISE_K, n),
                  q + k * rng.normal(0, FLUX_NOISE_W_M2, n), np.full(n, 10.0))


def _fit(rec, layers=LAYERS):
    return ds.fit_stack(rec, layers, 1e-6, 1.0, 0.10,
                        math.hypot(JUNCTION_NOISE_K, JUNCTION_LSB_K / 12 ** 0.5), TC_NOISE_K,
                        FLUX_NOISE_W_M2)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_fit_finds_the_layers_and_lag_the_readings_were_made_with(seed):
    """Readings made with a face layer 1.4x, a back layer 0.8x, the junction
    sensor 0.13 s behind and 0.2 K off (the flux sensor taken as un-lagged,
    gain 1): each inside its 95 % interval (the fit's own bias included as
    its type-B part, ``MODEL_REL``), the face layer's narrower than +-1 %,
    the residual at the noise (chi2/dof within 0.7-1.4)."""
    fit = _fit(_readings(1.4, 0.8, 0.13, 0.2, seed))
    truth = {"face_layer_thickness": 1.4, "back_layer_thickness": 0.8,
             "junction_lag_s": 0.13, "offset_k": 0.2}
    for name, true in truth.items():
        p = fit.params[name]
        assert p.lo <= true <= p.hi, (name, p, true)
    face = fit.params["face_layer_thickness"]
    assert face.hi - face.lo < 0.014 * 2
    assert 0.7 < fit.chi2_per_dof < 1.4


@pytest.mark.parametrize("face, back, tau_j", [(1.4, 0.8, 0.13), (1.0, 1.0, 0.10),
                                              (0.7, 1.3, 0.08), (2.5, 1.0, 0.10)])
def test_the_fits_own_bias_is_under_its_type_b_share(face, back, tau_j):
    """Without noise, what is left is the fit's own bias (its inputs held
    over each window): under the relative uncertainty ``MODEL_REL`` states
    for each factor, so the stated interval carries it."""
    fit = _fit(_readings(face, back, tau_j, 0.2, noisy=False))
    for name, true in (("face_layer_thickness", face), ("back_layer_thickness", back),
                       ("junction_lag_s", tau_j)):
        bias = abs(fit.params[name].value / true - 1)
        assert bias <= ds.MODEL_REL[name], (name, bias)


def test_a_far_face_layer_is_found():
    """A face layer 2.5x its design (grease pumped thick, a film of another
    make) is found within its interval."""
    fit = _fit(_readings(2.5, 1.0, 0.1, 0.0))
    p = fit.params["face_layer_thickness"]
    assert p.lo <= 2.5 <= p.hi, p


def test_a_layer_at_its_bound_is_refused_not_reported():
    """A plate 6 times its design (past the fit's factor of 5) pins its
    factor at the bound, where the face layer's would be biased (+13 %,
    its interval missing the truth at a chi2 that passes): refused, naming
    the layer."""
    with pytest.raises(CalibrationError, match="back_layer_thickness ended at its bound"):
        _fit(_readings(1.4, 6.0, 0.1, 0.0))


def test_a_pad_of_one_layer_is_refused_by_name():
    rec = _readings(1.0, 1.0, 0.1, 0.0)
    with pytest.raises(CalibrationError, match="1 layer"):
        _fit(rec, LAYERS[:1])


def test_the_face_drop_takes_the_flux_at_each_steps_end():
    """The drop over the face's half cell is taken with the flux at each
    step's end, the mean of the two steps around it (the step's own mean
    would lag it half a step on a ramp): on a layer whose heat capacity
    holds its cells still over the steps, the face is the start less that
    drop, exactly."""
    from telethermal.physics.materials import Material
    still = Material("still", "pad", 0.3, 1e12, 1e3, "a heat capacity no flux moves")
    layers = (Layer(still, 3e-4), Layer(still, 1e-4))
    a, b, r = ds.stack_system(layers)
    q = np.array([0.0, 1000.0, 3000.0, 2000.0])
    out = ds.face_c(a, b, r, np.full(q.size, 30.0), q, 0.01, 30.0)
    at_end = np.array([500.0, 2000.0, 2500.0, 2000.0])
    assert out == pytest.approx(30.0 - at_end * r, abs=1e-6)     # the cells move 2e-9 K
