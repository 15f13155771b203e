"""The design of the display's junction loop for the sensor it reads.

The loop (:class:`~telethermal.control.junction.DisplayJunctionLoop`) is two
degrees of freedom: a feed-forward from the module model makes the junction
follow a smoothed target, and a PI closes the loop on what the bonded
junction sensor reads against what that sensor would read if the junction
followed the target. The PI only has to remove what the model misses, so
its crossover can sit where the sensor's lag allows it.

The design model (all from the configuration: the module's datasheet, the
pad's layers, the nominal contact and the sensor's stated lag; never the
simulator's objects):

``P(s) = b / (s + a) * 1 / (tau s + 1) * exp(-s d)``

* ``b = S Tc / C`` (K/(A s)): the module's pump per ampere at the design
  point over the heat capacity the junction moves with: its own (copper tabs
  and half the pellets) and the pad's layers (at the loop's crossover,
  0.1-1 Hz, heat penetrates ``sqrt(2 alpha / omega)`` >= 0.3 mm of the film,
  all of it: the layers move with the junction);
* ``a = G / C`` (1/s): the junction's losses, to the hot side through the
  module (K) and to the finger through the layers and the contact;
* ``tau``: the junction sensor's time constant as mounted;
* ``d``: one control period (the reading of a period acts in the next).

The PI ``kp (1 + wi / s)`` puts its zero a fifth of the crossover below it
and the crossover where the loop's phase margin is the one asked for
(60 degrees by default); :func:`loop_margins` checks both with
python-control on the design model, the delay as a third-order Pade
approximant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from telethermal.errors import ControlError
from telethermal.physics.thermoelectric import KELVIN, ModuleParams

#: The PI's zero this far below the crossover (it costs atan(1/5) = 11 deg).
ZERO_FRACTION = 0.2
#: The phase margin asked for: robust to the sensor's lag between half and
#: twice its stated value (checked by loop_margins and in the tests).
PHASE_MARGIN_DEG = 60.0


@dataclass(frozen=True)
class JunctionPlantModel:
    """What the junction loop knows of its plant (see the module docstring)."""

    pump_w_a: float          # S Tc at the design point, W/A
    heat_j_k: float          # what the junction moves with, J/K
    loss_w_k: float          # its losses, W/K
    sensor_tau_s: float      # the junction sensor's lag, as stated
    delay_s: float           # one control period

    def __post_init__(self):
        if not (self.pump_w_a > 0 and self.heat_j_k > 0 and self.loss_w_k >= 0
                and self.sensor_tau_s >= 0 and self.delay_s >= 0):
            raise ControlError(f"junction plant model out of range: {self}")

    @property
    def b_k_as(self) -> float:
        return self.pump_w_a / self.heat_j_k

    @property
    def a_per_s(self) -> float:
        return self.loss_w_k / self.heat_j_k


def plant_model(params: ModuleParams, pad_layers, area_m2: float, conductance_w_m2k: float,
                sensor_tau_s: float, dt_s: float, design_c: float = 20.0) -> JunctionPlantModel:
    """The design model from the display's configuration: the module's
    parameters, the pad's layers (contact surface first), the face's area,
    the pad-finger contact conductance (0: the pad in air, its front
    adiabatic: the junction's smallest loss, hence the loop's least phase)
    and the sensor's stated lag."""
    layers = tuple(pad_layers)
    if not (area_m2 > 0 and conductance_w_m2k >= 0 and dt_s > 0):
        raise ControlError(f"plant_model needs area, conductance and dt > 0 (got {area_m2}, "
                           f"{conductance_w_m2k}, {dt_s})")
    heat = params.cold_heat_j_k + area_m2 * sum(
        layer.material.volumetric_heat_j_m3k * layer.thickness_m for layer in layers)
    r_layers = sum(layer.thickness_m / layer.material.conductivity_w_mk for layer in layers)
    to_finger_w_k = 0.0 if conductance_w_m2k == 0 else \
        area_m2 / (r_layers + 1.0 / conductance_w_m2k)
    return JunctionPlantModel(params.seebeck_v_k * (design_c + KELVIN), heat,
                              params.conductance_w_k + to_finger_w_k, sensor_tau_s, dt_s)


def _phase_deg(model: JunctionPlantModel, w: float) -> float:
    """The loop's phase at ``w`` (rad/s) with the PI zero at ZERO_FRACTION w."""
    return -math.degrees(math.atan(ZERO_FRACTION) + math.atan(w / max(model.a_per_s, 1e-12))
                                + math.atan(w * model.sensor_tau_s) + w * model.delay_s)


def design_gains(model: JunctionPlantModel, phase_margin_deg: float = PHASE_MARGIN_DEG):
    """(kp A/K, ki A/(K s), crossover rad/s) for the phase margin asked for,
    on the design model (its phase falls monotonically with w: bisection)."""
    target = -180.0 + phase_margin_deg
    lo, hi = 1e-4, 1e5
    if _phase_deg(model, lo) < target:
        raise ControlError(f"no crossover gives {phase_margin_deg} deg of phase margin")
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if _phase_deg(model, mid) > target else (lo, mid)
    wc = lo
    a, b, tau = model.a_per_s, model.b_k_as, model.sensor_tau_s
    plant_mag = b / math.hypot(wc, a) / math.hypot(1.0, wc * tau)
    pi_mag = math.hypot(1.0, ZERO_FRACTION)
    kp = 1.0 / (plant_mag * pi_mag)
    return kp, kp * ZERO_FRACTION * wc, wc


@dataclass(frozen=True)
class LoopMargins:
    phase_margin_deg: float
    crossover_rad_s: float
    gain_margin: float
    bandwidth_hz: float       # -3 dB of the closed loop (reading -> target)


def loop_margins(model: JunctionPlantModel, kp_a_k: float, ki_a_ks: float,
                 sensor_tau_s: float | None = None) -> LoopMargins:
    """Phase margin, crossover, gain margin and closed-loop bandwidth of the
    PI on ``model`` (its sensor lag replaced by ``sensor_tau_s`` if given: a
    sensor off its datasheet), by python-control."""
    import control as ct

    tau = model.sensor_tau_s if sensor_tau_s is None else sensor_tau_s
    s = ct.tf("s")
    plant = model.b_k_as / (s + model.a_per_s) / (tau * s + 1)
    if model.delay_s > 0:
        num, den = ct.pade(model.delay_s, 3)
        plant = plant * ct.tf(num, den)
    loop = (kp_a_k + ki_a_ks / s) * plant
    gm, pm, _wg, wc = ct.margin(loop)
    closed = ct.feedback(loop, 1)
    return LoopMargins(float(pm), float(wc), float(gm), float(ct.bandwidth(closed)) / (2 * math.pi))


def design_display_loop(params: ModuleParams, pad_layers, area_m2: float, sensor_tau_s: float,
                        dt_s: float, reference_tau_s: float, slew_a_s: float):
    """The display's junction loop designed for its sensor, and the design
    (gains, crossover, the model's heat capacity): on the pad in air, the
    junction's least loss and so the loop's least phase (it idles there;
    a finger adds loss, hence phase margin)."""
    from telethermal.control.junction import DisplayJunctionLoop, JunctionGains
    from telethermal.physics.thermoelectric import default_driver

    model = plant_model(params, pad_layers, area_m2, 0.0, sensor_tau_s, dt_s)
    kp, ki, wc = design_gains(model)
    design = {"kp_a_k": kp, "ki_a_ks": ki, "crossover_rad_s": wc,
              "phase_margin_deg": PHASE_MARGIN_DEG, "sensor_tau_s": sensor_tau_s,
              "heat_j_k": model.heat_j_k}
    return DisplayJunctionLoop(params, default_driver(params), model, JunctionGains(kp, ki),
                               reference_tau_s, slew_a_s), design
