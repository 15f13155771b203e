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
    """The hello half of :class:`~telethermal.wire.transport.Endpoint` (a
    base class of it). Uses the endpoint's ``role``, ``config``, ``clock``,
    ``counters``, ``session_id``, ``peer_*``, ``latest``, ``_stream_seen``,
    ``_last_heard``, its ``lossless`` stream's ``expected``, ``last_seq``,
    ``restart`` and ``resend_from``, and ``_raw_send``, ``_send_to``,
    ``_drop`` and ``_unordered``."""

    def _init_hello(self) -> None:
        self._last_hello: tuple[str, int, float] | None = None
        self._refused_at = -1e9

    def _hello(self):
        self._raw_send(self.control, self._unordered(
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
            self._raw_send(self.control, message)

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
