"""The master against the document: a slave written from PROTOCOL.md
(ROUTER and PUB, CURVE server; pyzmq + msgpack only) and a real
``telethermal master`` process connecting to it over loopback. The master
runs the same transport code as the slave; this checks what it sends and
that it counts what it must not accept."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import msgpack
import pytest
import zmq
import zmq.auth

import protocol_doc as doc
from conftest import GUARD_S, HEARTBEAT_S, SCENE, free_ports
from doc_peer import pack


class DocSlave:
    def __init__(self, ctx, keys_root, control_port: int, stream_port: int):
        public, secret = zmq.auth.load_certificate(str(keys_root / "slave" / "slave.key_secret"))
        self.control, self.stream = ctx.socket(zmq.ROUTER), ctx.socket(zmq.PUB)
        for sock, port in ((self.control, control_port), (self.stream, stream_port)):
            sock.linger = 0
            sock.curve_server, sock.curve_publickey, sock.curve_secretkey = True, public, secret
            sock.bind(f"tcp://127.0.0.1:{port}")
        self.master: bytes | None = None
        self.received: list[dict] = []
        self.deviations: list[str] = []
        self.kind_seq: dict[str, int] = {}
        self.next_seq = 1

    def envelope(self, kind: str) -> dict:
        if doc.KINDS[kind].lossless:
            seq, self.next_seq = self.next_seq, self.next_seq + 1
        else:
            seq = self.kind_seq[kind] = self.kind_seq.get(kind, 0) + 1
        return {"kind": kind, "v": 1, "seq": seq, "sent_s": time.monotonic()}

    def send(self, data: bytes) -> None:
        self.control.send_multipart([self.master, data])

    def pump(self, seconds: float, until=None, heartbeats: bool = False) -> bool:
        end = time.monotonic() + seconds
        beat = 0.0
        while time.monotonic() < end:
            if until is not None and until():
                return True
            if heartbeats and self.master is not None and time.monotonic() - beat >= HEARTBEAT_S:
                self.heartbeat()
                beat = time.monotonic()
            if self.control.poll(20):
                identity, data = self.control.recv_multipart()
                self.master = identity
                message = msgpack.unpackb(data, raw=False)
                self.deviations += doc.deviations(message, sender="master", stream="control")
                self.received.append(message)
        return until is not None and until()

    def of(self, kind: str) -> list[dict]:
        return [m for m in self.received if m["kind"] == kind]

    def hello(self, versions=(1,)) -> None:
        self.send(pack({**self.envelope("hello"), "role": "slave", "versions": list(versions),
                        "software": "doc-slave 1", "session_id": "doc-slave",
                        "resume_from": 1}))

    def heartbeat(self) -> None:
        got = sorted(m["seq"] for m in self.received if doc.KINDS[m["kind"]].lossless)
        ack = 0
        for seq in got:                          # the highest received in order
            ack = seq if seq == ack + 1 else ack
        self.send(pack({**self.envelope("heartbeat"), "ack": ack, "echo_sent_s": None,
                        "echo_held_s": None}))


@pytest.fixture(scope="module")
def master_setup(tmp_path_factory, curve_keys):
    folder = tmp_path_factory.mktemp("master")
    keys = folder / "keys"
    keys.mkdir()
    root = curve_keys["root"]
    (keys / "master.key_secret").write_bytes((root / "a" / "a.key_secret").read_bytes())
    (keys / "master.key").write_bytes((root / "a" / "a.key").read_bytes())
    (keys / "slave.key").write_bytes((root / "slave" / "slave.key").read_bytes())
    control, stream, admin = free_ports(3)
    config = folder / "master.toml"
    config.write_text(f'[master]\nscene = "{SCENE}"\nrate_hz = 200.0\nadmin_port = {admin}\n\n'
                      f'[transport]\nhost = "127.0.0.1"\ncontrol_port = {control}\n'
                      f'stream_port = {stream}\nsecurity = "curve"\nkeys_dir = "{keys}"\n'
                      f'heartbeat_s = {HEARTBEAT_S}\ndead_after_s = 0.5\n')
    ctx = zmq.Context()
    slave = DocSlave(ctx, root, control, stream)
    log = open(folder / "master.log", "wb")
    proc = subprocess.Popen([sys.executable, "-m", "telethermal", "master", "--config",
                             str(config)], stdout=log, stderr=subprocess.STDOUT,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    yield slave, proc, admin, ctx
    proc.send_signal(signal.SIGTERM)
    code = proc.wait(15)
    log.close()
    ctx.destroy(linger=0)
    assert code == 0, (folder / "master.log").read_text()[-2000:]


def admin_status(ctx, port: int) -> dict:
    sock = ctx.socket(zmq.REQ)
    sock.linger = 0
    sock.connect(f"tcp://127.0.0.1:{port}")
    try:
        sock.send(msgpack.packb({"cmd": "status"}))
        assert sock.poll(5000), "the master's admin socket did not answer"
        return msgpack.unpackb(sock.recv(), raw=False)
    finally:
        sock.close(linger=0)


def test_the_master_speaks_the_document(master_setup):
    slave, proc, _, _ = master_setup
    assert slave.pump(GUARD_S, until=lambda: len(slave.of("hello")) >= 3), "no hello"
    hellos = slave.of("hello")
    # Repeated until answered, each counted (those before the connection was
    # up never left the master: its socket queues to live connections only).
    seqs = [h["seq"] for h in hellos]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs))) and seqs[0] >= 1
    assert hellos[0]["role"] == "master" and hellos[0]["resume_from"] == 1
    slave.hello()
    slave.heartbeat()
    assert slave.pump(GUARD_S, until=lambda: slave.of("status") and len(slave.of("heartbeat")) >= 3)
    beats = [h["seq"] for h in slave.of("heartbeat")]
    assert beats == list(range(beats[0], beats[0] + len(beats)))
    status = slave.of("status")[0]
    assert status["seq"] == 1 and status["state"] == "idle"                 # lossless, from 1
    assert set(doc.counters()) <= set(status["counters"])
    assert slave.deviations == []


def test_the_master_counts_what_it_must_not_accept(master_setup):
    slave, proc, admin, ctx = master_setup
    assert slave.pump(GUARD_S, until=lambda: slave.master is not None)
    before = admin_status(ctx, admin)["counters"]
    slave.send(b"\x00junk")                                              # invalid
    slave.send(pack({**slave.envelope("heartbeat"), "kind": "teleport"}))  # unknown_kind
    slave.send(pack({**slave.envelope("flux_setpoint"), "contact_id": 1,   # wrong_direction
                     "t_since_contact_s": 0.0, "flux_w_m2": 1.0}))
    slave.send(pack({**slave.envelope("material_estimate"), "contact_id": 1,   # invalid (NaN)
                     "t_since_contact_s": float("nan"), "classes": ["a"], "posteriors": [1.0],
                     "label": "a", "confidence": 1.0, "decided": True, "reason": "confident",
                     "object_temp_c": 20.0}))
    slave.stream.send(pack({**slave.envelope("heartbeat"), "ack": 0, "echo_sent_s": None,
                            "echo_held_s": None}))                         # wrong stream
    expected = {"invalid": 2, "unknown_kind": 1, "wrong_direction": 2}

    def moved():
        after = admin_status(ctx, admin)["counters"]
        return {k: after[k] - before[k] for k in after if after[k] != before[k] and k in (
            "invalid", "unknown_kind", "wrong_direction")}

    # Until the master has counted all five (not after a fixed 0.6 s), then
    # exactly these.
    slave.pump(GUARD_S, until=lambda: sum(moved().values()) >= sum(expected.values()))
    assert moved() == expected
    assert proc.poll() is None


def test_a_slave_with_no_common_version_gets_a_version_fault(master_setup):
    slave, proc, admin, ctx = master_setup
    before = admin_status(ctx, admin)["counters"]["version_mismatch"]
    slave.received.clear()
    # Silence until the master finds us dead and says hello again (a hang guard).
    assert slave.pump(GUARD_S, until=lambda: slave.of("hello")), "no hello again"
    slave.hello(versions=[7])
    assert slave.pump(GUARD_S, until=lambda: any(f["code"] == "version" and f["seq"] == 0
                                             for f in slave.of("fault")))
    assert admin_status(ctx, admin)["counters"]["version_mismatch"] == before + 1
    assert slave.deviations == []


def test_a_touch_from_the_master_follows_section_6(master_setup):
    # The document slave gives the master a session (hello, session_config,
    # the object's temperature); the master's simulated operator touches and
    # lifts, and the master's contact events match their table.
    import threading

    slave, proc, admin, ctx = master_setup
    slave.received.clear()
    # Silence until the master finds us dead and says hello again (a hang guard).
    assert slave.pump(GUARD_S, until=lambda: slave.of("hello")), "no hello again"
    slave.hello()
    slave.send(pack({**slave.envelope("session_config"), "scene": SCENE,
                     "sample_rate_hz": 100.0, "classes": ["steel", "wood"],
                     "identifier": "doc", "threshold": 0.99,
                     "curves": {"steel": {"t_s": [0.01, 1.0], "g_w_m2k": [900.0, 500.0]},
                                "wood": {"t_s": [0.01, 1.0], "g_w_m2k": [200.0, 100.0]}}}))
    slave.send(pack({**slave.envelope("contact_event"), "contact_id": 0, "touching": False,
                     "t_s": time.monotonic(), "force_n": 0.0, "object_temp_c": 22.0}))
    assert slave.pump(GUARD_S, heartbeats=True,
                      until=lambda: admin_status(ctx, admin).get("session"))
    reply = []
    thread = threading.Thread(target=lambda: reply.append(_admin(ctx, admin, "touch",
                                                                 contact_s=0.5, seed=1)))
    thread.start()
    try:
        assert slave.pump(GUARD_S, heartbeats=True, until=lambda: any(
            m["kind"] == "contact_event" and not m["touching"] for m in slave.received))
    finally:
        thread.join(20)
    events = [m for m in slave.received if m["kind"] == "contact_event"]
    assert [e["touching"] for e in events] == [True, False]
    assert events[0]["contact_id"] == events[1]["contact_id"] >= 1
    assert events[0]["finger_temp_c"] is not None and events[0]["t_s"] <= events[1]["t_s"]
    assert reply and reply[0]["ok"], reply
    assert slave.deviations == []


def _admin(ctx, port: int, cmd: str, **args) -> dict:
    sock = ctx.socket(zmq.REQ)
    sock.linger = 0
    sock.connect(f"tcp://127.0.0.1:{port}")
    try:
        sock.send(msgpack.packb({"cmd": cmd, **args}))
        assert sock.poll(30_000), f"admin {cmd}: no reply"
        return msgpack.unpackb(sock.recv(), raw=False)
    finally:
        sock.close(linger=0)


def test_the_master_reads_posteriors_from_the_stream_and_the_object_memory(master_setup):
    # Section 6a and 6b from the slave's side: the document slave announces
    # an object with a remembered material, answers the master's touch with
    # its own contact event (the same object), posteriors on the stream
    # (some lost: their seq skips) and one decision on the lossless stream.
    import threading

    slave, proc, admin, ctx = master_setup
    assert slave.pump(GUARD_S, until=lambda: slave.master is not None), "no hello"
    slave.received.clear()
    # Silence until the master finds us dead and says hello again (a hang guard).
    assert slave.pump(GUARD_S, until=lambda: slave.of("hello")), "no hello again"
    slave.hello()
    classes = ["steel", "wood"]
    slave.send(pack({**slave.envelope("session_config"), "scene": SCENE,
                     "sample_rate_hz": 100.0, "classes": classes,
                     "identifier": "doc", "threshold": 0.99,
                     "curves": {"steel": {"t_s": [0.01, 1.0], "g_w_m2k": [900.0, 500.0]},
                                "wood": {"t_s": [0.01, 1.0], "g_w_m2k": [200.0, 100.0]}}}))
    memory = {"object_id": "doc-cup", "object_material": "wood", "object_confidence": 0.995}
    slave.send(pack({**slave.envelope("contact_event"), "contact_id": 0, "touching": False,
                     "t_s": time.monotonic(), "force_n": 0.0, "object_temp_c": 22.0, **memory}))
    assert slave.pump(GUARD_S, heartbeats=True, until=lambda: admin_status(ctx, admin).get(
        "object_material") == "wood")
    before = admin_status(ctx, admin)["counters"]
    assert admin_status(ctx, admin)["object_id"] == "doc-cup"
    # (The previous test's contact events may come again: resent until acknowledged.)
    old = {m["contact_id"] for m in slave.of("contact_event")}
    touches = lambda: [m for m in slave.of("contact_event")                 # noqa: E731
                       if m["touching"] and m["contact_id"] not in old]
    reply = []
    thread = threading.Thread(target=lambda: reply.append(_admin(ctx, admin, "touch",
                                                                 contact_s=1.5, seed=1)))
    thread.start()
    try:
        assert slave.pump(GUARD_S, heartbeats=True, until=touches)
        contact_id = touches()[0]["contact_id"]
        slave.send(pack({**slave.envelope("contact_event"), "contact_id": contact_id,
                         "touching": True, "t_s": time.monotonic(), "force_n": 5.0,
                         "object_temp_c": 22.0, **memory}))
        for i in range(1, 13):
            p = min(0.5 + 0.04 * i, 0.995)
            estimate = {"contact_id": contact_id, "t_since_contact_s": 0.02 * i,
                        "classes": classes, "posteriors": [1.0 - p, p], "label": "wood",
                        "confidence": p, "decided": i == 12,
                        "reason": "confident" if i == 12 else "", "object_temp_c": 22.0}
            if i % 4 == 0:           # the one before was lost on the wire: seq skips one
                slave.kind_seq["posterior_estimate"] = slave.kind_seq.get(
                    "posterior_estimate", 0) + 1
            message = {**slave.envelope("posterior_estimate"), **estimate}
            if i == 12:
                slave.send(pack({**slave.envelope("material_estimate"), **estimate}))
            slave.stream.send(pack(message))
            slave.pump(0.02, heartbeats=True)
        assert slave.pump(GUARD_S, heartbeats=True, until=lambda: any(
            m["kind"] == "contact_event" and not m["touching"] and
            m["contact_id"] == contact_id for m in slave.received))
    finally:
        thread.join(20)
    assert reply and reply[0]["ok"], reply
    result = reply[0]
    assert result["identified"] == "wood" and result["decision_time_s"] == pytest.approx(0.24)
    assert result["estimates"] == 13                 # 12 posteriors and the decision
    links = result["link_counters"]
    assert links["memory_used"] >= 1 and links["memory_overruled"] == 0
    assert links["memory_mismatch"] == 0
    after = admin_status(ctx, admin)["counters"]
    assert after["unknown_kind"] == before["unknown_kind"]    # a kind this master knows
    assert after["invalid"] == before["invalid"]
    assert after["stream_lost"] - before["stream_lost"] == 3
    assert slave.deviations == []
