"""ZeroMQ transport of the wire protocol (``proto/PROTOCOL.md`` sections 1-5).

:class:`Endpoint` is one side's two connections (control, stream) with the
lossless-stream machinery (sequence numbers, acknowledgements in
heartbeats, resends, duplicate and gap accounting), liveness, clock-offset
estimation and CURVE security. It never blocks for long: the services call
:meth:`Endpoint.poll` from their loops with a timeout that fits the loop.
"""

from __future__ import annotations

import ipaddress
import logging
import os
import socket
import time
import uuid
from collections import OrderedDict, deque
from dataclasses import dataclass, field
from pathlib import Path

import msgpack
import zmq
import zmq.auth

from telethermal import __version__
from telethermal.errors import ProtocolError, TransportError, UnknownKindError
from telethermal.wire.codec import decode, encode
from telethermal.wire.handshake import AllowedKeys, HandshakeWatch, diagnose, fingerprint
from telethermal.wire.loglimit import LogLimiter
from telethermal.wire.ordering import MAX_BUFFERED, OrderedReceiver  # noqa: F401 (re-export)
from telethermal.wire.schema import (KINDS, LOSSLESS, MAX_MESSAGE_BYTES, PROTOCOL_VERSION,
                                     SUPPORTED_VERSIONS)

log = logging.getLogger(__name__)

MAX_UNACKED = 4096
#: Heartbeat periods a message may wait unacknowledged before it is sent again.
RETRANSMIT_AFTER = 3
#: A lossless gap still open after this many ``dead_after_s`` is given up.
GAP_GIVE_UP_DEAD = 5
#: ``status`` is sent at least this often while a peer is there.
STATUS_PERIOD_S = 1.0
#: ZeroMQ drops the *connection* of a peer sending more than this (the
#: message is never read); up to it, a message over MAX_MESSAGE_BYTES is read,
#: counted (``oversized``) and dropped.
RECEIVE_LIMIT_BYTES = 4 * MAX_MESSAGE_BYTES
#: Every counter, in ``status.counters`` and on the admin socket
#: (``proto/PROTOCOL.md`` section 4).
COUNTERS = ("lossless_sent", "lossless_received", "duplicates", "gaps", "recovered", "resent",
            "lossless_dropped", "stream_lost", "invalid", "unknown_kind", "heartbeats_missed",
            "reconnects", "duplicate_hellos", "oversized", "version_mismatch", "before_hello",
            "not_peer", "wrong_direction", "out_of_window", "skipped", "resend_throttled",
            "refused", "curve_rejected", "sockets_recreated")
#: The master names the likely cause when no handshake completed this long.
DIAGNOSE_AFTER_S = 3.0
DIAGNOSE_REPEAT_S = 30.0
#: libzmq's reconnect cap.
RECONNECT_IVL_MAX_S = 0.5
#: The wait before a socket whose handshake the slave refused is recreated:
#: half the reconnect cap, so a key copied in meanwhile is in use within one
#: reconnect interval (this wait, a heartbeat tick and the handshake).
REFUSED_RETRY_S = 0.25
#: A master socket whose connect nothing answered this long is recreated.
UNANSWERED_S = 2.0


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


def generate_keys(folder: str | Path, name: str) -> tuple[Path, Path]:
    """``name.key`` (public) and ``name.key_secret`` in ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    public, secret = zmq.auth.create_certificates(str(folder), name)
    os.chmod(secret, 0o600)
    return Path(public), Path(secret)


def generate_link_keys(folder: str | Path) -> Path:
    """Keys for one master-slave link, laid out as the configs expect:
    ``slave/`` (the slave's pair), ``master/`` (the master's pair and the
    slave's public key), ``allowed/`` (the master's public key)."""
    folder = Path(folder)
    generate_keys(folder / "slave", "slave")
    generate_keys(folder / "master", "master")
    (folder / "allowed").mkdir(exist_ok=True)
    (folder / "allowed" / "master.key").write_bytes((folder / "master" / "master.key").read_bytes())
    (folder / "master" / "slave.key").write_bytes((folder / "slave" / "slave.key").read_bytes())
    return folder


def _load_secret(folder, name):
    path = Path(folder) / f"{name}.key_secret"
    if not path.is_file():
        raise TransportError(f"{path}: no such key file (create it with `telethermal keys`)")
    public, secret = zmq.auth.load_certificate(str(path))
    if secret is None:
        raise TransportError(f"{path}: holds no secret key")
    return public, secret


def _load_public(folder, name):
    path = Path(folder) / f"{name}.key"
    if not path.is_file():
        raise TransportError(f"{path}: no such public key file")
    return zmq.auth.load_certificate(str(path))[0]


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
    """One side of a master-slave link."""

    def __init__(self, role: str, config: TransportConfig, context: zmq.Context | None = None,
                 clock=time.monotonic):
        if role not in ("master", "slave"):
            raise TransportError(f"role must be master or slave, got {role!r}")
        config.validate(role)
        self.role, self.config, self.clock = role, config, clock
        self.ctx = context or zmq.Context.instance()
        self.session_id = uuid.uuid4().hex[:16]
        self.counters = dict.fromkeys(COUNTERS, 0)
        self.offset = ClockOffset()
        self._auth = None
        self.extra_counters: dict[str, int] = {}      # the service's own, in status too
        self._limited = LogLimiter(log)
        self._next_seq = 1
        self._outbox: OrderedDict[int, dict] = OrderedDict()
        self.receiver = OrderedReceiver(self.counters)
        #: What ``status`` reports; the service sets it, the endpoint sends it
        #: on every change and every STATUS_PERIOD_S.
        self.state = "idle"
        self.status_message = ""
        self._status_state: str | None = None
        self._status_at = -1e9
        self._last_hello: tuple[str, int, float] | None = None
        self._refused_at = -1e9
        self._resend_served_at = -1e9
        self._kind_seq: dict[str, int] = {}
        self._stream_seen: dict[str, int] = {}
        self.latest: dict[str, dict] = {}             # newest message per lossy kind
        #: Lossy kinds that :meth:`poll` also returns, each newer message once
        #: as it arrives (the master's ``posterior_estimate``); the others
        #: are only kept in ``latest``.
        self.deliver_stream: frozenset[str] = frozenset()
        self.peer_session: str | None = None
        self.peer_identity: bytes | None = None
        self.peer_version: int | None = None
        self._last_heard = None
        self._last_heartbeat_sent = -1e9
        self._last_peer_hb: tuple[float, float] | None = None   # (its sent_s, our receipt)
        self._resend_asked_at = -1e9
        self._tail_since: float | None = None       # when a lost tail was first seen
        self._ack_moved_at = -1e9
        self._retransmitted_at = -1e9
        self._was_alive = False
        self._open_sockets()

    # ------------------------------------------------------------ sockets
    def _secure(self, sock, server: bool):
        cfg = self.config
        if cfg.security != "curve":
            return
        if server:
            public, secret = _load_secret(cfg.keys_dir, cfg.server_key)
            sock.curve_publickey, sock.curve_secretkey = public, secret
            sock.curve_server = True
        else:
            public, secret = _load_secret(cfg.keys_dir, cfg.client_key)
            sock.curve_publickey, sock.curve_secretkey = public, secret
            sock.curve_serverkey = _load_public(cfg.keys_dir, cfg.server_key)

    def _common(self, sock):
        sock.linger = 0
        sock.setsockopt(zmq.MAXMSGSIZE, RECEIVE_LIMIT_BYTES)
        sock.setsockopt(zmq.RECONNECT_IVL, 100)
        # At most 0.5 s between attempts: a restarted peer is found again well
        # within one heartbeat timeout (a 2 s cap measured 1.4 s to relink).
        sock.setsockopt(zmq.RECONNECT_IVL_MAX, int(RECONNECT_IVL_MAX_S * 1000))

    def _bind(self, sock, port: int) -> int:
        """Bind; port 0 takes a free one (tests). Returns the port bound."""
        if port == 0:
            return sock.bind_to_random_port(f"tcp://{self.config.bind_host}")
        sock.bind(f"tcp://{self.config.bind_host}:{port}")
        return port

    def _open_sockets(self):
        cfg = self.config
        try:
            if self.role == "slave":
                if cfg.security == "curve":
                    allowed = Path(cfg.allowed_dir)
                    if not allowed.is_dir():
                        raise TransportError(f"{allowed}: allowed-keys folder does not exist")
                    self._auth = AllowedKeys(self.ctx, allowed, self.counters)
                    self._auth.start()
                self.control = self.ctx.socket(zmq.ROUTER)
                self.control.setsockopt(zmq.ROUTER_MANDATORY, 1)
                self._common(self.control)
                self._secure(self.control, server=True)
                self.ports = [self._bind(self.control, cfg.control_port)]
                self.stream = self.ctx.socket(zmq.PUB)
                self._common(self.stream)
                self.stream.sndhwm = cfg.stream_hwm
                self._secure(self.stream, server=True)
                self.ports.append(self._bind(self.stream, cfg.stream_port))
            else:
                self._watch: dict[str, HandshakeWatch] = {}
                self._unlinked_since = self.clock()
                self._diagnosed_at = -1e9
                self._fingerprint: str | None = None
                self.diagnosis: dict | None = None
                for name in ("control", "stream"):
                    self._connect(name)
        except TransportError:
            self.close()
            raise
        except zmq.ZMQError as exc:
            self.close()
            raise TransportError(f"{self.role}: cannot open sockets on {cfg.bind_host if self.role == 'slave' else cfg.host}:"
                                 f"{cfg.control_port}/{cfg.stream_port}: {exc}") from None
        self.poller = zmq.Poller()
        self.poller.register(self.control, zmq.POLLIN)
        self.poller.register(self.stream, zmq.POLLIN)

    def _connect(self, name: str) -> None:
        """The master's control DEALER or stream SUB, connected and watched."""
        cfg = self.config
        if name == "control":
            sock = self.ctx.socket(zmq.DEALER)
            sock.setsockopt(zmq.IDENTITY, self.session_id.encode())
            sock.setsockopt(zmq.IMMEDIATE, 1)
        else:
            sock = self.ctx.socket(zmq.SUB)
            sock.setsockopt(zmq.SUBSCRIBE, b"")
            sock.rcvhwm = cfg.stream_hwm
        self._common(sock)
        setattr(self, name, sock)
        self._secure(sock, server=False)
        where = f"tcp://{cfg.host}:{cfg.control_port if name == 'control' else cfg.stream_port}"
        self._watch[name] = HandshakeWatch.on(sock, where, self.clock())
        sock.connect(where)

    def _recreate(self, name: str) -> None:
        """After a refused handshake libzmq never connects again, and after
        dropped SYNs the kernel waits longer and longer: a new socket tries
        at once (the slave reads its allowed keys anew at each attempt)."""
        old, watch = getattr(self, name), self._watch[name]
        self.poller.unregister(old)
        watch.read(self.clock())
        watch.close(old)
        old.close(linger=0)
        self._connect(name)
        self._watch[name] = watch.merged(self._watch[name])
        self.poller.register(getattr(self, name), zmq.POLLIN)
        self.counters["sockets_recreated"] += 1
        log.debug("master: %s socket recreated (refused, or nothing answered)", name)

    def _watch_handshakes(self, now: float, alive: bool) -> None:
        """Master: recreate a socket the slave refused, and name the likely
        cause while no session comes up."""
        for name, watch in self._watch.items():
            watch.read(now)
            if (watch.gave_up_at is not None and now - watch.gave_up_at >= REFUSED_RETRY_S) \
                    or watch.unanswered(now, UNANSWERED_S):
                self._recreate(name)
        control = self._watch["control"]
        if alive:
            if self._unlinked_since is not None:
                for watch in self._watch.values():
                    watch.reset()
            self._unlinked_since, self.diagnosis = None, None
            return
        if self._unlinked_since is None:
            self._unlinked_since = now
        waited = now - self._unlinked_since
        refused = control.auth_failed > 0
        if waited < DIAGNOSE_AFTER_S and not refused:
            return
        if self._fingerprint is None:
            self._fingerprint = "none (plain)" if self.config.security != "curve" else \
                fingerprint(_load_secret(self.config.keys_dir, self.config.client_key)[0])
        d = diagnose(control, waited, self._fingerprint, self.config.keys_dir or "keys")
        # Logged when first known, when the likely cause changes (a refusal
        # arrives after silence, say), and every DIAGNOSE_REPEAT_S.
        if self.diagnosis is None or d["likely"] != self.diagnosis["likely"] or \
                now - self._diagnosed_at >= DIAGNOSE_REPEAT_S:
            self._diagnosed_at = now
            log.warning("master: %s. Likely: %s. Other causes: %s", d["problem"], d["fix"],
                        "; ".join(c for c in d["causes"] if c != d["fix"]))
        self.diagnosis = d

    def close(self) -> None:
        for name in ("control", "stream"):
            sock = getattr(self, name, None)
            watch = getattr(self, "_watch", {}).get(name)
            if sock is not None:
                if watch is not None:
                    watch.close(sock)
                sock.close(linger=0)
        if self._auth is not None:
            self._auth.stop()
            self._auth = None

    # ------------------------------------------------------------ state
    @property
    def peer_alive(self) -> bool:
        return self._last_heard is not None and \
            self.clock() - self._last_heard < self.config.dead_after_s

    @property
    def last_rejected_key(self) -> dict | None:
        """Slave: the latest master key refused (fingerprint, address)."""
        return getattr(self._auth, "last_rejected", None)

    @property
    def silent_s(self) -> float | None:
        """How long since the session's peer was last heard (None: never)."""
        return None if self._last_heard is None else self.clock() - self._last_heard

    @property
    def unacked(self) -> int:
        return len(self._outbox)

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

    def send(self, kind: str, **fields) -> int:
        """Send one message; returns its seq. Lossless kinds are kept until
        acknowledged; a lossy kind goes on the stream socket (slave only)."""
        if kind not in KINDS:
            raise ProtocolError(f"unknown message kind {kind!r}")
        now = self.clock()
        if kind in LOSSLESS:
            seq = self._next_seq
            self._next_seq += 1
            message = {"kind": kind, "v": PROTOCOL_VERSION, "seq": seq, "sent_s": now, **fields}
            data = encode(message)              # bad content is refused before it is kept
            self._outbox[seq] = message
            if len(self._outbox) > MAX_UNACKED:
                self._outbox.popitem(last=False)
                self.counters["lossless_dropped"] += 1
            self.counters["lossless_sent"] += 1
            if self.peer_version is not None:
                self._raw_send(self.control, message, data)
            return seq
        message = self._unordered(kind, now, **fields)
        sock = self.stream if KINDS[kind].stream == "stream" else self.control
        if sock is self.stream and self.role != "slave":
            raise TransportError(f"{kind} goes from the slave to the master")
        self._raw_send(sock, message)
        return message["seq"]

    def _hello(self):
        self._raw_send(self.control, self._unordered(
            "hello", self.clock(), role=self.role, versions=list(SUPPORTED_VERSIONS),
            software=f"telethermal {__version__}", session_id=self.session_id,
            resume_from=self.receiver.expected))

    def _heartbeat(self, now):
        echo = held = None
        if self._last_peer_hb is not None:
            echo, received = self._last_peer_hb
            held = max(now - received, 0.0)
        self._raw_send(self.control, self._unordered(
            "heartbeat", now, ack=self.receiver.expected - 1, echo_sent_s=echo,
            echo_held_s=held, last_seq=self._next_seq - 1))
        self._last_heartbeat_sent = now

    def _ask_resend(self, now: float) -> None:
        self._raw_send(self.control, self._unordered("resend", now,
                                                     from_seq=self.receiver.expected))
        self._resend_asked_at = now

    def _refuse(self, identity, now: float, code: str, text: str) -> None:
        """``fault`` to a connection whose hello is not taken up (no common
        version; the slave busy with another master). Outside the lossless
        stream (seq 0, never resent: there is no session to resend in), at
        most once per heartbeat period so a flood of hellos is not echoed."""
        if now - self._refused_at < self.config.heartbeat_s:
            return
        self._refused_at = now
        message = {"kind": "fault", "v": PROTOCOL_VERSION, "seq": 0, "sent_s": now,
                   "code": code, "message": text[:200], "safe_state": True}
        if self.role == "slave":
            self._send_to(identity, encode(message))
        else:
            self._raw_send(self.control, message)

    def _publish_status(self, now: float) -> None:
        """``status`` on change of state and every second while a peer is there."""
        if self.state == self._status_state and now - self._status_at < STATUS_PERIOD_S:
            return
        self._status_state, self._status_at = self.state, now
        fields = {"state": self.state, "counters": self.all_counters()}
        if self.status_message:
            fields["message"] = self.status_message[:200]
        self.send("status", **fields)

    def all_counters(self) -> dict[str, int]:
        """The transport's counters and the service's own (``extra_counters``)."""
        return {**self.counters, **self.extra_counters}

    def _repair(self, now: float) -> list[dict]:
        """Once per heartbeat. As receiver: a gap still open is asked for
        again (the first ``resend`` may itself have been lost), and given up
        after ``gap_give_up_s`` (its seqs counted as ``skipped``). As sender:
        messages kept unacknowledged for ``RETRANSMIT_AFTER`` heartbeats with
        the peer's ack standing still are sent again from the first one (a
        lost *tail* leaves the receiver no gap to see)."""
        out = []
        rx = self.receiver
        if rx.buffer:
            rtt = self.offset.rtt_s or 0.0
            give_up = max(GAP_GIVE_UP_DEAD * self.config.dead_after_s, 4 * rtt)
            if now - rx.gap_since_s >= give_up:
                first = rx.expected
                out = rx.skip_gap(now)
                self._limited.warn("skipped", now, "%s: lossless seq %d-%d never arrived in "
                                   "%.1f s: skipped", self.role, first, rx.expected - 1, give_up)
            if rx.buffer:
                self._ask_resend(now)
        if self._outbox:
            first = next(iter(self._outbox))
            waited = now - max(self._outbox[first]["sent_s"], self._ack_moved_at)
            # Never sooner than two round trips: on a long link the ack is on its way.
            timeout = max(RETRANSMIT_AFTER * self.config.heartbeat_s,
                          2 * (self.offset.rtt_s or 0.0) + self.config.heartbeat_s)
            if waited >= timeout and now - self._retransmitted_at >= timeout:
                self._retransmitted_at = now
                self._resend_from(first)
        return out

    def _resend_from(self, first: int):
        for seq, message in list(self._outbox.items()):
            if seq >= first:
                self._raw_send(self.control, {**message, "sent_s": self.clock()})
                self.counters["resent"] += 1

    # ------------------------------------------------------------ receiving
    def poll(self, timeout_s: float = 0.0) -> list[dict]:
        """Housekeeping (heartbeats, hellos, resends, liveness, status) and
        every application message that arrived, lossless ones in order."""
        now = self.clock()
        alive = self.peer_alive
        if self._was_alive and not alive:
            self.counters["heartbeats_missed"] += 1
            log.warning("%s: peer silent for %.2f s", self.role, self.config.dead_after_s)
        self._was_alive = alive
        out = []
        if now - self._last_heartbeat_sent >= self.config.heartbeat_s:
            if self.role == "master":
                self._watch_handshakes(now, alive)
            if self.role == "master" and (not alive or self.peer_version is None):
                self._hello()
            if self.peer_version is not None:
                self._heartbeat(now)
                out += self._repair(now)
            else:
                self._last_heartbeat_sent = now
        if self.peer_version is not None and alive:
            self._publish_status(now)
        events = dict(self.poller.poll(max(0.0, timeout_s) * 1000))
        if self.control in events:
            while True:
                try:
                    frames = self.control.recv_multipart(flags=zmq.NOBLOCK)
                except zmq.Again:
                    break
                identity = frames[0] if self.role == "slave" and len(frames) > 1 else None
                out += self._on_control(frames[-1], identity)
        if self.stream in events:
            while True:
                try:
                    data = self.stream.recv(flags=zmq.NOBLOCK)
                except zmq.Again:
                    break
                out += self._on_stream(data)
        return out

    def _drop(self, key: str, now: float, fmt: str, *args) -> None:
        """Count one dropped message under ``key`` and log it, rate-limited."""
        self.counters[key] += 1
        self._limited.warn(key, now, "%s: dropped a message (%s): " + fmt, self.role, key, *args)

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
        return None, _lossless_seq(data)

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
                self._last_heard = now
                return self.receiver.push(void_seq, None, now)
            return []
        kind = message["kind"]
        if kind == "hello":
            return self._on_hello(message, identity, now)
        if kind == "fault" and message["seq"] == 0 and self.role == "master" and \
                self.peer_version is None:
            # The slave did not take up our hello (no common version, or busy
            # with another master): said once per heartbeat at most.
            self.counters["refused"] += 1
            self._limited.warn("refused", now, "%s: the peer refused our hello (%s): %s",
                               self.role, message["code"], message["message"])
            return [message]
        if self.peer_version is None:
            self._drop("before_hello", now, "%s before hello", kind)
            return []
        if identity is not None and identity != self.peer_identity:
            if self.peer_alive:
                self._drop("not_peer", now, "%s from a connection that is not the session's "
                           "master", kind)
            else:
                self._drop("before_hello", now, "%s from a connection before its hello", kind)
            return []
        self._last_heard = now
        if not self._may_receive(kind):
            self._drop("wrong_direction", now, "%s may not come from the %s", kind,
                       "master" if self.role == "slave" else "slave")
            return self.receiver.push(message["seq"], None, now) if kind in LOSSLESS else []
        if kind == "heartbeat":
            self._on_heartbeat(message, now)
            return []
        if kind == "resend":
            if now - self._resend_served_at < self.config.heartbeat_s:
                self._drop("resend_throttled", now, "a second resend within %.3f s",
                           self.config.heartbeat_s)
                return []
            self._resend_served_at = now
            self._resend_from(message["from_seq"])
            return []
        out = self.receiver.push(message["seq"], message, now)
        if self.receiver.buffer and now - self._resend_asked_at >= self.config.heartbeat_s:
            self.counters["gaps"] += 1
            self._ask_resend(now)
        return out

    def _may_receive(self, kind: str) -> bool:
        k = KINDS[kind]
        peer = "slave" if self.role == "master" else "master"
        return k.stream == "control" and k.direction in ("both", f"{peer}->{self.role}")

    def _on_heartbeat(self, message, now) -> None:
        ack = message["ack"]
        acked = [s for s in self._outbox if s <= ack]
        for seq in acked:
            del self._outbox[seq]
        if acked:
            self._ack_moved_at = now
        self._last_peer_hb = (message["sent_s"], now)
        # Both echo fields or neither: with one of them nil there is no
        # exchange to time (a peer that sent that crashed the slave: fuzzing).
        if message["echo_sent_s"] is not None and message["echo_held_s"] is not None:
            rtt = (now - message["echo_sent_s"]) - message["echo_held_s"]
            self.offset.add(rtt, message["sent_s"] - now + rtt / 2)
        self._check_tail(message.get("last_seq"), now)

    def _check_tail(self, last_seq: int | None, now: float) -> None:
        """A lost *tail*: the peer says it sent up to ``last_seq`` and nothing
        after our next expected seq arrived to show a gap (the lossless
        stream is sparse: contact events and decisions, seconds apart). Ask
        for it now rather than wait for the peer's retransmission timer (two
        round trips and a heartbeat); given up like a gap."""
        rx = self.receiver
        if last_seq is None or last_seq < rx.expected or rx.buffer:
            self._tail_since = None
            return
        if self._tail_since is None:
            self._tail_since = now
            self.counters["gaps"] += 1
        give_up = max(GAP_GIVE_UP_DEAD * self.config.dead_after_s, 4 * (self.offset.rtt_s or 0))
        if now - self._tail_since >= give_up:
            self.counters["skipped"] += last_seq - rx.expected + 1
            self._limited.warn("skipped", now, "%s: lossless seq %d-%d never arrived in %.1f s: "
                               "skipped", self.role, rx.expected, last_seq, give_up)
            rx.expected, self._tail_since = last_seq + 1, None
        elif now - self._resend_asked_at >= self.config.heartbeat_s:
            self._ask_resend(now)

    def _on_hello(self, message, identity, now) -> list[dict]:
        common = set(message["versions"]) & set(SUPPORTED_VERSIONS)
        if not common:
            self._drop("version_mismatch", now, "hello with versions %s, we speak %s",
                       message["versions"][:16], list(SUPPORTED_VERSIONS))
            self._refuse(identity, now, "version",
                         f"no common protocol version: peer {message['versions'][:16]}, "
                         f"this {self.role} {list(SUPPORTED_VERSIONS)}")
            return []
        if identity is not None and self.peer_identity is not None and \
                identity != self.peer_identity and self.peer_alive:
            # One master at a time: another session takes over only once the
            # current one is dead (silent for dead_after_s).
            self._drop("not_peer", now, "hello from session %s while session %s is alive",
                       message["session_id"][:32], self.peer_session)
            self._refuse(identity, now, "busy", f"this slave serves session "
                         f"{self.peer_session}; try again after it goes silent")
            return []
        last = self._last_hello
        if last is not None and identity == self.peer_identity and \
                last[0] == message["session_id"] and last[1] == message["resume_from"] and \
                now - last[2] < self.config.dead_after_s:
            # The same hello again: the master repeats it every heartbeat until
            # the answer arrives, so a link slower than a heartbeat carries
            # several. Answering or resending for each would multiply the
            # traffic (measured: 30 session configs at 500 ms one way).
            self._last_heard = now
            self.counters["duplicate_hellos"] += 1
            return []
        self._last_hello = (message["session_id"], message["resume_from"], now)
        restarted = self.peer_session is not None and message["session_id"] != self.peer_session
        if restarted or (self.peer_session is None and self._next_seq > 1 and
                         message["resume_from"] == 1 and self.role == "slave"):
            # A new run of the peer: both directions start again from 1.
            log.info("%s: peer session %s (new run)", self.role, message["session_id"][:32])
            self.receiver.reset()
            self._tail_since = None
            self._next_seq, self._outbox = 1, OrderedDict()
            # Its lossy kinds count from 1 again too: without this, every
            # stream message of the new run would look older than the last
            # one of the previous run and be ignored until its seq caught up.
            self._stream_seen.clear()
            self.latest.clear()
        if self.peer_session is not None:
            self.counters["reconnects"] += 1
        self.peer_session = message["session_id"]
        self.peer_version = max(common)
        self.peer_identity = identity
        self._last_heard = now
        if self.role == "slave":
            self._hello()                          # answer every hello
        self._resend_from(message["resume_from"])
        return [message]


def _lossless_seq(data: bytes) -> int | None:
    """The seq of a lossless message that failed validation, if its envelope
    (a lossless kind and an unsigned seq >= 1) can still be read."""
    try:
        # A bad string elsewhere (not UTF-8) must not hide a good envelope.
        raw = msgpack.unpackb(data, raw=False, strict_map_key=False, unicode_errors="replace")
    except Exception:                          # noqa: BLE001 - any garbage: no envelope
        return None
    if not isinstance(raw, dict):
        return None
    seq = raw.get("seq")
    kind = raw.get("kind")
    if isinstance(kind, str) and kind in LOSSLESS and type(seq) is int and 1 <= seq < 2 ** 64:
        return seq
    return None
