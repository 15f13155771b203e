"""The lossless stream of an :class:`~telethermal.wire.transport.Endpoint`
(``proto/PROTOCOL.md`` section 3): numbered messages kept until the peer
acknowledges them in its heartbeats and sent again when they are not;
heartbeats that carry the acknowledgement and time the round trip; gaps and
lost tails asked for (``resend``), and given up when they never arrive.
The receiving order itself is :class:`~telethermal.wire.ordering.OrderedReceiver`.
"""

from __future__ import annotations

from collections import OrderedDict

import msgpack

from telethermal.errors import WindowFull
from telethermal.wire.codec import encode
from telethermal.wire.ordering import MAX_BUFFERED, OrderedReceiver
from telethermal.wire.schema import LOSSLESS, PROTOCOL_VERSION

#: The sender's window: at most this many messages kept unacknowledged; a
#: send with the window full is refused (:class:`WindowFull`), never a kept
#: message dropped. No larger than the receiver's buffer, so nothing the
#: window lets out is ever out of the receiver's window.
WINDOW = 4096
assert WINDOW <= MAX_BUFFERED
#: A ``resend`` or a retransmission sends at most this many messages from the
#: first one asked for; the rest follow as the peer's ack moves (under the
#: sockets' high-water mark of 1000, so a repair does not itself overflow them).
RESEND_BURST = 256
#: Heartbeat periods a message may wait unacknowledged before it is sent again.
RETRANSMIT_AFTER = 3
#: A lossless gap still open after this many ``dead_after_s`` is given up.
GAP_GIVE_UP_DEAD = 5


class LosslessStream:
    """The lossless stream of one :class:`~telethermal.wire.transport.Endpoint`,
    which owns it: the messages it numbered and keeps until acknowledged,
    the receiving order (``receiver``), and the heartbeats' timing of the
    round trip (into ``offset``).

    What it needs of the endpoint is passed in: ``send(message, data=None)``
    puts a message on the control connection to the session's peer;
    ``unordered(kind, now, **fields)`` makes a message outside this stream
    (heartbeat, resend); ``drop(key, now, fmt, *args)`` counts and logs a
    dropped message; ``counters`` is the endpoint's (shared with the
    receiver), ``limited`` its rate-limited log, ``offset`` its
    :class:`~telethermal.wire.transport.ClockOffset`."""

    def __init__(self, *, role: str, config, clock, counters: dict, offset, limited,
                 send, unordered, drop):
        self.role, self.config, self.clock = role, config, clock
        self.counters, self.offset, self._limited = counters, offset, limited
        self._send, self._unordered, self._drop = send, unordered, drop
        self._next_seq = 1
        self._outbox: OrderedDict[int, dict] = OrderedDict()
        self.receiver = OrderedReceiver(counters)
        self._last_peer_hb: tuple[float, float] | None = None   # (its sent_s, our receipt)
        self._resend_asked_at = -1e9
        self._resend_served_at = -1e9
        self._tail_since: float | None = None       # when a lost tail was first seen
        self._ack_moved_at = -1e9
        self._retransmitted_at = -1e9

    @property
    def unacked(self) -> int:
        return len(self._outbox)

    @property
    def expected(self) -> int:
        """The next seq expected from the peer (a hello's ``resume_from``)."""
        return self.receiver.expected

    @property
    def last_seq(self) -> int:
        """The last seq this run numbered (0: none yet)."""
        return self._next_seq - 1

    def send(self, kind: str, now: float, fields: dict, session_up: bool) -> int:
        """Number ``kind`` in the lossless stream, keep it until acknowledged,
        and send it if a session is up; returns its seq."""
        if len(self._outbox) >= WINDOW:
            self.counters["refused_by_window"] += 1
            raise WindowFull(f"{self.role}: {kind} refused: the lossless window is full "
                             f"({len(self._outbox)} messages unacknowledged by the peer since "
                             f"seq {next(iter(self._outbox))})")
        seq = self._next_seq
        message = {"kind": kind, "v": PROTOCOL_VERSION, "seq": seq, "sent_s": now, **fields}
        data = encode(message)              # bad content is refused before it is kept
        self._next_seq += 1
        self._outbox[seq] = message
        self.counters["lossless_sent"] += 1
        if session_up:
            self._send(message, data)
        return seq

    def restart(self) -> None:
        """A new run of the peer: both directions start again from 1."""
        self.receiver.reset()
        self._tail_since = None
        self._next_seq, self._outbox = 1, OrderedDict()

    def void(self, seq: int, now: float) -> list[dict]:
        """A lossless message from the peer that cannot be used still uses
        up its seq (one bad message must not wedge the ordered stream)."""
        return self.receiver.push(seq, None, now)

    def heartbeat(self, now: float) -> None:
        """Ours: the ack of what arrived in order, the echo of the peer's
        last heartbeat (to time the round trip) and the last seq numbered."""
        echo = held = None
        if self._last_peer_hb is not None:
            echo, received = self._last_peer_hb
            held = max(now - received, 0.0)
        self._send(self._unordered(
            "heartbeat", now, ack=self.receiver.expected - 1, echo_sent_s=echo,
            echo_held_s=held, last_seq=self._next_seq - 1))

    def _ask_resend(self, now: float) -> None:
        self._send(self._unordered("resend", now, from_seq=self.receiver.expected))
        self._resend_asked_at = now

    def repair(self, now: float) -> list[dict]:
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
                self.resend_from(first)
        return out

    def resend_from(self, first: int) -> None:
        """What was asked: the kept messages from ``first``, at most
        ``RESEND_BURST`` of them."""
        sent = 0
        for seq, message in list(self._outbox.items()):
            if sent >= RESEND_BURST:
                break
            if seq >= first:
                self._send({**message, "sent_s": self.clock()})
                self.counters["resent"] += 1
                sent += 1

    def serve_resend(self, message: dict, now: float) -> None:
        """The peer's ``resend``: at most one served per heartbeat period."""
        if now - self._resend_served_at < self.config.heartbeat_s:
            self._drop("resend_throttled", now, "a second resend within %.3f s",
                       self.config.heartbeat_s)
            return
        self._resend_served_at = now
        self.resend_from(message["from_seq"])

    def receive(self, message: dict, now: float) -> list[dict]:
        """A lossless message from the peer, through the ordering; a gap it
        opens is asked for at once (at most once per heartbeat period)."""
        out = self.receiver.push(message["seq"], message, now)
        if self.receiver.buffer and now - self._resend_asked_at >= self.config.heartbeat_s:
            self.counters["gaps"] += 1
            self._ask_resend(now)
        return out

    def on_heartbeat(self, message, now) -> None:
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


def lossless_seq(data: bytes) -> int | None:
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
