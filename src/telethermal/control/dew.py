"""No dew on the display's pad: the dew point of the room's air and the
floor the pad's idle keeps above it.

A pad idling below the dew point of the air around it fogs: a film of water
changes its contact with the finger and the flux it exchanges (and water
on the electronics is no better). The dew point by the Magnus formula with
Alduchov and Eskridge's coefficients ("Improved Magnus form approximation
of saturation vapor pressure", Journal of Applied Meteorology 35(4), 1996:
``a = 17.625``, ``b = 243.04 C``; within 0.1 K over -40..50 C):

``gamma = ln(RH / 100) + a T / (b + T)``, ``T_dew = b gamma / (a - gamma)``.

The margin: a room hygrometer's +-3 % RH is +-0.9 K of dew point at 24 C
and 50 %, the junction sensor's bias +-0.26 K; 1.5 K keeps the pad's face
dry with both at their limits (the face idles at the junction: the pad is
uniform in air).
"""

from __future__ import annotations

import math

from telethermal.errors import ControlError

MAGNUS_A = 17.625
MAGNUS_B_C = 243.04
#: The pad's idle stays this far above the dew point (see the module docstring).
DEW_MARGIN_K = 1.5


def dew_point_c(temp_c: float, humidity_pct: float) -> float:
    """The dew point (C) of air at ``temp_c`` and relative humidity
    ``humidity_pct`` (0-100 %, exclusive of 0)."""
    if not (0 < humidity_pct <= 100 and math.isfinite(temp_c)):
        raise ControlError(f"dew point needs 0 < humidity_pct <= 100 and a finite "
                           f"temperature, got {humidity_pct!r} %, {temp_c!r} C")
    gamma = math.log(humidity_pct / 100.0) + MAGNUS_A * temp_c / (MAGNUS_B_C + temp_c)
    return MAGNUS_B_C * gamma / (MAGNUS_A - gamma)


def idle_floor_c(room_c: float, humidity_pct: float, margin_k: float = DEW_MARGIN_K) -> float:
    """The lowest idle the pad may hold in this room: the dew point plus the
    margin (-inf in perfectly dry air)."""
    if humidity_pct <= 0:
        return -math.inf
    return dew_point_c(room_c, humidity_pct) + margin_k
