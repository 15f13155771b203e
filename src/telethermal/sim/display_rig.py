"""The display on a lab's bench, simulated, for its calibration
(``telethermal calibrate display``): the master's display pad as built
(``[as_built.display]``) with a reference block pressed on its face from
session time 0, lifted at the end of that part, its face then free in air
(control/display_calibration.py's routine drives it through the display
devices, as the master would).

The block part comes first, from rest: the module idle at 0 A sits at its
sink's temperature and the sink at the room's, as the block does, so the
contact brings no step of temperature. Pressed on a pad a kelvin off it,
the contact's first milliseconds carry a spike of flux (1.4 K on grease:
27 kW/m^2) that the simulated plant's modal model and the fit's closed form
disagree on (measured: the flux lag read 8 % long)."""

from __future__ import annotations

import math

import numpy as np

from telethermal.control.display_calibration import BLOCK_FORCE_N, RATE_HZ, steps_duration_s
from telethermal.physics.layered import Boundary, Layer, LayeredContact
from telethermal.physics.materials import get_material
from telethermal.teleop.display_calibration import (DEFAULT_BLOCK, DisplayCalibration,
                                                    calibrate_display)
from telethermal.sim.touch import DisplayTouch, Operator

#: A block pressed on the pad with thermal grease: a 50 um line of a
#: 1 W/(m K) compound (common silicone greases: 0.7-3 W/(m K)), 2e4 W/(m^2 K).
GREASED_CONTACT_W_M2K = 2.0e4


class BenchTouch(DisplayTouch):
    """A :class:`DisplayTouch` whose face meets a semi-infinite block of
    ``block`` (a material of the table) instead of a finger."""

    def __init__(self, scene, operator: Operator, rate_hz: float, contact_s: float,
                 idle_c: float, rng: np.random.Generator, block: str):
        super().__init__(scene, operator, rate_hz, contact_s, idle_c, rng)
        self.model = LayeredContact(self.layers, (Layer(get_material(block), math.inf),),
                                    Boundary("isothermal"), Boundary("adiabatic"),
                                    min(self.dt_s, 1e-3), round(contact_s + 1.0, 3))

    def sense(self, t: float):
        if self.plant is not None and not self.touching(t):
            self.plant = None       # the block lifted: the face in air again
        return super().sense(t)


def simulated_bench(scene, block: str, seed: int, rate_hz: float) -> BenchTouch:
    """The display of ``scene`` on the bench with a block of ``block`` at the
    room's temperature; the pad idles there before the routine. Its session
    holds the part on the block (from 0) and the part in air (from
    :func:`air_start_s`, as the block is lifted)."""
    rng = np.random.default_rng([seed, 44])
    room = scene.room_temp_c
    tc_bias = float(rng.uniform(-1, 1) * scene.sensors.display_tc_reference_limit_k)
    operator = Operator(room, room, 1.0, 1.0, BLOCK_FORCE_N, GREASED_CONTACT_W_M2K, tc_bias)
    d = steps_duration_s()
    touch = BenchTouch(scene, operator, rate_hz, 2 * d, room, rng, block)
    touch.contact_s = d
    return touch


def air_start_s() -> float:
    """Session time the part in air starts at: the block is lifted then."""
    return steps_duration_s()


def calibrate_simulated(scene, block: str = DEFAULT_BLOCK, seed: int = 0,
                        devices: str = "sim") -> DisplayCalibration:
    """The routine on the simulated bench (sim/display_rig.py): the
    display as built (``[as_built.display]``) through ``devices`` ("sim"
    or "emulated": the master's drivers)."""
    from telethermal.devices.display import open_display

    touch = simulated_bench(scene, block, seed, RATE_HZ)
    now = [0.0]
    display = open_display(devices, touch, clock=lambda: now[0], seed=seed)
    try:
        return calibrate_display(scene, _Clocked(display, now), block,
                                 bench="simulated" if devices == "sim" else "emulated")
    finally:
        display.close()


class _Clocked:
    """A display whose devices' clock follows the routine's session time."""

    def __init__(self, display, now: list):
        self.display, self.now = display, now

    def read(self, t_s: float):
        self.now[0] = t_s
        return self.display.read(t_s)

    def apply(self, t_s: float, step, dt_s: float, force_n: float) -> None:
        self.display.apply(t_s, step, dt_s, force_n)
