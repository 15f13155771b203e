"""One display factory (issue 45, deliverable 2): the master service and
the simulator's master (which the in-process run and the simulated network
both drive: sim/loop.py) build their display through :func:`~telethermal.teleop.display_setup.build_display`, from what
the master heard of the object (the announcement's temperature and expected
material, the session config's curves), never from the slave pad's own
reading. Fed the same messages and the same operator, the two displays are
equal in everything the factory sets: the idle (standby) temperature, the
pre-conditioning, the skin controller's model and the generator's curves.

The announcement the master hears here says the object is 1.5 K warmer than
the pad's own reading: before the factory the in-process run idled on the
pad's reading and the others on what was heard."""

from dataclasses import replace

import numpy as np

from telethermal.render.sampled import sample_curves
from telethermal.services.config import MasterConfig
from telethermal.ports import free_ports
from telethermal.services.master import MasterService, Touch
from telethermal.teleop.display_setup import build_display, display_idle
from telethermal.sim.sides import SimMasterService
from telethermal.teleop.session import PRE_CONTACT_S, SlaveSession
from telethermal.sim.touch import master_rng, draw_operator
from telethermal.teleop.slave import Slave, slave_rng
from telethermal.wire.codec import decode
from telethermal.wire.messages import parse
from telethermal.wire.transport import TransportConfig

from test_master_drivers import CONFIG, SCENE, SEED, wire_message

MATERIAL = "aluminium"
#: What the master heard, above the pad's own reading (K).
HEARD_ABOVE_K = 1.5
#: Where the generators' curves are compared (s).
T_S = np.geomspace(1e-3, 10.0, 50)


def fingerprint(display, idle_c: float) -> tuple:
    """What the factory sets in a display, comparable by value."""
    shift = display.precondition
    return (idle_c, display.safety.applied_temp_c, display.safety.safe, display.finger_temp_c,
            display.r_pad_m2k_w, display.sensor_lag_s, display.junction_sensor,
            display.dew_floor_c, display.config,
            None if shift is None else tuple(shift(m, 24.0) for m in (None, MATERIAL, "wood")),
            tuple((m, display.generator.normalised(m, T_S).tobytes())
                  for m in display.generator.materials))


def test_the_drivers_build_equal_displays_from_what_the_master_heard(trained_models):
    identifier, generator = trained_models.pair(SCENE, 0)
    curves = sample_curves(generator, [c for c in identifier.classes_
                                       if c in generator.materials])
    t0 = -PRE_CONTACT_S
    session = SlaveSession(curves, SCENE.sample_rate_hz)
    pad = Slave(SCENE, MATERIAL, identifier, slave_rng(SEED))
    session.place(pad, MATERIAL)
    own = session.announcement(t0).message
    heard = replace(own, object_temp_c=own.object_temp_c + HEARD_ABOVE_K)
    session_config = wire_message("session_config", dict(
        scene=SCENE.name, sample_rate_hz=SCENE.sample_rate_hz,
        classes=list(identifier.classes_), identifier=identifier.method,
        threshold=float(identifier.threshold), curves=curves), 1, t0)
    finger_c = draw_operator(SCENE, master_rng(SEED)).finger_ir_c     # the service's operator

    sim = SimMasterService(SCENE, CONFIG, curves, list(identifier.classes_), heard, finger_c)
    netsim = fingerprint(sim.display, sim.idle_c)

    control, stream, admin = free_ports(3)
    service = MasterService(MasterConfig(seed=SEED, admin_port=admin, transport=TransportConfig(
        security="plain", control_port=control, stream_port=stream)))
    touch = None
    try:
        service._on_message(parse(decode(session_config)), t0)
        service._on_message(parse(decode(wire_message("contact_event", heard.fields(), 2, t0))),
                            t0)
        service.loop.run(None, 0)       # the loop's statistics, as its run starts them
        touch = Touch(service, 1.0, SEED, t0)
        assert touch.operator.finger_ir_c == finger_c
        served = fingerprint(touch.display, touch.idle_c)
    finally:
        if touch is not None:
            touch.devices.close()
        service.shutdown()

    assert netsim == served
    # The idle is the factory's on what was heard, not on the pad's reading.
    link_idle = build_display(SCENE, CONFIG, finger_c, sim.session.link)[1]
    pad_idle, _ = display_idle(SCENE, CONFIG, finger_c, pad.object_ir_c,
                               sim.session.link.expected_material)
    assert sim.session.link.object_temp_c == heard.object_temp_c
    assert sim.idle_c == link_idle != pad_idle


def test_the_in_process_run_and_the_services_report_one_decision(trained_models,
                                                                 monkeypatch):
    """One touch (test_master_drivers' recorded slave session, simulated
    clock): what the slave decided, by the in-process run's and the slave
    service's definition (its pad's estimates), and what the master service
    reports from the estimates it heard are the same fields
    (teleop/decision.py)."""
    from test_master_drivers import (_models, operator_and_forces, run_service,
                                     slave_recording)
    from telethermal.services import master as master_service
    from telethermal.teleop.decision import pad_decision

    models = _models(trained_models.pair(SCENE, 0))
    pads, results = [], []
    lift = SlaveSession.lift
    monkeypatch.setattr(SlaveSession, "lift",
                        lambda self, now: (pads.append(self.pad), lift(self, now))[1])
    monkeypatch.setattr(master_service, "log_touch_figures", results.append)
    operator, forces = operator_and_forces(1.0)
    # Plexiglass: committed to a pair first, refined later (the master
    # reported the member's time before, the slave the pair's).
    before, arrivals, _, _ = slave_recording(models, "plexiglass", forces,
                                             operator.finger_ir_c, reorder=True)
    run_service(before, arrivals, len(forces), "trajectory", 1.0)
    (pad,), (result,) = pads, results
    decision = pad_decision(pad)
    slave = decision.fields()
    assert slave["identified"] == "plexiglass" and decision.committed.label.is_group
    assert slave["decision_time_s"] < slave["identified_at_s"]
    assert {k: result[k] for k in slave} == slave
