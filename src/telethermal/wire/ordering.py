"""The receiving half of the lossless control stream (``proto/PROTOCOL.md``
section 4): delivery strictly in ``seq`` order, duplicates, a bounded
window of buffered successors, and the rule that keeps one bad or lost
message from wedging the stream.

It holds no socket and reads no clock (``now_s`` is passed in), so every
case is a unit test.
"""

from __future__ import annotations

from dataclasses import dataclass, field

#: Largest number of out-of-order messages buffered, and how far ahead of
#: the next expected seq a message may be (further is out of window).
MAX_BUFFERED = 4096


@dataclass
class OrderedReceiver:
    """``push(seq, message)`` returns what can be delivered now, in order.

    ``message`` None is a *void*: a lossless message whose envelope was
    readable but whose content was not (invalid, or a kind the sender may
    not send): it uses up its ``seq`` and delivers nothing.
    """

    counters: dict
    expected: int = 1
    buffer: dict = field(default_factory=dict)
    gap_since_s: float | None = None        # when the gap at ``expected`` opened

    def reset(self) -> None:
        """The peer restarted: its sequence starts again from 1."""
        self.expected, self.buffer, self.gap_since_s = 1, {}, None

    def push(self, seq: int, message: dict | None, now_s: float) -> list[dict]:
        self.counters["lossless_received"] += 1
        if seq < self.expected or seq in self.buffer:
            self.counters["duplicates"] += 1
            return []
        if seq >= self.expected + MAX_BUFFERED:
            # A replayed, wrapped or forged seq far ahead: buffering it and
            # later skipping to it would make every real message a duplicate.
            self.counters["out_of_window"] += 1
            return []
        if seq > self.expected:
            self.buffer[seq] = message
            if self.gap_since_s is None:
                self.gap_since_s = now_s
            return []
        self.expected += 1
        return self._drain([message], now_s)

    def _drain(self, out: list, now_s: float) -> list[dict]:
        while self.expected in self.buffer:
            out.append(self.buffer.pop(self.expected))
            self.counters["recovered"] += 1
            self.expected += 1
        # A gap still open after the drain is a new one: its clock starts now.
        self.gap_since_s = now_s if self.buffer else None
        return [m for m in out if m is not None]

    def skip_gap(self, now_s: float) -> list[dict]:
        """Give up the missing seqs before the first buffered one: they are
        counted as ``skipped`` and the buffered successors delivered."""
        if not self.buffer:
            return []
        first = min(self.buffer)
        self.counters["skipped"] += first - self.expected
        self.expected = first
        return self._drain([], now_s)
