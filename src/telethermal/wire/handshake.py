"""Wrong set-ups named: the slave's CURVE gatekeeper and the master's
handshake watch.

The slave authenticates masters with :class:`AllowedKeys`, a ZAP handler
(pyzmq's ``zmq.auth``) that reads the allowed-keys folder again whenever an
unknown key knocks, so a key copied in is accepted at the master's next
attempt, and that logs and counts every rejected key with its fingerprint
and the peer's address.

The master watches its sockets' events (:class:`HandshakeWatch`): libzmq
reports a refused TCP connection, a TCP connection whose CURVE handshake
failed, and a handshake the slave's authenticator refused. After such a
refusal libzmq does not reconnect at all, so the transport recreates the
socket; :func:`diagnose` turns the counts into the likely cause and its fix.
"""

from __future__ import annotations

import hashlib
import logging
import time
from dataclasses import dataclass
from pathlib import Path

import zmq
import zmq.auth
from zmq.auth.thread import ThreadAuthenticator
from zmq.utils.monitor import recv_monitor_message

log = logging.getLogger("telethermal.zap")
#: A key rejected again from the same address is logged at most this often.
REPEAT_LOG_S = 10.0


def fingerprint(z85_key: bytes | str) -> str:
    """A short, stable name of a CURVE public key (Z85 text): the first 12
    hex digits of its SHA-256. ``telethermal keys`` prints it for a new key
    pair, ``telethermal check`` for every allowed key."""
    text = z85_key.encode() if isinstance(z85_key, str) else bytes(z85_key)
    return "sha256:" + hashlib.sha256(text.strip()).hexdigest()[:12]


def key_file_fingerprint(path: str | Path) -> str:
    return fingerprint(zmq.auth.load_certificate(str(path))[0])


class AllowedKeys(ThreadAuthenticator):
    """ZAP handler for the slave: CURVE keys of the files in ``folder``.

    ``counters["curve_rejected"]`` counts every refused handshake;
    ``last_rejected`` holds the latest one (fingerprint, address, time)."""

    def __init__(self, context: zmq.Context, folder: str | Path, counters: dict):
        super().__init__(context, log=logging.getLogger("telethermal.zap.detail"))
        self.folder = Path(folder)
        self.counters = counters
        self.counters.setdefault("curve_rejected", 0)
        self.last_rejected: dict | None = None
        self._address = ""
        self._logged: dict[tuple[str, str], list] = {}      # (key, address) -> [time, repeats]
        self._keys = self._read()

    def start(self) -> None:
        super().start()
        self.configure_curve_callback(domain="*", credentials_provider=self)

    def _read(self) -> set[bytes]:
        try:
            return set(zmq.auth.load_certificates(str(self.folder)))
        except (OSError, ValueError) as exc:
            log.error("allowed keys %s unreadable: %s", self.folder, exc)
            return set()

    async def handle_zap_message(self, msg: list[bytes]) -> None:
        self._address = msg[3].decode("utf-8", "replace") if len(msg) > 3 else "?"
        await super().handle_zap_message(msg)

    def callback(self, domain: str, z85_key: bytes) -> bool:
        """True for an allowed key; an unknown one makes the folder be read
        again first (a key copied in since the last attempt)."""
        if z85_key in self._keys:
            return True
        self._keys = self._read()
        if z85_key in self._keys:
            log.info("allowed key %s (new in %s) from %s", fingerprint(z85_key), self.folder,
                     self._address)
            return True
        self._rejected(z85_key, self._address)
        return False

    def _rejected(self, z85_key: bytes, address: str) -> None:
        self.counters["curve_rejected"] += 1
        name = fingerprint(z85_key)
        now = time.monotonic()
        self.last_rejected = {"fingerprint": name, "address": address,
                              "public_key": z85_key.decode("ascii", "replace"),
                              "count": self.counters["curve_rejected"]}
        seen = self._logged.setdefault((name, address), [-1e9, 0])
        seen[1] += 1
        if now - seen[0] >= REPEAT_LOG_S:
            log.warning("rejected CURVE key %s from %s (%d time%s): not in %s; to let this "
                        "master in, copy its public key file (master.key, public key %s) "
                        "into that folder", name, address, seen[1], "s" if seen[1] > 1 else "",
                        self.folder, z85_key.decode("ascii", "replace"))
            seen[0] = now


# ---------------------------------------------------------------- master side
_FAILED = (zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL, zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL)


@dataclass
class HandshakeWatch:
    """Counts of one connecting socket's events (libzmq's socket monitor)."""

    endpoint: str
    monitor: zmq.Socket | None = None
    attempts: int = 0             # TCP connects started
    refused: int = 0              # connects that failed (refused, unreachable)
    tcp_connected: int = 0
    auth_failed: int = 0          # the slave's authenticator refused our key
    handshake_failed: int = 0     # CURVE failed otherwise (wrong slave key, not a slave)
    succeeded: int = 0
    gave_up_at: float | None = None   # a refused key: libzmq will not retry by itself
    # This socket's own life (not carried over, not reset):
    created_at: float = 0.0
    ever_connected: bool = False
    own_refused: int = 0

    @classmethod
    def on(cls, sock: zmq.Socket, endpoint: str, now: float = 0.0) -> "HandshakeWatch":
        return cls(endpoint, sock.get_monitor_socket(), created_at=now)

    def unanswered(self, now: float, after_s: float) -> bool:
        """A connect that nothing answered for ``after_s`` (its SYNs dropped):
        the kernel retries it at 1, 3, 7, 15 s..., so a firewall opened
        meanwhile would be noticed late; a new socket tries at once."""
        return not self.ever_connected and not self.own_refused and \
            now - self.created_at >= after_s

    def read(self, now: float) -> None:
        """Take every event waiting (never blocks)."""
        while self.monitor is not None and self.monitor.poll(0):
            event = recv_monitor_message(self.monitor, zmq.NOBLOCK)["event"]
            if event == zmq.EVENT_CONNECT_DELAYED:
                self.attempts += 1
            elif event == zmq.EVENT_CONNECT_RETRIED:
                self.refused += 1
                self.own_refused += 1
            elif event == zmq.EVENT_CONNECTED:
                self.tcp_connected += 1
                self.ever_connected = True
            elif event == zmq.EVENT_HANDSHAKE_FAILED_AUTH:
                self.auth_failed += 1
                self.gave_up_at = now
            elif event in _FAILED:
                self.handshake_failed += 1
            elif event == zmq.EVENT_HANDSHAKE_SUCCEEDED:
                self.succeeded += 1

    def close(self, sock: zmq.Socket) -> None:
        if self.monitor is not None:
            try:
                sock.disable_monitor()
            except zmq.ZMQError:
                pass
            self.monitor.close(linger=0)
            self.monitor = None

    def reset(self) -> None:
        """A session came up: the next diagnosis counts from here."""
        for name in ("attempts", "refused", "tcp_connected", "auth_failed", "handshake_failed",
                     "succeeded"):
            setattr(self, name, 0)

    def merged(self, other: "HandshakeWatch") -> "HandshakeWatch":
        """Counts carried over to the socket that replaces this one."""
        for name in ("attempts", "refused", "tcp_connected", "auth_failed", "handshake_failed",
                     "succeeded"):
            setattr(other, name, getattr(self, name) + getattr(other, name))
        return other


def diagnose(watch: HandshakeWatch, waited_s: float, key_fingerprint: str,
             keys_dir: str) -> dict:
    """The likely cause of a handshake that has not completed, and the fix.

    Returns ``problem`` (one line: what was tried and what happened),
    ``likely`` (the cause the events point to) and ``causes``: the three
    usual ones (address or port, firewall, key not allowed), each with its fix."""
    tried = (f"no session with the slave at {watch.endpoint} after {waited_s:.1f} s "
             f"({watch.attempts} TCP attempts, {watch.refused} refused or unreachable, "
             f"{watch.tcp_connected} connected, {watch.auth_failed} handshakes refused by "
             f"the slave, {watch.handshake_failed} failed)")
    causes = {
        "address": "wrong address or port, or the slave is not running: check host and "
                   "control_port/stream_port in [transport] against the slave's bind_host "
                   "and ports, and that `telethermal slave` runs there",
        "firewall": "nothing answers: a firewall drops the connection (on the slave host "
                    "open TCP control_port and stream_port to this master's address, "
                    "deploy/two-host/slave.nft), or no machine has that address",
        "key": f"this master's key is not allowed: copy {keys_dir}/master.key (fingerprint "
               f"{key_fingerprint}) into the slave's allowed_dir; no restart needed",
        "slave_key": f"{keys_dir}/slave.key is not this slave's public key: copy the "
                     "slave's keys/slave.key again",
    }
    if watch.auth_failed:
        likely = "key"
    elif watch.handshake_failed:
        likely = "slave_key"
    elif watch.refused and not watch.tcp_connected:
        likely = "address"
    elif not watch.tcp_connected:
        likely = "firewall"       # attempts that never answer: packets dropped
    else:
        likely = "address"
    return {"problem": tried, "likely": likely, "fix": causes[likely],
            "causes": [causes[k] for k in ("address", "firewall", "key")]}
