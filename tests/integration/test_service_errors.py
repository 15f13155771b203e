"""An unexpected error in one piece of a service's work (one message, one
sample period, one touch, one outgoing message) is that piece's: logged,
counted, answered, the pad safe, and the service goes on (issue 47). And a
contact ended by ``place`` is counted by its cause (PROTOCOL.md 5a)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from telethermal.physics.scene import load_scene, with_finger
from telethermal.services.config import MasterConfig, SlaveConfig
from telethermal.ports import free_ports
from telethermal.services.master import MasterService
from telethermal.services.slave import SlaveService
from telethermal.teleop.links import EndpointLink
from telethermal.teleop.session import Send
from telethermal.wire.messages import ContactEvent, parse
from telethermal.wire.transport import TransportConfig

SCENE = with_finger(load_scene("fingertip-7"))
TOUCH = {"kind": "contact_event", "contact_id": 1, "touching": True, "t_s": 0.0,
         "force_n": 1.5, "finger_temp_c": 31.2}


def _ports():
    control, stream, admin = free_ports(3)
    return dict(admin_port=admin, transport=TransportConfig(
        security="plain", control_port=control, stream_port=stream))


@pytest.fixture
def slave(trained_models):
    service = SlaveService(SlaveConfig(place="wood", seed=5, **_ports()),
                           *trained_models.pair(SCENE, 0))
    sent = []
    service.endpoint.send = lambda kind, **fields: sent.append((kind, fields)) or 0
    service.sent = sent
    yield service
    service.shutdown()


def _lifts(service) -> list[int]:
    return [f["contact_id"] for k, f in service.sent if k == "contact_event" and
            f["touching"] is False]


def test_an_error_in_a_sample_period_lifts_the_pad_and_the_slave_goes_on(slave, monkeypatch):
    slave._on_message(parse(TOUCH), 100.0)
    assert slave.touch_t0 is not None

    def broken(now):
        raise ZeroDivisionError("an identifier's bug")

    monkeypatch.setattr(slave, "_sample", broken)
    slave.endpoint.hello._last_heard = slave.endpoint.clock()     # the master is alive
    slave._step(0.0, 1e-3)
    assert slave.counters["internal_errors"] == 1
    assert slave.touch_t0 is None and _lifts(slave) == [1]       # lifted, the master told
    monkeypatch.undo()
    slave._step(0.0, 1e-3)                                        # and it goes on
    assert slave.status()["pad_down"] is False


def test_an_error_in_one_message_is_counted_and_the_next_is_read(slave, monkeypatch):
    calls = []

    def on_message(message, now):
        calls.append(message)
        if len(calls) == 1:
            raise KeyError("a field the handler did not expect")

    lift = {**TOUCH, "touching": False}
    monkeypatch.setattr(slave, "_on_message", on_message)
    monkeypatch.setattr(slave.endpoint, "poll", lambda timeout_s: [TOUCH, lift])
    slave._step(0.0, 1e-3)
    assert [m.touching for m in calls] == [True, False]
    assert slave.counters["internal_errors"] == 1


def test_a_message_the_typed_messages_refuse_is_counted_and_the_rest_are_read(
        slave, monkeypatch):
    """The endpoint checks each message against the schema; one that passes
    it but not its typed class all the same is counted as the endpoint
    counts its own refusals (a kind it does not know: ``unknown_kind``; a
    field missing: ``invalid``) and left out, and the next is handled."""
    calls = []
    monkeypatch.setattr(slave, "_on_message", lambda m, now: calls.append(m))
    no_id = {k: v for k, v in TOUCH.items() if k != "contact_id"}
    monkeypatch.setattr(slave.endpoint, "poll", lambda timeout_s: [{"kind": "a"}, no_id, TOUCH])
    before = dict(slave.endpoint.counters)
    slave._step(0.0, 1e-3)
    assert [m.kind for m in calls] == ["contact_event"]
    assert slave.endpoint.counters["unknown_kind"] == before["unknown_kind"] + 1
    assert slave.endpoint.counters["invalid"] == before["invalid"] + 1


@pytest.mark.parametrize("silent_s, peer, counted", [
    (None, None, "lifted_by_place"),            # a live master's lift still on the way
    (0.05, None, "lifted_by_place"),            # heard half a heartbeat ago
    (0.5, None, "masters_lost"),                # silent for 5 heartbeats: killed
    (None, "new-session", "contacts_superseded"),
])
def test_a_contact_ended_by_place_is_counted_by_its_cause(slave, silent_s, peer, counted):
    slave._on_message(parse(TOUCH), 100.0)
    if silent_s is not None:
        slave.endpoint.hello._last_heard = slave.endpoint.clock() - silent_s
    if peer is not None:
        slave.endpoint.hello.peer_session = peer
    slave.admin.reply = lambda **r: None
    before = dict(slave.counters)
    slave._on_admin({"cmd": "place", "material": "steel", "seed": 9})
    changed = {k for k in before if slave.counters[k] != before[k]}
    assert changed == {counted} and slave.counters[counted] == before[counted] + 1
    assert slave.touch_t0 is None and _lifts(slave) == [1]


def test_an_error_in_a_touch_makes_the_master_pad_safe_and_answers(monkeypatch):
    service = MasterService(MasterConfig(seed=5, **_ports()))
    closed, replies, sent = [], [], []
    service.admin.reply = lambda **r: replies.append(r)
    service.admin.pending = True                      # the touch request waits for its end
    service.endpoint.send = lambda kind, **fields: sent.append((kind, fields)) or 0
    service.touch = SimpleNamespace(contact_id=3, reply_when_done=True,
                                    devices=SimpleNamespace(close=lambda: closed.append(1)),
                                    operator=SimpleNamespace(finger_ir_c=31.0))

    def broken(now, dt_s):
        raise AttributeError("'int' object has no attribute 'get'")

    monkeypatch.setattr(service, "_touch_period", broken)
    try:
        assert service.step(0.0, 1e-3) is True                 # the service goes on
        assert closed == [1] and service.touch is None         # the pad driver disabled
        assert replies and not replies[-1]["ok"] and "internal error" in replies[-1]["error"]
        assert service.counters["internal_errors"] == 1
        assert service.status()["counters"]["internal_errors"] == 1
        assert service.step(0.0, 1e-3) is True
    finally:
        service.shutdown()


def test_a_message_that_cannot_be_sent_is_counted_and_the_rest_go(caplog):
    out = []

    def send(kind, **fields):
        if fields["contact_id"] == 2:
            raise OverflowError("an integer msgpack cannot hold")
        out.append(fields["contact_id"])

    endpoint = SimpleNamespace(send=send, extra_counters={})
    sends = [Send(0.0, ContactEvent(contact_id=k, touching=True, t_s=0.0, force_n=1.0))
             for k in (1, 2, 3)]
    sent = EndpointLink(endpoint, __import__("logging").getLogger("test")).send_all(sends)
    assert out == [1, 3] and [s.message.contact_id for s in sent] == [1, 3]
    assert endpoint.extra_counters == {"send_errors": 1}
    assert "contact_event not sent: OverflowError" in caplog.text
