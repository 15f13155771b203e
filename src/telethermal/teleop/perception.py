"""What the operator feels, in perceptual units beside the kelvins: the
rendered touch against the same finger's direct contact.

* **Heat extraction over the first second**: the heat the finger lost to
  the pad against what it lost to the object, a ratio. Two materials are
  told apart by the rate they extract heat only when the rates differ by
  about 43 % (the discrimination threshold for heat-extraction rate,
  Bergmann Tiest and Kappers, "Tactile perception of thermal diffusivity",
  Attention, Perception & Psychophysics 71(3), 2009): a ratio within
  ``1 +- 0.43`` is, by that yardstick, the same material.
* **Time above the detection threshold**: how long the skin's temperature
  differs from the direct contact's by more than a fingertip detects.
  Fingertip thresholds for young adults are of the order of 0.3 K for
  cooling and 0.5 K for warming (Stevens and Choo, "Temperature sensitivity
  of the body surface over the life span", Somatosensory & Motor Research
  15(1), 1998: every region detects cold better than warmth); they hold for
  changes faster than about 0.1 K/s and rise below it (Kenshalo's
  measurements, as the issue cites them; the exact paper not checked
  here). The time counted
  here takes the thresholds at every rate, so it over-counts an error that
  drifts slower than 0.1 K/s: an upper bound.

Pure functions of a session's trace (after
:func:`~telethermal.sim.direct.compare_with_direct` has added the
direct contact's curves).
"""

from __future__ import annotations

import math

import numpy as np

#: Bergmann Tiest and Kappers 2009: heat-extraction-rate discrimination.
EXTRACTION_DISCRIMINATION_REL = 0.43
#: Stevens and Choo 1998, fingertip: detection of cooling / warming, K.
COOL_DETECTION_K = 0.3
WARM_DETECTION_K = 0.5


def heat_extraction_ratio(trace: dict, first_s: float = 1.0) -> float:
    """Heat the finger lost to the pad over the contact's first ``first_s``
    over what it lost to the object directly (flux positive pad -> finger,
    so the finger loses ``-flux``); NaN where the direct contact exchanged
    no heat."""
    t = trace["t_s"]
    window = (t >= 0) & (t < first_s) & np.isfinite(trace["direct_flux_w_m2"])
    if window.sum() < 2:
        return math.nan
    rendered = -np.trapezoid(trace["flux_w_m2"][window], t[window])
    direct = -np.trapezoid(trace["direct_flux_w_m2"][window], t[window])
    return float(rendered / direct) if direct != 0 else math.nan


def skin_above_threshold_s(trace: dict) -> float:
    """Seconds of contact during which the skin is warmer than in direct
    contact by more than the warming threshold, or cooler by more than the
    cooling one."""
    t = trace["t_s"]
    err = trace["skin_surface_c"] - trace["direct_skin_c"]
    ok = np.isfinite(err)
    if ok.sum() < 2:
        return 0.0
    dt = float(np.median(np.diff(t[ok])))
    above = (err[ok] > WARM_DETECTION_K) | (err[ok] < -COOL_DETECTION_K)
    return float(above.sum() * dt)
