"""The display pad's Peltier driver on a CAN bus (python-can; frames in
``peltier.dbc``, read with cantools, documented in ``proto/CAN.md``).

:class:`PeltierDriver` is the master's side: it sends the junction setpoint
every period (``PELTIER_CMD``), and reads the driver's status (applied
junction temperature, current, fault flags) and its heartbeat. It never
raises on what the bus brings: error frames, undecodable frames, a driver
that reboots or reports over-temperature are counted and logged; a send
that fails (bus-off, a controller in error) counts, shuts the bus and
reopens it after ``reopen_s``. :attr:`PeltierDriver.healthy` says whether
the actuator can be trusted this period (heartbeat alive, enabled, no
fault flag); the display treats "not healthy" as a missing reading, so the
safety supervisor holds the safe state.

The bus is given by interface and channel: ``socketcan:can0`` in a lab,
``virtual:<name>`` (one process) or ``udp_multicast:<group>`` here.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from importlib import resources

import can
import cantools

from telethermal.control.safety import SafetyLimits
from telethermal.devices.board import DeviceError

log = logging.getLogger(__name__)

CAN_VERSION = 1
STATE_BOOT, STATE_OPERATIONAL, STATE_DISABLED, STATE_FAULT = 0, 5, 127, 128
FAULTS = ("over_temp", "over_current", "sensor_fault", "watchdog")


def database() -> cantools.database.Database:
    with resources.as_file(resources.files("telethermal.devices") / "peltier.dbc") as path:
        return cantools.database.load_file(str(path))


DB = database()
CMD, STATUS, HEARTBEAT = (DB.get_message_by_name(n) for n in
                          ("PELTIER_CMD", "PELTIER_STATUS", "PELTIER_HEARTBEAT"))


def parse_bus(spec: str) -> tuple[str, str]:
    """``"interface:channel"`` -> (interface, channel), with a clear error."""
    interface, sep, channel = spec.partition(":")
    if not sep or not interface or not channel:
        raise DeviceError(f"CAN bus {spec!r}: use interface:channel, e.g. socketcan:can0, "
                          "virtual:display or udp_multicast:239.74.163.2")
    return interface, channel


def open_bus(spec: str) -> can.BusABC:
    interface, channel = parse_bus(spec)
    try:
        return can.Bus(interface=interface, channel=channel, receive_own_messages=False)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        raise DeviceError(f"CAN bus {spec!r}: {exc}") from exc


@dataclass(frozen=True, slots=True)
class DriverStatus:
    enabled: bool
    junction_c: float
    current_a: float
    heatsink_c: float
    faults: tuple[str, ...]
    received_s: float


class PeltierDriver:
    CMD, STATUS, HEARTBEAT = CMD, STATUS, HEARTBEAT
    FAULTS = FAULTS
    what = "Peltier driver"

    def __init__(self, bus: str, heartbeat_timeout_s: float = 0.5, reopen_s: float = 0.2,
                 clock=time.monotonic):
        self.spec = bus
        self.bus = open_bus(bus)
        self.clock = clock
        self.heartbeat_timeout_s, self.reopen_s = heartbeat_timeout_s, reopen_s
        self.status: DriverStatus | None = None
        self.state: int | None = None
        self.last_heartbeat_s: float | None = None
        self._counter = 0
        self._next_open = 0.0
        self.counters = dict.fromkeys(("sent", "send_failed", "bus_off", "reopened",
                                       "error_frames", "undecodable", "statuses", "heartbeats",
                                       "reboots", "faults_reported"), 0)
        self._faults_seen: tuple[str, ...] = ()

    # ------------------------------------------------------------ sending
    def command(self, junction_c: float, enable: bool = True) -> bool:
        """Send the setpoint; False if it could not be sent this period."""
        if not math.isfinite(junction_c):
            raise DeviceError(f"Peltier setpoint must be finite, got {junction_c}")
        return self._send_command({"enable": int(enable), "counter": self._counter,
                                   "setpoint_c": min(max(junction_c, -50.0), 150.0),
                                   "version": CAN_VERSION})       # clamped above

    def _send_command(self, signals: dict) -> bool:
        if self.bus is None and not self._reopen():
            return False
        data = self.CMD.encode(signals, strict=False)
        self._counter = (self._counter + 1) & 0xF
        try:
            self.bus.send(can.Message(arbitration_id=self.CMD.frame_id, data=data,
                                      is_extended_id=False))
        except can.CanError as exc:
            self._bus_failed(exc)
            return False
        self.counters["sent"] += 1
        return True

    def _bus_failed(self, exc: Exception) -> None:
        self.counters["send_failed"] += 1
        # python-can has no bus-off class: CanOperationError is its nearest,
        # and a backend that raises the plain CanError says bus-off only in
        # its text (a third party's message, not one of ours).
        text = str(exc).lower()
        if "bus-off" in text or "bus off" in text or isinstance(exc, can.CanOperationError):
            self.counters["bus_off"] += 1
        log.warning("CAN %s: send failed (%s); reopening the bus in %.2f s", self.spec, exc,
                    self.reopen_s)
        try:
            self.bus.shutdown()
        except Exception:              # noqa: BLE001 - the controller is in error already
            pass
        self.bus = None
        self._next_open = self.clock() + self.reopen_s

    def _reopen(self) -> bool:
        if self.clock() < self._next_open:
            return False
        try:
            self.bus = open_bus(self.spec)
        except DeviceError as exc:
            log.warning("%s", exc)
            self._next_open = self.clock() + self.reopen_s
            return False
        self.counters["reopened"] += 1
        log.warning("CAN %s: bus reopened", self.spec)
        return True

    # ------------------------------------------------------------ receiving
    def poll(self, wait_s: float = 0.0) -> int:
        """Handle every frame that has arrived (waiting up to ``wait_s`` for
        the first); returns how many."""
        if self.bus is None:
            return 0
        n = 0
        timeout = wait_s
        while True:
            try:
                msg = self.bus.recv(timeout)
            except can.CanError as exc:
                self._bus_failed(exc)
                return n
            if msg is None:
                return n
            timeout = 0.0
            n += 1
            self._handle(msg)

    def _handle(self, msg: can.Message) -> None:
        if msg.is_error_frame:
            self.counters["error_frames"] += 1
            log.warning("CAN %s: error frame (id %#x, data %s)", self.spec, msg.arbitration_id,
                        bytes(msg.data).hex())
            return
        try:
            if msg.arbitration_id == self.STATUS.frame_id:
                s = self.STATUS.decode(bytes(msg.data))
                faults = tuple(f for f in self.FAULTS if s[f])
                self.status = self._status_of(s, faults)
                self.counters["statuses"] += 1
                if faults and faults != self._faults_seen:
                    self.counters["faults_reported"] += 1
                    log.warning("%s reports %s: pad to its safe state", self.what,
                                ", ".join(faults))
                self._faults_seen = faults
            elif msg.arbitration_id == self.HEARTBEAT.frame_id:
                h = self.HEARTBEAT.decode(bytes(msg.data), decode_choices=False)
                if h["state"] == STATE_BOOT and self.state not in (None, STATE_BOOT):
                    self.counters["reboots"] += 1
                    log.warning("%s rebooted", self.what)
                self.state = int(h["state"])
                self.last_heartbeat_s = self.clock()
                self.counters["heartbeats"] += 1
        except (cantools.database.DecodeError, ValueError, KeyError) as exc:
            self.counters["undecodable"] += 1
            log.warning("CAN %s: undecodable frame id %#x (%s)", self.spec, msg.arbitration_id,
                        exc)

    def _status_of(self, s: dict, faults: tuple[str, ...]) -> DriverStatus:
        return DriverStatus(bool(s["enabled"]), float(s["junction_c"]), float(s["current_a"]),
                            float(s["heatsink_c"]), faults, self.clock())

    @property
    def alive(self) -> bool:
        return self.last_heartbeat_s is not None and \
            self.clock() - self.last_heartbeat_s <= self.heartbeat_timeout_s

    @property
    def healthy(self) -> bool:
        """The actuator can be trusted: heartbeat alive, a status within the
        heartbeat timeout, enabled, no fault flag."""
        s = self.status
        return self.bus is not None and self.alive and s is not None and s.enabled and \
            not s.faults and self.clock() - s.received_s <= self.heartbeat_timeout_s

    def close(self) -> None:
        """Disable the driver (its own watchdog would, once commands stop),
        then release the bus."""
        if self.bus is not None:
            self.command(SafetyLimits().neutral_c, enable=False)
        if self.bus is not None:
            self.bus.shutdown()
            self.bus = None
