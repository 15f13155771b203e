"""The display routine on a lab's own master (``telethermal calibrate
display --devices hardware``; docs/calibration.md): the sensor board and
the Peltier driver opened by URL and bus as the master service opens them,
the routine of :mod:`telethermal.control.display_calibration` paced by the
real clock, the lab asked to press the reference block on the face and
then to lift it, and the display's figures fitted as on the simulated
bench (:func:`~telethermal.teleop.display_calibration.fit_display`).

The driver is disabled (0 A) while the routine waits for the lab, when it
ends, and on any error or interrupt: the pad is never left driven."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from telethermal.control import display_calibration as routine
from telethermal.control.contact import ContactDetector
from telethermal.control.safety import SafetyLimits
from telethermal.errors import CalibrationError
from telethermal.teleop.display_calibration import (DEFAULT_BLOCK, DisplayCalibration,
                                                    fit_display)

#: What the lab is asked before each part; the routine goes on when it answers.
PRESS_BLOCK = ("the display idle at 0 A and the block at the room's temperature for a while, "
               "press a {block} block (3 cm thick or more, its face flat) on the display's face "
               "over a thin line of thermal grease and load it to about 10 N (a 1 kg weight), "
               "then press Enter")
LIFT_BLOCK = ("lift the block off, wipe the grease from the face, leave the face free in air, "
              "then press Enter")
#: Periods in a row without a trusted reading, or with the module's junction
#: outside what the master's safety allows, after which a part is stopped
#: (the driver disabled): the steps run open loop, and are not driven blind.
BLIND_MAX = 25


class _Guarded:
    """The display as the routine drives it on hardware: a board frame that
    is not new this period reads as missing (the board's own reading holds
    a frame for its ``stale_s``), and a part is stopped when the readings
    stay missing, or the junction out of the safety limits, for
    :data:`BLIND_MAX` periods."""

    def __init__(self, display):
        self.display, self.blind = display, 0
        self.limits = SafetyLimits()

    def read(self, t_s: float):
        s = self.display.read(t_s)
        if not self.display.fresh:                          # no new frame this period
            s = replace(s, flux_w_m2=math.nan, pad_temp_c=math.nan, force_n=math.nan)
        ok = math.isfinite(s.flux_w_m2) and math.isfinite(s.pad_temp_c) and \
            self.limits.reading_min_c < s.junction_c < self.limits.reading_max_c
        self.blind = 0 if ok else self.blind + 1
        if self.blind >= BLIND_MAX:
            raise CalibrationError(
                f"no trusted reading for {self.blind} periods in a row (last: flux "
                f"{s.flux_w_m2:.4g} W/m^2, face {s.pad_temp_c:.4g} C, junction "
                f"{s.junction_c:.4g} C): the routine stopped and the driver is disabled; "
                "check the board's and the driver's links")
        return s

    def apply(self, t_s: float, step, dt_s: float, force_n: float) -> None:
        self.display.apply(t_s, step, dt_s, force_n)


def _rest(display) -> None:
    """The driver disabled (0 A) while the routine waits for the lab; the
    next part's first command enables it again."""
    display.peltier.command(0.0, enable=False)


def _check_force(rec: routine.Record, pressed: bool) -> None:
    """The board's force channel agrees with the part: the block's weight
    felt (over the contact detector's onset force) or the face free (under
    its release force)."""
    detector = ContactDetector()
    if not np.isfinite(rec.force_n).any():
        raise CalibrationError(
            "the board gave no force reading: the routine checks with it that the block is on "
            "the face, then off it; connect or calibrate the board's force channel")
    force = float(np.nanmedian(rec.force_n))
    if pressed and not force > detector.on_n:
        raise CalibrationError(
            f"the force sensor read {force:.2f} N (median) with the block on the face, under "
            f"the {detector.on_n:g} N a touch needs: was the block on the face, its weight on "
            "it? Run the routine again")
    if not pressed and not force < detector.off_n:
        raise CalibrationError(
            f"the force sensor read {force:.2f} N (median) with the face free, over the "
            f"{detector.off_n:g} N of a release: was the block lifted? Run the routine again")


def calibrate_hardware(scene, board_url: str, can_bus: str, block: str = DEFAULT_BLOCK,
                       board_calibration=None, prompt=input, clock=None,
                       rate_hz: float = routine.RATE_HZ,
                       wait_s: float | None = None) -> DisplayCalibration:
    """Run the routine on the display at ``board_url`` (the sensor board)
    and ``can_bus`` (the Peltier driver) and fit its figures.
    ``board_calibration``: the board's ADC calibration
    (:class:`~telethermal.devices.board.Calibration`; the master's
    ``calibration`` file). ``prompt(text)``: asks the lab and returns when
    it is done (a terminal's ``input`` by default). ``clock``: ``now()`` and
    ``sleep_until(deadline)`` (the real clock by default). ``wait_s``: how
    long each period waits for the board's next frame (default half a
    period: a board streams on its own)."""
    from telethermal.control.loop import RealClock
    from telethermal.devices.board import Calibration
    from telethermal.devices.display import HardwareDisplay

    clock = clock if clock is not None else RealClock.for_period(1.0 / rate_hz)
    display = HardwareDisplay(board_url, can_bus, board_calibration or Calibration(),
                              clock=clock.now,
                              wait_s=0.5 / rate_hz if wait_s is None else wait_s)
    try:
        guarded = _Guarded(display)
        _rest(display)
        prompt(PRESS_BLOCK.format(block=block))
        on_block = routine.run_part(guarded, 0.0, rate_hz, clock)
        _rest(display)
        prompt(LIFT_BLOCK)
        guarded.blind = 0
        in_air = routine.run_part(guarded, 0.0, rate_hz, clock)
    finally:
        display.close()             # disabled, 0 A, whatever happened
    on_block = routine.on_grid(on_block, rate_hz, "on the block")
    in_air = routine.on_grid(in_air, rate_hz, "in air")
    routine.check_settled(on_block, "on the block")
    _check_force(on_block, True)
    _check_force(in_air, False)
    return fit_display(scene, on_block, in_air, block, "hardware")
