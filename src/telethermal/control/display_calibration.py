"""The display pad calibrated on its own bench (``telethermal calibrate
display``; issue 44's display half, docs/calibration.md).

The routine a lab runs on its master, through the display's devices (the
``read(t_s)`` / ``apply(t_s, step, dt_s, force_n)`` interface the master
drives: :mod:`telethermal.devices.display`), in two parts:

1. **The face free in air**, open-loop current steps (+-1 A, 1 s each).
   Nothing leaves the face, and the fit takes the pad's **surface
   thermocouple** for the junction, read by the junction sensor through its
   lag. That holds only where the layers follow the junction at once: on a
   real pad the face lags the junction by the layers' diffusion (the
   shipped stack's slowest mode about 0.2 s, a review's finite-difference
   model, as long as the sensor's own lag), and the simulated display lumps
   its layers with the junction in air, which hides it. So this part's
   lag is reported and NOT used by the master (its configured lag is:
   ``teleop/display_calibration.calibrated_lags``). The fit
   ``J_n = z_n + b``, ``z_n = z_{n-1} + g (T_n - z_{n-1})``,
   ``g = 1 - exp(-dt / tau_j)`` gives the **junction sensor's lag**
   ``tau_j`` and its offset from the thermocouple ``b``. The air's own
   flux is nil here, so the flux sensor learns nothing in this part.
2. **A reference block pressed on the face** (a block of a material of the
   table, semi-infinite over the part: 3 cm of PMMA is, for 10 s), the same
   steps. The flux into a semi-infinite block of known effusivity ``e``
   through a contact ``h`` fixes the pad's surface temperature:
   ``T_s = T_0 + q / h + 1 / (e sqrt(pi)) int q(s) / sqrt(t - s) ds``.
   The flux sensor reads ``gain`` times ``q`` through its lag ``tau_f``, so
   the measured flux, un-lagged (``q = (s + tau_f ds/dt) / gain``), predicts
   the thermocouple; the fit gives **``tau_f``, the flux gain** (relative
   to the block's table effusivity: a block 5 % off the table reads a gain
   5 % off), ``h`` and ``T_0`` (the block's temperature with the
   thermocouple's bias). A low-effusivity block keeps the contact's own
   time ``(e / h)^2`` far below the lag (PMMA on grease: about 1 ms
   against 150 ms): on a metal block the contact and the lag could not be
   told apart. The same part then gives the pad's layers between the
   junction and the face (:mod:`telethermal.control.display_stack`).

The fits are ``scipy.optimize.least_squares`` on residuals divided by the
noise the configuration states (the junction sensor's, the thermocouple's,
the flux sensor's carried through the un-lagging); each parameter's 95 %
interval is ``+-1.96 sd`` of its ``ln`` (Gauss-Newton covariance at the
optimum, widened by the chi-square per degree of freedom where over 1), and
a chi-square per degree of freedom over :data:`CHI2_MAX` refuses the
calibration (the pad does not behave as its model: a block not pressed
flat, a sensor not bonded).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from telethermal.errors import CalibrationError

#: The current steps of each part: (current A, seconds), from rest.
STEPS = ((0.0, 0.5), (1.0, 1.0), (-1.0, 1.0), (1.0, 1.0), (-1.0, 1.0), (0.0, 1.5))
#: The reference block's weight on the pad (its force sensor reads contact), N.
BLOCK_FORCE_N = 10.0
#: The control period's rate of the routine, Hz (the master's default).
RATE_HZ = 500.0
#: The chi-square per degree of freedom past which the display does not fit
#: its model (the pad calibration's limit: docs/calibration.md).
CHI2_MAX = 2.0
#: A 95 % interval: +-1.96 sd.
Z95 = 1.959964
#: Type-T thermocouple sensitivity near 25 C, uV/K (NIST ITS-90 tables:
#: 40.7 uV/K at 25 C): the surface thermocouple's noise in kelvin.
TYPE_T_UV_PER_K = 40.7


def steps_duration_s() -> float:
    return sum(s for _, s in STEPS)


def current_at(t_s: float) -> float:
    """The routine's current ``t_s`` seconds into a part, A."""
    for current, seconds in STEPS:
        if t_s < seconds:
            return current
        t_s -= seconds
    return 0.0


@dataclass(frozen=True)
class RoutineStep:
    """What the routine asks of the display in one period (the fields a
    display's ``apply`` reads of the master's step)."""

    t_s: float
    current_a: float
    phase: str = "calibration"
    touching: bool = False
    desired_flux_w_m2: float = math.nan
    junction_cmd_c: float = math.nan
    junction_applied_c: float = math.nan
    safe: bool = False


@dataclass(frozen=True)
class Record:
    """One part's readings, one row per control period (arrays)."""

    t_s: np.ndarray
    current_a: np.ndarray
    junction_c: np.ndarray
    surface_c: np.ndarray
    flux_w_m2: np.ndarray
    force_n: np.ndarray


def run_part(display, t0_s: float, rate_hz: float = RATE_HZ, clock=None) -> Record:
    """Drive ``display`` through :data:`STEPS` from session time ``t0_s``,
    one period at a time, as the master drives it; the readings. ``clock``
    (``now()``, ``sleep_until(deadline)``: a lab's display on the real
    clock) paces the periods, each reading stamped at its period's start,
    and a period whose deadline had passed by a whole period is skipped, a
    row of NaN (missed, as :func:`on_grid` counts it: the steps stay on
    time); None: back to back, stamped on the routine's grid (a simulated
    display)."""
    dt = 1.0 / rate_hz
    n = int(round(steps_duration_s() * rate_hz))
    rows = []
    base = None if clock is None else clock.now()
    for k in range(n):
        current = current_at(k * dt)
        if clock is None:
            t = t0_s + k * dt
        else:
            if clock.now() - base >= (k + 1) * dt:          # this period is over: missed
                rows.append((t0_s + k * dt, current) + (math.nan,) * 4)
                continue
            clock.sleep_until(base + k * dt)
            t = t0_s + (clock.now() - base)
        s = display.read(t)
        rows.append((t, current, s.junction_c, s.pad_temp_c, s.flux_w_m2, s.force_n))
        display.apply(t, RoutineStep(t, current), dt, s.force_n)
    return Record(*(np.array(c, float) for c in zip(*rows)))


#: The share of a part's periods a display on the real clock may miss (a
#: stale board frame, a driver not yet trusted: a NaN reading) before the
#: part is refused; fewer are filled from their neighbours.
MISSING_MAX = 0.02


#: The longest run of missed periods filled from its neighbours (20 ms at
#: 500 Hz: a straight line across a first-order response of 0.1-0.15 s
#: misses its curve by under g^2 / (8 tau^2), 0.5 % of a step, here under
#: the sensors' noise); a longer gap refuses the part.
GAP_MAX = 10


def on_grid(rec: Record, rate_hz: float, part: str) -> Record:
    """A part read on the real clock, on the routine's own grid (one row
    per period, from :func:`run_part`): the sensors' columns interpolated
    from their readings at the instants they were taken (a late period,
    a missed one filled from its neighbours); refused when more than
    :data:`MISSING_MAX` of the periods miss a reading or :data:`GAP_MAX`
    in a row do. The force is left as read (NaN where the board has no
    force channel: the caller says so)."""
    used = np.isfinite(rec.junction_c) & np.isfinite(rec.surface_c) & \
        np.isfinite(rec.flux_w_m2)
    missing = int(rec.t_s.size - used.sum())
    runs = np.diff(np.flatnonzero(np.concatenate(([True], used, [True])))) - 1
    longest = int(runs.max()) if runs.size else 0
    if missing > MISSING_MAX * rec.t_s.size or longest > GAP_MAX or used.sum() < 2:
        raise CalibrationError(
            f"the part {part} missed a reading in {missing} of {rec.t_s.size} periods, "
            f"{longest} in a row (refused over {100 * MISSING_MAX:g} %, or over {GAP_MAX} in "
            "a row: the board's frames stale, the Peltier driver not answering, or this "
            "computer late); check the board's and the driver's links and that nothing else "
            "loads this computer, then run it again")
    grid = rec.t_s[0] + np.arange(rec.t_s.size) / rate_hz
    t = rec.t_s[used]
    return Record(grid, rec.current_a, *(np.interp(grid, t, column[used]) for column in
                                         (rec.junction_c, rec.surface_c, rec.flux_w_m2)),
                  rec.force_n)


#: How many standard errors of its estimate the face's drift over the
#: first rest may reach before the pad and the block count as unsettled.
DRIFT_SIGMAS = 5.0


def _drift(t: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """The least-squares slope of ``y`` over ``t`` and its standard error,
    the noise taken from the readings' successive differences (sd / sqrt 2:
    white noise, not the slow curve of a transient, which would inflate a
    residual-based figure; no noise figure assumed)."""
    slope = np.polyfit(t, y, 1)[0]
    noise = np.std(np.diff(y), ddof=1) / np.sqrt(2.0)
    return float(slope), float(noise / np.sqrt(np.sum((t - t.mean()) ** 2)))


def check_settled(rec: Record, part: str) -> None:
    """Refuse a part whose first rest (0 A, before the steps) shows heat
    already flowing between the pad and what is on it, which the fit does
    not model (a block pressed on a pad 1 K off it read a flux lag 8 % long
    on the simulated bench): the sensed flux or the face's temperature
    drifting over that rest by more than :data:`DRIFT_SIGMAS` standard
    errors of its slope. (A pad and a block at two temperatures meet at a
    nearly steady face; the flux between them decays, so the flux shows it.)"""
    m = int(round(STEPS[0][1] * (rec.t_s.size - 1) / (rec.t_s[-1] - rec.t_s[0])))
    t = rec.t_s[:m] - rec.t_s[0]
    for name, y, unit, scale in (("sensed flux", rec.flux_w_m2[:m], "W/m^2/s", 1.0),
                                 ("face", rec.surface_c[:m], "mK/s", 1e3)):
        ok = np.isfinite(y)
        if ok.sum() < 10:
            continue                # too few readings to judge; on_grid refuses those
        slope, se = _drift(t[ok], y[ok])
        if abs(slope) > DRIFT_SIGMAS * se:
            raise CalibrationError(
                f"the {name} drifted {slope * scale:+.1f} {unit} ({abs(slope) / se:.0f} "
                f"standard errors) while the routine rested at 0 A before the steps {part}: "
                "heat was already flowing between the pad and the block, which the fit does "
                "not model; leave them together at rest, the display idle, until the readings "
                "are steady, then run it again")


@dataclass(frozen=True)
class Fitted:
    """One fitted parameter: its value and 95 % interval."""

    value: float
    lo: float
    hi: float


def _intervals(result, names, chi2: float, log_scale: set) -> dict[str, Fitted]:
    jac = result.jac
    cov = np.linalg.pinv(jac.T @ jac) * max(1.0, chi2)
    sd = np.sqrt(np.diag(cov))
    out = {}
    for i, name in enumerate(names):
        x, d = result.x[i], Z95 * sd[i]
        out[name] = (Fitted(math.exp(x), math.exp(x - d), math.exp(x + d))
                     if name in log_scale else Fitted(x, x - d, x + d))
    return out


def lag_filter(x: np.ndarray, tau_s: float, dt_s: float, z0: float) -> np.ndarray:
    """The first-order lag over samples: ``z_n = z_{n-1} + g (x_n - z_{n-1})``."""
    from scipy.signal import lfilter
    g = -math.expm1(-dt_s / tau_s) if tau_s > 0 else 1.0
    z, _ = lfilter([g], [1.0, g - 1.0], x, zi=[(1.0 - g) * z0])
    return z


@dataclass(frozen=True)
class PartFit:
    params: dict[str, Fitted]
    chi2_per_dof: float
    residual_rms: float
    noise_rms: float
    samples: int


def fit_junction_lag(rec: Record, tau0_s: float, junction_noise_k: float,
                     surface_noise_k: float) -> PartFit:
    """The junction sensor's lag from the part in air (see the module)."""
    dt = float(np.median(np.diff(rec.t_s)))
    junction, surface = rec.junction_c, rec.surface_c
    if not (np.isfinite(junction).all() and np.isfinite(surface).all()):
        raise CalibrationError("the part in air has readings the display could not trust "
                               "(NaN): run the routine again")
    g0 = -math.expm1(-dt / tau0_s)
    # The thermocouple's noise reaches the prediction through the lag.
    sigma = math.sqrt(junction_noise_k ** 2 + surface_noise_k ** 2 * g0 / (2 - g0))

    # The first rest's residuals left out: the filter starts from the
    # thermocouple, the sensor from wherever the part before left it.
    skip = int(round(STEPS[0][1] / dt))

    def residual(p):
        lagged = lag_filter(surface, math.exp(p[0]), dt, surface[0])
        return (lagged[skip:] + p[1] - junction[skip:]) / sigma

    result = least_squares(residual, [math.log(tau0_s), junction[0] - surface[0]],
                           x_scale=[0.1, 0.1])
    return _part(result, ("junction_lag_s", "offset_k"), {"junction_lag_s"}, sigma)


def _part(result, names, log_scale, sigma) -> PartFit:
    n = result.fun.size
    chi2 = float(result.fun @ result.fun) / max(1, n - len(names))
    return PartFit(_intervals(result, names, chi2, log_scale), chi2,
                   float(np.sqrt(np.mean(result.fun ** 2))) * sigma, sigma, n)


#: The flux is un-lagged over windows of this length, s: ``tau ds/dt`` over
#: one sample carries the flux sensor's noise ``tau / dt`` times (about 100x
#: at 500 Hz), and a fit whose input is that noisy prefers the parameters
#: that carry less of it (errors in variables: measured, a lag 8 % long);
#: over 10 ms it is 10x less, and the sensor's own 150 ms lag is smooth there.
WINDOW_S = 0.01


def unlag_windows(sensed: np.ndarray, tau_s: float, dt_s: float, m: int) -> np.ndarray:
    """The mean flux over each window of ``m`` samples a first-order sensor
    reading ``sensed`` saw: ``tau (s_b - s_a) + int_a^b s dt`` over the
    window's length (the lag's equation integrated; trapezoids)."""
    n = (sensed.size - 1) // m
    edges = sensed[: n * m + 1: m]
    inner = sensed[: n * m + 1]
    trapz = (0.5 * (inner[:-1] + inner[1:])).reshape(n, m).sum(axis=1) * dt_s
    return (tau_s * np.diff(edges) + trapz) / (m * dt_s)


def halfspace_weights(n: int, dt_s: float, effusivity: float) -> np.ndarray:
    """The surface temperature rise of a semi-infinite solid per W/m^2 held
    over one period of ``dt_s``, ``m`` periods after it (K per W/m^2)."""
    m = np.arange(n, dtype=float)
    return 2.0 * math.sqrt(dt_s) * (np.sqrt(m + 1.0) - np.sqrt(m)) / (effusivity * math.sqrt(math.pi))


def surface_from_flux(q: np.ndarray, weights: np.ndarray, h_w_m2k: float,
                      t0_c: float) -> np.ndarray:
    """The pad's surface temperature over the block at each window's end:
    ``T_0`` plus the block's surface rise plus the contact's drop (``q``
    the windows' mean flux; the drop with the flux at the window's end,
    the mean of the two windows around it)."""
    rise = np.convolve(q, weights)[: q.size]
    at_end = np.concatenate((0.5 * (q[:-1] + q[1:]), q[-1:]))
    return t0_c + rise + at_end / h_w_m2k


def fit_flux(rec: Record, effusivity: float, tau0_s: float, h0_w_m2k: float,
             surface_noise_k: float, flux_noise_w_m2: float) -> PartFit:
    """The flux sensor's lag and gain, the contact and the block's start
    from the part with the block pressed (see the module)."""
    dt = float(np.median(np.diff(rec.t_s)))
    flux, surface = rec.flux_w_m2, rec.surface_c
    if not (np.isfinite(flux).all() and np.isfinite(surface).all()):
        raise CalibrationError("the part on the block has readings the display could not "
                               "trust (NaN): run the routine again")
    m = max(1, int(round(WINDOW_S / dt)))
    n = (flux.size - 1) // m
    at_ends = surface[m: n * m + 1: m]
    w = halfspace_weights(n, m * dt, effusivity)
    # The flux sensor's noise carried through the un-lagging and the block
    # (one draw of it, fixed): its share of the prediction's error.
    draw = np.random.default_rng(0).normal(0.0, flux_noise_w_m2, flux.size)
    carried = float(np.std(surface_from_flux(unlag_windows(draw, tau0_s, dt, m), w,
                                             h0_w_m2k, 0.0)))
    sigma = math.sqrt(surface_noise_k ** 2 + carried ** 2)

    def residual(p):
        q = unlag_windows(flux, math.exp(p[0]), dt, m) / math.exp(p[1])
        return (surface_from_flux(q, w, 1.0 / (p[2] * 1e-5), p[3]) - at_ends) / sigma

    # The contact as its resistance (1e-5 m^2 K/W units; >= 0): a perfect
    # contact is its edge, not a log factor gone to infinity.
    start = [math.log(tau0_s), 0.0, 1e5 / h0_w_m2k, float(surface[0])]
    result = least_squares(residual, start, x_scale=[0.1, 0.05, 1.0, 0.1],
                           bounds=([-np.inf, -np.inf, 1e-6, -np.inf], np.inf))
    return _part(result, ("flux_lag_s", "flux_gain", "contact_resistance_1e5_m2k_w",
                          "block_c"), {"flux_lag_s", "flux_gain"}, sigma)


def refuse_misfit(part: str, fit: PartFit) -> None:
    """A part whose residual the noise cannot explain is refused."""
    if not fit.chi2_per_dof <= CHI2_MAX:
        raise CalibrationError(
            f"the display does not fit its model in the part {part}: residual "
            f"{fit.residual_rms:.4g} K rms against {fit.noise_rms:.4g} K the sensors' noise "
            f"allows (chi2/dof {fit.chi2_per_dof:.2f} > {CHI2_MAX:g}); check the block "
            "is pressed flat on grease and the sensors are bonded, then run it again")
