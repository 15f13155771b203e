"""One set of session rules, on three links (issues 26 and 45): the slave
service (on its sockets) and the simulator's slave
(:class:`~telethermal.sim.sides.SimSlaveService`, the side the in-process
run and ``bench faults``' simulated network both drive) over the
in-process wire and over the simulated network all run the same
:class:`~telethermal.teleop.session.SlaveSession`, so the same touch fed
the same contact events at the same instants gives the same messages at
the master, byte for byte (msgpack, as on the wire). Before the session core the two differed:
the simulator sent a trajectory only on a label change and a fixed
``valid_s``, its touching event left out ``object_material``, and it
never lifted."""

import msgpack
import numpy as np
import pytest

from telethermal.physics.scene import load_scene, with_finger
from telethermal.services.config import SlaveConfig
from telethermal.ports import free_ports
from telethermal.services.slave import SlaveService
from telethermal.teleop.memory import ObjectMemory
from telethermal.sim.inprocess import service_sensors
from telethermal.sim.links import instant_pair
from telethermal.sim.network import NetworkSpec, SimNetwork
from telethermal.sim.sides import SimSlaveService
from telethermal.teleop.session import Send
from telethermal.teleop.slave import Slave, slave_rng
from telethermal.wire.messages import parse
from telethermal.wire.transport import TransportConfig

SCENE = with_finger(load_scene("fingertip-7"))


@pytest.fixture(scope="module")
def models(trained_models):
    return trained_models.pair(SCENE, 0)


def master_events(lift_at_s: float):
    touch = {"kind": "contact_event", "contact_id": 1, "touching": True, "t_s": 0.0,
             "force_n": 1.5, "finger_temp_c": 31.2}
    lift = {"kind": "contact_event", "contact_id": 1, "touching": False, "t_s": lift_at_s,
            "force_n": 0.0, "finger_temp_c": 31.2}
    return {0: touch, int(round(lift_at_s * 1000)): lift}


def wire(messages):
    return [msgpack.packb([kind, fields], use_bin_type=True) for kind, fields in messages]


@pytest.mark.parametrize("material, lift_at_s", [("aluminium", 1.0), ("plexiglass", 1.0),
                                               ("wood", 0.03)])
def test_the_slave_sends_the_same_messages_on_the_three_links(models, material, lift_at_s):
    identifier, generator = models
    control, stream, admin = free_ports(3)
    config = SlaveConfig(place=material, seed=5, admin_port=admin, transport=TransportConfig(
        security="plain", control_port=control, stream_port=stream))
    service = SlaveService(config, identifier, generator)
    # The simulator draws and calibrates the service's instruments as the
    # service did (its seed: service_sensors, as the demo's in-process touches).
    assert service_sensors(SCENE, 5).describe() == service.sensors.describe()
    # The pad the service placed, made again for the simulator: the same
    # trial (seed) read through the same calibrated instruments.
    pad = Slave(SCENE, material, identifier, slave_rng(5), session=service.sensors)
    # The simulator's slave on the in-process wire, and on a perfect
    # simulated network (the services' lossless stream), each on its own
    # copy of the same trial.
    net = SimNetwork(NetworkSpec(), np.random.default_rng(0))
    links = {"in-process": instant_pair(), "network": (net.end("slave"), net.end("master"))}
    sims = {name: SimSlaveService(Slave(SCENE, material, identifier, slave_rng(5),
                                        session=service.sensors), service.curves,
                                  object_id=material, memory=ObjectMemory(),
                                  rate_hz=service.rate_hz) for name in links}
    from_service = []
    heard = {name: [] for name in links}
    service.endpoint.send = lambda kind, **fields: from_service.append((kind, fields)) or 0
    events = master_events(lift_at_s)
    try:
        for k in range(int(round(1000 * (lift_at_s + 0.2)))):
            now = 100.0 + k / 1000          # the same clock for every driver
            if k in events:
                service._on_message(parse(events[k]), now)        # as the codec decoded it
            if service.touch_t0 is not None:
                service._sample(now)
            for name, (slave_end, master_end) in links.items():
                if k in events:
                    master_end.send(Send(now, parse(events[k])))
                for m in slave_end.due(now):
                    sims[name].on_message(m, now)
                sims[name].step(now, slave_end)
                heard[name] += [(m.kind, m.fields()) for m in master_end.due(now)]
    finally:
        service.shutdown()
    sent = [(kind, fields) for kind, fields in from_service
            if kind not in ("measurement_batch", "status")]   # the simulator models no reader
    from_inproc, from_net = heard["in-process"], heard["network"]
    assert [k for k, _ in sent] == [k for k, _ in from_inproc] == [k for k, _ in from_net]
    assert wire(sent) == wire(from_inproc) == wire(from_net)
    kinds = [k for k, _ in sent]
    # Both ends of the contact, and the slave's lift last.
    assert kinds.count("contact_event") == 2 and kinds[-1] == "contact_event"
    assert sent[-1][1]["touching"] is False
    if lift_at_s > 0.5:
        assert "flux_trajectory" in kinds and "material_estimate" in kinds
        assert any(k == "measurement_batch" for k, _ in from_service)
        # And the bench's decision on the very same touch (issue 29): what
        # bench identify counts is what the slave told the master, and when.
        from telethermal.ident.anytime import decide
        from telethermal.ident.prepare import from_trials
        contacts, _ = from_trials([pad.trial], max_s=2.0)
        bench = decide(identifier, contacts.x[0], contacts.gap_k[0], contacts.force_n[0])
        final = [f for k, f in sent if k == "material_estimate"][-1]
        assert final["decided"] and final["label"] == str(bench.label)
        assert abs(final["t_since_contact_s"] - bench.time_s) < 1e-6
    else:
        # A contact that ends before the identifier has decided: no
        # trajectory, and the memory learns nothing from it.
        assert "flux_trajectory" not in kinds
        assert service.memory.recall(material) is None
        assert all(sim.session.memory.recall(material) is None for sim in sims.values())
    for sim in sims.values():
        np.testing.assert_equal(service.memory.to_dict(), sim.session.memory.to_dict())


def wood_slave(models) -> SlaveService:
    """A slave service on free loopback ports, wood placed (seed 5)."""
    control, stream, admin = free_ports(3)
    config = SlaveConfig(place="wood", seed=5, admin_port=admin, transport=TransportConfig(
        security="plain", control_port=control, stream_port=stream))
    return SlaveService(config, *models)


def test_placing_another_object_during_a_contact_lifts_the_pad_first(models):
    # Under delay, the operator's next `place` can reach the slave before the
    # master's lift: the contact going on ends (its lift and final decision
    # sent, counted), then the new object is placed (bench faults hit this).
    service = wood_slave(models)
    sent = []
    service.endpoint.send = lambda kind, **fields: sent.append((kind, fields)) or 0
    replies = []
    service.admin.reply = lambda **r: replies.append(r)
    try:
        service._on_message(parse(master_events(1.0)[0]), 100.0)
        for k in range(300):
            service._sample(100.0 + k / 1000)
        built, build = [], service._simulated_pad
        service._simulated_pad = lambda m, s: built.append((m, s)) or build(m, s)
        service._on_admin({"cmd": "place", "material": "steel", "seed": 9})
        assert service.touch_t0 is None
        service._next_prepared(wait=True)              # built off the loop, then placed
        assert built == [("steel", 9)]                 # no next touch of wood built first
        assert service.material == "steel"
        assert service.counters["lifted_by_place"] == 1 and replies[-1]["ok"]
        lifts = [f for k, f in sent if k == "contact_event" and f["touching"] is False]
        assert [f["contact_id"] for f in lifts] == [1]
    finally:
        service.shutdown()


def test_a_touch_on_the_slave_service_keeps_no_fits_of_an_earlier_touch(models):
    # A simulated pad's repeated seed gives the same samples, whose fits the
    # effusivity fit keeps for the process: a live slave makes its own.
    from telethermal.ident import fitted

    service = wood_slave(models)
    try:
        fitted._CACHE[("an earlier touch",)] = (0.0, 0.0, 0.0)
        service._on_message(parse(master_events(1.0)[0]), 100.0)
        assert service.touch_t0 is not None
        assert ("an earlier touch",) not in fitted._CACHE
    finally:
        service.shutdown()


def test_a_slave_refused_for_a_busy_port_writes_no_recording(models, tmp_path):
    # It left a 99 KB recording of nothing, which the view then listed.
    import socket

    from telethermal.errors import TelethermalError

    identifier, generator = models
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    control = busy.getsockname()[1]
    stream, admin = free_ports(2)
    config = SlaveConfig(seed=5, admin_port=admin, record_dir=str(tmp_path / "rec"),
                         transport=TransportConfig(security="plain", control_port=control,
                                                   stream_port=stream))
    try:
        with pytest.raises(TelethermalError, match=str(control)):
            SlaveService(config, identifier, generator)
    finally:
        busy.close()
    assert not (tmp_path / "rec").exists() or not any((tmp_path / "rec").iterdir())
    # A failure after the sockets and the recording opened (an object the
    # scene does not have): the recording is removed, the sockets closed.
    config = SlaveConfig(seed=5, admin_port=admin, record_dir=str(tmp_path / "rec"),
                         place="unobtainium", transport=TransportConfig(
                             security="plain", control_port=control, stream_port=stream))
    with pytest.raises(TelethermalError, match="unobtainium"):
        SlaveService(config, identifier, generator)
    assert not any((tmp_path / "rec").glob("*.mcap"))
    # The ports it did take are free again: a slave starts on them now.
    config = SlaveConfig(seed=5, admin_port=admin, record_dir=str(tmp_path / "rec"),
                         transport=TransportConfig(security="plain", control_port=control,
                                                   stream_port=stream))
    service = SlaveService(config, identifier, generator)
    service.shutdown()
    assert len(list((tmp_path / "rec").glob("slave-*.mcap"))) == 1


def test_the_next_touch_is_prepared_off_the_loop_and_placed_before_the_touch(models):
    # The simulated pad's next touch is computed in advance (its physics);
    # after a lift that runs on a worker thread, so the service's loop keeps
    # its heartbeats (the master declares a slave silent for dead_after_s
    # lost), and a touch waits for it. Held here until the lift returned.
    import threading

    identifier, _ = models
    service = wood_slave(models)
    service.endpoint.send = lambda kind, **fields: 0
    try:
        service._on_message(parse(master_events(1.0)[0]), 100.0)
        for k in range(300):
            service._sample(100.0 + k / 1000)
        used, seed = service.pad, service._seed
        gate = threading.Event()
        build = service._simulated_pad
        service._simulated_pad = lambda m, s: build(m, s) if gate.wait(10) else None
        service._lift(100.3)
        assert service.next_touch_preparing and service.pad is used          # the lift did not wait
        service._step(0.0, 1.0 / service.rate_hz)                      # nor does the loop
        assert service.next_touch_preparing and service.pad is used
        assert service.status()["next_touch_preparing"] is True
        gate.set()
        touch = dict(master_events(1.0)[0], contact_id=2, t_s=1.0)
        service._on_message(parse(touch), 101.0)
        assert service.touch_t0 is not None and service.pad is not used
        assert service.status()["next_touch_preparing"] is False
        assert service._seed == seed + 1 and service.object_id == "wood"
        # The very trial the loop would have placed itself.
        same = Slave(SCENE, "wood", identifier, slave_rng(seed + 1), session=service.sensors)
        np.testing.assert_array_equal(service.pad.trial.channels["heat_flux_W_m2"],
                                      same.trial.channels["heat_flux_W_m2"])
    finally:
        service.shutdown()


def numbered(n: int) -> dict:
    """A message as the endpoint delivers it, told apart by ``n`` (a lift
    of contact ``n``: nothing the tests below act on)."""
    return {"kind": "contact_event", "contact_id": n, "touching": False, "t_s": 0.0,
            "force_n": 0.0, "finger_temp_c": 31.0}


def test_what_arrived_while_the_devices_held_the_loop_is_handled_first_in_order(models):
    # _keep_alive (called by the devices while they pre-condition the pad)
    # reads the transport; the loop's next wake handles what it read before
    # what arrives then, without waiting in the poll.
    service = wood_slave(models)
    handled, timeouts = [], []
    service._on_message = lambda m, now: handled.append(m.contact_id)
    try:
        service.endpoint.poll = lambda timeout_s=0.0: timeouts.append(timeout_s) or \
            [numbered(1)]
        service._keep_alive()
        service._keep_alive()
        service.endpoint.poll = lambda timeout_s=0.0: timeouts.append(timeout_s) or \
            [numbered(2)]
        service._step(float("inf"), 1.0 / service.rate_hz)
        assert handled == [1, 1, 2] and timeouts == [0.0, 0.0, 0.0]
        service._step(float("inf"), 1.0 / service.rate_hz)     # nothing waiting: it waits
        assert handled == [1, 1, 2, 2] and timeouts[-1] > 0
    finally:
        del service.endpoint.poll
        service.shutdown()


def test_what_arrived_while_the_devices_held_the_loop_is_recorded_as_it_arrived(models):
    # A recording's wire log says when a message came, not when the loop
    # got to it after the pad's pre-conditioning (a second or more).
    import time

    class Wire:
        def __init__(self):
            self.log = []

        def wire(self, t_s, direction, message):
            self.log.append((t_s, direction, message["contact_id"]))

    service = wood_slave(models)
    handled = []
    service._on_message = lambda m, now: handled.append((now, m.contact_id))
    service.recorder = recorder = Wire()
    try:
        service.endpoint.poll = lambda timeout_s=0.0: [numbered(1)]
        before = time.monotonic()
        service._keep_alive()
        after = time.monotonic()
        assert [(d, n) for _, d, n in recorder.log] == [("in", 1)] and not handled
        assert before <= recorder.log[0][0] <= after
        service.endpoint.poll = lambda timeout_s=0.0: [numbered(2)]
        service._step(float("inf"), 1.0 / service.rate_hz)
        assert [n for _, n in handled] == [1, 2]
        assert [(d, n) for _, d, n in recorder.log] == [("in", 1), ("in", 2)]
        assert recorder.log[0][0] <= after <= handled[0][0]      # recorded before handled
    finally:
        del service.endpoint.poll
        service.recorder = None
        service.shutdown()


def test_an_admin_place_is_built_off_the_loop_and_answered_once_placed(models):
    # A place between touches builds the trial on the worker thread (the
    # loop keeps its heartbeats) and is answered when the loop places it;
    # its default seed follows the touch being prepared; a build that fails
    # is answered with why; a stop while one is pending answers it too.
    import threading

    service = wood_slave(models)
    service.endpoint.send = lambda kind, **fields: 0
    replies = []
    service.admin.reply = lambda **r: replies.append(r)
    gate = threading.Event()
    build = service._simulated_pad
    try:
        service._simulated_pad = lambda m, s: build(m, s) if gate.wait(10) else None
        service._on_admin({"cmd": "place", "material": "steel"})
        assert not replies and service.status()["next_touch_preparing"]
        assert service.next_seed() == 5 + 2          # after the one being built (seed 6)
        service._step(0.0, 1.0 / service.rate_hz)    # the loop goes on meanwhile
        assert not replies and service.material == "wood"
        gate.set()
        service._next_prepared(wait=True)
        assert replies[-1]["ok"] and replies[-1]["object_id"] == "steel"
        assert service.material == "steel" and service._seed == 6
        service._simulated_pad = lambda m, s: 1 / 0
        service._on_admin({"cmd": "place", "material": "wood", "seed": 9})
        service._next_prepared(wait=True)
        assert replies[-1]["ok"] is False and "division by zero" in replies[-1]["error"]
        assert service.material == "steel"                     # the last one stays
        # Placing what was built fails: counted, and the request answered.
        service._simulated_pad = build
        placed, errors = service._placed, service.counters["internal_errors"]
        service._placed = lambda *a: 1 / 0
        service._on_admin({"cmd": "place", "material": "wood", "seed": 9})
        service._next_prepared(wait=True)
        service._placed = placed
        assert replies[-1]["ok"] is False and "division by zero" in replies[-1]["error"]
        assert service.counters["internal_errors"] == errors + 1
        gate.clear()
        service._simulated_pad = lambda m, s: build(m, s) if gate.wait(10) else None
        service._on_admin({"cmd": "place", "material": "wood"})
        service.admin.pending = True
    finally:
        gate.set()
        service.shutdown()
    assert replies[-1] == {"ok": False, "error": "place: the slave is stopping"}


def test_a_touch_belongs_to_the_master_that_sent_it_even_if_a_hello_comes_meanwhile(models):
    # On devices a touch may first pre-condition the pad, polling the
    # transport (_keep_alive), where a new master's hello can be accepted:
    # the touch stays the sending master's, so the new one supersedes it.
    service = wood_slave(models)
    service.endpoint.send = lambda kind, **fields: 0
    hello = service.endpoint.hello
    try:
        hello.peer_session = "old-master"
        prepared = service._next_prepared

        def a_hello_while_preparing(wait=False):
            prepared(wait)
            hello.peer_session = "new-master"
        service._next_prepared = a_hello_while_preparing
        service._on_message(parse(master_events(1.0)[0]), 100.0)
        assert service.touch_t0 is not None and service.session.owner == "old-master"
    finally:
        hello.peer_session = None
        service.shutdown()


def test_a_slave_stopping_mid_contact_lifts_without_preparing_a_touch(models):
    # Shutdown lifts the pad (the master hears it) and starts nothing it
    # would then abandon: no next touch is being built when it returns.
    service = wood_slave(models)
    sent = []
    service.endpoint.send = lambda kind, **fields: sent.append(kind) or 0
    service._on_message(parse(master_events(1.0)[0]), 100.0)
    for k in range(100):
        service._sample(100.0 + k / 1000)
    started = []
    service._next.start = lambda *a, **k: started.append(a)
    service.shutdown()
    assert service.touch_t0 is None and service.last_touch is not None
    assert not started and not service.next_touch_preparing


def test_admin_requests_on_the_slave_between_and_during_touches(models):
    """The slave's admin requests (services/slave_admin.py) straight on the
    service: a calibration refused during a contact, by name; one right
    after a lift, while the next touch is being prepared in the background,
    calibrates and measures the object anew (the pad placed with the new
    calibration, nothing left pending); a place with an object name
    answers with it; a forget empties the memory."""
    service = wood_slave(models)
    service.endpoint.send = lambda kind, **fields: 0
    replies = []
    service.admin.reply = lambda **r: replies.append(r)
    try:
        service._on_message(parse(master_events(1.0)[0]), 100.0)
        service._on_admin({"cmd": "calibrate_thermometer"})
        assert replies[-1]["ok"] is False
        assert "cannot calibrate during a contact" in replies[-1]["error"]
        for k in range(300):
            service._sample(100.0 + k / 1000)
        service._lift(100.3)
        assert service.next_touch_preparing
        before = service.sensors
        service._on_admin({"cmd": "calibrate_thermometer"})
        assert replies[-1]["ok"] and replies[-1]["calibrated"] is True
        assert not service.next_touch_preparing and service.sensors is not before
        assert service._seed == 6 and service.material == "wood"   # the lift's next trial
        assert service.pad.samples_read == 0 and service.touch_t0 is None
        n = len(replies)
        service._on_admin({"cmd": "place", "material": "steel", "seed": 3,
                           "object_id": "the steel cup"})
        assert len(replies) == n and service.next_touch_preparing     # answered once placed
        service._next_prepared(wait=True)
        assert replies[-1]["ok"] and replies[-1]["object_id"] == "the steel cup"
        assert service.material == "steel" and service._seed == 3
        service._on_admin({"cmd": "place", "material": "steel", "object_id": ""})
        assert replies[-1]["ok"] is False and "object_id" in replies[-1]["error"]
        service._on_admin({"cmd": "place", "material": "unobtainium"})
        assert replies[-1]["ok"] is False and "no object of 'unobtainium'" in \
            replies[-1]["error"] and not service.next_touch_preparing
        service._on_admin({"cmd": "forget"})
        assert replies[-1]["ok"] and replies[-1]["memory"] == service.memory.to_dict()
    finally:
        service.shutdown()
