"""The master's display as a plant for a control loop: the Peltier pad under
the operator's finger, stepped at a fixed period.

The pad's layers see the Peltier module's cold junction behind them. Two
ways to step:

* :meth:`DisplayPlant.step_current` (what the display runs): the module's
  current is the input, held over the period. The cold junction is a node of
  :class:`~telethermal.physics.thermoelectric.ThermoelectricStack` (with the
  hot side and the heat sink); the layers' period-mean heat flow into it is
  exact and affine in the junction's end temperature, so the stack solves
  the junction's temperature implicitly and the layers then take their exact
  step with it held.
* :meth:`DisplayPlant.step` (``junction_c`` held over the period): the
  layers alone, an ideal temperature source behind them. Used for the exact
  checks and for the floor's unbounded reference, never by the display.

Each layer step is exact: in the modal form of
:class:`~telethermal.physics.layered.LayeredContact` every mode moves by
``w <- exp(-lam dt) w + phi(lam, dt) f_unit (u - T_ref)``, and the heat-flux
sensor's first-order lag by its own exact one-step map, so a step costs
O(cells) and holds at any period.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from telethermal.errors import ControlError
from telethermal.physics.layered import LayeredContact
from telethermal.physics.modal import _psi, lag_kernels, phi_any
from telethermal.physics.thermoelectric import ModuleStep, ThermoelectricStack


@dataclass(frozen=True, slots=True)
class PlantReading:
    t_s: float
    flux_w_m2: float             # as the pad's sensor reads it (lagged)
    contact_flux_w_m2: float     # true flux from the pad into the finger
    pad_surface_c: float
    skin_surface_c: float
    junction_c: float = float("nan")     # the module's cold junction (nan: no module)


class DisplayPlant:
    """Pad (side a, junction behind it) pressed on the finger (side b).

    Parameters
    ----------
    model : LayeredContact
        Pad layers as side a (isothermal back = the junction), the finger as side b.
    pad_temp_c, finger_temp_c : float
        Uniform temperatures at contact (t = 0).
    conductance_w_m2k : float
        Pad-finger contact conductance.
    dt_s : float
        Control period.
    sensor_lag_s : float, optional
        Time constant of the pad's heat-flux sensor (none: reads the true flux).
    skin_k_scale, skin_heat_scale : float
        This operator's skin conductivity and rho*c relative to the nominal skin.
    """

    def __init__(self, model: LayeredContact, pad_temp_c: float, finger_temp_c: float,
                 conductance_w_m2k: float, dt_s: float, sensor_lag_s: float | None = None,
                 skin_k_scale: float = 1.0, skin_heat_scale: float = 1.0):
        if not dt_s > 0:
            raise ControlError(f"plant period must be > 0, got {dt_s}")
        one = np.ones(1)
        ta, tb = np.array([pad_temp_c], float), np.array([finger_temp_c], float)
        scales = (one, one, one * skin_k_scale, one * skin_heat_scale)
        system = model.modal_system(ta, tb, np.array([conductance_w_m2k], float), scales,
                                    finger_temp_c + 1.0, None, 5)
        self._ref_c = finger_temp_c
        lam, f_unit = system.lam[0], system.f[0]
        self._m = system.m[0][:3]
        # The heat flow from the junction into the layers, W/m^2: g_back u + m4 . w;
        # over a period with u held its mean is back_w . w0 + back_u u.
        self._stored_row = system.m[0][3]
        m4, g_back = system.m[0][4], float(system.g_ba[0])
        self._back_w = m4 * phi_any(lam, dt_s) / dt_s
        self._back_u = g_back + float(m4 @ (_psi(lam, dt_s) * f_unit)) / dt_s
        self._junction_c = pad_temp_c
        na = model.grid.n_a
        self._r_pad, self._r_skin = system.r_half[0, na - 1], system.r_half[0, na]
        self._decay = np.exp(-lam * dt_s)
        self._drive = phi_any(lam, dt_s) * f_unit
        self._w = system.w0[0].copy()
        self._dt = dt_s
        self._lag = None
        if sensor_lag_s:
            ge, gp = lag_kernels(lam, dt_s, sensor_lag_s)
            self._lag = (np.exp(-dt_s / sensor_lag_s), ge * self._m[0],
                         float((gp * f_unit) @ self._m[0]))
        self._sensed = 0.0
        self.t_s = 0.0

    def read(self) -> PlantReading:
        out = self._m @ self._w
        flux = float(out[0])
        return PlantReading(self.t_s, self._sensed if self._lag else flux, flux,
                            self._ref_c + float(out[1]) - flux * self._r_pad,
                            self._ref_c + float(out[2]) + flux * self._r_skin,
                            self._junction_c)

    def step_current(self, stack: ThermoelectricStack, current_a: float, area_m2: float
                     ) -> tuple[PlantReading, ModuleStep]:
        """Drive the module with ``current_a`` for one period (``stack`` is
        the module under this pad, its cold junction behind the layers;
        ``area_m2`` the area the layers' W/m^2 act on). Returns the reading
        at the period's end and the module's heat for the period."""
        if not np.isfinite(current_a):
            raise ControlError(f"module current must be finite, got {current_a}")
        # Heat into the junction from the layers, W: -(area) (back_w . w + back_u u),
        # u = Tc - ref: affine in the junction's end temperature Tc.
        a_w = -area_m2 * (float(self._back_w @ self._w) - self._back_u * self._ref_c)
        b_w_k = -area_m2 * self._back_u
        heat = stack.step(current_a, self._dt, a_w, b_w_k)
        return self.step(stack.state.cold_c), heat

    def step(self, junction_c: float) -> PlantReading:
        """Hold the junction at ``junction_c`` for one period; read at its end."""
        if not np.isfinite(junction_c):
            raise ControlError(f"junction temperature must be finite, got {junction_c}")
        u = junction_c - self._ref_c
        if self._lag:
            e_tau, ge_m, gp_m = self._lag
            self._sensed = e_tau * self._sensed + float(ge_m @ self._w) + gp_m * u
        self._w = self._decay * self._w + self._drive * u
        self._junction_c = float(junction_c)
        self.t_s += self._dt
        return self.read()

    def stored_j_m2(self) -> float:
        """Heat in the layers and the finger relative to the finger's initial
        temperature, J/m^2 (for balance checks; the modal state's own sum)."""
        return float(self._stored_row @ self._w)
