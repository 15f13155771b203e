"""A minimal master written from proto/PROTOCOL.md with pyzmq and msgpack
only (no telethermal import): sockets (section 1), CURVE (2), envelope and
encoding (3), the lossless stream with acks and resends (4), heartbeats (5).

It records every message the slave sends, with the deviations the document
finds in it, so a test can both drive the slave and check what it says.
"""

from __future__ import annotations

import time
import uuid

import msgpack
import zmq

import protocol_doc as doc

HEARTBEAT_S = 0.05


def pack(message) -> bytes:
    return msgpack.packb(message, use_bin_type=True)


class DocMaster:
    """One master session. ``close()`` without a word is a killed master."""

    def __init__(self, ctx: zmq.Context, control: str, stream: str, keys: dict,
                 session_id: str | None = None, identity: bytes | None = None,
                 heartbeat_s: float = HEARTBEAT_S):
        self.session_id = session_id or uuid.uuid4().hex[:16]
        self.heartbeat_s = heartbeat_s
        self.control = ctx.socket(zmq.DEALER)
        self.stream = ctx.socket(zmq.SUB)
        for sock in (self.control, self.stream):
            sock.linger = 0
            sock.curve_publickey, sock.curve_secretkey = keys["public"], keys["secret"]
            sock.curve_serverkey = keys["server"]
        if identity is not None:
            self.control.setsockopt(zmq.IDENTITY, identity)
        self.stream.setsockopt(zmq.SUBSCRIBE, b"")
        self.control.sndtimeo = 10_000
        self.control.connect(control)
        self.stream.connect(stream)
        self.next_seq = 1                   # our lossless counter
        self.kind_seq: dict[str, int] = {}  # our other kinds' counters
        self.kept: dict[int, dict] = {}     # our unacknowledged lossless messages
        self.expected = 1                   # the slave's next lossless seq
        self.buffer: dict[int, dict] = {}
        self.received: list[tuple[str, dict]] = []   # (stream, message), as they came
        self.delivered: list[dict] = []     # the slave's lossless messages, in order
        self.deviations: list[str] = []
        self.peer_hello: dict | None = None
        self.last_heard = -1e9
        self._last_hb = -1e9
        self._hello_at = -1e9
        self.peer_hb: tuple[float, float] | None = None
        self.echoed_s = -1e9                # newest of our own heartbeats the slave echoed
        self._ours: set[float] = set()      # sent_s of heartbeats we sent (not a test's)
        self.ack_override: int | None = None   # a test that wants nothing acknowledged
        self.answer_resend = True

    def restart(self) -> None:
        """A new run of the master on the same connection: a new session id,
        both lossless directions from 1 again (section 4), hello again."""
        self.session_id = uuid.uuid4().hex[:16]
        self.next_seq, self.kept, self.expected, self.buffer = 1, {}, 1, {}
        self.delivered, self.received, self.peer_hello = [], [], None

    # ------------------------------------------------------------ sending
    def envelope(self, kind: str, lossless: bool) -> dict:
        if lossless:
            seq, self.next_seq = self.next_seq, self.next_seq + 1
        else:
            seq = self.kind_seq.get(kind, 0) + 1
            self.kind_seq[kind] = seq
        return {"kind": kind, "v": 1, "seq": seq, "sent_s": time.monotonic()}

    def send(self, kind: str, **fields) -> dict:
        lossless = doc.KINDS[kind].lossless
        message = {**self.envelope(kind, lossless), **fields}
        if lossless:
            self.kept[message["seq"]] = message
        self.send_raw(pack(message))
        return message

    def send_raw(self, data: bytes) -> None:
        self.control.send(data)             # waits (SNDTIMEO) if the slave is behind

    def hello(self, versions=(1,), resume_from: int | None = None) -> None:
        self.send("hello", role="master", versions=list(versions), software="doc-master 1",
                  session_id=self.session_id,
                  resume_from=self.expected if resume_from is None else resume_from)
        self._hello_at = time.monotonic()

    def touch(self, contact_id: int, touching: bool = True, finger_temp_c: float = 33.0):
        return self.send("contact_event", contact_id=contact_id, touching=touching,
                         t_s=time.monotonic(), force_n=5.0 if touching else 0.0,
                         finger_temp_c=finger_temp_c)

    def _heartbeat(self, now: float) -> None:
        echo = held = None
        if self.peer_hb is not None:
            echo, at = self.peer_hb
            held = max(now - at, 0.0)
        ack = self.expected - 1 if self.ack_override is None else self.ack_override
        sent = self.send("heartbeat", ack=ack, echo_sent_s=echo, echo_held_s=held)
        self._ours.add(sent["sent_s"])
        self._last_hb = now

    def sync(self, timeout_s: float = 60.0) -> None:              # a hang guard
        """Return once the slave has read everything sent so far: the control
        connection is ordered, so the slave's echo of a heartbeat sent now
        means it has handled every message before it."""
        self._heartbeat(time.monotonic())
        now = max(self._ours)
        assert self.pump(timeout_s, until=lambda: self.echoed_s >= now), \
            f"the slave did not echo a heartbeat in {timeout_s} s"

    # ------------------------------------------------------------ receiving
    def pump(self, seconds: float, until=None, heartbeats: bool = True) -> bool:
        """Receive and answer for up to ``seconds``; True once ``until()``."""
        end = time.monotonic() + seconds
        while True:
            now = time.monotonic()
            if heartbeats and self.peer_hello is not None and now - self._last_hb >= \
                    self.heartbeat_s:
                self._heartbeat(now)
            if heartbeats and self.peer_hello is None and now - self._hello_at >= \
                    self.heartbeat_s:
                self.hello()
            if until is not None and until():
                return True
            if now >= end:
                return False
            self._receive(min(self.heartbeat_s, max(end - now, 0.0)))

    def _receive(self, timeout_s: float) -> None:
        poller = zmq.Poller()
        poller.register(self.control, zmq.POLLIN)
        poller.register(self.stream, zmq.POLLIN)
        for sock, _ in poller.poll(timeout_s * 1000):
            while True:
                try:
                    data = sock.recv(flags=zmq.NOBLOCK)
                except zmq.Again:
                    break
                self._on(data, "control" if sock is self.control else "stream")

    def _on(self, data: bytes, stream: str) -> None:
        if len(data) > doc.LIMITS["message_bytes"]:
            self.deviations.append(f"a message of {len(data)} bytes")
            return
        message = msgpack.unpackb(data, raw=False)
        errors = doc.deviations(message, sender="slave", stream=stream)
        self.deviations += errors
        self.received.append((stream, message))
        if errors:
            return
        now = time.monotonic()
        self.last_heard = now
        kind = message["kind"]
        if kind == "hello":
            self.peer_hello = message
            for seq in sorted(s for s in self.kept if s >= message["resume_from"]):
                self.send_raw(pack({**self.kept[seq], "sent_s": time.monotonic()}))
        elif kind == "heartbeat":
            for seq in [s for s in self.kept if s <= message["ack"]]:
                del self.kept[seq]
            self.peer_hb = (message["sent_s"], now)
            if message["echo_sent_s"] in self._ours:      # (a test's own heartbeats
                self.echoed_s = max(self.echoed_s, message["echo_sent_s"])   # may lie)
        elif kind == "resend" and self.answer_resend:
            for seq in sorted(s for s in self.kept if s >= message["from_seq"]):
                self.send_raw(pack({**self.kept[seq], "sent_s": time.monotonic()}))
        elif stream == "control" and doc.KINDS[kind].lossless and message["seq"] != 0:
            self._lossless(message)

    def _lossless(self, message: dict) -> None:
        seq = message["seq"]
        if seq < self.expected:
            return
        self.buffer[seq] = message
        while self.expected in self.buffer:
            self.delivered.append(self.buffer.pop(self.expected))
            self.expected += 1

    # ------------------------------------------------------------ reading
    def of(self, kind: str, **match) -> list[dict]:
        """Messages of ``kind`` received (lossless ones once, in order)."""
        source = self.delivered if doc.KINDS[kind].lossless else \
            [m for _, m in self.received]
        return [m for m in source if m.get("kind") == kind and
                all(m.get(k) == v for k, v in match.items())]

    def connect(self, timeout_s: float = 60.0) -> None:           # a hang guard
        """hello until the slave's hello, session_config and object arrive."""
        ok = self.pump(timeout_s, until=lambda: self.of("session_config") and
                       self.of("contact_event", contact_id=0))
        assert ok, f"no session from the slave in {timeout_s} s: {self.received[-5:]}"

    def close(self) -> None:
        self.control.close(linger=0)
        self.stream.close(linger=0)
