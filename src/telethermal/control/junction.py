"""The inner loop of a Peltier pad: the module's current that brings its cold
junction to a target temperature, within what the module and its driver
allow.

What a TEC controller board does (a PI on the junction's thermistor), with
two things a board's loop does not know and this one does, because the
host has them: a feed-forward of the current that would hold the target
with the present hot side and load (the smaller root of ``Qc(I) = load``,
:func:`~telethermal.physics.thermoelectric.hold_current_a`), and the
H-bridge's limits (``|I| <= Imax`` and the supply voltage), against which the
integral does not wind up (it integrates only while the output is free, or
when the error would take it back inside).

Gains: the junction behind the pad's alumina is a thermal mass of about
0.5 J/K on a 20 x 20 mm module (junction node plus the cold plate), and a
current pumps about ``S Tc`` = 3.6 W/A at room temperature; ``kp`` = 10 A/K
puts the loop's crossover near 70 rad/s (11 Hz), far under any control rate
used here (100 Hz and up; the phase lost to one period's delay is then
under 40 degrees at 100 Hz), and ``ki/kp`` = 50 /s removes the steady error
of the feed-forward's imperfect load within about 0.1 s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from telethermal.errors import ControlError
from telethermal.physics.thermoelectric import HBridge, ModuleParams, hold_current_a


@dataclass(frozen=True)
class JunctionGains:
    kp_a_k: float = 10.0
    ki_a_ks: float = 500.0

    def __post_init__(self):
        if not (self.kp_a_k >= 0 and self.ki_a_ks >= 0 and
                math.isfinite(self.kp_a_k) and math.isfinite(self.ki_a_ks)):
            raise ControlError(f"junction gains must be finite and >= 0, got {self}")


@dataclass(frozen=True, slots=True)
class JunctionOutput:
    current_a: float           # what the driver is asked for (inside its limits)
    saturated: bool            # the limits cut the request


class JunctionLoop:
    """One :meth:`update` per control period; pure (no device, no clock)."""

    def __init__(self, params: ModuleParams, driver: HBridge,
                 gains: JunctionGains = JunctionGains()):
        self.params, self.driver, self.gains = params, driver, gains
        self.integral_a = 0.0
        self.saturated_periods = 0

    def reset(self) -> None:
        self.integral_a = 0.0

    def update(self, target_c: float, junction_c: float, hot_c: float, dt_s: float,
               load_w: float = 0.0) -> JunctionOutput:
        """The current for this period. ``junction_c``/``hot_c``: the board's
        readings of the cold junction and of the hot side (its heat sink);
        ``load_w``: heat flowing into the junction from the pad, W, as far as
        the caller knows it (0 if not). A reading that is not finite gives
        0 A: the module then only conducts, and the caller's supervisor
        decides what is safe."""
        if not (dt_s > 0 and math.isfinite(dt_s)):
            raise ControlError(f"junction loop needs a positive period, got {dt_s}")
        if not (math.isfinite(target_c) and math.isfinite(junction_c) and math.isfinite(hot_c)
                and math.isfinite(load_w)):
            self.integral_a = 0.0
            return JunctionOutput(0.0, False)
        error = junction_c - target_c        # positive: too warm, cool (positive current)
        ff = hold_current_a(self.params, target_c, hot_c, load_w)
        free = ff + self.gains.kp_a_k * error + self.integral_a
        current, cut = self.driver.limit(self.params, free, junction_c, hot_c)
        # Integrate while free, or when the error drives the output back inside.
        if not cut or (free > current) != (error > 0):
            self.integral_a += self.gains.ki_a_ks * error * dt_s
        if cut:
            self.saturated_periods += 1
        return JunctionOutput(current, cut)
