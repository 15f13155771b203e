"""An in-process telepresence session on the simulator: the slave touches
the object, identifies it, the master renders the flux, and the result is
compared with the operator's finger touching the object directly.

The finger touches at session time 0. The two sides run the services'
session rules (:mod:`telethermal.teleop.session`) over a wire with no delay
(:class:`InProcessWire`): the slave's pad goes down when the master's
contact onset reaches it (the paper has both sides touch at once,
learning-based-thermal-rendering: "contact is established at the same time
both in the master and the slave side"; the product's slave waits for the
master's onset, a debounce later), and what the slave sends, the master
reads the same period. The master runs its loop at ``config.rate_hz`` on a
simulated clock (exact and instant) or on the real clock (``realtime=True``:
the same loop, sleeping to absolute deadlines, its period measured).

The operator is drawn like a person of database 2: finger temperature,
skin properties, pressing force (hence the contact conductance); the same
draws give the direct-contact reference, so the comparison is with what
*this* finger would have felt.
"""

from __future__ import annotations

import contextlib
import functools
import math
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from telethermal.control.loop import (FixedRateLoop, LoopStats, RealClock, SessionClock,
                                      SimClock, WorldPausedClock, master_step_summary,
                                      session_clock)
from telethermal.control.dew import dew_point_c
from telethermal.devices.sim_plant import DisplayPlant
from telethermal.errors import SceneError
from telethermal.ident.anytime import Estimate, Label, Reason
from telethermal.ident.fitted import clear_cache as clear_fits
from telethermal.ident.openset import touch_text
from telethermal.physics.as_built import simulated_display
from telethermal.physics.layered import Boundary, Layer, LayeredContact
from telethermal.physics.layered import pad_resistance  # noqa: F401  (its importers')
from telethermal.physics.materials import get_material
from telethermal.physics.scene import FingerSpec, Scene
from telethermal.physics.sensors import ForceSensor, quantise
from telethermal.physics.thermoelectric import (JunctionSensorSpec, ModuleState,
                                                ThermoelectricStack)
from telethermal.devices.readings import PadSensors
from telethermal.teleop.decision import pad_decision
from telethermal.teleop.direct import CORRECT_WITHIN, compare_with_direct  # noqa: F401
from telethermal.teleop.display_setup import (display_idle, display_model_args,  # noqa: F401
                                              module_summary, safety_summary)
from telethermal.teleop.inprocess import PRE_CONTACT_S, InProcessWire
from telethermal.teleop.master import DisplayConfig
from telethermal.teleop.memory import ObjectMemory, memory_counts
from telethermal.teleop.perception import heat_extraction_ratio, skin_above_threshold_s
from telethermal.teleop.slave import Slave

#: The fingertip used where a scene has none (the gripper scenes): the
#: first paper's operator, nominal skin.
DEFAULT_FINGER = FingerSpec(temp_c=33.0, temp_sd_c=0.8, persons=5, trials_per_person=10,
                            contact_duration_s=60.0, contact_conductance_w_m2k=5000.0,
                            property_sd=0.12)
AFTER_RELEASE_S = 0.2


def slave_rng(seed: int) -> np.random.Generator:
    """The slave side's draws for a touch (object, pad, sensors)."""
    return np.random.default_rng([seed, 0])


def master_rng(seed: int) -> np.random.Generator:
    """The master side's draws for a touch (operator, display sensors). Apart
    from the slave's, so a networked touch with the same seed sees the very
    same physics as the in-process session."""
    return np.random.default_rng([seed, 1])


def with_finger(scene: Scene) -> Scene:
    return scene if scene.finger is not None else replace(scene, finger=DEFAULT_FINGER)


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


def idle_surface_minus_dew_k(trace: dict, contact_s: float, dew_c: float | None):
    """The least of the pad's true surface temperature over the periods
    with nothing on it (before the contact and after the release) less the
    room's dew point, K: where dew would form, whatever the controller
    commanded. None in dry air (no dew point) or with no such period."""
    t, surface = trace["t_s"], trace["pad_surface_c"]
    free = ((t < 0) | (t >= contact_s)) & np.isfinite(surface)
    if dew_c is None or not free.any():
        return None
    return float(surface[free].min() - dew_c)


@dataclass
class SessionResult:
    summary: dict
    trace: dict          # arrays over the master's periods
    #: The loop's record and the master's step times (s): to pool sessions.
    loop_stats: LoopStats | None = None
    master_step_s: tuple = ()
    #: The slave's final estimate (what its object memory learns of the touch).
    slave_estimate: Estimate | None = None


def run_session(scene: Scene, material: str, identifier, generator,
                config: DisplayConfig = DisplayConfig(), contact_s: float = 5.0, seed: int = 0,
                realtime: SessionClock | bool | str = False, devices: str = "sim",
                record: str | Path | None = None, expected_material=None,
                news_filter=None, idle_scene: Scene | None = None,
                fresh_fits: bool = False, junction_lag_scale: float = 1.0,
                display_calibration=None) -> SessionResult:
    """One touch; see the module docstring. Returns the summary and the trace.
    ``devices``: "sim" (the simulator directly) or "emulated" (the master's
    sensor board on a pty and its Peltier driver on a CAN bus, emulated,
    read through the real drivers). ``record``: an MCAP file to record the
    session to (:mod:`telethermal.record.recording`). ``expected_material``:
    the slave's object memory holds it for this object (an earlier touch
    decided it; a label, or that touch's decided ``Estimate``: a new
    material's carries its effusivity), so the touch runs as a repeated one
    does in the services: announced, pre-conditioned for and rendered from
    memory at onset.
    ``realtime``: a :class:`~telethermal.control.loop.SessionClock`:
    SIMULATED (False), REAL (True: the simulated world's time charged to
    the loop) or WORLD_PAUSED ("master": the real clock less the time of
    the slave and the display's plant and sensors, other hardware).
    ``news_filter(news, t)``: what the master reads instead of the slave's
    news (:class:`~telethermal.teleop.inprocess.InProcessWire`; a bench's
    oracle or closed set), None: as the services run. ``idle_scene``: the
    scene whose idle policy the display applies (default ``scene``; a bench
    touching objects outside the trained ones gives the trained scene).
    ``fresh_fits``: the slave's fits made afresh, none of the process's
    kept ones (a run whose CPU is measured; always on the real clock).
    ``junction_lag_scale``: the display's junction sensor lags this many
    times its stated time constant (the controller is designed for the
    stated one: a robustness study). ``display_calibration``: the master's
    display calibration (``DisplayCalibration``): its flux lag in the
    controllers, its flux gain on the readings."""
    kind = session_clock(realtime, SceneError)
    realtime = kind != SessionClock.SIMULATED
    if realtime or fresh_fits:
        # Timed: the slave fits every window as a live slave does. The
        # effusivity fit keeps the process's fits, so a second run of one
        # touch made none (bench record's runs without recording paid them,
        # those with it did not; bench devices' sim run paid them for the
        # emulated one; bench render's CPU at 50 Hz exceeded 100 Hz's).
        clear_fits()
    if kind == SessionClock.WORLD_PAUSED and devices != "sim":  # driver, emulator: one thread
        raise SceneError(f"realtime='master' needs devices='sim' (got {devices!r}): the "
                         "driver's time and its emulator's cannot be told apart")
    from telethermal.devices.display import open_display
    from telethermal.record.recorder import SessionRecorder

    if not (contact_s > 0 and math.isfinite(contact_s)):
        raise SceneError(f"contact_s must be > 0, got {contact_s}")
    scene = with_finger(scene)
    slave = Slave(scene, material, identifier, slave_rng(seed))
    rng = master_rng(seed)
    operator = draw_operator(scene, rng)
    # The two sides' session rules, as the services run them, over a wire
    # with no delay: the slave's pad goes down when the master's onset
    # reaches it, the master renders what the slave sends (its sampled curves).
    memory = ObjectMemory()
    if isinstance(expected_material, Estimate):     # an earlier touch's own decision
        memory.learn(material, expected_material, -PRE_CONTACT_S, classes=identifier.classes_)
    elif expected_material is not None:   # an earlier touch of this object decided it
        label = Label.parse(expected_material)
        memory.learn(material, Estimate(0.0, (), label, 1.0, True, Reason.CONFIDENT_GROUP
                                        if label.is_group else Reason.CONFIDENT), -PRE_CONTACT_S)
    wire = InProcessWire(slave, generator, identifier, scene.sample_rate_hz, material,
                         memory=memory, news_filter=news_filter)
    # The master has idled at its standby before this touch: the object's
    # temperature, pre-conditioned for what the slave announced (object
    # memory) or, for an unknown object, by the idle policy (``config.idle``;
    # control/preconditioning.py).
    master = wire.set_up_display(scene, config, operator.finger_ir_c,
                                 idle_scene and with_finger(idle_scene), display_calibration)
    idle = wire.idle_c
    touch = DisplayTouch(scene, operator, config.rate_hz, contact_s, idle, rng,
                         junction_lag_scale=junction_lag_scale)
    now = [0.0]
    display = open_display(devices, touch, clock=lambda: now[0], realtime=bool(realtime),
                           seed=seed)
    recorder = SessionRecorder.open(record, scene, material, identifier, generator, config,
                                    operator, idle, seed, contact_s, devices,
                                    sampled=list(wire.curves), display=master) \
        if record else None

    # On the real clock, the master's own share of each period (its news,
    # display step and messages; not the simulated plants and slave that
    # share the loop's thread here and run on their own hardware in a lab).
    master_busy_s: list[float] = []

    clock = (WorldPausedClock if kind == SessionClock.WORLD_PAUSED else RealClock).for_period(
        1.0 / config.rate_hz) if realtime else SimClock()
    world = clock.world if isinstance(clock, WorldPausedClock) else contextlib.nullcontext

    def one_period(t_loop: float, dt_loop: float) -> bool:
        if touch.done:
            return False
        # Simulated time follows the loop: exact on the simulated clock, the
        # real elapsed time on the real one.
        t = now[0] = t_loop - PRE_CONTACT_S
        with world():
            wire.slave_period(t, deliver=False)
        wire.deliver(t)                 # the master's session reads it: the master's work
        with world():
            sensors = display.read(t)
        started = time.perf_counter()           # reported on the real clock only
        news, step = wire.master_step(t, dt_loop, sensors)
        master_busy_s.append(time.perf_counter() - started)
        with world():
            display.apply(t, step, dt_loop, sensors.force_n)
        if recorder is not None:
            recorder.period(t, dt_loop, sensors, news, step)
        return True

    try:
        stats = FixedRateLoop(1.0 / config.rate_hz, clock).run(one_period, touch.n_total)
    finally:
        device_counters = display.counters()
        display.close()
        wire.end(t_end=now[0])
        if recorder is not None:
            recorder.slave(slave)
    # What the touch decided, as every summary defines it (teleop/decision.py).
    decision = pad_decision(slave)
    est = decision.estimate
    # The slave's trial times are from its pad going down (at the master's
    # onset, as in the services); on the session's clock they are later by that.
    slave_t0 = wire.slave_t0_s or 0.0
    decided = est is not None and est.decided
    # The error "after identification" starts at the slave's first decision
    # (a material or a pair it is sure of), never where the master began to
    # render one material (that hides the transient between the two); when
    # the slave said only "unknown", where it said so.
    render_from = None
    if slave.onset_s is not None and decision.decision_time_s is not None:
        render_from = slave_t0 + slave.onset_s + decision.decision_time_s
    metrics = compare_with_direct(scene, material, slave.object_true_c, operator, touch.trace,
                                  contact_s, render_from)
    metrics["heat_extraction_ratio_first_s"] = heat_extraction_ratio(touch.trace)
    dew_c = dew_point_c(scene.room_temp_c, scene.room_humidity_pct) \
        if scene.room_humidity_pct > 0 else None
    metrics["skin_above_threshold_s"] = skin_above_threshold_s(touch.trace)
    summary = {
        "scene": scene.name, "material": material, "seed": seed,
        **decision.fields(),                   # identified, decision_time_s, identified_at_s
        "identified_correctly": decided and est.label == material,
        "decision_text": touch_text(est),      # a new material: with its estimate
        "decision_reason": est.reason if decided else Reason.NO_DECISION,
        "slave_onset_s": None if slave.onset_s is None else slave_t0 + slave.onset_s,
        "slave_touch_s": wire.slave_t0_s, "master_onset_s": master.last_onset_s,
        "master_release_s": master.last_release_s, "decision_from_s": render_from,
        "render_start_s": master.rendered_from_s,
        "before_identification": config.before, "rate_hz": config.rate_hz,
        "gains": asdict(config.gains), "contact_s": contact_s,
        "operator": asdict(operator), "object_true_c": slave.object_true_c,
        "object_ir_c": slave.object_ir_c, "slave_pad_before_c": slave.pad_before_c,
        "display_idle_c": idle,
        "dew_point_c": dew_c,
        "idle_surface_minus_dew_k": idle_surface_minus_dew_k(touch.trace, touch.contact_s, dew_c),
        "room_humidity_pct": scene.room_humidity_pct,
        "expected_material": None if expected_material is None else
        str(getattr(expected_material, "label", expected_material)),
        "memory_counts": memory_counts(wire.master.link.counters, wire.slave.counters),
        **metrics, **safety_summary(master),
        "clock": kind.value,
        "loop": stats.summary(),
        "devices": devices, "device_counters": device_counters,
        "module": module_summary(touch, master),
    }
    if recorder is not None:
        summary["recording"] = recorder.close(summary, touch.trace)
    if realtime:
        summary["loop_period_p99_us"] = summary["loop"]["period_p99_us"]
        summary["loop"].update(master_step_summary(master_busy_s, config.rate_hz))
    return SessionResult(summary, touch.trace, stats, tuple(master_busy_s), est)
