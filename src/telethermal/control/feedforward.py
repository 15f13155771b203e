"""Impedance rendering on the display: the junction command that makes the
pad's surface behave as the rendered object's surface would, so that the
operator's skin exchanges with the pad what it would exchange with the object.

Why (measured with ``telethermal session --scene fingertip-7``, 5 seeds, see
the README section "Skin temperature"): tracking the generator's flux leaves
two errors on the skin, which integrates the flux it exchanges through a
``1/sqrt(t)`` memory:

- the first ~0.3 s on metals: the pad's sensor film is a slow, low-effusivity
  layer (``L^2/alpha`` = 0.46 s, effusivity 680 against the skin's 1140) and
  the junction stops at the skin band (15 C); the heat not drawn then keeps
  the skin warm for seconds. The floor of this with the junction in the band
  and the pad at the object's temperature at contact, for a controller that
  knows the plant and the material exactly, is 0.62 K RMS over 5 s on
  aluminium, 0.50 K on steel;
- afterwards, the generator's flux is the mean finger's: on a metal the flux
  is set by the operator's own contact and skin, not by the object, so a
  flux rendered exactly is still the wrong one for this operator (up to
  20 % at 4 s, skin off by 1.6 K).

What this controller does instead:

- The target is the object, not a flux: a semi-infinite object at
  ``T_object`` whose surface takes heat ``-q`` is at ``T_object - (1/e)
  int q(s) / sqrt(pi (t - s)) ds``. The half-integral of the measured flux is
  kept on a sum of exponentials (:func:`half_integral_modes`). The pad's
  surface is steered to that temperature; then the operator's own skin and
  contact set the flux, as in direct contact. No finger temperature, skin
  property or contact conductance enters the target.
- It knows the display's dynamics: the pad layers (junction behind them) on
  a semi-infinite nominal fingertip, in the exact modal form of
  :class:`~telethermal.physics.layered.LayeredContact`, stepped with the
  junction temperature actually applied. It picks the junction temperature
  which, held over the horizon, brings the predicted surface to the target
  predicted at the horizon's end.
- It closes the loop on what is measured: the true flux is recovered from the
  sensor by inverting its first-order lag (``q_s + tau dq_s/dt``), the
  surface is the pad's thermocouple, and the model only predicts how both
  will move from the measured present (offset-free, like a model-predictive
  controller with an output-disturbance estimate).

Everything is a pure update of a small state; time comes as ``dt_s``.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from telethermal.errors import ControlError
from telethermal.physics.layered import Boundary, Layer, LayeredContact
from telethermal.physics.materials import get_material
from telethermal.physics.modal import phi_any


def half_integral_modes(t_min_s: float, t_max_s: float, per_decade: int = 6):
    """Rates ``s`` (1/s) and weights ``c`` with ``sum c exp(-s t) ~ 1/sqrt(pi t)``.

    From ``1/sqrt(pi t) = (1/pi) int_0^inf exp(-s t) s^-1/2 ds`` with
    ``s = exp(x)``, integrated by the trapezoidal rule in ``x`` (exponentially
    convergent for this integrand). The rates reach two decades above
    ``1/t_min`` (the rest weighs ``exp(-100)``) and six below ``1/t_max``
    (what is cut off there weighs ``2 sqrt(s_lo t / pi)`` = 1e-3 at
    ``t_max``). With 6 nodes per decade the relative error is under 2e-3 on
    ``[t_min, t_max]`` (checked in the tests).
    """
    if not 0 < t_min_s < t_max_s:
        raise ControlError(f"need 0 < t_min_s < t_max_s, got {t_min_s}, {t_max_s}")
    lo, hi = math.log(1e-6 / t_max_s), math.log(1e2 / t_min_s)
    n = int(math.ceil((hi - lo) / math.log(10) * per_decade)) + 1
    x = np.linspace(lo, hi, n)
    dx = x[1] - x[0]
    rates = np.exp(x)
    weights = np.sqrt(rates) * dx / math.pi
    weights[[0, -1]] *= 0.5
    return rates, weights


class ImpedanceController:
    """The display's impedance controller: :meth:`observe` every period,
    :meth:`start` at contact, :meth:`command_impedance` while rendering and
    :meth:`advance` with the junction temperature applied.

    Parameters
    ----------
    layers : sequence of Layer
        The display pad from its contact surface to the junction.
    conductance_w_m2k : float
        Pad-fingertip contact conductance the model assumes.
    sensor_lag_s : float
        Time constant of the pad's heat-flux sensor.
    dt_s : float
        Nominal control period.
    horizon_s : float
        The junction command is held over this long in the prediction.
    t_max_s : float
        Longest contact the skin memory is accurate for.
    flux_inverse_s : float
        The flux sensor's lag is inverted as ``(tau s + 1) / (flux_inverse_s
        s + 1)``: its noise gain ``tau / flux_inverse_s`` instead of the
        exact inverse's ``tau / dt`` (0: the exact inverse, for the tests
        that check it).
    bias_filter_s : float
        The offsets between what is measured (flux, surface) and what the
        model predicts are low-pass filtered over this long before they
        correct the prediction (a disturbance estimate, slow by nature; 0:
        taken raw). The thermocouple's 0.025 K of noise per reading would
        otherwise reach the junction command amplified by the model's
        inverse (1 / surface gain over the horizon).
    """

    def __init__(self, layers, conductance_w_m2k: float, sensor_lag_s: float, dt_s: float,
                 horizon_s: float = 0.05, t_max_s: float = 120.0, flux_inverse_s: float = 0.0,
                 bias_filter_s: float = 0.0):
        if not (dt_s > 0 and horizon_s > 0 and conductance_w_m2k > 0 and sensor_lag_s >= 0
                and flux_inverse_s >= 0 and bias_filter_s >= 0):
            raise ControlError("ImpedanceController needs dt_s, horizon_s, conductance > 0 and "
                               f"sensor_lag_s >= 0 (got {dt_s}, {horizon_s}, "
                               f"{conductance_w_m2k}, {sensor_lag_s})")
        self.dt_s, self.tau_s = dt_s, sensor_lag_s
        self.flux_inverse_s, self.bias_filter_s = flux_inverse_s, bias_filter_s
        self._smoothed_w_m2: float | None = None      # the reading through flux_inverse_s
        self.n_ahead = max(1, int(round(horizon_s / dt_s)))
        skin = (Layer(get_material("skin"), math.inf),)
        model = LayeredContact(tuple(layers), skin, Boundary("isothermal"),
                               Boundary("adiabatic"), min(dt_s, 1e-3), t_max_s)
        one = np.ones(1)
        # Deviations from the finger's temperature: the pad uniform at +1 K
        # (initial state per kelvin) and the junction at +1 K (drive per kelvin).
        system = model.modal_system(one, one * 0.0, one * conductance_w_m2k,
                                    (one, one, one, one), 1.0, None, 2)
        lam, f, m_flux = system.lam[0], system.f[0], system.m[0][0]
        # The pad's contact surface (as sim/plant.py reads it), per modal state.
        m_surface = system.m[0][1] - system.r_half[0, model.grid.n_a - 1] * m_flux
        horizon = self.n_ahead * dt_s
        self._surface_free = m_surface * np.exp(-lam * horizon)
        self._surface_gain = float((m_surface * phi_any(lam, horizon)) @ f)
        self._m_surface = m_surface
        self._unit_w0 = system.w0[0]
        self._lam, self._f, self._m_flux = lam, f, m_flux
        self._decay = np.exp(-lam * dt_s)
        self._drive = phi_any(lam, dt_s) * f
        steps = np.arange(1, self.n_ahead + 1) * dt_s
        # Flux j periods ahead = free[j] . w + gain[j] (u - ref), j = 1..n.
        self._free = m_flux[None, :] * np.exp(-lam[None, :] * steps[:, None])
        self._gain = (m_flux[None, :] * phi_any(lam[None, :], steps[:, None])) @ f
        rates, weights = half_integral_modes(dt_s, t_max_s)
        self._s_decay = np.exp(-rates * dt_s)
        self._s_in = weights * -np.expm1(-rates * dt_s) / rates
        # Effect on the half-integral at the horizon's end of a unit flux held
        # over period j (j = 0..n-1), and the past memory's decay to it.
        left = (self.n_ahead - 1 - np.arange(self.n_ahead)) * dt_s
        self._future = np.exp(-rates[None, :] * left[:, None]) @ self._s_in
        self._past_decay = np.exp(-rates * self.n_ahead * dt_s)
        # The coming periods' flux folded onto the modal state once, so a
        # period costs a few dot products (about 50 us here at 1 kHz).
        self._future_free = self._future @ self._free
        self._future_sum = float(self._future.sum())
        self._future_gain = float(self._future @ self._gain)
        self._recent: deque[float] = deque(maxlen=int(round(1.0 / dt_s)) + 1)
        self._last_sensed_w_m2: float | None = None
        self.true_flux_w_m2 = 0.0
        self.reset()

    def reset(self) -> None:
        """No contact: forget the model state and the flux memory."""
        self._w = None
        self._ref_c = math.nan
        self._bias: tuple[float, float] | None = None       # (flux, surface), filtered
        # The half-integral of the flux since contact, on the kernel's modes.
        self._flux_memory = np.zeros_like(self._s_in)

    @property
    def running(self) -> bool:
        return self._w is not None

    def observe(self, sensed_flux_w_m2: float, dt_s: float) -> None:
        """One period's flux reading, every period (in contact or not): the
        true flux is recovered by inverting the sensor's lag."""
        if not math.isfinite(sensed_flux_w_m2):
            return
        last = self._last_sensed_w_m2
        self._last_sensed_w_m2 = sensed_flux_w_m2
        if self.flux_inverse_s > 0:
            # (tau s + 1) / (tf s + 1) = tau/tf + (1 - tau/tf) / (tf s + 1).
            smooth = self._smoothed_w_m2
            smooth = sensed_flux_w_m2 if smooth is None or not dt_s > 0 else \
                smooth - math.expm1(-dt_s / self.flux_inverse_s) * (sensed_flux_w_m2 - smooth)
            self._smoothed_w_m2 = smooth
            ratio = self.tau_s / self.flux_inverse_s
            self.true_flux_w_m2 = ratio * sensed_flux_w_m2 + (1.0 - ratio) * smooth
        else:
            slope = (sensed_flux_w_m2 - last) / dt_s if last is not None and dt_s > 0 else 0.0
            self.true_flux_w_m2 = sensed_flux_w_m2 + self.tau_s * slope
        self._recent.append(self.true_flux_w_m2)
        if self._w is not None:
            self._flux_memory = self._s_decay * self._flux_memory + self._s_in * self.true_flux_w_m2

    def start(self, pad_temp_c: float, finger_temp_c: float, since_contact_s: float,
              junction_c: float) -> None:
        """Contact began ``since_contact_s`` ago with the pad uniform at
        ``pad_temp_c`` and the junction held at ``junction_c`` since."""
        self._ref_c = finger_temp_c
        self._w = (pad_temp_c - finger_temp_c) * self._unit_w0
        n = int(round(max(since_contact_s, 0.0) / self.dt_s))
        for _ in range(n):
            self.advance(junction_c)
        # The readings since contact (the last one is this period's).
        for q in list(self._recent)[-(n + 1):]:
            self._flux_memory = self._s_decay * self._flux_memory + self._s_in * q

    def advance(self, junction_applied_c: float, dt_s: float | None = None) -> None:
        """The junction was held at ``junction_applied_c`` for ``dt_s`` (one
        nominal period when not given)."""
        if self._w is None:
            return
        if dt_s is None or abs(dt_s - self.dt_s) < 1e-12:
            decay, drive = self._decay, self._drive
        else:
            decay, drive = np.exp(-self._lam * dt_s), phi_any(self._lam, dt_s) * self._f
        self._w = decay * self._w + drive * (junction_applied_c - self._ref_c)

    def model_flux_w_m2(self) -> float:
        return float(self._m_flux @ self._w)

    def _offsets(self, flux_w_m2: float, surface_k: float) -> tuple[float, float]:
        """The measured-minus-model offsets, through ``bias_filter_s``."""
        if self.bias_filter_s <= 0 or self._bias is None:
            self._bias = (flux_w_m2, surface_k)
            return self._bias
        g = -math.expm1(-self.dt_s / self.bias_filter_s)
        q, s = self._bias
        self._bias = (q + g * (flux_w_m2 - q), s + g * (surface_k - s))
        return self._bias

    def command_impedance(self, pad_temp_c: float, object_temp_c: float,
                          inverse_effusivity: float) -> float:
        """The junction temperature (C) that makes the pad's surface behave as
        the object's would, after :meth:`observe`.

        A semi-infinite object at ``object_temp_c`` whose surface takes heat
        ``-q`` (``q`` from pad to finger) warms as ``T_s = T_object - (1/e)
        int q(s) / sqrt(pi (t - s)) ds``; the finger then exchanges with the
        pad, through its own contact and skin, the very flux it would
        exchange with the object: no finger temperature, skin or contact
        figure enters. ``inverse_effusivity``: ``1/e`` of the object, m^2 K
        s^-1/2 / W. The pad's surface and flux are predicted one horizon
        ahead by the model, anchored on the thermocouple and the flux sensor.
        """
        if self._w is None:
            raise ControlError("ImpedanceController.command_impedance before start()")
        bias_q, bias_s = self._offsets(self.true_flux_w_m2 - self.model_flux_w_m2(),
                                       pad_temp_c - (self._ref_c + float(self._m_surface @ self._w)))
        memory = float(self._past_decay @ self._flux_memory) + \
            float(self._future_free @ self._w) + self._future_sum * bias_q
        surface_free = self._ref_c + float(self._surface_free @ self._w) + bias_s
        du = (object_temp_c - surface_free - inverse_effusivity * memory) / \
            (self._surface_gain + inverse_effusivity * self._future_gain)
        return self._ref_c + du
