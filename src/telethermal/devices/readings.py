"""What one control period reads from the master pad's own sensors, whichever
devices (simulated, emulated, hardware) deliver it."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class PadSensors:
    """One period's readings of the master's own sensors."""

    flux_w_m2: float        # pad -> finger, as the film sensor reads it
    pad_temp_c: float       # the sensor's thermocouple, at the contact surface
    force_n: float
    #: The Peltier module's cold junction and heat sink, as its driver board
    #: reports them (nan where the devices give none).
    junction_c: float = float("nan")
    heatsink_c: float = float("nan")
