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

import numpy as np

from telethermal.control import display_calibration as routine
from telethermal.control.contact import ContactDetector
from telethermal.errors import CalibrationError
from telethermal.teleop.display_calibration import (DEFAULT_BLOCK, DisplayCalibration,
                                                    fit_display)

#: What the lab is asked before each part; the routine goes on when it answers.
PRESS_BLOCK = ("press a {block} block (3 cm thick or more, its face flat, at the room's "
               "temperature) on the display's face over a thin line of thermal grease, "
               "its weight on it, then press Enter")
LIFT_BLOCK = ("lift the block off, wipe the grease from the face, leave the face free in air, "
              "then press Enter")


def _rest(display) -> None:
    """The driver disabled (0 A) while the routine waits for the lab (its
    watchdog trips meanwhile, harmlessly; the next part's commands resume it)."""
    display.peltier.command(0.0, enable=False)


def _check_force(rec: routine.Record, pressed: bool) -> None:
    """The board's force channel agrees with the part: the block's weight
    felt (over the contact detector's onset force) or the face free (under
    its release force)."""
    detector = ContactDetector()
    force = float(np.median(rec.force_n))
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
        _rest(display)
        prompt(PRESS_BLOCK.format(block=block))
        on_block = routine.run_part(display, 0.0, rate_hz, clock)
        _rest(display)
        prompt(LIFT_BLOCK)
        in_air = routine.run_part(display, 0.0, rate_hz, clock)
    finally:
        display.close()             # disabled, 0 A, whatever happened
    on_block = routine.on_grid(on_block, rate_hz, "on the block")
    in_air = routine.on_grid(in_air, rate_hz, "in air")
    _check_force(on_block, True)
    _check_force(in_air, False)
    return fit_display(scene, on_block, in_air, block, "hardware")
