"""Device emulators driven by the physics simulator, speaking the very bytes
and frames the real devices do, so the drivers run unchanged against them.

:class:`SensorBoardEmulator` writes the sensor board's frames into a
pseudo-terminal (``os.openpty``); a driver opens its slave side by path as
it would open ``/dev/ttyUSB0``. Given ``link_path``, that path is a symlink
that the emulator re-points when the "port" comes back after
:meth:`~SensorBoardEmulator.disappear`.

:class:`PeltierEmulator` is a Peltier driver board on a python-can bus:
it drives the module current it receives (through a callback into the
simulator), answers with the simulated module's state as its status, sends
its heartbeat, trips on over-current and hot-side over-temperature, and
drives 0 A when no command arrives for ``watchdog_s``.

Both take faults at run time: noise, a stuck value, dropouts, bit flips,
garbage between frames, a reboot; error frames, over-temperature and
over-current on CAN.
"""

from __future__ import annotations

import math
import os
import time
import tty
from pathlib import Path

import can
import numpy as np

from telethermal.control.safety import SafetyLimits
from telethermal.devices.board import Calibration
from telethermal.devices.frames import (FRAME_VERSION, STATUS_ALL, STATUS_FLUX, STATUS_FORCE,
                                        STATUS_HEATER, STATUS_IR, STATUS_PUMP, STATUS_TC,
                                        TYPE_BOOT, TYPE_SAMPLE, BoardFrame, encode)
from telethermal.devices.peltier import (CAN_VERSION, CMD, DEFAULT_CURRENT_LIMIT_A,
                                         FRAME_CURRENT_A, HEARTBEAT, STATE_BOOT,
                                         STATE_DISABLED, STATE_FAULT, STATE_OPERATIONAL,
                                         STATUS, open_bus)


class SensorBoardEmulator:
    """``version``: 1, the display's board; 2, the slave's (IR thermometer,
    active pad state: the keyword arguments of :meth:`send`)."""

    def __init__(self, link_path: str | Path | None = None, cold_junction_c: float = 25.0,
                 calibration: Calibration = Calibration(), seed: int = 0,
                 version: int = FRAME_VERSION):
        self.version = version
        self.link_path = Path(link_path) if link_path else None
        self.cold_junction_c = cold_junction_c
        self.calibration = calibration
        self.rng = np.random.default_rng(seed)
        self.seq = 0
        self.t0 = time.monotonic()
        # Faults, settable at any time.
        self.noise_uv = 0.0            # extra noise on both microvolt channels, RMS
        self.stuck = False             # repeat the last frame's values
        self.dropout = 0.0             # probability a frame is not sent
        self.bit_flips = 0.0           # probability a frame has one bit flipped
        self.counters = dict.fromkeys(("frames", "dropped", "flipped", "overruns",
                                       "garbage_bytes", "boots"), 0)
        self._last: BoardFrame | None = None
        self._master = self._slave = None
        self._open()

    # ------------------------------------------------------------ the pty
    def _open(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)                  # no line discipline on our bytes
        os.set_blocking(self._master, False)
        if self.link_path is not None:
            tmp = self.link_path.with_name(f".{self.link_path.name}.tmp")
            tmp.unlink(missing_ok=True)
            tmp.symlink_to(os.ttyname(self._slave))
            os.replace(tmp, self.link_path)

    @property
    def path(self) -> str:
        """What a driver opens: the symlink if any, else the tty itself."""
        if self.link_path is not None:
            return str(self.link_path)
        return os.ttyname(self._slave)

    def disappear(self) -> None:
        """The port goes away (a USB cable pulled): the pty closes, the link
        is removed; readers get an error."""
        if self.link_path is not None:
            self.link_path.unlink(missing_ok=True)
        for fd in (self._master, self._slave):
            if fd is not None:
                os.close(fd)
        self._master = self._slave = None

    def reappear(self) -> None:
        """The port comes back (at the same link path), and the board boots."""
        self._open()
        self.reboot()

    def close(self) -> None:
        self.disappear()

    # ------------------------------------------------------------ frames
    def _write(self, data: bytes) -> bool:
        if self._master is None:
            return False
        try:
            os.write(self._master, data)
            return True
        except BlockingIOError:
            self.counters["overruns"] += 1          # nobody reads: the board drops it
            return False

    def reboot(self) -> None:
        """The board restarts: a boot frame, the sequence from 0."""
        self.seq = 0
        self.counters["boots"] += 1
        extra = {} if self.version == FRAME_VERSION else \
            {"ir_object_c": 0.0, "ir_ambient_c": 0.0, "pad_drive": 0.0}
        self._write(encode(BoardFrame(0, 0, 0.0, 0.0, self.cold_junction_c, 0.0, 0,
                                      TYPE_BOOT, self.version, **extra)))
        self.seq = 1

    def garbage(self, n: int) -> None:
        """``n`` random bytes between frames (line noise, a reset board's banner)."""
        self.counters["garbage_bytes"] += n
        self._write(self.rng.integers(0, 256, n, dtype=np.uint8).tobytes())

    def frame_for(self, t_s: float, flux_w_m2: float, pad_temp_c: float,
                  force_n: float, ir_object_c: float = math.nan, ir_ambient_c: float = math.nan,
                  pad_drive: float = 0.0, heater: bool = False, pump: bool = False,
                  ir_ok: bool = True) -> BoardFrame:
        cal, cj = self.calibration, self.cold_junction_c
        status, flux_uv, tc_uv = STATUS_ALL, 0.0, 0.0
        if math.isfinite(flux_w_m2):
            flux_uv = cal.flux_uv(flux_w_m2)
        else:
            status &= ~STATUS_FLUX            # the board flags a channel it could not read
        if math.isfinite(pad_temp_c):
            tc_uv = cal.tc_uv(pad_temp_c, cj)
        else:
            status &= ~STATUS_TC
        if not math.isfinite(force_n):
            force_n, status = 0.0, status & ~STATUS_FORCE
        if self.noise_uv:
            flux_uv += self.noise_uv * self.rng.standard_normal()
            tc_uv += self.noise_uv * self.rng.standard_normal()
        if self.stuck and self._last is not None:
            last = self._last
            flux_uv, tc_uv, force_n, status = last.flux_uv, last.tc_uv, last.force_n, last.status
        if self.version == FRAME_VERSION:
            return BoardFrame(self.seq, int(t_s * 1e6), flux_uv, tc_uv, cj, force_n, status,
                              TYPE_SAMPLE)
        # The IR sensor's bit: the board clears it when the sensor did not
        # answer (``ir_ok``); the values go as the sensor gave them.
        status |= (STATUS_IR if ir_ok else 0) | (STATUS_HEATER if heater else 0) | \
            (STATUS_PUMP if pump else 0)
        return BoardFrame(self.seq, int(t_s * 1e6), flux_uv, tc_uv, cj, force_n, status,
                          TYPE_SAMPLE, self.version, ir_object_c, ir_ambient_c, pad_drive)

    def send(self, t_s: float, flux_w_m2: float, pad_temp_c: float, force_n: float,
             **slave) -> bool:
        """One sample's frame on the line (unless a dropout takes it);
        ``slave``: the version-2 fields (:meth:`frame_for`)."""
        frame = self.frame_for(t_s, flux_w_m2, pad_temp_c, force_n, **slave)
        self._last = frame
        self.seq = (self.seq + 1) & 0xFFFF
        if self.dropout and self.rng.random() < self.dropout:
            self.counters["dropped"] += 1
            return False
        data = bytearray(encode(frame))
        if self.bit_flips and self.rng.random() < self.bit_flips:
            i = int(self.rng.integers(0, len(data) - 1))         # not the delimiter
            data[i] ^= 1 << int(self.rng.integers(0, 8))
            self.counters["flipped"] += 1
        self.counters["frames"] += 1
        return self._write(bytes(data))


#: Frames a Peltier emulator handles per poll; the rest wait for the next.
MAX_FRAMES_PER_POLL = 64


class PeltierEmulator:
    """A Peltier driver board on ``bus`` (protocol ``version``, default
    :data:`~telethermal.devices.peltier.CAN_VERSION`).

    ``on_current(current_a)`` is called with the current the board drives
    (the command clamped to ``current_limit_a``; 0 A when disabled, faulted
    or its watchdog has tripped). ``state()`` gives the simulated module's
    ``(junction_c, heatsink_c, current_a)``; the status frames report it
    with the board's quantisation (0.01 C, 1 mA). Without ``state``, an
    element that is not simulated: the junction at neutral, the heat sink at
    ``heatsink_c``, the current as driven.

    Safe state: 0 A, not a hold current toward neutral. With no current the
    module is passive (it conducts between sink and pad, no Joule heat), and
    it needs nothing the board may have lost: a faulted board cannot trust
    its own sensors to regulate a hold, and the junction loop lives on the
    master, which commands a hold current itself while it trusts the board.

    Protections (latched; cleared by :meth:`clear_faults`, or by a command
    with enable 0 once the measured cause has gone, as the firmware does):
    ``over_current`` when the measured |current| exceeds ``over_current_a``
    (default 10 % above the limit the bridge regulates to: past it the bridge
    or the module has failed, the command cannot do it), ``over_temp`` when
    the hot side (heat sink) exceeds ``max_heatsink_c``, ``sensor_fault``
    when a reading is not finite. ``sink_saturated`` is a warning, not a
    fault: the sink is above ``sink_saturated_c``, the board keeps driving.
    """

    CMD, STATUS, HEARTBEAT = CMD, STATUS, HEARTBEAT
    #: Protections the board checks on its measurements.
    PROTECTIONS = ("over_temp", "over_current", "sensor_fault")

    def __init__(self, bus: str, on_current, clock=time.monotonic, state=None,
                 watchdog_s: float = 0.1, heartbeat_s: float = 0.1,
                 current_limit_a: float = DEFAULT_CURRENT_LIMIT_A,
                 over_current_a: float | None = None, max_heatsink_c: float = 70.0,
                 sink_saturated_c: float = 60.0, heatsink_c: float = 25.0,
                 version: int = CAN_VERSION):
        self.bus = open_bus(bus)
        self.on_current = on_current
        self.state_fn = state
        self.clock = clock
        self.watchdog_s, self.heartbeat_s = watchdog_s, heartbeat_s
        self.current_limit_a = float(current_limit_a)
        self.over_current_a = 1.1 * self.current_limit_a if over_current_a is None \
            else float(over_current_a)
        self.max_heatsink_c, self.sink_saturated_c = max_heatsink_c, sink_saturated_c
        self.heatsink_c = heatsink_c
        self.version = version
        self.neutral_c = SafetyLimits().neutral_c
        self.enabled = False
        self.current_a = 0.0                    # what the board drives
        self.faults: set[str] = set()
        self._forced: set[str] = set()          # faults injected by a test (over_temperature)
        self.state = STATE_BOOT
        self._last_cmd_s: float | None = None
        self._next_heartbeat = -math.inf
        self._counter = 0
        self.counters = dict.fromkeys(("commands", "bad_commands", "watchdog_trips",
                                       "protection_trips"), 0)
        self.offline_until_s = -math.inf       # a reboot: silent meanwhile

    def _send(self, message, data) -> None:
        self.bus.send(can.Message(arbitration_id=message.frame_id, data=data,
                                  is_extended_id=False))

    def error_frame(self) -> None:
        self.bus.send(can.Message(arbitration_id=0, is_error_frame=True, data=b"\x00" * 8,
                                  is_extended_id=False))

    # ------------------------------------------------------------ the module
    def measured(self) -> tuple[float, float, float]:
        """(junction_c, heatsink_c, current_a) as the board measures them."""
        if self.state_fn is None:
            return self.neutral_c, self.heatsink_c, self.current_a
        junction_c, heatsink_c, current_a = self.state_fn()
        return float(junction_c), float(heatsink_c), float(current_a)

    def _protection_faults(self) -> set[str]:
        junction_c, heatsink_c, current_a = self.measured()
        tripped = set(self._forced)
        if not all(math.isfinite(v) for v in (junction_c, heatsink_c, current_a)):
            tripped.add("sensor_fault")
        if heatsink_c > self.max_heatsink_c:
            tripped.add("over_temp")
        if abs(current_a) > self.over_current_a:
            tripped.add("over_current")
        return tripped

    def _protect(self) -> None:
        """Trip on what the board measures: the current to 0 A, flagged."""
        tripped = self._protection_faults() - self.faults
        if tripped:
            self.counters["protection_trips"] += 1
            self.faults |= tripped
            self._disable()
            self._status()

    def over_temperature(self) -> None:
        """The hot side's protection trips (as if the sink read hot):
        disabled, 0 A, flagged until :meth:`clear_faults`."""
        self.trip("over_temp")

    def trip(self, fault: str) -> None:
        """Inject one of :attr:`PROTECTIONS`, latched until :meth:`clear_faults`;
        reported at once in a status frame, as the firmware does."""
        if fault not in self.PROTECTIONS:
            raise ValueError(f"fault must be one of {', '.join(self.PROTECTIONS)}, got {fault!r}")
        self._forced.add(fault)
        self.faults.add(fault)
        self._disable()
        self._status()

    def clear_faults(self) -> None:
        self._forced.clear()
        self.faults.clear()

    def reboot(self, offline_s: float = 0.2) -> None:
        self.offline_until_s = self.clock() + offline_s
        self._disable()
        self.state = STATE_BOOT
        self.clear_faults()

    def _disable(self) -> None:
        self.enabled = False
        self._drive(0.0)

    def _drive(self, current_a: float) -> None:
        self.current_a = current_a
        self.on_current(current_a)

    # ------------------------------------------------------------ frames
    def _status(self) -> None:
        data = self.STATUS.encode(self._status_signals(), strict=False)
        self._counter = (self._counter + 1) & 0xFF
        self._send(self.STATUS, data)

    @staticmethod
    def _frame_c(value: float) -> float:
        """A temperature within what the frame carries (a NaN as -50 C: the
        sensor_fault flag says it is not a reading)."""
        return min(max(value, -50.0), 150.0) if math.isfinite(value) else -50.0

    def _status_signals(self) -> dict:
        junction_c, heatsink_c, current_a = self.measured()
        current_a = min(max(current_a, -FRAME_CURRENT_A), FRAME_CURRENT_A) \
            if math.isfinite(current_a) else 0.0
        return {
            "enabled": int(self.enabled), "over_temp": int("over_temp" in self.faults),
            "over_current": int("over_current" in self.faults),
            "sensor_fault": int("sensor_fault" in self.faults),
            "watchdog": int("watchdog" in self.faults),
            "sink_saturated": int(math.isfinite(heatsink_c) and
                                  heatsink_c > self.sink_saturated_c),
            "counter": self._counter, "junction_c": self._frame_c(junction_c),
            "current_a": current_a, "heatsink_c": self._frame_c(heatsink_c)}

    def _command(self, cmd: dict) -> None:
        """An accepted command (right version): drive or disable."""
        if not cmd["enable"]:
            # The master acknowledges: protections whose cause has gone clear.
            self.faults &= {"watchdog"} | self._protection_faults()
        if cmd["enable"] and not self.faults:
            self.enabled = True
            limit = self.current_limit_a
            self._drive(min(max(float(cmd["current_a"]), -limit), limit))
        elif self.enabled or not cmd["enable"]:
            self._disable()

    def poll(self) -> None:
        """Handle the commands that arrived; protections, heartbeat and watchdog."""
        now = self.clock()
        if now < self.offline_until_s:
            while self.bus.recv(0.0) is not None:        # rebooting: deaf
                pass
            return
        if self.state == STATE_BOOT and now >= self.offline_until_s:
            self.state = STATE_DISABLED
            self._send(self.HEARTBEAT, self.HEARTBEAT.encode({"state": STATE_BOOT,
                                                              "version": self.version}))
        self._protect()
        for _ in range(MAX_FRAMES_PER_POLL):      # a flood cannot starve the heartbeat
            msg = self.bus.recv(0.0)
            if msg is None:
                break
            if msg.is_error_frame or msg.arbitration_id != self.CMD.frame_id:
                continue
            try:
                cmd = self.CMD.decode(bytes(msg.data))
            except Exception:              # noqa: BLE001 - a real driver ignores it too
                self.counters["bad_commands"] += 1
                continue
            self.counters["commands"] += 1
            self._last_cmd_s = now
            self.faults.discard("watchdog")
            if cmd["version"] != self.version:
                self.counters["bad_commands"] += 1     # another protocol: not answered
                continue
            self._command(cmd)
            self._protect()
            self._status()
        if self.enabled and self._last_cmd_s is not None and \
                now - self._last_cmd_s > self.watchdog_s:
            self.counters["watchdog_trips"] += 1
            self.faults.add("watchdog")
            self._disable()
            self._status()
        if now >= self._next_heartbeat:
            self._next_heartbeat = now + self.heartbeat_s
            state = STATE_FAULT if self.faults else \
                STATE_OPERATIONAL if self.enabled else STATE_DISABLED
            self.state = state
            self._send(self.HEARTBEAT, self.HEARTBEAT.encode({"state": state,
                                                              "version": self.version}))

    def close(self) -> None:
        self.bus.shutdown()
