"""ZeroMQ transport of the wire protocol (``proto/PROTOCOL.md`` sections 1-5).

:class:`Endpoint` is one side's two connections (control, stream) with the
lossless-stream machinery (sequence numbers, acknowledgements in
heartbeats, resends, duplicate and gap accounting), liveness, clock-offset
estimation and CURVE security. It never blocks for long: the services call
:meth:`Endpoint.poll` from their loops with a timeout that fits the loop.

It owns its parts as objects, each in its module beside this one: the
sockets and the master's handshake watch (``sockets``,
:mod:`~telethermal.wire.sockets`), the lossless stream (``lossless``,
:mod:`~telethermal.wire.lossless`), the hello exchange and the session it
agrees (``hello``, :mod:`~telethermal.wire.hello`); the key files are in
:mod:`~telethermal.wire.keys`. This module holds the configuration, the
messages' way in and out, and :meth:`Endpoint.poll`.
"""

from __future__ import annotations

import ipaddress
import logging
import math
import socket
import time
import uuid
from collections import deque
from dataclasses import dataclass, field

import zmq

from telethermal.errors import ProtocolError, TransportError, UnknownKindError
from telethermal.wire.codec import decode, encode
from telethermal.wire.hello import HelloExchange
from telethermal.wire.lossless import WINDOW, LosslessStream, lossless_seq
from telethermal.wire.loglimit import LogLimiter
from telethermal.wire.schema import (KINDS, LOSSLESS, MAX_MESSAGE_BYTES, PROTOCOL_VERSION,
                                     MessageKind)
from telethermal.wire.sockets import EndpointSockets

log = logging.getLogger(__name__)

#: ``status`` is sent at least this often while a peer is there.
STATUS_PERIOD_S = 1.0
#: Every counter, in ``status.counters`` and on the admin socket
#: (``proto/PROTOCOL.md`` section 4).
COUNTERS = ("lossless_sent", "lossless_received", "duplicates", "gaps", "recovered", "resent",
            "refused_by_window", "stream_lost", "invalid", "unknown_kind", "heartbeats_missed",
            "reconnects", "duplicate_hellos", "oversized", "version_mismatch", "before_hello",
            "not_peer", "wrong_direction", "out_of_window", "skipped", "resend_throttled",
            "refused", "curve_rejected", "handshake_refused", "sockets_recreated")


@dataclass
class TransportConfig:
    """Where and how the two peers meet.

    ``host`` is the slave's address (the master connects to it; the slave
    binds on ``bind_host``). ``security``: "curve" (default) or "plain",
    which is accepted only when both ends are loopback.
    """

    host: str = "127.0.0.1"
    bind_host: str = "127.0.0.1"
    control_port: int = 5560
    stream_port: int = 5561
    security: str = "curve"
    keys_dir: str | None = None          # this side's <name>.key_secret, the server's .key
    allowed_dir: str | None = None       # slave: public keys of masters it accepts
    server_key: str = "slave"
    client_key: str = "master"
    heartbeat_s: float = 0.1
    dead_after_s: float = 1.0
    stream_hwm: int = 64

    def validate(self, role: str) -> None:
        from telethermal.ports import port_problem

        for name in ("control_port", "stream_port"):
            # 0: the system picks a free port (a slave bound in a test).
            why = port_problem(getattr(self, name), "the system picks one")
            if why:
                raise TransportError(f"{name} = {getattr(self, name)!r}: {why}")
        if self.security not in ("curve", "plain"):
            raise TransportError(f"security must be 'curve' or 'plain', got {self.security!r}")
        if self.security == "plain":
            hosts = [self.host] if role == "master" else [self.bind_host]
            for h in hosts:
                if not is_loopback(h):
                    raise TransportError(f"security = 'plain' is allowed only on loopback; "
                                         f"{h!r} is not a loopback address (use 'curve')")
        elif not self.keys_dir:
            raise TransportError("security = 'curve' needs keys_dir (see `telethermal keys`)")
        if role == "slave" and self.security == "curve" and not self.allowed_dir:
            raise TransportError("a CURVE slave needs allowed_dir: the public keys of the "
                                 "masters it accepts")
        if not (0 < self.heartbeat_s < self.dead_after_s):
            raise TransportError("need 0 < heartbeat_s < dead_after_s")


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        try:
            return ipaddress.ip_address(socket.gethostbyname(host)).is_loopback
        except OSError:
            return False


@dataclass
class ClockOffset:
    """Peer clock minus ours, from the heartbeat exchange (min-RTT filter)."""

    samples: deque = field(default_factory=lambda: deque(maxlen=64))

    def add(self, rtt_s: float, offset_s: float) -> None:
        if rtt_s >= 0:
            self.samples.append((rtt_s, offset_s))

    @property
    def offset_s(self) -> float | None:
        return min(self.samples)[1] if self.samples else None

    @property
    def rtt_s(self) -> float | None:
        return min(self.samples)[0] if self.samples else None


class Endpoint:
    """One side of a master-slave link: owns its ``sockets``
    (:class:`~telethermal.wire.sockets.EndpointSockets`), its ``lossless``
    stream (:class:`~telethermal.wire.lossless.LosslessStream`) and its
    ``hello`` exchange (:class:`~telethermal.wire.hello.HelloExchange`).

    ``time_scale``: how many of the machine's seconds one of ``clock``'s
    lasts (a service's ``time_scale``): :meth:`poll` waits ``clock``'s time."""

    def __init__(self, role: str, config: TransportConfig, context: zmq.Context | None = None,
                 clock=time.monotonic, time_scale: float = 1.0):
        if role not in ("master", "slave"):
            raise TransportError(f"role must be master or slave, got {role!r}")
        if not (isinstance(time_scale, (int, float)) and 1.0 <= time_scale < math.inf):
            raise TransportError(f"time_scale must be a finite number >= 1, got {time_scale!r}")
        config.validate(role)
        self.role, self.config, self.clock = role, config, clock
        self.time_scale = float(time_scale)
        self.ctx = context or zmq.Context.instance()
        self.session_id = uuid.uuid4().hex[:16]
        self.counters = dict.fromkeys(COUNTERS, 0)
        self.offset = ClockOffset()
        self.extra_counters: dict[str, int] = {}      # the service's own, in status too
        self._limited = LogLimiter(log)
        #: What ``status`` reports; the service sets it, the endpoint sends it
        #: on every change and every STATUS_PERIOD_S.
        self.state = "idle"
        self.status_message = ""
        self._status_state: str | None = None
        self._status_at = -1e9
        self._kind_seq: dict[str, int] = {}
        self._stream_seen: dict[str, int] = {}
        self.latest: dict[str, dict] = {}             # newest message per lossy kind
        #: Lossy kinds that :meth:`poll` also returns, each newer message once
        #: as it arrives (the master's ``posterior_estimate``); the others
        #: are only kept in ``latest``.
        self.deliver_stream: frozenset[str] = frozenset()
        self._was_alive = False
        self._held_back: list[dict] = []            # arrived while a send waited for room
        self._last_heartbeat_sent = -1e9            # poll's once-a-heartbeat housekeeping
        self.lossless = LosslessStream(
            role=role, config=config, clock=clock, counters=self.counters, offset=self.offset,
            limited=self._limited, send=self._to_peer, unordered=self._unordered,
            drop=self._drop)
        self.hello = HelloExchange(
            role=role, config=config, clock=clock, session_id=self.session_id,
            counters=self.counters, lossless=self.lossless, send=self._to_peer,
            send_to=self._send_to, unordered=self._unordered, drop=self._drop,
            forget_stream=self._forget_stream)
        self.sockets = EndpointSockets(role=role, config=config, ctx=self.ctx, clock=clock,
                                       session_id=self.session_id, counters=self.counters)
        self.sockets.open()

    # ------------------------------------------------------------ state
    @property
    def peer_alive(self) -> bool:
        return self.hello.peer_alive

    @property
    def silent_s(self) -> float | None:
        """How long since the session's peer was last heard (None: never)."""
        return self.hello.silent_s

    @property
    def peer_session(self) -> str | None:
        """The session id of the peer's run (None before its first hello)."""
        return self.hello.peer_session

    @property
    def peer_version(self) -> int | None:
        """The protocol version of the session (None: no session yet)."""
        return self.hello.peer_version

    @property
    def peer_identity(self) -> bytes | None:
        """Slave: the session's master's connection."""
        return self.hello.peer_identity

    @property
    def unacked(self) -> int:
        """Lossless messages kept until the peer acknowledges them."""
        return self.lossless.unacked

    @property
    def control(self):
        """The control socket (slave: ROUTER; master: DEALER)."""
        return self.sockets.control

    @property
    def stream(self):
        """The stream socket (slave: PUB; master: SUB)."""
        return self.sockets.stream

    @property
    def ports(self) -> list[int]:
        """Slave: the ports bound (control, stream)."""
        return self.sockets.ports

    @property
    def poller(self) -> zmq.Poller | None:
        """Polls both sockets (a service registers its own beside them)."""
        return self.sockets.poller

    @property
    def diagnosis(self) -> dict | None:
        """Master: the likely cause while no session comes up, else None."""
        return self.sockets.diagnosis

    @property
    def last_rejected_key(self) -> dict | None:
        """Slave: the latest master key refused (fingerprint, address)."""
        return self.sockets.last_rejected_key

    def close(self) -> None:
        self.sockets.close()

    def say_stopping(self, message: str, linger_s: float = 0.05) -> None:
        """A service's last word before :meth:`close`: if a peer has said
        hello, ``status`` STOPPING with every counter and ``message``, and
        ``linger_s`` of the machine's time for it to leave (and the peer's
        last messages to be read and dropped)."""
        if self.peer_version is None:
            return
        self.send("status", state="stopping", counters=self.all_counters(),
                  message=message[:200])
        self.poll(linger_s / self.time_scale)            # the machine's seconds

    # ------------------------------------------------------------ sending
    def _raw_send(self, sock, message: dict, data: bytes | None = None) -> bool:
        data = encode(message) if data is None else data
        if sock is self.control and self.role == "slave":
            return self._send_to(self.peer_identity, data)
        try:
            sock.send(data, flags=zmq.NOBLOCK)
            return True
        except zmq.Again:
            return False

    def _to_peer(self, message: dict, data: bytes | None = None) -> bool:
        """On the control connection, to the session's peer."""
        return self._raw_send(self.control, message, data)

    def _send_to(self, identity: bytes | None, data: bytes) -> bool:
        """The slave's ROUTER: to one master's connection, never blocking."""
        if identity is None:
            return False
        try:
            self.control.send_multipart([identity, data], flags=zmq.NOBLOCK)
            return True
        except zmq.Again:
            return False
        except zmq.ZMQError as exc:            # EHOSTUNREACH: the peer is gone (ROUTER)
            if exc.errno == zmq.EHOSTUNREACH:
                return False
            raise

    def _unordered(self, kind: str, now: float, **fields) -> dict:
        """A message outside the lossless stream: ``seq`` counts its kind."""
        seq = self._kind_seq.get(kind, 0) + 1
        self._kind_seq[kind] = seq
        return {"kind": kind, "v": PROTOCOL_VERSION, "seq": seq, "sent_s": now, **fields}

    def send(self, kind: str, wait_s: float = 0.0, **fields) -> int:
        """Send one message; returns its seq. Lossless kinds are kept until
        acknowledged; a lossy kind goes on the stream socket (slave only).
        With the lossless window full (``WINDOW`` unacknowledged), a lossless
        send polls for the peer's acknowledgement up to ``wait_s`` and then
        raises :class:`~telethermal.errors.WindowFull` (counted
        ``refused_by_window``): the message was not accepted, nothing kept
        is dropped. What arrives while it waits, the next ``poll`` returns."""
        if kind not in KINDS:
            raise UnknownKindError(f"unknown message kind {kind!r}")
        now = self.clock()
        if kind in LOSSLESS:
            deadline = now + max(wait_s, 0.0)
            while self.unacked >= WINDOW and self.clock() < deadline:
                # (poll hands back what was held back, then what is new)
                self._held_back = self.poll(min(deadline - self.clock(),
                                                self.config.heartbeat_s / 4))
            return self.lossless.send(kind, self.clock(), fields, self.peer_version is not None)
        message = self._unordered(kind, now, **fields)
        sock = self.stream if KINDS[kind].stream == "stream" else self.control
        if sock is self.stream and self.role != "slave":
            raise TransportError(f"{kind} goes from the slave to the master")
        self._raw_send(sock, message)
        return message["seq"]

    def _publish_status(self, now: float) -> None:
        """``status`` on change of state and every second while a peer is there."""
        if self.state == self._status_state and now - self._status_at < STATUS_PERIOD_S:
            return
        self._status_state, self._status_at = self.state, now
        fields = {"state": self.state, "counters": self.all_counters()}
        if self.status_message:
            fields["message"] = self.status_message[:200]
        if self.unacked >= WINDOW:
            # No room: this status is refused (counted); the next carries the state.
            self.counters["refused_by_window"] += 1
            return
        self.send("status", **fields)

    def all_counters(self) -> dict[str, int]:
        """The transport's counters and the service's own (``extra_counters``)."""
        return {**self.counters, **self.extra_counters}

    # ------------------------------------------------------------ receiving
    def poll(self, timeout_s: float = 0.0) -> list[dict]:
        """Housekeeping (heartbeats, hellos, resends, liveness, status) and
        every application message that arrived, lossless ones in order.
        What arrived while this process was away (a stall: its socket
        unread) is read first, so the peer is judged on it: a stall of
        this process is not the peer's silence."""
        out, self._held_back = self._held_back, []
        out += self._receive(control=True, stream=self.role == "master")   # the slave's: PUB
        now = self.clock()
        alive = self.peer_alive
        if self._was_alive and not alive:
            self.counters["heartbeats_missed"] += 1
            log.warning("%s: peer silent for %.2f s", self.role, self.config.dead_after_s)
        self._was_alive = alive
        if now - self._last_heartbeat_sent >= self.config.heartbeat_s:
            if self.role == "master":
                self.sockets.watch_handshakes(now, alive)
            else:
                self.sockets.watch_refusals(now)
            if self.role == "master" and (not alive or self.peer_version is None):
                self.hello.send()
            if self.peer_version is not None:
                self.lossless.heartbeat(now)
                self._last_heartbeat_sent = now
                out += self.lossless.repair(now)
            else:
                self._last_heartbeat_sent = now
        if self.peer_version is not None and alive:
            self._publish_status(now)
        events = dict(self.poller.poll(max(0.0, timeout_s) * 1000 * self.time_scale))
        out += self._receive(control=self.control in events, stream=self.stream in events)
        return out

    def _receive(self, control: bool, stream: bool) -> list[dict]:
        """Every message waiting on the control and/or stream socket."""
        out = []
        while control:
            try:
                frames = self.control.recv_multipart(flags=zmq.NOBLOCK)
            except zmq.Again:
                break
            identity = frames[0] if self.role == "slave" and len(frames) > 1 else None
            out += self._on_control(frames[-1], identity)
        while stream:
            try:
                data = self.stream.recv(flags=zmq.NOBLOCK)
            except zmq.Again:
                break
            out += self._on_stream(data)
        return out

    def _forget_stream(self) -> None:
        """The peer's new run: its lossy kinds count from 1 again."""
        self._stream_seen.clear()
        self.latest.clear()

    def _drop(self, key: str, now: float, fmt: str, *args) -> None:
        """Count one dropped message under ``key`` and log it, rate-limited."""
        self.counters[key] += 1
        self._limited.warn(key, now, "%s: dropped a message (%s): " + fmt, self.role, key, *args)

    def refuse(self, exc: ProtocolError) -> None:
        """A delivered message its reader could not use after all (its typed
        class refused it): counted as :meth:`poll` counts one it refuses
        itself (``unknown_kind`` or ``invalid``) and logged, rate-limited."""
        key = "unknown_kind" if isinstance(exc, UnknownKindError) else "invalid"
        self._drop(key, self.clock(), "%s", exc)

    def _decode(self, data, now):
        """(message, None) or, for a message that cannot be used, (None,
        seq of the lossless slot it occupied, or None)."""
        if len(data) > MAX_MESSAGE_BYTES:
            self._drop("oversized", now, "%d bytes > %d", len(data), MAX_MESSAGE_BYTES)
            return None, None
        try:
            return decode(data), None
        except UnknownKindError as exc:
            self._drop("unknown_kind", now, "%s", exc)
        except ProtocolError as exc:
            self._drop("invalid", now, "%s", exc)
        return None, lossless_seq(data)

    def _on_stream(self, data) -> list[dict]:
        """Keep the newest message of each lossy kind; count the gaps in its
        ``seq`` (``stream_lost``); return it if its kind is delivered."""
        now = self.clock()
        message, _ = self._decode(data, now)
        if message is None:
            return []
        kind = message["kind"]
        if KINDS[kind].stream != "stream":
            self._drop("wrong_direction", now, "%s on the stream socket", kind)
            return []
        last = self._stream_seen.get(kind)
        if last is not None and message["seq"] > last + 1:
            self.counters["stream_lost"] += message["seq"] - last - 1
        if last is None or message["seq"] > last:
            self._stream_seen[kind] = message["seq"]
            self.latest[kind] = message
            if kind in self.deliver_stream:
                return [message]
        return []

    def _from_peer(self, identity) -> bool:
        return self.peer_version is not None and (identity is None or
                                                  identity == self.peer_identity)

    def _on_control(self, data, identity) -> list[dict]:
        now = self.clock()
        message, void_seq = self._decode(data, now)
        if message is None:
            # An unusable lossless message from the peer still uses up its
            # seq: one bad message must not wedge the ordered stream.
            if void_seq is not None and self._from_peer(identity):
                self.hello.heard(now)
                return self.lossless.void(void_seq, now)
            return []
        kind = message["kind"]
        if kind == MessageKind.HELLO:
            return self.hello.receive(message, identity, now)
        if kind == MessageKind.FAULT and message["seq"] == 0 and self.role == "master" and \
                self.peer_version is None:
            # The slave did not take up our hello (no common version, or busy
            # with another master): said once per heartbeat at most.
            self.counters["refused"] += 1
            self._limited.warn("refused", now, "%s: the peer refused our hello (%s): %s",
                               self.role, message["code"], message["message"])
            return [message]
        if not self._session_message(kind, identity, now):
            return []
        self.hello.heard(now)
        if not self._may_receive(kind):
            self._drop("wrong_direction", now, "%s may not come from the %s", kind,
                       "master" if self.role == "slave" else "slave")
            return self.lossless.void(message["seq"], now) if kind in LOSSLESS else []
        if kind == MessageKind.HEARTBEAT:
            self.lossless.on_heartbeat(message, now)
            return []
        if kind == MessageKind.RESEND:
            self.lossless.serve_resend(message, now)
            return []
        return self.lossless.receive(message, now)

    def _session_message(self, kind: str, identity, now: float) -> bool:
        """Whether a message (not a hello) comes within the session: after a
        hello, from the session's peer; the others are dropped, counted."""
        if self.peer_version is None:
            self._drop("before_hello", now, "%s before hello", kind)
            return False
        if identity is not None and identity != self.peer_identity:
            if self.peer_alive:
                self._drop("not_peer", now, "%s from a connection that is not the session's "
                           "master", kind)
            else:
                self._drop("before_hello", now, "%s from a connection before its hello", kind)
            return False
        return True

    def _may_receive(self, kind: str) -> bool:
        k = KINDS[kind]
        peer = "slave" if self.role == "master" else "master"
        return k.stream == "control" and k.direction in ("both", f"{peer}->{self.role}")
