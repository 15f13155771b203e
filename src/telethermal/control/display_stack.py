"""The display pad's layers fitted on the reference block (``telethermal
calibrate display``'s third fit; docs/calibration.md).

Between the module's junction and the pad's face lie the pad's layers
(``[pad] layers``: the flux sensor's film, grease, the module's cold plate).
With the block pressed, the routine reads the three quantities that tie
them down, as a thermal-interface tester does (ASTM D5470: a layer's
thermal impedance from the heat flux through it and the temperatures on
its two sides):

- the **junction's** temperature, by the junction sensor through its lag
  (``tau_j``) and off the thermocouple by a constant (``b``: the two
  sensors' biases);
- the **heat flux out of the face**, by the flux sensor as the block part's
  flux fit calibrated it (its lag and gain);
- the **face's** temperature, by the surface thermocouple.

The layers are a chain of finite volumes (:func:`stack_system`: each
layer cut into cells thin against its diffusion over a window), held at
the junction's temperature behind (un-lagged from the junction sensor)
and losing the measured flux at the face; the face they predict is
compared with the thermocouple. Fitted by ``scipy.optimize.least_squares``
(the display calibration's conventions:
:mod:`telethermal.control.display_calibration`):

- ``face_layer_thickness``, the contact-side layer's thickness (the flux
  sensor's film) as a factor on its design, at its table conductivity and
  heat capacity: **lumped**, it carries the stack's resistance but the
  junction-side layer's (the shipped film is 95 % of it; a thicker grease
  line reads as a thicker film) and cannot tell the film's thickness from
  its conductivity (fitted as two on the simulated bench, the film's heat
  capacity read only to +-16-37 %: it shows only through its diffusion, as
  slow as the sensors' lags). This is the factor the master's model takes;
- ``back_layer_thickness``, the junction-side layer's (the cold plate), a
  nuisance: its diffusion time (about 0.09 s through 0.8 mm of alumina) is
  as long as the junction sensor's lag, and the two trade against each
  other: fitted so the face layer's is not biased by them (measured: held
  at its design, a plate drawn 1.27x read the junction sensor's lag 36 %
  short), reported, not used;
- ``junction_lag_s``, the junction sensor's lag, reported with its
  interval for the same reason;
- ``offset_k``, the junction sensor's reading less the thermocouple's at
  one temperature.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.linalg import expm
from scipy.optimize import least_squares

from telethermal.control.display_calibration import (STEPS, Z95, Fitted, PartFit, Record,
                                                      _part, unlag_windows)
from telethermal.errors import CalibrationError

#: The windows the sensors are un-lagged over, s (the flux fit's: 10 ms,
#: ``display_calibration.WINDOW_S``; the fit's inputs are held over each).
WINDOW_S = 0.01
#: The face layer's factor is started from each of these; the fit with the
#: least cost is kept (a guard: with the plate held at its design, one start
#: at the design fell into a far minimum on a film drawn 1.65x, x2.7 at
#: chi2/dof 25; with the plate free, one start found every pad tried).
FACE_STARTS = (0.5, 1.0, 2.0)
#: A layer's cells: at most this many, each thin enough that its diffusion
#: time is about one window or less.
MAX_CELLS = 10
#: The fit starts the junction sensor's lag at its configured one; the two
#: factors and the lag (against that) are bounded to (1/BOUND, BOUND).
BOUND = 5.0
NAMES = ("face_layer_thickness", "back_layer_thickness", "junction_lag_s", "offset_k")


def _cells(layer, window_s: float, max_cells: int = MAX_CELLS) -> int:
    alpha = layer.material.conductivity_w_mk / layer.material.volumetric_heat_j_m3k
    return int(min(max_cells, 1 + round(layer.thickness_m / math.sqrt(alpha * window_s))))


def stack_system(layers, face_factor: float = 1.0, back_factor: float = 1.0,
                 window_s: float = WINDOW_S, max_cells: int = MAX_CELLS):
    """The layers (``[0]`` at the face, ``[-1]`` at the junction) as
    ``C dT/dt = -K T + g_j T_j e_last - q e_0``, the first layer's thickness
    times ``face_factor`` and (with two layers or more) the last's times
    ``back_factor``, each layer in at most ``max_cells`` cells. Returns ``(A, B, r_face)``: ``dT/dt = A T + B [T_j,
    q]`` over the cells' temperatures (face first) and the face's
    half-cell resistance (the face is ``T_0 - q r_face``)."""
    caps, halves = [], []
    last = len(layers) - 1
    for i, layer in enumerate(layers):
        scale = face_factor if i == 0 else back_factor if i == last else 1.0
        thickness = layer.thickness_m * scale
        n = _cells(layer, window_s, max_cells)
        dx = thickness / n
        caps += [layer.material.volumetric_heat_j_m3k * dx] * n
        halves += [dx / (2.0 * layer.material.conductivity_w_mk)] * n
    caps, halves = np.array(caps), np.array(halves)
    g = 1.0 / (halves[:-1] + halves[1:])
    k = np.zeros((caps.size, caps.size))
    idx = np.arange(g.size)
    k[idx, idx] += g
    k[idx + 1, idx + 1] += g
    k[idx, idx + 1] -= g
    k[idx + 1, idx] -= g
    g_back = 1.0 / halves[-1]
    k[-1, -1] += g_back
    b = np.zeros((caps.size, 2))
    b[-1, 0] = g_back
    b[0, 1] = -1.0
    return -k / caps[:, None], b / caps[:, None], float(halves[0])


def face_c(a: np.ndarray, b: np.ndarray, r_face: float, junction_c: np.ndarray,
           flux_w_m2: np.ndarray, step_s: float, start_c: float) -> np.ndarray:
    """The face's temperature at the end of each step of ``step_s``, the
    junction's temperature and the face's flux held over each step (exact:
    the system's matrix exponential), the layers uniform at ``start_c``."""
    n = a.shape[0]
    aug = np.zeros((n + 2, n + 2))
    aug[:n, :n], aug[:n, n:] = a * step_s, b * step_s
    e = expm(aug)
    ad, bd = e[:n, :n], e[:n, n:]
    x = np.full(n, float(start_c))
    out = np.empty(junction_c.size)
    for i, (tj, q) in enumerate(zip(junction_c, flux_w_m2)):
        x = ad @ x + bd[:, 0] * tj + bd[:, 1] * q
        out[i] = x[0]
    # The drop over the face's half cell with the flux at each step's end
    # (the mean of the two steps around it), not the step's mean.
    at_end = np.concatenate((0.5 * (flux_w_m2[:-1] + flux_w_m2[1:]), flux_w_m2[-1:]))
    return out - at_end * r_face


def fit_stack(rec: Record, layers, flux_lag_s: float, flux_gain: float,
              junction_tau0_s: float, junction_noise_k: float, surface_noise_k: float,
              flux_noise_w_m2: float, flux_lag_sd_ln: float = 0.0,
              flux_gain_sd_ln: float = 0.0) -> PartFit:
    """The pad's layers (and, alongside, the junction sensor's lag) from the
    part on the block (see the module). ``flux_lag_s`` and ``flux_gain``:
    the block part's flux fit, their standard uncertainties (of their ``ln``)
    ``flux_lag_sd_ln`` and ``flux_gain_sd_ln``, carried into the fitted
    factors (each refitted with its input one sd off: a gain 1 % high reads
    the face layer about 0.8 % thick); the noises: the configured sensors'.
    Refused when a factor ends at its bound (the pad is not its design's
    stack within a factor :data:`BOUND`) or when the model does not fit."""
    dt = float(np.median(np.diff(rec.t_s)))
    junction, flux, surface = rec.junction_c, rec.flux_w_m2, rec.surface_c
    if not (np.isfinite(junction).all() and np.isfinite(flux).all()
            and np.isfinite(surface).all()):
        raise CalibrationError("the part on the block has readings the display could not "
                               "trust (NaN): run the routine again")
    m = max(1, int(round(WINDOW_S / dt)))
    n = (flux.size - 1) // m
    step = m * dt
    at_ends = surface[m: n * m + 1: m]
    rest = int(round(STEPS[0][1] / dt))
    start_c = float(np.mean(surface[:rest]))
    # The sensors' noise carried to the predicted face (one draw of it,
    # fixed, through the design's layers): its share of the residual.
    rng = np.random.default_rng(0)
    a0, b0, r0 = stack_system(layers, window_s=step)
    carried = float(np.std(face_c(
        a0, b0, r0, unlag_windows(rng.normal(0.0, junction_noise_k, flux.size),
                                  junction_tau0_s, dt, m),
        unlag_windows(rng.normal(0.0, flux_noise_w_m2, flux.size), flux_lag_s, dt, m)
        / flux_gain, step, 0.0)))
    sigma = math.hypot(surface_noise_k, carried)

    def solve(lag_s, gain, starts):
        q = unlag_windows(flux, lag_s, dt, m) / gain

        def residual(p):
            a, b, r = stack_system(layers, math.exp(p[0]), math.exp(p[1]), step)
            tj = unlag_windows(junction, math.exp(p[2]), dt, m) - p[3]
            return (face_c(a, b, r, tj, q, step, start_c) - at_ends) / sigma

        best = None
        for start in starts:
            result = least_squares(residual, start, x_scale=[0.1, 0.1, 0.1, 0.1],
                                   bounds=(lo, hi))
            if best is None or result.cost < best.cost:
                best = result
        return best

    if len(layers) < 2:
        raise CalibrationError(f"the pad has {len(layers)} layer(s); the fit needs the face's "
                               "and the junction's (a Peltier pad's cold plate is its last)")
    tau0 = math.log(junction_tau0_s)
    span = math.log(BOUND)
    lo = [-span, -span, tau0 - span, -np.inf]
    hi = [span, span, tau0 + span, np.inf]
    best = solve(flux_lag_s, flux_gain, [[math.log(face), 0.0, tau0,
                                          float(junction[0] - surface[0])]
                                         for face in FACE_STARTS])
    pinned = [(name, math.exp(x)) for name, x, active in
              zip(NAMES[:3], best.x, best.active_mask) if active]
    if pinned:
        raise CalibrationError(
            "the pad's layers do not fit their design within a factor "
            f"{BOUND:g}: {', '.join(f'{n} ended at its bound ({v:.4g})' for n, v in pinned)}; "
            "check the scene's [pad] layers and junction sensor are this pad's (a layer "
            "missing or another part), then run it again")
    fit = _part(best, NAMES, set(NAMES[:3]), sigma)
    # The flux fit's uncertainty, carried: each input one sd off, refitted
    # from this optimum; its shift in each factor's ln, in quadrature.
    carried_ln = np.zeros(3)
    for lag_s, gain in ((flux_lag_s * math.exp(flux_lag_sd_ln), flux_gain),
                        (flux_lag_s, flux_gain * math.exp(flux_gain_sd_ln))):
        if (lag_s, gain) != (flux_lag_s, flux_gain):
            carried_ln += (solve(lag_s, gain, [best.x]).x[:3] - best.x[:3]) ** 2
    return replace(fit, params={**fit.params, **{
        name: _widened(fit.params[name], math.hypot(MODEL_REL[name], math.sqrt(c)))
        for name, c in zip(NAMES[:3], carried_ln)}})


#: The fit's own bias, as a type-B relative uncertainty (GUM 4.3) added in
#: quadrature to each factor's: its inputs are held over each window
#: (their means, from the un-lagging), which the layers' fast modes see.
#: Measured without noise on readings made on a chain twice as fine,
#: stepped at the sample period, four pads from 0.7x to 2.5x
#: (tests/unit/test_display_stack.py): the face layer up to 0.47 %, the
#: back layer up to 3.6 %, the junction sensor's lag up to 5.1 %; each
#: taken rounded up.
MODEL_REL = {"face_layer_thickness": 0.005, "back_layer_thickness": 0.04,
             "junction_lag_s": 0.06}


def _widened(p: Fitted, rel: float) -> Fitted:
    """``p`` (fitted in ln) with a relative sd ``rel`` added in quadrature."""
    sd = math.log(p.hi / p.value) / Z95
    half = Z95 * math.hypot(sd, rel)
    return Fitted(p.value, p.value * math.exp(-half), p.value * math.exp(half))
