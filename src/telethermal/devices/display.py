"""The master's display devices behind one interface, whichever they are.

``read(t_s) -> PadSensors`` and ``apply(t_s, step, dt_s, force_n)`` each
control period (``step.current_a``: the module current the master commands,
after its limits); ``counters()``; ``close()``. The hardware displays also
give ``module_readings() -> (junction_c, heatsink_c, current_a)``, the
Peltier driver's last status (NaN when it cannot be trusted), for the
master's junction loop.

* :class:`SimDisplay` (``devices = "sim"``): the simulator directly.
* :class:`HardwareDisplay`: the sensor board on a serial port and the
  Peltier driver on a CAN bus, real or emulated; no simulator in it.
* :class:`EmulatedDisplay` (``devices = "emulated"``): the simulator behind
  emulated devices (a pty and a python-can virtual bus) and a
  :class:`HardwareDisplay` reading them, so every byte the real devices
  would send goes through the drivers.

A reading the display cannot trust (a missing or stale frame, a channel the
board flagged, a Peltier driver that is not healthy: no heartbeat,
disabled by its own protection, a fault flag) comes out as NaN, and the
safety supervisor puts the pad in its safe state in that very period.
"""

from __future__ import annotations

import importlib
import itertools
import math
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Protocol

from telethermal.control.safety import SafetyLimits
from telethermal.devices.board import Calibration, SensorBoard
from telethermal.devices.emulators import PeltierEmulator, SensorBoardEmulator
from telethermal.devices.kinds import DeviceKind, parse_device_kind
from telethermal.devices.peltier import PeltierDriver
from telethermal.devices.readings import PadSensors

DEVICE_KINDS = tuple(k.value for k in (DeviceKind.SIM, DeviceKind.EMULATED))
_bus_names = itertools.count()


class SimDisplay:
    kind = DeviceKind.SIM

    def __init__(self, touch):
        self.touch = touch

    def read(self, t_s: float) -> PadSensors:
        return self.touch.sense(t_s)

    def apply(self, t_s: float, step, dt_s: float, force_n: float) -> None:
        self.touch.actuate(t_s, step, dt_s, force_n)

    def counters(self) -> dict:
        return {}

    def close(self) -> None:
        pass


class HardwareDisplay:
    kind = DeviceKind.HARDWARE

    def __init__(self, board_url: str, can_bus: str, calibration: Calibration = Calibration(),
                 clock=time.monotonic, wait_s: float = 0.0):
        self.clock = clock
        self.wait_s = wait_s
        self.board = SensorBoard(board_url, calibration, clock=clock)
        try:
            self.peltier = PeltierDriver(can_bus, clock=clock)
        except Exception:
            self.board.close()
            raise
        self._first_command_s: float | None = None
        self.untrusted_periods = 0
        self.stale_readings = 0          # periods the board gave no current reading
        #: Whether the last :meth:`read` brought a new board frame (False: the
        #: board's reading held its previous one, within its ``stale_s``).
        self.fresh = False

    def _actuator_trusted(self) -> bool:
        p = self.peltier
        if p.healthy:
            return True
        # Until the driver has answered a first command, it cannot be healthy.
        return p.status is None and (self._first_command_s is None or
                                     self.clock() - self._first_command_s <=
                                     p.heartbeat_timeout_s)

    def read(self, t_s: float) -> PadSensors:
        before = self.board.latest
        flux, temp, force = self.board.reading(self.wait_s)
        self.fresh = self.board.latest is not before
        if not (math.isfinite(flux) and math.isfinite(temp)):
            self.stale_readings += 1
        self.peltier.poll()
        if not self._actuator_trusted():
            self.untrusted_periods += 1
            flux = math.nan
        junction, sink, _ = self.peltier.readings()
        return PadSensors(flux, temp, force, junction, sink)

    def apply(self, t_s: float, step, dt_s: float, force_n: float) -> None:
        """Send ``step.current_a`` (clamped to the driver's limit; a NaN is
        the driver's :class:`DeviceError`, the caller's safe state)."""
        if self._first_command_s is None:
            self._first_command_s = self.clock()
        self.peltier.command(step.current_a)

    def module_readings(self) -> tuple[float, float, float]:
        """(junction_c, heatsink_c, current_a) the Peltier driver last
        reported; NaN when it is not healthy."""
        return self.peltier.readings()

    def counters(self) -> dict:
        return {"board": self.board.all_counters, "peltier": dict(self.peltier.counters),
                "untrusted_periods": self.untrusted_periods,
                "stale_readings": self.stale_readings}

    def close(self) -> None:
        try:
            self.peltier.close()
        finally:
            self.board.close()


class EmulatedDisplay:
    """The simulator's display touch behind emulated devices, stepped in
    lockstep with the control loop (each period the board's frame is written
    and waited for, and the Peltier driver's reply is read back)."""

    kind = DeviceKind.EMULATED

    def __init__(self, touch, clock=time.monotonic, realtime: bool = False, seed: int = 0):
        self.touch = touch
        self._dir = tempfile.TemporaryDirectory(prefix="telethermal-dev-")
        self.board_emulator = SensorBoardEmulator(Path(self._dir.name) / "sensor-board",
                                                  seed=seed)
        bus = f"virtual:telethermal-display-{next(_bus_names)}"
        self._applied_a: float | None = None
        self._junction_c = getattr(touch, "junction_c", SafetyLimits().neutral_c)
        self.peltier_emulator = PeltierEmulator(bus, self._on_current, clock=clock,
                                                state=self._module_state)
        # In lockstep on the simulated clock, wait for each frame; on the real
        # clock, a board streams on its own and the loop takes what is there.
        self.hardware = HardwareDisplay(self.board_emulator.path, bus, clock=clock,
                                        wait_s=5e-4 if realtime else 0.05)

    def _on_current(self, current_a: float) -> None:
        self._applied_a = current_a

    @property
    def applied_a(self) -> float | None:
        """The current the emulated board drove on the last command it took
        since :meth:`clear_applied` (or the last :meth:`apply`); None if none."""
        return self._applied_a

    def clear_applied(self) -> None:
        self._applied_a = None

    def _module_state(self) -> tuple[float, float, float]:
        """What the emulated board measures: the touch's ``module_state()``
        (junction_c, heatsink_c, current_a) once the physics side gives the
        touch one; until then the junction the touch was last driven to, the
        heat sink at 25 C and the current the board drives."""
        module_state = getattr(self.touch, "module_state", None)
        if module_state is not None:
            return module_state()
        return self._junction_c, self.peltier_emulator.heatsink_c, \
            self.peltier_emulator.current_a

    def module_readings(self) -> tuple[float, float, float]:
        return self.hardware.module_readings()

    def read(self, t_s: float) -> PadSensors:
        s = self.touch.sense(t_s)          # the physics and the sensors' own noise and ADC
        self.board_emulator.send(t_s, s.flux_w_m2, s.pad_temp_c, s.force_n)
        self.peltier_emulator.poll()       # heartbeat, watchdog
        return self.hardware.read(t_s)

    def apply(self, t_s: float, step, dt_s: float, force_n: float) -> None:
        """The master's current through the driver and the emulated board to
        the touch: ``touch.actuate`` gets ``step`` with ``current_a`` = the
        current the board drives (0 A when it is disabled or faulted)."""
        self.hardware.apply(t_s, step, dt_s, force_n)
        self._applied_a = None
        self.peltier_emulator.poll()       # the command arrives, the board drives
        current = self._applied_a if self._applied_a is not None else \
            self.peltier_emulator.current_a
        self._junction_c = step.junction_applied_c
        self.touch.actuate(t_s, replace(step, current_a=current), dt_s, force_n)

    def counters(self) -> dict:
        """The drivers' counters, and the emulated Peltier board's own
        (``driver_board``: its watchdog trips when the loop's commands stop
        for longer than its watchdog, as a real board's would)."""
        return {**self.hardware.counters(),
                "driver_board": dict(self.peltier_emulator.counters)}

    def close(self) -> None:
        try:
            self.hardware.close()
        finally:
            self.peltier_emulator.close()
            self.board_emulator.close()
            self._dir.cleanup()


class Display(Protocol):
    """What the master's loop needs of its display's devices, whatever they are."""

    def read(self, t_s: float) -> PadSensors: ...
    def apply(self, t_s: float, step, dt_s: float, force_n: float) -> None: ...
    def counters(self) -> dict: ...
    def close(self) -> None: ...


def _by_name(module: str, name: str) -> Callable[..., Display]:
    """A display class reached by name, as python-can's ``BACKENDS`` reach
    an interface: imported when chosen (``qemu_display`` builds on
    :class:`HardwareDisplay` here, so this module does not import it)."""
    def factory(touch, clock, realtime, seed, **options) -> Display:
        return getattr(importlib.import_module(module), name)(touch, clock, realtime, seed,
                                                              **options)
    return factory


#: A simulated touch's display devices by kind (python-can's ``BACKENDS``
#: shape): ``factory(touch, clock, realtime, seed)``. The hardware display
#: has no simulated touch (``HardwareDisplay``, the master service opens it).
DISPLAYS: dict[DeviceKind, Callable[..., Display]] = {
    DeviceKind.SIM: lambda touch, clock, realtime, seed: SimDisplay(touch),
    DeviceKind.EMULATED: EmulatedDisplay,
    DeviceKind.QEMU: _by_name("telethermal.devices.qemu_display", "QemuDisplay"),
}


def open_display(kind: str, touch, clock=time.monotonic, realtime: bool = False,
                 seed: int = 0, **options) -> Display:
    """The display devices of ``kind`` around a simulated ``touch``;
    ``options`` go to its class (``boards``: a service's QEMU cores)."""
    factory = DISPLAYS.get(parse_device_kind(kind))
    if factory is None:
        raise ValueError(f"devices = {kind!r} has no simulated touch (kinds with one: "
                         f"{', '.join(DISPLAYS)}); the master service opens the hardware")
    return factory(touch, clock, realtime, seed, **options)
