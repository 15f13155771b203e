"""The slave's sensing pad on its devices: the sensor board (frame version 2:
heat flux, the pad's thermocouple, force, the IR thermometer) over a serial
line and the active pad's driver on CAN (``PAD_*`` frames).

:class:`SlavePadDrivers` is what the slave runs against, real or emulated:

* :meth:`~SlavePadDrivers.object_reading_c`: the IR thermometer's reading of
  the object, as the board reports it (NaN when the board flags it or it is
  outside what the sensor can report; the slave then identifies nothing);
* :meth:`~SlavePadDrivers.precondition`: the pad to a temperature, as a
  closed loop (a PI on the pad's thermocouple read on the board, its junction
  demand sent on CAN as the module current that holds it) until the reading
  has settled;
* :meth:`~SlavePadDrivers.contact`: during a contact, every sample the board
  sends, in order, on the sample grid: a frame lost on the line is filled
  with the previous sample (``held_samples``), a channel the board flagged
  likewise (``stale_readings``), each marked not measured
  (``ContactSamples.measured``: the identifier's pad-model check leaves it
  out of its residual); the board going silent for ``lost_after_s``
  (unplugged, crashed) ends the contact (``boards_lost``);
* :meth:`~SlavePadDrivers.safe`: the pad's safe state (disabled, 0 A).

The simulator behind emulated devices is
:class:`~telethermal.devices.slave_pad.EmulatedSlavePad`.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from telethermal.devices.kinds import DeviceKind
from telethermal.devices.active_pad import ActivePadDriver, junction_current_a
from telethermal.devices.board import Calibration, DeviceError, SensorBoard
from telethermal.devices.frames import FRAME_VERSION_SLAVE

log = logging.getLogger(__name__)


@dataclass
class LoopGains:
    """The pre-conditioning loop: junction set point = target + kp e + ki
    integral(e), e = target - the pad's thermocouple reading, integrating
    only within ``band_k`` of the target (no wind-up on the way); settled
    when the readings of the last ``settle_s`` average within ``tol_k`` of
    the target and its two halves within ``tol_k / 2`` of each other (after
    at least ``min_s``); refused after ``timeout_s``."""

    kp: float = 1.0
    ki_per_s: float = 2.0
    band_k: float = 0.3
    settle_s: float = 0.5
    tol_k: float = 0.02
    min_s: float = 1.0
    timeout_s: float = 30.0


@dataclass
class ContactSamples:
    """The samples of one contact as the board delivered them, on the
    sample grid (index = sequence number since the contact's first frame)."""

    n: int
    flux_w_m2: np.ndarray = field(init=False)
    temp_c: np.ndarray = field(init=False)
    force_n: np.ndarray = field(init=False)
    received_s: np.ndarray = field(init=False)     # perf_counter when the driver decoded it
    #: True where the board sent the sample's values; False where the driver
    #: filled them in (a frame lost on the line, a flagged reading: held).
    measured: np.ndarray = field(init=False)
    available: int = 0                              # samples 0..available-1 are in

    def __post_init__(self):
        for name in ("flux_w_m2", "temp_c", "force_n", "received_s"):
            setattr(self, name, np.full(self.n, np.nan))
        self.measured = np.zeros(self.n, dtype=bool)


class SlavePadDrivers:
    """The slave's board and active pad driver (``board_url``: a pyserial
    URL; ``can_bus``: ``interface:channel``)."""

    kind = DeviceKind.HARDWARE

    def __init__(self, board_url: str, can_bus: str, rate_hz: float,
                 calibration: Calibration = Calibration(), clock=time.monotonic,
                 wait_s: float = 0.0, gains: LoopGains = LoopGains(),
                 lost_after_s: float = 0.1, no_reading_s: float = 0.5):
        self.rate_hz = float(rate_hz)
        self.clock, self.wait_s, self.gains = clock, wait_s, gains
        self.lost_after_s, self.no_reading_s = lost_after_s, no_reading_s
        self.board = SensorBoard(board_url, calibration, clock=clock, keep=True,
                                 versions=(FRAME_VERSION_SLAVE,),
                                 stale_s=max(0.05, 3.0 / self.rate_hz))
        try:
            self.pad = ActivePadDriver(can_bus, clock=clock)
        except Exception:
            self.board.close()
            raise
        self.counters = dict.fromkeys(("contacts", "held_samples", "stale_readings",
                                       "boards_lost", "ir_refused", "preconditions",
                                       "precondition_failed", "safe_commands"), 0)
        self.last_precondition: dict = {}
        #: Called once a period while a loop here holds the caller's thread
        #: (the pre-conditioning: a second or more): a service keeps its
        #: transport's heartbeats going there. It must not use these devices.
        self.on_wait: Callable[[], None] | None = None
        self._loop: dict | None = None          # the pad loop's target, integral, set point
        self._samples: ContactSamples | None = None
        self._seq0: int | None = None
        self._begun = False                     # begin_contact called for this contact

    # ------------------------------------------------------------ one period
    def tick(self):
        """One period: the newest reading, or None. Waits up to ``wait_s`` for
        a new frame, so that on a board streaming on its own a loop runs at
        the board's rate."""
        self.pad.poll()
        self.board.poll(self.wait_s)
        self.board.take_readings()
        r = self.board.latest
        if r is None or self.clock() - r.received_s > self.board.stale_s:
            return None
        return r

    def hold(self):
        """One period of the pad's loop at its last target (or the safe
        state's neutral before any): the newest reading."""
        r = self.tick()
        reading = r.pad_temp_c if r is not None else math.nan
        if self._loop is not None and math.isfinite(reading):
            self._loop_step(reading)
        setpoint = self._loop["setpoint"] if self._loop is not None else self._neutral_c()
        self._command_junction(setpoint)
        self._after_command()
        return r

    def _loop_step(self, reading: float) -> float:
        """PI on the pad's reading: the junction's next set point."""
        loop, g = self._loop, self.gains
        e = loop["target"] - reading
        if abs(e) < g.band_k:
            loop["integral"] += e / self.rate_hz
        loop["setpoint"] = loop["target"] + g.kp * e + g.ki_per_s * loop["integral"]
        return loop["setpoint"]

    # ------------------------------------------------------------ before contact
    def object_reading_c(self) -> float:
        """The IR thermometer's reading of the object (uncorrected), NaN if
        the board flags it or it is out of range; :class:`DeviceError` if
        the board sends nothing."""
        since = self.clock()
        r = self.tick()
        # A sample frame (a boot frame carries no reading), within no_reading_s.
        while (r is None or not math.isfinite(r.pad_temp_c)) and \
                self.clock() - since <= self.no_reading_s:
            r = self.tick()
        if r is None or not math.isfinite(r.pad_temp_c):
            raise DeviceError(f"the slave's sensor board {self.board.url} gives no frame "
                              f"(counters {self.board.all_counters}): no object measurement")
        value = r.ir_object_c
        if not math.isfinite(value):
            self.counters["ir_refused"] += 1
        return value

    def precondition(self, target_c: float) -> dict:
        """Hold the pad's thermocouple reading at ``target_c`` (closed loop);
        returns what the loop did. Raises :class:`DeviceError` if the pad
        does not settle within the timeout (the pad is then made safe)."""
        g, dt = self.gains, 1.0 / self.rate_hz
        self.counters["preconditions"] += 1
        window = []
        n_settle, n_min = max(1, round(g.settle_s / dt)), round(g.min_s / dt)
        self._loop = {"target": target_c, "integral": 0.0, "setpoint": target_c}
        missing_since = None
        for k in range(int(g.timeout_s / dt) + 1):
            r = self.tick()
            reading = r.pad_temp_c if r is not None else math.nan
            if math.isfinite(reading):
                missing_since = None
            elif missing_since is None:
                missing_since = self.clock()
            elif self.clock() - missing_since > self.no_reading_s:
                self.counters["precondition_failed"] += 1
                self.safe()
                raise DeviceError(f"active pad pre-conditioning: no pad temperature from the "
                                  f"sensor board {self.board.url} for "
                                  f"{self.clock() - missing_since:.2f} s (counters "
                                  f"{self.board.all_counters}): pad made safe")
            if math.isfinite(reading):
                self._loop_step(reading)
                window = (window + [reading])[-n_settle:]
            setpoint = self._loop["setpoint"]
            self._command_junction(setpoint)
            self._after_command()
            if self.on_wait is not None:
                self.on_wait()
            half = n_settle // 2
            if k >= n_min and len(window) == n_settle and \
                    abs(float(np.mean(window)) - target_c) <= g.tol_k and \
                    abs(float(np.mean(window[:half]) - np.mean(window[half:]))) <= g.tol_k / 2:
                self.last_precondition = {"target_c": target_c, "settled_s": (k + 1) * dt,
                                          "reading_c": float(np.mean(window)),
                                          "setpoint_c": setpoint}
                return self.last_precondition
        self.counters["precondition_failed"] += 1
        self.safe()
        raise DeviceError(f"active pad did not settle at {target_c:.2f} C within "
                          f"{g.timeout_s:g} s (last reading {window[-1] if window else 'none'}); "
                          f"board {self.board.url}, pad driver on {self.pad.spec}: pad made safe")

    def _command_junction(self, junction_c: float) -> None:
        """The loop asks for a junction temperature; the pad's module is driven
        by current (``PAD_CMD`` version 2): the module's small-signal steady
        state at the heat sink the driver last reported (before any report,
        the demand itself, 0 A). The loop's integral on the pad's reading
        takes up what the map leaves out (Joule heat, the pad's load)."""
        s = self.pad.status
        sink_c = s.heatsink_c if s is not None and math.isfinite(s.heatsink_c) else junction_c
        self.pad.command(junction_current_a(junction_c, sink_c))

    def _after_command(self) -> None:
        """Hook: an emulated pad applies the command here."""

    def safe(self) -> None:
        self.counters["safe_commands"] += 1
        self._loop = None
        self.pad.safe()
        self._after_command()

    # ------------------------------------------------------------ contact
    def contact(self, n: int) -> ContactSamples:
        """Start collecting a contact of (at most) ``n`` samples: the next
        frame is sample 0."""
        self.counters["contacts"] += 1
        self.board.poll()
        self.board.take_readings()
        self._samples = ContactSamples(n)
        latest = self.board.latest
        self._seq0 = None if latest is None else (latest.seq + 1) & 0xFFFF
        self._begun = False
        return self._samples

    def begin_contact(self) -> None:
        """The pad goes down now: the next frame is sample 0 of the contact
        started by :meth:`contact` (what came before is dropped)."""
        self.board.poll()
        self.board.take_readings()
        latest = self.board.latest
        self._seq0 = None if latest is None else (latest.seq + 1) & 0xFFFF
        s = self._samples
        s.available = 0
        for a in (s.flux_w_m2, s.temp_c, s.force_n, s.received_s):
            a[:] = np.nan
        s.measured[:] = False
        self._begun = True

    def feed(self, upto_t_s: float) -> bool:
        """A board that streams on its own clock: read the samples due by
        ``upto_t_s`` since :meth:`begin_contact` (called at the first feed);
        False once the board is lost."""
        if not self._begun:
            self.begin_contact()
        expected = min(self._samples.n, int(math.floor(upto_t_s * self.rate_hz + 1e-9)) + 1)
        return self.collect(max(expected, 0))

    def collect(self, expected: int) -> bool:
        """Read what the board sent since, waiting up to ``wait_s`` for
        ``expected`` samples in all; False once the board is lost (the port
        went away, or more than ``lost_after_s`` of expected samples are
        missing)."""
        s = self._samples
        until_index = expected - 1 if expected > s.available else None
        end = time.monotonic() + self.wait_s
        while True:
            lost_before = self.board.counters["port_lost"]
            self.board.poll(0.0 if until_index is None else max(0.0, end - time.monotonic()))
            for r in self.board.take_readings():
                self._store(r)
            if self.board.counters["port_lost"] > lost_before:
                return self._lost("the port went away")
            if until_index is None or s.available > until_index or time.monotonic() >= end:
                break
        missing = expected - s.available
        if missing > self.lost_after_s * self.rate_hz:
            return self._lost(f"{missing} samples due have not come")
        # During the contact the junction stays where the loop left it (the
        # pad's thermocouple now reads the contact, not the set point).
        self._command_junction(self._loop["setpoint"] if self._loop is not None
                               else self._neutral_c())
        self._after_command()
        return True

    @staticmethod
    def _neutral_c() -> float:
        from telethermal.control.safety import SafetyLimits
        return SafetyLimits().neutral_c

    def _store(self, r) -> None:
        s = self._samples
        if self._seq0 is None:
            self._seq0 = r.seq
        i = (r.seq - self._seq0) & 0xFFFF
        if i >= s.n or i < s.available:
            return                                  # beyond the contact, or a repeat
        values = (r.flux_w_m2, r.pad_temp_c, r.force_n)
        measured = all(math.isfinite(v) for v in values)
        if not measured:
            self.counters["stale_readings"] += 1
            if s.available == 0:
                return                              # nothing to hold yet
            values = (s.flux_w_m2[s.available - 1], s.temp_c[s.available - 1],
                      s.force_n[s.available - 1])
        for j in range(s.available, i):             # frames lost on the line: hold
            self.counters["held_samples"] += 1
            if s.available == 0:
                s.flux_w_m2[j], s.temp_c[j], s.force_n[j] = values
            else:
                s.flux_w_m2[j], s.temp_c[j], s.force_n[j] = (
                    s.flux_w_m2[j - 1], s.temp_c[j - 1], s.force_n[j - 1])
            s.received_s[j] = math.nan            # never received
        s.flux_w_m2[i], s.temp_c[i], s.force_n[i] = values
        s.received_s[i] = time.perf_counter()
        s.measured[i] = measured
        s.available = i + 1

    def _lost(self, why: str) -> bool:
        self.counters["boards_lost"] += 1
        log.warning("slave's sensor board %s lost mid-contact (%s): pad to its safe state",
                    self.board.url, why)
        self.safe()
        return False

    # ------------------------------------------------------------ the rest
    def all_counters(self) -> dict:
        return {"board": self.board.all_counters, "pad": dict(self.pad.counters),
                **self.counters}

    def close(self) -> None:
        try:
            self.pad.close()
        finally:
            self.board.close()
