"""What a faulty network does to one direction of a link, message by
message: the pure part of the fault proxy, driven by the caller's clock
(so tests run it on simulated time).

For each message given at time ``now`` the channel returns when (if ever)
and how many times it is delivered:

- ``loss``: dropped with this probability;
- ``duplicate``: delivered twice with this probability (the copy after an
  extra jitter draw);
- ``delay_s`` plus ``jitter`` drawn from a named distribution (``none``,
  ``uniform`` on [0, 2 scale], ``normal`` with sd = scale folded at 0,
  ``exponential`` with mean = scale, ``pareto`` shape 2.5 with mean = scale);
  a jitter larger than the spacing of messages reorders them, as a real
  network does;
- ``reorder``: with this probability a message is held back an extra
  ``reorder_hold_s`` (explicit reordering);
- ``bandwidth_bytes_s``: a serialising link; a message leaves when the link
  has sent the ones before it (queueing delay grows with load);
- ``partitions``: windows ``(start_s, duration_s)`` in which every message
  is lost (a blackhole), times relative to the channel's ``t0_s``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from telethermal.errors import TelethermalError

JITTER_KINDS = ("none", "uniform", "normal", "exponential", "pareto")


class FaultProfileError(TelethermalError):
    """A fault profile that cannot be used (names the key)."""


@dataclass(frozen=True)
class Direction:
    delay_s: float = 0.0
    jitter: str = "none"
    jitter_s: float = 0.0
    loss: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    reorder_hold_s: float = 0.05
    bandwidth_bytes_s: float = math.inf
    partitions: tuple[tuple[float, float], ...] = ()

    def __post_init__(self):
        for name in ("loss", "duplicate", "reorder"):
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise FaultProfileError(f"{name} must be a probability in [0, 1], got {p}")
        for name in ("delay_s", "jitter_s", "reorder_hold_s"):
            v = getattr(self, name)
            if not (v >= 0 and math.isfinite(v)):
                raise FaultProfileError(f"{name} must be >= 0 seconds, got {v}")
        if self.jitter not in JITTER_KINDS:
            raise FaultProfileError(f"jitter must be one of {JITTER_KINDS}, got {self.jitter!r}")
        if not self.bandwidth_bytes_s > 0:
            raise FaultProfileError(f"bandwidth_bytes_s must be > 0, got {self.bandwidth_bytes_s}")
        for window in self.partitions:
            if len(window) != 2 or window[1] < 0:
                raise FaultProfileError(f"a partition is (start_s, duration_s >= 0), got {window}")


@dataclass
class Channel:
    """One direction; ``send(now, n_bytes)`` -> delivery times (maybe none)."""

    profile: Direction
    rng: np.random.Generator
    t0_s: float = 0.0
    counters: dict = field(default_factory=lambda: dict.fromkeys(
        ("messages", "lost", "partitioned", "duplicated", "reordered", "delivered"), 0))
    _link_free_at: float = -math.inf

    def _jitter(self) -> float:
        p = self.profile
        scale = p.jitter_s
        if p.jitter == "none" or scale == 0:
            return 0.0
        if p.jitter == "uniform":
            return float(self.rng.uniform(0.0, 2 * scale))
        if p.jitter == "normal":
            return float(abs(self.rng.normal(0.0, scale)))
        if p.jitter == "exponential":
            return float(self.rng.exponential(scale))
        shape = 2.5                                          # pareto, mean = scale
        return float((self.rng.pareto(shape) + 1) * scale * (shape - 1) / shape)

    def partitioned(self, now: float) -> bool:
        t = now - self.t0_s
        return any(start <= t < start + length for start, length in self.profile.partitions)

    def send(self, now: float, n_bytes: int) -> list[float]:
        p = self.profile
        self.counters["messages"] += 1
        if self.partitioned(now):
            self.counters["partitioned"] += 1
            return []
        if p.loss and self.rng.random() < p.loss:
            self.counters["lost"] += 1
            return []
        # A serialising link: this message leaves once the previous ones have.
        start = max(now, self._link_free_at)
        self._link_free_at = start + n_bytes / p.bandwidth_bytes_s
        base = self._link_free_at + p.delay_s
        times = [base + self._jitter()]
        if p.reorder and self.rng.random() < p.reorder:
            times[0] += p.reorder_hold_s
            self.counters["reordered"] += 1
        if p.duplicate and self.rng.random() < p.duplicate:
            times.append(base + self._jitter())
            self.counters["duplicated"] += 1
        self.counters["delivered"] += len(times)
        return times
