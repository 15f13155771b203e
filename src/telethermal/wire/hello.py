"""The hello exchange of an :class:`~telethermal.wire.transport.Endpoint`
(``proto/PROTOCOL.md`` section 2): the master says hello every heartbeat
until the slave answers; the versions both speak are agreed; one master
at a time is served (another is refused with a ``fault`` until the
current one goes silent); a peer's new run starts both lossless directions
again from 1, a reconnection resumes them where the peer left off.
"""

from __future__ import annotations

import logging

from telethermal import __version__
from telethermal.wire.codec import encode
from telethermal.wire.schema import PROTOCOL_VERSION, SUPPORTED_VERSIONS

# The endpoint's one log, named as before its code was split in modules.
log = logging.getLogger("telethermal.wire.transport")


class HelloExchange:
    """The hello exchange of one :class:`~telethermal.wire.transport.Endpoint`,
    which owns it, and the session it agrees: the peer's run
    (``peer_session``), the version both speak (``peer_version``, None
    until a hello is taken up), the slave's connection to it
    (``peer_identity``) and when it was last heard (:meth:`heard`,
    :attr:`peer_alive`).

    What it needs of the endpoint is passed in: the endpoint's ``lossless``
    stream (restarted for a peer's new run, resent from where a hello
    resumes); ``send(message, data=None)`` to the session's peer on the
    control connection and ``send_to(identity, data)`` to one connection
    of the slave's; ``unordered(kind, now, **fields)`` makes the hello;
    ``drop(key, now, fmt, *args)`` counts and logs a dropped hello;
    ``forget_stream()`` forgets the peer's lossy kinds for its new run."""

    def __init__(self, *, role: str, config, clock, session_id: str, counters: dict,
                 lossless, send, send_to, unordered, drop, forget_stream):
        self.role, self.config, self.clock = role, config, clock
        self.session_id, self.counters, self.lossless = session_id, counters, lossless
        self._send, self._send_to, self._unordered = send, send_to, unordered
        self._drop, self._forget_stream = drop, forget_stream
        self.peer_session: str | None = None
        self.peer_identity: bytes | None = None
        self.peer_version: int | None = None
        self._last_heard: float | None = None
        self._last_hello: tuple[str, int, float] | None = None
        self._refused_at = -1e9

    # ------------------------------------------------------------ the session's peer
    def heard(self, now: float) -> None:
        """A message from the session's peer arrived at ``now``."""
        self._last_heard = now

    @property
    def peer_alive(self) -> bool:
        return self._last_heard is not None and \
            self.clock() - self._last_heard < self.config.dead_after_s

    @property
    def silent_s(self) -> float | None:
        """How long since the session's peer was last heard (None: never)."""
        return None if self._last_heard is None else self.clock() - self._last_heard

    # ------------------------------------------------------------ the exchange
    def send(self) -> None:
        """Our hello (the master's every heartbeat until answered; the
        slave's in answer to each hello taken up)."""
        self._send(self._unordered(
            "hello", self.clock(), role=self.role, versions=list(SUPPORTED_VERSIONS),
            software=f"telethermal {__version__}", session_id=self.session_id,
            resume_from=self.lossless.expected))

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
            self._send(message)

    def receive(self, message, identity, now) -> list[dict]:
        """A hello from connection ``identity`` (None: the master's one):
        taken up (returned) or refused, dropped or repeated (nothing)."""
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
        if self._repeated_hello(message, identity, now):
            return []
        self._last_hello = (message["session_id"], message["resume_from"], now)
        restarted = self.peer_session is not None and message["session_id"] != self.peer_session
        if restarted or (self.peer_session is None and self.lossless.last_seq > 0 and
                         message["resume_from"] == 1 and self.role == "slave"):
            log.info("%s: peer session %s (new run)", self.role, message["session_id"][:32])
            self.lossless.restart()
            # Its lossy kinds count from 1 again too: without this, every
            # stream message of the new run would look older than the last
            # one of the previous run and be ignored until its seq caught up.
            self._forget_stream()
        if self.peer_session is not None:
            self.counters["reconnects"] += 1
        self.peer_session = message["session_id"]
        self.peer_version = max(common)
        self.peer_identity = identity
        self._last_heard = now
        if self.role == "slave":
            self.send()                            # answer every hello
        self.lossless.resend_from(message["resume_from"])
        return [message]

    def _repeated_hello(self, message, identity, now) -> bool:
        """The same hello again: the master repeats it every heartbeat until
        the answer arrives, so a link slower than a heartbeat carries
        several. Answering or resending for each would multiply the traffic
        (measured: 30 session configs at 500 ms one way)."""
        last = self._last_hello
        if last is not None and identity == self.peer_identity and \
                last[0] == message["session_id"] and last[1] == message["resume_from"] and \
                now - last[2] < self.config.dead_after_s:
            self._last_heard = now
            self.counters["duplicate_hellos"] += 1
            return True
        return False
