"""The slave's active pad on CAN (node 2; ``PAD_*`` frames in ``peltier.dbc``,
``proto/CAN.md``): the driver the slave commands, and its emulator.

:class:`ActivePadDriver` is :class:`~telethermal.devices.peltier.PeltierDriver`
with the pad's frames: the module current (a Peltier pad; protocol version
2, as ``PELTIER_CMD``), or a heater duty and the pump (a water pad), and the
same rules for what it receives (counted, never raised), for versions and
for when the pad can be trusted (:attr:`healthy`). :class:`ActivePadEmulator`
is the pad's driver board on a python-can bus, with the display driver's
watchdog, heartbeat and protections; its status reports the Peltier current
as ``drive``, a fraction of its current limit.

The slave's pre-conditioning loop thinks in junction temperatures;
:func:`junction_current_a` and :func:`current_junction_c` are the module's
small-signal steady state that turns one into the other (the loop's
integral on the pad's reading takes up what it leaves out).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from telethermal.devices.board import DeviceError
from telethermal.devices.emulators import PeltierEmulator
from telethermal.devices.peltier import CAN_VERSION, DB, PeltierDriver, clamp_current_a
from telethermal.physics.thermoelectric import DEFAULT_MODULE, KELVIN, derive, get_module

PAD_CMD, PAD_STATUS, PAD_HEARTBEAT = (DB.get_message_by_name(n) for n in
                                      ("PAD_CMD", "PAD_STATUS", "PAD_HEARTBEAT"))
PAD_FAULTS = ("over_temp", "sensor_fault", "watchdog")
_MODULE = derive(get_module(DEFAULT_MODULE))


def amps_per_kelvin(heatsink_c: float, params=_MODULE) -> float:
    """The module's small-signal steady state with no load: a current I holds
    the junction ``I / g`` below the sink, ``g = K / (S Tc)`` (A/K; Joule
    heat, second order in I, left out). For the default module at 25 C,
    about 0.047 A/K."""
    return params.conductance_w_k / (params.seebeck_v_k * (heatsink_c + KELVIN))


def junction_current_a(junction_c: float, heatsink_c: float) -> float:
    """The current that holds the junction at ``junction_c`` (positive
    cools: a junction below the sink)."""
    return amps_per_kelvin(heatsink_c) * (heatsink_c - junction_c)


def current_junction_c(current_a: float, heatsink_c: float) -> float:
    """The junction a held ``current_a`` settles to (the inverse)."""
    return heatsink_c - current_a / amps_per_kelvin(heatsink_c)


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
    FAULTS, WARNINGS = PAD_FAULTS, ()
    what = "active pad driver"

    def command(self, current_a: float, enable: bool = True, pump: bool = False,
                heater_duty: float = 0.0) -> bool:
        """Send the Peltier pad's module current (A, positive cools the pad
        side, clamped to ``current_limit_a``; and, for a water pad, heater
        duty and pump); False if it could not be sent this period."""
        if not math.isfinite(heater_duty):
            raise DeviceError(f"active pad command must be finite, got heater_duty="
                              f"{heater_duty!r}")
        applied = clamp_current_a(current_a, self.current_limit_a)
        self.commanded_a = applied
        return self._send_command({"enable": int(enable), "pump": int(pump),
                                   "counter": self._counter, "current_a": applied,
                                   "heater_duty": min(max(heater_duty, 0.0), 1.0),
                                   "version": CAN_VERSION})

    def _status_of(self, s: dict, faults: tuple[str, ...]) -> PadStatus:
        return PadStatus(bool(s["enabled"]), float(s["actuator_c"]), float(s["drive"]),
                         float(s["heatsink_c"]), bool(s["pump_on"]), bool(s["heater_on"]),
                         faults, self.clock())

    def readings(self) -> tuple[float, float, float]:
        """(actuator_c, heatsink_c, drive) of the last status, NaN when not healthy."""
        s = self.status
        if s is None or not self.healthy:
            return math.nan, math.nan, math.nan
        return s.actuator_c, s.heatsink_c, s.drive

    def safe(self) -> bool:
        """The pad's safe state: disabled (0 A), pump and heater off."""
        return self.command(0.0, enable=False)


class ActivePadEmulator(PeltierEmulator):
    """The active pad's driver board: ``on_current(current_a)`` is called
    with the current it drives (0 A when disabled); ``state`` as
    :class:`PeltierEmulator`'s. ``PAD_STATUS`` has no over-current flag: an
    over-current is reported as ``sensor_fault`` (the board cut the current
    on a measurement it cannot explain)."""

    CMD, STATUS, HEARTBEAT = PAD_CMD, PAD_STATUS, PAD_HEARTBEAT

    def __init__(self, bus: str, on_current, **kw):
        super().__init__(bus, on_current, **kw)
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
        junction_c, heatsink_c, current_a = self.measured()
        drive = max(-1.0, min(1.0, current_a / self.current_limit_a)) \
            if math.isfinite(current_a) else 0.0
        return {"enabled": int(self.enabled), "over_temp": int("over_temp" in self.faults),
                "sensor_fault": int(bool({"sensor_fault", "over_current"} & self.faults)),
                "watchdog": int("watchdog" in self.faults), "pump_on": int(self.pump_on),
                "heater_on": int(self.heater_duty > 0), "counter": self._counter,
                "actuator_c": self._frame_c(junction_c), "drive": drive,
                "heatsink_c": self._frame_c(heatsink_c)}
