"""Wrong two-host set-ups are named, and a master whose key was missing gets
in once the key is added, with no restart of either side (loopback, CURVE)."""

import dataclasses
import logging
import shutil
import socket
import time

import pytest

from telethermal.wire.handshake import fingerprint, key_file_fingerprint
from telethermal.wire.sockets import RECONNECT_IVL_MAX_S
from telethermal.wire.transport import Endpoint, TransportConfig
from telethermal.wire.keys import generate_keys

CURVE = TransportConfig(security="curve", control_port=0, stream_port=0, heartbeat_s=0.02,
                        dead_after_s=0.3)


#: How long a test waits for what it pumps for: a hang guard (a pump ends as
#: soon as its condition holds; how soon is the machine's load's).
GUARD_S = 30.0


def pump(*endpoints, seconds, until=None):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for e in endpoints:
            e.poll(0.002)
        if until is not None and until():
            return True
    return False


@pytest.fixture
def keys(tmp_path):
    """A slave's keys with an empty allowed/ folder, and a master's keys."""
    generate_keys(tmp_path / "slave", "slave")
    master_public, _ = generate_keys(tmp_path / "master", "master")
    shutil.copy(tmp_path / "slave" / "slave.key", tmp_path / "master" / "slave.key")
    (tmp_path / "allowed").mkdir()
    return tmp_path, master_public


@pytest.fixture
def endpoints():
    made = []
    yield made
    for e in made:
        e.close()


def test_a_missing_key_is_named_on_both_sides_and_adding_it_lets_the_master_in(
        keys, endpoints, caplog):
    folder, master_public = keys
    caplog.set_level(logging.INFO)
    slave = Endpoint("slave", dataclasses.replace(CURVE, keys_dir=str(folder / "slave"),
                                                  allowed_dir=str(folder / "allowed")))
    endpoints.append(slave)
    master = Endpoint("master", dataclasses.replace(CURVE, keys_dir=str(folder / "master"),
                                                    control_port=slave.ports[0],
                                                    stream_port=slave.ports[1]))
    endpoints.append(master)
    # The slave refuses the key (logged with the fingerprint and the peer's
    # address, counted); the master names the cause at once (the pump's
    # own bound; no wall-clock figure is asserted on this shared machine).
    assert pump(slave, master, seconds=GUARD_S,
                until=lambda: master.diagnosis is not None)
    assert master.diagnosis["likely"] == "key"
    assert key_file_fingerprint(master_public) in master.diagnosis["fix"]
    assert slave.counters["curve_rejected"] >= 1
    rejected = slave.sockets._auth.last_rejected
    assert rejected["fingerprint"] == key_file_fingerprint(master_public)
    assert rejected["address"] == "127.0.0.1"
    slave_log = [r.getMessage() for r in caplog.records if r.name == "telethermal.zap"]
    assert any("rejected CURVE key " + rejected["fingerprint"] in m and "127.0.0.1" in m
               for m in slave_log)
    assert any("master.key" in r.getMessage() and r.name == "telethermal.wire.transport"
               for r in caplog.records)
    # libzmq gives up after a refused handshake; the master keeps trying with
    # new sockets, and the slave keeps counting.
    assert pump(slave, master, seconds=GUARD_S + 3 * RECONNECT_IVL_MAX_S,
                until=lambda: master.counters["sockets_recreated"] >= 2 and
                slave.counters["curve_rejected"] >= 2)
    before = slave.counters["curve_rejected"]
    assert before >= 2 and not master.peer_alive
    # The key is added; no restart of either side.
    shutil.copy(master_public, folder / "allowed" / "master.key")
    # Back without a restart: the socket is recreated REFUSED_RETRY_S after
    # a refusal, at a heartbeat tick, then the handshake and hellos (the
    # pump's bound; no wall-clock figure asserted on this shared machine).
    assert pump(slave, master, seconds=GUARD_S,
                until=lambda: master.peer_alive and slave.peer_alive)
    assert pump(slave, master, seconds=GUARD_S, until=lambda: master.diagnosis is None)
    master.send("contact_event", contact_id=1, touching=True, t_s=0.0, force_n=1.0)
    assert pump(slave, master, seconds=GUARD_S, until=lambda: master.unacked == 0)


def test_a_closed_port_is_named_as_address_or_port(keys, endpoints):
    folder, _ = keys
    with socket.socket() as s:                   # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    master = Endpoint("master", dataclasses.replace(CURVE, keys_dir=str(folder / "master"),
                                                    control_port=port, stream_port=port))
    endpoints.append(master)
    assert pump(master, seconds=GUARD_S, until=lambda: master.diagnosis)
    d = master.diagnosis
    assert d["likely"] == "address" and f"127.0.0.1:{port}" in d["problem"]
    assert len(d["causes"]) == 3 and "firewall" in d["causes"][1]


def test_a_wrong_slave_public_key_is_named(keys, endpoints):
    folder, master_public = keys
    shutil.copy(master_public, folder / "allowed" / "master.key")
    generate_keys(folder / "impostor", "slave")          # the master holds another slave's key
    shutil.copy(folder / "impostor" / "slave.key", folder / "master" / "slave.key")
    slave = Endpoint("slave", dataclasses.replace(CURVE, keys_dir=str(folder / "slave"),
                                                  allowed_dir=str(folder / "allowed")))
    endpoints.append(slave)
    master = Endpoint("master", dataclasses.replace(CURVE, keys_dir=str(folder / "master"),
                                                    control_port=slave.ports[0],
                                                    stream_port=slave.ports[1]))
    endpoints.append(master)
    assert pump(slave, master, seconds=GUARD_S, until=lambda: master.diagnosis)
    assert master.diagnosis["likely"] == "slave_key"


def test_fingerprint_is_short_and_stable():
    key = b"rq:rM>}U?@Lns47E1%kR.o@n%FcmmsL/@{H8]yf7"
    assert fingerprint(key) == fingerprint(key.decode()) == fingerprint(key + b"\n")
    assert fingerprint(key).startswith("sha256:") and len(fingerprint(key)) == 19
    assert fingerprint(key) != fingerprint(key[:-1] + b"8")
