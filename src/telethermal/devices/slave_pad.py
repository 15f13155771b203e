"""The slave's sensing pad on its devices: the sensor board (frame version 2:
heat flux, the pad's thermocouple, force, the IR thermometer) over a serial
line and the active pad's driver on CAN (``PAD_*`` frames).

:class:`~telethermal.devices.pad_drivers.SlavePadDrivers` (importable from
here too) is what the slave runs against, real or emulated: the object's IR
reading, the pad's pre-conditioning loop, a contact's samples, the safe state.

:class:`EmulatedSlavePad` puts the simulator behind emulated devices (the
board on a pty, the pad's driver on a python-can virtual bus) and steps
them in lockstep with the slave: the pad's temperature is a first-order
plant driven by the junction the module current the emulated driver
receives holds (:func:`~telethermal.devices.active_pad.current_junction_c`), its
thermocouple and the object thermometer are the session's instruments (bias,
noise, resolution), and during a contact the simulator's samples are written
as the board's frames. The identifier sees the bytes a board would send.

A water pad (paper 2, eq. 11-13) is pre-conditioned by the simulator in
this version; its heater and pump have CAN signals but no emulator drives
them yet, so a water-pad scene refuses ``devices = "emulated"``.
"""

from __future__ import annotations

import itertools
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from telethermal.devices.kinds import DeviceKind
from telethermal.devices.active_pad import ActivePadEmulator, current_junction_c
from telethermal.devices.board import DeviceError
from telethermal.devices.emulators import SensorBoardEmulator
from telethermal.devices.frames import FRAME_VERSION_SLAVE
from telethermal.devices.pad_drivers import ContactSamples, SlavePadDrivers

_bus_names = itertools.count()


class EmulatedSlavePad(SlavePadDrivers):
    """:class:`SlavePadDrivers` on emulated devices fed by the simulator.

    ``instruments``: the session's (the pad thermocouple's bias, the object
    thermometer's bias, gain error, noise and resolution); ``rng`` draws the
    per-reading noise of the pad's loop. The thermometer sees the object
    (:meth:`show_object`) or the pad (:meth:`aim_at_pad`, calibration).
    """

    kind = DeviceKind.EMULATED

    def __init__(self, scene, instruments, seed: int = 0, wait_s: float = 0.05,
                 pad_tau_s: float = 0.5, board_noise_uv: float = 0.0, clock=time.monotonic):
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
        self._ir_rng: np.random.Generator | None = None     # aim_at_pad's noise
        self.object_raw_c = math.nan
        #: Faults of the IR sensor: None, "flagged" (the board clears its
        #: bit), or a value (degC) it reports whatever it sees.
        self.ir_fault: str | float | None = None
        board_url, bus = self._open_boards(seed, board_noise_uv)
        try:
            super().__init__(board_url, bus, scene.sample_rate_hz, wait_s=wait_s, clock=clock)
        except Exception:
            self._close_boards()
            raise
        self.board.reopen_s = 0.05
        self.write_s: np.ndarray | None = None       # when each contact sample left the board
        self._trial = None
        self._sent = 0

    def _open_boards(self, seed: int, board_noise_uv: float) -> tuple[str, str]:
        """The boards the simulator feeds: ``board_emulator`` (``send``) and
        ``pad_emulator`` (``poll``, ``current_a``, ``enabled``); returns the
        board's URL and the pad driver's bus."""
        self._dir = tempfile.TemporaryDirectory(prefix="telethermal-slave-dev-")
        self.board_emulator = SensorBoardEmulator(Path(self._dir.name) / "slave-board",
                                                  cold_junction_c=self.room_c, seed=seed,
                                                  version=FRAME_VERSION_SLAVE)
        self.board_emulator.noise_uv = board_noise_uv
        bus = f"virtual:telethermal-slave-pad-{next(_bus_names)}"
        # The pad's driver board keeps the rig's time (its watchdog counts
        # periods the slave let pass, not the simulator's own computing).
        self.pad_emulator = ActivePadEmulator(bus, self._on_current, heatsink_c=self.room_c,
                                              clock=lambda: self.t_s,
                                              state=lambda: (self.junction_c, self.room_c,
                                                             self.pad_emulator.current_a))
        return self.board_emulator.path, bus

    def _close_boards(self) -> None:
        try:
            self.pad_emulator.close()
            self.board_emulator.close()
        finally:
            self._dir.cleanup()

    # ------------------------------------------------------------ the simulator side
    def _on_current(self, current_a: float) -> None:
        """The board drives ``current_a``: the junction goes to the module's
        small-signal steady state on a sink at room temperature (0 A: the
        room's)."""
        self.junction_c = current_junction_c(current_a, self.room_c)

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
            # period passes on the drivers' clock too, so its reopening runs.
            end = self.clock() + dt
            while self.clock() < end:
                time.sleep(dt / 10)
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
        return self.contact(len(t_s))     # begun at the trial's first frame (feed)

    def feed(self, upto_t_s: float) -> bool:
        """Write the frames of the samples up to ``upto_t_s`` and read them
        back (lockstep); False once the board is lost. Without a trial
        (:meth:`start_contact` not called: a test driving the board itself)
        the drivers' own :meth:`SlavePadDrivers.feed`."""
        if self._trial is None:
            return super().feed(upto_t_s)
        t, flux, temp, force = self._trial
        if self._sent == 0:
            # The pad may have been held since the contact was prepared (a
            # service holds it every sample period until the touch): those
            # periods' frames were the board's, not the contact's. The
            # contact starts at the trial's first frame, the next one: the
            # emulator's next sequence number where it has one (a held
            # period's frame lost on the line changes nothing then), else
            # the one after the last frame read (the firmware numbers its own).
            self.begin_contact()
            next_seq = getattr(self.board_emulator, "seq", None)
            if next_seq is not None:
                self._seq0 = next_seq
        while self._sent < len(t) and t[self._sent] <= upto_t_s + 1e-12:
            i = self._sent
            self.t_s += 1.0 / self.rate_hz
            if self._loop is not None:
                # A period of the rig: the slave's pad command of that period
                # (a batch of late samples must not look like a silent slave).
                self._command_junction(self._loop["setpoint"])
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
            self._close_boards()


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
        raise CalibrationError(f"calibration through the devices: {exc}") from exc
