"""The slave's active pad on CAN (node 2; ``PAD_*`` frames in ``peltier.dbc``,
``proto/CAN.md``): the driver the slave commands, and its emulator.

:class:`ActivePadDriver` is :class:`~telethermal.devices.peltier.PeltierDriver`
with the pad's frames: a set point (a Peltier pad's junction), or a heater
duty and the pump (a water pad), and the same rules for what it receives
(counted, never raised) and for when the pad can be trusted
(:attr:`healthy`). :class:`ActivePadEmulator` is the pad's driver board on
a python-can bus, with the display driver's watchdog and heartbeat.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from telethermal.devices.board import DeviceError
from telethermal.devices.emulators import PeltierEmulator
from telethermal.devices.peltier import CAN_VERSION, DB, PeltierDriver

PAD_CMD, PAD_STATUS, PAD_HEARTBEAT = (DB.get_message_by_name(n) for n in
                                      ("PAD_CMD", "PAD_STATUS", "PAD_HEARTBEAT"))
PAD_FAULTS = ("over_temp", "sensor_fault", "watchdog")


@dataclass(frozen=True, slots=True)
class PadStatus:
    enabled: bool
    actuator_c: float          # the Peltier junction, or the water pad's water
    drive: float               # Peltier current fraction, or heater duty
    heatsink_c: float
    pump_on: bool
    heater_on: bool
    faults: tuple[str, ...]
    received_s: float


class ActivePadDriver(PeltierDriver):
    CMD, STATUS, HEARTBEAT = PAD_CMD, PAD_STATUS, PAD_HEARTBEAT
    FAULTS = PAD_FAULTS
    what = "active pad driver"

    def command(self, setpoint_c: float, enable: bool = True, pump: bool = False,
                heater_duty: float = 0.0) -> bool:
        """Send the pad's set point (and, for a water pad, heater duty and
        pump); False if it could not be sent this period."""
        if not (math.isfinite(setpoint_c) and math.isfinite(heater_duty)):
            raise DeviceError(f"active pad command must be finite, got set point {setpoint_c}, "
                              f"heater duty {heater_duty}")
        return self._send_command({"enable": int(enable), "pump": int(pump),
                                   "counter": self._counter,
                                   "setpoint_c": min(max(setpoint_c, -50.0), 150.0),
                                   "heater_duty": min(max(heater_duty, 0.0), 1.0),
                                   "version": CAN_VERSION})

    def _status_of(self, s: dict, faults: tuple[str, ...]) -> PadStatus:
        return PadStatus(bool(s["enabled"]), float(s["actuator_c"]), float(s["drive"]),
                         float(s["heatsink_c"]), bool(s["pump_on"]), bool(s["heater_on"]),
                         faults, self.clock())

    def safe(self) -> bool:
        """The pad's safe state: disabled (neutral), pump and heater off."""
        from telethermal.control.safety import SafetyLimits
        return self.command(SafetyLimits().neutral_c, enable=False)


class ActivePadEmulator(PeltierEmulator):
    """The active pad's driver board: ``apply(setpoint_c)`` is called with
    what it drives the Peltier junction to (neutral when disabled)."""

    CMD, STATUS, HEARTBEAT = PAD_CMD, PAD_STATUS, PAD_HEARTBEAT

    def __init__(self, bus: str, apply, **kw):
        super().__init__(bus, apply, **kw)
        self.pump_on = False
        self.heater_duty = 0.0

    def _command(self, cmd: dict) -> None:
        super()._command(cmd)
        self.pump_on = bool(cmd["pump"]) and self.enabled
        self.heater_duty = float(cmd["heater_duty"]) if self.enabled else 0.0

    def _disable(self) -> None:
        self.pump_on, self.heater_duty = False, 0.0
        super()._disable()

    def _status_signals(self) -> dict:
        drive = max(-1.0, min(1.0, 0.05 * (self.junction_c - self.heatsink_c)))
        return {"enabled": int(self.enabled), "over_temp": int("over_temp" in self.faults),
                "sensor_fault": int("sensor_fault" in self.faults),
                "watchdog": int("watchdog" in self.faults), "pump_on": int(self.pump_on),
                "heater_on": int(self.heater_duty > 0), "counter": self._counter,
                "actuator_c": self.junction_c, "drive": drive, "heatsink_c": self.heatsink_c}
