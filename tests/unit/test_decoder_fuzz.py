"""Hypothesis against the decoders of input from outside the process that
the protocol suite does not reach: the Peltier driver's CAN frames and the
admin socket's requests. Whatever arrives, the reader counts or refuses it
and never raises (the sensor board's frames: tests/unit/test_board_frames.py;
the wire codec: tests/unit/test_wire_codec.py, tests/conformance/)."""

import can
import msgpack
import pytest
import zmq
from hypothesis import given, settings
from hypothesis import strategies as st

from telethermal.devices.peltier import HEARTBEAT, STATUS, PeltierDriver
from telethermal.services.admin import AdminServer


@pytest.fixture(scope="module")
def driver():
    d = PeltierDriver("virtual:decoder-fuzz")
    yield d
    d.close()


@settings(max_examples=300, deadline=None)
@given(st.sampled_from([STATUS.frame_id, HEARTBEAT.frame_id, 0x7FF, 0]),
       st.binary(max_size=8), st.booleans())
def test_any_can_frame_is_decoded_or_counted_never_raised(driver, frame_id, data, error):
    before = sum(driver.counters.values())
    driver._handle(can.Message(arbitration_id=frame_id, data=data, is_error_frame=error,
                               is_extended_id=False))
    known = frame_id in (STATUS.frame_id, HEARTBEAT.frame_id)
    assert sum(driver.counters.values()) >= before + (1 if known or error else 0)


class _Service:
    stop_requested = False

    def status(self):
        return {"state": "idle"}


@pytest.fixture(scope="module")
def admin():
    ctx = zmq.Context()
    server = AdminServer(0, ctx)
    client = ctx.socket(zmq.REQ)
    client.linger = 0
    client.connect(f"tcp://127.0.0.1:{server.port}")
    yield server, client
    client.close(linger=0)
    server.close()
    ctx.destroy(linger=0)


ANY = st.recursive(st.none() | st.booleans() | st.integers(-2 ** 63, 2 ** 64 - 1) |
                   st.floats() | st.text(max_size=8) | st.binary(max_size=8),
                   lambda inner: st.lists(inner, max_size=3) |
                   st.dictionaries(st.text(max_size=6), inner, max_size=3), max_leaves=6)


@settings(max_examples=150, deadline=None)
@given(st.one_of(st.binary(max_size=64), ANY.map(lambda v: msgpack.packb(v)),
                 st.dictionaries(st.sampled_from(["cmd", "material", "seed"]), ANY)
                 .map(lambda v: msgpack.packb(v))))
def test_any_admin_request_gets_a_reply(admin, data):
    server, client = admin
    client.send(data)
    assert server.sock.poll(2000), "the request never arrived"
    request = server.receive()               # None: refused, and already answered
    if request is not None:
        server.handle(request, _Service(), {"place": lambda r: {"placed": str(r["material"])}})
    assert client.poll(2000), "no reply"
    reply = msgpack.unpackb(client.recv(), raw=False)
    assert isinstance(reply, dict) and isinstance(reply.get("ok"), bool)
    assert not server.pending


def test_a_request_missing_a_field_says_which(admin):
    """`admin send slave place` without its material had been answered
    "place: 'material'" (a KeyError's text): now the field and the form."""
    server, client = admin
    client.send(msgpack.packb({"cmd": "place"}))
    assert server.sock.poll(2000)
    server.handle(server.receive(), _Service(),
                  {"place": lambda r: {"placed": str(r["material"])}})
    assert client.poll(2000)
    reply = msgpack.unpackb(client.recv(), raw=False)
    assert reply == {"ok": False, "error": "place: needs material=... (a key=value argument)"}
