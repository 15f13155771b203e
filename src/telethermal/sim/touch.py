"""One touch's simulated world on the master's side: the draws of a touch
(slave and master apart, so every driver of a touch sees the same physics
for one seed), the operator (drawn like a person of database 2: finger
temperature, skin properties, pressing force, hence the contact
conductance) and the display pad under the finger with its sensors
(:class:`DisplayTouch`).

The product never imports this module: the services reach the simulated
display through the device registry (``devices = "sim"`` or
``"emulated"``), the in-process session (:mod:`telethermal.sim.inprocess`)
and the simulated network (:mod:`telethermal.sim.network`) build it
directly.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from telethermal.devices.readings import PadSensors
from telethermal.errors import SceneError
from telethermal.physics.as_built import simulated_display
from telethermal.physics.layered import Boundary, Layer, LayeredContact
from telethermal.physics.materials import get_material
from telethermal.physics.scene import Scene
from telethermal.physics.sensors import ForceSensor, quantise
from telethermal.physics.thermoelectric import (JunctionSensorSpec, ModuleState,
                                                ThermoelectricStack)
from telethermal.sim.plant import DisplayPlant
from telethermal.teleop.session import PRE_CONTACT_S

#: The session's time the display's trace runs on after the finger lifts (s).
AFTER_RELEASE_S = 0.2


def master_rng(seed: int) -> np.random.Generator:
    """The master side's draws for a touch (operator, display sensors). Apart
    from the slave's (:func:`~telethermal.teleop.slave.slave_rng`), so a
    networked touch with the same seed sees the very same physics as the
    in-process session."""
    return np.random.default_rng([seed, 1])


@functools.lru_cache(maxsize=16)
def display_model(pad_layers: tuple[Layer, ...], t_max_s: float, t_min_s: float) -> LayeredContact:
    """The display pad (junction behind its layers) on a semi-infinite fingertip."""
    return LayeredContact(pad_layers, (Layer(get_material("skin"), math.inf),),
                          Boundary("isothermal"), Boundary("adiabatic"), t_min_s, t_max_s)


@dataclass
class Operator:
    finger_c: float
    finger_ir_c: float
    skin_k_scale: float
    skin_heat_scale: float
    force_n: float
    conductance_w_m2k: float
    #: The master pad's thermocouple bias in this session (its reading is
    #: the surface plus this; the finger thermometer is calibrated against it).
    pad_tc_bias_k: float = 0.0


def draw_operator(scene: Scene, rng: np.random.Generator, session=None) -> Operator:
    """The operator of one touch; the finger's temperature by the master's
    thermometer in ``session`` (drawn from ``rng`` and calibrated, unless given)."""
    from telethermal.data.generate import sensor_session

    session = session or sensor_session(scene, rng, role="master")
    finger, var = scene.finger, scene.variability
    finger_c = float(rng.normal(finger.temp_c, finger.temp_sd_c))
    k, c = np.exp(rng.normal(0.0, finger.property_sd, 2))
    force = float(np.clip(rng.normal(var.force_n, var.force_sd_n), 0.3 * var.force_n,
                          3 * var.force_n))
    h = finger.contact_conductance_w_m2k * (force / var.reference_force_n) ** var.conductance_force_exponent
    ir = float(session.measure_c(np.array([finger_c]), rng)[0])
    return Operator(finger_c, ir, float(k), float(c), force, float(h),
                    float(session.instruments.pad_tc_bias_k))


class DisplayTouch:
    """The master's hardware for one touch, simulated: the operator's finger
    and pressing force, the display pad under it, and the pad's sensors.

    Session time 0 is the finger's true contact; it lasts ``contact_s``.
    ``sense(t)`` reads the sensors, ``actuate(t, step, dt_loop, force_n)``
    drives the module with the step's current for the period (stepping the
    physics through a stall of the loop), and every period is recorded in
    ``trace``.

    The pad is built as ``[as_built.display]`` says (``built``: its layers,
    flux sensor, module, contact and junction sensor's lag off the scene's
    design; the scene's own pad without it). Its Peltier module is a
    :class:`~telethermal.physics.thermoelectric.ThermoelectricStack`. Before
    contact the pad's layers sit in air (their front face taken as
    adiabatic) and move with the junction as one lumped mass; at contact they
    start uniform at the junction's temperature (the pad has idled there)
    and the exact layered plant takes over, the module's state carried on.
    """

    #: The heat sink's thermistor: NTC 10 kOhm, +-1 % at 25 C (TDK/EPCOS
    #: B57861S: about +-0.25 K, a bias per instrument), read at 0.01 K with
    #: 0.01 K of noise per reading; its lag (seconds) is far under the
    #: sink's own (36 J/K on 1 K/W). The junction's sensor is the pad's
    #: part (``junction_sensor``, physics/modules.toml): bonded to the cold
    #: plate, it reads the junction through its own first-order lag.
    THERMISTOR_BIAS_LIMIT_K = 0.25
    THERMISTOR_NOISE_K = 0.01
    THERMISTOR_LSB_K = 0.01

    def __init__(self, scene: Scene, operator: Operator, rate_hz: float, contact_s: float,
                 idle_c: float, rng: np.random.Generator,
                 junction_sensor: JunctionSensorSpec | None = None,
                 junction_lag_scale: float = 1.0):
        self.scene, self.operator, self.contact_s = scene, operator, contact_s
        self.dt_s = 1.0 / rate_hz
        #: The pad as built (``[as_built.display]``; the scene's nominal pad without it).
        self.built = built = simulated_display(scene)
        self.layers = built.layers
        self.model = display_model(self.layers, round(contact_s + 1.0, 3), min(self.dt_s, 1e-3))
        sens = scene.sensors
        self.flux_sensor = sens.flux_sensor(lag_s=built.flux_lag_s)
        self.force_sensor = ForceSensor()
        self.n_total = int(round((PRE_CONTACT_S + contact_s + AFTER_RELEASE_S) * rate_hz))
        self.noise = rng.normal(size=(self.n_total + 1, 3))
        self.trace = {k: np.full(self.n_total, np.nan) for k in (
            "t_s", "desired_flux_w_m2", "flux_w_m2", "flux_sensed_w_m2", "pad_surface_c",
            "skin_surface_c", "junction_cmd_c", "junction_c", "safe", "force_n")}
        self.trace["phase"] = np.empty(self.n_total, dtype=object)
        self.k = 0
        self.plant = None
        self.junction_c = idle_c
        self._reading = None
        self._module_reading = (idle_c, scene.room_temp_c)
        self._current_a = 0.0
        # The module (as built), idling at ``idle_c`` on a sink at the room's temperature.
        sink = scene.pad.module_params()[1]
        self.module = built.module
        self.area_m2 = scene.pad.area_m2            # the pad's face: the module's by default
        self.stack = ThermoelectricStack(self.module, sink, scene.room_temp_c,
                                         ModuleState(idle_c, scene.room_temp_c,
                                                     scene.room_temp_c))
        self._pad_heat_j_k = self.area_m2 * sum(
            layer.material.volumetric_heat_j_m3k * layer.thickness_m for layer in self.layers)
        # The part the scene names, at its stated lag (the controller's
        # design figure) times the as-built factor below.
        self.junction_sensor = junction_sensor or scene.sensors.junction_sensor_spec()
        if not (junction_lag_scale >= 0 and math.isfinite(junction_lag_scale)):
            raise SceneError(f"junction_lag_scale must be finite and >= 0, got "
                             f"{junction_lag_scale!r}")
        #: The junction sensor's true lag in this session (its stated one
        #: times ``junction_lag_scale``: a part off its datasheet, a bond
        #: thicker than designed).
        self.junction_lag_s = self.junction_sensor.tau_s * junction_lag_scale \
            * built.junction_lag_factor
        self._junction_sensed_c = idle_c       # the bonded chip's own temperature
        js = self.junction_sensor
        self.thermistor_bias_k = rng.uniform(-1, 1, 2) * (js.bias_limit_k,
                                                          self.THERMISTOR_BIAS_LIMIT_K)
        self.thermistor_noise = rng.normal(size=(self.n_total + 1, 2))
        #: Periods past the module's datasheet limits (current above Imax,
        #: hot side above its rating): the driver bounds the current, so
        #: these count what the physics would do if it did not.
        self.limit_counts = {"current_exceeded": 0, "hot_side_exceeded": 0}
        self.max_current_a = 0.0
        self.max_hot_c = self.stack.state.hot_c
        self.max_sink_c = self.stack.state.sink_c
        for key in ("current_a", "hot_c", "sink_c", "junction_true_c"):
            self.trace[key] = np.full(self.n_total, np.nan)

    @property
    def done(self) -> bool:
        return self.k >= self.n_total

    def touching(self, t: float) -> bool:
        return 0.0 <= t < self.contact_s

    def release_at(self, t: float) -> None:
        """The operator lifts the finger at ``t`` (s), before the planned end."""
        if t < self.contact_s:
            self.contact_s = max(t, 0.0)
            self.n_total = min(self.n_total, self.k + int(round(AFTER_RELEASE_S / self.dt_s)))

    def sense(self, t: float) -> PadSensors:
        op = self.operator
        touching = self.touching(t)
        if touching and self.plant is None:
            # Contact: the pad, held at the junction temperature, meets the finger.
            self.plant = DisplayPlant(self.model, self.junction_c, op.finger_c,
                                      op.conductance_w_m2k * self.built.contact_factor,
                                      self.dt_s, self.built.flux_lag_s,
                                      op.skin_k_scale, op.skin_heat_scale)
        if touching:
            r = self.plant.read()
            reading = (r.contact_flux_w_m2, r.flux_w_m2, r.pad_surface_c, r.skin_surface_c)
        else:
            reading = (0.0, 0.0, self.junction_c, math.nan)
        self._reading = reading
        fs, noise = self.flux_sensor, self.noise[min(self.k, self.n_total)]
        # The sensor's true sensitivity is its nominal one times its gain as built.
        flux = quantise(reading[1] * fs.sensitivity_uv_per_w_m2 * self.built.flux_gain
                        + fs.noise_uv_rms * noise[0], fs.adc_lsb_uv) / fs.sensitivity_uv_per_w_m2
        # The thermocouple at the surface: its session's bias, 1 uV ~ 0.025 K of noise.
        pad = reading[2] + op.pad_tc_bias_k + 0.025 * noise[1]
        force = (op.force_n * -math.expm1(-t / self.force_sensor.rise_s) if touching else 0.0) \
            + self.force_sensor.noise_n_rms * noise[2]
        st, tn = self.stack.state, self.thermistor_noise[min(self.k, self.n_total)]
        js = self.junction_sensor
        junction, sink = (quantise(true + bias + noise_k * n, lsb) for true, bias, noise_k, lsb, n
                          in zip((self._junction_sensed_c, st.sink_c), self.thermistor_bias_k,
                                 (js.noise_k, self.THERMISTOR_NOISE_K),
                                 (js.lsb_k, self.THERMISTOR_LSB_K), tn))
        self._module_reading = (float(junction), float(sink))
        return PadSensors(float(flux), float(pad), float(force), float(junction), float(sink))

    def module_state(self) -> tuple[float, float, float]:
        """(junction_c, heatsink_c, current_a) as the module's driver board
        measures them (its thermistors, last read; the current it drives)."""
        junction, sink = self._module_reading
        return junction, sink, self._current_a

    def _drive(self, current_a: float) -> None:
        """One physics period of the module at ``current_a``."""
        if self.plant is not None:
            _, heat = self.plant.step_current(self.stack, current_a, self.area_m2)
        else:
            # In air: the pad's layers move with the junction as one mass.
            c = self._pad_heat_j_k / self.dt_s
            heat = self.stack.step(current_a, self.dt_s, c * self.stack.state.cold_c, -c)
        st = self.stack.state
        # The bonded sensor's exact first-order step toward the period's end value.
        lag = self.junction_lag_s
        gain = 1.0 if lag <= 0 else -math.expm1(-self.dt_s / lag)
        self._junction_sensed_c += gain * (st.cold_c - self._junction_sensed_c)
        self.limit_counts["current_exceeded"] += int(abs(heat.current_a) > self.module.spec.imax_a)
        self.limit_counts["hot_side_exceeded"] += int(st.hot_c > self.module.spec.hot_side_max_c)
        self.max_current_a = max(self.max_current_a, abs(heat.current_a))
        self.max_hot_c = max(self.max_hot_c, float(st.hot_c))
        self.max_sink_c = max(self.max_sink_c, float(st.sink_c))

    def actuate(self, t: float, step, dt_loop: float, force_n: float) -> None:
        current = self._current_a = float(step.current_a)
        for _ in range(max(1, round(dt_loop / self.dt_s))):
            self._drive(current)
        self.junction_c = self.stack.state.cold_c
        if self.k < self.n_total:
            st = self.stack.state
            for key, value in (("current_a", current), ("hot_c", st.hot_c),
                               ("sink_c", st.sink_c), ("junction_true_c", st.cold_c)):
                self.trace[key][self.k] = value
            true_flux, sensed, pad_c, skin_c = self._reading
            for key, value in (("t_s", t), ("desired_flux_w_m2", step.desired_flux_w_m2),
                               ("flux_w_m2", true_flux), ("flux_sensed_w_m2", sensed),
                               ("pad_surface_c", pad_c), ("skin_surface_c", skin_c),
                               ("junction_cmd_c", step.junction_cmd_c),
                               ("junction_c", step.junction_applied_c), ("safe", step.safe),
                               ("force_n", force_n)):
                self.trace[key][self.k] = value
            self.trace["phase"][self.k] = step.phase
        self.k += 1


class MasterWorld:
    """The master's side of one simulated touch, drawn from ``seed`` as
    every driver of a touch draws it: the operator first (the display idles
    for the finger's temperature), then the display pad under the finger
    (:meth:`display`, once the display's idle temperature is known). The
    master service reaches it by name (``devices/simulated.py``)."""

    def __init__(self, scene: Scene, seed: int):
        self.scene = scene
        self._rng = master_rng(seed)
        self.operator = draw_operator(scene, self._rng)

    def display(self, rate_hz: float, contact_s: float, idle_c: float, **kw) -> DisplayTouch:
        """The display pad under the operator's finger for a touch of
        ``contact_s``, idled at ``idle_c`` (``kw``: :class:`DisplayTouch`'s)."""
        return DisplayTouch(self.scene, self.operator, rate_hz, contact_s, idle_c, self._rng, **kw)
