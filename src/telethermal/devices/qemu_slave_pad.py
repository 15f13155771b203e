"""The slave's sensing pad with the reference firmware as its boards,
processor in the loop (``devices = "qemu"``): the version-2 sensor board
image (``tt_board2``) and the active pad's driver image (``tt_pad``) each on
an emulated STM32F405 (:mod:`telethermal.devices.qemu`), read and commanded
through the slave's own drivers (``SensorBoard`` on the board's USART1 pty,
``ActivePadDriver`` on python-can's ``slcan`` over the driver's USART1).

The simulator side is :class:`~telethermal.devices.slave_pad.EmulatedSlavePad`'s
(the pad's first-order plant, the session's instruments, the contact's
samples); only the boards differ, bridged as
:mod:`~telethermal.devices.qemu_display` bridges the display's, in step with
the simulated clock:

* each sample the simulator gives (the pad's thermocouple, the flux, the
  force, the IR thermometer's reading) is written on the board's plant link
  (USART2) as the ADC channels' values, and the bridge waits for the frame
  the core sends for it;
* each command the slave sends is awaited until the core answers it
  (``PAD_STATUS``); the H-bridge's current the core reports on its plant
  link (``set`` lines) drives the simulated pad; the pad's measurement
  (junction, heat sink, current) goes to the core before each period.

The cores keep their own clocks (the watchdog, the heartbeat, the frames'
``t_us``), which follow the host's while they wait, stretched by the
service's ``time_scale`` (:class:`~telethermal.devices.qemu.QemuBoards`;
the drivers then read the service's clock too): between touches, when the
slave sends no command for more than 100 ms of that time, the pad's driver
turns the element off and says so (counted by the driver), as a real board
would.
"""

from __future__ import annotations

import math
import re
import time

from telethermal.devices import qemu
from telethermal.devices.board import Calibration
from telethermal.devices.frames import STATUS_FLUX, STATUS_FORCE, STATUS_IR, STATUS_TC
from telethermal.devices.kinds import DeviceKind
from telethermal.devices.qemu_display import ANSWER_WAIT_S
from telethermal.devices.slave_pad import EmulatedSlavePad

NAMES = ("tt_board2", "tt_pad")         # the slave's images
#: The element's current limit in the pad image (tt_peltier_default_config:
#: 8500 mA, the TM-31-1.4-8.5's Imax): the measured drive is its fraction.
CURRENT_LIMIT_A = 8.5
#: How long the bridge listens on the plant link after the core's answer for
#: the H-bridge's line the core sent just before it (s of the host's time).
SET_LINE_WAIT_S = 0.002


class _BoardFeed:
    """The slave's board image fed as the emulated board is (``send``): a
    sample's ADC values on the plant link, then the core's frame awaited."""

    def __init__(self, core: qemu.QemuCore, plant: qemu.PtyLine, room_c: float,
                 calibration: Calibration):
        self.core, self.plant, self.calibration = core, plant, calibration
        self.path = core.link_path
        self.noise_uv = 0.0             # the core adds none: the instruments' noise only
        self.counters = {"samples": 0, "frames_missed": 0}
        self.cj_c = room_c              # the cold junction at room temperature, as emulated
        self.pipelined = False
        self._ends = 0                  # frame delimiters the core has sent
        core.tap = self._tap

    def _tap(self, uart: int, data: bytes) -> None:
        if uart == 0:
            self._ends += data.count(0)

    def line(self, flux_w_m2, pad_temp_c, force_n, ir_object_c, ir_ambient_c, pad_drive,
             ir_ok) -> bytes:
        cal, status = self.calibration, 0
        for bit, value in ((STATUS_FLUX, flux_w_m2), (STATUS_TC, pad_temp_c),
                           (STATUS_FORCE, force_n)):
            status |= bit if math.isfinite(value) else 0
        values = (cal.flux_uv(flux_w_m2) if status & STATUS_FLUX else 0.0,
                  cal.tc_uv(pad_temp_c, self.cj_c) if status & STATUS_TC else 0.0,
                  self.cj_c, force_n if status & STATUS_FORCE else 0.0)
        status |= STATUS_IR if ir_ok else 0
        extra = (ir_object_c, ir_ambient_c, pad_drive)
        return ("s " + " ".join(f"{v:.9g}" for v in values) + f" {status} " +
                " ".join(f"{v:.9g}" for v in extra) + "\n").encode()

    def send(self, t_s: float, flux_w_m2: float, pad_temp_c: float, force_n: float,
             ir_object_c: float = math.nan, ir_ambient_c: float = math.nan,
             pad_drive: float = 0.0, ir_ok: bool = True) -> bool:
        """One sample on the plant link (the core stamps it with its own
        clock: ``t_s`` is not sent), its frame awaited unless ``pipelined``
        (a contact's samples go to the core one after another while it
        frames the earlier ones; the drivers wait for them, ``wait_s``)."""
        del t_s
        before = self._ends
        self.plant.write(self.line(flux_w_m2, pad_temp_c, force_n, ir_object_c,
                                   ir_ambient_c, pad_drive, ir_ok))
        self.counters["samples"] += 1
        deadline = time.monotonic() + ANSWER_WAIT_S
        while not self.pipelined and self._ends == before and time.monotonic() < deadline:
            time.sleep(0.0005)
        if not self.pipelined and self._ends == before:
            self.counters["frames_missed"] += 1
            return False
        return True

    def disappear(self) -> None:
        self.core.cut.add(0)            # the cable pulled: nothing either way

    def reappear(self) -> None:
        self.core.cut.discard(0)

    def close(self) -> None:
        pass


class _PadFeed:
    """The pad image's analog side: its measurement written before each
    period (``poll``), the H-bridge's current read from its ``set`` lines."""

    def __init__(self, plant: qemu.PtyLine, on_current, state):
        self.plant, self.on_current, self.state = plant, on_current, state
        self.enabled, self.current_a = False, 0.0

    def read_sets(self, wait_s: float = 0.0) -> None:
        self.plant.read(wait_s)
        sets = re.findall(rb"set \d+ (\d) (-?\d+)\n", self.plant.buf)
        if b"\n" in self.plant.buf:
            self.plant.buf = self.plant.buf[self.plant.buf.rindex(b"\n") + 1:]
        if sets:
            enabled, ma = sets[-1]
            self.enabled = enabled == b"1"
            current_a = int(ma) / 1000.0 if self.enabled else 0.0
            if current_a != self.current_a or not self.enabled:
                self.current_a = current_a
                self.on_current(current_a)

    def poll(self) -> None:
        self.read_sets()
        junction_c, heatsink_c, current_a = self.state()
        ok = all(math.isfinite(v) for v in (junction_c, heatsink_c, current_a))
        cc = [round(100 * v) if ok else 0 for v in (junction_c, heatsink_c)]
        ma = round(1000 * current_a) if ok else 0
        drive = round(1000 * max(-1.0, min(1.0, current_a / CURRENT_LIMIT_A))) if ok else 0
        self.plant.write(f"m {cc[0]} {cc[1]} {ma} {drive} {int(ok)}\n".encode())


class QemuSlavePad(EmulatedSlavePad):
    """:class:`EmulatedSlavePad` with the firmware images as its boards
    (``build_dir``: the firmware's build folder, empty: a temporary one)."""

    kind = DeviceKind.QEMU

    def __init__(self, scene, instruments, seed: int = 0, build_dir: str = "",
                 time_scale: float = 1.0, **kw):
        """``time_scale``: the service's (the cores' millisecond stretched
        as much: :class:`~telethermal.devices.qemu.QemuBoards`)."""
        self._build_dir, self._time_scale = build_dir, time_scale
        self.counters_ = {"answers_missed": 0}
        super().__init__(scene, instruments, seed=seed, wait_s=kw.pop("wait_s", ANSWER_WAIT_S),
                         **kw)

    def _open_boards(self, seed: int, board_noise_uv: float) -> tuple[str, str]:
        del seed, board_noise_uv        # the instruments' noise is the simulator's
        self.boards = qemu.QemuBoards(NAMES, self._build_dir,
                                      purpose="the slave's devices = 'qemu'",
                                      time_scale=self._time_scale)
        try:
            board, pad = (self.boards.cores[n] for n in NAMES)
            self.board_emulator = _BoardFeed(board, self.boards.plants["tt_board2"],
                                             self.room_c, Calibration())
            self.pad_emulator = _PadFeed(self.boards.plants["tt_pad"], self._on_current,
                                         lambda: (self.junction_c, self.room_c,
                                                  self.pad_emulator.current_a))
        except BaseException:
            self.boards.close()
            raise
        return board.link_path, f"slcan:{pad.link_path}"

    def _close_boards(self) -> None:
        self.boards.close()

    def _after_command(self) -> None:
        """The command's answer awaited (the core has applied it), then the
        H-bridge's current it drives."""
        answered = self.pad.counters["statuses"]
        deadline = time.monotonic() + ANSWER_WAIT_S
        while self.pad.counters["statuses"] == answered and time.monotonic() < deadline:
            self.pad.poll(wait_s=0.002)
        if self.pad.counters["statuses"] == answered:
            self.counters_["answers_missed"] += 1
        # The core writes the H-bridge's line before it answers, but on the
        # other UART: a moment's listening (host time) for its bytes.
        self.pad_emulator.read_sets(SET_LINE_WAIT_S)

    def feed(self, upto_t_s: float) -> bool:
        """A contact's samples pipelined through the board's core; every
        other period (the pad's loop, the object's reading) waits for its
        frame, so that each period reads its own sample."""
        self.board_emulator.pipelined = True
        try:
            return super().feed(upto_t_s)
        finally:
            self.board_emulator.pipelined = False

    def all_counters(self) -> dict:
        return {**super().all_counters(), **self.counters_,
                "bridge": dict(self.board_emulator.counters)}
