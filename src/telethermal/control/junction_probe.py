"""Before a stopped junction loop re-arms: does its sensor follow the module?

A junction sensor that has come off its plate (debonded) reads the air
beside the module. At idle, the module stopped (0 A, no load), the junction
settles at its hot side, and the hot side sits near the room: the air
agrees with the settled module as well as a bonded sensor does, so "the
sensor reads the hot side" cannot tell the two apart. What tells them apart
is a move: a small current for a short time, which the module's model
(the loop's own configuration: the module's S, R, K and the heat capacity
the junction moves with, the sensor's stated lag) says warms the junction
by about ``PROBE_K``. A bonded sensor sees that warming; one in the air
does not.

The verdict is the least-squares gain of the measured response on the
predicted one over the probe, ``g = sum(m p) / sum(p^2)`` (``m``, ``p``: the
sensor's measured and modelled departures from its reading at the start):
1 for a sensor that follows the module as modelled, 0 for one that does
not. The sensor follows if ``GAIN_MIN <= g <= GAIN_MAX``: half-way between
the two hypotheses below, and the same factor of two above (a pad whose
heat capacity is off its configuration by 30 % gives 0.69-1.39; a sensor
lagging ten times its stated value 0.15-0.35: tests/unit/test_junction_rearm.py).
The probe can only decide
if the response stands far out of the sensor's scatter: the predicted
warming must reach ``SCATTER_RATIO`` times the scatter measured while the
module settled (from successive differences, so a slow drift does not
count), or the probe refuses for that reason. With the shipped chip (0.01 K
of noise) the modelled warming (0.81 K on fingertip-7's pad: ``PROBE_K``
less the losses) is some eighty times its scatter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from telethermal.physics.thermoelectric import KELVIN, HBridge, ModuleParams

#: How long the probe drives its current, in the sensor's stated lags: a
#: sensor lagging within the range the loop is designed for (half to twice
#: its stated value) then gives a gain of 0.74-1.16, one lagging ten times
#: 0.15-0.35 (its reading has not caught up with the warming); at least
#: ``PROBE_MIN_S``, and for the shipped chip (0.10 s) 0.5 s: a seventeenth
#: of the junction's own time constant in air (C/G = 8.6 s on fingertip-7's
#: pad), so the warming
#: is mostly the current's and little the losses'.
PROBE_LAGS = 5.0
PROBE_MIN_S = 0.1
#: The warming the probe's current is sized for: imperceptible, nobody
#: touching (the probe runs only at idle), and warming, so no dew.
PROBE_K = 1.0
GAIN_MIN, GAIN_MAX = 0.5, 2.0
SCATTER_RATIO = 20.0


@dataclass(frozen=True, slots=True)
class ProbeVerdict:
    follows: bool
    gain: float                # measured on predicted response (see the module docstring)
    measured_k: float          # the sensor's departure at the end of the probe
    predicted_k: float         # the model's
    current_a: float
    reason: str                # why it was refused ("" when it follows)


class JunctionProbe:
    """One probe of a stopped module (pure; the loop owns it). The caller
    applies :attr:`current_a` for the periods the probe runs and reports
    each period's reading with the current that acted before it."""

    def __init__(self, params: ModuleParams, driver: HBridge, heat_j_k: float,
                 sensor_tau_s: float, start_c: float, hot_c: float, scatter_k: float):
        self.params, self.heat_j_k, self.sensor_tau_s = params, heat_j_k, sensor_tau_s
        self.start_c, self.scatter_k = start_c, scatter_k
        pump_w_a = params.seebeck_v_k * (start_c + KELVIN)
        # Warming: a negative current (positive cools), sized by the pump alone.
        self.duration_s = max(PROBE_LAGS * sensor_tau_s, PROBE_MIN_S)
        wanted = -PROBE_K * heat_j_k / (pump_w_a * self.duration_s)
        self.current_a, _ = driver.limit(params, wanted, start_c, hot_c)
        self.junction_c = self.sensor_c = start_c        # the model's
        self.elapsed_s = 0.0
        self._mp = self._pp = 0.0
        self._measured_k = self._predicted_k = 0.0

    def observe(self, sensed_c: float, hot_c: float, applied_a: float,
                dt_s: float) -> ProbeVerdict | None:
        """Advance the model by the period's ``applied_a`` and compare the
        reading; the verdict once :attr:`duration_s` has passed, else None."""
        qc_w = float(self.params.heat_w(applied_a, self.junction_c, hot_c)[0])
        self.junction_c -= dt_s * qc_w / self.heat_j_k
        tau = self.sensor_tau_s
        self.sensor_c += (1.0 if tau <= 0 else -math.expm1(-dt_s / tau)) * \
            (self.junction_c - self.sensor_c)
        m, p = sensed_c - self.start_c, self.sensor_c - self.start_c
        self._mp, self._pp = self._mp + m * p, self._pp + p * p
        self._measured_k, self._predicted_k = m, p
        self.elapsed_s += dt_s
        return self.verdict() if self.elapsed_s >= self.duration_s - 0.5 * dt_s else None

    def verdict(self) -> ProbeVerdict:
        gain = self._mp / self._pp if self._pp > 0 else math.nan
        m, p, i = self._measured_k, self._predicted_k, self.current_a
        if not abs(p) >= SCATTER_RATIO * self.scatter_k:
            reason = (f"the junction sensor's scatter ({self.scatter_k:.3f} K) is too large to "
                      f"see a {i:+.2f} A test current's {p:+.2f} K: it cannot be checked")
        elif not GAIN_MIN <= gain <= GAIN_MAX:
            reason = (f"under a {i:+.2f} A test current the junction sensor moved {m:+.2f} K "
                      f"where the module's model moved {p:+.2f} K (gain {gain:.2f}, outside "
                      f"{GAIN_MIN}-{GAIN_MAX}): it does not follow the module (debonded, or "
                      f"lagging far past its stated {self.sensor_tau_s:.2f} s)")
        else:
            reason = ""
        return ProbeVerdict(not reason, gain, m, p, i, reason)
