"""Contact detection from a force (master) or pressure (slave) reading.

Hysteresis: contact begins above ``on_n`` and ends below ``off_n`` (the
operator presses about 10 N; a light brush or sensor noise is not a touch).
Debounce: the new state must hold for ``debounce_s`` before it is reported,
and the reported onset is the first sample of that run, so the contact
instant is not delayed by the debounce. Time comes with each sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from telethermal.errors import ControlError


@dataclass(frozen=True, slots=True)
class ContactChange:
    """The detector's debounced change of state (the wire's ``ContactEvent``,
    wire/messages.py, is what the master tells the slave of it)."""

    touching: bool
    t_s: float          # onset (or release) instant: first sample past the threshold


class ContactDetector:
    def __init__(self, on_n: float = 2.0, off_n: float = 1.0, debounce_s: float = 0.02):
        if not 0 <= off_n < on_n:
            raise ControlError(f"need 0 <= off_n < on_n, got {off_n}, {on_n}")
        if debounce_s < 0:
            raise ControlError("debounce_s must be >= 0")
        self.on_n, self.off_n, self.debounce_s = on_n, off_n, debounce_s
        self.touching = False
        self._candidate_since: float | None = None
        self._last_t: float | None = None

    def update(self, t_s: float, force_n: float) -> ContactChange | None:
        """Feed one sample; returns an event when the debounced state changes.

        A non-finite force is refused (the caller's safety supervisor decides
        what a dead sensor means); time must increase."""
        if not (math.isfinite(t_s) and math.isfinite(force_n)):
            raise ControlError(f"contact sample must be finite, got t={t_s}, force={force_n}")
        if self._last_t is not None and t_s <= self._last_t:
            raise ControlError(f"contact samples must move forward in time ({t_s} after "
                               f"{self._last_t})")
        self._last_t = t_s
        crossing = force_n < self.off_n if self.touching else force_n > self.on_n
        if not crossing:
            self._candidate_since = None
            return None
        if self._candidate_since is None:
            self._candidate_since = t_s
        if t_s - self._candidate_since >= self.debounce_s:
            self.touching = not self.touching
            onset, self._candidate_since = self._candidate_since, None
            return ContactChange(self.touching, onset)
        return None
