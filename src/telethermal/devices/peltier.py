"""The display pad's Peltier driver on a CAN bus (python-can; frames in
``peltier.dbc``, read with cantools, documented in ``proto/CAN.md``).

Protocol version 2: the module is driven by CURRENT. :class:`PeltierDriver`
is the master's side: every period it sends the module current (A, signed,
positive cools the pad side; 1 mA steps) and enable (``PELTIER_CMD``), and
reads the driver's status (junction and heat-sink temperatures, the measured
current, fault flags, the ``sink_saturated`` warning) and its heartbeat. It
never raises on what the bus brings: error frames, undecodable frames, a
driver that reboots, reports a fault or speaks another protocol version are
counted and logged; a send that fails (bus-off, a controller in error)
counts, shuts the bus and reopens it after ``reopen_s``.
:attr:`PeltierDriver.healthy` says whether the actuator can be trusted this
period (heartbeat alive and of this version, enabled, no fault flag); the
display treats "not healthy" as a missing reading, so the safety supervisor
holds the safe state.

Versions: both sides put the version in the same place (``PELTIER_CMD``
byte 3, ``PELTIER_HEARTBEAT`` byte 1). A driver ignores, counts and does not
answer a command of another version (a version-1 board, which reads bytes
1-2 as a junction set point, never sees a current as a set point); this
driver reads the board's version from its heartbeat and, if it is not
:data:`CAN_VERSION`, logs an error naming both, ignores that board's status
frames and is never healthy (:attr:`PeltierDriver.version_error`).

The bus is given by interface and channel: ``socketcan:can0`` in a lab,
``virtual:<name>`` (one process) or ``udp_multicast:<group>`` here.
"""

from __future__ import annotations

import logging
import math
import os
import time
from dataclasses import dataclass
from importlib import resources

import can
import cantools
import serial

from telethermal.devices.board import DeviceError
from telethermal.physics.thermoelectric import DEFAULT_MODULE, get_module

log = logging.getLogger(__name__)

#: Version 2: PELTIER_CMD and PAD_CMD carry the module current (version 1: a
#: junction set point, in the same bytes).
CAN_VERSION = 2
STATE_BOOT, STATE_OPERATIONAL, STATE_DISABLED, STATE_FAULT = 0, 5, 127, 128
#: Flags that make the driver untrustworthy (it has cut the current itself).
FAULTS = ("over_temp", "over_current", "sensor_fault", "watchdog")
#: Flags the driver reports while it keeps driving.
WARNINGS = ("sink_saturated",)
#: The display module's datasheet Imax (TM-31-1.4-8.5: 8.5 A): the driver's
#: default current limit.
DEFAULT_CURRENT_LIMIT_A = get_module(DEFAULT_MODULE).imax_a
#: What the frames can carry: int16 in mA.
FRAME_CURRENT_A = 32.767


def clamp_current_a(current_a: float, limit_a: float) -> float:
    """``current_a`` within +-``limit_a`` (and what the frame can carry);
    :class:`DeviceError` naming the value if it is NaN or infinite."""
    if not math.isfinite(current_a):
        raise DeviceError(f"Peltier current must be finite, got current_a={current_a!r}: "
                          "nothing sent (the caller's safe state takes over)")
    limit = min(abs(limit_a), FRAME_CURRENT_A)
    return min(max(float(current_a), -limit), limit)


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
    options = {}
    if interface == "slcan" and os.path.realpath(channel.split("@")[0]).startswith("/dev/pts/"):
        # python-can waits 2 s after opening for an adapter that resets when
        # its port opens (an Arduino's DTR); a pseudo-terminal (an emulated
        # core's UART) is none.
        options["sleep_after_open"] = 0.0
    try:
        return can.Bus(interface=interface, channel=channel, receive_own_messages=False,
                       **options)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        raise DeviceError(f"CAN bus {spec!r}: {exc}") from exc


#: How long a command may wait to leave a serial (SLCAN) adapter, whose
#: python-can send otherwise waits for ever (pyserial's write timeout): an
#: adapter that takes nothing for that long fails the send (counted, the bus
#: reopened) instead of holding the display's loop for good; half the
#: driver's own watchdog (proto/CAN.md: 100 ms) at real time (a rig slowed
#: by its time_scale only gives the write more room). Other interfaces keep
#: python-can's default, which fails at once on a full queue (socketcan).
SLCAN_SEND_TIMEOUT_S = 0.05


@dataclass(frozen=True, slots=True)
class DriverStatus:
    enabled: bool
    junction_c: float
    current_a: float
    heatsink_c: float
    faults: tuple[str, ...]
    received_s: float
    warnings: tuple[str, ...] = ()


class PeltierDriver:
    CMD, STATUS, HEARTBEAT = CMD, STATUS, HEARTBEAT
    FAULTS, WARNINGS = FAULTS, WARNINGS
    what = "Peltier driver"

    def __init__(self, bus: str, heartbeat_timeout_s: float = 0.5, reopen_s: float = 0.2,
                 clock=time.monotonic, current_limit_a: float = DEFAULT_CURRENT_LIMIT_A):
        if not (current_limit_a > 0 and math.isfinite(current_limit_a)):
            raise DeviceError(f"{self.what}: current_limit_a must be > 0 A, got "
                              f"{current_limit_a!r}")
        self.current_limit_a = float(current_limit_a)
        self.commanded_a = 0.0           # the last current sent, after the limit
        self.peer_version: int | None = None
        self.version_error: str | None = None
        self.spec = bus
        self.bus = open_bus(bus)
        self._send_timeout_s = SLCAN_SEND_TIMEOUT_S if parse_bus(bus)[0] == "slcan" else None
        self.clock = clock
        self.heartbeat_timeout_s, self.reopen_s = heartbeat_timeout_s, reopen_s
        self.status: DriverStatus | None = None
        self.state: int | None = None
        self.last_heartbeat_s: float | None = None
        self._counter = 0
        self._next_open = 0.0
        self.counters = dict.fromkeys(("sent", "send_failed", "bus_off", "reopened",
                                       "error_frames", "undecodable", "statuses", "heartbeats",
                                       "reboots", "faults_reported", "version_mismatch"), 0)
        self._faults_seen: tuple[str, ...] = ()

    # ------------------------------------------------------------ sending
    def command(self, current_a: float, enable: bool = True) -> bool:
        """Send the module current (A, positive cools the pad side), clamped
        to ``current_limit_a`` (:attr:`commanded_a` holds what was sent);
        False if it could not be sent this period. :class:`DeviceError` for
        a NaN or infinite current (nothing is sent)."""
        applied = clamp_current_a(current_a, self.current_limit_a)
        self.commanded_a = applied
        return self._send_command({"enable": int(enable), "counter": self._counter,
                                   "current_a": applied, "version": CAN_VERSION})

    def _send_command(self, signals: dict) -> bool:
        if self.bus is None and not self._reopen():
            return False
        data = self.CMD.encode(signals, strict=False)
        self._counter = (self._counter + 1) & 0xF
        try:
            self.bus.send(can.Message(arbitration_id=self.CMD.frame_id, data=data,
                                      is_extended_id=False), timeout=self._send_timeout_s)
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
        timed_out = isinstance(exc.__cause__, serial.SerialTimeoutException)   # not bus-off
        if not timed_out and ("bus-off" in text or "bus off" in text or
                              isinstance(exc, can.CanOperationError)):
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
            except ValueError as exc:      # a line the interface could not parse (slcan)
                self.counters["undecodable"] += 1
                log.warning("CAN %s: unreadable frame (%s)", self.spec, exc)
                timeout = 0.0
                continue
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
                if self.peer_version not in (None, CAN_VERSION):
                    self.counters["version_mismatch"] += 1     # not read as ours
                    return
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
                self._peer_version(int(h["version"]))
        except (cantools.database.DecodeError, ValueError, KeyError) as exc:
            self.counters["undecodable"] += 1
            log.warning("CAN %s: undecodable frame id %#x (%s)", self.spec, msg.arbitration_id,
                        exc)

    def _peer_version(self, version: int) -> None:
        if version == CAN_VERSION:
            self.peer_version, self.version_error = version, None
            return
        self.counters["version_mismatch"] += 1
        if version != self.peer_version:
            self.version_error = (
                f"{self.what} on {self.spec} speaks CAN protocol version {version}, this "
                f"master version {CAN_VERSION} (module current in PELTIER_CMD/PAD_CMD; "
                "version 1 carried a junction set point): it refuses our commands and we "
                "ignore its status; update its firmware")
            log.error("%s", self.version_error)
        self.peer_version = version
        self.status = None

    def _status_of(self, s: dict, faults: tuple[str, ...]) -> DriverStatus:
        return DriverStatus(bool(s["enabled"]), float(s["junction_c"]), float(s["current_a"]),
                            float(s["heatsink_c"]), faults, self.clock(),
                            tuple(w for w in self.WARNINGS if s[w]))

    def readings(self) -> tuple[float, float, float]:
        """(junction_c, heatsink_c, current_a) of the last status, NaN when
        the driver is not healthy (no status, stale, faulted, another
        version): what the master's junction loop reads."""
        s = self.status
        if s is None or not self.healthy:
            return math.nan, math.nan, math.nan
        return s.junction_c, s.heatsink_c, s.current_a

    @property
    def alive(self) -> bool:
        return self.last_heartbeat_s is not None and \
            self.clock() - self.last_heartbeat_s <= self.heartbeat_timeout_s

    @property
    def healthy(self) -> bool:
        """The actuator can be trusted: heartbeat alive, a status within the
        heartbeat timeout, enabled, no fault flag."""
        s = self.status
        return self.bus is not None and self.alive and self.peer_version == CAN_VERSION and \
            s is not None and s.enabled and not s.faults and \
            self.clock() - s.received_s <= self.heartbeat_timeout_s

    def close(self) -> None:
        """Disable the driver, 0 A (its own watchdog would, once commands
        stop), then release the bus."""
        if self.bus is not None:
            self.command(0.0, enable=False)
        if self.bus is not None:
            self.bus.shutdown()
            self.bus = None
