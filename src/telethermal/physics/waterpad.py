"""The water-circulation gripper pad of active-heat-flow-sensing, eq. (11)-(12).

STEP 1 of that paper: before contact, a PI controller drives the Peltier
element to its command, the Peltier heats or cools a small water tank, and an
on/off micro-pump circulates the water under the pad surface when the pad is
away from its command ``T_g^cmd = T_object + gap`` (eq. 13). With the pump off
only natural convection couples water and pad, which is the state kept during
contact (STEP 2) so the sensor sees the object's natural heat flow.

States per trial: Peltier ``T_p``, water ``T_w``, pad ``T_g`` (degC):

    C_p dT_p/dt = u - (T_p - T_w)/R_w - (T_p - T_a)/R_pa
    C_w dT_w/dt = (T_p - T_w)/R_w - (T_w - T_g)/R_g          (11)
    C_g dT_g/dt = (T_w - T_g)/R_g - (T_g - T_a)/R_a          (12)

``u`` (W, saturated at +-``u_max_w``) comes from the PI; ``R_g`` is
``r_g_pump_on`` or ``r_g_pump_off``. The system is linear for each pump state,
so each step is the exact zero-order-hold discretisation (matrix exponential,
computed once per pump state): stable at any step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from telethermal.errors import ModelError


@dataclass(frozen=True, slots=True)
class WaterPadParams:
    """Lumped parameters of a 15 x 15 mm water-cooled pad (SI units)."""

    c_p_j_k: float = 2.0
    c_w_j_k: float = 10.0
    c_g_j_k: float = 0.5
    r_w_k_w: float = 2.0
    r_pa_k_w: float = 50.0
    r_a_k_w: float = 220.0
    r_g_pump_on_k_w: float = 4.0
    r_g_pump_off_k_w: float = 150.0
    u_max_w: float = 6.0
    kp_w_k: float = 3.0
    ki_w_ks: float = 0.3
    pump_on_error_k: float = 0.3
    pump_off_error_k: float = 0.1
    #: The Peltier is driven this far beyond the pad command (away from room),
    #: so the water can make up the pad's losses and the pump has work to do.
    peltier_overdrive_k: float = 1.0


@dataclass
class WaterPadRun:
    """Result of :func:`precondition`; arrays are (n_steps, batch) or (batch,)."""

    t_s: np.ndarray
    temp_peltier_c: np.ndarray
    temp_water_c: np.ndarray
    temp_pad_c: np.ndarray
    pump_on: np.ndarray
    peltier_w: np.ndarray

    @property
    def final_pad_c(self) -> np.ndarray:
        return self.temp_pad_c[-1]

    @property
    def final_water_c(self) -> np.ndarray:
        return self.temp_water_c[-1]


def _discretise(p: WaterPadParams, r_g: float, dt_s: float):
    """Exact ZOH matrices (A_d, B_d) for inputs [u, T_a]."""
    a = np.array([
        [-(1 / p.r_w_k_w + 1 / p.r_pa_k_w) / p.c_p_j_k, 1 / (p.r_w_k_w * p.c_p_j_k), 0.0],
        [1 / (p.r_w_k_w * p.c_w_j_k), -(1 / p.r_w_k_w + 1 / r_g) / p.c_w_j_k, 1 / (r_g * p.c_w_j_k)],
        [0.0, 1 / (r_g * p.c_g_j_k), -(1 / r_g + 1 / p.r_a_k_w) / p.c_g_j_k],
    ])
    b = np.array([[1 / p.c_p_j_k, 1 / (p.r_pa_k_w * p.c_p_j_k)],
                  [0.0, 0.0],
                  [0.0, 1 / (p.r_a_k_w * p.c_g_j_k)]])
    block = np.zeros((5, 5))
    block[:3, :3], block[:3, 3:] = a, b
    e = expm(block * dt_s)
    return e[:3, :3], e[:3, 3:]


class WaterPad:
    """STEP 1 as a loop: the pad's PI and pump logic and its exact plant, one
    control period per :meth:`step`, for a batch of pads (arrays of shape (B,)).

    The slave service runs one of these before contact; :func:`precondition`
    runs it for the databases.
    """

    def __init__(self, target_pad_c, room_c: float, dt_s: float,
                 params: WaterPadParams = WaterPadParams(), start_c=None):
        if not (dt_s > 0 and np.isfinite(dt_s)):
            raise ModelError(f"water pad control period must be > 0, got {dt_s}")
        self.params, self.room_c, self.dt_s = params, float(room_c), dt_s
        self._mats = {on: _discretise(params, params.r_g_pump_on_k_w if on else
                                      params.r_g_pump_off_k_w, dt_s) for on in (False, True)}
        self.retarget(target_pad_c)
        start = np.full_like(self.target_c, room_c) if start_c is None else \
            np.broadcast_to(np.asarray(start_c, dtype=np.float64), self.target_c.shape)
        #: (B, 3): the Peltier's, the water's and the pad's temperatures.
        self.temps_c = np.stack([start, start, start], axis=1).astype(np.float64)
        self.integral_ks = np.zeros_like(self.target_c)    # the PI's integral, K s
        self.pump = np.zeros(self.target_c.shape, dtype=bool)
        self.u_w = np.zeros_like(self.target_c)            # the Peltier's heat, W

    def retarget(self, target_pad_c) -> None:
        """A new pad command ``T_object + gap`` (e.g. a new IR reading)."""
        target = np.atleast_1d(np.asarray(target_pad_c, dtype=np.float64))
        if not np.all(np.isfinite(target)):
            raise ModelError(f"water pad command must be finite, got {target}")
        self.target_c = target
        self.peltier_cmd_c = target + self.params.peltier_overdrive_k * \
            np.sign(target - self.room_c)

    @property
    def pad_c(self) -> np.ndarray:
        return self.temps_c[:, 2]

    @property
    def water_c(self) -> np.ndarray:
        return self.temps_c[:, 1]

    def step(self, pump_allowed: bool = True) -> None:
        """One period: PI on the Peltier, pump on/off on the pad's lag."""
        p, dt, x = self.params, self.dt_s, self.temps_c
        err_p = self.peltier_cmd_c - x[:, 0]
        u_raw = p.kp_w_k * err_p + p.ki_w_ks * (self.integral_ks + err_p * dt)
        u = np.clip(u_raw, -p.u_max_w, p.u_max_w)
        self.integral_ks = np.where(u == u_raw, self.integral_ks + err_p * dt,  # anti-windup
                                    self.integral_ks)
        # Pump on while the pad lags its command (towards the Peltier side),
        # off once it is within pump_off_error_k of it or past it.
        lag = (self.target_c - x[:, 2]) * np.sign(self.target_c - self.room_c)
        pump = np.where(lag > p.pump_on_error_k, True,
                        np.where(lag < p.pump_off_error_k, False, self.pump))
        if not pump_allowed:
            pump[:] = False
        x_next = np.empty_like(x)
        for on in (False, True):
            sel = pump == on
            if sel.any():
                ad, bd = self._mats[on]
                inputs = np.stack([u[sel], np.full(sel.sum(), self.room_c)], axis=1)
                x_next[sel] = x[sel] @ ad.T + inputs @ bd.T
        self.temps_c, self.pump, self.u_w = x_next, pump, u


def precondition(target_pad_c, room_c: float, duration_s: float, dt_s: float = 0.05,
                 params: WaterPadParams = WaterPadParams(), start_c=None) -> WaterPadRun:
    """Run STEP 1 for a batch of pads, each driven to its own command.

    Parameters
    ----------
    target_pad_c : ndarray, shape (B,)
        Pad temperature commands ``T_object + gap``, degC.
    room_c : float
        Air temperature, degC.
    duration_s, dt_s : float
        Length of the pre-conditioning and the control period, s.
    start_c : ndarray, shape (B,), optional
        Initial temperature of all three nodes (default: room).

    Returns
    -------
    WaterPadRun
        The pump is left off at the end (the state kept during contact).
    """
    if not (dt_s > 0 and duration_s >= dt_s):
        raise ModelError(f"need 0 < dt_s <= duration_s, got {dt_s}, {duration_s}")
    pad = WaterPad(target_pad_c, room_c, dt_s, params, start_c)
    n = int(round(duration_s / dt_s))
    hist = np.empty((n, 5, len(pad.target_c)))
    for k in range(n):
        pad.step(pump_allowed=k < n - 1)
        hist[k, :3], hist[k, 3], hist[k, 4] = pad.temps_c.T, pad.pump, pad.u_w
    return WaterPadRun(dt_s * np.arange(1, n + 1), hist[:, 0], hist[:, 1], hist[:, 2],
                       hist[:, 3].astype(bool), hist[:, 4])
