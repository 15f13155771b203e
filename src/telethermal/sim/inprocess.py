"""An in-process telepresence session on the simulator: the slave touches
the object, identifies it, the master renders the flux, and the result is
compared with the operator's finger touching the object directly
(:func:`run_session`).

The finger touches at session time 0. The two sides run the services'
session rules (:mod:`telethermal.sim.sides`) in the loop every simulated
touch runs (:mod:`telethermal.sim.loop`), over a wire with no delay
(:func:`~telethermal.sim.links.instant_pair`; or over the simulated
network, ``network``): the slave's pad goes down when the master's
contact onset reaches it (the paper has both sides touch at once,
learning-based-thermal-rendering: "contact is established at the same time
both in the master and the slave side"; the product's slave waits for the
master's onset, a debounce later), and what the slave sends, the master
reads the same period. The master runs its loop at ``config.rate_hz`` on a
simulated clock (exact and instant) or on the real clock (``realtime=True``:
the same loop, sleeping to absolute deadlines, its period measured).

The operator is drawn like a person of database 2
(:func:`~telethermal.sim.touch.draw_operator`); the same draws give the
direct-contact reference, so the comparison is with what *this* finger
would have felt. A bench may show the master other news than the slave's
(``news_filter``: the oracle's or the closed set's target, ``bench
unseen``); the slave, its touch and the display are the same.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from telethermal.control.dew import dew_point_c
from telethermal.control.loop import (LoopStats, RealClock, SessionClock, SimClock,
                                      WorldPausedClock, master_step_summary, session_clock)
from telethermal.errors import SceneError
from telethermal.ident.anytime import Estimate, Label, Reason
from telethermal.ident.fitted import clear_cache as clear_fits
from telethermal.ident.openset import touch_text
from telethermal.physics.scene import Scene, with_finger
from telethermal.render.sampled import sample_curves
from telethermal.sim.direct import compare_with_direct
from telethermal.sim.links import instant_pair
from telethermal.sim.loop import LoopRun, close_session, run_touch_loop
from telethermal.sim.network import NetworkSpec, SimNetwork
from telethermal.sim.sides import SimMasterService, SimSlaveService
from telethermal.sim.touch import MasterWorld
from telethermal.teleop.decision import pad_decision
from telethermal.teleop.display_setup import module_summary, safety_summary
from telethermal.teleop.display_config import DisplayConfig
from telethermal.teleop.memory import ObjectMemory, memory_counts
from telethermal.teleop.perception import heat_extraction_ratio, skin_above_threshold_s
from telethermal.teleop.session import PRE_CONTACT_S
from telethermal.teleop.slave import Slave, instruments_rng, slave_rng


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


def service_sensors(scene: Scene, service_seed: int, calibration: dict | None = None):
    """The instruments a slave service started with ``service_seed`` reads
    its pad through (drawn once per process, :func:`instruments_rng`), with
    ``calibration``: its object thermometer's calibration as the service
    reports it (``status``' ``thermometer_calibration``: after a
    recalibration only the service knows it); None: calibrated on the
    simulator as the service does at start. A :func:`run_session` given it
    touches as that service touches the same seed on ``devices = "sim"``:
    the same trial, the same decisions (on a service's emulated or QEMU
    boards the pad goes through their drivers, which this run does not
    model)."""
    from dataclasses import replace

    from telethermal.control.thermometer_calibration import ThermometerCalibration
    from telethermal.data.generate import sensor_session

    session = sensor_session(scene, instruments_rng(service_seed), calibration is None)
    return session if calibration is None else replace(
        session, calibration=ThermometerCalibration.from_dict(
            calibration, "the slave's thermometer_calibration"))


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
                display_calibration=None,
                network: NetworkSpec | None = None,
                slave_sensors=None, display_model: dict | None = None) -> SessionResult:
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
    news (a bench's oracle or closed set; the slave and its messages
    unchanged), None: as the services run. ``idle_scene``: the
    scene whose idle policy the display applies (default ``scene``; a bench
    touching objects outside the trained ones gives the trained scene;
    ``bench render --as-built``'s exact display, the drawn layers).
    ``fresh_fits``: the slave's fits made afresh, none of the process's
    kept ones (a run whose CPU is measured; always on the real clock).
    ``junction_lag_scale``: the display's junction sensor lags this many
    times its stated time constant (the controller is designed for the
    stated one: a robustness study). ``display_calibration``: the master's
    display calibration (``DisplayCalibration``): its flux lag in the
    controllers, its flux gain on the readings. ``network``: the simulated
    network between the sides (its draws seeded by ``seed``); None: the
    in-process wire, no delay and no loss. ``slave_sensors``: the slave's
    instruments and thermometer calibration (a ``SensorSession``; a slave
    service's: :func:`service_sensors`, so the touch is the one that
    service makes of the same seed); None: drawn for this touch.
    ``display_model``: the master's display model in place of the one its
    configuration and calibration give (``display_model_args``'s keys; a
    bench's oracle: ``bench render --as-built``'s exact display)."""
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
    slave = Slave(scene, material, identifier, slave_rng(seed), session=slave_sensors)
    world = MasterWorld(scene, seed)
    operator = world.operator
    # The two sides' session rules, as the services run them: the slave's
    # pad goes down when the master's onset reaches it, the master renders
    # what the slave sends (its sampled curves).
    memory = ObjectMemory()
    if isinstance(expected_material, Estimate):     # an earlier touch's own decision
        memory.learn(material, expected_material, -PRE_CONTACT_S, classes=identifier.classes_)
    elif expected_material is not None:   # an earlier touch of this object decided it
        label = Label.parse(expected_material)
        memory.learn(material, Estimate(0.0, (), label, 1.0, True, Reason.CONFIDENT_GROUP
                                        if label.is_group else Reason.CONFIDENT), -PRE_CONTACT_S)
    curves = sample_curves(generator, [c for c in identifier.classes_
                                       if c in generator.materials])
    sides = SimSlaveService(slave, curves, object_id=material, memory=memory,
                            rate_hz=scene.sample_rate_hz)
    # The master has idled at its standby before this touch: the object's
    # temperature it heard, pre-conditioned for what the slave announced
    # (object memory) or, for an unknown object, by the idle policy of
    # ``idle_scene`` (``config.idle``; control/preconditioning.py), as the
    # services build it.
    master_side = SimMasterService(scene, config, curves, slave.classes,
                                   sides.announcement(-PRE_CONTACT_S), operator.finger_ir_c,
                                   news_filter=news_filter, calibration=display_calibration,
                                   idle_scene=idle_scene and with_finger(idle_scene),
                                   model=display_model)
    master, idle = master_side.display, master_side.idle_c
    if network is None:
        slave_end, master_end = instant_pair()
    else:
        net = SimNetwork(network, np.random.default_rng([seed, 15]))
        slave_end, master_end = net.end("slave"), net.end("master")
    touch = world.display(config.rate_hz, contact_s, idle,
                          junction_lag_scale=junction_lag_scale)
    run = LoopRun()             # its t_end_s: the session's clock, the display's too
    display = open_display(devices, touch, clock=lambda: run.t_end_s, realtime=bool(realtime),
                           seed=seed)
    recorder = SessionRecorder.open(record, scene, material, identifier, generator, config,
                                    operator, idle, seed, contact_s, devices,
                                    sampled=list(curves), display=master) \
        if record else None

    clock = (WorldPausedClock if kind == SessionClock.WORLD_PAUSED else RealClock).for_period(
        1.0 / config.rate_hz) if realtime else SimClock()
    world = clock.world if isinstance(clock, WorldPausedClock) else contextlib.nullcontext

    try:
        run_touch_loop(touch, display, sides, master_side, slave_end, master_end,
                       config.rate_hz, clock, world,
                       recorder.period if recorder is not None else None, run)
    finally:
        device_counters = display.counters()
        display.close()
        close_session(run.t_end_s, sides, master_side, slave_end, master_end)
        if recorder is not None:
            recorder.slave(slave)
    stats, master_busy_s = run.stats, run.master_busy_s
    # What the touch decided, as every summary defines it (teleop/decision.py).
    decision = pad_decision(slave)
    est = decision.estimate
    # The slave's trial times are from its pad going down (at the master's
    # onset, as in the services); on the session's clock they are later by that.
    slave_t0 = sides.touch_t0 or 0.0
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
        "slave_touch_s": sides.touch_t0, "master_onset_s": master.last_onset_s,
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
        "memory_counts": memory_counts(master_side.session.link.counters, sides.session.counters),
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
