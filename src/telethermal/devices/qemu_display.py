"""The master's display with the reference firmware as its boards,
processor in the loop (``devices = "qemu"``): the sensor board image and
the Peltier driver image each on an emulated STM32F405
(:mod:`telethermal.devices.qemu`), read and commanded through the project's
drivers exactly as the real boards would be (``SensorBoard`` on the board's
USART1 pty, ``PeltierDriver`` on python-can's ``slcan`` over the driver's
USART1), and a bridge that, each control period, in step with the
simulated clock:

* writes the touch's analog readings on each core's plant link (USART2):
  the sample the board's ADCs would convert (the flux sensor's and the
  thermocouple's microvolts through the calibration, the force), and the
  thermistors and current the driver would measure;
* waits for the board's frame, and after the command for the driver's
  answer, and takes the H-bridge's current back from the driver's plant
  link, which drives the simulated module.

The cores keep their own clocks (the watchdog, the heartbeat, the
frames' ``t_us``); the loop waits for each of their answers, so a period
takes as long as the cores need to hear and answer it (the emulated UART
takes a byte in about 0.1 ms of the host's time). A master service on a
slowed clock (``time_scale``) has its boards' cores stretch their
millisecond as much (:class:`~telethermal.devices.qemu.QemuBoards`) and
gives the drivers its clock, so their timeouts, heartbeats and watchdog
run on its time.
"""

from __future__ import annotations

import math
import re
import time
from dataclasses import replace

from telethermal.devices import qemu
from telethermal.devices.board import Calibration, DeviceError
from telethermal.devices.display import HardwareDisplay
from telethermal.devices.kinds import DeviceKind
from telethermal.devices.readings import PadSensors

#: How long the bridge waits for a core's answer (or frame) before it
#: counts a miss: s of the host's time, a hang guard only (the wait ends
#: as the answer arrives; nothing is timed by it), generous because this
#: host can stall the emulator for a good part of a second; a miss is then
#: a core that did not answer at all, not a slow host.
ANSWER_WAIT_S = 5.0
COLD_JUNCTION_C = 25.0          # the board's boot frame says so (main_board.c)
NAMES = ("tt_board", "tt_peltier")      # the display's images


class QemuDisplay:
    kind = DeviceKind.QEMU

    def __init__(self, touch, clock=time.monotonic, realtime: bool = False, seed: int = 0,
                 calibration: Calibration = Calibration(), boards: qemu.QemuBoards | None = None):
        """``boards``: a service's cores (``tt_board``, ``tt_peltier``),
        restarted for this touch and left running at :meth:`close`; without,
        the display builds and starts its own and stops them at close."""
        del realtime, seed              # the cores keep their own time; no noise added here
        self.touch, self.calibration = touch, calibration
        self._own = boards is None
        self.boards = qemu.QemuBoards(NAMES) if boards is None else boards
        self.cores = [self.boards.cores[n] for n in NAMES]
        self.plants = [self.boards.plants[n] for n in NAMES]
        self.hardware = None
        self.counters_ = {"board_waits_missed": 0, "answers_missed": 0}
        self._applied_ma = 0
        try:
            if not self._own:
                self.boards.restart()
            self.hardware = HardwareDisplay(self.cores[0].link_path,
                                            f"slcan:{self.cores[1].link_path}",
                                            calibration, clock=clock, wait_s=ANSWER_WAIT_S)
            self._heard()
        except BaseException:
            self.close()
            raise

    def _heard(self) -> None:
        """Until the driver has heard the core's heartbeat (every 100 ms of
        the core's time, which the rig's time scale stretches; a driver that
        has not cannot trust the core, and the touch would start with its
        readings untrusted); a hang guard of ANSWER_WAIT_S plus two
        heartbeats of the machine's time."""
        driver = self.hardware.peltier
        scale = self.boards.scale_milli / 1000
        guard_s = ANSWER_WAIT_S + 2 * qemu.HEARTBEAT_S * scale
        deadline = time.monotonic() + guard_s
        while not driver.alive and time.monotonic() < deadline:
            driver.poll(wait_s=0.01)
        if not driver.alive:
            raise DeviceError(f"the Peltier driver's core sent no heartbeat within "
                              f"{guard_s:g} s of the machine's time (time scale {scale:g}; "
                              f"{self.cores[1].link_path})")

    # ------------------------------------------------------------ the bridge
    def _sample_line(self, s: PadSensors) -> bytes:
        """The board's ADC channels for the touch's reading, as a plant line;
        status bits cleared for a channel with no reading (NaN)."""
        cal, status, values = self.calibration, 0, []
        for bit, value in ((1, s.flux_w_m2), (2, s.pad_temp_c), (4, s.force_n)):
            status |= bit if math.isfinite(value) else 0
        values.append(cal.flux_uv(s.flux_w_m2) if status & 1 else 0.0)
        values.append(cal.tc_uv(s.pad_temp_c, COLD_JUNCTION_C) if status & 2 else 0.0)
        values.append(COLD_JUNCTION_C)
        values.append(s.force_n if status & 4 else 0.0)
        # Nine significant digits: every float32 exactly, in a short line
        # (the emulated UART takes about 0.1 ms a byte).
        return ("s " + " ".join(f"{v:.9g}" for v in values) + f" {status}\n").encode()

    def _measure_line(self) -> bytes:
        junction_c, heatsink_c, current_a = self.touch.module_state()
        ok = all(math.isfinite(v) for v in (junction_c, heatsink_c, current_a))
        cc = [round(100 * v) if ok else 0 for v in (junction_c, heatsink_c)]
        ma = round(1000 * current_a) if ok else 0
        return f"m {cc[0]} {cc[1]} {ma} 0 {int(ok)}\n".encode()

    def _latest_current_ma(self) -> int:
        """The H-bridge's current from the driver's plant link: its last
        ``set`` line (the driver reports every change)."""
        plant = self.plants[1]
        plant.read()
        sets = re.findall(rb"set \d+ (\d) (-?\d+)\n", plant.buf)
        if sets:
            enabled, ma = sets[-1]
            self._applied_ma = int(ma) if enabled == b"1" else 0
            plant.buf = plant.buf[plant.buf.rindex(b"\n") + 1:]
        return self._applied_ma

    # ------------------------------------------------------------ the display
    def read(self, t_s: float) -> PadSensors:
        s = self.touch.sense(t_s)
        self.plants[1].write(self._measure_line())
        self.plants[0].write(self._sample_line(s))
        sensors = self.hardware.read(t_s)
        if not self.hardware.fresh:
            self.counters_["board_waits_missed"] += 1
        return sensors

    def module_readings(self) -> tuple[float, float, float]:
        return self.hardware.module_readings()

    def apply(self, t_s: float, step, dt_s: float, force_n: float) -> None:
        """The master's current through PeltierDriver and SLCAN to the
        driver's core; the current its H-bridge drives to the touch."""
        driver = self.hardware.peltier
        answered = driver.counters["statuses"]
        self.hardware.apply(t_s, step, dt_s, force_n)
        deadline = time.monotonic() + ANSWER_WAIT_S
        while driver.counters["statuses"] == answered and time.monotonic() < deadline:
            driver.poll(wait_s=0.002)
        if driver.counters["statuses"] == answered:
            self.counters_["answers_missed"] += 1
        current_a = self._latest_current_ma() / 1000.0
        self.touch.actuate(t_s, replace(step, current_a=current_a), dt_s, force_n)

    def counters(self) -> dict:
        return {**self.hardware.counters(), **self.counters_,
                "bridge_bytes": dict(self.cores[0].bytes),
                "bridge_dropped_bytes": sum(core.dropped_bytes for core in self.cores)}

    def close(self) -> None:
        try:
            if self.hardware is not None:
                self.hardware.close()
        finally:
            if self._own:
                self.boards.close()
