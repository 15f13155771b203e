"""Rate-limited warnings for input a peer controls.

A peer that sends garbage must not be able to fill the disk with our log:
each kind of complaint is logged in full the first few times, then at most
once per ``period_s`` with the number of occurrences left unlogged since the
last line (``proto/PROTOCOL.md`` section 4, "Errors and counters").
"""

from __future__ import annotations

import logging


class LogLimiter:
    """``warn(key, now_s, fmt, *args)`` logs unless ``key`` has spoken too
    often; the clock is passed in (no wall clock read here)."""

    def __init__(self, logger: logging.Logger, burst: int = 3, period_s: float = 10.0):
        self.logger, self.burst, self.period_s = logger, burst, period_s
        self._seen: dict[str, int] = {}              # occurrences per key, ever
        self._last_s: dict[str, float] = {}          # when the key last logged
        self._quiet: dict[str, int] = {}             # occurrences not logged since

    def warn(self, key: str, now_s: float, fmt: str, *args, exc_info=None) -> bool:
        """Log at WARNING if allowed (with ``exc_info``'s traceback if given);
        returns whether a line was written."""
        seen = self._seen.get(key, 0) + 1
        self._seen[key] = seen
        if seen > self.burst and now_s - self._last_s.get(key, -1e18) < self.period_s:
            self._quiet[key] = self._quiet.get(key, 0) + 1
            return False
        quiet = self._quiet.pop(key, 0)
        self._last_s[key] = now_s
        if quiet:
            fmt += " (and %d more like it not logged in the last %.0f s)"
            args = (*args, quiet, self.period_s)
        self.logger.warning(fmt, *args, exc_info=exc_info)
        return True
