"""A fixed-rate loop runner that measures its own timing, on a real or a
simulated clock.

On the real clock each period sleeps to an absolute deadline (never "sleep
for dt", which accumulates drift) and busy-waits the last ``spin_s`` of it,
which holds p99 lateness to some microseconds on this class of machine
where ``time.sleep`` alone overshoots by 50-100 us, and by up to some
hundreds after a sleep of several milliseconds (a virtual machine's idle
vCPU wakes late). :meth:`RealClock.for_period` spins a fixed fraction of
the period (``SPIN_FRACTION``: the same share of a core at every rate).
When a step overruns (or the machine stalls), the missed deadlines are skipped, not made up in a
burst: the next deadline is the first one still in the future, the miss is
counted, and the step is given the true elapsed time ``dt_s`` so that
controllers integrate over what really passed.

:class:`SimClock` moves only when slept on, so a loop on it is exact and
instant; tests use it, and can make chosen steps "take" a given time to
check the overrun policy.
"""

from __future__ import annotations

import gc
import math
import os
import time
import warnings
from collections import deque
from contextlib import contextmanager
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Callable

import numpy as np

from telethermal.errors import ControlError

#: A lateness above this is a stall of the machine, reported apart (s).
STALL_S = 3e-3
#: The share of each period :meth:`RealClock.for_period` busy-waits: 200 us
#: at 1 kHz (50-100 us of sleep overshoot covered), 1 ms at 200 Hz. Spinning
#: the last fifth of the period rather than sleeping through it absorbs the
#: operating system's wake-up delay (``bench render``'s real-clock rows give
#: the lateness it leaves). A fifth of a core at any rate.
SPIN_FRACTION = 0.2

#: The display loop's rate, chosen from ``bench render``'s error against
#: rate (bench/results/render.json): the skin error is flat from 100 Hz to
#: 2 kHz, the flux error over the first second falls with the rate and 500 Hz
#: has all but a fraction of a point of it, and a 2-core machine's master
#: loop misses fewer deadlines at 500 Hz than at 1 kHz, where its sleeps are
#: too short to absorb the wake-up delays (docs/concepts/loop.md has the
#: figures). The first paper's dSPACE ran at 100 Hz.
DEFAULT_RATE_HZ = 500.0


#: The display loop's SCHED_FIFO priority in the shipped deployments
#: (deploy/two-host/master.toml, the systemd unit, ``telethermal demo``): above
#: every normal thread, below the kernel's own real-time threads (50).
DEPLOYED_PRIORITY = 20


def set_realtime(priority: int) -> str:
    """The calling thread at SCHED_FIFO ``priority`` (0: normal scheduling,
    left as it is). Returns "" when granted, else why not (no root nor
    CAP_SYS_NICE, or a platform without it): the loop then runs at normal
    priority, which the caller says."""
    if not priority:
        return ""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return str(exc) or type(exc).__name__
    return ""


@contextmanager
def realtime(priority: int):
    """:func:`set_realtime` for a block, the thread's policy restored after
    (a restore the system refuses is warned about, never raised over the
    block's own error). Yields ``(granted, why_not)``: the priority granted
    (0: refused or not asked) and the refusal's reason ("" when granted)."""
    if not priority:
        yield 0, ""
        return
    try:
        before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
    except (OSError, AttributeError) as exc:        # a platform without them
        yield 0, str(exc) or type(exc).__name__
        return
    refused = set_realtime(priority)
    try:
        yield (0 if refused else priority), refused
    finally:
        if not refused:
            try:
                os.sched_setscheduler(0, before[0], os.sched_param(before[1]))
            except OSError as exc:
                warnings.warn(f"the thread's scheduling policy {before} not restored after "
                              f"SCHED_FIFO {priority}: {exc}", RuntimeWarning, stacklevel=3)


class RealClock:
    """``time.perf_counter`` with an absolute-deadline sleep.

    ``scale``: how many of the machine's seconds one of this clock's lasts
    (1: the machine's time). A loop on a scaled clock runs ``scale`` times
    slower than its period says, every time it reads and every deadline it
    sleeps to: for boards emulated slower than real time (QEMU's cores,
    ``time_scale`` in the services' configs), whose plant waits for them.
    ``spin_s`` stays in the machine's seconds."""

    def __init__(self, spin_s: float = 200e-6, scale: float = 1.0):
        if not (spin_s >= 0 and math.isfinite(spin_s)):
            raise ControlError(f"spin_s must be a finite time >= 0, got {spin_s}")
        check_time_scale(scale)
        self.spin_s, self.scale = spin_s, float(scale)

    @classmethod
    def for_period(cls, period_s: float, scale: float = 1.0):
        """A clock for a loop of ``period_s``: it spins ``SPIN_FRACTION`` of it."""
        return cls(SPIN_FRACTION * period_s, scale)

    def now(self) -> float:
        return time.perf_counter() / self.scale

    def monotonic(self) -> float:
        """``time.monotonic`` on this clock's scale (the services' message times)."""
        return time.monotonic() / self.scale

    def sleep_until(self, deadline_s: float) -> None:
        remaining = (deadline_s - self.now()) * self.scale      # the machine's seconds
        if remaining > self.spin_s:
            time.sleep(remaining - self.spin_s)
        while self.now() < deadline_s:
            pass


#: The slowest a scaled clock may run: past it a period of a 500 Hz display
#: lasts over 0.2 s of the machine's time.
MAX_TIME_SCALE = 100.0


def check_time_scale(scale, error: type[Exception] = ControlError, name: str = "scale") -> float:
    """``scale`` if it is a number from 1 to :data:`MAX_TIME_SCALE`, else
    ``error`` naming ``name``."""
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or \
            not (1.0 <= scale <= MAX_TIME_SCALE):
        raise error(f"{name} = {scale!r}: how many of the machine's seconds one second of "
                    f"the services lasts, from 1 (real time) to {MAX_TIME_SCALE:g}")
    return float(scale)


class SessionClock(StrEnum):
    """The clock a simulated session's loop runs on (its value is what the
    session's summary says in ``clock``)."""
    #: :class:`SimClock`: exact and instant.
    SIMULATED = "simulated"
    #: :class:`RealClock`: the simulated world's time charged to the loop.
    REAL = "real"
    #: :class:`WorldPausedClock`: the real clock less the world's time.
    WORLD_PAUSED = "real, less the world's time"


#: What a session's summary calls a run on :class:`WorldPausedClock`.
WORLD_PAUSED = SessionClock.WORLD_PAUSED.value

#: The older spellings ``run_session(realtime=...)`` still takes.
_CLOCK_ALIASES = {False: SessionClock.SIMULATED, True: SessionClock.REAL,
                  "master": SessionClock.WORLD_PAUSED}


def session_clock(value, error: type[Exception] = ValueError) -> SessionClock:
    """``value`` as a :class:`SessionClock`: one, its value, or False
    (simulated), True (real) or "master" (world paused); ``error`` naming
    the choices."""
    if isinstance(value, (bool, str)) and value in _CLOCK_ALIASES:
        return _CLOCK_ALIASES[value]
    try:
        return SessionClock(value)
    except (ValueError, TypeError):
        raise error("realtime must be a SessionClock ("
                    f"{', '.join(repr(c.value) for c in SessionClock)}), False, True or "
                    f"'master', got {value!r}") from None


class WorldPausedClock(RealClock):
    """The real clock less the time spent inside :meth:`world`: for a loop
    that also simulates what, in a lab, runs elsewhere (the plant, the
    remote side). The loop's deadlines, lateness and busy time are then its
    own work's on this machine (the OS, the sleeps, the machine's stalls
    outside the world's spans included); the world's time is not charged
    to it."""

    def __init__(self, spin_s: float = 200e-6, scale: float = 1.0):
        if scale != 1.0:
            raise ControlError(f"a world-paused clock runs on the machine's time, got scale "
                               f"{scale!r}")
        super().__init__(spin_s)
        self.paused_s = 0.0

    def now(self) -> float:
        return time.perf_counter() - self.paused_s

    def sleep_until(self, deadline_s: float) -> None:
        super().sleep_until(deadline_s + self.paused_s)

    @contextmanager
    def world(self):
        start = time.perf_counter()
        try:
            yield
        finally:
            self.paused_s += time.perf_counter() - start


class SimClock:
    """Simulated time: ``sleep_until`` jumps there; ``advance`` models work."""

    def __init__(self, start_s: float = 0.0):
        self._t = start_s

    def now(self) -> float:
        return self._t

    def sleep_until(self, deadline_s: float) -> None:
        self._t = max(self._t, deadline_s)

    def advance(self, seconds: float) -> None:
        if seconds < 0:
            raise ControlError("a simulated clock cannot go back")
        self._t += seconds


@dataclass
class LoopStats:
    """What a run of the loop measured (seconds inside, microseconds out)."""

    period_s: float
    starts_s: list = field(default_factory=list)       # when each step began
    lateness_s: list = field(default_factory=list)     # start - its deadline
    busy_s: list = field(default_factory=list)         # how long each step took
    missed_deadlines: int = 0                          # deadlines skipped
    #: Deadlines that passed during a step that then restarted the loop's
    #: deadlines (:meth:`FixedRateLoop.restart_deadlines`): counted here,
    #: never in ``missed_deadlines``.
    set_aside: int = 0
    count: int = 0                                     # steps run (all, even if not kept)
    #: Steps finished (their busy time kept): ``count`` less one while a
    #: step is running (a summary taken from inside one).
    finished: int = 0
    #: Python's garbage collections during the run, per generation, and the
    #: longest (s): a pause inside a step the loop's own figures cannot name.
    gc_collections: list = field(default_factory=lambda: [0, 0, 0])
    gc_max_s: float = 0.0

    def summary(self, last: int | None = None) -> dict:
        """Period p50/p99/max, lateness p99/max, overruns, stalls (us), over
        every kept step or the ``last`` ones (deadline misses: all steps)."""
        return combined_summary([self], last)


def combined_summary(runs: list[LoopStats], last: int | None = None) -> dict:
    """:meth:`LoopStats.summary` over several runs of one period, as if one:
    periods are taken within each run (never across two), counts summed,
    percentiles over the pooled samples."""
    if not runs or len({r.period_s for r in runs}) != 1:
        raise ControlError("combined_summary needs one or more runs of one period")

    def tail(xs):
        xs = list(xs)
        return np.asarray(xs[-last:] if last else xs, dtype=float)

    def busy_tail(r):
        xs = list(r.busy_s)
        if not last:
            return np.asarray(xs, dtype=float)
        # A step still running (a summary taken inside it) has its start
        # kept and no busy time yet: the last ``last`` steps' busy times
        # are then the ``last - 1`` kept, not the one before them too.
        n = min(last, len(r.starts_s)) - (r.count - r.finished)
        return np.asarray(xs[max(0, len(xs) - n):] if n > 0 else [], dtype=float)

    starts = [tail(r.starts_s) for r in runs]
    periods = np.concatenate([np.diff(s) for s in starts if len(s) > 1] or [np.zeros(0)])
    late = np.concatenate([tail(r.lateness_s) for r in runs])
    busy = np.concatenate([busy_tail(r) for r in runs])
    period_s = runs[0].period_s

    def pct(a, q):
        return float(np.percentile(a, q) * 1e6) if len(a) else math.nan

    return {"steps": int(sum(len(s) for s in starts)), "period_target_us": period_s * 1e6,
            "period_p50_us": pct(periods, 50), "period_p99_us": pct(periods, 99),
            "period_max_us": float(periods.max() * 1e6) if len(periods) else math.nan,
            "lateness_p50_us": pct(late, 50), "lateness_p99_us": pct(late, 99),
            "lateness_max_us": float(late.max() * 1e6) if len(late) else math.nan,
            "busy_p50_us": pct(busy, 50), "busy_p99_us": pct(busy, 99),
            "busy_mean_us": float(np.mean(busy) * 1e6) if len(busy) else math.nan,
            "overruns": int(np.sum(busy > period_s)),
            "deadline_misses": int(sum(r.missed_deadlines for r in runs)),
            "deadlines_set_aside": int(sum(r.set_aside for r in runs)),
            "stalls": int(np.sum(late > STALL_S)),
            "gc_collections": [int(sum(r.gc_collections[g] for r in runs)) for g in range(3)],
            "gc_max_us": max(r.gc_max_s for r in runs) * 1e6}


def master_step_summary(step_s, rate_hz: float) -> dict:
    """A step's own times (s; one or more runs' pooled), in us: the part of
    each period a loop's caller times itself (the master's step in a
    session that also simulates its world)."""
    us = np.asarray(step_s) * 1e6
    return {"master_step_p50_us": float(np.percentile(us, 50)),
            "master_step_p99_us": float(np.percentile(us, 99)),
            "master_step_mean_us": float(np.mean(us)),
            "master_step_over_period": int(np.sum(us > 1e6 / rate_hz))}


class _GcWatch:
    """A ``gc.callbacks`` entry counting collections into ``stats``."""

    def __init__(self, stats: LoopStats):
        self.stats, self.started = stats, 0.0

    def __call__(self, phase: str, info: dict) -> None:
        if phase == "start":
            self.started = time.perf_counter()
            return
        self.stats.gc_collections[info["generation"]] += 1
        self.stats.gc_max_s = max(self.stats.gc_max_s, time.perf_counter() - self.started)


class FixedRateLoop:
    """Call ``step(t_s, dt_s)`` every ``period_s`` on ``clock``.

    ``t_s`` is the time since the loop started (at the step's start) and
    ``dt_s`` the time since the previous step began (the nominal period on
    the first step). ``step`` returns False to stop early.
    """

    def __init__(self, period_s: float, clock=None):
        if not (period_s > 0 and math.isfinite(period_s)):
            raise ControlError(f"loop period must be a positive number of seconds, "
                               f"got {period_s}")
        self.period_s = period_s
        self.clock = clock if clock is not None else RealClock.for_period(period_s)
        self._restart = False

    def restart_deadlines(self) -> None:
        """Called from a step that did work no period was waiting for (a
        service setting up a touch while nothing is being controlled): when
        the step returns, the next step starts at once (given the period as
        its ``dt_s``, as a first step is) and the deadlines follow a period
        apart from it. The deadlines that passed during this
        step are counted in :attr:`LoopStats.set_aside`, not as missed; the
        steps' start times stay on the clock, so the pause shows in the
        periods."""
        self._restart = True

    def run(self, step: Callable[[float, float], bool | None], n_steps: int,
            keep_last: int | None = None) -> LoopStats:
        """Run ``n_steps`` (``math.inf``: until ``step`` returns False);
        ``keep_last`` bounds the timing kept in memory (a long-running service)."""
        if n_steps < 0:
            raise ControlError(f"n_steps must be >= 0, got {n_steps}")
        stats = LoopStats(self.period_s)
        if keep_last:
            stats.starts_s, stats.lateness_s, stats.busy_s = (deque(maxlen=keep_last)
                                                              for _ in range(3))
        self.stats = stats
        watch = _GcWatch(stats)
        gc.callbacks.append(watch)
        try:
            return self._run(stats, step, n_steps)
        finally:
            gc.callbacks.remove(watch)

    def _run(self, stats: LoopStats, step, n_steps) -> LoopStats:
        clock, period = self.clock, self.period_s
        t0 = clock.now()
        grid = t0                               # deadline k is at grid + k * period
        k = 0                                   # index of the next deadline
        last_start = None
        done = 0
        while done < n_steps:
            done += 1
            stats.count += 1
            deadline = grid + k * period
            clock.sleep_until(deadline)
            start = clock.now()
            dt = period if last_start is None else start - last_start
            last_start = start
            stats.starts_s.append(start - t0)
            stats.lateness_s.append(start - deadline)
            self._restart = False
            keep_going = step(start - t0, dt)
            end = clock.now()
            stats.busy_s.append(end - start)
            stats.finished += 1
            # The first deadline not yet passed; count the ones skipped.
            nxt = max(k + 1, math.ceil((end - grid) / period - 1e-9))
            if self._restart:
                # The next deadline is now, the grid moved with it, and the
                # next step's dt is the period, as at the loop's first.
                stats.set_aside += nxt - (k + 1)
                k += 1
                grid = end - k * period
                last_start = None
            else:
                stats.missed_deadlines += nxt - (k + 1)
                k = nxt
            if keep_going is False:
                break
        return stats
