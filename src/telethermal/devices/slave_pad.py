"""The slave's sensing pad on its devices: the sensor board (frame version 2:
heat flux, the pad's thermocouple, force, the IR thermometer) over a serial
line and the active pad's driver on CAN (``PAD_*`` frames).

:class:`SlavePadDrivers` is what the slave runs against, real or emulated:

* :meth:`~SlavePadDrivers.object_reading_c`: the IR thermometer's reading of
  the object, as the board reports it (NaN when the board flags it or it is
  outside what the sensor can report; the slave then identifies nothing);
* :meth:`~SlavePadDrivers.precondition`: the pad to a temperature, as a
  closed loop (a PI on the pad's thermocouple read on the board, commanding
  the Peltier junction's set point on CAN) until the reading has settled;
* :meth:`~SlavePadDrivers.contact`: during a contact, every sample the board
  sends, in order, on the sample grid: a frame lost on the line is filled
  with the previous sample (``held_samples``), a channel the board flagged
  likewise (``stale_readings``); the board going silent for ``lost_after_s``
  (unplugged, crashed) ends the contact (``boards_lost``);
* :meth:`~SlavePadDrivers.safe`: the pad's safe state (disabled).

:class:`EmulatedSlavePad` puts the simulator behind emulated devices (the
board on a pty, the pad's driver on a python-can virtual bus) and steps
them in lockstep with the slave: the pad's temperature is a first-order
plant driven by the junction set point the emulated driver receives, its
thermocouple and the object thermometer are the session's instruments (bias,
noise, resolution), and during a contact the simulator's samples are written
as the board's frames. The identifier sees the bytes a board would send.

A water pad (paper 2, eq. 11-13) is pre-conditioned by the simulator in
this version; its heater and pump have CAN signals but no emulator drives
them yet, so a water-pad scene refuses ``devices = "emulated"``.
"""

from __future__ import annotations

import itertools
import logging
import math
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from telethermal.devices.active_pad import ActivePadDriver, ActivePadEmulator
from telethermal.devices.board import Calibration, DeviceError, SensorBoard
from telethermal.devices.emulators import SensorBoardEmulator
from telethermal.devices.frames import FRAME_VERSION_SLAVE

log = logging.getLogger(__name__)

_bus_names = itertools.count()


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
    available: int = 0                              # samples 0..available-1 are in

    def __post_init__(self):
        for name in ("flux_w_m2", "temp_c", "force_n", "received_s"):
            setattr(self, name, np.full(self.n, np.nan))


class SlavePadDrivers:
    """The slave's board and active pad driver (``board_url``: a pyserial
    URL; ``can_bus``: ``interface:channel``)."""

    kind = "hardware"

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
        self._loop: dict | None = None          # the pad loop's target, integral, set point
        self._samples: ContactSamples | None = None
        self._seq0: int | None = None

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
        self.pad.command(setpoint)
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
            self.pad.command(setpoint)
            self._after_command()
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
        self._begun = True

    def feed(self, upto_t_s: float) -> bool:
        """A board that streams on its own clock: read the samples due by
        ``upto_t_s`` since :meth:`begin_contact` (called at the first feed);
        False once the board is lost."""
        if not getattr(self, "_begun", False):
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
        self.pad.command(self._loop["setpoint"] if self._loop is not None
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
        if not all(math.isfinite(v) for v in values):
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


class EmulatedSlavePad(SlavePadDrivers):
    """:class:`SlavePadDrivers` on emulated devices fed by the simulator.

    ``instruments``: the session's (the pad thermocouple's bias, the object
    thermometer's bias, gain error, noise and resolution); ``rng`` draws the
    per-reading noise of the pad's loop. The thermometer sees the object
    (:meth:`show_object`) or the pad (:meth:`aim_at_pad`, calibration).
    """

    kind = "emulated"

    def __init__(self, scene, instruments, seed: int = 0, wait_s: float = 0.05,
                 pad_tau_s: float = 0.5, board_noise_uv: float = 0.0):
        from telethermal.physics.sensors import Thermocouple

        if scene.pad.kind != "peltier":
            raise DeviceError(f"scene {scene.name}: its pad is a {scene.pad.kind} pad; the "
                              "emulated slave drives a Peltier pad only (the water pad's "
                              "pre-conditioning stays on the simulator: devices = \"sim\")")
        self.scene, self.instruments = scene, instruments
        self.rng = np.random.default_rng((seed, 0x5A1E))
        self.pad_tau_s = pad_tau_s
        self.room_c = scene.room_temp_c
        self.tc = Thermocouple(noise_uv_rms=scene.sensors.thermocouple_noise_uv,
                               cold_junction_c=self.room_c, bias_k=instruments.pad_tc_bias_k)
        self.pad_true_c = self.junction_c = self.room_c
        self.t_s = 0.0
        self._ir_target = "object"
        self.object_raw_c = math.nan
        #: Faults of the IR sensor: None, "flagged" (the board clears its
        #: bit), or a value (degC) it reports whatever it sees.
        self.ir_fault: str | float | None = None
        self._dir = tempfile.TemporaryDirectory(prefix="telethermal-slave-dev-")
        self.board_emulator = SensorBoardEmulator(Path(self._dir.name) / "slave-board",
                                                  cold_junction_c=self.room_c, seed=seed,
                                                  version=FRAME_VERSION_SLAVE)
        self.board_emulator.noise_uv = board_noise_uv
        bus = f"virtual:telethermal-slave-pad-{next(_bus_names)}"
        # The pad's driver board keeps the rig's time (its watchdog counts
        # periods the slave let pass, not the simulator's own computing).
        self.pad_emulator = ActivePadEmulator(bus, self._on_junction, heatsink_c=self.room_c,
                                              clock=lambda: self.t_s)
        try:
            super().__init__(self.board_emulator.path, bus, scene.sample_rate_hz,
                             wait_s=wait_s)
        except Exception:
            self.pad_emulator.close()
            self.board_emulator.close()
            self._dir.cleanup()
            raise
        self.board.reopen_s = 0.05
        self.write_s: np.ndarray | None = None       # when each contact sample left the board
        self._trial = None
        self._sent = 0

    # ------------------------------------------------------------ the simulator side
    def _on_junction(self, junction_c: float) -> None:
        self.junction_c = junction_c

    def _after_command(self) -> None:
        self.pad_emulator.poll()

    def show_object(self, raw_c: float) -> None:
        """The thermometer now sees the object, reading ``raw_c`` (the
        simulator's reading of the object: the session's instrument)."""
        self._ir_target, self.object_raw_c = "object", float(raw_c)

    def aim_at_pad(self, rng: np.random.Generator) -> None:
        """The thermometer now sees the pad (self-calibration): each frame
        carries its reading of the pad's true temperature, noise from ``rng``."""
        self._ir_target, self._ir_rng = "pad", rng

    def _ir_c(self) -> tuple[float, bool]:
        if self.ir_fault == "flagged":
            return 0.0, False
        if isinstance(self.ir_fault, (int, float)):
            return float(self.ir_fault), True
        if self._ir_target == "pad":
            return float(self.instruments.thermometer.read_c(np.array([self.pad_true_c]),
                                                             self._ir_rng)[0]), True
        return self.object_raw_c, True

    def _drive(self) -> float:
        return max(-1.0, min(1.0, 0.05 * (self.junction_c - self.room_c))) \
            if self.pad_emulator.enabled else 0.0

    def tick(self):
        """One period of the simulated pad: it moves toward the junction,
        the board sends its frame, the driver reads it."""
        dt = 1.0 / self.rate_hz
        self.t_s += dt
        self.pad_true_c += -math.expm1(-dt / self.pad_tau_s) * (self.junction_c -
                                                                  self.pad_true_c)
        reading = float(self.tc.read_c(np.array([self.pad_true_c]), self.rng)[0])
        ir, ok = self._ir_c()
        self.board_emulator.send(self.t_s, 0.0, reading, 0.0, ir_object_c=ir,
                                 ir_ambient_c=self.room_c, pad_drive=self._drive(), ir_ok=ok)
        self.pad_emulator.poll()
        if self.board._ser is None:
            # The driver's port is closed (the board is away): in lockstep the
            # period passes on the real clock too, so its reopening runs.
            time.sleep(dt)
        return super().tick()

    def measure_object(self, true_c, rng: np.random.Generator) -> np.ndarray:
        """The simulator's thermometer reads the object (``true_c``), the
        board sends it, the driver reads it: raw readings, NaN if refused."""
        raw = self.instruments.thermometer.read_c(np.asarray(true_c, dtype=np.float64), rng)
        out = []
        for value in np.atleast_1d(raw):
            self.show_object(value)
            out.append(self.object_reading_c())
        return np.array(out)

    def pad_loop(self, command_c) -> np.ndarray:
        """The pad pre-conditioned to each of ``command_c`` through the
        drivers; the pad's true temperatures at the end (the contact's
        initial condition)."""
        out = []
        for c in np.atleast_1d(command_c):
            self.precondition(float(c))
            out.append(self.pad_true_c)
        return np.array(out)

    # ------------------------------------------------------------ contact
    def start_contact(self, t_s, flux_w_m2, temp_c, force_n) -> ContactSamples:
        """The simulator's contact (the samples the board's ADCs give) will be
        written frame by frame by :meth:`feed`."""
        self._trial = (np.asarray(t_s), np.asarray(flux_w_m2), np.asarray(temp_c),
                       np.asarray(force_n))
        self._sent = 0
        self.write_s = np.full(len(t_s), np.nan)
        contact = self.contact(len(t_s))
        self._begun = True                     # in lockstep: the next frame is sample 0
        return contact

    def feed(self, upto_t_s: float) -> bool:
        """Write the frames of the samples up to ``upto_t_s`` and read them
        back (lockstep); False once the board is lost. Without a trial
        (:meth:`start_contact` not called: a test driving the board itself)
        the drivers' own :meth:`SlavePadDrivers.feed`."""
        if self._trial is None:
            return super().feed(upto_t_s)
        t, flux, temp, force = self._trial
        while self._sent < len(t) and t[self._sent] <= upto_t_s + 1e-12:
            i = self._sent
            self.t_s += 1.0 / self.rate_hz
            if self._loop is not None:
                # A period of the rig: the slave's pad command of that period
                # (a batch of late samples must not look like a silent slave).
                self.pad.command(self._loop["setpoint"])
                self.pad_emulator.poll()
            ir, ok = self._ir_c()
            self.write_s[i] = time.perf_counter()
            self.board_emulator.send(float(t[i]), float(flux[i]), float(temp[i]),
                                     float(force[i]), ir_object_c=ir, ir_ambient_c=self.room_c,
                                     pad_drive=self._drive(), ir_ok=ok)
            self._sent += 1
        self.pad_emulator.poll()
        self.pad.poll()
        return self.collect(self._sent)

    def unplug(self) -> None:
        """The board's USB cable is pulled: the port disappears."""
        self.board_emulator.disappear()

    def replug(self) -> None:
        """... and plugged back: the port returns and the board boots."""
        self.board_emulator.reappear()

    def close(self) -> None:
        try:
            super().close()
        finally:
            self.pad_emulator.close()
            self.board_emulator.close()
            self._dir.cleanup()


class DriverPadTarget:
    """The thermometer's self-calibration target through the devices: the
    pad set by the pre-conditioning loop, read on the board with the
    thermometer's reading of it (``proto/SERIAL.md`` version 2)."""

    def __init__(self, devices: SlavePadDrivers):
        self.devices = devices
        self._last = None

    def set_pad_c(self, temp_c: float) -> None:
        self.devices.precondition(temp_c)

    def read_pad_c(self) -> float:
        r = self._last = self.devices.hold()
        return r.pad_temp_c if r is not None else math.nan

    def read_thermometer_c(self) -> float:
        r = self._last
        return r.ir_object_c if r is not None else math.nan


def calibrate_on_devices(devices: SlavePadDrivers, room_c: float, **kw):
    """:func:`~telethermal.control.thermometer_calibration.calibrate_thermometer`
    with the pad and the thermometer read through the devices, at the
    default set points (room -5, +5, +15 K). A pad that does not settle is a
    :class:`~telethermal.errors.CalibrationError` too."""
    from telethermal.control.thermometer_calibration import (DEFAULT_OFFSETS_K,
                                                            calibrate_thermometer)
    from telethermal.errors import CalibrationError

    try:
        return calibrate_thermometer(DriverPadTarget(devices),
                                     [room_c + d for d in DEFAULT_OFFSETS_K], **kw)
    except DeviceError as exc:
        raise CalibrationError(f"calibration through the devices: {exc}") from None
