"""Every admin request with hostile values, through the services' real
admin sockets and loops (issue 47): each is answered once (refused with an
error naming the field, or served), no request meets an unexpected error,
and the service serves ``status`` after each and a real request at the end.

The services run in this process on loopback ports (plain transport); a
REQ socket sends each request and the service's own loop step (the slave's
``_step``, the master's ``step``) receives, checks, handles and answers it."""

from __future__ import annotations

import math

import msgpack
import pytest
import zmq
from hypothesis import given
from hypothesis import strategies as st

from fuzzing import TALLY, fuzz_settings
from telethermal.physics.scene import load_scene, with_finger
from telethermal.services.config import MasterConfig, SlaveConfig
from telethermal.ports import free_ports
from telethermal.services.master import MasterService
from telethermal.services.requests import MASTER, SLAVE, check_request
from telethermal.services.slave import SlaveService
from telethermal.wire.transport import TransportConfig

SCENE = with_finger(load_scene("fingertip-7"))

HOSTILE = st.recursive(
    st.none() | st.booleans() | st.integers(-2 ** 63, 2 ** 64 - 1) | st.floats() |
    st.text(max_size=40) | st.binary(max_size=16) |
    st.sampled_from(["x" * 300, "é" * 200, "wood", "abc", "", "\x00", "1e308", "nan"]),
    lambda inner: st.lists(inner, max_size=3) |
    st.dictionaries(st.text(max_size=12), inner, max_size=3), max_leaves=8)


def requests_of(schema: dict):
    """A command of ``schema`` with any subset of its fields (and now and
    then a field it does not have), each of hostile value; ``truth``'s
    fields hostile too."""
    def fields_of(cmd):
        names = list(schema[cmd]) + ["object_true_c", "zzz"]
        values = st.dictionaries(st.sampled_from(names), HOSTILE, max_size=4)
        truth = st.fixed_dictionaries({}, optional={"material": HOSTILE,
                                                    "object_true_c": HOSTILE})
        return st.tuples(values, truth, st.booleans()).map(
            lambda v: {"cmd": cmd, **v[0], **({"truth": v[1]} if v[2] and cmd == "touch"
                                               else {})})
    return st.sampled_from(sorted(schema)).flatmap(fields_of)


class Driver:
    """A REQ socket on a service's admin socket; ``ask`` sends one request
    and runs the service's loop step until the reply comes."""

    def __init__(self, service, step):
        self.service, self.step = service, step
        self.ctx = zmq.Context()
        self.sock = self.ctx.socket(zmq.REQ)
        self.sock.linger = 0
        self.sock.connect(f"tcp://127.0.0.1:{service.admin.port}")

    def ask(self, request) -> dict:
        return self.ask_raw(msgpack.packb(request, use_bin_type=True))

    def ask_raw(self, data: bytes) -> dict:
        self.sock.send(data)
        for _ in range(2000):
            assert self.step() is not False, "the service stopped"
            if self.sock.poll(1):
                return msgpack.unpackb(self.sock.recv(), raw=False)
        raise AssertionError(f"no reply to {data!r:.200}")

    def close(self):
        self.sock.close(linger=0)
        self.ctx.destroy(linger=0)


def ports():
    control, stream, admin = free_ports(3)
    return dict(admin_port=admin, transport=TransportConfig(
        security="plain", control_port=control, stream_port=stream))


@pytest.fixture(scope="module")
def slave(trained_models):
    service = SlaveService(SlaveConfig(place="wood", seed=5, **ports()),
                           *trained_models.pair(SCENE, 0))
    deadline = [0.0]

    def step():
        deadline[0] = service._step(0.0, 1.0 / service.rate_hz)
        return not service.stop_requested

    driver = Driver(service, step)
    yield driver
    driver.close()
    service.shutdown()


@pytest.fixture(scope="module")
def master():
    service = MasterService(MasterConfig(seed=5, **ports()))
    service.loop.run(None, 0)            # its statistics, as its run starts them
    driver = Driver(service, lambda: service.step(0.0, service.loop.period_s))
    yield driver
    driver.close()
    service.shutdown()


def _check_reply(reader: str, schema: dict, request: dict, reply: dict) -> None:
    assert isinstance(reply, dict) and isinstance(reply.get("ok"), bool), reply
    if reply["ok"]:
        check_request(request, schema)          # served: it was within the schema
        TALLY[reader]["served"] += 1
        return
    error = reply.get("error")
    assert isinstance(error, str) and error and len(error) <= 1000, reply
    assert "internal error" not in error, error
    TALLY[reader]["refused"] += 1


def _still_serving(driver, reader: str) -> None:
    status = driver.ask({"cmd": "status"})
    assert status["ok"] and status["admin"]["internal_errors"] == 0, status
    assert driver.service.counters["internal_errors"] == 0
    TALLY[reader]["status_after"] += 1


@fuzz_settings(scale=0.5)
@given(request=requests_of(SLAVE))
def test_the_slave_refuses_hostile_admin_requests_and_goes_on(slave, request):
    _check_reply("admin-slave", SLAVE, request, slave.ask(request))
    _still_serving(slave, "admin-slave")


@fuzz_settings(scale=0.5)
@given(request=requests_of(MASTER))
def test_the_master_refuses_hostile_admin_requests_and_goes_on(master, request):
    _check_reply("admin-master", MASTER, request, master.ask(request))
    _still_serving(master, "admin-master")


#: Requests of the wrong shape, as the admin socket's guard
#: (``AdminSocket.receive``) and the command table meet them: not a map, a
#: map without ``cmd`` or with one that is not a string, an unknown command
#: (huge ones too), and bytes that are not msgpack at all (cut, an unused
#: code, a string that is not UTF-8, nesting past msgpack's stack, an
#: integer key).
HUGE = "x" * 1_000_000
SHAPES = (
    (HOSTILE.filter(lambda v: not isinstance(v, dict))
     | st.dictionaries(st.text(max_size=12).filter(lambda k: k != "cmd"), HOSTILE, max_size=3)
     | st.builds(lambda cmd, rest: {**rest, "cmd": cmd},
                 HOSTILE.filter(lambda v: not isinstance(v, str)),
                 st.dictionaries(st.text(max_size=12), HOSTILE, max_size=2))
     | st.builds(lambda cmd: {"cmd": cmd},
                 st.text(max_size=40).filter(lambda c: c not in {*SLAVE, *MASTER, "status",
                                                                  "stop"})
                 | st.sampled_from([HUGE, "\x00" * 5000, "status" * 100_000])))
    .map(lambda request: msgpack.packb(request, use_bin_type=True))
    | st.sampled_from([b"", b"\xc1", b"\x92\x01", b"\xa2\xff\xfe", b"\x91" * 5000,
                       b"\x81\x01\x02\x03", b"\x81\xa3cmd\xa4wo", b"\xdb\xff\xff\xff\xff"])
    | st.binary(max_size=64))


def _refused_and_serving(driver, reader: str, data: bytes) -> None:
    """Answered ok: false with a short error naming what was wrong, never an
    internal error; then ``status`` is served."""
    try:
        request = msgpack.unpackb(data, raw=False)
    except ValueError:
        request = None                        # not msgpack: the guard's to refuse
    reply = driver.ask_raw(data)
    assert isinstance(reply, dict) and reply.get("ok") is False, (data[:80], reply)
    error = reply.get("error")
    assert isinstance(error, str) and error and len(error) <= 1000, reply
    assert "internal error" not in error, error
    if isinstance(request, dict) and isinstance(request.get("cmd"), str):
        assert "unknown command" in error, error
    else:
        assert error.startswith("bad request"), error
    TALLY[reader]["refused"] += 1
    _still_serving(driver, reader)


@fuzz_settings(scale=0.5)
@given(data=SHAPES)
def test_the_slave_refuses_requests_of_every_wrong_shape_and_goes_on(slave, data):
    _refused_and_serving(slave, "admin-slave", data)


@fuzz_settings(scale=0.5)
@given(data=SHAPES)
def test_the_master_refuses_requests_of_every_wrong_shape_and_goes_on(master, data):
    _refused_and_serving(master, "admin-master", data)


def test_after_the_fuzz_the_slave_places_and_reports(slave):
    placed = slave.ask({"cmd": "place", "material": "steel", "seed": 3})
    assert placed["ok"] and math.isfinite(placed["object_ir_c"]), placed
    assert slave.ask({"cmd": "status"})["material"] == "steel"


# ------------------------------------------------------------ the cases
@pytest.mark.parametrize("truth, field", [
    (5, "truth"), ("wood", "truth"), ([1, 2], "truth"), (True, "truth"), (b"x", "truth"),
    (5.5, "truth"),
    ({"material": "wood", "object_true_c": "abc"}, "object_true_c of truth"),
    ({"material": "wood", "object_true_c": math.nan}, "object_true_c of truth"),
    ({"material": "wood", "object_true_c": 1e308}, "object_true_c of truth"),
    ({"material": "wood", "object_true_c": True}, "object_true_c of truth"),
    ({"material": 5, "object_true_c": 20.0}, "material of truth"),
    ({"material": "w" * 300, "object_true_c": 20.0}, "material of truth"),
    ({"material": "wood", "colour": "red"}, "'colour' of truth"),
])
def test_a_touch_truth_of_every_wrong_type_is_refused_naming_it(master, truth, field):
    reply = master.ask({"cmd": "touch", "contact_s": 0.5, "truth": truth})
    assert not reply["ok"] and field in reply["error"], reply
    _still_serving(master, "admin-master")


@pytest.mark.parametrize("fields, named", [
    ({"contact_s": math.nan}, "contact_s"), ({"contact_s": 0}, "contact_s"),
    ({"contact_s": "5"}, "contact_s"), ({"seed": -1}, "seed"), ({"seed": 2 ** 63}, "seed"),
    ({"seed": 1.5}, "seed"), ({"source": "x" * 10_000}, "source"), ({"wait": "no"}, "wait"),
])
def test_a_touch_field_out_of_range_is_refused_naming_it(master, fields, named):
    reply = master.ask({"cmd": "touch", **fields})
    assert not reply["ok"] and reply["error"].startswith(f"touch: {named} must be"), reply
    assert len(reply["error"]) < 300
