"""How hard a rendering is on the module: its current's sign reversals and
ripple over a touch (module makers warn against fast polarity reversal,
which cycles the junctions thermally and shortens a module's life, and
against ripple, which lowers its COP: e.g. Laird Thermal Systems,
"Thermoelectric Handbook", and their application notes on PWM drive).
Pure functions of the current the driver was asked for, period by period.
"""

from __future__ import annotations

import numpy as np

#: A reversal is counted when the current crosses from below -this to above
#: +this (or back): a dither of a few mA around 0 A cycles nothing.
REVERSAL_HYSTERESIS_A = 0.1
#: The ripple is the current less its centred moving mean over this long.
RIPPLE_WINDOW_S = 0.1


def sign_reversals(current_a, hysteresis_a: float = REVERSAL_HYSTERESIS_A) -> int:
    """How many times the current changed sign by more than the hysteresis
    (from ``< -h`` to ``> +h`` or back; the band between counts as neither)."""
    values = np.asarray(current_a, dtype=float)
    sign = np.where(values > hysteresis_a, 1, np.where(values < -hysteresis_a, -1, 0))
    held = sign[sign != 0]
    return int(np.count_nonzero(held[1:] != held[:-1]))


def ripple_rms_a(current_a, dt_s: float, window_s: float = RIPPLE_WINDOW_S) -> float:
    """RMS of the current less its centred moving mean over ``window_s``,
    over the samples whose window lies wholly inside the series (NaN if
    none does)."""
    values = np.asarray(current_a, dtype=float)
    k = max(1, int(round(window_s / dt_s)))
    if k % 2 == 0:
        k += 1
    if values.size < k:
        return float("nan")
    mean = np.convolve(values, np.ones(k) / k, mode="valid")
    half = k // 2
    return float(np.sqrt(np.mean((values[half:values.size - half] - mean) ** 2)))
