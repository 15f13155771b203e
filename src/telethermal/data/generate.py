"""Generate the two databases of a scene from the physics simulator.

Database 1 (``pad/``): the sensing pad against each object, for
identification. Database 2 (``finger/``): the operator's fingertip directly on
each object (5 persons x 10 trials in the first paper), for flux generation;
written only when the scene has a ``[finger]``.

A database is one *session* of the scene's instruments
(:func:`~telethermal.physics.sensors.draw_instruments`): the pad's
thermocouple and the flux sensor keep the errors of their instrument, the
object thermometer (infrared or contact) has this session's bias and gain
error. Before the trials, the session calibrates the object thermometer
against the pad (:mod:`telethermal.control.thermometer_calibration`), as a
lab would, unless told not to; the manifest's ``T_object_C`` is the
corrected reading and ``generation.json`` records the instruments' true
errors and the calibration.

Each trial's ``t_s = 0`` is the onset that the pad's contact detector
finds in the recorded force (the first sample past its threshold), as a
lab's recording made with that detector is cut and as the slave finds it
live; ``onset_offset_s`` is the true contact instant on that axis.

A Peltier pad's junction is a node of its module (the scene's module and
heat sink, :mod:`telethermal.physics.held_pad`): the pad's 1 kHz loop holds
the junction's reading at the set point, before contact the pad, the
junction and the module's hot side and sink are in the steady state of that
hold, and during contact the junction droops as the object pulls heat
through the layers (``junction_droop_k`` and ``module_peak_current_a`` in
the manifest). A water pad is pre-conditioned and then left to itself, as
before.

Trial-to-trial variability: pressing force and through it the contact
conductance (``h ~ F^0.8``), the onset of contact relative to the recorded
``t_s = 0``, the object's true temperature and the thermometer's per-reading
noise on it (the pad is set from that reading, so the real gap varies), the
pad's own set-point error (Peltier) or pre-conditioning (water pad), each
person's skin properties and finger temperature, and sensor noise and
quantisation.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from telethermal.data.dataset import Trial, staged_dir, write_trials
from telethermal.errors import ModelError, SceneError
from telethermal.physics.scene import (ONSET_MARGIN_S, ObjectSpec, Scene, SensorSpec,
                                       finger_contact_model, pad_contact_model)
from telethermal.control.contact import ContactDetector
from telethermal.control.thermometer_calibration import (UNCALIBRATED, ThermometerCalibration,
                                                        calibrate_simulated)
from telethermal.physics.as_built import (flux_gain_factor, simulated_module,
                                          simulated_pad_scene)
from telethermal.physics.held_pad import HeldPad, HeldPadResult
from telethermal.physics.thermoelectric import default_driver
from telethermal.physics.sensors import (ForceSensor, Instruments,
                                         Thermocouple, draw_instruments)
from telethermal.physics.waterpad import precondition

log = logging.getLogger(__name__)

#: Standard deviation of a Peltier pad's set-point error, K.
PELTIER_SETPOINT_SD_K = 0.05
#: Length of the water pad's pre-conditioning (STEP 1), s.
PRECONDITION_S = 120.0


#: The simulated touches of the pad (:func:`touch_contact_model`, the stand-in
#: for a real contact) are solved this much finer than the scene's ``[model]
#: tolerance_rel``, to which a model of the pad in the product is computed
#: (the slave's effusivity estimator). Solved on one grid, a model matches
#: the touches it fits to rounding: measured on fingertip-7, every object
#: but the high-diffusivity metals was solved on the estimator's own grid
#: and its curve equalled the touches to 1e-6 of the flux, while the metals,
#: on a coarser one, differed by 5e-4. A quarter: the finest the layered
#: grid's refinement reaches for every material of the table (aluminium's
#: stops at 1.2e-4).
TOUCH_TOLERANCE_FACTOR = 0.25


def touch_contact_model(scene: Scene, obj: ObjectSpec):
    """The pad touching ``obj`` as the simulated touches are solved: to
    :data:`TOUCH_TOLERANCE_FACTOR` of the scene's tolerance; where the
    layered grid cannot refine that far (a scene whose own tolerance is
    near the grid's limit), to the scene's tolerance, said once in the log
    (every shipped scene reaches it: ``tests/unit/test_touch_model.py``).
    (model, ModelChoice), remembered per scene and object."""
    return _touch_model(scene, obj, float(TOUCH_TOLERANCE_FACTOR))


@functools.lru_cache(maxsize=256)
def _touch_model(scene: Scene, obj: ObjectSpec, factor: float):
    fine = dataclasses.replace(scene, tolerance_rel=scene.tolerance_rel * factor)
    try:
        return pad_contact_model(fine, obj)
    except SceneError as exc:
        if not isinstance(exc.__cause__, ModelError):
            raise
        log.warning("%s: %s's touches are solved to the scene's tolerance %g, not %g: %s",
                    scene.source or scene.name, obj.name, scene.tolerance_rel,
                    fine.tolerance_rel, exc.__cause__)
        return pad_contact_model(scene, obj)


@dataclass(frozen=True)
class SensorSession:
    """The instruments of one session and the calibration of its object
    thermometer (identity when the session did not calibrate)."""

    instruments: Instruments
    calibration: ThermometerCalibration = UNCALIBRATED

    def measure_c(self, true_c, rng: np.random.Generator) -> np.ndarray:
        """The object thermometer's corrected measurement of ``true_c``."""
        return self.calibration.correct_c(self.instruments.thermometer.read_c(true_c, rng))

    def describe(self) -> dict:
        return {"instruments": self.instruments.describe(),
                "calibration": self.calibration.to_dict()}


def sensor_session(scene: Scene, rng: np.random.Generator, calibrate: bool = True,
                   instruments: Instruments | None = None, role: str = "slave") -> SensorSession:
    """Draw a session's instruments of ``role`` (slave or master; unless
    given) and calibrate its object thermometer against the pad (unless
    ``calibrate`` is False)."""
    instruments = instruments or draw_instruments(scene.sensors, rng, role)
    if not calibrate:
        return SensorSession(instruments)
    cal = calibrate_simulated(instruments, scene.room_temp_c, rng,
                              scene.sensors.thermocouple_noise_uv)
    return SensorSession(instruments, cal)


@dataclass
class _Contacts:
    """Per-trial draws for one object (arrays of shape (n,))."""

    force_n: np.ndarray
    conductance_w_m2k: np.ndarray
    onset_s: np.ndarray
    object_true_c: np.ndarray
    object_ir_c: np.ndarray


def _draw(scene: Scene, obj, n: int, reference_h: float, rng,
          session: SensorSession, measure=None) -> _Contacts:
    var, sens = scene.variability, scene.sensors
    force = np.clip(rng.normal(var.force_n, var.force_sd_n, n), 0.3 * var.force_n,
                    3.0 * var.force_n)
    h = reference_h * (force / var.reference_force_n) ** var.conductance_force_exponent
    jitter = sens.onset_jitter_s
    onset = np.clip(rng.normal(0.0, jitter, n), -3 * jitter, 3 * jitter) if jitter else np.zeros(n)
    true_c = obj.temp_c + rng.normal(0.0, var.object_temp_sd_c, n)
    measured_c = session.measure_c(true_c, rng) if measure is None else measure(true_c, rng)
    return _Contacts(force, h, onset, true_c, measured_c)


def _time_axis(scene: Scene, duration_s: float) -> np.ndarray:
    rate = scene.sample_rate_hz
    n_pre = int(round(scene.pre_contact_s * rate))
    n_post = int(round(duration_s * rate))
    return (np.arange(-n_pre, n_post + 1)) / rate


def _record(scene, result, times, draws, first_contact_temp, rng, group_of, prefix, model_kind,
            extra_of, session: SensorSession, duration_s: float):
    """Turn a ContactResult into trials with sensor readings."""
    sens = scene.sensors
    flux = sens.flux_sensor(gain=session.instruments.flux_gain).read_w_m2(
        result.flux_sensed_w_m2, rng)
    thermo = Thermocouple(noise_uv_rms=sens.thermocouple_noise_uv,
                          cold_junction_c=scene.room_temp_c,
                          bias_k=session.instruments.pad_tc_bias_k)
    temp = thermo.read_c(result.surface_temp_a_c, rng)
    trials = []
    for i in range(len(draws.force_n)):
        force = ForceSensor().read_n(times - draws.onset_s[i], draws.force_n[i], rng)
        # t_s = 0 where the pad's own contact detector finds the onset, as a
        # recording made with it would be cut (and as the slave sees it live).
        detected = detected_onset_s(times, force)
        t_s = np.round(times - detected, 9)
        keep = t_s <= duration_s + 1e-9            # the contact's duration after the onset
        trial_id = f"{prefix}-{i:02d}" if group_of is None else f"{prefix}-{group_of(i)}-{i:02d}"
        trials.append(Trial(
            trial_id=trial_id, material=prefix, file=f"trials/{trial_id}.csv",
            sample_rate_hz=scene.sample_rate_hz,
            T_object_C=round(float(draws.object_ir_c[i]), 3),
            T_pad_C=round(float(first_contact_temp[i]), 3),
            T_room_C=scene.room_temp_c,
            group=f"trial-{i % 10}" if group_of is None else group_of(i),
            extra={"T_object_true_C": f"{draws.object_true_c[i]:.4f}",
                   "contact_conductance_w_m2k": f"{draws.conductance_w_m2k[i]:.1f}",
                   "force_N": f"{draws.force_n[i]:.3f}",
                   "onset_offset_s": f"{draws.onset_s[i] - detected:.5f}",
                   "model": model_kind, **extra_of(i)},
            channels={"t_s": t_s[keep], "heat_flux_W_m2": flux[i][keep],
                      "temperature_C": temp[i][keep], "force_N": force[keep]}))
    return trials


def detected_onset_s(times: np.ndarray, force_n: np.ndarray) -> float:
    """The onset the contact detector (its default thresholds, those the
    slave uses live) finds in a force trace; 0 when it finds none."""
    detector = ContactDetector()
    for t, f in zip(times, force_n):
        event = detector.update(float(t), float(f))
        if event is not None and event.touching:
            return float(event.t_s)
    return 0.0


def pad_database(scene: Scene, rng: np.random.Generator,
                 session: SensorSession | None = None, measure=None,
                 pad_loop=None) -> list[Trial]:
    """Database 1: the scene's pad against each object, in one session of
    its instruments (drawn from ``rng`` and calibrated, unless given).

    ``measure(true_c, rng)`` and ``pad_loop(command_c)``: the object's
    measurement (corrected) and the pad's pre-conditioning (its true
    temperatures at contact) through devices instead of the simulator's
    shortcuts (a Peltier pad only); the random draws stay the same, so the
    trials are the same but for what the devices change."""
    session = session or sensor_session(scene, rng)
    tc_bias = session.instruments.pad_tc_bias_k
    # The pad as built ([as_built.pad]; the scene itself without one): its
    # layers, contact conductance, lag, module and flux gain.
    built, recorded = simulated_pad_scene(scene), _built_session(scene, session)
    trials = []
    n = scene.pad.trials_per_material
    times = _time_axis(scene, scene.pad.contact_duration_s + ONSET_MARGIN_S)
    for obj in scene.objects:
        model, choice = touch_contact_model(built, obj)
        draws = _draw(scene, obj, n, built.pad.contact_conductance_w_m2k, rng, session, measure)
        command = np.array([scene.pad_temp_c(t) for t in draws.object_ir_c])
        # The pad's loop holds its thermocouple's reading at the command: the
        # pad itself sits the thermocouple's bias below it.
        t_s = times[None, :] - draws.onset_s[:, None]
        extra = {}
        if scene.pad.kind == "peltier":
            pad_c = command - tc_bias + rng.normal(0.0, PELTIER_SETPOINT_SD_K, n)
            if pad_loop is not None:
                pad_c = pad_loop(command)           # the loop's own error instead
            # The junction is a node of the module, held at the set point by
            # the pad's 1 kHz loop; it droops when the object pulls heat.
            result = _held_pad_contact(built, obj, model, t_s, pad_c, draws,
                                       simulated_module(scene, _pad_module(scene)[0]))
            extra = {"junction_droop_k": result.peak_droop_k,
                     "module_peak_current_a": result.peak_current_a}
        else:
            run = precondition(command - tc_bias, scene.room_temp_c, PRECONDITION_S)
            pad_c, back_c = run.final_pad_c, run.final_water_c
            result = model.solve(t_s, pad_c, draws.object_true_c, draws.conductance_w_m2k,
                                 back_temp_a_c=back_c, sensor_lag_s=built.sensors.flux_lag_s)
        # T_pad_C is what the pad's thermocouple read just before contact.
        before = Thermocouple(cold_junction_c=scene.room_temp_c, bias_k=tc_bias).read_c(pad_c, rng)
        trials += _record(built, result, times, draws, before, rng, None, obj.name,
                          choice.kind, lambda i: {"T_pad_true_C": f"{pad_c[i]:.4f}",
                                                  **{k: f"{v[i]:.4f}" for k, v in extra.items()}},
                          recorded, scene.pad.contact_duration_s)
    return trials


def _built_session(scene: Scene, session: SensorSession) -> SensorSession:
    """The session whose flux sensor has the gain of the pad as built
    (its instrument's drawn error times ``[as_built.pad] flux_gain``)."""
    factor = flux_gain_factor(scene)
    if factor == 1.0:
        return session
    inst = session.instruments
    return dataclasses.replace(session, instruments=dataclasses.replace(
        inst, flux_gain=inst.flux_gain * factor))


def _held_pad_contact(scene: Scene, obj, model, t_s, pad_c, draws,
                      module=None) -> HeldPadResult:
    """The scene's Peltier pad on its module and heat sink, its junction held
    at ``pad_c`` by the pad's loop (:mod:`telethermal.physics.held_pad`),
    touching ``obj``; settled at the set point before contact. A contact
    that takes the module past its datasheet's limits is an error (the
    database would hold touches the pad cannot make)."""
    params, sink = _pad_module(scene)
    params = module or params             # the module as built (the simulator's)
    plant = HeldPad(model, params, sink, default_driver(params), scene.room_temp_c,
                    sensor_lag_s=scene.sensors.flux_lag_s, area_m2=scene.pad.area_m2)
    result = plant.run(t_s, pad_c, draws.object_true_c, draws.conductance_w_m2k)
    over_i, over_hot = int(result.over_current_periods.sum()), int(result.over_hot_periods.sum())
    if over_i or over_hot:
        raise SceneError(f"{scene.source}: the pad's module {params.spec.name} on "
                         f"{obj.name}: {over_i} periods above Imax {params.spec.imax_a} A, "
                         f"{over_hot} with the hot side above {params.spec.hot_side_max_c} C")
    return result


def _pad_module(scene: Scene):
    """(ModuleParams, SinkParams) of the scene's pad."""
    return scene.pad.module_params()


def finger_database(scene: Scene, rng: np.random.Generator,
                    session: SensorSession | None = None) -> list[Trial]:
    """Database 2: each person's fingertip directly on each object; the
    finger's and the object's temperatures by the session's calibrated
    thermometer (the master's instruments)."""
    session = session or sensor_session(scene, rng, role="master")
    finger = scene.finger
    persons = finger.persons
    # One draw of skin properties per person, shared across objects.
    k_scale = np.exp(rng.normal(0.0, finger.property_sd, persons))
    heat_scale = np.exp(rng.normal(0.0, finger.property_sd, persons))
    per = finger.trials_per_person
    person = np.repeat(np.arange(persons), per)
    times = _time_axis(scene, finger.contact_duration_s + ONSET_MARGIN_S)
    trials = []
    for obj in scene.objects:
        model, choice = finger_contact_model(scene, obj)
        draws = _draw(scene, obj, persons * per, finger.contact_conductance_w_m2k, rng, session)
        finger_c = rng.normal(finger.temp_c, finger.temp_sd_c, persons * per)
        result = model.solve(times[None, :] - draws.onset_s[:, None], finger_c,
                             draws.object_true_c, draws.conductance_w_m2k,
                             k_scale_a=k_scale[person], heat_scale_a=heat_scale[person],
                             sensor_lag_s=scene.sensors.flux_lag_s)
        finger_ir = session.measure_c(finger_c, rng)
        trials += _record(scene, result, times, draws, finger_ir, rng,
                          lambda i: f"person-{person[i]}", obj.name, choice.kind,
                          lambda i: {"T_finger_true_C": f"{finger_c[i]:.4f}",
                                     "person": str(person[i]),
                                     "skin_effusivity_scale": f"{np.sqrt(k_scale[person[i]] * heat_scale[person[i]]):.4f}"},
                          session, finger.contact_duration_s)
    return trials


def generate_databases(scene: Scene, out: str | Path, seed: int = 0, overwrite: bool = False,
                       progress: Callable[[str], None] | None = None,
                       calibrate: bool = True) -> dict:
    """Write ``out/pad`` (and ``out/finger``) all or nothing; return a summary
    (with each database's session: its instruments' true errors and the
    thermometer calibration, or none when ``calibrate`` is False)."""
    rng = np.random.default_rng(seed)
    summary = {"scene": scene.name, "seed": seed, "datasets": {}}
    if scene.as_built is not None:
        log.warning("%s: the simulated touches are of %s", scene.name, scene.as_built.describe())
        summary["as_built"] = scene.as_built.to_dict()
    with staged_dir(out, overwrite) as staging:
        parts = [("pad", pad_database)]
        if scene.finger is not None:
            parts.append(("finger", finger_database))
        for name, build in parts:
            if progress:
                progress(name)
            session = sensor_session(scene, rng, calibrate,
                                     role="slave" if name == "pad" else "master")
            trials = build(scene, rng, session)
            write_trials(staging / name, trials)
            summary["datasets"][name] = {"trials": len(trials),
                                         "materials": sorted({t.material for t in trials}),
                                         "session": session.describe()}
        (staging / "generation.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def single_contact(pad: str, obj: str, pad_temp_c: float, object_temp_c: float, seconds: float,
                   rate_hz: float, ideal: bool = False, seed: int = 0,
                   contact_conductance_w_m2k: float = 3000.0, sensors: SensorSpec = SensorSpec(),
                   room_temp_c: float = 24.0) -> Trial:
    """One contact between two semi-infinite bodies, as a one-trial dataset row.

    ``ideal``: perfect contact, no sensor, no noise; the closed form itself.
    Its flux is infinite at t = 0, so the samples start one period after
    contact. Otherwise: the given contact conductance and the scene-default
    sensors (lag, noise, quantisation), samples from t = 0.
    """
    from telethermal.physics.materials import get_material
    from telethermal.physics.model import AnalyticContact

    if not (seconds > 0 and rate_hz > 0):
        raise ModelError(f"need seconds > 0 and rate_hz > 0, got {seconds}, {rate_hz}")
    n = int(round(seconds * rate_hz))
    model = AnalyticContact(get_material(pad), get_material(obj))
    if ideal:
        times = np.arange(1, n + 1) / rate_hz
        result = model.solve(times, pad_temp_c, object_temp_c, np.inf)
        flux, temp = result.flux_w_m2[0], result.surface_temp_a_c[0]
    else:
        rng = np.random.default_rng(seed)
        times = np.arange(0, n + 1) / rate_hz
        result = model.solve(times, pad_temp_c, object_temp_c, contact_conductance_w_m2k,
                             sensor_lag_s=sensors.flux_lag_s)
        flux = sensors.flux_sensor().read_w_m2(result.flux_sensed_w_m2, rng)[0]
        temp = Thermocouple(noise_uv_rms=sensors.thermocouple_noise_uv,
                            cold_junction_c=room_temp_c).read_c(result.surface_temp_a_c, rng)[0]
    trial_id = f"{pad}-on-{obj}"
    return Trial(trial_id=trial_id, material=obj, file=f"trials/{trial_id}.csv",
                 sample_rate_hz=float(rate_hz), T_object_C=float(object_temp_c),
                 T_pad_C=float(pad_temp_c), T_room_C=float(room_temp_c), group="single",
                 extra={"pad_material": pad, "ideal": str(bool(ideal)).lower(),
                        "contact_conductance_w_m2k": "inf" if ideal else
                        f"{contact_conductance_w_m2k:g}", "model": "analytic"},
                 channels={"t_s": times, "heat_flux_W_m2": flux, "temperature_C": temp})
