"""One contract for the display's devices, run against the simulator
directly, against the emulated devices (a pty and a CAN bus, through the
real drivers), and against real hardware when it is named:

    TELETHERMAL_BOARD_URL=/dev/ttyUSB0 TELETHERMAL_CAN_BUS=socketcan:can0 make test

(real hardware: the at-rest contract only; the touch needs an operator).
The tolerances are the sensors' own: flux noise and ADC, the thermocouple's
NIST inverse (+-0.04 C), the driver's 0.01 C setpoint resolution."""

import math
import os

import numpy as np
import pytest

from telethermal.control.junction_design import design_display_loop
from telethermal.devices.display import EmulatedDisplay, HardwareDisplay, SimDisplay
from telethermal.physics.thermoelectric import DEFAULT_JUNCTION_SENSOR, get_junction_sensor
from telethermal.physics.scene import load_scene, with_finger
from telethermal.teleop.master import MasterStep
from telethermal.sim.touch import DisplayTouch, Operator
from telethermal.sim.inprocess import run_session

SCENE = with_finger(load_scene("fingertip-7"))
OPERATOR = Operator(finger_c=33.0, finger_ir_c=33.0, skin_k_scale=1.0, skin_heat_scale=1.0,
                    force_n=4.0, conductance_w_m2k=5000.0)
IDLE_C = 28.0
HARDWARE = os.environ.get("TELETHERMAL_BOARD_URL"), os.environ.get("TELETHERMAL_CAN_BUS")


class Clock:
    t = 0.0

    def __call__(self):
        return self.t


@pytest.fixture(params=["sim", "emulated", "hardware"])
def display(request):
    clock = Clock()
    touch = DisplayTouch(SCENE, OPERATOR, 1000.0, 1.0, IDLE_C, np.random.default_rng(0))
    if request.param == "sim":
        d = SimDisplay(touch)
    elif request.param == "emulated":
        d = EmulatedDisplay(touch, clock=clock)
    else:
        if not all(HARDWARE):
            pytest.skip("no hardware named (TELETHERMAL_BOARD_URL, TELETHERMAL_CAN_BUS)")
        import time
        clock = time.monotonic
        d = HardwareDisplay(*HARDWARE, wait_s=0.01)
    yield d, clock
    d.close()


def step_to(t, junction_c, current_a=0.0):
    return MasterStep(t, "contact", True, math.nan, junction_c, junction_c, False, current_a)


def run(d, clock, t0, t1, junction_c, rate=1000.0):
    """Drive the display's junction to ``junction_c`` through the module's
    current, as the master's inner loop does (control/junction.py), from the
    junction and heat-sink readings the devices give."""
    params, _ = SCENE.pad.module_params()
    loop, _ = design_display_loop(params, SCENE.pad.layers, SCENE.pad.area_m2,
                                  get_junction_sensor(DEFAULT_JUNCTION_SENSOR).tau_s, 1 / rate,
                                  0.02, 100.0)
    out = []
    for k in range(int(round((t1 - t0) * rate))):
        t = t0 + k / rate
        if isinstance(clock, Clock):
            clock.t = t
        s = d.read(t)
        current = loop.update(junction_c, s.junction_c, s.heatsink_c, 1 / rate).current_a
        d.apply(t, step_to(t, junction_c, current), 1 / rate, s.force_n)
        out.append((t, s.flux_w_m2, s.pad_temp_c, s.force_n))
    return np.array(out)


def test_at_rest_the_readings_are_finite_quiet_and_untouched(display):
    d, clock = display
    rows = run(d, clock, -0.2, -0.05, IDLE_C)[20:]
    t, flux, pad, force = rows.T
    assert np.isfinite(rows).all()
    assert np.abs(np.median(flux)) < 20.0 and np.std(flux) < 100.0      # W/m^2: noise only
    assert np.abs(force).max() < 0.5                                      # N: nobody presses
    if d.kind != "hardware":
        assert np.abs(pad - IDLE_C).max() < 0.5


def test_a_touch_on_a_pad_hotter_than_the_finger_heats_the_finger(display):
    d, clock = display
    if d.kind == "hardware":
        pytest.skip("needs an operator's finger on the pad")
    run(d, clock, -0.1, 0.0, IDLE_C)
    # Junction 7 K above the finger: 12 K above the idle, which the loop's
    # target climbs at what the module can heat (about 25 K/s) through the
    # bonded sensor's lag; the flux turns positive within 0.6 s.
    rows = run(d, clock, 0.0, 0.95, 40.0)                     # the touch lasts 1 s
    t, flux, pad, force = rows.T
    late = t > 0.6
    assert np.isfinite(rows[late]).all()
    assert (flux[late] > 500.0).all()                          # pad -> finger positive
    assert pad[-1] > pad[np.argmax(t >= 0.05)]                 # the pad warms toward 40 C
    assert (force[late] > 0.5 * OPERATOR.force_n).all()


def test_emulated_devices_read_what_the_simulator_reads():
    # Same touch, same noise draws: the emulated path differs from the direct
    # one only by float32 microvolts, the NIST inverse, and the CAN frames'
    # 1 mA current and 0.01 C junction readings (the junction loop's 0.85 A/K
    # turns a 0.01 C step into 0.01 A: under 2 % of the peak flux).
    out = {}
    for kind in ("sim", "emulated"):
        touch = DisplayTouch(SCENE, OPERATOR, 1000.0, 1.0, IDLE_C, np.random.default_rng(0))
        clock = Clock()
        d = SimDisplay(touch) if kind == "sim" else EmulatedDisplay(touch, clock=clock)
        try:
            out[kind] = run(d, clock, -0.1, 0.5, 38.0)
        finally:
            d.close()
    a, b = out["sim"], out["emulated"]
    assert np.abs(a[:, 1] - b[:, 1]).max() < 0.02 * np.abs(a[:, 1]).max()   # W/m^2
    assert np.abs(a[:, 2] - b[:, 2]).max() < 0.1                # C (the currents above)
    assert np.abs(a[:, 3] - b[:, 3]).max() < 1e-5               # N


def test_a_session_through_emulated_devices_writes_the_same_json_as_with_sim(trained_models):
    ident, gen = trained_models.pair(SCENE, 0)
    sim = run_session(SCENE, "plexiglass", ident, gen, contact_s=1.0, seed=3).summary
    emu = run_session(SCENE, "plexiglass", ident, gen, contact_s=1.0, seed=3,
                      devices="emulated").summary
    assert set(sim) == set(emu) and emu["devices"] == "emulated"
    assert emu["flux_rms_error_rel_whole"] == pytest.approx(sim["flux_rms_error_rel_whole"],
                                                            rel=0.05)
    assert emu["safety_events"] == sim["safety_events"] == 0
    board = emu["device_counters"]["board"]
    assert board["frames"] > 0 and board["crc"] == board["seq_gaps"] == 0


def _emulated_display_and_master():
    """A clock, the emulated display (board on a pty, Peltier driver on a
    virtual CAN bus), a static-PID master holding at the idle, its news."""
    from telethermal.teleop.display_config import DisplayConfig
    from telethermal.teleop.master import MasterDisplay, SlaveNews
    from telethermal.physics.layered import pad_resistance
    touch = DisplayTouch(SCENE, OPERATOR, 1000.0, 1.0, IDLE_C, np.random.default_rng(0))
    clock = Clock()
    d = EmulatedDisplay(touch, clock=clock)
    master = MasterDisplay(DisplayConfig(before="hold", feedforward_model="static",
                                         rate_hz=1000.0), None,          # stepped every 1 ms
                           pad_resistance(SCENE.pad.layers), SCENE.sensors.flux_lag_s, 33.0,
                           idle_c=IDLE_C)
    return clock, d, master, SlaveNews(object_temp_c=IDLE_C)


def test_a_missing_reading_or_an_over_temperature_driver_is_the_safe_state_that_period():
    clock, d, master, news = _emulated_display_and_master()
    safe = {}
    try:
        for k in range(700):
            t = clock.t = -0.1 + k * 1e-3
            if k == 300:
                d.board_emulator.dropout = 1.0            # the board goes quiet
            if k == 400:
                d.board_emulator.dropout = 0.0
            if k == 500:
                d.peltier_emulator.over_temperature()
            s = d.read(t)
            step = master.step(t, 1e-3, s, news)
            d.apply(t, step, 1e-3, s.force_n)
            safe[k] = step.safe
    finally:
        d.close()
    assert not any(safe[k] for k in range(100, 300))
    # Quiet from k = 300: stale after stale_s (50 ms), safe from then on.
    assert all(safe[k] for k in range(352, 400))
    assert all(safe[k] for k in range(502, 700))          # over-temperature: safe, stays
    assert master.safety.events                            # and the supervisor says why


def test_a_peltier_driver_that_stops_reporting_is_the_safe_state_within_its_heartbeat():
    # The driver board goes silent (a reboot that does not come back within
    # the test): its last heartbeat ages past heartbeat_timeout_s, the
    # display stops trusting the actuator, its flux reading is withdrawn and
    # the supervisor holds the safe state from then on, saying why.
    clock, d, master, news = _emulated_display_and_master()
    timeout_k = int(round(d.hardware.peltier.heartbeat_timeout_s / 1e-3))
    safe, healthy = {}, {}
    try:
        for k in range(300 + timeout_k + 200):
            t = clock.t = -0.1 + k * 1e-3
            if k == 300:
                d.peltier_emulator.reboot(offline_s=10.0)     # silent from here
            s = d.read(t)
            step = master.step(t, 1e-3, s, news)
            d.apply(t, step, 1e-3, s.force_n)
            safe[k], healthy[k] = step.safe, d.hardware.peltier.healthy
    finally:
        d.close()
    assert not any(safe[k] for k in range(100, 300))
    assert all(healthy[k] for k in range(100, 300))
    # Unhealthy, and the display in its safe state, no later than one
    # heartbeat timeout plus two periods after the last report; stays so.
    end = 300 + timeout_k + 2
    assert not healthy[end] and all(safe[k] for k in range(end, 300 + timeout_k + 200))
    assert d.counters()["untrusted_periods"] > 0
    assert master.safety.events
