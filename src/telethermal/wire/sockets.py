"""The sockets of an :class:`~telethermal.wire.transport.Endpoint`
(``proto/PROTOCOL.md`` sections 1-2): the slave's control ROUTER and stream
PUB (bound, CURVE server), the master's control DEALER and stream SUB
(connected, CURVE client), and on the master the watch over its handshakes:
a socket the slave refused, or that nothing answered, is made anew, and
while no session comes up the likely cause is named (``diagnosis``).
"""

from __future__ import annotations

import logging
from pathlib import Path

import zmq
from zmq.utils.monitor import recv_monitor_message

from telethermal.errors import TransportError
from telethermal.ports import wait_released
from telethermal.wire.handshake import AllowedKeys, HandshakeWatch, diagnose, fingerprint
from telethermal.wire.keys import check_allowed_folder, load_public, load_secret
from telethermal.wire.loglimit import LogLimiter
from telethermal.wire.schema import MAX_MESSAGE_BYTES

# The endpoint's one log, named as before its code was split in modules
# (operators filter on it; tests/integration/test_setup_errors.py reads it).
log = logging.getLogger("telethermal.wire.transport")

#: ZeroMQ drops the *connection* of a peer sending more than this (the
#: message is never read); up to it, a message over MAX_MESSAGE_BYTES is read,
#: counted (``oversized``) and dropped.
RECEIVE_LIMIT_BYTES = 4 * MAX_MESSAGE_BYTES
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


class EndpointSockets:
    """The sockets of one :class:`~telethermal.wire.transport.Endpoint`,
    which owns them: opens (:meth:`open`), secures, recreates and closes
    ``control`` and ``stream``. ``session_id`` names the master's control
    connection; ``counters`` is the endpoint's (``curve_rejected``,
    ``sockets_recreated``)."""

    def __init__(self, *, role: str, config, ctx: zmq.Context, clock, session_id: str,
                 counters: dict):
        """The socket state, declared before any socket is opened (so that
        :meth:`close` after a failed open closes what there is)."""
        self.role, self.config, self.ctx, self.clock = role, config, ctx, clock
        self.session_id, self.counters = session_id, counters
        self.control = self.stream = None
        self.ports: list[int] = []                  # slave: the ports bound
        self.poller: zmq.Poller | None = None
        self._auth: AllowedKeys | None = None
        #: Slave (CURVE): monitors of handshakes refused before a key was offered.
        self._refusals: dict[str, zmq.Socket] = {}
        self._limiter = LogLimiter(log)
        self._watch: dict[str, HandshakeWatch] = {}   # master: per socket
        self._unlinked_since: float | None = self.clock()
        self._diagnosed_at = -1e9
        self._fingerprint: str | None = None
        #: Master: the likely cause while no session comes up, else None.
        self.diagnosis: dict | None = None

    def _secure(self, sock, server: bool):
        cfg = self.config
        if cfg.security != "curve":
            return
        if server:
            public, secret = load_secret(cfg.keys_dir, cfg.server_key, private=True)
            sock.curve_publickey, sock.curve_secretkey = public, secret
            sock.curve_server = True
        else:
            public, secret = load_secret(cfg.keys_dir, cfg.client_key)
            sock.curve_publickey, sock.curve_secretkey = public, secret
            sock.curve_serverkey = load_public(cfg.keys_dir, cfg.server_key)

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

    def open(self) -> None:
        """Open, bind or connect, and poll both sockets."""
        cfg = self.config
        try:
            if self.role == "slave":
                self._open_slave_sockets()
            else:
                for name in ("control", "stream"):
                    self._connect(name)
        except TransportError:
            self.close()
            raise
        except zmq.ZMQError as exc:
            self.close()
            host = cfg.bind_host if self.role == "slave" else cfg.host
            raise TransportError(f"{self.role}: cannot open sockets on {host}:"
                                 f"{cfg.control_port}/{cfg.stream_port}: {exc}") from exc
        self.poller = zmq.Poller()
        self.poller.register(self.control, zmq.POLLIN)
        self.poller.register(self.stream, zmq.POLLIN)

    def _open_slave_sockets(self) -> None:
        """The slave's ROUTER and PUB, bound (CURVE: keys of ``allowed_dir``)."""
        cfg = self.config
        if cfg.security == "curve":
            allowed = Path(cfg.allowed_dir)
            check_allowed_folder(allowed)        # no other user may add a master
            # A secret others can read refused before the authenticator starts.
            load_secret(cfg.keys_dir, cfg.server_key, private=True)
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
        if cfg.security == "curve":
            self._refusals = {name: getattr(self, name).get_monitor_socket(
                zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL | zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL)
                for name in ("control", "stream")}

    def watch_refusals(self, now: float) -> None:
        """Slave: connections whose handshake failed before any key was
        offered (a plain client, a wrong mechanism, not ZeroMQ): counted
        (``handshake_refused``) and logged, rate-limited. libzmq's monitor
        gives the listening address only, not the peer's."""
        for name, monitor in self._refusals.items():
            while monitor.poll(0):
                event = recv_monitor_message(monitor, zmq.NOBLOCK)
                self.counters["handshake_refused"] += 1
                self._limiter.warn("handshake_refused", now, "slave: refused a connection on "
                                   "%s (%s socket): handshake failed (%s): a plain or "
                                   "non-CURVE client; %d refused so far",
                                   event["endpoint"].decode("ascii", "replace"), name,
                                   zmq.Event(event["event"]).name,
                                   self.counters["handshake_refused"])

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

    def watch_handshakes(self, now: float, alive: bool) -> None:
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
                fingerprint(load_secret(self.config.keys_dir, self.config.client_key)[0])
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
            sock = getattr(self, name)
            watch = self._watch.get(name)
            monitor = self._refusals.pop(name, None)
            if sock is not None:
                if watch is not None:
                    watch.close(sock)
                if monitor is not None:
                    HandshakeWatch(name, monitor).close(sock)
                sock.close(linger=0)
        if self._auth is not None:
            self._auth.stop()
            self._auth = None
        if self.role == "slave" and self.ports:
            # Closed means free: the ports can be bound again when this returns.
            wait_released(self.config.bind_host, self.ports)
            self.ports = []

    @property
    def last_rejected_key(self) -> dict | None:
        """Slave: the latest master key refused (fingerprint, address)."""
        return None if self._auth is None else self._auth.last_rejected
